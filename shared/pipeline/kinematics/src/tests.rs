//! The hand models against the shipped profiles, the old hard-coded Revo2 model and the
//! public URDFs.

use glam::Vec3;
use teleop_hand_profile::HandProfile;

use crate::*;

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

#[test]
fn glove_fingers_map_to_the_operator_model_s_fingers() {
    // GLOVE_FINGERS: little, ring, middle, index, thumb; FINGERS: thumb .. little.
    let mapped: Vec<Option<usize>> = (0..6).map(finger_of_glove_finger).collect();
    assert_eq!(mapped, [Some(4), Some(3), Some(2), Some(1), Some(0), None]);
    assert_eq!(FINGERS[finger_of_glove_finger(4).unwrap()], "thumb");
}
