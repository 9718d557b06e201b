//! The Hand E's joints and the motors that drive them (notes/shadow.md, "Motors, units,
//! limits": E's `mappings/default_mappings`; C's `general_info.yaml` picks one per hand).
//!
//! Joint order FFJ0-4, MFJ0-4, RFJ0-4, LFJ0-5, THJ1-5, WRJ1-2 (26 entries; J0 is the coupled
//! distal pair J1 + J2 of a finger, driven by one motor, so J1 and J2 have none).

/// Joints in the mapping order.
pub const JOINT_NAMES: [&str; 26] = [
    "FFJ0", "FFJ1", "FFJ2", "FFJ3", "FFJ4", "MFJ0", "MFJ1", "MFJ2", "MFJ3", "MFJ4", "RFJ0", "RFJ1",
    "RFJ2", "RFJ3", "RFJ4", "LFJ0", "LFJ1", "LFJ2", "LFJ3", "LFJ4", "LFJ5", "THJ1", "THJ2", "THJ3",
    "THJ4", "THJ5",
];

/// The wrist joints that follow [`JOINT_NAMES`] in every mapping.
pub const WRIST_NAMES: [&str; 2] = ["WRJ1", "WRJ2"];

/// A joint -> motor mapping of a Hand E generation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mapping {
    /// `rh_E_v3` (the launch default).
    EV3,
    /// `rh_E_v4`.
    EV4,
    /// `rh_E_v5`.
    EV5,
}

impl Mapping {
    /// Motor (0..19) per joint of [`JOINT_NAMES`] then [`WRIST_NAMES`]; -1: no motor.
    pub fn table(self) -> [i8; 28] {
        match self {
            Mapping::EV3 => [
                0, -1, -1, 1, 2, 3, -1, -1, 11, 13, 15, -1, -1, 16, 17, 12, -1, -1, 10, 14, 4, 6,
                5, 7, 9, 19, 18, 8,
            ],
            Mapping::EV4 => [
                2, -1, -1, 4, 3, 0, -1, -1, 10, 1, 11, -1, -1, 14, 17, 12, -1, -1, 13, 16, 15, 7,
                6, 5, 9, 19, 18, 8,
            ],
            Mapping::EV5 => [
                2, -1, -1, 4, 3, 10, -1, -1, 1, 0, 11, -1, -1, 13, 16, 12, -1, -1, 14, 15, 17, 5,
                7, 6, 9, 19, 18, 8,
            ],
        }
    }

    /// The joint a motor drives, by name.
    pub fn joint_of_motor(self, motor: u8) -> Option<&'static str> {
        let names = JOINT_NAMES.iter().chain(WRIST_NAMES.iter());
        self.table()
            .iter()
            .zip(names)
            .find(|(m, _)| **m >= 0 && **m as u8 == motor)
            .map(|(_, n)| *n)
    }

    /// The motor of a joint, by name (`None`: no such joint, or a joint without a motor).
    pub fn motor_of_joint(self, joint: &str) -> Option<u8> {
        let names = JOINT_NAMES.iter().chain(WRIST_NAMES.iter());
        self.table()
            .iter()
            .zip(names)
            .find(|(_, n)| **n == joint)
            .and_then(|(m, _)| u8::try_from(*m).ok())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_mapping_drives_twenty_motors_once() {
        for m in [Mapping::EV3, Mapping::EV4, Mapping::EV5] {
            let mut motors: Vec<i8> = m.table().iter().copied().filter(|x| *x >= 0).collect();
            motors.sort_unstable();
            assert_eq!(motors, (0..20).collect::<Vec<i8>>(), "{m:?}");
            for motor in 0..20 {
                let joint = m.joint_of_motor(motor).expect("a joint");
                assert_eq!(m.motor_of_joint(joint), Some(motor));
            }
            assert_eq!(m.motor_of_joint("FFJ1"), None, "J1 is driven through J0");
        }
        assert_eq!(Mapping::EV3.motor_of_joint("THJ5"), Some(19));
        assert_eq!(Mapping::EV4.motor_of_joint("MFJ0"), Some(0));
        assert_eq!(Mapping::EV5.motor_of_joint("WRJ2"), Some(8));
    }
}
