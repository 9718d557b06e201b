//! The device document's protocol (hands 1.x-3.x).
//!
//! Ids. The document's text says the 32-bit id splits into a 26-bit command and 3-bit
//! destination and source ids, but its sample code builds an 11-bit standard id
//! `cmd << 6 | dest << 3 | src` and decodes `cmd = (id >> 6) & 0x1F`: the code is what hands and
//! every driver use (docs/devices/allegro.md: R1, L), so this module does the same.
//!
//! Direction. The host always sends destination `ID_COMMON` (1) and source `ID_DEVICE_MAIN` (2),
//! so a host command's id is `cmd << 6 | 0x0A`. The hand's position reports come from the finger
//! (`src` 3..6). Their destination is not checked: the document's table says `ID_DEVICE_MAIN`,
//! no driver checks it (docs/devices/allegro.md).
//!
//! Joint state. The document's command table lists `ID_CMD_QUERY_STATE_DATA` (0x0E) twice: as
//! the host's request (`ID_COMMON` <- `ID_DEVICE_MAIN`, [`Request::QueryState`]) and as the
//! "joint state response" from `ID_DEVICE_SUB_01..04` to `ID_DEVICE_MAIN`
//! ([`Report::State`]); the stream's position frames are `ID_CMD_QUERY_CONTROL_DATA` (0x0F,
//! [`Report::Position`]), the only ones its decoding sample and every driver decode. The
//! document gives no payload for the 0x0E answer, so [`Report::State`] keeps its bytes as they
//! came (a hand may lay them out as a position frame; nothing here assumes it).
//!
//! Torque frames are big-endian `i16` PWM counts in the joint order of the hand version
//! ([`TorqueOrder`](crate::TorqueOrder)); position frames are little-endian `u16` counts, zero at
//! 32768. `QUERY_ID` (0x10) and its reply are not in the document (R1, L).

use embedded_can::Frame;

use crate::{data_frame, standard_id, DecodeError, TorqueOrder};

/// The hand (destination of host commands).
pub const ID_COMMON: u8 = 0x01;
/// The control PC (source of host commands).
pub const ID_DEVICE_MAIN: u8 = 0x02;
/// The index finger.
pub const ID_DEVICE_SUB_01: u8 = 0x03;
/// The middle finger.
pub const ID_DEVICE_SUB_02: u8 = 0x04;
/// The third finger (the document's "pinky"/"little"; the ring finger's place).
pub const ID_DEVICE_SUB_03: u8 = 0x05;
/// The thumb.
pub const ID_DEVICE_SUB_04: u8 = 0x06;

/// Start periodic communication.
pub const CMD_SYSTEM_ON: u8 = 0x01;
/// Stop periodic communication.
pub const CMD_SYSTEM_OFF: u8 = 0x02;
/// Set the communication period (one byte, ms).
pub const CMD_SET_PERIOD: u8 = 0x03;
/// Joint command transmission mode.
pub const CMD_SET_MODE_JOINT: u8 = 0x04;
/// Task command transmission mode.
pub const CMD_SET_MODE_TASK: u8 = 0x05;
/// Torque of finger 0; fingers 1..3 follow (0x06..0x09).
pub const CMD_SET_TORQUE_1: u8 = 0x06;
/// Position commands (0x0A..0x0D): unused.
pub const CMD_SET_POSITION_1: u8 = 0x0A;
/// Request the joint state (host -> hand); also the id of the hand's answer, one frame per
/// finger ([`Report::State`]).
pub const CMD_QUERY_STATE_DATA: u8 = 0x0E;
/// Joint positions of one finger (hand -> host; the document's `ID_CMD_QUERY_CONTROL_DATA`).
pub const CMD_POSITION: u8 = 0x0F;
/// Ask for the hand's revision and firmware (R1, L; not in the document).
pub const CMD_QUERY_ID: u8 = 0x10;
/// Set the AHRS rate and mask (L; not sent by this crate).
pub const CMD_AHRS_SET: u8 = 0x11;

/// The 11-bit id `cmd << 6 | dest << 3 | src` (each field masked to its width).
pub fn id(cmd: u8, dest: u8, src: u8) -> u16 {
    (u16::from(cmd & 0x1F) << 6) | (u16::from(dest & 0x07) << 3) | u16::from(src & 0x07)
}

/// `(cmd, dest, src)` of an id, as the document's decoding sample splits it.
pub fn split(id: u16) -> (u8, u8, u8) {
    (
        ((id >> 6) & 0x1F) as u8,
        ((id >> 3) & 0x07) as u8,
        (id & 0x07) as u8,
    )
}

/// The id of a host command.
fn host_id(cmd: u8) -> u16 {
    id(cmd, ID_COMMON, ID_DEVICE_MAIN)
}

/// A host -> hand command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// Start streaming (and applying torques).
    SystemOn,
    /// Stop streaming; torques off.
    SystemOff,
    /// Period of the stream in ms (3 in every driver).
    SetPeriod {
        /// Milliseconds.
        ms: u8,
    },
    /// Joint mode.
    ModeJoint,
    /// Task mode (the mode drivers set).
    ModeTask,
    /// PWM torque commands of one finger's four joints, j0..j3 (the frame's order is the hand
    /// version's).
    Torque {
        /// Finger 0..3.
        finger: u8,
        /// PWM counts of joints 0..3.
        pwm: [i16; 4],
    },
    /// Request the joint state.
    QueryState,
    /// Ask for the hand's revision and firmware.
    QueryId,
}

impl Request {
    /// This command as a frame (the host's destination and source), torque values in `order`.
    /// A torque command for a finger beyond 3 addresses finger `finger % 4`.
    pub fn encode<F: Frame>(&self, order: TorqueOrder) -> F {
        match *self {
            Request::SystemOn => data_frame(host_id(CMD_SYSTEM_ON), &[]),
            Request::SystemOff => data_frame(host_id(CMD_SYSTEM_OFF), &[]),
            Request::SetPeriod { ms } => data_frame(host_id(CMD_SET_PERIOD), &[ms]),
            Request::ModeJoint => data_frame(host_id(CMD_SET_MODE_JOINT), &[]),
            Request::ModeTask => data_frame(host_id(CMD_SET_MODE_TASK), &[]),
            Request::Torque { finger, pwm } => {
                let mut bytes = [0u8; 8];
                for slot in 0..4 {
                    let value = pwm[order.joint_in_slot(slot)];
                    bytes[2 * slot..2 * slot + 2].copy_from_slice(&value.to_be_bytes());
                }
                data_frame(host_id(CMD_SET_TORQUE_1 + finger % 4), &bytes)
            }
            Request::QueryState => data_frame(host_id(CMD_QUERY_STATE_DATA), &[]),
            Request::QueryId => data_frame(host_id(CMD_QUERY_ID), &[]),
        }
    }

    /// What a frame on the bus asks of the hand (the simulated hand's side), torque values read
    /// in `order`. Like the drivers, the hand matches on the command only: destination and
    /// source are not checked. Lengths are checked where the command carries data (torque: 8;
    /// period: at least 1).
    pub fn decode<F: Frame>(frame: &F, order: TorqueOrder) -> Result<Request, DecodeError> {
        let id = standard_id(frame)?;
        if frame.is_remote_frame() {
            return Err(DecodeError::Remote { id });
        }
        let data = frame.data();
        let (cmd, _, src) = split(id);
        // Reports from a finger are not requests.
        if (ID_DEVICE_SUB_01..=ID_DEVICE_SUB_04).contains(&src) {
            return Err(DecodeError::UnknownCommand { id });
        }
        Ok(match cmd {
            CMD_SYSTEM_ON => Request::SystemOn,
            CMD_SYSTEM_OFF => Request::SystemOff,
            CMD_SET_PERIOD => match data.first() {
                Some(&ms) => Request::SetPeriod { ms },
                None => {
                    return Err(DecodeError::Length {
                        id,
                        what: "SET_PERIOD",
                        expected: "1",
                        got: 0,
                    })
                }
            },
            CMD_SET_MODE_JOINT => Request::ModeJoint,
            CMD_SET_MODE_TASK => Request::ModeTask,
            c @ CMD_SET_TORQUE_1..=0x09 => {
                let bytes: &[u8; 8] = data.try_into().map_err(|_| DecodeError::Length {
                    id,
                    what: "SET_TORQUE",
                    expected: "8",
                    got: data.len(),
                })?;
                let mut pwm = [0i16; 4];
                for slot in 0..4 {
                    pwm[order.joint_in_slot(slot)] =
                        i16::from_be_bytes([bytes[2 * slot], bytes[2 * slot + 1]]);
                }
                Request::Torque {
                    finger: c - CMD_SET_TORQUE_1,
                    pwm,
                }
            }
            CMD_QUERY_STATE_DATA => Request::QueryState,
            CMD_QUERY_ID => Request::QueryId,
            _ => return Err(DecodeError::UnknownCommand { id }),
        })
    }
}

/// A hand -> host report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Report {
    /// One finger's four raw joint positions (u16 counts, zero at 32768 before calibration).
    Position {
        /// Finger 0..3.
        finger: u8,
        /// Raw counts of joints 0..3.
        raw: [u16; 4],
    },
    /// One finger's answer to `QUERY_STATE_DATA` (the document: 0x0E from `ID_DEVICE_SUB_01..04`
    /// to `ID_DEVICE_MAIN`, "joint state response"). Its payload is not documented: the bytes
    /// as they came, any length 0..8.
    State {
        /// Finger 0..3.
        finger: u8,
        /// Payload length.
        len: u8,
        /// Payload (bytes past `len` are 0).
        data: [u8; 8],
    },
    /// The reply to `QUERY_ID` (R1, L): revision u16 LE at byte 2, firmware u16 LE at byte 4,
    /// hardware type u8 at byte 7.
    Id {
        /// Hardware revision.
        revision: u16,
        /// Firmware version.
        firmware: u16,
        /// Hardware type.
        hw_type: u8,
    },
}

impl Report {
    /// This report as the hand sends it, addressed to `dest` (the document: `ID_DEVICE_MAIN`).
    /// Positions come from the finger (src 3..6; finger taken modulo 4), the id reply from
    /// `ID_COMMON`.
    pub fn encode<F: Frame>(&self, dest: u8) -> F {
        match *self {
            Report::Position { finger, raw } => {
                let mut bytes = [0u8; 8];
                for (k, r) in raw.iter().enumerate() {
                    bytes[2 * k..2 * k + 2].copy_from_slice(&r.to_le_bytes());
                }
                data_frame(
                    id(CMD_POSITION, dest, ID_DEVICE_SUB_01 + finger % 4),
                    &bytes,
                )
            }
            Report::State { finger, len, data } => data_frame(
                id(CMD_QUERY_STATE_DATA, dest, ID_DEVICE_SUB_01 + finger % 4),
                &data[..usize::from(len.min(8))],
            ),
            Report::Id {
                revision,
                firmware,
                hw_type,
            } => {
                let mut bytes = [0u8; 8];
                bytes[2..4].copy_from_slice(&revision.to_le_bytes());
                bytes[4..6].copy_from_slice(&firmware.to_le_bytes());
                bytes[7] = hw_type;
                data_frame(id(CMD_QUERY_ID, dest, ID_COMMON), &bytes)
            }
        }
    }

    /// What a frame from the hand reports. Positions need 8 bytes and a finger source (3..6);
    /// a state answer a finger source (any length); the id reply 8 bytes from a non-finger
    /// source. Anything else is an error (a host
    /// command on the bus is `UnknownCommand` here: it is not a report).
    pub fn decode<F: Frame>(frame: &F) -> Result<Report, DecodeError> {
        let id = standard_id(frame)?;
        if frame.is_remote_frame() {
            return Err(DecodeError::Remote { id });
        }
        let data = frame.data();
        let (cmd, _, src) = split(id);
        match cmd {
            CMD_POSITION => {
                if !(ID_DEVICE_SUB_01..=ID_DEVICE_SUB_04).contains(&src) {
                    return Err(DecodeError::BadFinger {
                        id,
                        finger: src.wrapping_sub(ID_DEVICE_SUB_01),
                    });
                }
                let bytes: &[u8; 8] = data.try_into().map_err(|_| DecodeError::Length {
                    id,
                    what: "joint positions",
                    expected: "8",
                    got: data.len(),
                })?;
                let raw =
                    std::array::from_fn(|k| u16::from_le_bytes([bytes[2 * k], bytes[2 * k + 1]]));
                Ok(Report::Position {
                    finger: src - ID_DEVICE_SUB_01,
                    raw,
                })
            }
            // From a finger it is the answer; from anyone else the host's request.
            CMD_QUERY_STATE_DATA if (ID_DEVICE_SUB_01..=ID_DEVICE_SUB_04).contains(&src) => {
                let mut bytes = [0u8; 8];
                let n = data.len().min(8);
                bytes[..n].copy_from_slice(&data[..n]);
                Ok(Report::State {
                    finger: src - ID_DEVICE_SUB_01,
                    len: n as u8,
                    data: bytes,
                })
            }
            CMD_QUERY_ID if src != ID_DEVICE_MAIN => {
                let bytes: &[u8; 8] = data.try_into().map_err(|_| DecodeError::Length {
                    id,
                    what: "QUERY_ID reply",
                    expected: "8",
                    got: data.len(),
                })?;
                Ok(Report::Id {
                    revision: u16::from_le_bytes([bytes[2], bytes[3]]),
                    firmware: u16::from_le_bytes([bytes[4], bytes[5]]),
                    hw_type: bytes[7],
                })
            }
            _ => Err(DecodeError::UnknownCommand { id }),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::test_frame::{arbitrary_frame, data, extended, remote, TestFrame};
    use embedded_can::Frame;
    use proptest::prelude::*;

    fn bytes(f: &TestFrame) -> (u16, Vec<u8>) {
        (standard_id(f).unwrap(), f.data().to_vec())
    }

    #[test]
    fn host_commands_known_answers() {
        // Computed by hand from the document's sample code: Txid = cmd << 6 | 1 << 3 | 2.
        let o = TorqueOrder::J3First;
        let enc = |r: Request| bytes(&r.encode::<TestFrame>(o));
        assert_eq!(enc(Request::SystemOn), (0x04A, vec![]));
        assert_eq!(enc(Request::SystemOff), (0x08A, vec![]));
        assert_eq!(enc(Request::SetPeriod { ms: 3 }), (0x0CA, vec![3]));
        assert_eq!(enc(Request::ModeJoint), (0x10A, vec![]));
        assert_eq!(enc(Request::ModeTask), (0x14A, vec![]));
        assert_eq!(enc(Request::QueryState), (0x38A, vec![]));
        assert_eq!(enc(Request::QueryId), (0x40A, vec![]));
    }

    #[test]
    fn torque_frames_in_both_joint_orders() {
        // The document's example: 0.1 N m x 800 = 80 = 0x0050 on every joint, finger 0.
        let same = Request::Torque {
            finger: 0,
            pwm: [80; 4],
        };
        assert_eq!(
            bytes(&same.encode::<TestFrame>(TorqueOrder::J3First)),
            (0x18A, vec![0x00, 0x50, 0x00, 0x50, 0x00, 0x50, 0x00, 0x50])
        );
        // Distinct values show the order: 2.0+ sends pwm[3] first, 1.0 pwm[0] first.
        let t = Request::Torque {
            finger: 3,
            pwm: [0x0102, 0x0304, -2, 0x0708],
        };
        assert_eq!(
            bytes(&t.encode::<TestFrame>(TorqueOrder::J3First)),
            (0x24A, vec![0x07, 0x08, 0xFF, 0xFE, 0x03, 0x04, 0x01, 0x02])
        );
        assert_eq!(
            bytes(&t.encode::<TestFrame>(TorqueOrder::J0First)),
            (0x24A, vec![0x01, 0x02, 0x03, 0x04, 0xFF, 0xFE, 0x07, 0x08])
        );
        for order in [TorqueOrder::J0First, TorqueOrder::J3First] {
            let f: TestFrame = t.encode(order);
            assert_eq!(Request::decode(&f, order).unwrap(), t);
        }
    }

    #[test]
    fn position_reports_known_answers() {
        // Finger 0 (src 3) to ID_DEVICE_MAIN: id 0x0F << 6 | 2 << 3 | 3 = 0x3D3; LE u16.
        let r = Report::Position {
            finger: 0,
            raw: [32768, 0x1234, 0, 0xFFFF],
        };
        assert_eq!(
            bytes(&r.encode::<TestFrame>(ID_DEVICE_MAIN)),
            (0x3D3, vec![0x00, 0x80, 0x34, 0x12, 0x00, 0x00, 0xFF, 0xFF])
        );
        assert_eq!(
            Report::decode(&data(0x3D3, &[0x00, 0x80, 0x34, 0x12, 0, 0, 0xFF, 0xFF])).unwrap(),
            r
        );
        // The thumb (src 6) with another destination: dest is not checked.
        let thumb = Report::decode(&data(0x3C6, &[0; 8])).unwrap();
        assert_eq!(
            thumb,
            Report::Position {
                finger: 3,
                raw: [0; 4]
            }
        );
    }

    #[test]
    fn state_answers_are_told_from_positions_and_from_the_request() {
        // The document's table: 0x0E from ID_DEVICE_SUB_01 (3) to ID_DEVICE_MAIN (2): 0x393.
        let r = Report::State {
            finger: 0,
            len: 8,
            data: [1, 2, 3, 4, 5, 6, 7, 8],
        };
        assert_eq!(
            bytes(&r.encode::<TestFrame>(ID_DEVICE_MAIN)),
            (0x393, vec![1, 2, 3, 4, 5, 6, 7, 8])
        );
        assert_eq!(
            Report::decode(&data(0x393, &[1, 2, 3, 4, 5, 6, 7, 8])).unwrap(),
            r
        );
        // No payload: still the thumb's state answer, not a position.
        assert_eq!(
            Report::decode(&data(0x396, &[])).unwrap(),
            Report::State {
                finger: 3,
                len: 0,
                data: [0; 8]
            }
        );
        // The host's request (src 2) is not a report, and a finger's answer not a request.
        assert!(matches!(
            Report::decode(&data(0x38A, &[])),
            Err(DecodeError::UnknownCommand { id: 0x38A })
        ));
        assert!(Request::decode(&data(0x393, &[]), TorqueOrder::J0First).is_err());
    }

    #[test]
    fn id_reply_as_r1_reads_it() {
        let r = Report::Id {
            revision: 0x0302,
            firmware: 0x0105,
            hw_type: 7,
        };
        let f: TestFrame = r.encode(ID_DEVICE_MAIN);
        assert_eq!(bytes(&f), (0x411, vec![0, 0, 0x02, 0x03, 0x05, 0x01, 0, 7]));
        assert_eq!(Report::decode(&f).unwrap(), r);
        // The host's QUERY_ID request (src 2) is not a reply.
        assert!(matches!(
            Report::decode(&data(0x40A, &[])),
            Err(DecodeError::UnknownCommand { id: 0x40A })
        ));
    }

    #[test]
    fn bad_frames_are_typed_errors() {
        assert!(matches!(
            Report::decode(&data(0x3D3, &[0; 7])),
            Err(DecodeError::Length { got: 7, .. })
        ));
        assert!(matches!(
            Report::decode(&data(0x3D2, &[0; 8])),
            Err(DecodeError::BadFinger { .. })
        ));
        assert!(matches!(
            Report::decode(&remote(0x3D3, 8)),
            Err(DecodeError::Remote { .. })
        ));
        assert!(matches!(
            Report::decode(&extended(0x3D3, &[0; 8])),
            Err(DecodeError::Extended { .. })
        ));
        assert!(matches!(
            Request::decode(&data(0x18A, &[0; 4]), TorqueOrder::J0First),
            Err(DecodeError::Length { got: 4, .. })
        ));
        assert!(matches!(
            Request::decode(&data(0x0CA, &[]), TorqueOrder::J0First),
            Err(DecodeError::Length { .. })
        ));
        // A position report is not a request.
        assert!(Request::decode(&data(0x3D3, &[0; 8]), TorqueOrder::J0First).is_err());
        let text = Report::decode(&data(0x3D3, &[0; 2]))
            .unwrap_err()
            .to_string();
        assert!(
            text.contains("0x3D3") && text.contains("joint positions"),
            "{text}"
        );
    }

    #[test]
    fn split_undoes_id() {
        for cmd in 0..32u8 {
            for dest in 0..8u8 {
                for src in 0..8u8 {
                    assert_eq!(split(id(cmd, dest, src)), (cmd, dest, src));
                }
            }
        }
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
            let _ = Request::decode(&f, TorqueOrder::J0First);
            let _ = Request::decode(&f, TorqueOrder::J3First);
        }

        #[test]
        fn requests_round_trip(finger in 0u8..4, pwm in any::<[i16; 4]>(), ms in any::<u8>(), j3 in any::<bool>()) {
            let order = if j3 { TorqueOrder::J3First } else { TorqueOrder::J0First };
            for r in [Request::Torque { finger, pwm }, Request::SetPeriod { ms }, Request::SystemOn, Request::QueryId] {
                let f: TestFrame = r.encode(order);
                prop_assert_eq!(Request::decode(&f, order).unwrap(), r);
            }
        }

        #[test]
        fn reports_round_trip(finger in 0u8..4, raw in any::<[u16; 4]>(), rev in any::<u16>(), fw in any::<u16>(), hw in any::<u8>()) {
            let mut state = [0u8; 8];
            state[..2].copy_from_slice(&rev.to_le_bytes());
            let len = hw % 9;
            state[usize::from(len)..].fill(0);
            for r in [Report::Position { finger, raw }, Report::State { finger, len, data: state }, Report::Id { revision: rev, firmware: fw, hw_type: hw }] {
                let f: TestFrame = r.encode(ID_DEVICE_MAIN);
                prop_assert_eq!(Report::decode(&f).unwrap(), r);
            }
        }
    }
}
