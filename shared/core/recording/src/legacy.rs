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

use crate::file::normalised;
use teleop_msgs::{
    fingertip_sensor, link_kind, Fingertip, HandState, JointState, Message, SampleHeader, Tactile,
    MAX_FINGERTIPS, MAX_JOINTS,
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

/// A recorded payload layout of an earlier contract version that this build converts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Legacy {
    /// `HandState` of contract version 1.
    HandStateV1,
    /// `Tactile` of contract version 1.
    TactileV1,
}

impl Legacy {
    /// The earlier layout of the contract type `schema_name` whose (normalised) schema text is
    /// `text`, if any.
    pub(crate) fn recognise(schema_name: &str, text: &[&str]) -> Option<Self> {
        [Self::HandStateV1, Self::TactileV1]
            .into_iter()
            .find(|legacy| {
                legacy.schema_name() == schema_name && normalised(legacy.schema()) == text
            })
    }

    fn schema_name(self) -> &'static str {
        match self {
            Self::HandStateV1 => HandState::SCHEMA_NAME,
            Self::TactileV1 => Tactile::SCHEMA_NAME,
        }
    }

    fn schema(self) -> &'static str {
        match self {
            Self::HandStateV1 => HAND_STATE_V1_SCHEMA,
            Self::TactileV1 => TACTILE_V1_SCHEMA,
        }
    }

    /// The contract version of this layout.
    pub(crate) fn version(self) -> u32 {
        match self {
            Self::HandStateV1 | Self::TactileV1 => 1,
        }
    }

    /// Payload size in this layout.
    pub(crate) fn size(self) -> usize {
        match self {
            Self::HandStateV1 => hand_state_v1::SIZE,
            Self::TactileV1 => tactile_v1::SIZE,
        }
    }

    /// The current payload's bytes for `bytes` in this layout (the caller checks the size;
    /// missing bytes would read as zero).
    pub(crate) fn convert(self, bytes: &[u8]) -> Vec<u8> {
        match self {
            Self::HandStateV1 => hand_state_from_v1(bytes).as_bytes().to_vec(),
            Self::TactileV1 => tactile_from_v1(bytes).as_bytes().to_vec(),
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
