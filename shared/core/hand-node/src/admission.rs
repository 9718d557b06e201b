//! Command admission: the one rule by which every hand node takes or refuses a `hand/command`.
//!
//! A command is checked in this order, and the first check it fails refuses it (the hand then
//! holds; the caller counts and logs the [`Refusal`]):
//!
//! 1. model: `hand_model` is the profile's (`UNKNOWN` is refused like another hand's);
//! 2. units: the profile's `command_units` (normalised or radians);
//! 3. mode: one the hand follows ([`Modes`]); an unknown mode is refused like an unsupported one;
//! 4. joint count: exactly the profile's;
//! 5. finiteness: every used joint's target, speed limit and effort limit is a finite number
//!    (NaN and +-inf never become a target, nor the open angle);
//!
//! then the profile's joint limits (in the command's units) apply in every mode: a position
//! target is clamped into them; a velocity, effort or duty value is first bounded by the mode's
//! magnitude ([`Modes`]) and then stopped (zero) toward a limit the joint's latest measured
//! position is at or past, free to move away from it; before the first measurement drives move
//! nothing. The number of values changed is returned once per call: [`crate::HandPorts`] counts
//! it once per command sample.
//!
//! Pure: no clock, no I/O, no allocation.

use teleop_hand_profile::{CommandUnits, HandProfile};
use teleop_msgs::{control_mode, units, HandCommand, MAX_JOINTS};

/// The control modes a hand follows, and for the drive modes the largest magnitude it takes
/// (the command's units: travel per second or rad/s for velocity, a fraction of the maximum for
/// effort and duty).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Modes {
    /// Position targets (`control_mode::POSITION`).
    pub position: bool,
    /// Position targets reached in a given time (`control_mode::POSITION_TIME`).
    pub position_time: bool,
    /// Velocity targets, up to this magnitude.
    pub velocity: Option<f32>,
    /// Effort targets, up to this magnitude.
    pub effort: Option<f32>,
    /// Duty-cycle targets, up to this magnitude.
    pub duty: Option<f32>,
}

impl Modes {
    /// Position targets only.
    pub const POSITION: Self = Self {
        position: true,
        position_time: false,
        velocity: None,
        effort: None,
        duty: None,
    };

    /// What a mode is to this hand: `None` when it does not follow it (or the mode is unknown).
    fn kind(&self, mode: u8) -> Option<Drive> {
        match mode {
            control_mode::POSITION if self.position => Some(Drive::Position),
            control_mode::POSITION_TIME if self.position_time => Some(Drive::Position),
            control_mode::VELOCITY => self.velocity.map(Drive::Bounded),
            control_mode::EFFORT => self.effort.map(Drive::Bounded),
            control_mode::DUTY => self.duty.map(Drive::Bounded),
            _ => None,
        }
    }
}

/// How a mode's targets meet the joint limits.
#[derive(Debug, Clone, Copy)]
enum Drive {
    /// Targets are positions: clamped into the limits.
    Position,
    /// Targets drive the joint (positive toward the upper limit) up to this magnitude.
    Bounded(f32),
}

/// Why a command was refused (the hand holds).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// For another hand, or for none (`UNKNOWN`).
    #[error("hand/command is for hand model {got} (0: unknown), not this node's {want}")]
    Model {
        /// The command's `hand_model`.
        got: u8,
        /// The profile's.
        want: u8,
    },
    /// In other units than the profile's.
    #[error(
        "hand/command is in units {got}; this hand takes units {want} (0 normalised, 1 radians)"
    )]
    Units {
        /// The command's `units`.
        got: u8,
        /// The profile's.
        want: u8,
    },
    /// A mode this hand does not follow, or no mode at all.
    #[error("hand/command has control mode {0}, which this hand does not follow")]
    Mode(u8),
    /// Another joint count than the profile's.
    #[error("hand/command has {got} joints; this hand has {want}")]
    JointCount {
        /// The command's `joint_count`.
        got: u8,
        /// The profile's.
        want: u8,
    },
    /// A NaN or infinite target, speed limit or effort limit.
    #[error("hand/command joint {0} has a value that is not a finite number")]
    NotFinite(u8),
}

/// The one admission rule, set up from a hand's profile and the modes it follows.
#[derive(Debug, Clone, PartialEq)]
pub struct Admission {
    model: u8,
    units: u8,
    modes: Modes,
    /// Joint limits in the command's units, lower then upper, in the profile's joint order.
    limits: [(f32, f32); MAX_JOINTS],
    joints: u8,
}

impl Admission {
    /// The rule for the hand of `profile` (model, command units, joint count, joint limits)
    /// following `modes`. In normalised units a joint's limits are its `lower` and `upper`
    /// angles as fractions from its `open` to its `closed` angle.
    pub fn new(profile: &HandProfile, modes: Modes) -> Self {
        let units = match profile.command_units {
            CommandUnits::Normalised => units::NORMALISED,
            CommandUnits::Radians => units::PHYSICAL,
        };
        let mut limits = [(0.0, 0.0); MAX_JOINTS];
        for (l, j) in limits.iter_mut().zip(&profile.joints) {
            *l = match profile.command_units {
                CommandUnits::Radians => (j.lower, j.upper),
                CommandUnits::Normalised => {
                    let (a, b) = (j.normalised(j.lower), j.normalised(j.upper));
                    (a.min(b), a.max(b))
                }
            };
        }
        Self {
            model: profile.model_id,
            units,
            modes,
            limits,
            joints: profile.joints.len().min(MAX_JOINTS) as u8,
        }
    }

    /// The hand model commands must name.
    pub fn model(&self) -> u8 {
        self.model
    }

    /// The units commands must be in (`teleop_msgs::units`).
    pub fn units(&self) -> u8 {
        self.units
    }

    /// The joint count commands must have.
    pub fn joints(&self) -> usize {
        usize::from(self.joints)
    }

    /// The joint limits in the command's units (lower, upper), in the profile's order.
    pub fn limits(&self) -> &[(f32, f32)] {
        &self.limits[..self.joints()]
    }

    /// Checks `cmd` and brings its targets within the limits in place (see the module
    /// documentation); `measured` is the latest measured position of each joint in the
    /// command's units (`None` before the first). Returns how many values were changed.
    pub fn admit(&self, cmd: &mut HandCommand, measured: Option<&[f32]>) -> Result<u32, Refusal> {
        if cmd.hand_model != self.model {
            return Err(Refusal::Model {
                got: cmd.hand_model,
                want: self.model,
            });
        }
        if cmd.units != self.units {
            return Err(Refusal::Units {
                got: cmd.units,
                want: self.units,
            });
        }
        let drive = self
            .modes
            .kind(cmd.control_mode)
            .ok_or(Refusal::Mode(cmd.control_mode))?;
        if cmd.joint_count != self.joints {
            return Err(Refusal::JointCount {
                got: cmd.joint_count,
                want: self.joints,
            });
        }
        let n = self.joints();
        if let Some(j) = cmd.joints[..n].iter().position(|j| {
            !(j.target.is_finite() && j.speed_limit.is_finite() && j.effort_limit.is_finite())
        }) {
            return Err(Refusal::NotFinite(j as u8));
        }
        let measured = measured.filter(|m| m.len() >= n);
        let mut changed = 0;
        for (j, (joint, &(lo, hi))) in cmd.joints[..n].iter_mut().zip(&self.limits).enumerate() {
            let target = match (drive, measured) {
                (Drive::Position, _) => joint.target.clamp(lo, hi),
                (Drive::Bounded(_), None) => {
                    // Nothing moves before the first measurement (nothing to count either).
                    joint.target = 0.0;
                    continue;
                }
                (Drive::Bounded(max), Some(at)) => {
                    let v = joint.target.clamp(-max, max);
                    if (v > 0.0 && at[j] >= hi) || (v < 0.0 && at[j] <= lo) {
                        0.0
                    } else {
                        v
                    }
                }
            };
            changed += u32::from(target != joint.target);
            joint.target = target;
        }
        Ok(changed)
    }
}

/// A hand profile given to a hand node that it does not fit (checked once, at start, before
/// anything moves).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProfileMismatch {
    /// Another joint count than the hand's.
    #[error("hand profile {profile:?} has {got} joints; the {hand} has {want} ({layout})")]
    Joints {
        /// The profile's name.
        profile: String,
        /// The hand.
        hand: &'static str,
        /// The profile's joint count.
        got: usize,
        /// The hand's.
        want: usize,
        /// The hand's joint order, in words.
        layout: &'static str,
    },
    /// A profile for another device model.
    #[error("hand profile {profile:?} is for device model {got}, not the {hand} ({want})")]
    Model {
        /// The profile's name.
        profile: String,
        /// The hand.
        hand: &'static str,
        /// The profile's model id.
        got: u8,
        /// The hand's.
        want: u8,
    },
}

/// What a hand node checks of its profile before it starts: the hand's device model and joint
/// count (`layout` names the joint order in the error).
#[derive(Debug, Clone, Copy)]
pub struct HandKind {
    /// The hand, in words ("the Allegro Hand" reads "the {hand}").
    pub hand: &'static str,
    /// Its `teleop_msgs::device_model`.
    pub model: u8,
    /// Its joint count.
    pub joints: usize,
    /// Its joint order, in words.
    pub layout: &'static str,
}

impl HandKind {
    /// Refuses a profile that is not for this hand.
    pub fn check(&self, profile: &HandProfile) -> Result<(), ProfileMismatch> {
        if profile.joints.len() != self.joints {
            return Err(ProfileMismatch::Joints {
                profile: profile.name.clone(),
                hand: self.hand,
                got: profile.joints.len(),
                want: self.joints,
                layout: self.layout,
            });
        }
        if profile.model_id != self.model {
            return Err(ProfileMismatch::Model {
                profile: profile.name.clone(),
                hand: self.hand,
                got: profile.model_id,
                want: self.model,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use teleop_msgs::device_model;

    fn revo2() -> Admission {
        let modes = Modes {
            position: true,
            position_time: true,
            velocity: Some(2.0),
            effort: Some(1.0),
            duty: Some(1.0),
        };
        Admission::new(&HandProfile::builtin("revo2").unwrap(), modes)
    }

    fn command(a: &Admission, mode: u8, target: f32) -> HandCommand {
        let mut c = HandCommand {
            hand_model: a.model(),
            joint_count: a.joints() as u8,
            control_mode: mode,
            units: a.units(),
            ..Default::default()
        };
        for j in &mut c.joints[..a.joints()] {
            j.target = target;
        }
        c
    }

    #[test]
    fn a_profile_for_another_hand_is_refused_by_count_then_model() {
        let allegro = HandKind {
            hand: "Allegro Hand",
            model: device_model::ALLEGRO,
            joints: 16,
            layout: "index 0-3, middle 4-7, ring 8-11, thumb 12-15",
        };
        allegro
            .check(&HandProfile::builtin("allegro").unwrap())
            .unwrap();
        let e = allegro
            .check(&HandProfile::builtin("revo2").unwrap())
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "hand profile \"revo2\" has 6 joints; the Allegro Hand has 16 (index 0-3, middle \
             4-7, ring 8-11, thumb 12-15)"
        );
        let e = allegro
            .check(&HandProfile::builtin("leap").unwrap())
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "hand profile \"leap\" is for device model 5, not the Allegro Hand (2)"
        );
    }

    #[test]
    fn every_hand_takes_its_profile() {
        for (name, model, units, joints) in [
            ("revo2", device_model::REVO2, units::NORMALISED, 6),
            ("allegro", device_model::ALLEGRO, units::PHYSICAL, 16),
            ("shadow", device_model::SHADOW, units::PHYSICAL, 24),
            ("leap", device_model::LEAP, units::PHYSICAL, 16),
        ] {
            let profile = HandProfile::builtin(name).unwrap();
            let a = Admission::new(&profile, Modes::POSITION);
            assert_eq!((a.model(), a.units(), a.joints()), (model, units, joints));
            for (l, j) in a.limits().iter().zip(&profile.joints) {
                if units == units::PHYSICAL {
                    assert_eq!(*l, (j.lower, j.upper), "{name}");
                }
                assert!(l.0 < l.1, "{name}");
            }
        }
        assert!(revo2()
            .limits()
            .iter()
            .all(|&(lo, hi)| lo.abs() < 1e-6 && (hi - 1.0).abs() < 1e-6));
    }

    #[test]
    fn refusals_in_order() {
        let a = revo2();
        let good = command(&a, control_mode::POSITION, 0.5);
        let mut c = good;
        assert_eq!(a.admit(&mut c, None), Ok(0));
        for (change, want) in [
            (
                (|c: &mut HandCommand| c.hand_model = device_model::UNKNOWN)
                    as fn(&mut HandCommand),
                Refusal::Model { got: 0, want: 1 },
            ),
            (
                |c| c.hand_model = device_model::SHADOW,
                Refusal::Model { got: 3, want: 1 },
            ),
            (
                |c| c.units = units::PHYSICAL,
                Refusal::Units { got: 1, want: 0 },
            ),
            (|c| c.control_mode = 0, Refusal::Mode(0)),
            (|c| c.control_mode = 9, Refusal::Mode(9)),
            (
                |c| c.joint_count = 5,
                Refusal::JointCount { got: 5, want: 6 },
            ),
            (
                |c| c.joint_count = 7,
                Refusal::JointCount { got: 7, want: 6 },
            ),
            (|c| c.joints[3].target = f32::NAN, Refusal::NotFinite(3)),
            (
                |c| c.joints[0].target = f32::INFINITY,
                Refusal::NotFinite(0),
            ),
            (
                |c| c.joints[5].target = f32::NEG_INFINITY,
                Refusal::NotFinite(5),
            ),
            (
                |c| c.joints[2].speed_limit = f32::NAN,
                Refusal::NotFinite(2),
            ),
            (
                |c| c.joints[1].effort_limit = f32::INFINITY,
                Refusal::NotFinite(1),
            ),
        ] {
            let mut c = good;
            change(&mut c);
            assert_eq!(a.admit(&mut c, None), Err(want));
        }
        // A joint past the count is not looked at.
        let mut c = good;
        c.joints[6].target = f32::NAN;
        assert_eq!(a.admit(&mut c, None), Ok(0));
        // A mode the hand does not follow.
        let allegro = Admission::new(&HandProfile::builtin("allegro").unwrap(), Modes::POSITION);
        for mode in [
            control_mode::POSITION_TIME,
            control_mode::VELOCITY,
            control_mode::EFFORT,
            control_mode::DUTY,
        ] {
            let mut c = command(&allegro, mode, 0.1);
            assert_eq!(allegro.admit(&mut c, None), Err(Refusal::Mode(mode)));
        }
    }

    #[test]
    fn positions_are_clamped_into_the_profile_limits_and_counted() {
        let allegro = Admission::new(&HandProfile::builtin("allegro").unwrap(), Modes::POSITION);
        let mut c = command(&allegro, control_mode::POSITION, 0.0);
        let middle: Vec<f32> = allegro
            .limits()
            .iter()
            .map(|(lo, hi)| (lo + hi) / 2.0)
            .collect();
        for (j, m) in c.joints.iter_mut().zip(&middle) {
            j.target = *m;
        }
        c.joints[0].target = 2.0;
        c.joints[1].target = -5.0;
        assert_eq!(allegro.admit(&mut c, None), Ok(2));
        assert_eq!(c.joints[0].target, allegro.limits()[0].1);
        assert_eq!(c.joints[1].target, allegro.limits()[1].0);
        assert_eq!(c.joints[2].target, middle[2]);
        let a = revo2();
        let mut c = command(&a, control_mode::POSITION_TIME, 1.5);
        assert_eq!(a.admit(&mut c, None), Ok(6));
        assert!(c
            .active_joints()
            .iter()
            .all(|j| (j.target - 1.0).abs() < 1e-6));
    }

    #[test]
    fn drives_are_bounded_and_stop_toward_a_limit_the_joint_is_at() {
        let a = revo2();
        for (mode, max) in [
            (control_mode::VELOCITY, 2.0),
            (control_mode::EFFORT, 1.0),
            (control_mode::DUTY, 1.0),
        ] {
            // Before the first measurement nothing moves (not counted: nothing was asked of a
            // known joint).
            let mut c = command(&a, mode, 0.5);
            assert_eq!(a.admit(&mut c, None), Ok(0), "{mode}");
            assert!(c.active_joints().iter().all(|j| j.target == 0.0));
            let mut c = command(&a, mode, 0.5);
            c.joints[0].target = 9.0;
            c.joints[2].target = -0.5;
            let at = [0.5, 1.0, 0.0, 0.5, 0.5, 0.5];
            assert_eq!(a.admit(&mut c, Some(&at)), Ok(3), "{mode}");
            assert_eq!(c.joints[0].target, max, "{mode}: bounded");
            assert_eq!(
                c.joints[1].target, 0.0,
                "{mode}: at the upper limit, closing"
            );
            assert_eq!(
                c.joints[2].target, 0.0,
                "{mode}: at the lower limit, opening"
            );
            assert_eq!(c.joints[3].target, 0.5, "{mode}");
            // Away from a limit: followed (joint 2 still opens against its lower limit).
            let mut c = command(&a, mode, -0.5);
            assert_eq!(a.admit(&mut c, Some(&at)), Ok(1), "{mode}");
            assert_eq!(c.joints[1].target, -0.5, "{mode}");
        }
    }
}
