//! The Hand E's joints and the motors that drive them (docs/devices/shadow.md, "Motors,
//! units, limits": E's `mappings/default_mappings`; C's `general_info.yaml` picks one per hand).
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

/// The 24 joints a Hand E reports, in the order of `config/hands/shadow.toml` (and of
/// `hand/state`): each finger's J1 and J2 separately.
pub const HAND_JOINTS: [&str; 24] = [
    "FFJ1", "FFJ2", "FFJ3", "FFJ4", "MFJ1", "MFJ2", "MFJ3", "MFJ4", "RFJ1", "RFJ2", "RFJ3", "RFJ4",
    "LFJ1", "LFJ2", "LFJ3", "LFJ4", "LFJ5", "THJ1", "THJ2", "THJ3", "THJ4", "THJ5", "WRJ1", "WRJ2",
];

/// Limits (rad) of [`HAND_JOINTS`]: Shadow's published Hand E joint ranges (the
/// sr_description URDF; degrees there: J1/J2 0..90, J3 -15..90, J4 -20..20, LFJ5 0..45, THJ1
/// -15..90, THJ2 -40..40, THJ3 -12..12, THJ4 0..70, THJ5 -60..60, WRJ1 -40..28, WRJ2 -30..10).
pub const HAND_LIMITS: [(f64, f64); 24] = {
    const fn deg(lo: f64, hi: f64) -> (f64, f64) {
        (
            lo * core::f64::consts::PI / 180.0,
            hi * core::f64::consts::PI / 180.0,
        )
    }
    const DISTAL: (f64, f64) = deg(0.0, 90.0);
    const KNUCKLE: (f64, f64) = deg(-15.0, 90.0);
    const SPREAD: (f64, f64) = deg(-20.0, 20.0);
    [
        DISTAL,
        DISTAL,
        KNUCKLE,
        SPREAD,
        DISTAL,
        DISTAL,
        KNUCKLE,
        SPREAD,
        DISTAL,
        DISTAL,
        KNUCKLE,
        SPREAD,
        DISTAL,
        DISTAL,
        KNUCKLE,
        SPREAD,
        deg(0.0, 45.0),
        KNUCKLE,
        deg(-40.0, 40.0),
        deg(-12.0, 12.0),
        deg(0.0, 70.0),
        deg(-60.0, 60.0),
        deg(-40.0, 28.0),
        deg(-30.0, 10.0),
    ]
};

/// The palm's ADC channels of each joint of [`HAND_JOINTS`] (docs/devices/shadow.md, "Sensors":
/// FFJ1-4 0-3, MFJ1-4 4-7, RFJ1-4 8-11, LFJ1-5 12-16, THJ1-4 17-20, THJ5A/B 21-22, WRJ1A/B
/// 23-24, WRJ2 25); THJ5 and WRJ1 have two sensors, read as their mean.
pub const HAND_CHANNELS: [(usize, Option<usize>); 24] = {
    let mut c = [(0, None); 24];
    let mut j = 0;
    while j < 21 {
        c[j] = (j, None);
        j += 1;
    }
    c[21] = (21, Some(22));
    c[22] = (23, Some(24));
    c[23] = (25, None);
    c
};

/// The palm's sensor words by index (docs/devices/shadow.md, "Sensors"); the rest up to 37 unused.
pub const SENSOR_NAMES: [&str; 36] = [
    "FFJ1", "FFJ2", "FFJ3", "FFJ4", "MFJ1", "MFJ2", "MFJ3", "MFJ4", "RFJ1", "RFJ2", "RFJ3", "RFJ4",
    "LFJ1", "LFJ2", "LFJ3", "LFJ4", "LFJ5", "THJ1", "THJ2", "THJ3", "THJ4", "THJ5A", "THJ5B",
    "WRJ1A", "WRJ1B", "WRJ2", "ACCX", "ACCY", "ACCZ", "GYRX", "GYRY", "GYRZ", "AN0", "AN1", "AN2",
    "AN3",
];

/// What a motor drives: one joint of [`HAND_JOINTS`], or a finger's J1 and J2 together (its
/// J0 = J1 + J2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dof {
    /// Its name in the mapping (FFJ0, FFJ3, ..., WRJ2).
    pub name: &'static str,
    /// The joints of [`HAND_JOINTS`] it moves (the second only for J0).
    pub joints: (usize, Option<usize>),
}

impl Dof {
    /// Its value in `angles` ([`HAND_JOINTS`] order; J0 = J1 + J2).
    pub fn of(&self, angles: &[f64; 24]) -> f64 {
        angles[self.joints.0] + self.joints.1.map_or(0.0, |j| angles[j])
    }

    /// Its limits (J0: from 0 to the sum of J1's and J2's upper limits).
    pub fn limits(&self) -> (f64, f64) {
        let (lo, hi) = HAND_LIMITS[self.joints.0];
        match self.joints.1 {
            Some(j) => (lo + HAND_LIMITS[j].0, hi + HAND_LIMITS[j].1),
            None => (lo, hi),
        }
    }
}

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

    /// What each motor drives, by motor number.
    pub fn dofs(self) -> [Option<Dof>; 20] {
        let mut out = [None; 20];
        let names = JOINT_NAMES.iter().chain(WRIST_NAMES.iter());
        let index = |n: &str| HAND_JOINTS.iter().position(|j| *j == n);
        for (name, motor) in names.zip(self.table()) {
            let Ok(motor) = usize::try_from(motor) else {
                continue;
            };
            let joints = match name.strip_suffix("J0") {
                Some(finger) => match index(&format!("{finger}J1")) {
                    Some(j1) => (j1, Some(j1 + 1)),
                    None => continue,
                },
                None => match index(name) {
                    Some(j) => (j, None),
                    None => continue,
                },
            };
            if let Some(slot) = out.get_mut(motor) {
                *slot = Some(Dof { name, joints });
            }
        }
        out
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

    #[test]
    fn every_motor_has_a_dof_and_j0_is_j1_plus_j2() {
        for m in [Mapping::EV3, Mapping::EV4, Mapping::EV5] {
            let d = m.dofs();
            assert!(d.iter().all(Option::is_some), "{m:?}");
            let ff0 = d[usize::from(m.motor_of_joint("FFJ0").unwrap_or(0))].unwrap_or(Dof {
                name: "",
                joints: (9, None),
            });
            assert_eq!(ff0.joints, (0, Some(1)));
            assert_eq!(ff0.limits(), (0.0, core::f64::consts::PI));
            let mut angles = [0.0; 24];
            angles[0] = 0.25;
            angles[1] = 0.5;
            assert_eq!(ff0.of(&angles), 0.75);
        }
        assert_eq!(HAND_CHANNELS[21], (21, Some(22)));
        assert_eq!(HAND_CHANNELS[23], (25, None));
    }
}
