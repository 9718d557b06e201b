//! The Hand E's 24 joints behind its 20 motors: each motor's torque moves its joint against
//! viscous damping within the joint's limits; the distal pair J1/J2 of each finger is one
//! tendon-driven joint J0 = J1 + J2 (split evenly here); a virtual ball under the middle
//! finger stops it and presses on its fingertip. What the palm reads of it: the joint ADCs
//! (12-bit, through this emulated hand's own linear calibration) and the PST fingertip
//! pressure.
//!
//! Joint order, limits, ADC channels and the motor of each joint are
//! `teleop_shadow_protocol::mapping`'s.

use teleop_shadow_protocol::layout::{MOTORS, SENSORS, TACTILE};
use teleop_shadow_protocol::mapping::{Dof, Mapping, HAND_CHANNELS};

pub use teleop_shadow_protocol::mapping::{HAND_JOINTS as JOINTS, HAND_LIMITS as LIMITS};

/// This emulated hand's sensors: raw = [`ADC_CENTRE`] + angle * [`ADC_PER_RAD`].
pub const ADC_CENTRE: f64 = 2048.0;
/// ADC counts per radian of the emulated sensors.
pub const ADC_PER_RAD: f64 = 1200.0;
/// Joint torque per raw motor torque unit (full scale 0x7FFF = 1 N m).
pub const NM_PER_UNIT: f64 = 1.0 / 32767.0;
/// Viscous damping of every joint, N m s / rad.
pub const DAMPING: f64 = 0.05;
/// Fingertip lever for the contact force, m.
pub const LEVER_M: f64 = 0.05;
/// PST pressure counts per newton on the fingertip (this emulator's sensor).
pub const PST_PER_N: f64 = 100.0;
/// PST reading without contact.
pub const PST_IDLE: u16 = 10;

/// A virtual object: it stops a finger whose closure (J3 + J0 / 2) reaches `closure` rad.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualObject {
    /// The finger (0 FF, 1 MF, 2 RF, 3 LF).
    pub finger: usize,
    /// Closure at contact, rad.
    pub closure: f64,
}

impl VirtualObject {
    /// The default: a ball under the middle finger.
    pub fn ball() -> Self {
        Self {
            finger: 1,
            closure: 1.0,
        }
    }
}

/// The hand.
#[derive(Debug, Clone)]
pub struct Hand {
    /// Joint angles (rad), [`JOINTS`] order.
    pub angles: [f64; 24],
    /// What each motor drives.
    dofs: [Option<Dof>; MOTORS],
    /// The object, if any.
    pub object: Option<VirtualObject>,
    /// Contact force on each fingertip (FF, MF, RF, LF, TH), N.
    pub contact_n: [f64; TACTILE],
}

/// First joint (J1) of each of the four fingers in [`JOINTS`].
const FINGER_J1: [usize; 4] = [0, 4, 8, 12];

impl Hand {
    /// An open hand with the motors of `mapping` and `object`.
    pub fn new(mapping: Mapping, object: Option<VirtualObject>) -> Self {
        Self {
            angles: [0.0; 24],
            dofs: mapping.dofs(),
            object,
            contact_n: [0.0; TACTILE],
        }
    }

    fn set_dof_angle(&mut self, d: &Dof, q: f64) {
        match d.joints {
            (a, Some(b)) => {
                self.angles[a] = q / 2.0;
                self.angles[b] = q / 2.0;
            }
            (a, None) => self.angles[a] = q,
        }
    }

    /// A finger's closure: J3 + J0 / 2.
    fn closure(&self, finger: usize) -> f64 {
        let j1 = FINGER_J1[finger];
        self.angles[j1 + 2] + (self.angles[j1] + self.angles[j1 + 1]) / 2.0
    }

    /// `dt` seconds with these motor torques (raw units, by motor number).
    pub fn step(&mut self, torques: &[f64; MOTORS], dt: f64) {
        self.contact_n = [0.0; TACTILE];
        let dofs = self.dofs;
        for (motor, d) in dofs.iter().enumerate() {
            let Some(d) = d else { continue };
            let tau = torques[motor] * NM_PER_UNIT;
            let q = d.of(&self.angles);
            let (lo, hi) = d.limits();
            let mut next = (q + tau / DAMPING * dt).clamp(lo, hi);
            if let Some(o) = self.object {
                let j1 = FINGER_J1.get(o.finger).copied().unwrap_or(usize::MAX);
                let flexes_finger = d.joints.0 == j1 || d.joints.0 == j1 + 2;
                if flexes_finger && self.closure(o.finger) >= o.closure && tau > 0.0 {
                    next = next.min(q); // blocked: the torque presses on the object
                    self.contact_n[o.finger] += tau / LEVER_M;
                }
            }
            self.set_dof_angle(d, next);
        }
    }

    /// The 37 sensor words: each joint's ADCs (J1 and J2 separately), the rest 0.
    pub fn sensors(&self) -> [u16; SENSORS] {
        let mut s = [0u16; SENSORS];
        for (j, angle) in self.angles.iter().enumerate() {
            let raw = (ADC_CENTRE + angle * ADC_PER_RAD)
                .round()
                .clamp(0.0, 4095.0) as u16;
            let (a, b) = HAND_CHANNELS[j];
            s[a] = raw;
            if let Some(b) = b {
                s[b] = raw;
            }
        }
        s
    }

    /// PST pressure per fingertip (FF, MF, RF, LF, TH).
    pub fn pst(&self) -> [u16; TACTILE] {
        self.contact_n.map(|n| {
            (f64::from(PST_IDLE) + n * PST_PER_N)
                .round()
                .clamp(0.0, 65535.0) as u16
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn torque_on(mapping: Mapping, joint: &str, t: f64) -> [f64; MOTORS] {
        let mut torques = [0.0; MOTORS];
        torques[usize::from(mapping.motor_of_joint(joint).unwrap())] = t;
        torques
    }

    #[test]
    fn a_motor_moves_its_joint_within_limits_and_j0_moves_j1_and_j2() {
        let mut hand = Hand::new(Mapping::EV3, None);
        let t = torque_on(Mapping::EV3, "FFJ3", 3000.0);
        for _ in 0..2000 {
            hand.step(&t, 0.001);
        }
        assert!(
            (hand.angles[2] - LIMITS[2].1).abs() < 1e-9,
            "FFJ3 at its limit"
        );
        let t = torque_on(Mapping::EV3, "FFJ0", 2000.0);
        hand.step(&t, 0.01);
        assert!(hand.angles[0] > 0.0 && (hand.angles[0] - hand.angles[1]).abs() < 1e-12);
        let s = hand.sensors();
        assert_eq!(
            s[2],
            (ADC_CENTRE + LIMITS[2].1 * ADC_PER_RAD).round() as u16
        );
        let t = torque_on(Mapping::EV3, "THJ5", -3000.0);
        for _ in 0..2000 {
            hand.step(&t, 0.001);
        }
        let s = hand.sensors();
        assert_eq!(s[21], s[22], "THJ5 A and B");
        assert!(s[21] < 2048);
    }

    #[test]
    fn the_ball_stops_the_middle_finger_and_presses_its_fingertip() {
        let mut hand = Hand::new(Mapping::EV4, Some(VirtualObject::ball()));
        let mut t = torque_on(Mapping::EV4, "MFJ3", 3000.0);
        t[usize::from(Mapping::EV4.motor_of_joint("FFJ3").unwrap())] = 3000.0;
        for _ in 0..3000 {
            hand.step(&t, 0.001);
        }
        let closure = hand.closure(1);
        assert!((1.0..1.01).contains(&closure), "{closure}");
        assert!(hand.angles[2] > 1.5, "the index finger closes freely");
        let pst = hand.pst();
        assert!(pst[1] > 100, "{pst:?}");
        assert_eq!(pst[0], PST_IDLE);
    }
}
