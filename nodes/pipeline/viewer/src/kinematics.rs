//! Kinematic hand models: joint values in, joint positions out (metres, hand frame).
//!
//! Both hands use the same frame, a right hand lying palm down: the wrist at the origin, the
//! fingers pointing along +Y, the back of the hand facing +Z (so flexion curls the fingers
//! towards -Z) and the thumb on the -X side (the frame of `teleop_hand_profile`).
//!
//! - [`OperatorHand`]: a human hand posed from the glove's normalised positions (five flexions
//!   and the thumb's rotation), with the usual MCP/PIP/DIP coupling of a human finger; its
//!   fingers are in anatomical order ([`FINGERS`]: thumb, index, middle, ring, little).
//! - [`RobotHand`]: whichever robot hand a profile describes, its fingers in the profile's
//!   order, posed from joint angles in radians by forward kinematics of each finger's chain.
//!
//! Pure geometry with `glam`: no I/O, no rerun.

use glam::{Quat, Vec3};
use teleop_hand_profile::HandProfile;

/// The operator's (glove) fingers in anatomical order, the order of the operator model's
/// per-finger arrays.
pub const FINGERS: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];

/// The glove channel ([`teleop_msgs::GLOVE_CHANNELS`] index) of each finger in [`FINGERS`]
/// order.
pub const GLOVE_CHANNEL_OF_FINGER: [usize; 5] = [4, 3, 2, 1, 0];
/// The glove's thumb rotation channel.
pub const GLOVE_THUMB_ROTATION: usize = 5;

/// Towards the palm (the direction flexion curls a finger).
const PALM_SIDE: Vec3 = Vec3::new(0.0, 0.0, -1.0);

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
        let fingers = vec![thumb, long(1), long(2), long(3), long(4)];
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
}

/// A robot hand drawn from its profile's kinematics (`teleop_hand_profile`): each finger is a
/// chain from its base pose (`base`, `base_rpy`); each link translates by its `origin` from the
/// previous frame, then turns by `ratio ×` its joint's angle about its `axis`; the fingertip is
/// the `tip` offset in the last link's frame. Posed from joint angles in radians, in the
/// profile's joint order.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotHand {
    profile: HandProfile,
    /// Where the profile came from (a file, a recording, or compiled in), for display.
    source: String,
    /// Base pose of each finger, hand frame.
    bases: Vec<(Vec3, Quat)>,
    /// The finger of each fingertip sensor, in `hand/tactile` order.
    tip_fingers: Vec<usize>,
    /// The fingers whose base outlines the palm, ordered around the wrist (thumb side first).
    palm: Vec<usize>,
}

impl RobotHand {
    /// The hand of `profile`; `source` says where it came from.
    pub fn new(profile: HandProfile, source: impl Into<String>) -> Self {
        let bases: Vec<(Vec3, Quat)> = profile
            .fingers
            .iter()
            .map(|f| {
                let [roll, pitch, yaw] = f.base_rpy;
                // URDF convention: roll about x, then pitch about y, then yaw about z (fixed axes).
                let rotation = Quat::from_rotation_z(yaw)
                    * Quat::from_rotation_y(pitch)
                    * Quat::from_rotation_x(roll);
                (Vec3::from(f.base), rotation)
            })
            .collect();
        // Finger names are unique (the loader checks), so a fingertip's name finds its finger.
        let tip_fingers = profile
            .fingertips()
            .filter_map(|tip| profile.fingers.iter().position(|f| f.name == tip.name))
            .collect();
        // The palm: the bases in front of the wrist, by their angle around it from the thumb
        // side (-X) to the little finger side (+X). A chain behind the wrist (the Shadow Hand's
        // wrist joints) is drawn on its own.
        let mut palm: Vec<(f32, usize)> = bases
            .iter()
            .enumerate()
            .filter(|(_, (base, _))| base.y > 0.0)
            .map(|(i, (base, _))| (base.x.atan2(base.y), i))
            .collect();
        palm.sort_by(|a, b| a.0.total_cmp(&b.0));
        Self {
            profile,
            source: source.into(),
            bases,
            tip_fingers,
            palm: palm.into_iter().map(|(_, i)| i).collect(),
        }
    }

    /// The builtin profile of a contract hand model id (`hand_model` fields), if one is
    /// compiled in.
    pub fn builtin_for_model(model_id: u8) -> Option<Self> {
        HandProfile::builtin_for_model(model_id).map(|p| {
            let source = format!("builtin `{}`", p.name);
            Self::new(p, source)
        })
    }

    /// The profile.
    pub fn profile(&self) -> &HandProfile {
        &self.profile
    }

    /// Where the profile came from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The finger index of each fingertip sensor, in `hand/tactile` order.
    pub fn tip_fingers(&self) -> &[usize] {
        &self.tip_fingers
    }

    /// Every joint at its `open` angle, radians.
    pub fn open_angles(&self) -> Vec<f32> {
        self.profile.joints.iter().map(|j| j.open).collect()
    }

    /// The hand at joint angles in radians (profile joint order; missing joints rest at their
    /// `open` angle, angles are clamped to the limits and NaN counts as open).
    pub fn pose(&self, radians: &[f32]) -> Skeleton {
        let angles: Vec<f32> = self
            .profile
            .joints
            .iter()
            .enumerate()
            .map(|(i, j)| j.clamp(radians.get(i).copied().unwrap_or(j.open)))
            .collect();
        let fingers: Vec<Vec<Vec3>> = self
            .profile
            .fingers
            .iter()
            .zip(&self.bases)
            .map(|(finger, &(base, rotation))| {
                let mut position = base;
                let mut rotation = rotation;
                let mut points = vec![position];
                for link in &finger.links {
                    position += rotation * Vec3::from(link.origin);
                    let angle = link.joint.map_or(0.0, |j| angles[j]) * link.ratio;
                    rotation *= Quat::from_axis_angle(Vec3::from(link.axis), angle);
                    push_distinct(&mut points, position);
                }
                push_distinct(&mut points, position + rotation * Vec3::from(finger.tip));
                points
            })
            .collect();
        let mut outline = vec![Vec3::ZERO];
        outline.extend(self.palm.iter().map(|&i| fingers[i][0]));
        outline.push(Vec3::ZERO);
        Skeleton {
            wrist: Vec3::ZERO,
            palm: if self.palm.is_empty() {
                vec![]
            } else {
                vec![outline]
            },
            fingers,
        }
    }
}

/// Appends `p` unless it is where the chain already is (a link that only turns).
fn push_distinct(points: &mut Vec<Vec3>, p: Vec3) {
    if points.last().is_none_or(|last| last.distance(p) > 1e-7) {
        points.push(p);
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
    fn a_model_number_draws_the_shipped_profile_of_that_name() {
        // One numbering: each shipped profile's number is the contract's for its name, so a
        // sample's `hand_model` finds the hand it names.
        for name in HandProfile::builtin_names() {
            let profile = HandProfile::builtin(name).unwrap();
            let model = teleop_msgs::device_model::from_name(name);
            assert_eq!(Some(profile.model_id), model, "{name}");
            let drawn = RobotHand::builtin_for_model(profile.model_id).unwrap();
            assert_eq!(drawn.profile().name, name);
        }
        let unknown = teleop_msgs::device_model::UNKNOWN;
        assert!(RobotHand::builtin_for_model(unknown).is_none());
        let glove = teleop_msgs::device_model::GLOVE;
        assert!(RobotHand::builtin_for_model(glove).is_none());
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

    fn builtin(name: &str) -> RobotHand {
        let profile = HandProfile::builtin(name).expect("a shipped profile");
        RobotHand::new(profile, "test")
    }

    /// Radians of normalised values (0 = open, 1 = closed) per joint.
    fn at(hand: &RobotHand, normalised: &[f32]) -> Vec<f32> {
        hand.profile()
            .joints
            .iter()
            .zip(normalised)
            .map(|(j, q)| j.radians(*q))
            .collect()
    }

    #[test]
    fn revo2_profile_poses_the_hand_as_the_old_model() {
        // Fingertips (thumb, index, middle, ring, pinky) of the hard-coded Revo2 model this
        // viewer drew before hand profiles (commit 6879ae8 compared both models directly), at
        // normalised joint positions in the Revo2 order (thumb flex, thumb abduct, index,
        // middle, ring, pinky).
        let golden: [([f32; 6], [[f32; 3]; 5]); 5] = [
            (
                [0.0; 6],
                [
                    [-0.094, 0.118, -0.012],
                    [-0.027, 0.19, 0.0],
                    [-0.008, 0.199, 0.0],
                    [0.011, 0.19, 0.0],
                    [0.029, 0.169, 0.0],
                ],
            ),
            (
                [1.0; 6],
                [
                    [0.019_888, 0.037_653, -0.017_740],
                    [-0.027, 0.058_517, -0.054_570],
                    [-0.008, 0.059_542, -0.058_883],
                    [0.011, 0.058_517, -0.054_570],
                    [0.029, 0.057_443, -0.045_632],
                ],
            ),
            (
                [0.5; 6],
                [
                    [-0.017_146, 0.087_501, -0.083_843],
                    [-0.027, 0.137_236, -0.075_812],
                    [-0.008, 0.143_222, -0.080_634],
                    [0.011, 0.137_236, -0.075_812],
                    [0.029, 0.124_109, -0.064_173],
                ],
            ),
            (
                [0.2, 0.9, 0.1, 0.4, 0.7, 1.0],
                [
                    [-0.009_149, 0.112_527, -0.077_652],
                    [-0.027, 0.187_552, -0.019_859],
                    [-0.008, 0.161_266, -0.071_475],
                    [0.011, 0.100_982, -0.079_251],
                    [0.029, 0.057_443, -0.045_632],
                ],
            ),
            (
                [1.0, 0.0, 0.3, 0.0, 0.6, 0.25],
                [
                    [-0.033_740, 0.037_653, -0.059_889],
                    [-0.027, 0.169_028, -0.054_570],
                    [-0.008, 0.199, 0.0],
                    [0.011, 0.119_052, -0.079_821],
                    [0.029, 0.156_391, -0.039_744],
                ],
            ),
        ];
        let hand = builtin("revo2");
        assert_eq!(hand.profile().joints.len(), 6);
        assert_eq!(hand.tip_fingers(), &[0, 1, 2, 3, 4]);
        for (q, old) in golden {
            let new = hand.pose(&at(&hand, &q)).tips();
            for (finger, (n, o)) in new.iter().zip(old).enumerate() {
                let o = Vec3::from(o);
                assert!(n.distance(o) < 1e-3, "{q:?} finger {finger}: {n} vs {o}");
            }
        }
    }

    /// Sum of segment lengths of each finger.
    fn lengths(s: &Skeleton) -> Vec<f32> {
        s.fingers.iter().map(|c| finger_length(c)).collect()
    }

    /// Each finger's flexion joints moved from open to closed (the rest open) bring its tip
    /// closer to the palm at every step (the centre of the palm's outline, 2 cm to the palm
    /// side), keeping the link lengths.
    fn flexion_closes_towards_the_palm(hand: &RobotHand) {
        let open = hand.open_angles();
        let open_pose = hand.pose(&open);
        let outline = &open_pose.palm[0];
        let centre = outline.iter().sum::<Vec3>() / outline.len() as f32 - Vec3::Z * 0.02;
        for (f, finger) in hand.profile().fingers.iter().enumerate() {
            let flex: Vec<usize> = (0..hand.profile().joints.len())
                .filter(|&j| {
                    let joint = &hand.profile().joints[j];
                    joint.finger == f && joint.role == teleop_hand_profile::Role::Flex
                })
                .collect();
            if flex.is_empty() {
                continue;
            }
            let start = open_pose.tips()[f].distance(centre);
            let mut last = start;
            for k in 1..=4 {
                let mut angles = open.clone();
                for &j in &flex {
                    angles[j] = hand.profile().joints[j].radians(k as f32 / 4.0);
                }
                let posed = hand.pose(&angles);
                let distance = posed.tips()[f].distance(centre);
                assert!(
                    distance < last,
                    "{}: step {k}: {distance} m from the palm after {last}",
                    finger.name
                );
                last = distance;
                for (a, b) in lengths(&posed).iter().zip(lengths(&open_pose)) {
                    assert!((a - b).abs() < 1e-5, "{}: lengths {a} vs {b}", finger.name);
                }
            }
            assert!(
                last < start - 0.02,
                "{}: closed {last} m from the palm, open {start}",
                finger.name
            );
        }
    }

    #[test]
    fn revo2_opens_straight_and_closes_under_the_palm() {
        let hand = builtin("revo2");
        let open = hand.pose(&hand.open_angles());
        // Open: index .. pinky point straight along +Y, two phalanges each.
        for chain in &open.fingers[1..] {
            assert_eq!(chain.len(), 3);
            let along = chain[2] - chain[0];
            assert!(along.normalize().abs_diff_eq(Vec3::Y, EPS), "{along}");
        }
        flexion_closes_towards_the_palm(&hand);
        // Only the driven finger moves.
        let one = hand.pose(&at(&hand, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0]));
        assert_eq!(one.fingers[1], open.fingers[1]);
        assert_ne!(one.fingers[2], open.fingers[2]);
        // Out of range and NaN: clamped to the limits, NaN = open.
        let wild = hand.pose(&[f32::NAN, 9.0, -3.0, 0.0, 0.0, 0.0]);
        let expect = hand.pose(&[0.0, core::f32::consts::FRAC_PI_2, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(wild, expect);
        // Missing joints rest open.
        assert_eq!(hand.pose(&[]), open);
    }

    #[test]
    fn allegro_has_four_fingers_that_close_towards_the_palm() {
        let hand = builtin("allegro");
        assert_eq!(hand.profile().fingers.len(), 4);
        assert_eq!(hand.profile().joints.len(), 16);
        assert!(hand.tip_fingers().is_empty(), "no fingertip sensors");
        let open = hand.pose(&hand.open_angles());
        assert_eq!(open.fingers.len(), 4);
        assert_eq!(open.tips().len(), 4);
        flexion_closes_towards_the_palm(&hand);
        // Joint 0 turns a finger about its own axis (as in the URDF): a straight index stays
        // where it is, a bent one swings sideways.
        let mut turned = hand.open_angles();
        turned[0] = 0.3;
        assert!(hand.pose(&turned).tips()[0].abs_diff_eq(open.tips()[0], EPS));
        let mut bent = hand.open_angles();
        bent[1] = 1.0;
        let mut bent_turned = bent.clone();
        bent_turned[0] = 0.3;
        let moved = hand.pose(&bent_turned).tips()[0] - hand.pose(&bent).tips()[0];
        assert!(moved.x.abs() > 0.01, "{moved}");
    }

    #[test]
    fn shadow_has_24_joints_and_coupled_distal_joints() {
        let hand = builtin("shadow");
        let profile = hand.profile();
        assert_eq!(profile.joints.len(), 24);
        assert_eq!(hand.tip_fingers().len(), 5);
        flexion_closes_towards_the_palm(&hand);
        // J1 follows J2: a command with J2 closed and J1 at its coupled angle curls the
        // distal phalanx further than J2 alone.
        let ffj1 = profile.joint_index("FFJ1").expect("FFJ1");
        let ffj2 = profile.joint_index("FFJ2").expect("FFJ2");
        let coupling = profile.joints[ffj1].coupling.expect("FFJ1 is coupled");
        assert_eq!(coupling.to, ffj2);
        let ff = profile
            .fingers
            .iter()
            .position(|f| f.name == "ff")
            .expect("ff");
        let mut j2 = hand.open_angles();
        j2[ffj2] = 1.0;
        let mut both = j2.clone();
        both[ffj1] = coupling.ratio * j2[ffj2];
        let (j2_only, coupled) = (hand.pose(&j2), hand.pose(&both));
        // (curled back towards the wrist).
        assert!(coupled.tips()[ff].y < j2_only.tips()[ff].y - 0.01);
        // The middle phalanx is where J2 alone put it: J1 turns only the distal one.
        let n = coupled.fingers[ff].len();
        assert!(coupled.fingers[ff][n - 2].abs_diff_eq(j2_only.fingers[ff][n - 2], EPS));
        for (a, b) in lengths(&coupled).iter().zip(lengths(&j2_only)) {
            assert!((a - b).abs() < 1e-6, "{a} vs {b}");
        }
    }

    /// A fingertip at joint angles given by name (the rest open).
    fn tip_at(hand: &RobotHand, finger: &str, angles: &[(&str, f32)]) -> Vec3 {
        let profile = hand.profile();
        let mut q = hand.open_angles();
        for (name, a) in angles {
            q[profile.joint_index(name).expect(name)] = *a;
        }
        let f = profile.fingers.iter().position(|f| f.name == finger);
        hand.pose(&q).tips()[f.expect(finger)]
    }

    #[test]
    fn allegro_and_shadow_chains_reproduce_their_urdfs() {
        // Expected tips: forward kinematics of allegro_hand_description_right.urdf and of
        // sr_description's right hand (joint origins, rpy and axes as published), mapped into
        // the hand frame as config/hands/{allegro,shadow}.toml describe.
        let allegro = builtin("allegro");
        let cases = [
            (
                &allegro,
                "index",
                vec![
                    ("index_0", 0.2),
                    ("index_1", 0.8),
                    ("index_2", 0.6),
                    ("index_3", 0.4),
                ],
                Vec3::new(-0.068_550, 0.145_957, -0.100_535),
            ),
            (
                &allegro,
                "thumb",
                vec![
                    ("thumb_0", 1.0),
                    ("thumb_1", 0.5),
                    ("thumb_2", 0.7),
                    ("thumb_3", 0.3),
                ],
                Vec3::new(-0.054_896, 0.079_325, -0.103_080),
            ),
        ];
        let shadow = builtin("shadow");
        let shadow_cases = [
            (
                &shadow,
                "lf",
                vec![
                    ("LFJ5", 0.5),
                    ("LFJ4", 0.2),
                    ("LFJ3", 0.6),
                    ("LFJ2", 0.8),
                    ("LFJ1", 0.8),
                ],
                Vec3::new(-0.004_926, 0.089_239, -0.085_482),
            ),
            (
                &shadow,
                "th",
                vec![
                    ("THJ5", 0.4),
                    ("THJ4", 1.0),
                    ("THJ3", 0.1),
                    ("THJ2", 0.5),
                    ("THJ1", 0.9),
                ],
                Vec3::new(-0.014_539, 0.098_510, -0.048_393),
            ),
        ];
        for (hand, finger, angles, expect) in cases.iter().chain(&shadow_cases) {
            let tip = tip_at(hand, finger, angles);
            assert!(tip.distance(*expect) < 1e-5, "{finger}: {tip} vs {expect}");
        }
        // Straight and not spread, the Shadow's first finger points out from its knuckle:
        // 0.045 + 0.025 + 0.026.
        let ff = tip_at(&shadow, "ff", &[("FFJ4", 0.0)]);
        assert!(
            ff.abs_diff_eq(Vec3::new(-0.033, 0.095 + 0.096, 0.0), EPS),
            "{ff}"
        );
    }

    #[test]
    fn base_rpy_is_roll_then_pitch_then_yaw_about_fixed_axes() {
        let mut profile = HandProfile::builtin("revo2").expect("revo2");
        let finger = &mut profile.fingers[1];
        finger.base = [0.0; 3];
        finger.base_rpy = [
            core::f32::consts::FRAC_PI_2,
            0.0,
            core::f32::consts::FRAC_PI_2,
        ];
        finger.links.truncate(1);
        finger.links[0].joint = None;
        finger.tip = [0.0, 0.1, 0.0];
        let hand = RobotHand::new(profile, "test");
        // Roll +90 deg about x takes +Y to +Z; yaw about z leaves +Z alone.
        let tip = hand.pose(&hand.open_angles()).tips()[1];
        assert!(tip.abs_diff_eq(Vec3::new(0.0, 0.0, 0.1), EPS), "{tip}");
    }

    #[test]
    fn strips_and_joints_cover_the_skeleton() {
        let s = OperatorHand::default().pose(&OperatorPose::default());
        assert_eq!(s.strips().len(), 5 + 1 + 5);
        assert_eq!(s.joints().len(), 1 + 5 * 4);
        // Revo2: the palm outline (wrist, five bases, wrist), then five fingers; joints:
        // thumb base, two joints and tip; base, joint and tip of the others.
        let hand = builtin("revo2");
        let r = hand.pose(&hand.open_angles());
        assert_eq!(
            r.palm,
            vec![{
                let mut outline = vec![Vec3::ZERO];
                outline.extend(r.fingers.iter().map(|c| c[0]));
                outline.push(Vec3::ZERO);
                outline
            }]
        );
        assert_eq!(r.strips().len(), 1 + 5);
        assert_eq!(r.joints().len(), 1 + 4 + 4 * 3);
    }
}
