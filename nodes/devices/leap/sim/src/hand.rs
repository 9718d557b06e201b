//! The simulated LEAP Hand's mechanics: 16 joints in motor-ID order (index 0-3, middle 4-7,
//! ring 8-11, thumb 12-15; each long finger MCP side, MCP forward, PIP, DIP), each driven by
//! its servo's torque, with inertia, viscous damping, the URDF limits as hard stops and a
//! virtual object the fingers close on.
//!
//! The object lives in the hand's joint space (as the simulator kit's objects do on every
//! simulator): a finger touches it when its closure, the sum of its three flexing joints'
//! angles (URDF radians; MCP forward, PIP, DIP of a long finger, joints 13-15 of the thumb),
//! passes the object's closure for that finger; the object then pushes back on each of those
//! joints with a spring-damper on the excess closure (pushing only, never pulling). A finger
//! closing on it stops there while its servo's current rises; a finger it does not reach, or
//! one that stays more open, moves freely. Joints are decoupled otherwise (a geared joint as
//! its motor sees it: a diagonal inertia). With the torque off a joint keeps its place (no
//! gravity: the joint is limp, damping stops it).
//!
//! Pure: the caller steps it ([`Hand::step`]) with the servos' torques.

use teleop_hand_profile::HandProfile;
use teleop_sim_kit::plant::Joint;
use teleop_sim_kit::Object;

/// Joints (= servos), in motor-ID order.
pub const JOINTS: usize = 16;
/// Fingers: index, middle, ring, thumb.
pub const FINGERS: usize = 4;

/// Each finger's flexing joints (whose sum is its closure), motor IDs: a long finger's MCP
/// forward, PIP and DIP; the thumb's 12 (which swings it under the palm) and 14, 15 (which bend
/// it; 13 turns it about its own length and closes nothing).
pub const FLEXING: [[usize; 3]; FINGERS] = [[1, 2, 3], [5, 6, 7], [9, 10, 11], [12, 14, 15]];

/// The joint limits of the builtin LEAP profile (`config/hands/leap.toml`: the URDF's, rad,
/// motor-ID order).
pub fn leap_limits() -> Result<[(f64, f64); JOINTS], String> {
    let profile = HandProfile::builtin("leap")
        .ok_or_else(|| "the builtin hand profile `leap` is missing".to_string())?;
    let n = profile.joints.len();
    let limits: Vec<(f64, f64)> = profile
        .joints
        .iter()
        .map(|j| (f64::from(j.lower), f64::from(j.upper)))
        .collect();
    limits
        .try_into()
        .map_err(|_| format!("the LEAP profile has {n} joints, the hand {JOINTS}"))
}

/// Where an object meets each finger: the closure (rad) at contact, `None` for a finger it
/// does not reach.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualObject {
    /// Per finger (index, middle, ring, thumb): closure at contact, rad.
    pub contact: [Option<f64>; FINGERS],
    /// Stiffness, N m per rad of excess closure (on each flexing joint).
    pub stiffness: f64,
    /// Damping, N m s per rad of closure speed, only while pressing in.
    pub damping: f64,
}

impl VirtualObject {
    /// A ball in the palm: every finger and the thumb meet it about a third closed (the long
    /// fingers' flexing joints can close by about 6 rad in all, the thumb's by about 6).
    pub fn ball() -> Self {
        Self {
            contact: [Some(1.5), Some(1.5), Some(1.5), Some(1.2)],
            stiffness: 3.0,
            damping: 0.02,
        }
    }

    /// A bar across the palm: the three long fingers wrap it, further closed than the ball;
    /// the thumb does not reach it.
    pub fn bar() -> Self {
        Self {
            contact: [Some(1.8), Some(1.8), Some(1.8), None],
            ..Self::ball()
        }
    }

    /// The geometry of the simulator kit's `object`.
    pub fn of(object: Object) -> Self {
        match object {
            Object::Ball => Self::ball(),
            Object::Bar => Self::bar(),
        }
    }
}

/// Physical constants (no published figures for the LEAP's joints: plausible values for an
/// XC330 behind a short finger link).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandParams {
    /// Joint inertia as the servo sees it, kg m^2.
    pub inertia: f64,
    /// Viscous joint damping, N m s/rad.
    pub damping: f64,
}

impl Default for HandParams {
    fn default() -> Self {
        Self {
            inertia: 2.0e-4,
            damping: 0.05,
        }
    }
}

/// The hand.
#[derive(Debug, Clone)]
pub struct Hand {
    params: HandParams,
    limits: [(f64, f64); JOINTS],
    object: Option<Object>,
    q: [f64; JOINTS],
    qd: [f64; JOINTS],
    contact: [f64; FINGERS],
}

impl Hand {
    /// A hand with these joint limits (URDF radians, motor-ID order), at rest at 0 rad (the
    /// servos' 2048, "flat") clamped into the limits.
    pub fn new(params: HandParams, limits: [(f64, f64); JOINTS], object: Option<Object>) -> Self {
        Self {
            params,
            limits,
            object,
            q: core::array::from_fn(|j| 0.0f64.clamp(limits[j].0, limits[j].1)),
            qd: [0.0; JOINTS],
            contact: [0.0; FINGERS],
        }
    }

    /// Places or removes the object.
    pub fn set_object(&mut self, object: Option<Object>) {
        self.object = object;
    }

    /// The object.
    pub fn object(&self) -> Option<Object> {
        self.object
    }

    /// One step of `h` seconds with the servos' torques `torque` (N m, motor-ID order;
    /// non-finite values count as 0).
    pub fn step(&mut self, h: f64, torque: &[f64; JOINTS]) {
        let mut external = [0.0; JOINTS];
        self.contact = [0.0; FINGERS];
        if let Some(object) = self.object.map(VirtualObject::of) {
            for (f, joints) in FLEXING.iter().enumerate() {
                let Some(at) = object.contact[f] else {
                    continue;
                };
                let closure: f64 = joints.iter().map(|&j| self.q[j]).sum();
                let speed: f64 = joints.iter().map(|&j| self.qd[j]).sum();
                let depth = closure - at;
                if depth <= 0.0 {
                    continue;
                }
                let push = (object.stiffness * depth + object.damping * speed).max(0.0);
                self.contact[f] = push;
                for &j in joints {
                    external[j] -= push;
                }
            }
        }
        let joint = Joint {
            inertia: self.params.inertia,
            damping: self.params.damping,
        };
        for j in 0..JOINTS {
            let motor = if torque[j].is_finite() {
                torque[j]
            } else {
                0.0
            };
            joint.step(
                &mut self.q[j],
                &mut self.qd[j],
                motor + external[j],
                h,
                self.limits[j],
            );
        }
    }

    /// Joint angles, URDF rad.
    pub fn positions(&self) -> [f64; JOINTS] {
        self.q
    }

    /// Joint velocities, rad/s.
    pub fn velocities(&self) -> [f64; JOINTS] {
        self.qd
    }

    /// The object's push on each finger at the last step, N m on each flexing joint (0: no
    /// contact).
    pub fn contact(&self) -> [f64; FINGERS] {
        self.contact
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> [(f64, f64); JOINTS] {
        leap_limits().expect("the builtin LEAP profile")
    }

    /// Closes finger `f` with a constant torque on its flexing joints for `seconds`.
    fn close(hand: &mut Hand, f: usize, nm: f64, seconds: f64) {
        let mut t = [0.0; JOINTS];
        for &j in &FLEXING[f] {
            t[j] = nm;
        }
        let steps = (seconds / 0.000_25) as usize;
        for _ in 0..steps {
            hand.step(0.000_25, &t);
        }
    }

    #[test]
    fn a_free_finger_closes_to_its_stops_and_one_on_the_ball_stops_at_it() {
        let mut free = Hand::new(HandParams::default(), limits(), None);
        let mut held = Hand::new(HandParams::default(), limits(), Some(Object::Ball));
        close(&mut free, 1, 0.15, 1.0);
        close(&mut held, 1, 0.15, 1.0);
        for &j in &FLEXING[1] {
            assert!((free.positions()[j] - limits()[j].1).abs() < 1e-9, "{j}");
        }
        let closure: f64 = FLEXING[1].iter().map(|&j| held.positions()[j]).sum();
        assert!(closure > 1.5 && closure < 1.6, "{closure}");
        assert!(
            (held.contact()[1] - 0.15).abs() < 0.01,
            "{:?}",
            held.contact()
        );
        assert!(held.velocities().iter().all(|v| v.abs() < 1e-3));
        assert_eq!(held.contact()[0], 0.0, "the index finger was not moved");
    }

    #[test]
    fn the_bar_does_not_reach_the_thumb_and_nothing_moves_without_torque() {
        let mut hand = Hand::new(HandParams::default(), limits(), Some(Object::Bar));
        close(&mut hand, 3, 0.15, 1.0);
        assert_eq!(hand.contact()[3], 0.0);
        let before = hand.positions();
        close(&mut hand, 3, 0.0, 0.5);
        assert_eq!(hand.positions(), before, "limp joints stay where they are");
    }
}
