//! Force feedback for the Allegro and Shadow hands (and the Revo2), driven by the operator's glove
//! trajectory recorded in `recordings/grasp.sample.mcap`: the recorded glove goes through
//! retargeting with the hand's profile, a hand model follows the commands except where an object
//! stops its index finger at a quarter of its travel, and the feedback engine's force comes from the source each profile
//! configures; the glove finger the Allegro lacks never gets a force.

#![allow(clippy::unwrap_used)]

use std::path::Path;

use teleop_feedback::{Event, FeedbackEngine, NodeConfig};
use teleop_hand_profile::{HandProfile, Role};
use teleop_msgs::{
    contact_source, units, GloveForceCommand, GloveState, HandCommand, HandState, Message, Tactile,
};
use teleop_recording::{read_messages, Filter};
use teleop_retarget::RetargetEngine;
use teleop_retargeting::Calibration;

const INDEX: usize = 3; // glove order: little, ring, middle, index, thumb
const LITTLE: usize = 0;
const MIDDLE: usize = 2;

fn recorded_glove() -> Vec<GloveState> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../recordings/grasp.sample.mcap");
    read_messages(&path, &Filter::topics([GloveState::TOPIC]))
        .unwrap()
        .map(|m| m.unwrap().decode::<GloveState>().unwrap())
        .collect()
}

/// How the simulated hand reports contact.
#[derive(Clone, Copy, PartialEq)]
enum Touch {
    /// Only through its joints (position error; effort = stiffness × error).
    Joints,
    /// Fingertip normal force on the blocked finger's tip, too.
    Tactile,
    /// Fingertip sensors present but invalid (e.g. a PST that reports only raw pressure).
    InvalidTactile,
}

/// Runs the recorded glove through retargeting and a hand whose index flexion joints are stopped
/// at 25 % of their travel by an object; returns the glove force commands.
fn session(profile: &HandProfile, touch: Touch) -> Vec<GloveForceCommand> {
    let mut retarget = RetargetEngine::new(
        &teleop_retarget::NodeConfig::default(),
        Calibration::default(),
        profile,
    )
    .unwrap();
    let mut feedback = FeedbackEngine::new(&NodeConfig::default(), profile).unwrap();
    // The index finger: the finger whose joints the glove's index channel drives.
    let index_finger = profile
        .joints
        .iter()
        .find(|j| j.glove.channels.iter().any(|&(c, _)| c == INDEX))
        .unwrap()
        .finger;
    let blocked: Vec<bool> = profile
        .joints
        .iter()
        .map(|j| j.finger == index_finger && j.role == Role::Flex)
        .collect();
    let tips: Vec<usize> = profile
        .fingers
        .iter()
        .enumerate()
        .filter(|(_, f)| f.tip_sensor != teleop_hand_profile::TipSensor::None)
        .map(|(i, _)| i)
        .collect();
    let mut out = Vec::new();
    for (k, glove) in recorded_glove().iter().enumerate() {
        let now = 1_000_000_000 + k as u64 * 3_000_000;
        let Some(cmd) = retarget.on_glove(glove, glove.header.stamp_ns).command else {
            continue;
        };
        // Samples made now, as the hand node would.
        let mut state = hand_state(profile, &cmd, &blocked);
        state.header.stamp_ns = now;
        feedback.handle(&Event::Command(cmd), now);
        let pressing =
            (0..profile.joints.len()).any(|j| blocked[j] && state.joints[j].effort.abs() > 0.3);
        let mut o = feedback.handle(&Event::State(state), now);
        if touch != Touch::Joints && !tips.is_empty() {
            let mut t = Tactile {
                hand_model: profile.model_id,
                fingertip_count: tips.len() as u8,
                ..Default::default()
            };
            t.header.stamp_ns = now;
            for (slot, &finger) in tips.iter().enumerate() {
                let tip = &mut t.fingertips[slot];
                tip.normal_n = if finger == index_finger && pressing {
                    3.0
                } else {
                    0.0
                };
                if touch == Touch::InvalidTactile {
                    tip.normal_n = f32::NAN;
                }
            }
            o = feedback.handle(&Event::Tactile(t), now);
        }
        out.extend(o.command);
    }
    out
}

/// The hand follows the command except that the blocked joints stop at 25 % of their travel;
/// effort is a stiffness of 2 N m/rad times the position error.
fn hand_state(profile: &HandProfile, cmd: &HandCommand, blocked: &[bool]) -> HandState {
    let mut s = HandState {
        hand_model: cmd.hand_model,
        joint_count: cmd.joint_count,
        link_up: 1,
        units: cmd.units,
        ..Default::default()
    };
    for (j, joint) in profile.joints.iter().enumerate() {
        let to_rad = |v: f32| {
            if cmd.units == units::NORMALISED {
                joint.radians(v)
            } else {
                v
            }
        };
        let from_rad = |q: f32| {
            if cmd.units == units::NORMALISED {
                joint.normalised(q)
            } else {
                q
            }
        };
        let target = to_rad(cmd.joints[j].target);
        let stop = joint.radians(0.25);
        let reached = if blocked[j] && (target - stop) * (joint.closed - joint.open) > 0.0 {
            stop
        } else {
            target
        };
        s.joints[j].position = from_rad(reached);
        s.joints[j].effort = 2.0 * (target - reached).abs();
        s.joints[j].current_ma = f32::NAN;
    }
    s
}

fn max_force(commands: &[GloveForceCommand], finger: usize) -> i16 {
    commands.iter().map(|c| c.force[finger]).max().unwrap()
}

fn sources(commands: &[GloveForceCommand], finger: usize) -> Vec<u8> {
    let mut s: Vec<u8> = commands.iter().map(|c| c.source[finger]).collect();
    s.sort_unstable();
    s.dedup();
    s
}

#[test]
fn allegro_force_comes_from_its_joints_and_never_reaches_the_little_finger() {
    let allegro = HandProfile::builtin("allegro").unwrap();
    let forces = session(&allegro, Touch::Joints);
    assert!(forces.len() > 500);
    assert!(
        max_force(&forces, INDEX) > 300,
        "{}",
        max_force(&forces, INDEX)
    );
    assert!(sources(&forces, INDEX)
        .iter()
        .any(|&s| s == contact_source::POSITION_ERROR || s == contact_source::EFFORT));
    // The unblocked middle finger follows its command: no contact.
    assert_eq!(max_force(&forces, MIDDLE), 0);
    // No little finger on an Allegro: never a force, never a source.
    assert_eq!(max_force(&forces, LITTLE), 0);
    assert_eq!(sources(&forces, LITTLE), [contact_source::NONE]);
}

#[test]
fn shadow_force_comes_from_the_fingertip_then_from_joint_effort() {
    let shadow = HandProfile::builtin("shadow").unwrap();
    let tactile = session(&shadow, Touch::Tactile);
    assert!(max_force(&tactile, INDEX) > 300);
    assert!(sources(&tactile, INDEX).contains(&contact_source::TACTILE));
    assert_eq!(max_force(&tactile, MIDDLE), 0);
    // Fingertips present but invalid: the index's force comes from its joints' effort.
    let efforts = session(&shadow, Touch::InvalidTactile);
    assert!(max_force(&efforts, INDEX) > 300);
    let s = sources(&efforts, INDEX);
    assert!(!s.contains(&contact_source::TACTILE), "{s:?}");
    assert!(s.contains(&contact_source::EFFORT) || s.contains(&contact_source::POSITION_ERROR));
    assert_eq!(max_force(&efforts, MIDDLE), 0);
}

#[test]
fn revo2_force_comes_from_the_index_fingertip() {
    let revo2 = HandProfile::builtin("revo2").unwrap();
    let forces = session(&revo2, Touch::Tactile);
    assert!(max_force(&forces, INDEX) > 300);
    assert!(sources(&forces, INDEX).contains(&contact_source::TACTILE));
    assert_eq!(max_force(&forces, LITTLE), 0);
}
