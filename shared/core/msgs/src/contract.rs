//! The payloads, their topics, and the constants that give their fields meaning.

use iceoryx2::prelude::ZeroCopySend;

use crate::message::{define_struct, message, nested, topics};

/// Glove finger order used by every glove field: little, ring, middle, index, thumb.
pub const GLOVE_FINGERS: [&str; 5] = ["little", "ring", "middle", "index", "thumb"];
/// Glove position channels: the five fingers, then the thumb's lateral rotation.
pub const GLOVE_CHANNELS: [&str; 6] = [
    "little",
    "ring",
    "middle",
    "index",
    "thumb",
    "thumb_rotation",
];
/// Most joints a [`HandCommand`] or [`HandState`] can carry (Shadow Hand has 24 with the wrist).
pub const MAX_JOINTS: usize = 24;
/// Most fingertips a [`Tactile`] sample can carry.
pub const MAX_FINGERTIPS: usize = 5;

/// The one numbering of the devices the pipeline drives or reads: the `hand_model` fields of
/// [`HandCommand`], [`HandState`] and [`Tactile`], [`DeviceInfo::device_model`], and (by
/// [`name`](device_model::name)) the `name` of a hand profile, recording metadata keys
/// (`device.allegro`) and the viewer's entity paths.
pub mod device_model {
    /// Not known (a hand command for no particular hand is refused by every hand node).
    pub const UNKNOWN: u8 = 0;
    /// BrainCo Revo2 (6 joints, EtherCAT).
    pub const REVO2: u8 = 1;
    /// Wonik Allegro Hand (16 joints, CAN).
    pub const ALLEGRO: u8 = 2;
    /// Shadow Dexterous Hand (24 joints, EtherCAT).
    pub const SHADOW: u8 = 3;
    /// The EH55BF1 exoskeleton glove (serial line).
    pub const GLOVE: u8 = 4;
    /// LEAP Hand (16 Dynamixel XC330 servos on one serial bus, Protocol 2.0).
    pub const LEAP: u8 = 5;

    /// Every known model with its short name.
    const NAMES: [(u8, &str); 5] = [
        (REVO2, "revo2"),
        (ALLEGRO, "allegro"),
        (SHADOW, "shadow"),
        (GLOVE, "glove"),
        (LEAP, "leap"),
    ];

    /// The model's short name (`revo2`, `allegro`, `shadow`, `glove`, `leap`; `unknown` for
    /// [`UNKNOWN`] and any value not listed here): a hand profile's `name`, recording metadata
    /// keys (`device.allegro`) and the viewer's paths use it.
    pub fn name(model: u8) -> &'static str {
        NAMES
            .iter()
            .find(|(id, _)| *id == model)
            .map_or("unknown", |(_, name)| name)
    }

    /// The model whose short name is `name` (a hand profile's `name`), if there is one.
    pub fn from_name(name: &str) -> Option<u8> {
        NAMES.iter().find(|(_, n)| *n == name).map(|(id, _)| *id)
    }
}

/// Control modes of a [`HandCommand`].
pub mod control_mode {
    /// Position targets; `speed_limit` (if non-zero) bounds the joint speed.
    pub const POSITION: u8 = 1;
    /// Position targets reached in `duration_ms` of the joint record's `limit`.
    pub const POSITION_TIME: u8 = 2;
    /// Velocity targets.
    pub const VELOCITY: u8 = 3;
    /// Effort (motor current or torque) targets.
    pub const EFFORT: u8 = 4;
    /// Raw duty-cycle targets in [-1, 1].
    pub const DUTY: u8 = 5;
}

/// Units of joint values (`units` fields).
pub mod units {
    /// Positions as a fraction of travel (0 = open, 1 = closed), speeds in travel per second,
    /// efforts as a fraction of the maximum.
    pub const NORMALISED: u8 = 0;
    /// Radians, radians per second, amperes (or newton-metres for torque hands).
    pub const PHYSICAL: u8 = 1;
}

/// Bits of [`HandCommand::flags`].
pub mod command_flags {
    /// The command repeats the last one because the input went stale.
    pub const HELD: u8 = 1 << 0;
    /// At least one target was clamped to a joint limit.
    pub const CLAMPED: u8 = 1 << 1;
    /// At least one target was slew limited.
    pub const SLEW_LIMITED: u8 = 1 << 2;
}

/// Bits of [`GloveForceCommand::flags`].
pub mod force_flags {
    /// Forces are ramping to zero because an input is stale.
    pub const STALE: u8 = 1 << 0;
    /// The emergency stop is engaged: all forces are zero.
    pub const ESTOP: u8 = 1 << 1;
    /// At least one force was saturated at the configured maximum.
    pub const CLAMPED: u8 = 1 << 2;
}

/// Where a finger's force feedback came from (`source` of [`GloveForceCommand`]).
pub mod contact_source {
    /// No contact.
    pub const NONE: u8 = 0;
    /// Fingertip tactile normal force.
    pub const TACTILE: u8 = 1;
    /// Estimated from commanded minus measured joint position.
    pub const POSITION_ERROR: u8 = 2;
    /// Estimated from motor current.
    pub const CURRENT: u8 = 3;
    /// Ramping to zero after an input went stale.
    pub const RAMPING: u8 = 4;
    /// Held at zero by the emergency stop.
    pub const ESTOP: u8 = 5;
    /// Estimated from the joint effort (torque).
    pub const EFFORT: u8 = 6;
}

/// Link kinds (`link_kind` of [`HandState`] and [`DeviceInfo`]): how the node reaches the
/// device. They give [`HandState::bus_state`] and [`HandState::link_error_code`] their meaning.
pub mod link_kind {
    /// No link reported (a node without a bus, or not known).
    pub const NONE: u8 = 0;
    /// EtherCAT (Revo2; Shadow Hand palm).
    pub const ETHERCAT: u8 = 1;
    /// CAN (Allegro Hand).
    pub const CAN: u8 = 2;
    /// A serial line (the glove: USB serial, Bluetooth SPP or the simulator's pseudo-terminal;
    /// the LEAP Hand's Dynamixel bus through a USB adapter such as the U2D2).
    pub const SERIAL: u8 = 3;

    /// The kind's short name (`none`, `ethercat`, `can`, `serial`); `None` for a value not
    /// listed here.
    pub fn name(kind: u8) -> Option<&'static str> {
        match kind {
            NONE => Some("none"),
            ETHERCAT => Some("ethercat"),
            CAN => Some("can"),
            SERIAL => Some("serial"),
            _ => None,
        }
    }
}

/// Values of [`HandState::bus_state`]; which ones apply depends on [`HandState::link_kind`].
pub mod bus_state {
    /// Not known (and the value for [`link_kind::NONE`](super::link_kind::NONE), and while an
    /// EtherCAT link is down).
    pub const UNKNOWN: u8 = 0;
    /// EtherCAT AL state OP (the EtherCAT hands publish it while cycling).
    pub const AL_OP: u8 = 8;
    /// CAN controller error-active (normal operation).
    pub const CAN_ERROR_ACTIVE: u8 = 1;
    /// CAN controller error-passive (an error counter passed 127).
    pub const CAN_ERROR_PASSIVE: u8 = 2;
    /// CAN controller bus-off (transmit error counter passed 255): no traffic until recovery.
    pub const CAN_BUS_OFF: u8 = 3;
}

/// Fingertip sensor kinds (`Fingertip::sensor_kind`): which fields of a [`Fingertip`] it fills.
pub mod fingertip_sensor {
    /// No sensor (or an unused entry): no field is meaningful.
    pub const NONE: u8 = 0;
    /// Revo2 fingertip force sensor: normal and tangential force in newtons, direction,
    /// proximity, status and update counter; `pressure` and `temperature` are 0.
    pub const REVO2_FORCE: u8 = 1;
    /// Shadow Hand PST pressure sensor: `pressure` and `temperature` in the sensor's raw units
    /// as the palm reports them; the force fields are NaN, proximity 0.
    pub const PST_PRESSURE: u8 = 2;
}

/// Bits of [`Fingertip::status`] (the Revo2 touch-status low byte).
pub mod touch_status {
    /// The sensor's raw value is invalid.
    pub const INVALID: u8 = 1 << 0;
    /// The raw value has not been updated.
    pub const NOT_UPDATED: u8 = 1 << 1;
    /// The sensor timed out.
    pub const TIMEOUT: u8 = 1 << 2;
}

nested! {
    /// The header every payload starts with.
    SampleHeader("teleop_msgs/SampleHeader", "teleop::SampleHeader") {
        /// Per-publisher sequence number, starting at 1; gaps mean lost samples.
        seq: u64 => "uint64",
        /// CLOCK_MONOTONIC nanoseconds when this sample was made.
        stamp_ns: u64 => "uint64",
        /// `stamp_ns` of the device sample this one ultimately descends from (equal to
        /// `stamp_ns` for device samples): `stamp_ns - origin_ns` is the latency so far.
        origin_ns: u64 => "uint64",
        /// Who made it: `source_id(node name)`.
        source_id: u32 => "uint32",
        /// Zero.
        reserved: u32 => "uint32",
    }
}

nested! {
    /// One joint of a [`HandCommand`].
    JointCommand("teleop_msgs/JointCommand", "teleop::JointCommand") {
        /// Target in the command's units and mode.
        target: f32 => "float32",
        /// Speed limit (0 = none), or the motion time in ms for `POSITION_TIME`.
        speed_limit: f32 => "float32",
        /// Effort limit (0 = none).
        effort_limit: f32 => "float32",
    }
}

nested! {
    /// One joint of a [`HandState`].
    JointState("teleop_msgs/JointState", "teleop::JointState") {
        /// Measured position in the state's units.
        position: f32 => "float32",
        /// Measured speed in the state's units.
        speed: f32 => "float32",
        /// Joint effort in SI units whatever the state's `units` (N m for revolute joints),
        /// measured (Shadow Hand strain gauges) or estimated (Allegro commanded torque); NaN
        /// when the hand neither measures nor estimates it (Revo2).
        effort: f32 => "float32",
        /// Motor current in milliamperes (NaN when the hand does not report it).
        current_ma: f32 => "float32",
        /// Device-specific joint status word.
        status: u32 => "uint32",
    }
}

nested! {
    /// One fingertip of a [`Tactile`] sample. `sensor_kind` says which fields the fingertip's
    /// sensor fills (see [`fingertip_sensor`]); the others are NaN (floats) or 0 (raw values).
    Fingertip("teleop_msgs/Fingertip", "teleop::Fingertip") {
        /// Normal force in newtons.
        normal_n: f32 => "float32",
        /// Tangential force in newtons.
        tangential_n: f32 => "float32",
        /// Direction of the tangential force in degrees (0 = towards the fingertip, clockwise);
        /// meaningful only when `direction_valid` is 1.
        direction_deg: f32 => "float32",
        /// Proximity (raw sensor units, larger = closer).
        proximity: u32 => "uint32",
        /// Pressure in the raw units of the sensor (Shadow PST: the sensor's pressure reading
        /// as the palm reports it, uncalibrated; larger = more pressure).
        pressure: i32 => "int32",
        /// Temperature in the raw units of the sensor (Shadow PST: the sensor's temperature
        /// reading as the palm reports it, uncalibrated).
        temperature: i32 => "int32",
        /// Sensor status bits, see [`touch_status`].
        status: u8 => "uint8",
        /// The sensor's update counter (changes when the sensor produced new data).
        update_counter: u8 => "uint8",
        /// 1 when `direction_deg` is valid.
        direction_valid: u8 => "uint8",
        /// See [`fingertip_sensor`].
        sensor_kind: u8 => "uint8",
    }
}

message! {
    /// The glove's six positions as reported and normalised, and its measured finger forces.
    GloveState("teleop_msgs/msg/GloveState", topic "glove/state", nested [SampleHeader]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// Raw positions in [`GLOVE_CHANNELS`] order: 0 = bent (thumb rotation: innermost),
        /// 1000 = open (outermost).
        raw_position: [u16; 6] => "uint16[6]",
        /// Last measured finger forces in [`GLOVE_FINGERS`] order, glove units (-1000..1000;
        /// positive = the finger pushes towards a fist).
        force: [i16; 5] => "int16[5]",
        /// 1 while the serial link answers.
        link_up: u8 => "uint8",
        /// The glove's device id.
        glove_id: u8 => "uint8",
        /// `raw_position / 1000`, clamped to [0, 1] (same sense as `raw_position`).
        position: [f32; 6] => "float32[6]",
        /// Exchanges completed since the node started.
        exchanges: u32 => "uint32",
        /// Timeouts and bad frames since the node started.
        errors: u32 => "uint32",
    }
}

message! {
    /// Slow-rate glove diagnostics read from its registers.
    GloveDiagnostics("teleop_msgs/msg/GloveDiagnostics", topic "glove/diagnostics", nested [SampleHeader]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// Actual finger forces (register 1582), glove units.
        force: [i16; 5] => "int16[5]",
        /// Actuator currents in mA (register 1594).
        current_ma: [u16; 5] => "uint16[5]",
        /// System voltage register 1472 as read (the manual gives no unit).
        voltage_raw: u16 => "uint16",
        /// Actuator error bits (register 1606): bit0 locked rotor, bit1 over-temperature,
        /// bit2 over-current, bit3 abnormal operation, bit4 communication.
        error_bits: [u8; 5] => "uint8[5]",
        /// Actuator temperatures in degrees Celsius (register 1618).
        temperature_c: [u8; 5] => "uint8[5]",
    }
}

message! {
    /// Per-finger force the glove should apply.
    GloveForceCommand("teleop_msgs/msg/GloveForceCommand", topic "glove/force_command", nested [SampleHeader]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// Force per finger in [`GLOVE_FINGERS`] order, glove units -1000..1000; positive pushes
        /// the operator's hand open.
        force: [i16; 5] => "int16[5]",
        /// See [`force_flags`].
        flags: u8 => "uint8",
        /// Per finger, where the force came from; see [`contact_source`].
        source: [u8; 5] => "uint8[5]",
    }
}

message! {
    /// A hand-agnostic joint command.
    HandCommand("teleop_msgs/msg/HandCommand", topic "hand/command", nested [SampleHeader, JointCommand]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// The hand it is for, see [`device_model`].
        hand_model: u8 => "uint8",
        /// How many entries of `joints` are used.
        joint_count: u8 => "uint8",
        /// See [`control_mode`].
        control_mode: u8 => "uint8",
        /// See [`units`].
        units: u8 => "uint8",
        /// See [`command_flags`].
        flags: u8 => "uint8",
        /// Zero.
        reserved: [u8; 3] => "uint8[3]",
        /// Joint targets in the hand's joint order (its hand profile's `[[joint]]` order).
        joints: [JointCommand; MAX_JOINTS] => "teleop_msgs/JointCommand[24]",
    }
}

message! {
    /// Measured joint state and link status of a hand, whatever its bus.
    HandState("teleop_msgs/msg/HandState", topic "hand/state", nested [SampleHeader, JointState]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// The hand that measured it, see [`device_model`].
        hand_model: u8 => "uint8",
        /// How many entries of `joints` are used.
        joint_count: u8 => "uint8",
        /// See [`units`].
        units: u8 => "uint8",
        /// 1 when the hand is holding because its command went stale.
        holding: u8 => "uint8",
        /// 1 while the hand's link is up and cycling.
        link_up: u8 => "uint8",
        /// See [`link_kind`].
        link_kind: u8 => "uint8",
        /// The bus state, see [`bus_state`]: EtherCAT the AL state (8 OP while cycling, 0 while
        /// the link is down), CAN error-active, error-passive or bus-off.
        bus_state: u8 => "uint8",
        /// Zero.
        reserved: [u8; 5] => "uint8[5]",
        /// The link's last error code (0 = no error): EtherCAT the AL status code.
        link_error_code: u32 => "uint32",
        /// Cycles with a bad exchange since start (EtherCAT: wrong working counter; CAN: a
        /// device's frame missing from the cycle).
        link_errors: u32 => "uint32",
        /// Cycles whose frame was lost since start.
        lost_frames: u32 => "uint32",
        /// Joints in the hand's joint order.
        joints: [JointState; MAX_JOINTS] => "teleop_msgs/JointState[24]",
    }
}

message! {
    /// Fingertip tactile forces.
    Tactile("teleop_msgs/msg/Tactile", topic "hand/tactile", nested [SampleHeader, Fingertip]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// The hand that measured it, see [`device_model`].
        hand_model: u8 => "uint8",
        /// How many entries of `fingertips` are used.
        fingertip_count: u8 => "uint8",
        /// Zero.
        reserved: [u8; 2] => "uint8[2]",
        /// Fingertips in the hand's order (its hand profile's fingers with a tip sensor).
        fingertips: [Fingertip; MAX_FINGERTIPS] => "teleop_msgs/Fingertip[5]",
    }
}

/// Most named details a [`NodeHealth`] report carries.
pub const MAX_HEALTH_DETAILS: usize = 8;

nested! {
    /// One named, node-specific value of a [`NodeHealth`] report (e.g. the Allegro node's
    /// `reconnects`, the bridge's `rtt_ms`).
    HealthDetail("teleop_msgs/HealthDetail", "teleop::HealthDetail") {
        /// The value's name, `[a-z0-9_]` UTF-8, zero padded; empty for an unused entry.
        name: [u8; 24] => "uint8[24]",
        /// The value (counters count from the node's start; units are in the name: `_ms`, `_c`).
        value: f64 => "float64",
    }
}

message! {
    /// A node's periodic health report.
    NodeHealth("teleop_msgs/msg/NodeHealth", topic "health", nested [SampleHeader, HealthDetail]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// Node name, UTF-8, zero padded.
        node_name: [u8; 32] => "uint8[32]",
        /// Main loop rate over the last report period, in Hz.
        loop_rate_hz: f32 => "float32",
        /// How many entries of `input_age_ms` are used.
        input_count: u8 => "uint8",
        /// How many entries of `details` are used.
        detail_count: u8 => "uint8",
        /// Zero.
        reserved: [u8; 6] => "uint8[6]",
        /// Age of the newest sample of each input in ms, -1 if never received.
        input_age_ms: [f32; 5] => "float32[5]",
        /// Input watchdog timeouts since start.
        timeouts: u64 => "uint64",
        /// Values clamped to configured limits since start.
        clamps: u64 => "uint64",
        /// Errors since start (bad frames, failed sends, ...).
        errors: u64 => "uint64",
        /// Samples lost on inputs (sequence gaps) since start.
        dropped: u64 => "uint64",
        /// Node-specific values by name (see [`NodeHealth::details`]).
        details: [HealthDetail; MAX_HEALTH_DETAILS] => "teleop_msgs/HealthDetail[8]",
    }
}

message! {
    /// Emergency stop: while engaged, the glove applies no force.
    EStop("teleop_msgs/msg/EStop", topic "estop", nested [SampleHeader]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// 1 = engaged, 0 = released.
        engaged: u8 => "uint8",
        /// Zero.
        reserved: [u8; 7] => "uint8[7]",
    }
}

message! {
    /// A node's answer to the e-stop: published by every node that obeys it (the force feedback
    /// and the hand nodes) when it starts and after every [`EStop`] sample, with the state it
    /// now obeys (`teleop estop` lists the nodes that answered).
    EStopAck("teleop_msgs/msg/EStopAck", topic "estop/ack", nested [SampleHeader]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// 1 = the node holds the e-stop (glove forces zero, hand holding), 0 = released.
        engaged: u8 => "uint8",
        /// Zero.
        reserved: [u8; 7] => "uint8[7]",
        /// The node's name (with its namespace), UTF-8, zero padded.
        node_name: [u8; 32] => "uint8[32]",
    }
}

message! {
    /// Identity of a device, published by its node when the device connects (history keeps the
    /// last one for late subscribers such as the recorder). Each field is what its name says;
    /// what a device does not have or report is 0 or empty.
    DeviceInfo("teleop_msgs/msg/DeviceInfo", topic "device/info", nested [SampleHeader]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// See [`device_model`].
        device_model: u8 => "uint8",
        /// How the node reaches the device, see [`link_kind`].
        link_kind: u8 => "uint8",
        /// Zero.
        reserved: [u8; 6] => "uint8[6]",
        /// The device's address on its link: the glove's device id on its serial line, the
        /// Allegro's CAN device id (EtherCAT devices are addressed by position: 0).
        bus_address: u32 => "uint32",
        /// The serial number of the bus's identity record (EtherCAT: object 0x1018:04); 0 when
        /// the link has none.
        identity_serial: u32 => "uint32",
        /// Model name as the device or its protocol names it, UTF-8, zero padded.
        model_name: [u8; 32] => "uint8[32]",
        /// Serial number as the device reports it (Revo2: its control board's), UTF-8, zero
        /// padded.
        serial_number: [u8; 32] => "uint8[32]",
        /// Firmware version (Revo2: its control board's), UTF-8, zero padded.
        firmware_version: [u8; 32] => "uint8[32]",
        /// Hardware revision (Shadow Hand: the palm's EtherCAT revision number), UTF-8, zero
        /// padded.
        hardware_revision: [u8; 32] => "uint8[32]",
        /// The protocol generation the node speaks with it (Allegro Hand: `v1` .. `v4`), UTF-8,
        /// zero padded.
        protocol: [u8; 32] => "uint8[32]",
        /// Serial number of a second board with its own firmware (Revo2: the wrist board),
        /// UTF-8, zero padded.
        second_board_serial: [u8; 32] => "uint8[32]",
        /// Firmware version of that second board, UTF-8, zero padded.
        second_board_firmware: [u8; 32] => "uint8[32]",
        /// The link the node opened, as configured (a serial port, a CAN link spec such as
        /// `slcan:/dev/ttyACM0`, an EtherCAT interface or socket), UTF-8, zero padded.
        link: [u8; 64] => "uint8[64]",
    }
}

/// What an [`Episode`] sample asks of the recorder.
pub mod episode_event {
    /// Begin an episode (its task in [`Episode::task`](super::Episode)); an episode still open
    /// is first closed, unlabelled.
    pub const START: u8 = 1;
    /// End the open episode with [`Episode::outcome`](super::Episode).
    pub const STOP: u8 = 2;
    /// Throw away the open episode, or the last one closed when none is open.
    pub const DISCARD: u8 = 3;
}

/// How an episode ended ([`Episode::outcome`]).
pub mod episode_outcome {
    /// Not said.
    pub const UNLABELLED: u8 = 0;
    /// The task was done.
    pub const SUCCESS: u8 = 1;
    /// The task was not done.
    pub const FAILURE: u8 = 2;

    /// The outcome's name (`unlabelled`, `success`, `failure`; `unlabelled` for any other
    /// value): the recorder's episode records and the dataset export use it.
    pub fn name(outcome: u8) -> &'static str {
        match outcome {
            SUCCESS => "success",
            FAILURE => "failure",
            _ => "unlabelled",
        }
    }
}

/// Bytes of an episode's task text.
pub const EPISODE_TASK_BYTES: usize = 120;

message! {
    /// An operator's episode mark (`teleop episode`, the console): start an episode of a
    /// task, stop it with its outcome, or discard it. The recorder records it where it
    /// happens in the stream and closes an episode with its health; the dataset export cuts
    /// the recording into episodes by these marks. Always on the topics without a namespace:
    /// one operator's episode covers every side.
    Episode("teleop_msgs/msg/Episode", topic "episode", nested [SampleHeader]) {
        /// Common header.
        header: SampleHeader => "teleop_msgs/SampleHeader",
        /// See [`episode_event`].
        event: u8 => "uint8",
        /// See [`episode_outcome`] (with [`episode_event::STOP`]).
        outcome: u8 => "uint8",
        /// Zero.
        reserved: [u8; 6] => "uint8[6]",
        /// The task, in words (with [`episode_event::START`]), UTF-8, zero padded.
        task: [u8; EPISODE_TASK_BYTES] => "uint8[120]",
    }
}

/// Text into a zero-padded fixed field of any length (cut at a character boundary).
pub fn fixed_text<const N: usize>(text: &str) -> [u8; N] {
    let mut out = [0u8; N];
    let mut end = text.len().min(N);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    out[..end].copy_from_slice(&text.as_bytes()[..end]);
    out
}

/// A zero-padded fixed field as text (invalid UTF-8 replaced).
pub fn text_of(field: &[u8]) -> String {
    let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    String::from_utf8_lossy(&field[..end]).into_owned()
}

topics!(
    GloveState,
    GloveDiagnostics,
    GloveForceCommand,
    HandCommand,
    HandState,
    Tactile,
    NodeHealth,
    EStop,
    DeviceInfo,
    EStopAck,
    Episode,
);

impl Episode {
    /// The task text (invalid UTF-8 replaced).
    pub fn task(&self) -> String {
        text_of(&self.task)
    }
}

impl NodeHealth {
    /// Stores `name` (truncated to 32 bytes at a character boundary).
    pub fn set_name(&mut self, name: &str) {
        self.node_name = fixed_text(name);
    }

    /// The node name (invalid UTF-8 is replaced).
    pub fn name(&self) -> String {
        text_of(&self.node_name)
    }

    /// Sets the detail called `name` (truncated to 24 bytes), adding it when it is new; false
    /// when all [`MAX_HEALTH_DETAILS`] entries hold other names (nothing is stored).
    pub fn set_detail(&mut self, name: &str, value: f64) -> bool {
        let key: [u8; 24] = fixed_text(name);
        let used = usize::from(self.detail_count).min(MAX_HEALTH_DETAILS);
        if let Some(d) = self.details[..used].iter_mut().find(|d| d.name == key) {
            d.value = value;
            return true;
        }
        let Some(free) = self.details.get_mut(used) else {
            return false;
        };
        *free = HealthDetail { name: key, value };
        self.detail_count = (used + 1) as u8;
        true
    }

    /// The used details as (name, value), in the order they were first set.
    pub fn details(&self) -> impl Iterator<Item = (String, f64)> + '_ {
        self.details[..usize::from(self.detail_count).min(MAX_HEALTH_DETAILS)]
            .iter()
            .map(|d| (text_of(&d.name), d.value))
    }

    /// The value of the detail called `name`, if the report has it. Allocates nothing (a
    /// control loop reads the bridge's report with it).
    pub fn detail(&self, name: &str) -> Option<f64> {
        let key: [u8; 24] = fixed_text(name);
        self.details[..usize::from(self.detail_count).min(MAX_HEALTH_DETAILS)]
            .iter()
            .find(|d| d.name == key)
            .map(|d| d.value)
    }

    /// The node name's bytes, without the zero padding. Allocates nothing.
    pub fn name_bytes(&self) -> &[u8] {
        let end = self
            .node_name
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(self.node_name.len());
        &self.node_name[..end]
    }
}

impl DeviceInfo {
    /// The identity by field name, as text, without what the device does not have (empty
    /// texts; the bus address only on links that address devices, CAN and serial; the
    /// identity serial only when there is one): what the recorder writes as metadata and the
    /// viewer shows.
    pub fn named_fields(&self) -> Vec<(&'static str, String)> {
        let link_kind = match link_kind::name(self.link_kind) {
            Some("none") | None => "",
            Some(name) => name,
        };
        let mut fields = vec![
            (
                "device_model",
                device_model::name(self.device_model).to_string(),
            ),
            ("link_kind", link_kind.to_string()),
        ];
        if matches!(self.link_kind, link_kind::CAN | link_kind::SERIAL) {
            fields.push(("bus_address", self.bus_address.to_string()));
        }
        if self.identity_serial != 0 {
            fields.push(("identity_serial", self.identity_serial.to_string()));
        }
        for (name, text) in [
            ("model_name", &self.model_name[..]),
            ("serial_number", &self.serial_number),
            ("firmware_version", &self.firmware_version),
            ("hardware_revision", &self.hardware_revision),
            ("protocol", &self.protocol),
            ("second_board_serial", &self.second_board_serial),
            ("second_board_firmware", &self.second_board_firmware),
            ("link", &self.link),
        ] {
            fields.push((name, text_of(text)));
        }
        fields.retain(|(_, value)| !value.is_empty());
        fields
    }
}

impl HandCommand {
    /// The used joints.
    pub fn active_joints(&self) -> &[JointCommand] {
        &self.joints[..usize::from(self.joint_count).min(MAX_JOINTS)]
    }
}

impl HandState {
    /// The used joints.
    pub fn active_joints(&self) -> &[JointState] {
        &self.joints[..usize::from(self.joint_count).min(MAX_JOINTS)]
    }
}

impl Tactile {
    /// The used fingertips.
    pub fn active_fingertips(&self) -> &[Fingertip] {
        &self.fingertips[..usize::from(self.fingertip_count).min(MAX_FINGERTIPS)]
    }
}

impl Fingertip {
    /// True when the sensor reports its values as usable (no invalid/timeout bit).
    pub fn is_valid(&self) -> bool {
        self.status & (touch_status::INVALID | touch_status::TIMEOUT) == 0
    }
}
