//! Kinematic hand models: joint values in, joint positions out (metres, hand frame).
//!
//! Both hands use the same frame, a right hand lying palm down: the wrist at the origin, the
//! fingers pointing along +Y, the back of the hand facing +Z (so flexion curls the fingers
//! towards -Z) and the thumb on the -X side. Fingers are always in anatomical order
//! ([`FINGERS`]: thumb, index, middle, ring, little), whatever order a device uses.
//!
//! - [`OperatorHand`]: a human hand posed from the glove's normalised positions (five flexions
//!   and the thumb's rotation), with the usual MCP/PIP/DIP coupling of a human finger.
//! - [`Revo2Hand`]: the BrainCo Revo2's joint layout (thumb flex, thumb abduct, index, middle,
//!   ring, pinky: six actuated joints; each finger has two phalanges driven together by a
//!   linkage) posed from normalised joint positions (0 = open .. 1 = closed), mapped onto the
//!   joint ranges the rest of the pipeline assumes (`teleop_revo2_protocol::DEFAULT_JOINT_RANGES`).
//!
//! Pure geometry with `glam`: no I/O, no rerun.

use glam::{Quat, Vec3};

/// Finger names in anatomical order, the order of every per-finger array here.
pub const FINGERS: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];

/// The glove channel ([`teleop_msgs::GLOVE_CHANNELS`] index) of each finger in [`FINGERS`]
/// order.
pub const GLOVE_CHANNEL_OF_FINGER: [usize; 5] = [4, 3, 2, 1, 0];
/// The glove's thumb rotation channel.
pub const GLOVE_THUMB_ROTATION: usize = 5;

/// The Revo2 joint ([`teleop_msgs::REVO2_JOINTS`] index) that flexes each finger in
/// [`FINGERS`] order.
pub const REVO2_JOINT_OF_FINGER: [usize; 5] = [0, 2, 3, 4, 5];
/// The Revo2's thumb abduction joint.
pub const REVO2_THUMB_ABDUCT: usize = 1;

/// Towards the palm (the direction flexion curls a finger).
const PALM_SIDE: Vec3 = Vec3::new(0.0, 0.0, -1.0);

/// A posed hand: the wrist and, per finger, its joints from the base knuckle to the tip.
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    /// The wrist (origin of the hand frame).
    pub wrist: Vec3,
    /// Per finger ([`FINGERS`] order): base joint, intermediate joints, fingertip.
    pub fingers: [Vec<Vec3>; 5],
}

impl Skeleton {
    /// The fingertips, [`FINGERS`] order.
    pub fn tips(&self) -> [Vec3; 5] {
        core::array::from_fn(|i| self.fingers[i].last().copied().unwrap_or(self.wrist))
    }

    /// Unit direction of each distal phalanx (towards the tip), [`FINGERS`] order.
    pub fn tip_directions(&self) -> [Vec3; 5] {
        core::array::from_fn(|i| {
            let chain = &self.fingers[i];
            match chain.as_slice() {
                [.., a, b] => (*b - *a).normalize_or(Vec3::Y),
                _ => Vec3::Y,
            }
        })
    }

    /// Every joint (wrist first, then each finger's chain).
    pub fn joints(&self) -> Vec<Vec3> {
        let mut out = vec![self.wrist];
        for chain in &self.fingers {
            out.extend_from_slice(chain);
        }
        out
    }

    /// Line strips that draw the skeleton: the palm (wrist to each finger base, and the
    /// knuckle line from index to little), then each finger.
    pub fn strips(&self) -> Vec<Vec<Vec3>> {
        let bases: [Vec3; 5] =
            core::array::from_fn(|i| self.fingers[i].first().copied().unwrap_or(self.wrist));
        let mut out = Vec::with_capacity(11);
        for base in bases {
            out.push(vec![self.wrist, base]);
        }
        out.push(bases[1..].to_vec());
        for chain in &self.fingers {
            out.push(chain.clone());
        }
        out
    }
}

/// Walks a chain from `base` along `dir`, bending towards `curl` (perpendicular to `dir`) by
/// the cumulative joint angles; returns base, one point per segment end.
fn chain(base: Vec3, dir: Vec3, curl: Vec3, lengths: &[f32], angles: &[f32]) -> Vec<Vec3> {
    // Rotating `dir` about `dir x curl` by a positive angle moves it towards `curl`.
    let axis = dir.cross(curl).normalize_or(Vec3::NEG_X);
    let mut out = Vec::with_capacity(lengths.len() + 1);
    let mut point = base;
    let mut bend = 0.0;
    out.push(point);
    for (length, angle) in lengths.iter().zip(angles) {
        bend += angle;
        point += Quat::from_axis_angle(axis, bend) * dir * *length;
        out.push(point);
    }
    out
}

/// One long finger (index to little) of the operator model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FingerGeometry {
    /// Base knuckle (MCP) position, hand frame.
    pub base: Vec3,
    /// Proximal, middle and distal phalanx lengths, metres.
    pub lengths: [f32; 3],
}

/// The operator's thumb.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThumbGeometry {
    /// Carpometacarpal joint position, hand frame.
    pub base: Vec3,
    /// Metacarpal, proximal and distal lengths, metres.
    pub lengths: [f32; 3],
    /// Direction of the relaxed, fully rotated-out thumb (in the palm plane).
    pub direction: Vec3,
}

/// The operator's pose as the glove measures it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OperatorPose {
    /// Flexion per finger ([`FINGERS`] order): 0 = straight, 1 = fist.
    pub flexion: [f32; 5],
    /// Thumb rotation: 0 = rotated out beside the palm, 1 = rotated in under the palm.
    pub thumb_opposition: f32,
}

impl OperatorPose {
    /// From the glove's normalised positions ([`teleop_msgs::GLOVE_CHANNELS`] order; 0 =
    /// bent, 1 = open; thumb rotation 0 = innermost, 1 = outermost). Values are clamped to
    /// [0, 1]; a NaN counts as open.
    pub fn from_glove(position: &[f32; 6]) -> Self {
        let closed = |open: f32| (1.0 - clamp01(open)).clamp(0.0, 1.0);
        Self {
            flexion: core::array::from_fn(|i| closed(position[GLOVE_CHANNEL_OF_FINGER[i]])),
            thumb_opposition: closed(position[GLOVE_THUMB_ROTATION]),
        }
    }
}

/// A glove position clamped to [0, 1]; NaN (no information) counts as open (1).
fn clamp01(v: f32) -> f32 {
    if v.is_nan() {
        1.0
    } else {
        v.clamp(0.0, 1.0)
    }
}

/// A human right hand with typical adult proportions.
#[derive(Debug, Clone, PartialEq)]
pub struct OperatorHand {
    /// Index, middle, ring, little.
    pub fingers: [FingerGeometry; 4],
    /// The thumb.
    pub thumb: ThumbGeometry,
    /// MCP, PIP and DIP flexion at a full fist, radians.
    pub finger_fist_rad: [f32; 3],
    /// CMC, MCP and IP flexion at a full thumb flexion, radians.
    pub thumb_fist_rad: [f32; 3],
    /// Rotation of the thumb about the palm's long axis at full opposition, radians.
    pub opposition_rad: f32,
}

impl Default for OperatorHand {
    fn default() -> Self {
        let finger = |x: f32, y: f32, lengths: [f32; 3]| FingerGeometry {
            base: Vec3::new(x, y, 0.0),
            lengths,
        };
        Self {
            fingers: [
                finger(-0.028, 0.095, [0.045, 0.026, 0.020]),
                finger(-0.008, 0.098, [0.050, 0.030, 0.022]),
                finger(0.012, 0.094, [0.046, 0.028, 0.021]),
                finger(0.030, 0.086, [0.036, 0.020, 0.018]),
            ],
            thumb: ThumbGeometry {
                base: Vec3::new(-0.025, 0.025, -0.010),
                lengths: [0.045, 0.032, 0.028],
                direction: Vec3::new(-0.6, 0.8, 0.0),
            },
            finger_fist_rad: [90f32.to_radians(), 100f32.to_radians(), 70f32.to_radians()],
            thumb_fist_rad: [15f32.to_radians(), 50f32.to_radians(), 70f32.to_radians()],
            opposition_rad: 80f32.to_radians(),
        }
    }
}

impl OperatorHand {
    /// The hand in `pose`.
    pub fn pose(&self, pose: &OperatorPose) -> Skeleton {
        let thumb = {
            let f = pose.flexion[0].clamp(0.0, 1.0);
            let turn =
                Quat::from_rotation_y(-pose.thumb_opposition.clamp(0.0, 1.0) * self.opposition_rad);
            let angles = self.thumb_fist_rad.map(|a| a * f);
            chain(
                self.thumb.base,
                turn * self.thumb.direction,
                turn * PALM_SIDE,
                &self.thumb.lengths,
                &angles,
            )
        };
        let long = |i: usize| {
            let g = &self.fingers[i - 1];
            let f = pose.flexion[i].clamp(0.0, 1.0);
            let angles = self.finger_fist_rad.map(|a| a * f);
            chain(g.base, Vec3::Y, PALM_SIDE, &g.lengths, &angles)
        };
        Skeleton {
            wrist: Vec3::ZERO,
            fingers: [thumb, long(1), long(2), long(3), long(4)],
        }
    }
}

/// The Revo2's geometry and joint ranges.
#[derive(Debug, Clone, PartialEq)]
pub struct Revo2Hand {
    /// Angle at normalised 0 and 1 of each joint, radians, Revo2 joint order
    /// ([`teleop_msgs::REVO2_JOINTS`]).
    pub ranges_rad: [(f32, f32); 6],
    /// Base (MCP) of index, middle, ring and pinky.
    pub finger_bases: [Vec3; 4],
    /// Proximal and distal phalanx lengths of index, middle, ring and pinky.
    pub finger_lengths: [[f32; 2]; 4],
    /// Distal joint angle per radian of proximal angle (the finger linkage).
    pub distal_coupling: f32,
    /// Thumb base (the abduction joint).
    pub thumb_base: Vec3,
    /// Thumb metacarpal, proximal and distal lengths (the metacarpal only turns with the
    /// abduction joint; the flex joint bends the other two).
    pub thumb_lengths: [f32; 3],
    /// Direction of the thumb at abduction 0 (rotated out, in the palm plane).
    pub thumb_direction: Vec3,
    /// Thumb distal joint angle per radian of thumb flex (the thumb linkage).
    pub thumb_coupling: f32,
}

impl Default for Revo2Hand {
    fn default() -> Self {
        let ranges_rad = teleop_revo2_protocol::DEFAULT_JOINT_RANGES
            .map(|r| (r.min_deg.to_radians(), r.max_deg.to_radians()));
        Self {
            ranges_rad,
            finger_bases: [
                Vec3::new(-0.027, 0.100, 0.0),
                Vec3::new(-0.008, 0.103, 0.0),
                Vec3::new(0.011, 0.100, 0.0),
                Vec3::new(0.029, 0.093, 0.0),
            ],
            finger_lengths: [
                [0.048, 0.042],
                [0.052, 0.044],
                [0.048, 0.042],
                [0.040, 0.036],
            ],
            distal_coupling: 0.9,
            thumb_base: Vec3::new(-0.028, 0.030, -0.012),
            thumb_lengths: [0.040, 0.038, 0.032],
            thumb_direction: Vec3::new(-0.6, 0.8, 0.0),
            thumb_coupling: 0.8,
        }
    }
}

impl Revo2Hand {
    /// Joint angles (radians, Revo2 joint order) of normalised positions (0 = open, 1 =
    /// closed; clamped; NaN counts as open).
    pub fn angles(&self, normalised: &[f32; 6]) -> [f32; 6] {
        core::array::from_fn(|j| {
            let q = if normalised[j].is_nan() {
                0.0
            } else {
                normalised[j].clamp(0.0, 1.0)
            };
            let (lo, hi) = self.ranges_rad[j];
            lo + (hi - lo) * q
        })
    }

    /// Normalised positions of joint angles in radians (the inverse of [`angles`](Self::angles),
    /// for hands that report physical units).
    pub fn normalise(&self, radians: &[f32; 6]) -> [f32; 6] {
        core::array::from_fn(|j| {
            let (lo, hi) = self.ranges_rad[j];
            if (hi - lo).abs() < f32::EPSILON {
                0.0
            } else {
                ((radians[j] - lo) / (hi - lo)).clamp(0.0, 1.0)
            }
        })
    }

    /// The hand at normalised joint positions (Revo2 joint order).
    pub fn pose(&self, normalised: &[f32; 6]) -> Skeleton {
        let a = self.angles(normalised);
        let thumb = {
            let turn = Quat::from_rotation_y(-a[REVO2_THUMB_ABDUCT]);
            let flex = a[REVO2_JOINT_OF_FINGER[0]];
            chain(
                self.thumb_base,
                turn * self.thumb_direction,
                turn * PALM_SIDE,
                &self.thumb_lengths,
                &[0.0, flex, flex * self.thumb_coupling],
            )
        };
        let long = |i: usize| {
            let flex = a[REVO2_JOINT_OF_FINGER[i]];
            chain(
                self.finger_bases[i - 1],
                Vec3::Y,
                PALM_SIDE,
                &self.finger_lengths[i - 1],
                &[flex, flex * self.distal_coupling],
            )
        };
        Skeleton {
            wrist: Vec3::ZERO,
            fingers: [thumb, long(1), long(2), long(3), long(4)],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const EPS: f32 = 1e-5;

    fn finger_length(chain: &[Vec3]) -> f32 {
        chain.windows(2).map(|w| (w[1] - w[0]).length()).sum()
    }

    #[test]
    fn open_operator_hand_points_straight_out() {
        let hand = OperatorHand::default();
        let open = OperatorPose::from_glove(&[1.0; 6]);
        assert_eq!(open.flexion, [0.0; 5]);
        let s = hand.pose(&open);
        for (i, name) in FINGERS.iter().enumerate().skip(1) {
            let chain = &s.fingers[i];
            let base = chain[0];
            let tip = *chain.last().unwrap();
            let len: f32 = hand.fingers[i - 1].lengths.iter().sum();
            assert!(
                (tip - (base + Vec3::Y * len)).length() < EPS,
                "{} {tip}",
                name
            );
            assert!(s.tip_directions()[i].abs_diff_eq(Vec3::Y, EPS));
        }
        // The open thumb lies in its plane, pointing out and forward.
        let thumb_tip = s.tips()[0];
        assert!((thumb_tip.z - hand.thumb.base.z).abs() < EPS);
        assert!(thumb_tip.x < hand.thumb.base.x && thumb_tip.y > hand.thumb.base.y);
    }

    #[test]
    fn operator_fist_curls_the_tips_under_the_palm() {
        let hand = OperatorHand::default();
        let fist = OperatorPose::from_glove(&[0.0; 6]);
        assert_eq!(fist.flexion, [1.0; 5]);
        assert_eq!(fist.thumb_opposition, 1.0);
        let s = hand.pose(&fist);
        for (i, name) in FINGERS.iter().enumerate().skip(1) {
            let chain = &s.fingers[i];
            let base = chain[0];
            let tip = *chain.last().unwrap();
            // Curled: below the palm, back towards the wrist, close to the knuckle.
            assert!(tip.z < base.z - 0.01, "{} {tip}", name);
            assert!(tip.y < base.y + 0.01, "{} {tip}", name);
            assert!((tip - base).length() < 0.6 * finger_length(chain));
            // Phalanx lengths do not change with the pose.
            let len: f32 = hand.fingers[i - 1].lengths.iter().sum();
            assert!((finger_length(chain) - len).abs() < EPS);
        }
        // The opposed, flexed thumb is under the palm.
        assert!(s.tips()[0].z < hand.thumb.base.z - 0.02);
    }

    #[test]
    fn glove_channels_map_to_fingers() {
        // little, ring, middle, index, thumb, thumb rotation
        let p = OperatorPose::from_glove(&[0.9, 0.8, 0.7, 0.6, 0.5, 0.25]);
        let expect = [0.5, 0.4, 0.3, 0.2, 0.1];
        for (got, want) in p.flexion.iter().zip(expect) {
            assert!((got - want).abs() < EPS, "{:?}", p.flexion);
        }
        assert!((p.thumb_opposition - 0.75).abs() < EPS);
        // Out of range and NaN are clamped (NaN = open).
        let p = OperatorPose::from_glove(&[2.0, -1.0, f32::NAN, 0.5, 0.5, 0.5]);
        assert_eq!(&p.flexion[2..], &[0.0, 1.0, 0.0]);
    }

    #[test]
    fn revo2_joint_ranges() {
        let hand = Revo2Hand::default();
        // The pipeline's assumed ranges: 0..90 degrees for every joint.
        assert_eq!(hand.angles(&[0.0; 6]), [0.0; 6]);
        for a in hand.angles(&[1.0; 6]) {
            assert!((a - core::f32::consts::FRAC_PI_2).abs() < EPS);
        }
        // Clamped, NaN = open, and back again.
        let a = hand.angles(&[-0.5, 1.5, f32::NAN, 0.5, 0.25, 1.0]);
        assert_eq!(a[0], 0.0);
        assert!((a[1] - core::f32::consts::FRAC_PI_2).abs() < EPS);
        assert_eq!(a[2], 0.0);
        let back = hand.normalise(&a);
        assert!((back[3] - 0.5).abs() < EPS && (back[4] - 0.25).abs() < EPS);

        // 0 = open: straight fingers; 1 = closed: curled under the palm.
        let open = hand.pose(&[0.0; 6]);
        for (i, name) in FINGERS.iter().enumerate().skip(1) {
            let chain = &open.fingers[i];
            let len: f32 = hand.finger_lengths[i - 1].iter().sum();
            assert!(
                (chain[2] - (chain[0] + Vec3::Y * len)).length() < EPS,
                "{name}"
            );
            assert_eq!(chain.len(), 3, "{name}: two phalanges");
        }
        let closed = hand.pose(&[1.0; 6]);
        for (i, name) in FINGERS.iter().enumerate().skip(1) {
            let chain = &closed.fingers[i];
            assert!(chain[2].z < chain[0].z - 0.03, "{}", name);
            // The proximal phalanx points straight down at 90 degrees.
            assert!((chain[1] - chain[0])
                .normalize()
                .abs_diff_eq(Vec3::NEG_Z, 1e-4));
        }
        // Each finger closes monotonically: its reach along the palm shrinks.
        let mut last = f32::INFINITY;
        for k in 0..=10 {
            let q = k as f32 / 10.0;
            let reach = hand.pose(&[0.0, 0.0, q, 0.0, 0.0, 0.0]).tips()[1].y;
            assert!(reach < last, "q {q}: {reach} after {last}");
            last = reach;
        }
        // Only the driven finger moves.
        let one = hand.pose(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        assert_eq!(one.fingers[1], open.fingers[1]);
        assert_ne!(one.fingers[2], open.fingers[2]);
        // Thumb abduction swings the thumb under the palm; flexion alone keeps it beside it.
        let out = hand.pose(&[0.0; 6]).tips()[0];
        let abducted = hand.pose(&[0.0, 1.0, 0.0, 0.0, 0.0, 0.0]).tips()[0];
        assert!((out.z - hand.thumb_base.z).abs() < EPS);
        assert!(abducted.z < hand.thumb_base.z - 0.05);
    }

    #[test]
    fn strips_and_joints_cover_the_skeleton() {
        let s = OperatorHand::default().pose(&OperatorPose::default());
        assert_eq!(s.strips().len(), 5 + 1 + 5);
        assert_eq!(s.joints().len(), 1 + 5 * 4);
        let r = Revo2Hand::default().pose(&[0.0; 6]);
        assert_eq!(r.joints().len(), 1 + 4 + 4 * 3);
    }
}
