//! The v4 protocol (hands sold as v4, SAH040...; v5 keeps its core), from docs/devices/allegro.md:
//! Wonik's v4 protocol page as R4, W2 and fairo implement it. Not in the device document.
//!
//! Wire id = `msg << 2 | device` (device 0..3, kept in the hand's non-volatile memory, default
//! 0); every payload little-endian. A remote frame (DLC 0) with a query's id is answered by a
//! data frame with the same id, streaming or not.
//!
//! | msg | name | id (device 0) | payload |
//! |---|---|---|---|
//! | 0x40 / 0x41 | SYSTEM_ON / OFF | 0x100 / 0x104 | - |
//! | 0x60 + f | SET_TORQUE finger f | 0x180..0x18C | 4 x i16 PWM, j0..j3 |
//! | 0x81 | SET_PERIOD | 0x204 | u16 position ms, u16 IMU ms, u16 temperature ms (0 stops a stream) |
//! | 0x80 | HAND_INFO (RTR) | 0x200 | reply: hw u16, fw u16, hand type u8, temperature u8, status u8 |
//! | 0x88 | SERIAL (RTR) | 0x220 | reply: 8 ASCII characters |
//! | 0x20 + f | POSITION finger f | 0x080..0x08C | 4 x i16 counts from the joint's zero |
//! | 0x30 | IMU | 0x0C0 | 3 x u16, raw |
//! | 0x38 + f | TEMPERATURE finger f | 0x0E0..0x0EC | 4 x u8 deg C |
//!
//! Decisions: the temperature payload is four `u8` per finger (W2) rather than one `i32` (R4, L):
//! W2 is the newest and per-joint values fit the 4-byte frame. `SET_PERIOD` is sent with the
//! three documented values (6 bytes); fairo sends 8 (a fourth "status" u16), so decoding takes 6
//! or more. The CONFIG message (0x68) is never sent: R4 and L disagree on its layout.

use embedded_can::Frame;

use crate::{data_frame, remote_frame, standard_id, DecodeError};

/// SYSTEM_ON.
pub const MSG_SYSTEM_ON: u16 = 0x40;
/// SYSTEM_OFF.
pub const MSG_SYSTEM_OFF: u16 = 0x41;
/// SET_TORQUE of finger 0; fingers 1..3 follow.
pub const MSG_SET_TORQUE: u16 = 0x60;
/// HAND_INFO query and reply.
pub const MSG_HAND_INFO: u16 = 0x80;
/// SET_PERIOD.
pub const MSG_SET_PERIOD: u16 = 0x81;
/// SERIAL query and reply.
pub const MSG_SERIAL: u16 = 0x88;
/// POSITION of finger 0; fingers 1..3 follow.
pub const MSG_POSITION: u16 = 0x20;
/// IMU.
pub const MSG_IMU: u16 = 0x30;
/// TEMPERATURE of finger 0; fingers 1..3 follow.
pub const MSG_TEMPERATURE: u16 = 0x38;

/// The wire id of `msg` for `device` (masked to 0..3).
pub fn id(msg: u16, device: u8) -> u16 {
    ((msg & 0x1FF) << 2) | u16::from(device & 0x03)
}

/// `(msg, device)` of a wire id.
pub fn split(id: u16) -> (u16, u8) {
    ((id >> 2) & 0x1FF, (id & 0x03) as u8)
}

/// A host -> hand command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// Servo on (and streaming, with a non-zero period).
    SystemOn,
    /// Servo off.
    SystemOff,
    /// Stream periods in ms; 0 stops that stream.
    SetPeriod {
        /// Joint positions.
        position_ms: u16,
        /// IMU.
        imu_ms: u16,
        /// Temperatures.
        temperature_ms: u16,
    },
    /// PWM torque commands of one finger's joints 0..3.
    Torque {
        /// Finger 0..3.
        finger: u8,
        /// PWM counts of joints 0..3.
        pwm: [i16; 4],
    },
    /// Ask for the hand's info (remote frame).
    QueryInfo,
    /// Ask for the serial number (remote frame).
    QuerySerial,
}

impl Request {
    /// This command as a frame to `device`. A torque command for a finger beyond 3 addresses
    /// finger `finger % 4`.
    pub fn encode<F: Frame>(&self, device: u8) -> F {
        match *self {
            Request::SystemOn => data_frame(id(MSG_SYSTEM_ON, device), &[]),
            Request::SystemOff => data_frame(id(MSG_SYSTEM_OFF, device), &[]),
            Request::SetPeriod {
                position_ms,
                imu_ms,
                temperature_ms,
            } => {
                let mut b = [0u8; 6];
                b[0..2].copy_from_slice(&position_ms.to_le_bytes());
                b[2..4].copy_from_slice(&imu_ms.to_le_bytes());
                b[4..6].copy_from_slice(&temperature_ms.to_le_bytes());
                data_frame(id(MSG_SET_PERIOD, device), &b)
            }
            Request::Torque { finger, pwm } => {
                let mut b = [0u8; 8];
                for (k, p) in pwm.iter().enumerate() {
                    b[2 * k..2 * k + 2].copy_from_slice(&p.to_le_bytes());
                }
                data_frame(id(MSG_SET_TORQUE + u16::from(finger % 4), device), &b)
            }
            Request::QueryInfo => remote_frame(id(MSG_HAND_INFO, device)),
            Request::QuerySerial => remote_frame(id(MSG_SERIAL, device)),
        }
    }

    /// What a frame asks of the hand (the simulated hand's side): the device it is addressed to
    /// and the request.
    pub fn decode<F: Frame>(frame: &F) -> Result<(u8, Request), DecodeError> {
        let id = standard_id(frame)?;
        let (msg, device) = split(id);
        let data = frame.data();
        let remote = frame.is_remote_frame();
        let request = match msg {
            MSG_HAND_INFO | MSG_SERIAL if !remote => return Err(DecodeError::NotRemote { id }),
            MSG_HAND_INFO => Request::QueryInfo,
            MSG_SERIAL => Request::QuerySerial,
            _ if remote => return Err(DecodeError::Remote { id }),
            MSG_SYSTEM_ON => Request::SystemOn,
            MSG_SYSTEM_OFF => Request::SystemOff,
            MSG_SET_PERIOD => {
                if data.len() < 6 {
                    return Err(DecodeError::Length {
                        id,
                        what: "SET_PERIOD",
                        expected: "6 (or 8)",
                        got: data.len(),
                    });
                }
                let u = |k: usize| u16::from_le_bytes([data[k], data[k + 1]]);
                Request::SetPeriod {
                    position_ms: u(0),
                    imu_ms: u(2),
                    temperature_ms: u(4),
                }
            }
            m if (MSG_SET_TORQUE..MSG_SET_TORQUE + 4).contains(&m) => {
                let b: &[u8; 8] = data.try_into().map_err(|_| DecodeError::Length {
                    id,
                    what: "SET_TORQUE",
                    expected: "8",
                    got: data.len(),
                })?;
                Request::Torque {
                    finger: (m - MSG_SET_TORQUE) as u8,
                    pwm: std::array::from_fn(|k| i16::from_le_bytes([b[2 * k], b[2 * k + 1]])),
                }
            }
            _ => return Err(DecodeError::UnknownCommand { id }),
        };
        Ok((device, request))
    }
}

/// The hand's info (reply to [`Request::QueryInfo`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Info {
    /// Hardware version; its high byte is the supply generation (4: 12 V, R4).
    pub hw_version: u16,
    /// Firmware version.
    pub fw_version: u16,
    /// 0 right hand, 1 left hand.
    pub hand_type: u8,
    /// Temperature, deg C.
    pub temperature: u8,
    /// Status bits ([`status`]).
    pub status: u8,
}

/// Bits of [`Info::status`] (W2; fairo's reading of bits 2-4 differs and is unverified).
pub mod status {
    /// Servo on.
    pub const SERVO_ON: u8 = 0x01;
    /// High-temperature fault.
    pub const HIGH_TEMPERATURE: u8 = 0x02;
    /// Internal communication fault.
    pub const COMMUNICATION_FAULT: u8 = 0x04;
}

impl Info {
    /// PWM counts per N m: 1200 when the hardware version's high byte is 4 (a 12 V hand),
    /// else 800 (R4).
    pub fn pwm_per_nm(&self) -> f64 {
        if self.hw_version >> 8 == 4 {
            1200.0
        } else {
            800.0
        }
    }

    /// Whether the servo is on.
    pub fn servo_on(&self) -> bool {
        self.status & status::SERVO_ON != 0
    }

    /// Whether the hand reports a high-temperature fault.
    pub fn high_temperature(&self) -> bool {
        self.status & status::HIGH_TEMPERATURE != 0
    }

    /// Whether the hand reports an internal communication fault.
    pub fn communication_fault(&self) -> bool {
        self.status & status::COMMUNICATION_FAULT != 0
    }

    /// "right" or "left" (or the raw value).
    pub fn hand_side(&self) -> String {
        match self.hand_type {
            0 => "right".into(),
            1 => "left".into(),
            n => format!("type {n}"),
        }
    }
}

/// A hand -> host report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Report {
    /// One finger's four joint positions, signed counts from the joint's zero.
    Position {
        /// Finger 0..3.
        finger: u8,
        /// Counts of joints 0..3.
        raw: [i16; 4],
    },
    /// The hand's info.
    Info(Info),
    /// The serial number's 8 characters (shown as "SAH040" + them).
    Serial([u8; 8]),
    /// One finger's joint temperatures, deg C.
    Temperature {
        /// Finger 0..3.
        finger: u8,
        /// Joints 0..3.
        celsius: [u8; 4],
    },
    /// IMU values, raw (marked as a test protocol by Wonik).
    Imu([u16; 3]),
}

impl Report {
    /// This report as `device` sends it.
    pub fn encode<F: Frame>(&self, device: u8) -> F {
        match *self {
            Report::Position { finger, raw } => {
                let mut b = [0u8; 8];
                for (k, r) in raw.iter().enumerate() {
                    b[2 * k..2 * k + 2].copy_from_slice(&r.to_le_bytes());
                }
                data_frame(id(MSG_POSITION + u16::from(finger % 4), device), &b)
            }
            Report::Info(i) => {
                let mut b = [0u8; 7];
                b[0..2].copy_from_slice(&i.hw_version.to_le_bytes());
                b[2..4].copy_from_slice(&i.fw_version.to_le_bytes());
                b[4] = i.hand_type;
                b[5] = i.temperature;
                b[6] = i.status;
                data_frame(id(MSG_HAND_INFO, device), &b)
            }
            Report::Serial(s) => data_frame(id(MSG_SERIAL, device), &s),
            Report::Temperature { finger, celsius } => data_frame(
                id(MSG_TEMPERATURE + u16::from(finger % 4), device),
                &celsius,
            ),
            Report::Imu(v) => {
                let mut b = [0u8; 6];
                for (k, x) in v.iter().enumerate() {
                    b[2 * k..2 * k + 2].copy_from_slice(&x.to_le_bytes());
                }
                data_frame(id(MSG_IMU, device), &b)
            }
        }
    }

    /// What a frame from the hand reports, with the device that sent it.
    pub fn decode<F: Frame>(frame: &F) -> Result<(u8, Report), DecodeError> {
        let id = standard_id(frame)?;
        if frame.is_remote_frame() {
            return Err(DecodeError::Remote { id });
        }
        let (msg, device) = split(id);
        let data = frame.data();
        let need = |n: usize, what: &'static str, expected: &'static str| {
            if data.len() < n {
                Err(DecodeError::Length {
                    id,
                    what,
                    expected,
                    got: data.len(),
                })
            } else {
                Ok(())
            }
        };
        let report = match msg {
            m if (MSG_POSITION..MSG_POSITION + 4).contains(&m) => {
                need(8, "joint positions", "8")?;
                Report::Position {
                    finger: (m - MSG_POSITION) as u8,
                    raw: std::array::from_fn(|k| {
                        i16::from_le_bytes([data[2 * k], data[2 * k + 1]])
                    }),
                }
            }
            MSG_HAND_INFO => {
                need(7, "hand info", "7")?;
                Report::Info(Info {
                    hw_version: u16::from_le_bytes([data[0], data[1]]),
                    fw_version: u16::from_le_bytes([data[2], data[3]]),
                    hand_type: data[4],
                    temperature: data[5],
                    status: data[6],
                })
            }
            MSG_SERIAL => {
                need(8, "serial number", "8")?;
                Report::Serial(std::array::from_fn(|k| data[k]))
            }
            m if (MSG_TEMPERATURE..MSG_TEMPERATURE + 4).contains(&m) => {
                need(4, "temperatures", "4")?;
                Report::Temperature {
                    finger: (m - MSG_TEMPERATURE) as u8,
                    celsius: std::array::from_fn(|k| data[k]),
                }
            }
            MSG_IMU => {
                need(6, "IMU", "6")?;
                Report::Imu(std::array::from_fn(|k| {
                    u16::from_le_bytes([data[2 * k], data[2 * k + 1]])
                }))
            }
            _ => return Err(DecodeError::UnknownCommand { id }),
        };
        Ok((device, report))
    }
}

/// The serial number as Wonik's tools show it: "SAH040" followed by the 8 characters,
/// non-printable bytes as `\xNN`, trailing NULs dropped.
pub fn serial_text(raw: &[u8; 8]) -> String {
    let end = raw.iter().rposition(|&b| b != 0).map_or(0, |p| p + 1);
    let mut text = String::from("SAH040");
    for &b in &raw[..end] {
        if b.is_ascii_graphic() || b == b' ' {
            text.push(char::from(b));
        } else {
            text.push_str(&format!("\\x{b:02X}"));
        }
    }
    text
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::test_frame::{arbitrary_frame, data, remote, TestFrame};
    use embedded_can::Frame;
    use proptest::prelude::*;

    fn bytes(f: &TestFrame) -> (u16, bool, Vec<u8>) {
        (
            standard_id(f).unwrap(),
            f.is_remote_frame(),
            f.data().to_vec(),
        )
    }

    #[test]
    fn requests_known_answers() {
        // The slcan examples of docs/devices/allegro.md: SYSTEM_ON `t1000`, SET_PERIOD 3 ms
        // `t2046030000000000`, RTR info `r2000`.
        assert_eq!(
            bytes(&Request::SystemOn.encode::<TestFrame>(0)),
            (0x100, false, vec![])
        );
        assert_eq!(
            bytes(&Request::SystemOff.encode::<TestFrame>(0)),
            (0x104, false, vec![])
        );
        let period = Request::SetPeriod {
            position_ms: 3,
            imu_ms: 0,
            temperature_ms: 500,
        };
        assert_eq!(
            bytes(&period.encode::<TestFrame>(0)),
            (0x204, false, vec![3, 0, 0, 0, 0xF4, 0x01])
        );
        assert_eq!(
            bytes(&Request::QueryInfo.encode::<TestFrame>(0)),
            (0x200, true, vec![])
        );
        assert_eq!(
            bytes(&Request::QuerySerial.encode::<TestFrame>(0)),
            (0x220, true, vec![])
        );
        // Torque: LE, j0..j3, finger 2 of device 1: 0x62 << 2 | 1 = 0x189.
        let t = Request::Torque {
            finger: 2,
            pwm: [1, -1, 0x0203, 0],
        };
        assert_eq!(
            bytes(&t.encode::<TestFrame>(1)),
            (0x189, false, vec![1, 0, 0xFF, 0xFF, 0x03, 0x02, 0, 0])
        );
        assert_eq!(Request::decode(&t.encode::<TestFrame>(1)).unwrap(), (1, t));
    }

    #[test]
    fn fairos_eight_byte_period_is_taken() {
        let (dev, r) = Request::decode(&data(0x204, &[3, 0, 0, 0, 0, 0, 9, 9])).unwrap();
        assert_eq!(dev, 0);
        assert_eq!(
            r,
            Request::SetPeriod {
                position_ms: 3,
                imu_ms: 0,
                temperature_ms: 0
            }
        );
        assert!(matches!(
            Request::decode(&data(0x204, &[3, 0])),
            Err(DecodeError::Length { got: 2, .. })
        ));
    }

    #[test]
    fn queries_must_be_remote_frames() {
        assert!(matches!(
            Request::decode(&data(0x200, &[0; 7])),
            Err(DecodeError::NotRemote { id: 0x200 })
        ));
        assert!(matches!(
            Request::decode(&remote(0x100, 0)),
            Err(DecodeError::Remote { id: 0x100 })
        ));
        assert_eq!(
            Request::decode(&remote(0x223, 0)).unwrap(),
            (3, Request::QuerySerial)
        );
    }

    #[test]
    fn reports_known_answers() {
        // Finger 3 of device 0: 0x23 << 2 = 0x08C; signed LE.
        let (dev, r) =
            Report::decode(&data(0x08C, &[0xFF, 0xFF, 0x10, 0x00, 0, 0x80, 0xFF, 0x7F])).unwrap();
        assert_eq!(dev, 0);
        assert_eq!(
            r,
            Report::Position {
                finger: 3,
                raw: [-1, 16, i16::MIN, i16::MAX]
            }
        );
        let info = Info {
            hw_version: 0x0401,
            fw_version: 0x0102,
            hand_type: 1,
            temperature: 41,
            status: 0x03,
        };
        let f: TestFrame = Report::Info(info).encode(0);
        assert_eq!(
            bytes(&f),
            (0x200, false, vec![0x01, 0x04, 0x02, 0x01, 1, 41, 3])
        );
        assert_eq!(Report::decode(&f).unwrap(), (0, Report::Info(info)));
        assert_eq!(info.pwm_per_nm(), 1200.0);
        assert!(info.servo_on() && info.high_temperature() && !info.communication_fault());
        assert_eq!(info.hand_side(), "left");
        assert_eq!(
            Info {
                hw_version: 0x0301,
                ..info
            }
            .pwm_per_nm(),
            800.0
        );
        let (_, t) = Report::decode(&data(0x0E4, &[30, 31, 32, 33])).unwrap();
        assert_eq!(
            t,
            Report::Temperature {
                finger: 1,
                celsius: [30, 31, 32, 33]
            }
        );
    }

    #[test]
    fn serial_numbers_read_as_wonik_shows_them() {
        assert_eq!(serial_text(b"AR123456"), "SAH040AR123456");
        assert_eq!(
            serial_text(&[b'A', b'R', 1, 0, 0, 0, 0, 0]),
            "SAH040AR\\x01"
        );
    }

    #[test]
    fn doc_protocol_frames_are_not_v4_reports() {
        // 0x3D3 is msg 0xF4: unknown in v4.
        assert!(matches!(
            Report::decode(&data(0x3D3, &[0; 8])),
            Err(DecodeError::UnknownCommand { .. })
        ));
        assert!(matches!(
            Report::decode(&data(0x080, &[0; 3])),
            Err(DecodeError::Length { .. })
        ));
    }

    proptest! {
        #[test]
        fn decoders_never_panic(
            raw_id in any::<u32>(),
            ext in any::<bool>(),
            rtr in any::<bool>(),
            payload in proptest::collection::vec(any::<u8>(), 0..=8),
        ) {
            let f = arbitrary_frame(raw_id, ext, rtr, &payload);
            let _ = Report::decode(&f);
            let _ = Request::decode(&f);
        }

        #[test]
        fn round_trips(dev in 0u8..4, finger in 0u8..4, pwm in any::<[i16; 4]>(), p in any::<[u16; 3]>(),
                       serial in any::<[u8; 8]>(), celsius in any::<[u8; 4]>(), raw in any::<[i16; 4]>()) {
            for r in [
                Request::Torque { finger, pwm },
                Request::SetPeriod { position_ms: p[0], imu_ms: p[1], temperature_ms: p[2] },
                Request::QueryInfo, Request::QuerySerial, Request::SystemOn, Request::SystemOff,
            ] {
                let f: TestFrame = r.encode(dev);
                prop_assert_eq!(Request::decode(&f).unwrap(), (dev, r));
            }
            for r in [
                Report::Position { finger, raw },
                Report::Serial(serial),
                Report::Temperature { finger, celsius },
                Report::Imu(p),
                Report::Info(Info { hw_version: p[0], fw_version: p[1], hand_type: celsius[0], temperature: celsius[1], status: celsius[2] }),
            ] {
                let f: TestFrame = r.encode(dev);
                prop_assert_eq!(Report::decode(&f).unwrap(), (dev, r));
            }
        }
    }
}
