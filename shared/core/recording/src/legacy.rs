//! Recordings of earlier contract versions, converted on read.
//!
//! A recording stores each topic's schema text, which fixes the layout of its messages. When a
//! contract version changes a payload's layout, the schema text of the earlier version is
//! frozen here with that layout (as explicit byte offsets), and the reader converts each
//! recorded message into the current payload. Payloads whose schema text did not change need
//! nothing: their bytes are the same in both versions.
//!
//! Contract version 1 (recordings made before version 2, e.g. `recordings/grasp.sample.mcap`)
//! differs in two payloads:
//! - `HandState`: EtherCAT fields `al_state`, `al_status_code`, `wkc_errors` become the link
//!   fields (link kind EtherCAT, bus state = AL state, link error code = AL status code, link
//!   errors = wrong working counters); joints gain `effort`, unknown in version 1 (NaN).
//! - `Tactile`: every used fingertip was a Revo2 force sensor (sensor kind Revo2 force, no
//!   pressure or temperature: 0).
//!
//! Contract version 3 changes two more, whose layout versions 1 and 2 share (so recordings of
//! either convert the same way; they are reported as version 2):
//! - `DeviceInfo`: the device `kind` of its own numbering (1 glove, 2 Revo2, 3 Allegro, 4
//!   Shadow) becomes the one `device_model` numbering, and the slots `id`, `model`,
//!   `firmware_a/b`, `serial_a/b` become the fields they held for that device (see
//!   [`device_info_from_v2`]); the link kind follows from the device.
//! - `NodeHealth`: the seven anonymous `detail` bytes become named details, named as the node
//!   that published them filled them (by the node's name without its namespace: `feedback`,
//!   `bridge`, `allegro`; see [`V2_DETAIL_NAMES`]); a non-zero byte of any other node is kept
//!   as `detail_<index>`.

use crate::file::normalised;
use teleop_msgs::{
    device_model, fingertip_sensor, link_kind, DeviceInfo, Fingertip, HandState, JointState,
    Message, NodeHealth, SampleHeader, Tactile, MAX_FINGERTIPS, MAX_JOINTS,
};

/// Schema text of `teleop_msgs/msg/HandState` in contract version 1 (frozen).
pub const HAND_STATE_V1_SCHEMA: &str = "teleop_msgs/SampleHeader header
uint8 hand_model
uint8 joint_count
uint8 link_up
uint8 al_state
uint8 units
uint8 holding
uint16 al_status_code
uint32 wkc_errors
uint32 lost_frames
teleop_msgs/JointState[24] joints
================================================================================
MSG: teleop_msgs/SampleHeader
uint64 seq
uint64 stamp_ns
uint64 origin_ns
uint32 source_id
uint32 reserved
================================================================================
MSG: teleop_msgs/JointState
float32 position
float32 speed
float32 current_ma
uint32 status
";

/// Schema text of `teleop_msgs/msg/Tactile` in contract version 1 (frozen).
pub const TACTILE_V1_SCHEMA: &str = "teleop_msgs/SampleHeader header
uint8 hand_model
uint8 fingertip_count
uint8[2] reserved
teleop_msgs/Fingertip[5] fingertips
================================================================================
MSG: teleop_msgs/SampleHeader
uint64 seq
uint64 stamp_ns
uint64 origin_ns
uint32 source_id
uint32 reserved
================================================================================
MSG: teleop_msgs/Fingertip
float32 normal_n
float32 tangential_n
float32 direction_deg
uint32 proximity
uint8 status
uint8 update_counter
uint8 direction_valid
uint8 reserved
";

/// Schema text of `teleop_msgs/msg/DeviceInfo` in contract versions 1 and 2 (frozen).
pub const DEVICE_INFO_V2_SCHEMA: &str = "teleop_msgs/SampleHeader header
uint8 kind
uint8[3] reserved
uint32 id
uint8[32] model
uint8[32] firmware_a
uint8[32] firmware_b
uint8[32] serial_a
uint8[32] serial_b
================================================================================
MSG: teleop_msgs/SampleHeader
uint64 seq
uint64 stamp_ns
uint64 origin_ns
uint32 source_id
uint32 reserved
";

/// Schema text of `teleop_msgs/msg/NodeHealth` in contract versions 1 and 2 (frozen).
pub const NODE_HEALTH_V2_SCHEMA: &str = "teleop_msgs/SampleHeader header
uint8[32] node_name
float32 loop_rate_hz
uint8 input_count
uint8[7] detail
float32[5] input_age_ms
uint64 timeouts
uint64 clamps
uint64 errors
uint64 dropped
================================================================================
MSG: teleop_msgs/SampleHeader
uint64 seq
uint64 stamp_ns
uint64 origin_ns
uint32 source_id
uint32 reserved
";

/// The names version 3 gives the `detail` bytes of version 2, per node (its name without the
/// namespace) as that node filled them: the force feedback's contact source per glove finger,
/// the bridge's link state and its round-trip time and one-way latency p99 (each a
/// little-endian `u16` of 10 us units, over two bytes), the Allegro node's protocol generation,
/// bus state, frame counters (saturated at 255), hottest motor and late periods.
pub const V2_DETAIL_NAMES: [(&str, &[&str]); 3] = [
    (
        "feedback",
        &[
            "source_little",
            "source_ring",
            "source_middle",
            "source_index",
            "source_thumb",
        ],
    ),
    ("bridge", &["link_state", "rtt_ms", "latency_p99_ms"]),
    (
        "allegro",
        &[
            "protocol_generation",
            "bus_state",
            "unknown_frames",
            "bad_frames",
            "reconnects",
            "max_temperature_c",
            "late_periods",
        ],
    ),
];

/// Version 1 `HandState`: its size and byte offsets (CDR = `repr(C)`, no padding).
mod hand_state_v1 {
    pub const SIZE: usize = 432;
    pub const HAND_MODEL: usize = 32;
    pub const JOINT_COUNT: usize = 33;
    pub const LINK_UP: usize = 34;
    pub const AL_STATE: usize = 35;
    pub const UNITS: usize = 36;
    pub const HOLDING: usize = 37;
    pub const AL_STATUS_CODE: usize = 38;
    pub const WKC_ERRORS: usize = 40;
    pub const LOST_FRAMES: usize = 44;
    pub const JOINTS: usize = 48;
    /// One `JointState`: position, speed, current_ma (f32), status (u32).
    pub const JOINT_SIZE: usize = 16;
}

/// Version 1 `Tactile`: its size and byte offsets.
mod tactile_v1 {
    pub const SIZE: usize = 136;
    pub const HAND_MODEL: usize = 32;
    pub const FINGERTIP_COUNT: usize = 33;
    pub const RESERVED: usize = 34;
    pub const FINGERTIPS: usize = 36;
    /// One `Fingertip`: normal_n, tangential_n, direction_deg (f32), proximity (u32), status,
    /// update_counter, direction_valid, reserved (u8).
    pub const FINGERTIP_SIZE: usize = 20;
}

/// Version 2 (and 1) `DeviceInfo`: its size and byte offsets.
mod device_info_v2 {
    pub const SIZE: usize = 200;
    pub const KIND: usize = 32;
    pub const ID: usize = 36;
    pub const MODEL: usize = 40;
    pub const FIRMWARE_A: usize = 72;
    pub const FIRMWARE_B: usize = 104;
    pub const SERIAL_A: usize = 136;
    pub const SERIAL_B: usize = 168;
    /// The device kinds of version 2's own numbering.
    pub const GLOVE: u8 = 1;
    pub const REVO2: u8 = 2;
    pub const ALLEGRO: u8 = 3;
    pub const SHADOW: u8 = 4;
}

/// Version 2 (and 1) `NodeHealth`: its size and byte offsets.
mod node_health_v2 {
    pub const SIZE: usize = 128;
    pub const NODE_NAME: usize = 32;
    pub const LOOP_RATE_HZ: usize = 64;
    pub const INPUT_COUNT: usize = 68;
    pub const DETAIL: usize = 69;
    pub const DETAIL_LEN: usize = 7;
    pub const INPUT_AGE_MS: usize = 76;
    pub const TIMEOUTS: usize = 96;
    pub const CLAMPS: usize = 104;
    pub const ERRORS: usize = 112;
    pub const DROPPED: usize = 120;
}

/// A recorded payload layout of an earlier contract version that this build converts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Legacy {
    /// `HandState` of contract version 1.
    HandStateV1,
    /// `Tactile` of contract version 1.
    TactileV1,
    /// `DeviceInfo` of contract versions 1 and 2.
    DeviceInfoV2,
    /// `NodeHealth` of contract versions 1 and 2.
    NodeHealthV2,
}

impl Legacy {
    const ALL: [Self; 4] = [
        Self::HandStateV1,
        Self::TactileV1,
        Self::DeviceInfoV2,
        Self::NodeHealthV2,
    ];

    /// The earlier layout of the contract type `schema_name` whose (normalised) schema text is
    /// `text`, if any.
    pub(crate) fn recognise(schema_name: &str, text: &[&str]) -> Option<Self> {
        Self::ALL.into_iter().find(|legacy| {
            legacy.schema_name() == schema_name && normalised(legacy.schema()) == text
        })
    }

    fn schema_name(self) -> &'static str {
        match self {
            Self::HandStateV1 => HandState::SCHEMA_NAME,
            Self::TactileV1 => Tactile::SCHEMA_NAME,
            Self::DeviceInfoV2 => DeviceInfo::SCHEMA_NAME,
            Self::NodeHealthV2 => NodeHealth::SCHEMA_NAME,
        }
    }

    fn schema(self) -> &'static str {
        match self {
            Self::HandStateV1 => HAND_STATE_V1_SCHEMA,
            Self::TactileV1 => TACTILE_V1_SCHEMA,
            Self::DeviceInfoV2 => DEVICE_INFO_V2_SCHEMA,
            Self::NodeHealthV2 => NODE_HEALTH_V2_SCHEMA,
        }
    }

    /// The (last) contract version of this layout.
    pub(crate) fn version(self) -> u32 {
        match self {
            Self::HandStateV1 | Self::TactileV1 => 1,
            Self::DeviceInfoV2 | Self::NodeHealthV2 => 2,
        }
    }

    /// Payload size in this layout.
    pub(crate) fn size(self) -> usize {
        match self {
            Self::HandStateV1 => hand_state_v1::SIZE,
            Self::TactileV1 => tactile_v1::SIZE,
            Self::DeviceInfoV2 => device_info_v2::SIZE,
            Self::NodeHealthV2 => node_health_v2::SIZE,
        }
    }

    /// The current payload's bytes for `bytes` in this layout (the caller checks the size;
    /// missing bytes would read as zero).
    pub(crate) fn convert(self, bytes: &[u8]) -> Vec<u8> {
        match self {
            Self::HandStateV1 => hand_state_from_v1(bytes).as_bytes().to_vec(),
            Self::TactileV1 => tactile_from_v1(bytes).as_bytes().to_vec(),
            Self::DeviceInfoV2 => device_info_from_v2(bytes).as_bytes().to_vec(),
            Self::NodeHealthV2 => node_health_from_v2(bytes).as_bytes().to_vec(),
        }
    }
}

/// `W` bytes at `at` (zeros past the end: the caller has checked the size).
fn bytes_at<const W: usize>(bytes: &[u8], at: usize) -> [u8; W] {
    let mut out = [0u8; W];
    if let Some(src) = bytes.get(at..at + W) {
        out.copy_from_slice(src);
    }
    out
}

fn u8_at(bytes: &[u8], at: usize) -> u8 {
    bytes.get(at).copied().unwrap_or(0)
}

fn u16_at(bytes: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(bytes_at(bytes, at))
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes_at(bytes, at))
}

fn u64_at(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes_at(bytes, at))
}

fn f32_at(bytes: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(bytes_at(bytes, at))
}

/// The header, unchanged since version 1.
fn header_at(bytes: &[u8]) -> SampleHeader {
    SampleHeader {
        seq: u64_at(bytes, 0),
        stamp_ns: u64_at(bytes, 8),
        origin_ns: u64_at(bytes, 16),
        source_id: u32_at(bytes, 24),
        reserved: u32_at(bytes, 28),
    }
}

fn hand_state_from_v1(b: &[u8]) -> HandState {
    use hand_state_v1 as v1;
    let mut state = HandState {
        header: header_at(b),
        hand_model: u8_at(b, v1::HAND_MODEL),
        joint_count: u8_at(b, v1::JOINT_COUNT),
        units: u8_at(b, v1::UNITS),
        holding: u8_at(b, v1::HOLDING),
        link_up: u8_at(b, v1::LINK_UP),
        link_kind: link_kind::ETHERCAT,
        bus_state: u8_at(b, v1::AL_STATE),
        reserved: [0; 5],
        link_error_code: u32::from(u16_at(b, v1::AL_STATUS_CODE)),
        link_errors: u32_at(b, v1::WKC_ERRORS),
        lost_frames: u32_at(b, v1::LOST_FRAMES),
        joints: [JointState::default(); MAX_JOINTS],
    };
    for (i, joint) in state.joints.iter_mut().enumerate() {
        let at = v1::JOINTS + i * v1::JOINT_SIZE;
        *joint = JointState {
            position: f32_at(b, at),
            speed: f32_at(b, at + 4),
            // Version 1 had no effort: unknown.
            effort: f32::NAN,
            current_ma: f32_at(b, at + 8),
            status: u32_at(b, at + 12),
        };
    }
    state
}

fn tactile_from_v1(b: &[u8]) -> Tactile {
    use tactile_v1 as v1;
    let fingertip_count = u8_at(b, v1::FINGERTIP_COUNT);
    let mut tactile = Tactile {
        header: header_at(b),
        hand_model: u8_at(b, v1::HAND_MODEL),
        fingertip_count,
        reserved: bytes_at(b, v1::RESERVED),
        fingertips: [Fingertip::default(); MAX_FINGERTIPS],
    };
    for (i, tip) in tactile.fingertips.iter_mut().enumerate() {
        let at = v1::FINGERTIPS + i * v1::FINGERTIP_SIZE;
        // Every fingertip of version 1 was a Revo2 force sensor; unused entries have none.
        let sensor_kind = if i < usize::from(fingertip_count) {
            fingertip_sensor::REVO2_FORCE
        } else {
            fingertip_sensor::NONE
        };
        *tip = Fingertip {
            normal_n: f32_at(b, at),
            tangential_n: f32_at(b, at + 4),
            direction_deg: f32_at(b, at + 8),
            proximity: u32_at(b, at + 12),
            pressure: 0,
            temperature: 0,
            status: u8_at(b, at + 16),
            update_counter: u8_at(b, at + 17),
            direction_valid: u8_at(b, at + 18),
            sensor_kind,
        };
    }
    tactile
}

/// A version 2 `DeviceInfo` in version 3: what each device put in each slot, named.
///
/// | v2 kind | `id` | `firmware_a` | `firmware_b` | `serial_a` | `serial_b` |
/// |---|---|---|---|---|---|
/// | 1 glove | bus address | - | - | - | - |
/// | 2 Revo2 | identity serial | firmware version | second board firmware | serial number | second board serial |
/// | 3 Allegro | bus address | firmware version | protocol (`protocol v4`: `v4`) | serial number | link |
/// | 4 Shadow | identity serial | hardware revision (`palm revision 1`: `1`) | - | serial number | - |
///
/// `model` is the model name for every device. A kind version 2 did not number becomes
/// [`device_model::UNKNOWN`] with its slots kept as for the Revo2, `id` as the bus address.
pub fn device_info_from_v2(b: &[u8]) -> DeviceInfo {
    use device_info_v2 as v2;
    let text = |at: usize| -> [u8; 32] { bytes_at(b, at) };
    let id = u32_at(b, v2::ID);
    let mut info = DeviceInfo {
        header: header_at(b),
        model_name: text(v2::MODEL),
        ..Default::default()
    };
    match u8_at(b, v2::KIND) {
        v2::GLOVE => {
            info.device_model = device_model::GLOVE;
            info.link_kind = link_kind::SERIAL;
            info.bus_address = id;
        }
        v2::ALLEGRO => {
            info.device_model = device_model::ALLEGRO;
            info.link_kind = link_kind::CAN;
            info.bus_address = id;
            info.firmware_version = text(v2::FIRMWARE_A);
            info.protocol = without_prefix(text(v2::FIRMWARE_B), "protocol ");
            info.serial_number = text(v2::SERIAL_A);
            info.link[..32].copy_from_slice(&text(v2::SERIAL_B));
        }
        v2::SHADOW => {
            info.device_model = device_model::SHADOW;
            info.link_kind = link_kind::ETHERCAT;
            info.identity_serial = id;
            info.hardware_revision = without_prefix(text(v2::FIRMWARE_A), "palm revision ");
            info.serial_number = text(v2::SERIAL_A);
        }
        kind => {
            if kind == v2::REVO2 {
                info.device_model = device_model::REVO2;
                info.link_kind = link_kind::ETHERCAT;
                info.identity_serial = id;
            } else {
                info.bus_address = id;
            }
            info.firmware_version = text(v2::FIRMWARE_A);
            info.second_board_firmware = text(v2::FIRMWARE_B);
            info.serial_number = text(v2::SERIAL_A);
            info.second_board_serial = text(v2::SERIAL_B);
        }
    }
    info
}

/// A zero-padded text field without `prefix` (unchanged when it does not start with it).
fn without_prefix(field: [u8; 32], prefix: &str) -> [u8; 32] {
    let Some(rest) = field.strip_prefix(prefix.as_bytes()) else {
        return field;
    };
    let mut out = [0u8; 32];
    out[..rest.len()].copy_from_slice(rest);
    out
}

/// A version 2 `NodeHealth` in version 3: the counters as they were, the detail bytes named
/// (see [`V2_DETAIL_NAMES`]).
pub fn node_health_from_v2(b: &[u8]) -> NodeHealth {
    use node_health_v2 as v2;
    let mut health = NodeHealth {
        header: header_at(b),
        node_name: bytes_at(b, v2::NODE_NAME),
        loop_rate_hz: f32_at(b, v2::LOOP_RATE_HZ),
        input_count: u8_at(b, v2::INPUT_COUNT),
        timeouts: u64_at(b, v2::TIMEOUTS),
        clamps: u64_at(b, v2::CLAMPS),
        errors: u64_at(b, v2::ERRORS),
        dropped: u64_at(b, v2::DROPPED),
        ..Default::default()
    };
    for (i, age) in health.input_age_ms.iter_mut().enumerate() {
        *age = f32_at(b, v2::INPUT_AGE_MS + 4 * i);
    }
    let detail: [u8; v2::DETAIL_LEN] = bytes_at(b, v2::DETAIL);
    let name = health.name();
    let node = name.rsplit('/').next().unwrap_or("");
    let values: Vec<f64> = if node == "bridge" {
        let ms = |at: usize| f64::from(u16::from_le_bytes([detail[at], detail[at + 1]])) / 100.0;
        vec![f64::from(detail[0]), ms(1), ms(3)]
    } else {
        detail.iter().copied().map(f64::from).collect()
    };
    match V2_DETAIL_NAMES.iter().find(|(n, _)| *n == node) {
        Some((_, names)) => {
            for (name, value) in names.iter().zip(values) {
                health.set_detail(name, value);
            }
        }
        None => {
            for (i, value) in values.into_iter().enumerate().filter(|(_, v)| *v != 0.0) {
                health.set_detail(&format!("detail_{i}"), value);
            }
        }
    }
    health
}
