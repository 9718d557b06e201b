//! One protocol generation on the wire: the frames the node sends (start, torque, stop, info
//! queries) and what the frames it receives mean, over `teleop-allegro-protocol`'s codecs.

use std::time::Duration;

use teleop_allegro_protocol::{
    detect, doc, torque_to_pwm, v4, v4_raw_to_rad, Generation, JointCalibration, Protocol, FINGERS,
    JOINTS,
};
use teleop_can_link::CanFrame;

/// What a received frame means to a node running `generation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Incoming {
    /// One finger's joint positions, rad (calibrated).
    Position {
        /// Finger 0..4 (index, middle, ring, thumb).
        finger: u8,
        /// Joints 0..3 of the finger.
        q: [f64; 4],
    },
    /// v4: the hand's info (answer to the info query).
    Info(v4::Info),
    /// v4: the hand's serial number (answer to the serial query).
    Serial([u8; 8]),
    /// v4: one finger's joint temperatures.
    Temperature {
        /// Finger 0..4.
        finger: u8,
        /// Degrees C per joint.
        celsius: [u8; 4],
    },
    /// Document protocol: the answer to QUERY_ID.
    DocId {
        /// Hand revision.
        revision: u16,
        /// Firmware version.
        firmware: u16,
        /// Hardware type.
        hw_type: u8,
    },
    /// Document protocol: one finger's answer to QUERY_STATE_DATA (0x0E, the document's "joint
    /// state response"). Not a frame of the stream (0x0F): it neither completes nor breaks a
    /// period, and its payload is not documented, so no position is taken from it.
    StateAnswer {
        /// Finger 0..4.
        finger: u8,
    },
    /// A frame of the other protocol generation: the hand is not the one configured.
    Foreign(Protocol),
    /// Understood and not used (v4 IMU, another device id's frames).
    Other,
    /// An id neither protocol knows, or a remote frame where data is expected.
    Unknown,
    /// A known id with a payload that does not decode (wrong length, bad finger).
    Bad,
}

/// A step of a bring-up or stop sequence: a frame, then a pause.
#[derive(Debug, Clone, Copy)]
pub struct Step {
    /// The frame.
    pub frame: CanFrame,
    /// Pause after sending it.
    pub pause: Duration,
}

fn step(frame: CanFrame, pause_ms: u64) -> Step {
    Step {
        frame,
        pause: Duration::from_millis(pause_ms),
    }
}

/// The generation the node speaks, with its device id and per-joint calibration.
#[derive(Debug, Clone)]
pub struct Wire {
    generation: Generation,
    device_id: u8,
    calibration: [JointCalibration; JOINTS],
}

impl Wire {
    /// Speaks `generation` to device `device_id` (v4) with `calibration` (document protocol).
    pub fn new(
        generation: Generation,
        device_id: u8,
        calibration: [JointCalibration; JOINTS],
    ) -> Self {
        Self {
            generation,
            device_id,
            calibration,
        }
    }

    /// The generation.
    pub fn generation(&self) -> Generation {
        self.generation
    }

    /// The generation's protocol.
    pub fn protocol(&self) -> Protocol {
        self.generation.protocol()
    }

    /// What `frame` means.
    pub fn decode(&self, frame: &CanFrame) -> Incoming {
        match self.protocol() {
            Protocol::Doc => match doc::Report::decode(frame) {
                Ok(doc::Report::Position { finger, raw }) => {
                    let base = usize::from(finger) * 4;
                    let mut q = [0.0; 4];
                    for (k, v) in q.iter_mut().enumerate() {
                        *v = self.calibration[base + k].doc_raw_to_rad(raw[k]);
                    }
                    Incoming::Position { finger, q }
                }
                Ok(doc::Report::State { finger, .. }) => Incoming::StateAnswer { finger },
                Ok(doc::Report::Id {
                    revision,
                    firmware,
                    hw_type,
                }) => Incoming::DocId {
                    revision,
                    firmware,
                    hw_type,
                },
                Err(e) => self.undecoded(frame, &e),
            },
            Protocol::V4 => match v4::Report::decode(frame) {
                Ok((device, _)) if device != self.device_id => Incoming::Other,
                Ok((_, report)) => match report {
                    v4::Report::Position { finger, raw } => {
                        let mut q = [0.0; 4];
                        for (k, v) in q.iter_mut().enumerate() {
                            *v = v4_raw_to_rad(raw[k]);
                        }
                        Incoming::Position { finger, q }
                    }
                    v4::Report::Info(info) => Incoming::Info(info),
                    v4::Report::Serial(s) => Incoming::Serial(s),
                    v4::Report::Temperature { finger, celsius } => {
                        Incoming::Temperature { finger, celsius }
                    }
                    v4::Report::Imu(_) => Incoming::Other,
                },
                Err(e) => self.undecoded(frame, &e),
            },
        }
    }

    /// A frame this generation's decoder refused: the other generation's, unknown or bad.
    fn undecoded(&self, frame: &CanFrame, e: &teleop_allegro_protocol::DecodeError) -> Incoming {
        match detect(frame) {
            Some(p) if p != self.protocol() => Incoming::Foreign(p),
            _ if is_unknown(e) => Incoming::Unknown,
            _ => Incoming::Bad,
        }
    }

    /// The four torque frames for `torque` (N m, joint order), `pwm_per_nm` PWM counts per N m,
    /// each joint's PWM limited to `pwm_limit` (and to `pwm_per_nm`).
    pub fn torque_frames(
        &self,
        torque: &[f64; JOINTS],
        pwm_per_nm: f64,
        pwm_limit: &[i16; JOINTS],
    ) -> [CanFrame; FINGERS] {
        let mut frames = [CanFrame::default(); FINGERS];
        for (f, frame) in frames.iter_mut().enumerate() {
            let mut pwm = [0i16; 4];
            for (k, p) in pwm.iter_mut().enumerate() {
                let j = f * 4 + k;
                let motor_dir = match self.protocol() {
                    Protocol::Doc => self.calibration[j].motor_dir,
                    Protocol::V4 => 1,
                };
                let cap = pwm_per_nm.clamp(0.0, f64::from(i16::MAX)) as i16;
                *p = torque_to_pwm(torque[j], pwm_per_nm, motor_dir, pwm_limit[j].min(cap));
            }
            let finger = f as u8;
            *frame = match self.protocol() {
                Protocol::Doc => doc::Request::Torque { finger, pwm }
                    .encode::<CanFrame>(self.generation.torque_order()),
                Protocol::V4 => {
                    v4::Request::Torque { finger, pwm }.encode::<CanFrame>(self.device_id)
                }
            };
        }
        frames
    }

    /// Four frames of zero torque.
    pub fn zero_torque_frames(&self) -> [CanFrame; FINGERS] {
        self.torque_frames(&[0.0; JOINTS], 1.0, &[0; JOINTS])
    }

    /// The start sequence (docs/devices/allegro.md, "Sequences" and "Init R4"), after the link was
    /// drained. Document protocol: SYSTEM_OFF, SET_PERIOD, MODE_TASK, QUERY_ID, QUERY_STATE,
    /// SYSTEM_ON (the document's 10 ms pauses). v4: SYSTEM_OFF, info and serial queries,
    /// SET_PERIOD{period, no IMU, temperature}, SYSTEM_ON.
    pub fn start_sequence(&self, period_ms: u8, temperature_ms: u16) -> Vec<Step> {
        match self.protocol() {
            Protocol::Doc => {
                let order = self.generation.torque_order();
                let f = |r: doc::Request| r.encode::<CanFrame>(order);
                vec![
                    step(f(doc::Request::SystemOff), 10),
                    step(f(doc::Request::SetPeriod { ms: period_ms }), 10),
                    step(f(doc::Request::ModeTask), 10),
                    step(f(doc::Request::QueryId), 10),
                    step(f(doc::Request::QueryState), 10),
                    step(f(doc::Request::SystemOn), 0),
                ]
            }
            Protocol::V4 => {
                let d = self.device_id;
                vec![
                    step(v4::Request::SystemOff.encode::<CanFrame>(d), 1),
                    step(v4::Request::QueryInfo.encode::<CanFrame>(d), 1),
                    step(v4::Request::QuerySerial.encode::<CanFrame>(d), 1),
                    step(
                        v4::Request::SetPeriod {
                            position_ms: u16::from(period_ms),
                            imu_ms: 0,
                            temperature_ms,
                        }
                        .encode::<CanFrame>(d),
                        1,
                    ),
                    step(v4::Request::SystemOn.encode::<CanFrame>(d), 0),
                ]
            }
        }
    }

    /// The stop sequence, after zero torque: SYSTEM_OFF (v4: the periods set to zero first, as
    /// R4 and L stop; W2 sends SYSTEM_OFF: both are harmless).
    pub fn stop_sequence(&self) -> Vec<CanFrame> {
        match self.protocol() {
            Protocol::Doc => {
                vec![doc::Request::SystemOff.encode::<CanFrame>(self.generation.torque_order())]
            }
            Protocol::V4 => {
                let d = self.device_id;
                vec![
                    v4::Request::SetPeriod {
                        position_ms: 0,
                        imu_ms: 0,
                        temperature_ms: 0,
                    }
                    .encode::<CanFrame>(d),
                    v4::Request::SystemOff.encode::<CanFrame>(d),
                ]
            }
        }
    }

    /// v4: the info query (None for the document protocol, which has none while streaming).
    pub fn info_query(&self) -> Option<CanFrame> {
        match self.protocol() {
            Protocol::Doc => None,
            Protocol::V4 => Some(v4::Request::QueryInfo.encode::<CanFrame>(self.device_id)),
        }
    }
}

/// Whether a decode error means an id the protocol does not know (as opposed to a known id
/// with a bad payload).
fn is_unknown(e: &teleop_allegro_protocol::DecodeError) -> bool {
    use teleop_allegro_protocol::DecodeError as E;
    matches!(
        e,
        E::UnknownCommand { .. } | E::Extended { .. } | E::Remote { .. }
    )
}
