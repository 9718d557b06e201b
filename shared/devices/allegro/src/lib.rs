//! The Wonik Allegro Hand's CAN protocols, as pure and total codecs.
//!
//! Two generations speak incompatible protocols on the same 1 Mbit/s bus:
//! - [`doc`]: the device document's protocol (hands 1.x to 3.x): 11-bit id
//!   `cmd << 6 | dest << 3 | src`, torque frames big-endian with a joint order that depends on the
//!   hand version ([`TorqueOrder`]), joint positions little-endian `u16` with zero at 32768;
//! - [`v4`]: the protocol of hands sold as v4 (SAH040...): id `msg << 2 | device`, every payload
//!   little-endian, signed positions, remote (RTR) queries for the hand's info and serial number.
//!
//! Both count 333.3/65536 degrees per position count. The codecs are generic over
//! [`embedded_can::Frame`], so they work with any transport's frame type; every decoder takes
//! any frame and returns a value or a [`DecodeError`], never panics.
//!
//! Facts beyond the document come from `docs/devices/allegro.md`, whose sources are cited by
//! their letters there: R1 (allegro_hand_ros, v1-v3), L (allegro_hand_linux), R4
//! (allegro_hand_ros_v4), W2 (Wonik's allegro_hand_ros2), fairo (facebookresearch/fairo).
//!
//! Must not depend on: any transport, iceoryx2, messages.

pub mod doc;
pub mod v4;

use embedded_can::{Frame, Id};

/// Fingers on the bus (index, middle, ring (the document's "pinky"/"little"), thumb), each one
/// frame of four joints.
pub const FINGERS: usize = 4;
/// Joints of the hand, in CAN order: finger `f`'s joint `k` is joint `4 f + k`.
pub const JOINTS: usize = 16;
/// Degrees spanned by 65536 position counts (document: `(raw - 32768) x 333.3/65536`).
pub const COUNTS_SPAN_DEG: f64 = 333.3;
/// The position count of joint zero in the document's protocol.
pub const DOC_ZERO: i32 = 32768;

/// Radians per position count.
fn rad_per_count() -> f64 {
    (COUNTS_SPAN_DEG / 65536.0).to_radians()
}

/// Position counts (relative to zero) to radians.
pub fn counts_to_rad(counts: f64) -> f64 {
    counts * rad_per_count()
}

/// Radians to position counts (relative to zero), not rounded.
pub fn rad_to_counts(rad: f64) -> f64 {
    rad / rad_per_count()
}

/// A hand's protocol generation: the node's `protocol` setting.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Generation {
    /// Hands 1.x: the document's protocol, torque joint order j0..j3.
    V1,
    /// Hands 2.x: the document's protocol, torque joint order j3..j0, 800 PWM per N m.
    V2,
    /// Hands 3.x (SAH030): the document's protocol, order j3..j0, 1200 PWM per N m (R1, L).
    V3,
    /// Hands sold as v4 (SAH040): the v4 protocol.
    V4,
}

/// The two wire protocols.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Protocol {
    /// The device document's (hands 1.x-3.x).
    Doc,
    /// The v4 protocol.
    V4,
}

impl std::fmt::Display for Protocol {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Protocol::Doc => "the document's protocol (v1-v3)",
            Protocol::V4 => "v4",
        })
    }
}

/// Where joint 0 sits in a torque frame of the document's protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TorqueOrder {
    /// Bytes 0-1 carry j0, then j1, j2, j3 (hands 1.x; v4 frames, little-endian).
    J0First,
    /// Bytes 0-1 carry j3, then j2, j1, j0 (hands 2.0 and up, the document's first snippet).
    J3First,
}

impl TorqueOrder {
    /// The joint (0..3) whose value is in slot `slot` (0..3) of a torque frame.
    pub fn joint_in_slot(self, slot: usize) -> usize {
        match self {
            TorqueOrder::J0First => slot,
            TorqueOrder::J3First => 3 - slot,
        }
    }
}

impl Generation {
    /// Every generation, oldest first.
    pub const ALL: [Generation; 4] = [
        Generation::V1,
        Generation::V2,
        Generation::V3,
        Generation::V4,
    ];

    /// The wire protocol it speaks.
    pub fn protocol(self) -> Protocol {
        match self {
            Generation::V4 => Protocol::V4,
            _ => Protocol::Doc,
        }
    }

    /// The joint order of its torque frames. The document gives j0-first for hands 1.0 "and
    /// down" and j3-first for 2.0 "and up"; L reverses for 1, 2 and 3 alike, which is why the
    /// generation is a setting per hand. v4 frames carry j0..j3 (R4, W2).
    pub fn torque_order(self) -> TorqueOrder {
        match self {
            Generation::V1 | Generation::V4 => TorqueOrder::J0First,
            Generation::V2 | Generation::V3 => TorqueOrder::J3First,
        }
    }

    /// PWM counts per N m: 800 in the document (SAH020, 8 V), 1200 for SAH030 (R1, L) and for
    /// 12 V v4 hands (R4 reads the hardware version: see [`v4::Info::pwm_per_nm`]).
    pub fn default_pwm_per_nm(self) -> f64 {
        match self {
            Generation::V1 | Generation::V2 => 800.0,
            Generation::V3 | Generation::V4 => 1200.0,
        }
    }

    /// The largest PWM magnitude the motors take: the global cap of the supply voltage
    /// (docs/devices/allegro.md: 800 at 8 V, 1200 at 12 V).
    pub fn default_pwm_limit(self) -> i16 {
        match self {
            Generation::V1 | Generation::V2 => 800,
            Generation::V3 | Generation::V4 => 1200,
        }
    }
}

impl std::fmt::Display for Generation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Generation::V1 => "v1",
            Generation::V2 => "v2",
            Generation::V3 => "v3",
            Generation::V4 => "v4",
        })
    }
}

impl std::str::FromStr for Generation {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "v1" | "1" => Ok(Generation::V1),
            "v2" | "2" => Ok(Generation::V2),
            "v3" | "3" => Ok(Generation::V3),
            "v4" | "4" => Ok(Generation::V4),
            other => Err(format!(
                "unknown Allegro protocol generation {other:?} (expected v1, v2, v3 or v4)"
            )),
        }
    }
}

/// Why a frame was not decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// An extended (29-bit) id: both protocols use standard ids only.
    #[error("extended id 0x{id:08X}: the Allegro protocols use 11-bit ids only")]
    Extended {
        /// The raw id.
        id: u32,
    },
    /// A remote frame where a data frame was expected (or the other way round).
    #[error("id 0x{id:03X}: a remote frame where a data frame is expected")]
    Remote {
        /// The id.
        id: u16,
    },
    /// A data frame where the protocol expects a remote frame.
    #[error("id 0x{id:03X}: a data frame where a remote frame is expected")]
    NotRemote {
        /// The id.
        id: u16,
    },
    /// A known id with the wrong payload length.
    #[error("id 0x{id:03X} ({what}): {got} data bytes, expected {expected}")]
    Length {
        /// The id.
        id: u16,
        /// What the id means.
        what: &'static str,
        /// The length(s) it takes, as text.
        expected: &'static str,
        /// The length it had.
        got: usize,
    },
    /// An id this protocol does not know (in this direction).
    #[error("id 0x{id:03X}: not a known command")]
    UnknownCommand {
        /// The id.
        id: u16,
    },
    /// A known command for a finger that does not exist.
    #[error("id 0x{id:03X}: finger {finger} does not exist")]
    BadFinger {
        /// The id.
        id: u16,
        /// The finger it names.
        finger: u8,
    },
}

/// The standard id of `frame`, or why it has none.
pub(crate) fn standard_id<F: Frame>(frame: &F) -> Result<u16, DecodeError> {
    match frame.id() {
        Id::Standard(id) => Ok(id.as_raw()),
        Id::Extended(id) => Err(DecodeError::Extended { id: id.as_raw() }),
    }
}

/// Builds a standard data frame. Ids and lengths come from this crate's own tables, which
/// are in range; a frame type that refuses one is a bug in it.
pub(crate) fn data_frame<F: Frame>(id: u16, data: &[u8]) -> F {
    embedded_can::StandardId::new(id)
        .and_then(|sid| F::new(sid, data))
        .expect("the protocol's ids are 11-bit and its payloads at most 8 bytes")
}

/// Builds a standard remote frame with DLC 0.
pub(crate) fn remote_frame<F: Frame>(id: u16) -> F {
    embedded_can::StandardId::new(id)
        .and_then(|sid| F::new_remote(sid, 0))
        .expect("the protocol's ids are 11-bit")
}

/// Which protocol a streamed frame belongs to, from its id: the document's position reports
/// (cmd 0x0F from a finger, src 3..6: ids 0x3C3..0x3FE) or v4's (messages 0x20..0x23 of any device:
/// ids 0x080..0x08F). Anything else says nothing (None). The two id ranges do not overlap, so
/// a hand of the other generation is named instead of misread (docs/devices/allegro.md,
/// "Two incompatible protocols").
pub fn detect<F: Frame>(frame: &F) -> Option<Protocol> {
    let id = standard_id(frame).ok()?;
    if frame.is_remote_frame() {
        return None;
    }
    let (cmd, _dest, src) = doc::split(id);
    if cmd == doc::CMD_POSITION && (doc::ID_DEVICE_SUB_01..=doc::ID_DEVICE_SUB_04).contains(&src) {
        return Some(Protocol::Doc);
    }
    if (0x080..=0x08F).contains(&id) {
        return Some(Protocol::V4);
    }
    None
}

/// One joint's calibration on a document-protocol hand: its encoder offset (counts) and
/// direction, and its motor's direction (R1's `zero.yaml`; per hand). v4 hands report calibrated
/// positions and need none.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JointCalibration {
    /// Encoder counts at the joint's zero, relative to 32768.
    pub offset: i32,
    /// +1 or -1: the encoder's direction (R1: `dir x raw - 32768 - offset`).
    pub encoder_dir: i8,
    /// +1 or -1: the motor's direction (PWM sign).
    pub motor_dir: i8,
}

impl Default for JointCalibration {
    fn default() -> Self {
        Self {
            offset: 0,
            encoder_dir: 1,
            motor_dir: 1,
        }
    }
}

/// +1 for any non-negative direction, -1 for a negative one.
fn sign(dir: i8) -> i32 {
    if dir < 0 {
        -1
    } else {
        1
    }
}

impl JointCalibration {
    /// The joint angle (rad) of a raw position count, R1's form: `(dir x raw - 32768 - offset)`
    /// counts. A direction of -1 makes the raw value negative, which is why R1's offsets for such
    /// joints are near -65536.
    pub fn doc_raw_to_rad(&self, raw: u16) -> f64 {
        let counts = sign(self.encoder_dir) * i32::from(raw) - DOC_ZERO - self.offset;
        counts_to_rad(f64::from(counts))
    }

    /// The raw count a hand with this calibration reports at `rad` (what a simulated hand
    /// sends), rounded and saturated to the u16 range.
    pub fn rad_to_doc_raw(&self, rad: f64) -> u16 {
        let counts = rad_to_counts(rad).round();
        let counts = if counts.is_finite() { counts } else { 0.0 };
        let raw = (counts + f64::from(DOC_ZERO) + f64::from(self.offset))
            * f64::from(sign(self.encoder_dir));
        raw.round().clamp(0.0, f64::from(u16::MAX)) as u16
    }
}

/// A v4 position count (signed, zero at the joint's zero) in radians.
pub fn v4_raw_to_rad(raw: i16) -> f64 {
    counts_to_rad(f64::from(raw))
}

/// Radians as a v4 position count, rounded and saturated (NaN: 0).
pub fn rad_to_v4_raw(rad: f64) -> i16 {
    let counts = rad_to_counts(rad).round();
    if counts.is_nan() {
        0
    } else {
        counts.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
    }
}

/// The PWM command for `torque_nm`: `torque x pwm_per_nm x motor_dir`, rounded, clamped to
/// `±limit` (a negative limit counts as 0). NaN or infinite torque or scale gives 0: never a
/// command beyond the limit (property-tested).
pub fn torque_to_pwm(torque_nm: f64, pwm_per_nm: f64, motor_dir: i8, limit: i16) -> i16 {
    let limit = f64::from(limit.max(0));
    let pwm = torque_nm * pwm_per_nm * f64::from(sign(motor_dir));
    if !pwm.is_finite() {
        return 0;
    }
    pwm.round().clamp(-limit, limit) as i16
}

/// The torque (N m) a PWM command asks for: `pwm / pwm_per_nm x motor_dir` (0 for a
/// non-positive or non-finite scale).
pub fn pwm_to_torque(pwm: i16, pwm_per_nm: f64, motor_dir: i8) -> f64 {
    if !(pwm_per_nm.is_finite() && pwm_per_nm > 0.0) {
        return 0.0;
    }
    f64::from(pwm) / pwm_per_nm * f64::from(sign(motor_dir))
}

#[cfg(test)]
pub(crate) mod test_frame {
    //! A minimal frame type for the tests (the crate depends on no transport).

    use embedded_can::{ExtendedId, Frame, Id, StandardId};

    /// A classic CAN frame.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct TestFrame {
        pub id: Id,
        pub remote: bool,
        pub dlc: usize,
        pub data: [u8; 8],
    }

    impl Frame for TestFrame {
        fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
            if data.len() > 8 {
                return None;
            }
            let mut d = [0u8; 8];
            d[..data.len()].copy_from_slice(data);
            Some(Self {
                id: id.into(),
                remote: false,
                dlc: data.len(),
                data: d,
            })
        }

        fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
            (dlc <= 8).then(|| Self {
                id: id.into(),
                remote: true,
                dlc,
                data: [0; 8],
            })
        }

        fn is_extended(&self) -> bool {
            matches!(self.id, Id::Extended(_))
        }

        fn is_remote_frame(&self) -> bool {
            self.remote
        }

        fn id(&self) -> Id {
            self.id
        }

        fn dlc(&self) -> usize {
            self.dlc
        }

        fn data(&self) -> &[u8] {
            if self.remote {
                &[]
            } else {
                &self.data[..self.dlc]
            }
        }
    }

    /// A standard data frame.
    pub fn data(id: u16, bytes: &[u8]) -> TestFrame {
        TestFrame::new(StandardId::new(id).expect("11-bit"), bytes).expect("<= 8 bytes")
    }

    /// A standard remote frame.
    pub fn remote(id: u16, dlc: usize) -> TestFrame {
        TestFrame::new_remote(StandardId::new(id).expect("11-bit"), dlc).expect("dlc <= 8")
    }

    /// An extended data frame.
    pub fn extended(id: u32, bytes: &[u8]) -> TestFrame {
        TestFrame::new(ExtendedId::new(id).expect("29-bit"), bytes).expect("<= 8 bytes")
    }

    /// Any frame: standard or extended, data or remote.
    pub fn arbitrary_frame(id: u32, extended: bool, remote: bool, bytes: &[u8]) -> TestFrame {
        let len = bytes.len().min(8);
        let frame = if extended {
            let id = ExtendedId::new(id & 0x1FFF_FFFF).expect("masked");
            if remote {
                TestFrame::new_remote(id, len)
            } else {
                TestFrame::new(id, &bytes[..len])
            }
        } else {
            let id = StandardId::new((id & 0x7FF) as u16).expect("masked");
            if remote {
                TestFrame::new_remote(id, len)
            } else {
                TestFrame::new(id, &bytes[..len])
            }
        };
        frame.expect("len <= 8")
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::test_frame::{data, extended, remote};
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn generations_parse_and_say_their_protocol() {
        for g in Generation::ALL {
            assert_eq!(g.to_string().parse::<Generation>().unwrap(), g);
        }
        assert_eq!(" V3 ".parse::<Generation>().unwrap(), Generation::V3);
        let err = "v5".parse::<Generation>().unwrap_err();
        assert!(
            err.contains("v5") && err.contains("v1, v2, v3 or v4"),
            "{err}"
        );
        assert_eq!(Generation::V3.protocol(), Protocol::Doc);
        assert_eq!(Generation::V4.protocol(), Protocol::V4);
        assert_eq!(Generation::V1.torque_order(), TorqueOrder::J0First);
        assert_eq!(Generation::V2.torque_order(), TorqueOrder::J3First);
        assert_eq!(Generation::V2.default_pwm_per_nm(), 800.0);
        assert_eq!(Generation::V3.default_pwm_per_nm(), 1200.0);
    }

    #[test]
    fn the_documents_angle_conversion() {
        // Document: ang = (raw - 32768) x 333.3/65536 degrees.
        let cal = JointCalibration::default();
        assert_eq!(cal.doc_raw_to_rad(32768), 0.0);
        // A quarter of the count range (raw 49152) is a quarter of 333.3 degrees.
        let deg = cal.doc_raw_to_rad(49152).to_degrees();
        assert!((deg - 333.3 / 4.0).abs() < 1e-9, "{deg}");
        // 90 degrees is 17 696.49 counts: 32768 + 17696 after rounding, and back within a count.
        let raw = cal.rad_to_doc_raw(std::f64::consts::FRAC_PI_2);
        assert_eq!(raw, 32768 + 17696);
        let back = cal.doc_raw_to_rad(raw);
        assert!((back - std::f64::consts::FRAC_PI_2).abs() < counts_to_rad(1.0));
    }

    #[test]
    fn calibration_offsets_and_directions_as_r1_applies_them() {
        // R1's zero.yaml of SAH030C033R: index j0 offset -1591 counts.
        let cal = JointCalibration {
            offset: -1591,
            encoder_dir: 1,
            motor_dir: 1,
        };
        assert_eq!(cal.doc_raw_to_rad(32768 - 1591), 0.0);
        // A v1 joint with encoder direction -1 and an offset near -65536 (zero_SAH01010002).
        let cal = JointCalibration {
            offset: -65536 + 1000,
            encoder_dir: -1,
            motor_dir: -1,
        };
        // -raw - 32768 + 65536 - 1000 = 0 at raw = 31768.
        assert_eq!(cal.doc_raw_to_rad(31768), 0.0);
        let raw = cal.rad_to_doc_raw(0.5);
        assert!((cal.doc_raw_to_rad(raw) - 0.5).abs() < counts_to_rad(1.0));
        // The motor direction flips the PWM sign.
        assert_eq!(torque_to_pwm(0.1, 800.0, cal.motor_dir, 800), -80);
    }

    #[test]
    fn v4_positions_are_signed_counts_from_zero() {
        assert_eq!(v4_raw_to_rad(0), 0.0);
        assert_eq!(rad_to_v4_raw(v4_raw_to_rad(-1234)), -1234);
        assert_eq!(rad_to_v4_raw(1e9), i16::MAX);
        assert_eq!(rad_to_v4_raw(f64::NAN), 0);
    }

    #[test]
    fn the_documents_torque_scale() {
        // Document: PWM = 0.1 N m x 800.
        assert_eq!(torque_to_pwm(0.1, 800.0, 1, 800), 80);
        assert_eq!(torque_to_pwm(-2.0, 800.0, 1, 800), -800);
        assert_eq!(torque_to_pwm(2.0, 1200.0, 1, 675), 675);
        assert_eq!(torque_to_pwm(f64::NAN, 800.0, 1, 800), 0);
        assert_eq!(torque_to_pwm(1.0, f64::INFINITY, 1, 800), 0);
        assert_eq!(pwm_to_torque(80, 800.0, 1), 0.1);
        assert_eq!(pwm_to_torque(80, 0.0, 1), 0.0);
    }

    #[test]
    fn detection_by_the_streamed_position_ids() {
        // Document: finger 0 reports cmd 0x0F, dest ID_DEVICE_MAIN, src 3: id 0x3D3.
        assert_eq!(detect(&data(0x3D3, &[0; 8])), Some(Protocol::Doc));
        assert_eq!(detect(&data(0x3D6, &[0; 8])), Some(Protocol::Doc));
        // v4 device 0, fingers 0..3: 0x080..0x08C; device 3 finger 3: 0x08F.
        assert_eq!(detect(&data(0x080, &[0; 8])), Some(Protocol::V4));
        assert_eq!(detect(&data(0x08F, &[0; 8])), Some(Protocol::V4));
        // Commands, remote frames and extended ids say nothing.
        assert_eq!(detect(&data(0x04A, &[])), None);
        assert_eq!(detect(&remote(0x080, 0)), None);
        assert_eq!(detect(&extended(0x3D3, &[0; 8])), None);
    }

    proptest! {
        #[test]
        fn pwm_never_exceeds_its_limit(
            torque in proptest::num::f64::ANY,
            scale in proptest::num::f64::ANY,
            dir in any::<i8>(),
            limit in any::<i16>(),
        ) {
            let pwm = torque_to_pwm(torque, scale, dir, limit);
            prop_assert!(i32::from(pwm).abs() <= i32::from(limit.max(0)));
        }

        #[test]
        fn calibrated_positions_round_trip_within_a_count(
            rad in -2.5f64..2.5,
            offset in -3000i32..3000,
            dir in prop_oneof![Just(1i8), Just(-1i8)],
        ) {
            let offset = if dir < 0 { offset - 65536 } else { offset };
            let cal = JointCalibration { offset, encoder_dir: dir, motor_dir: 1 };
            let back = cal.doc_raw_to_rad(cal.rad_to_doc_raw(rad));
            prop_assert!((back - rad).abs() <= counts_to_rad(0.5) + 1e-12, "{rad} -> {back}");
        }

        #[test]
        fn conversions_never_panic(raw in any::<u16>(), offset in any::<i32>(), dir in any::<i8>(), rad in proptest::num::f64::ANY) {
            let cal = JointCalibration { offset: offset / 2, encoder_dir: dir, motor_dir: dir };
            let _ = cal.doc_raw_to_rad(raw);
            let _ = cal.rad_to_doc_raw(rad);
            let _ = rad_to_v4_raw(rad);
        }
    }
}
