//! Kinematic hand models: joint values in, positions out (metres, hand frame).
//!
//! # What this crate owns
//!
//! Both hands use one frame, a right hand lying palm down: the wrist at the origin, the fingers
//! pointing along +Y, the back of the hand facing +Z (so flexion curls the fingers towards -Z)
//! and the thumb on the -X side (the frame of `teleop_hand_profile`).
//!
//! - [`OperatorHand`]: the operator's hand posed from the glove's normalised positions (five
//!   flexions and the thumb's rotation) with the flexion coupling a single-channel finger
//!   implies (MCP, PIP and DIP bend in fixed proportion), its fingertip pads, and the
//!   per-operator parameters (segment lengths, bases, angles) that calibration fits. Fingers in
//!   anatomical order ([`FINGERS`]: thumb, index, middle, ring, little).
//! - [`Chains`]: forward kinematics of a hand profile's finger chains in `f64`, fingertips, pads
//!   and the pads' analytic Jacobians, allocation-free: what fingertip retargeting solves over.
//! - [`RobotHand`]: a profile's hand posed for drawing (the viewer), on the same chains.
//!
//! # What it must not depend on
//!
//! Pure geometry with `glam` over `teleop-hand-profile`: no I/O, no IPC, no message crate, no
//! rerun. The retargeting library, the viewer and the tools share it, so the operator the
//! viewer draws is the operator the retargeting solves for.

mod chains;
mod fit;
mod operator;
mod robot;
#[cfg(test)]
mod tests;

use glam::Vec3;

pub use chains::{Chain, Chains};
pub use fit::{fit_pinches, FitError, PinchFit, PinchGap, PinchSample, ThumbParams};
pub use operator::{
    finger_of_glove_finger, FingerGeometry, OperatorHand, OperatorPose, ThumbGeometry, FINGERS,
    GLOVE_CHANNEL_OF_FINGER, GLOVE_THUMB_ROTATION,
};
pub use robot::RobotHand;

/// A posed hand: the wrist, the palm's outline and, per finger, its joints from the base to
/// the tip.
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    /// The wrist (origin of the hand frame).
    pub wrist: Vec3,
    /// Line strips outlining the palm.
    pub palm: Vec<Vec<Vec3>>,
    /// Per finger (the model's finger order): base, intermediate joints, fingertip.
    pub fingers: Vec<Vec<Vec3>>,
}

impl Skeleton {
    /// The fingertips, finger order.
    pub fn tips(&self) -> Vec<Vec3> {
        self.fingers
            .iter()
            .map(|chain| chain.last().copied().unwrap_or(self.wrist))
            .collect()
    }

    /// Unit direction of each finger's last segment (towards the tip), finger order.
    pub fn tip_directions(&self) -> Vec<Vec3> {
        self.fingers
            .iter()
            .map(|chain| match chain.as_slice() {
                [.., a, b] => (*b - *a).normalize_or(Vec3::Y),
                _ => Vec3::Y,
            })
            .collect()
    }

    /// Every joint (wrist first, then each finger's chain).
    pub fn joints(&self) -> Vec<Vec3> {
        let mut out = vec![self.wrist];
        for chain in &self.fingers {
            out.extend_from_slice(chain);
        }
        out
    }

    /// Line strips that draw the skeleton: the palm, then each finger.
    pub fn strips(&self) -> Vec<Vec<Vec3>> {
        self.palm.iter().chain(&self.fingers).cloned().collect()
    }
}
