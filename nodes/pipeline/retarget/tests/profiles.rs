//! Retargeting for every shipped hand driven by the operator's glove trajectory recorded in
//! `recordings/grasp.sample.mcap`, in every mode: limits and couplings hold on every command, the
//! grasp closes and opens the hand, the glove finger the Allegro lacks moves nothing; and in
//! `joint` mode (the glove map) flexion is monotone.

#![allow(clippy::unwrap_used)]

use std::path::Path;

use teleop_hand_profile::{CommandUnits, HandProfile, RetargetMode, Role};
use teleop_kinematics::Chains;
use teleop_msgs::{units, GloveState, HandCommand, Message};
use teleop_recording::{read_messages, Filter};
use teleop_retarget::{NodeConfig, RetargetEngine};
use teleop_retargeting::Calibration;

/// The recorded glove samples (about 6 s of a reach, squeeze and release).
fn recorded_glove() -> Vec<GloveState> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../recordings/grasp.sample.mcap");
    let samples: Vec<GloveState> = read_messages(&path, &Filter::topics([GloveState::TOPIC]))
        .unwrap()
        .map(|m| m.unwrap().decode::<GloveState>().unwrap())
        .collect();
    assert!(samples.len() > 500, "{} glove samples", samples.len());
    samples
}

fn run(profile: &HandProfile, glove: &[GloveState], mode: RetargetMode) -> Vec<HandCommand> {
    let mut config = NodeConfig::default();
    config.retarget.mode = Some(mode);
    let mut engine = RetargetEngine::new(&config, Calibration::default(), profile).unwrap();
    glove
        .iter()
        .filter_map(|s| engine.on_glove(s, s.header.stamp_ns).command)
        .collect()
}

/// A joint's value in radians, whatever the command's units.
fn radians(profile: &HandProfile, cmd: &HandCommand, j: usize) -> f32 {
    let v = cmd.joints[j].target;
    if cmd.units == units::NORMALISED {
        profile.joints[j].radians(v)
    } else {
        v
    }
}

#[test]
fn every_command_respects_the_profile_limits_and_couplings() {
    let glove = recorded_glove();
    for (name, mode) in HandProfile::builtin_names()
        .flat_map(|n| RetargetMode::ALL.into_iter().map(move |m| (n, m)))
    {
        let profile = HandProfile::builtin(name).unwrap();
        let commands = run(&profile, &glove, mode);
        let name = format!("{name} ({})", mode.name());
        assert_eq!(commands.len(), glove.len(), "{name}");
        let want_units = match profile.command_units {
            CommandUnits::Normalised => units::NORMALISED,
            CommandUnits::Radians => units::PHYSICAL,
        };
        let mut couplings = 0;
        for cmd in &commands {
            assert_eq!(cmd.hand_model, profile.model_id, "{name}");
            assert_eq!(cmd.units, want_units, "{name}");
            assert_eq!(usize::from(cmd.joint_count), profile.joints.len(), "{name}");
            for (j, joint) in profile.joints.iter().enumerate() {
                let q = radians(&profile, cmd, j);
                assert!(
                    q.is_finite() && q >= joint.lower - 1e-5 && q <= joint.upper + 1e-5,
                    "{name} {}: {q} outside [{}, {}]",
                    joint.name,
                    joint.lower,
                    joint.upper
                );
                if let Some(c) = joint.coupling {
                    let leader = radians(&profile, cmd, c.to);
                    assert!(
                        (q - joint.clamp(c.ratio * leader)).abs() < 1e-5,
                        "{name} {} = {q} does not follow {} = {leader}",
                        joint.name,
                        profile.joints[c.to].name
                    );
                    couplings += 1;
                }
            }
        }
        if profile.name == "shadow" {
            assert_eq!(couplings, 4 * commands.len());
        }
    }
}

#[test]
fn the_recorded_grasp_closes_and_opens_every_hand() {
    let glove = recorded_glove();
    for name in HandProfile::builtin_names() {
        let profile = HandProfile::builtin(name).unwrap();
        // The glove map: a flexion joint the glove's index finger (channel 3) drives.
        let commands = run(&profile, &glove, RetargetMode::Joint);
        let index = profile
            .joints
            .iter()
            .position(|j| j.role == Role::Flex && j.glove.channels.iter().any(|&(c, _)| c == 3))
            .unwrap();
        let closure: Vec<f32> = commands
            .iter()
            .map(|c| profile.joints[index].normalised(radians(&profile, c, index)))
            .collect();
        let (lo, hi) = closure
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(lo < 0.1 && hi > 0.35, "{name}: index closure {lo}..{hi}");
        // Fingertip modes: the index fingertip goes down towards the palm and comes back.
        let chains = Chains::new(&profile);
        let finger = profile
            .fingers
            .iter()
            .position(|f| f.operator == Some(3))
            .unwrap();
        for mode in [RetargetMode::Vector, RetargetMode::Pinch] {
            let depth: Vec<f64> = run(&profile, &glove, mode)
                .iter()
                .map(|c| {
                    let q: Vec<f64> = (0..profile.joints.len())
                        .map(|j| f64::from(radians(&profile, c, j)))
                        .collect();
                    -chains.pad(finger, &q).z
                })
                .collect();
            let deepest = depth.iter().copied().fold(f64::MIN, f64::max);
            let (first, last) = (depth[0], depth[depth.len() - 1]);
            assert!(
                deepest > first + 0.03 && deepest > last + 0.03,
                "{name} ({}): index pad {:.3} m below the palm at first, {deepest:.3} at most, \
                 {last:.3} at the end",
                mode.name(),
                first
            );
        }
    }
}

/// The glove map only: fingertip optimisation may open one joint to close the fingertip.
#[test]
fn more_flexion_never_opens_a_joint() {
    let glove = recorded_glove();
    // The same operator, every finger 150 raw units more bent (0 = bent, 1000 = open).
    let bent: Vec<GloveState> = glove
        .iter()
        .map(|s| {
            let mut s = *s;
            for raw in &mut s.raw_position[..5] {
                *raw = raw.saturating_sub(150);
            }
            s
        })
        .collect();
    for name in HandProfile::builtin_names() {
        let profile = HandProfile::builtin(name).unwrap();
        let (a, b) = (
            run(&profile, &bent, RetargetMode::Joint),
            run(&profile, &glove, RetargetMode::Joint),
        );
        // Joints driven only by finger channels with positive gains, or following one.
        let by_fingers = |j: usize| {
            let g = &profile.joints[j].glove;
            !g.channels.is_empty() && g.channels.iter().all(|&(c, gain)| c < 5 && gain > 0.0)
        };
        let joints: Vec<usize> = (0..profile.joints.len())
            .filter(|&j| match profile.joints[j].coupling {
                Some(c) => by_fingers(c.to) && c.ratio > 0.0,
                None => by_fingers(j),
            })
            .collect();
        assert!(joints.len() >= 5, "{name}");
        let mut strictly = 0;
        for (k, (ca, cb)) in a.iter().zip(&b).enumerate() {
            for &j in &joints {
                let (qa, qb) = (radians(&profile, ca, j), radians(&profile, cb, j));
                let joint = &profile.joints[j];
                let closing = (joint.closed - joint.open).signum();
                assert!(
                    (qa - qb) * closing >= -1e-6,
                    "{name} sample {k} {}: bent {qa} < {qb}",
                    joint.name
                );
                strictly += usize::from((qa - qb) * closing > 1e-3);
            }
        }
        assert!(
            strictly > a.len(),
            "{name}: bending the fingers changed little"
        );
    }
}

#[test]
fn the_allegro_ignores_the_glove_finger_it_does_not_have() {
    let glove = recorded_glove();
    let profile = HandProfile::builtin("allegro").unwrap();
    let wiggled: Vec<GloveState> = glove
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let mut s = *s;
            s.raw_position[0] = ((k * 37) % 1001) as u16; // the little finger, anywhere
            s
        })
        .collect();
    for mode in RetargetMode::ALL {
        let (a, b) = (run(&profile, &wiggled, mode), run(&profile, &glove, mode));
        for (ca, cb) in a.iter().zip(&b) {
            let ta: Vec<f32> = ca.active_joints().iter().map(|j| j.target).collect();
            let tb: Vec<f32> = cb.active_joints().iter().map(|j| j.target).collect();
            assert_eq!(ta, tb, "{}", mode.name());
        }
        // The Revo2 does have a little finger: the same wiggle moves its pinky.
        let revo2 = HandProfile::builtin("revo2").unwrap();
        let (a, b) = (run(&revo2, &wiggled, mode), run(&revo2, &glove, mode));
        assert!(
            a.iter()
                .zip(&b)
                .any(|(x, y)| x.joints[5].target != y.joints[5].target),
            "{}",
            mode.name()
        );
    }
}
