//! The Allegro Hand's firmware as seen on the CAN bus, per protocol generation: frames in and
//! time in, frames out and motor torques. Pure: no I/O, no clock of its own (time is the
//! simulation's, a [`Duration`] since power-on).
//!
//! Document protocol (generations v1-v3; the device document and docs/devices/allegro.md):
//! - `SET_PERIOD` sets the stream period (u8 ms; 0 stops the stream); `SET_MODE_JOINT` /
//!   `SET_MODE_TASK` are accepted and remembered (they change nothing here);
//! - `SYSTEM_ON` starts the stream: the four position frames (`0x0F`, src 3..6, dest
//!   `ID_DEVICE_MAIN`) every period on the hand's own clock; `SYSTEM_OFF` stops it and zeroes
//!   the torques; torque frames are applied only while the system is on;
//! - `QUERY_STATE_DATA` is answered as the document's command table says: one
//!   `ID_CMD_QUERY_STATE_DATA` (0x0E) frame from each finger (`ID_DEVICE_SUB_01..04`) to
//!   `ID_DEVICE_MAIN`, not with the stream's 0x0F frames. Its payload is not documented
//!   (docs/devices/allegro.md, "Open"): [`FirmwareOptions::state_answer`] chooses the four raw
//!   counts laid out as a position frame, or none;
//! - `QUERY_ID` (R1/L, not in the document) is answered with revision, firmware and hardware
//!   type;
//! - torque frames (`0x06`..`0x09`, i16 big-endian PWM) are read in the generation's joint
//!   order (v1: j0 first; v2, v3: j3 first), clamped to the hand's PWM limit, and turned into
//!   torque as `pwm / pwm_per_nm x motor_dir`;
//! - positions are reported through the hand's own encoder offsets and directions
//!   ([`JointCalibration`]), so the driver's calibration is what recovers radians.
//!
//! v4 protocol: `SYSTEM_ON` / `SYSTEM_OFF`; `SET_PERIOD` with position, IMU and temperature periods
//! (0 stops that stream); the position stream needs `SYSTEM_ON` unless
//! [`FirmwareOptions::v4_stream_on_period`] (unknown on real hands: docs/devices/allegro.md,
//! "Open"); remote frames for `HAND_INFO` and `SERIAL` are answered whether streaming or not;
//! torque frames are four i16 little-endian PWM values j0..j3; temperatures are streamed as four u8
//! deg C per finger (W2's layout). Frames for another device id are ignored.
//!
//! Both: unknown ids are ignored (and counted), as firmware does; with
//! [`FirmwareOptions::torque_timeout`] a finger whose torque frames stop for that long gets
//! zero torque (unknown on real hands: an option, off by default); above
//! [`OVERHEAT_C`] the motors are switched off until they cool below [`COOLED_C`] (v4 reports
//! it in the status byte).

use std::time::Duration;

use teleop_allegro_protocol::{
    doc, pwm_to_torque, rad_to_v4_raw, v4, Generation, JointCalibration, Protocol, TorqueOrder,
};
use teleop_can_link::CanFrame;

use crate::hand::{Hand, FINGERS, JOINTS, JOINTS_PER_FINGER};

/// Motor temperature above which the firmware switches the motors off, deg C (a plausible
/// value; no published threshold).
pub const OVERHEAT_C: f64 = 80.0;
/// Temperature below which an overheated hand takes torque again, deg C.
pub const COOLED_C: f64 = 70.0;
/// Stream period before any `SET_PERIOD` (the value every driver sets).
pub const DEFAULT_PERIOD: Duration = Duration::from_millis(3);

/// v4 status byte bits (W2; fairo agrees on these two).
pub mod status {
    /// Servo on (after `SYSTEM_ON`).
    pub const SERVO_ON: u8 = 0x01;
    /// High-temperature fault.
    pub const HIGH_TEMPERATURE: u8 = 0x02;
}

/// The payload of the document protocol's answer to `QUERY_STATE_DATA` (not documented).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StateAnswer {
    /// The finger's four raw counts, u16 little-endian, as its position frame has them.
    #[default]
    Positions,
    /// No payload (DLC 0).
    Empty,
}

impl std::str::FromStr for StateAnswer {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "positions" => Ok(Self::Positions),
            "empty" => Ok(Self::Empty),
            other => Err(format!(
                "state answer `{other}`: `positions` (as a position frame) or `empty`"
            )),
        }
    }
}

/// What the firmware is built with.
#[derive(Debug, Clone, PartialEq)]
pub struct FirmwareOptions {
    /// Protocol generation.
    pub generation: Generation,
    /// v4 device id (0..3).
    pub device_id: u8,
    /// v4 serial number, 8 ASCII bytes.
    pub serial: [u8; 8],
    /// PWM counts per N m.
    pub pwm_per_nm: f64,
    /// Largest PWM the firmware applies (larger values are clamped).
    pub pwm_limit: i16,
    /// Per joint: the encoder offset and direction the document protocol reports through, and
    /// the motor direction torque frames are applied with.
    pub calibration: [JointCalibration; JOINTS],
    /// Zero a finger's torque when its torque frames stop for this long (None: hold forever).
    pub torque_timeout: Option<Duration>,
    /// v4: stream positions on a non-zero period alone (else only after `SYSTEM_ON`).
    pub v4_stream_on_period: bool,
    /// Firmware version reported (QUERY_ID, v4 INFO).
    pub firmware_version: u16,
    /// v4 hand type: 0 right, 1 left.
    pub hand_type: u8,
    /// Document protocol: the payload of the 0x0E answer to `QUERY_STATE_DATA`.
    pub state_answer: StateAnswer,
}

impl FirmwareOptions {
    /// A right hand of `generation` with its default PWM scale and limit, no encoder offsets.
    pub fn new(generation: Generation) -> Self {
        Self {
            generation,
            device_id: 0,
            serial: *b"00AR0042",
            pwm_per_nm: generation.default_pwm_per_nm(),
            pwm_limit: generation.default_pwm_limit(),
            calibration: [JointCalibration {
                offset: 0,
                encoder_dir: 1,
                motor_dir: 1,
            }; JOINTS],
            torque_timeout: None,
            v4_stream_on_period: false,
            firmware_version: 0x0102,
            hand_type: 0,
            state_answer: StateAnswer::default(),
        }
    }

    /// The v4 hardware version: high byte 4 for a 12 V hand (1200 PWM per N m), else 3 (R4
    /// reads the scale from it).
    pub fn hw_version(&self) -> u16 {
        if self.pwm_per_nm >= 1000.0 {
            0x0401
        } else {
            0x0301
        }
    }
}

/// Counters of what the firmware saw and did.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counters {
    /// Frames received and understood.
    pub frames_in: u64,
    /// Frames sent.
    pub frames_out: u64,
    /// Frames ignored: unknown ids, other devices, bad lengths.
    pub ignored: u64,
    /// Torque frames applied.
    pub torque_frames: u64,
    /// Torque frames ignored because the system was off or the motors overheated.
    pub torque_refused: u64,
    /// Times a finger's torque was zeroed by the torque timeout.
    pub torque_timeouts: u64,
}

/// What the firmware is doing, for the control socket and tests.
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    /// Protocol generation.
    pub generation: Generation,
    /// After `SYSTEM_ON` (servo on).
    pub system_on: bool,
    /// Position frames are going out.
    pub streaming: bool,
    /// Position period (None: no period, stream stopped).
    pub period: Option<Duration>,
    /// v4 temperature period.
    pub temperature_period: Option<Duration>,
    /// The stream held back on purpose (fault).
    pub stream_stopped: bool,
    /// Motors off for heat.
    pub overheated: bool,
    /// PWM applied per joint.
    pub pwm: [i16; JOINTS],
    /// Motor torque per joint, N m.
    pub torque: [f64; JOINTS],
    /// Joint positions, rad.
    pub position: [f64; JOINTS],
    /// Joint velocities, rad/s.
    pub velocity: [f64; JOINTS],
    /// Motor temperatures, deg C.
    pub temperature: [f64; JOINTS],
    /// The object's push per finger, N.
    pub contact: [f64; FINGERS],
    /// Counters.
    pub counters: Counters,
    /// Document protocol mode last set (`joint` / `task`), if any.
    pub mode: Option<&'static str>,
}

/// The firmware with its hand.
#[derive(Debug, Clone)]
pub struct Firmware {
    options: FirmwareOptions,
    hand: Hand,
    now: Duration,
    system_on: bool,
    period: Option<Duration>,
    imu_period: Option<Duration>,
    temperature_period: Option<Duration>,
    next_position: Option<Duration>,
    next_imu: Option<Duration>,
    next_temperature: Option<Duration>,
    stream_stopped: bool,
    overheated: bool,
    pwm: [i16; JOINTS],
    last_torque: [Option<Duration>; FINGERS],
    mode: Option<&'static str>,
    counters: Counters,
}

fn ms(v: u16) -> Option<Duration> {
    (v > 0).then(|| Duration::from_millis(u64::from(v)))
}

impl Firmware {
    /// A powered-on hand: system off, no stream, period [`DEFAULT_PERIOD`] (document
    /// protocol) or none (v4).
    pub fn new(options: FirmwareOptions, hand: Hand) -> Self {
        let period = match options.generation.protocol() {
            Protocol::Doc => Some(DEFAULT_PERIOD),
            Protocol::V4 => None,
        };
        Self {
            options,
            hand,
            now: Duration::ZERO,
            system_on: false,
            period,
            imu_period: None,
            temperature_period: None,
            next_position: None,
            next_imu: None,
            next_temperature: None,
            stream_stopped: false,
            overheated: false,
            pwm: [0; JOINTS],
            last_torque: [None; FINGERS],
            mode: None,
            counters: Counters::default(),
        }
    }

    /// The options.
    pub fn options(&self) -> &FirmwareOptions {
        &self.options
    }

    /// The hand.
    pub fn hand(&self) -> &Hand {
        &self.hand
    }

    /// The hand, to change it (object, gravity, temperatures).
    pub fn hand_mut(&mut self) -> &mut Hand {
        &mut self.hand
    }

    /// The firmware's time.
    pub fn now(&self) -> Duration {
        self.now
    }

    /// Switches to another protocol generation at run time (a fault: the hand answers in a
    /// protocol the driver does not expect). The system state, the stream and its period
    /// carry over; torques are zeroed.
    pub fn set_generation(&mut self, generation: Generation) {
        let period = self.period.or(Some(DEFAULT_PERIOD));
        self.options.generation = generation;
        self.options.pwm_per_nm = generation.default_pwm_per_nm();
        self.options.pwm_limit = generation.default_pwm_limit();
        self.period = period;
        self.temperature_period = None;
        self.imu_period = None;
        self.next_temperature = None;
        self.next_imu = None;
        self.zero_torque();
        self.schedule();
    }

    /// Holds the position stream back (true) or lets it go again (a fault: the stream stops
    /// while the hand is otherwise fine).
    pub fn stop_stream(&mut self, stopped: bool) {
        self.stream_stopped = stopped;
        self.schedule();
    }

    /// Heats every motor to `celsius` (a fault: above [`OVERHEAT_C`] the motors switch off).
    pub fn heat(&mut self, celsius: f64) {
        self.hand.set_temperatures(celsius);
        self.check_heat();
    }

    fn zero_torque(&mut self) {
        self.pwm = [0; JOINTS];
        self.apply_pwm();
    }

    fn apply_pwm(&mut self) {
        let mut torque = [0.0; JOINTS];
        if !self.overheated {
            for (j, t) in torque.iter_mut().enumerate() {
                *t = pwm_to_torque(
                    self.pwm[j],
                    self.options.pwm_per_nm,
                    self.options.calibration[j].motor_dir,
                );
            }
        }
        self.hand.set_torques(&torque);
    }

    fn check_heat(&mut self) {
        let hottest = self
            .hand
            .temperatures()
            .into_iter()
            .fold(f64::MIN, f64::max);
        let was = self.overheated;
        if hottest > OVERHEAT_C {
            self.overheated = true;
        } else if hottest < COOLED_C {
            self.overheated = false;
        }
        if was != self.overheated {
            self.apply_pwm();
        }
    }

    fn streams_positions(&self) -> bool {
        let on = match self.options.generation.protocol() {
            Protocol::Doc => self.system_on,
            Protocol::V4 => self.system_on || self.options.v4_stream_on_period,
        };
        on && !self.stream_stopped && self.period.is_some()
    }

    fn streams_others(&self) -> bool {
        self.options.generation.protocol() == Protocol::V4
            && (self.system_on || self.options.v4_stream_on_period)
    }

    /// Recomputes which streams run, keeping the phase of those already running.
    fn schedule(&mut self) {
        let now = self.now;
        let next = |current: Option<Duration>, period: Option<Duration>, on: bool| match period {
            Some(p) if on => Some(current.unwrap_or(now + p)),
            _ => None,
        };
        self.next_position = next(self.next_position, self.period, self.streams_positions());
        let others = self.streams_others();
        self.next_temperature = next(self.next_temperature, self.temperature_period, others);
        self.next_imu = next(self.next_imu, self.imu_period, others);
    }

    /// When [`Firmware::advance`] next has something to do (a stream frame or the torque
    /// timeout), if ever.
    pub fn next_due(&self) -> Option<Duration> {
        let timeout = self
            .options
            .torque_timeout
            .and_then(|t| self.last_torque.iter().flatten().map(|&at| at + t).min());
        [
            self.next_position,
            self.next_temperature,
            self.next_imu,
            timeout,
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Runs the hand up to `now`, sending the stream frames that fall due on the way (each with
    /// the time it was sent) into `out`.
    pub fn advance(&mut self, now: Duration, out: &mut Vec<(Duration, CanFrame)>) {
        while let Some(due) = self.next_due().filter(|&d| d <= now) {
            self.run_hand_to(due);
            self.expire_torques(due);
            if self.next_position == Some(due) {
                self.positions(due, out);
                self.next_position = self.period.map(|p| due + p);
            }
            if self.next_temperature == Some(due) {
                self.temperatures(due, out);
                self.next_temperature = self.temperature_period.map(|p| due + p);
            }
            if self.next_imu == Some(due) {
                // The hand is fixed: the IMU reports a still, level palm (raw 0, 0, 0).
                self.emit(
                    due,
                    v4::Report::Imu([0; 3]).encode(self.options.device_id),
                    out,
                );
                self.next_imu = self.imu_period.map(|p| due + p);
            }
        }
        self.run_hand_to(now);
        self.expire_torques(now);
    }

    fn run_hand_to(&mut self, t: Duration) {
        if t > self.now {
            self.hand.advance_to(t.as_secs_f64());
            self.now = t;
            self.check_heat();
        }
    }

    fn expire_torques(&mut self, now: Duration) {
        let Some(timeout) = self.options.torque_timeout else {
            return;
        };
        let mut changed = false;
        for f in 0..FINGERS {
            if self.last_torque[f].is_some_and(|at| at + timeout <= now) {
                self.last_torque[f] = None;
                self.pwm[f * JOINTS_PER_FINGER..(f + 1) * JOINTS_PER_FINGER].fill(0);
                self.counters.torque_timeouts += 1;
                changed = true;
            }
        }
        if changed {
            self.apply_pwm();
        }
    }

    fn emit(&mut self, at: Duration, frame: CanFrame, out: &mut Vec<(Duration, CanFrame)>) {
        self.counters.frames_out += 1;
        out.push((at, frame));
    }

    /// The four position frames, as the hand's encoders read now.
    fn positions(&mut self, at: Duration, out: &mut Vec<(Duration, CanFrame)>) {
        let q = self.hand.positions();
        for f in 0..FINGERS {
            let joints = f * JOINTS_PER_FINGER..(f + 1) * JOINTS_PER_FINGER;
            let frame = match self.options.generation.protocol() {
                Protocol::Doc => {
                    let raw = core::array::from_fn(|k| {
                        let j = joints.start + k;
                        self.options.calibration[j].rad_to_doc_raw(q[j])
                    });
                    doc::Report::Position {
                        finger: f as u8,
                        raw,
                    }
                    .encode(doc::ID_DEVICE_MAIN)
                }
                Protocol::V4 => {
                    let raw = core::array::from_fn(|k| rad_to_v4_raw(q[joints.start + k]));
                    v4::Report::Position {
                        finger: f as u8,
                        raw,
                    }
                    .encode(self.options.device_id)
                }
            };
            self.emit(at, frame, out);
        }
    }

    /// The document protocol's answer to `QUERY_STATE_DATA`: one 0x0E frame per finger.
    fn state_answer(&mut self, at: Duration, out: &mut Vec<(Duration, CanFrame)>) {
        let q = self.hand.positions();
        for f in 0..FINGERS {
            let mut data = [0u8; 8];
            let len = match self.options.state_answer {
                StateAnswer::Positions => {
                    for k in 0..JOINTS_PER_FINGER {
                        let j = f * JOINTS_PER_FINGER + k;
                        let raw = self.options.calibration[j].rad_to_doc_raw(q[j]);
                        data[2 * k..2 * k + 2].copy_from_slice(&raw.to_le_bytes());
                    }
                    8
                }
                StateAnswer::Empty => 0,
            };
            let frame = doc::Report::State {
                finger: f as u8,
                len,
                data,
            }
            .encode(doc::ID_DEVICE_MAIN);
            self.emit(at, frame, out);
        }
    }

    fn temperatures(&mut self, at: Duration, out: &mut Vec<(Duration, CanFrame)>) {
        let t = self.hand.temperatures();
        for f in 0..FINGERS {
            let celsius = core::array::from_fn(|k| {
                t[f * JOINTS_PER_FINGER + k].round().clamp(0.0, 255.0) as u8
            });
            let frame = v4::Report::Temperature {
                finger: f as u8,
                celsius,
            }
            .encode(self.options.device_id);
            self.emit(at, frame, out);
        }
    }

    /// Takes one frame from the bus at `now` (after running the hand up to then); answers go
    /// into `out`.
    pub fn receive(
        &mut self,
        now: Duration,
        frame: &CanFrame,
        out: &mut Vec<(Duration, CanFrame)>,
    ) {
        self.advance(now, out);
        let known = match self.options.generation.protocol() {
            Protocol::Doc => self.receive_doc(frame, out),
            Protocol::V4 => self.receive_v4(frame, out),
        };
        if known {
            self.counters.frames_in += 1;
        } else {
            self.counters.ignored += 1;
        }
        self.schedule();
    }

    fn set_torque(&mut self, finger: u8, pwm: [i16; 4]) {
        let f = usize::from(finger);
        if f >= FINGERS {
            return;
        }
        if !self.system_on || self.overheated {
            self.counters.torque_refused += 1;
            return;
        }
        let limit = self.options.pwm_limit.saturating_abs();
        for (k, &p) in pwm.iter().enumerate() {
            self.pwm[f * JOINTS_PER_FINGER + k] = p.clamp(-limit, limit);
        }
        self.last_torque[f] = Some(self.now);
        self.counters.torque_frames += 1;
        self.apply_pwm();
    }

    fn system(&mut self, on: bool) {
        self.system_on = on;
        if !on {
            self.zero_torque();
            self.last_torque = [None; FINGERS];
        }
    }

    fn receive_doc(&mut self, frame: &CanFrame, out: &mut Vec<(Duration, CanFrame)>) -> bool {
        let order: TorqueOrder = self.options.generation.torque_order();
        let Ok(request) = doc::Request::decode(frame, order) else {
            return false;
        };
        let now = self.now;
        match request {
            doc::Request::SystemOn => self.system(true),
            doc::Request::SystemOff => self.system(false),
            doc::Request::SetPeriod { ms: p } => {
                self.period = ms(u16::from(p));
                self.next_position = None;
            }
            doc::Request::ModeJoint => self.mode = Some("joint"),
            doc::Request::ModeTask => self.mode = Some("task"),
            doc::Request::Torque { finger, pwm } => self.set_torque(finger, pwm),
            doc::Request::QueryState => self.state_answer(now, out),
            doc::Request::QueryId => {
                let frame = doc::Report::Id {
                    revision: self.revision(),
                    firmware: self.options.firmware_version,
                    hw_type: self.options.hand_type,
                }
                .encode(doc::ID_DEVICE_MAIN);
                self.emit(now, frame, out);
            }
        }
        true
    }

    /// The hand revision QUERY_ID reports: the generation's major version in the high byte.
    fn revision(&self) -> u16 {
        match self.options.generation {
            Generation::V1 => 0x0100,
            Generation::V2 => 0x0200,
            Generation::V3 => 0x0300,
            Generation::V4 => 0x0400,
        }
    }

    fn receive_v4(&mut self, frame: &CanFrame, out: &mut Vec<(Duration, CanFrame)>) -> bool {
        let Ok((device, request)) = v4::Request::decode(frame) else {
            return false;
        };
        if device != self.options.device_id {
            return false;
        }
        let now = self.now;
        let dev = self.options.device_id;
        match request {
            v4::Request::SystemOn => self.system(true),
            v4::Request::SystemOff => self.system(false),
            v4::Request::SetPeriod {
                position_ms,
                imu_ms,
                temperature_ms,
            } => {
                self.period = ms(position_ms);
                self.imu_period = ms(imu_ms);
                self.temperature_period = ms(temperature_ms);
                self.next_position = None;
                self.next_imu = None;
                self.next_temperature = None;
            }
            v4::Request::Torque { finger, pwm } => self.set_torque(finger, pwm),
            v4::Request::QueryInfo => {
                let frame = v4::Report::Info(self.info()).encode(dev);
                self.emit(now, frame, out);
            }
            v4::Request::QuerySerial => {
                let frame = v4::Report::Serial(self.options.serial).encode(dev);
                self.emit(now, frame, out);
            }
        }
        true
    }

    /// The v4 HAND_INFO reply.
    pub fn info(&self) -> v4::Info {
        let hottest = self
            .hand
            .temperatures()
            .into_iter()
            .fold(f64::MIN, f64::max);
        let mut status = 0;
        if self.system_on {
            status |= status::SERVO_ON;
        }
        if self.overheated {
            status |= status::HIGH_TEMPERATURE;
        }
        v4::Info {
            hw_version: self.options.hw_version(),
            fw_version: self.options.firmware_version,
            hand_type: self.options.hand_type,
            temperature: hottest.round().clamp(0.0, 255.0) as u8,
            status,
        }
    }

    /// What the firmware is doing.
    pub fn status(&self) -> Status {
        Status {
            generation: self.options.generation,
            system_on: self.system_on,
            streaming: self.next_position.is_some(),
            period: self.period,
            temperature_period: self.temperature_period,
            stream_stopped: self.stream_stopped,
            overheated: self.overheated,
            pwm: self.pwm,
            torque: self.hand.torques(),
            position: self.hand.positions(),
            velocity: self.hand.velocities(),
            temperature: self.hand.temperatures(),
            contact: self.hand.contact_forces(),
            counters: self.counters,
            mode: self.mode,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hand::{HandParams, VirtualObject};

    fn firmware(generation: Generation) -> Firmware {
        firmware_with(FirmwareOptions::new(generation))
    }

    fn firmware_with(options: FirmwareOptions) -> Firmware {
        let hand = Hand::allegro(HandParams::default(), None).expect("builtin profile");
        Firmware::new(options, hand)
    }

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// Sends `frames` at `at`; returns what the firmware answered.
    fn send(fw: &mut Firmware, at: Duration, frames: &[CanFrame]) -> Vec<(Duration, CanFrame)> {
        let mut out = Vec::new();
        for f in frames {
            fw.receive(at, f, &mut out);
        }
        out
    }

    fn run(fw: &mut Firmware, to: Duration) -> Vec<(Duration, CanFrame)> {
        let mut out = Vec::new();
        fw.advance(to, &mut out);
        out
    }

    fn doc(r: doc::Request, g: Generation) -> CanFrame {
        r.encode(g.torque_order())
    }

    fn v4(r: v4::Request) -> CanFrame {
        r.encode(0)
    }

    fn ids(frames: &[(Duration, CanFrame)]) -> Vec<u32> {
        frames.iter().map(|(_, f)| f.raw_id()).collect()
    }

    #[test]
    fn doc_set_period_then_system_on_streams_four_frames_every_period() {
        for g in [Generation::V1, Generation::V2, Generation::V3] {
            let mut fw = firmware(g);
            let out = send(
                &mut fw,
                ms(1),
                &[
                    doc(doc::Request::SetPeriod { ms: 3 }, g),
                    doc(doc::Request::ModeTask, g),
                ],
            );
            assert!(out.is_empty(), "{g}: {out:?}");
            assert!(
                run(&mut fw, ms(20)).is_empty(),
                "{g}: silent before SYSTEM_ON"
            );
            assert!(send(&mut fw, ms(20), &[doc(doc::Request::SystemOn, g)]).is_empty());
            let out = run(&mut fw, ms(50));
            // At 23, 26, ..., 50 ms: ten periods of four frames.
            assert_eq!(out.len(), 40, "{g}");
            for (k, chunk) in out.chunks(4).enumerate() {
                let at = ms(23 + 3 * k as u64);
                assert!(chunk.iter().all(|(t, _)| *t == at), "{g}: {chunk:?}");
                assert_eq!(ids(chunk), [0x3D3, 0x3D4, 0x3D5, 0x3D6], "{g}");
                for (_, f) in chunk {
                    // At rest at 0 rad (the thumb's first joint at its lower limit 0.263 rad).
                    let raw = u16::from_le_bytes([f.data()[0], f.data()[1]]);
                    if f.raw_id() == 0x3D6 {
                        assert!(raw > 32768 + 2800, "{g}: {raw}");
                    } else {
                        assert_eq!(raw, 32768, "{g}");
                    }
                }
            }
            let s = fw.status();
            assert!(s.system_on && s.streaming);
            assert_eq!((s.mode, s.period), (Some("task"), Some(ms(3))));
            // SYSTEM_OFF stops the stream and zeroes the torques.
            send(
                &mut fw,
                ms(51),
                &[doc(
                    doc::Request::Torque {
                        finger: 1,
                        pwm: [10, 20, 30, 40],
                    },
                    g,
                )],
            );
            assert_ne!(fw.status().pwm, [0; JOINTS]);
            send(&mut fw, ms(52), &[doc(doc::Request::SystemOff, g)]);
            assert!(run(&mut fw, ms(80)).is_empty(), "{g}: SYSTEM_OFF stops");
            assert_eq!(fw.status().pwm, [0; JOINTS]);
            assert_eq!(fw.status().torque, [0.0; JOINTS]);
        }
    }

    #[test]
    fn doc_query_state_and_query_id_are_answered() {
        let g = Generation::V3;
        let mut fw = firmware(g);
        let out = send(&mut fw, ms(5), &[doc(doc::Request::QueryState, g)]);
        assert_eq!(
            ids(&out),
            [0x393, 0x394, 0x395, 0x396],
            "0x0E from each finger"
        );
        let out = send(&mut fw, ms(6), &[doc(doc::Request::QueryId, g)]);
        assert_eq!(out.len(), 1);
        assert_eq!(
            doc::Report::decode(&out[0].1).expect("id reply"),
            doc::Report::Id {
                revision: 0x0300,
                firmware: 0x0102,
                hw_type: 0
            }
        );
        assert!(run(&mut fw, ms(40)).is_empty(), "queries start no stream");
    }

    #[test]
    fn torque_frames_are_applied_in_the_generations_joint_order() {
        let pwm = [100, 200, 300, 400];
        for g in [
            Generation::V1,
            Generation::V2,
            Generation::V3,
            Generation::V4,
        ] {
            let mut fw = firmware(g);
            let (on, torque) = match g.protocol() {
                Protocol::Doc => (
                    doc(doc::Request::SystemOn, g),
                    doc(doc::Request::Torque { finger: 2, pwm }, g),
                ),
                Protocol::V4 => (
                    v4(v4::Request::SystemOn),
                    v4(v4::Request::Torque { finger: 2, pwm }),
                ),
            };
            send(&mut fw, ms(1), &[on, torque]);
            let s = fw.status();
            assert_eq!(s.pwm[8..12], pwm, "{g}");
            assert_eq!(s.pwm[..8], [0; 8], "{g}");
            let k = g.default_pwm_per_nm();
            assert!(
                (s.torque[11] - 400.0 / k).abs() < 1e-12,
                "{g}: {:?}",
                s.torque
            );
        }
        // A v2 frame read by a v1 hand lands on the joints the other way round.
        let mut v1 = firmware(Generation::V1);
        let g = Generation::V2;
        send(
            &mut v1,
            ms(1),
            &[
                doc(doc::Request::SystemOn, g),
                doc(doc::Request::Torque { finger: 0, pwm }, g),
            ],
        );
        assert_eq!(v1.status().pwm[..4], [400, 300, 200, 100]);
    }

    #[test]
    fn pwm_is_clamped_to_the_hands_limit_and_motor_directions_apply() {
        let mut o = FirmwareOptions::new(Generation::V2);
        o.calibration[1].motor_dir = -1;
        let mut fw = firmware_with(o);
        let g = Generation::V2;
        send(
            &mut fw,
            ms(1),
            &[
                doc(doc::Request::SystemOn, g),
                doc(
                    doc::Request::Torque {
                        finger: 0,
                        pwm: [5000, 400, -5000, i16::MIN],
                    },
                    g,
                ),
            ],
        );
        let s = fw.status();
        assert_eq!(s.pwm[..4], [800, 400, -800, -800]);
        assert!(
            (s.torque[1] + 0.5).abs() < 1e-12,
            "motor dir -1: {:?}",
            s.torque
        );
        assert!((s.torque[0] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn torque_needs_system_on() {
        let g = Generation::V3;
        let mut fw = firmware(g);
        send(
            &mut fw,
            ms(1),
            &[doc(
                doc::Request::Torque {
                    finger: 0,
                    pwm: [100; 4],
                },
                g,
            )],
        );
        assert_eq!(fw.status().pwm, [0; JOINTS]);
        assert_eq!(fw.status().counters.torque_refused, 1);
    }

    #[test]
    fn v4_streams_after_system_on_and_answers_info_and_serial_always() {
        let mut fw = firmware(Generation::V4);
        let info = v4::Request::QueryInfo.encode::<CanFrame>(0);
        let serial = v4::Request::QuerySerial.encode::<CanFrame>(0);
        let out = send(&mut fw, ms(1), &[info, serial]);
        assert_eq!(ids(&out), [0x200, 0x220], "answered while silent");
        match v4::Report::decode(&out[0].1).expect("info") {
            (0, v4::Report::Info(i)) => {
                assert_eq!(i.hw_version >> 8, 4, "12 V hand: 1200 PWM per N m");
                assert_eq!(i.status & status::SERVO_ON, 0);
                assert_eq!(i.temperature, 30);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            v4::Report::decode(&out[1].1).expect("serial"),
            (0, v4::Report::Serial(*b"00AR0042"))
        );
        send(
            &mut fw,
            ms(2),
            &[v4(v4::Request::SetPeriod {
                position_ms: 3,
                imu_ms: 0,
                temperature_ms: 9,
            })],
        );
        assert!(
            run(&mut fw, ms(20)).is_empty(),
            "needs SYSTEM_ON by default"
        );
        send(&mut fw, ms(20), &[v4(v4::Request::SystemOn)]);
        let out = run(&mut fw, ms(29));
        let positions: Vec<u32> = ids(&out).into_iter().filter(|&id| id < 0x0E0).collect();
        assert_eq!(
            positions,
            [0x080, 0x084, 0x088, 0x08C, 0x080, 0x084, 0x088, 0x08C, 0x080, 0x084, 0x088, 0x08C]
        );
        let temps: Vec<u32> = ids(&out).into_iter().filter(|&id| id >= 0x0E0).collect();
        assert_eq!(temps, [0x0E0, 0x0E4, 0x0E8, 0x0EC]);
        // Streaming: still answered.
        let out = send(&mut fw, ms(29), &[info]);
        assert_eq!(ids(&out), [0x200]);
        match v4::Report::decode(&out[0].1).expect("info") {
            (0, v4::Report::Info(i)) => assert_eq!(i.status & status::SERVO_ON, 1),
            other => panic!("{other:?}"),
        }
        // A zero position period stops the position stream.
        send(
            &mut fw,
            ms(30),
            &[v4(v4::Request::SetPeriod {
                position_ms: 0,
                imu_ms: 0,
                temperature_ms: 0,
            })],
        );
        assert!(run(&mut fw, ms(60)).is_empty());
    }

    #[test]
    fn v4_can_stream_on_the_period_alone_when_so_built() {
        let mut o = FirmwareOptions::new(Generation::V4);
        o.v4_stream_on_period = true;
        let mut fw = firmware_with(o);
        send(
            &mut fw,
            ms(0),
            &[v4(v4::Request::SetPeriod {
                position_ms: 3,
                imu_ms: 0,
                temperature_ms: 0,
            })],
        );
        assert_eq!(run(&mut fw, ms(9)).len(), 12);
    }

    #[test]
    fn v4_ignores_other_device_ids_and_unknown_ids_are_counted() {
        let mut fw = firmware(Generation::V4);
        let other = v4::Request::QueryInfo.encode::<CanFrame>(1);
        let unknown = CanFrame::standard(0x7F0, &[1, 2]).expect("frame");
        let doc_frame = doc(doc::Request::SystemOn, Generation::V3);
        let out = send(&mut fw, ms(1), &[other, unknown, doc_frame]);
        assert!(out.is_empty());
        assert_eq!(fw.status().counters.ignored, 3);
        assert!(!fw.status().system_on);
    }

    #[test]
    fn positions_go_out_through_the_hands_encoder_offsets_and_directions() {
        let mut o = FirmwareOptions::new(Generation::V3);
        o.calibration[0].offset = -1591;
        o.calibration[1].encoder_dir = -1;
        o.calibration[1].offset = -65536 + 100;
        let mut fw = firmware_with(o.clone());
        fw.hand_mut().set_position(1, 0.5);
        let out = send(
            &mut fw,
            ms(1),
            &[doc(doc::Request::QueryState, Generation::V3)],
        );
        let d = out[0].1.data();
        let raw = [
            u16::from_le_bytes([d[0], d[1]]),
            u16::from_le_bytes([d[2], d[3]]),
        ];
        assert_eq!(raw[0], 32768 - 1591);
        for (j, r) in raw.iter().enumerate() {
            let rad = o.calibration[j].doc_raw_to_rad(*r);
            let want = [0.0, 0.5][j];
            assert!((rad - want).abs() < 1e-3, "joint {j}: {rad}");
        }
    }

    #[test]
    fn torque_timeout_zeroes_a_silent_fingers_torque_and_is_off_by_default() {
        for timeout in [None, Some(ms(50))] {
            let mut o = FirmwareOptions::new(Generation::V4);
            o.torque_timeout = timeout;
            let mut fw = firmware_with(o);
            send(
                &mut fw,
                ms(0),
                &[
                    v4(v4::Request::SystemOn),
                    v4(v4::Request::Torque {
                        finger: 0,
                        pwm: [50; 4],
                    }),
                ],
            );
            run(&mut fw, ms(40));
            assert_eq!(fw.status().pwm[0], 50);
            run(&mut fw, ms(60));
            let held = fw.status().pwm[0];
            assert_eq!(held, if timeout.is_some() { 0 } else { 50 }, "{timeout:?}");
        }
    }

    #[test]
    fn switching_generation_changes_the_ids_on_the_stream() {
        let g = Generation::V3;
        let mut fw = firmware(g);
        send(
            &mut fw,
            ms(0),
            &[
                doc(doc::Request::SetPeriod { ms: 3 }, g),
                doc(doc::Request::SystemOn, g),
            ],
        );
        assert_eq!(ids(&run(&mut fw, ms(3))), [0x3D3, 0x3D4, 0x3D5, 0x3D6]);
        fw.set_generation(Generation::V4);
        assert_eq!(ids(&run(&mut fw, ms(6))), [0x080, 0x084, 0x088, 0x08C]);
        assert_eq!(fw.status().generation, Generation::V4);
    }

    #[test]
    fn a_stopped_stream_resumes() {
        let mut fw = firmware(Generation::V4);
        send(
            &mut fw,
            ms(0),
            &[
                v4(v4::Request::SetPeriod {
                    position_ms: 3,
                    imu_ms: 0,
                    temperature_ms: 0,
                }),
                v4(v4::Request::SystemOn),
            ],
        );
        assert_eq!(run(&mut fw, ms(3)).len(), 4);
        fw.stop_stream(true);
        assert!(run(&mut fw, ms(30)).is_empty());
        assert!(fw.status().system_on && fw.status().stream_stopped);
        fw.stop_stream(false);
        assert_eq!(run(&mut fw, ms(33)).len(), 4);
    }

    #[test]
    fn an_overheated_hand_switches_its_motors_off_and_says_so() {
        let mut fw = firmware(Generation::V4);
        send(
            &mut fw,
            ms(0),
            &[
                v4(v4::Request::SystemOn),
                v4(v4::Request::Torque {
                    finger: 0,
                    pwm: [100; 4],
                }),
            ],
        );
        fw.heat(95.0);
        assert_eq!(fw.status().torque, [0.0; JOINTS]);
        assert!(fw.status().overheated);
        assert_eq!(
            fw.info().status & status::HIGH_TEMPERATURE,
            status::HIGH_TEMPERATURE
        );
        assert_eq!(fw.info().temperature, 95);
        fw.heat(30.0);
        assert!(!fw.status().overheated);
        assert!(fw.status().torque[0] > 0.0, "the held PWM applies again");
    }

    #[test]
    fn temperature_rises_with_effort_on_the_temperature_stream() {
        let mut fw = firmware(Generation::V4);
        send(
            &mut fw,
            ms(0),
            &[
                v4(v4::Request::SetPeriod {
                    position_ms: 0,
                    imu_ms: 0,
                    temperature_ms: 100,
                }),
                v4(v4::Request::SystemOn),
                v4(v4::Request::Torque {
                    finger: 3,
                    pwm: [0, 0, 900, 0],
                }),
            ],
        );
        let out = run(&mut fw, Duration::from_secs(5));
        let last = out
            .iter()
            .rev()
            .find(|(_, f)| f.raw_id() == 0x0EC)
            .expect("thumb temperatures");
        match v4::Report::decode(&last.1).expect("temperature") {
            (0, v4::Report::Temperature { finger: 3, celsius }) => {
                assert!(celsius[2] > 31, "{celsius:?}");
                assert_eq!(celsius[0], 30);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_finger_driven_closed_stops_at_the_ball() {
        let hand = Hand::allegro(HandParams::default(), Some(VirtualObject::ball()))
            .expect("builtin profile");
        let mut fw = Firmware::new(FirmwareOptions::new(Generation::V4), hand);
        send(
            &mut fw,
            ms(0),
            &[
                v4(v4::Request::SystemOn),
                v4(v4::Request::Torque {
                    finger: 1,
                    pwm: [0, 360, 360, 360],
                }),
            ],
        );
        run(&mut fw, Duration::from_secs(1));
        let s = fw.status();
        assert!(s.contact[1] > 0.5, "{:?}", s.contact);
        assert!(
            s.position[5] < 1.0,
            "the proximal joint stops: {:?}",
            s.position
        );
    }
}
