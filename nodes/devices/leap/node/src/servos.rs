//! The servos between cycles (pure): which ones the cycle asks, what each last reported (the
//! bring-up's read first), which are silent or in a hardware error, and the conversion between
//! joint angles and servo counts (the hand profile's device map, `Joint::to_device` and
//! `from_device`, in its f32; goals within the profile's limits). No I/O, no clock, no
//! allocation.

use teleop_hand_profile::Joint;
use teleop_leap_protocol::xc330::{self, State};

use crate::bus::FastRead;
use crate::config::SERVOS;

/// Bits of a joint's `status` word in `hand/state` (the LEAP Hand's device-specific word).
pub mod status {
    /// Not read this cycle: the values are the last ones read.
    pub const STALE: u32 = 1 << 0;
    /// The servo does not answer (left out of the cycle's read, looked for every second).
    pub const SILENT: u32 = 1 << 1;
    /// The servo reports a hardware error (its Alert bit): it turned its torque off.
    pub const ALERT: u32 = 1 << 2;
    /// Never read since the hand came up: the values mean nothing (published as NaN).
    pub const UNKNOWN: u32 = 1 << 3;
    /// The servo's Hardware Error Status (control table 70) is in bits 8..15.
    pub const HARDWARE_ERROR_SHIFT: u32 = 8;
}

/// A set of joints, one bit per joint.
pub type Mask = u16;

/// What one servo last reported.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Reading {
    /// Present Current, mA (signed).
    pub current_ma: i16,
    /// Present Velocity, 0.229 rpm units (signed).
    pub velocity: i32,
    /// Present Position, counts (signed).
    pub position: i32,
}

/// What a cycle's read changed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Applied {
    /// Servos read.
    pub read: u32,
    /// Joints asked that sent no block (a good reply without them).
    pub missing: Mask,
    /// Joints whose block carries the Alert bit and did not before.
    pub new_alerts: Mask,
    /// Joints whose Alert bit went away (rebooted: their torque is off).
    pub cleared_alerts: Mask,
}

/// The servos' state between cycles.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Servos {
    ids: [u8; SERVOS],
    readings: [Reading; SERVOS],
    fresh: Mask,
    known: Mask,
    silent: Mask,
    alert: Mask,
    hardware_error: [u8; SERVOS],
}

impl Servos {
    /// The servos `ids` (in joint order), none read yet, `silent` not answering.
    pub fn new(ids: [u8; SERVOS], silent: Mask) -> Self {
        Self {
            ids,
            readings: [Reading::default(); SERVOS],
            fresh: 0,
            known: 0,
            silent,
            alert: 0,
            hardware_error: [0; SERVOS],
        }
    }

    /// The IDs this cycle reads (every servo not silent), in joint order, into `out`; how many.
    pub fn read_ids(&self, out: &mut [u8; SERVOS]) -> usize {
        let mut n = 0;
        for (j, id) in self.ids.iter().enumerate() {
            if self.silent & bit(j) == 0 {
                out[n] = *id;
                n += 1;
            }
        }
        n
    }

    /// The joint of servo `id`.
    pub fn joint_of(&self, id: u8) -> Option<usize> {
        self.ids.iter().position(|i| *i == id)
    }

    /// A new cycle: nothing read yet.
    pub fn begin_cycle(&mut self) {
        self.fresh = 0;
    }

    /// Takes one Fast Sync Read of the state (`xc330::STATE_LEN` bytes at `STATE_ADDR`) from
    /// the IDs `asked`.
    pub fn apply(&mut self, asked: &[u8], read: &FastRead) -> Applied {
        let mut out = Applied::default();
        for (id, block) in asked.iter().zip(&read.blocks) {
            let Some(j) = self.joint_of(*id) else {
                continue;
            };
            let Some(block) = block else {
                continue;
            };
            let Ok(state) = State::decode(&block.data[..usize::from(xc330::STATE_LEN)]) else {
                continue;
            };
            self.take(j, state);
            out.read += 1;
            let alert = block.error.alert();
            let was = self.alert & bit(j) != 0;
            if alert && !was {
                self.alert |= bit(j);
                out.new_alerts |= bit(j);
            } else if !alert && was {
                self.alert &= !bit(j);
                self.hardware_error[j] = 0;
                out.cleared_alerts |= bit(j);
            }
        }
        for (slot, id) in asked.iter().enumerate() {
            if read.blocks[slot].is_none() {
                if let Some(j) = self.joint_of(*id) {
                    out.missing |= bit(j);
                }
            }
        }
        out
    }

    /// Records joint `j`'s state, read now.
    pub fn take(&mut self, j: usize, state: State) {
        self.readings[j] = Reading {
            current_ma: state.current_ma,
            velocity: state.velocity,
            position: state.position,
        };
        self.fresh |= bit(j);
        self.known |= bit(j);
    }

    /// Joint `j`'s servo stopped answering: left out of the reads.
    pub fn mark_silent(&mut self, j: usize) {
        self.silent |= bit(j);
    }

    /// Joint `j`'s servo answers again (brought up again: no alert).
    pub fn revive(&mut self, j: usize) {
        self.silent &= !bit(j);
        self.alert &= !bit(j);
        self.hardware_error[j] = 0;
    }

    /// Joint `j`'s servo reported this Hardware Error Status (its alert is on).
    pub fn set_hardware_error(&mut self, j: usize, status: u8) {
        self.alert |= bit(j);
        self.hardware_error[j] = status;
    }

    /// Joints read at least once since the hand came up.
    pub fn known(&self) -> Mask {
        self.known
    }

    /// Joints read this cycle.
    pub fn fresh(&self) -> Mask {
        self.fresh
    }

    /// Silent joints.
    pub fn silent(&self) -> Mask {
        self.silent
    }

    /// Joints in a hardware error.
    pub fn alerts(&self) -> Mask {
        self.alert
    }

    /// Joint `j`'s last reading.
    pub fn reading(&self, j: usize) -> Reading {
        self.readings[j]
    }

    /// Joint `j`'s `status` word (see [`status`]).
    pub fn status_word(&self, j: usize) -> u32 {
        let b = bit(j);
        let mut s = 0;
        if self.fresh & b == 0 {
            s |= status::STALE;
        }
        if self.known & b == 0 {
            s |= status::UNKNOWN;
        }
        if self.silent & b != 0 {
            s |= status::SILENT;
        }
        if self.alert & b != 0 {
            s |= status::ALERT;
        }
        s | u32::from(self.hardware_error[j]) << status::HARDWARE_ERROR_SHIFT
    }
}

/// The bit of joint `j`.
pub fn bit(j: usize) -> Mask {
    1 << j
}

/// The joints of `mask`.
pub fn joints(mask: Mask) -> impl Iterator<Item = usize> {
    (0..SERVOS).filter(move |j| mask & bit(*j) != 0)
}

/// The most a Goal Position may be in current-based position mode (ROBOTIS e-manual, XC330
/// control table, Goal Position: +-256 revolutions).
pub const GOAL_LIMIT: i32 = 1_048_575;

/// A joint's angle as the servo's Goal Position: within the profile's limits (a second guard
/// after admission: mode 5 ignores the servo's own position limits), through the profile's
/// device map, rounded to the nearest count, within [`GOAL_LIMIT`]. A non-finite angle gives
/// `None`.
pub fn goal_counts(joint: &Joint, radians: f64) -> Option<i32> {
    let counts = joint.to_device(joint.clamp(radians as f32));
    (radians.is_finite() && counts.is_finite()).then(|| {
        counts
            .round()
            .clamp(-(GOAL_LIMIT as f32), GOAL_LIMIT as f32) as i32
    })
}

/// A servo's Present Position as the joint's angle, rad (the profile's device map).
pub fn position_rad(joint: &Joint, counts: i32) -> f64 {
    f64::from(joint.from_device(counts as f32))
}

/// A servo's Present Velocity as the joint's speed, rad/s: 0.229 rpm per unit is
/// `0.229 * 4096 / 60` counts per second, through the device map's counts per radian.
pub fn speed_rad_s(joint: &Joint, velocity: i32) -> f64 {
    let counts_per_s = f64::from(velocity) * xc330::RPM_PER_VELOCITY_UNIT * 4096.0 / 60.0;
    counts_per_s / f64::from(joint.device.scale)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::bus::Block;
    use proptest::prelude::*;
    use teleop_hand_profile::{DeviceMap, GloveMap, Role};
    use teleop_leap_protocol::packet::ErrorByte;

    /// A joint whose device map is the LEAP's: 2048 counts at 0 rad (180 degrees: flat), 4096
    /// counts per turn.
    fn joint() -> Joint {
        Joint {
            name: "index_pip".into(),
            finger: 0,
            role: Role::Flex,
            lower: -0.506,
            upper: 1.885,
            open: 0.0,
            closed: 1.5,
            device: DeviceMap {
                unit: "count".into(),
                scale: (4096.0 / std::f64::consts::TAU) as f32,
                offset: 2048.0,
            },
            glove: GloveMap {
                channels: Vec::new(),
                offset: 0.0,
            },
            coupling: None,
        }
    }

    fn ids() -> [u8; SERVOS] {
        let mut ids = [0; SERVOS];
        for (i, id) in ids.iter_mut().enumerate() {
            *id = i as u8;
        }
        ids
    }

    fn block(error: u8, current: i16, velocity: i32, position: i32) -> Option<Block> {
        let mut data = [0u8; 16];
        data[..2].copy_from_slice(&current.to_le_bytes());
        data[2..6].copy_from_slice(&velocity.to_le_bytes());
        data[6..10].copy_from_slice(&position.to_le_bytes());
        Some(Block {
            error: ErrorByte(error),
            data,
        })
    }

    #[test]
    fn angles_and_counts() {
        let j = joint();
        assert_eq!(goal_counts(&j, 0.0), Some(2048));
        assert_eq!(goal_counts(&j, 1.0), Some(2700));
        assert_eq!(goal_counts(&j, f64::NAN), None);
        assert_eq!(goal_counts(&j, f64::INFINITY), None);
        // Beyond the profile's limits (-0.506..1.885 rad): at the limit.
        assert_eq!(
            goal_counts(&j, -std::f64::consts::PI),
            goal_counts(&j, -0.506)
        );
        assert_eq!(goal_counts(&j, 1e12), Some(3277));
        assert!((position_rad(&j, 3072) - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
        // 60 units = 13.74 rpm = 1.4388 rad/s.
        let w = speed_rad_s(&j, 60);
        assert!(
            (w - 60.0 * 0.229 * std::f64::consts::TAU / 60.0).abs() < 1e-5,
            "{w}"
        );
    }

    proptest! {
        /// A goal within the limits read back is the angle to within half a count.
        #[test]
        fn goals_round_trip(rad in -0.506f64..1.885) {
            let j = joint();
            let counts = goal_counts(&j, rad).unwrap();
            let back = position_rad(&j, counts);
            prop_assert!((back - rad).abs() <= 0.5 / f64::from(j.device.scale) + 1e-6);
        }
    }

    #[test]
    fn a_read_updates_the_servos_and_names_the_missing_and_alerts() {
        let mut s = Servos::new(ids(), 0);
        let mut ask = [0u8; SERVOS];
        assert_eq!(s.read_ids(&mut ask), 16);
        let mut read = FastRead::EMPTY;
        for (slot, b) in read.blocks.iter_mut().enumerate() {
            *b = block(0, 10, -3, 2048 + slot as i32);
        }
        read.blocks[11] = None;
        read.blocks[5] = block(0x80, 400, 0, 1900);
        s.begin_cycle();
        let a = s.apply(&ask, &read);
        assert_eq!(a.read, 15);
        assert_eq!(a.missing, bit(11));
        assert_eq!(a.new_alerts, bit(5));
        assert_eq!(s.reading(3).position, 2051);
        assert_eq!(s.reading(5).current_ma, 400);
        assert_eq!(s.status_word(11), status::STALE | status::UNKNOWN);
        assert_eq!(s.status_word(3), 0);
        s.set_hardware_error(5, 0x20);
        assert_eq!(s.status_word(5), status::ALERT | 0x20 << 8);

        // The silent servo is left out; the alert stays until the servo is rebooted.
        s.mark_silent(11);
        assert_eq!(s.read_ids(&mut ask), 15);
        assert!(!ask[..15].contains(&11));
        s.begin_cycle();
        let mut read = FastRead::EMPTY;
        for (slot, id) in ask[..15].iter().enumerate() {
            read.blocks[slot] = block(if *id == 5 { 0x80 } else { 0 }, 0, 0, 2048);
        }
        let a = s.apply(&ask[..15], &read);
        assert_eq!((a.read, a.missing, a.new_alerts), (15, 0, 0));
        assert_eq!(
            s.status_word(11),
            status::STALE | status::UNKNOWN | status::SILENT
        );
        // Rebooted: no alert in its block.
        s.begin_cycle();
        read.blocks[5] = block(0, 0, 0, 2048);
        let a = s.apply(&ask[..15], &read);
        assert_eq!(a.cleared_alerts, bit(5));
        assert_eq!(s.status_word(5), 0);
        s.revive(11);
        assert_eq!(s.read_ids(&mut ask), 16);
    }
}
