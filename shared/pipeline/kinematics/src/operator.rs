//! The operator's hand: a human right hand posed from the glove.

use glam::{Quat, Vec3};

use crate::Skeleton;

/// The operator's (glove) fingers in anatomical order, the order of the operator model's
/// per-finger arrays.
pub const FINGERS: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];

/// The glove channel (`GLOVE_CHANNELS` index: little, ring, middle, index, thumb,
/// thumb_rotation) of each finger in [`FINGERS`] order.
pub const GLOVE_CHANNEL_OF_FINGER: [usize; 5] = [4, 3, 2, 1, 0];

/// The operator model's finger ([`FINGERS`] index) of a glove finger (`GLOVE_FINGERS` index:
/// little .. thumb, as a hand profile's `operator` holds it); `None` past the thumb.
pub fn finger_of_glove_finger(glove_finger: usize) -> Option<usize> {
    GLOVE_CHANNEL_OF_FINGER
        .iter()
        .position(|&channel| channel == glove_finger)
}
/// The glove's thumb rotation channel.
pub const GLOVE_THUMB_ROTATION: usize = 5;

/// Towards the palm (the direction flexion curls a finger).
const PALM_SIDE: Vec3 = Vec3::new(0.0, 0.0, -1.0);

/// Walks a chain from `base` along `dir`, bending towards `curl` (perpendicular to `dir`) by
/// the cumulative joint angles: `point` gets the base, then each segment's end.
fn walk(
    base: Vec3,
    dir: Vec3,
    curl: Vec3,
    lengths: &[f32; 3],
    angles: &[f32; 3],
    mut point: impl FnMut(Vec3),
) {
    // Rotating `dir` about `dir x curl` by a positive angle moves it towards `curl`.
    let axis = dir.cross(curl).normalize_or(Vec3::NEG_X);
    let mut at = base;
    let mut bend = 0.0;
    point(at);
    for (length, angle) in lengths.iter().zip(angles) {
        bend += angle;
        at += Quat::from_axis_angle(axis, bend) * dir * *length;
        point(at);
    }
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
    /// Radius of each fingertip's pad ([`FINGERS`] order), metres.
    pub pad_radius: [f32; 5],
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
            // Half a fingertip's thickness (about 16 mm, the thumb's 18 mm).
            pad_radius: [0.009, 0.008, 0.008, 0.008, 0.007],
        }
    }
}

impl OperatorHand {
    /// Walks finger `i` ([`FINGERS`] order) in `pose` (see [`walk`]).
    fn walk_finger(&self, pose: &OperatorPose, i: usize, point: impl FnMut(Vec3)) {
        let f = clamp01_flexion(pose.flexion[i]);
        if i == 0 {
            let turn = Quat::from_rotation_y(
                -clamp01_flexion(pose.thumb_opposition) * self.opposition_rad,
            );
            let angles = self.thumb_fist_rad.map(|a| a * f);
            walk(
                self.thumb.base,
                turn * self.thumb.direction,
                turn * PALM_SIDE,
                &self.thumb.lengths,
                &angles,
                point,
            );
        } else {
            let g = &self.fingers[i - 1];
            let angles = self.finger_fist_rad.map(|a| a * f);
            walk(g.base, Vec3::Y, PALM_SIDE, &g.lengths, &angles, point);
        }
    }

    /// The hand in `pose`.
    pub fn pose(&self, pose: &OperatorPose) -> Skeleton {
        let fingers: Vec<Vec<Vec3>> = (0..FINGERS.len())
            .map(|i| {
                let mut chain = Vec::with_capacity(4);
                self.walk_finger(pose, i, |p| chain.push(p));
                chain
            })
            .collect();
        // The wrist to each finger's base, and the knuckle line from index to little.
        let bases: Vec<Vec3> = fingers.iter().map(|chain| chain[0]).collect();
        let mut palm: Vec<Vec<Vec3>> = bases.iter().map(|b| vec![Vec3::ZERO, *b]).collect();
        palm.push(bases[1..].to_vec());
        Skeleton {
            wrist: Vec3::ZERO,
            palm,
            fingers,
        }
    }

    /// The centres of the fingertip pads in `pose` ([`FINGERS`] order): on each distal
    /// segment, one pad radius back from its tip, so the pad's sphere ends at the fingertip.
    /// Allocates nothing.
    pub fn pads(&self, pose: &OperatorPose) -> [Vec3; 5] {
        core::array::from_fn(|i| {
            let (mut before, mut last) = (Vec3::ZERO, Vec3::ZERO);
            self.walk_finger(pose, i, |p| {
                before = last;
                last = p;
            });
            last - (last - before).normalize_or(Vec3::Y) * self.pad_radius[i]
        })
    }

    /// The gap between the pads of fingers `a` and `b` ([`FINGERS`] indices) in `pose`, metres:
    /// the distance between their centres less both radii (negative when they overlap).
    pub fn pad_gap(&self, pose: &OperatorPose, a: usize, b: usize) -> f32 {
        let pads = self.pads(pose);
        pads[a].distance(pads[b]) - self.pad_radius[a] - self.pad_radius[b]
    }
}

/// A flexion or opposition clamped to [0, 1] (NaN = 0: straight / rotated out).
fn clamp01_flexion(v: f32) -> f32 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(0.0, 1.0)
    }
}
