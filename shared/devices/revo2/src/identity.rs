//! Device identity (section 1) and the orders of joints and fingertips.

/// EtherCAT vendor ID of BrainCo (section 1, also 0x1018:01).
pub const VENDOR_ID: u32 = 0x00BC_0000;
/// EtherCAT product code of the Revo2 slave (section 1, also 0x1018:02).
pub const PRODUCT_CODE: u32 = 0x0000_9252;
/// Revision number (section 1, also 0x1018:03).
pub const REVISION: u32 = 1;
/// Device name (section 1, also 0x1008).
pub const DEVICE_NAME: &str = "BrainCo-Revo2Slave";
/// Vendor name (section 1).
pub const VENDOR_NAME: &str = "BrainCo";

/// Number of actuated joints (motors).
pub const JOINTS: usize = 6;
/// Number of fingertips with a tactile sensor.
pub const FINGERTIPS: usize = 5;

/// One actuated joint, in the order of `finger_index_t` (section 2.2), which
/// is also the order of every 6-element array of the process data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Joint {
    /// `THUMB_FLEX` (拇指尖部, thumb tip / flexion), 0.
    ThumbFlex = 0,
    /// `THUMB_ABDUCT` (拇指根部, thumb root / abduction), 1.
    ThumbAbduct = 1,
    /// `INDEX_FINGER`, 2.
    Index = 2,
    /// `MIDDLE_FINGER`, 3.
    Middle = 3,
    /// `RING_FINGER`, 4.
    Ring = 4,
    /// `PINKY`, 5.
    Pinky = 5,
}

impl Joint {
    /// All joints in wire order.
    pub const ALL: [Joint; JOINTS] = [
        Joint::ThumbFlex,
        Joint::ThumbAbduct,
        Joint::Index,
        Joint::Middle,
        Joint::Ring,
        Joint::Pinky,
    ];

    /// The joint with `finger_index_t` value `id`, if any (0..=5).
    pub const fn from_u8(id: u8) -> Option<Joint> {
        match id {
            0 => Some(Joint::ThumbFlex),
            1 => Some(Joint::ThumbAbduct),
            2 => Some(Joint::Index),
            3 => Some(Joint::Middle),
            4 => Some(Joint::Ring),
            5 => Some(Joint::Pinky),
            _ => None,
        }
    }

    /// The `finger_index_t` value (0..=5), also the array index.
    pub const fn id(self) -> u8 {
        self as u8
    }

    /// Array index of the joint in the 6-element process-data arrays.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Short snake-case name ([`JOINT_NAMES`]).
    pub const fn name(self) -> &'static str {
        JOINT_NAMES[self as usize]
    }

    /// Index into the 5-element tactile arrays ([`FINGERTIP_NAMES`]) of the
    /// finger this joint moves (both thumb joints give the thumb, 0).
    pub const fn fingertip(self) -> usize {
        match self {
            Joint::ThumbFlex | Joint::ThumbAbduct => 0,
            Joint::Index => 1,
            Joint::Middle => 2,
            Joint::Ring => 3,
            Joint::Pinky => 4,
        }
    }
}

/// Names of the joints in wire order (`finger_index_t`).
pub const JOINT_NAMES: [&str; JOINTS] = [
    "thumb_flex",
    "thumb_abduct",
    "index",
    "middle",
    "ring",
    "pinky",
];

/// Names of the fingertips in the order of the 5-element tactile arrays.
///
/// The tactile configuration object 0x8010 orders its per-finger entries
/// thumb, index, middle, ring, pinky. The document does not give the order
/// of the arrays of the tactile process data 0x6010; we assume it is the
/// same (ambiguity 3 of the crate docs).
pub const FINGERTIP_NAMES: [&str; FINGERTIPS] = ["thumb", "index", "middle", "ring", "pinky"];
