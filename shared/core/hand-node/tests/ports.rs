//! `HandPorts` on real iceoryx2 ports (a root and prefix of the test's own): what is counted,
//! and how often. A command sample is counted once however many cycles follow it: its clamps, or
//! its refusal; a loss of fresh commands is one timeout.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use teleop_hand_node::{Admission, HandPorts, Modes, Target, Timing};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{control_mode, units, HandCommand};
use teleop_runtime::{IpcSettings, NodeRuntime};

#[test]
fn each_command_sample_is_counted_once_and_a_loss_of_commands_once() {
    let dir = tempfile::tempdir().unwrap();
    let ipc = IpcSettings::isolated(dir.path());
    let node = NodeRuntime::new("allegro", &ipc).unwrap();
    let operator = NodeRuntime::new("operator", &ipc).unwrap();
    let profile = HandProfile::builtin("allegro").unwrap();
    let admission = Admission::new(&profile, Modes::POSITION);
    let timing = Timing {
        stale_after: Duration::from_millis(100),
        health_period: Duration::from_secs(60),
        resume_speed: f64::INFINITY,
    };
    let mut ports = HandPorts::new(&node, admission, timing).unwrap();
    let mut commands = operator.publisher::<HandCommand>().unwrap();
    let mut cmd = HandCommand {
        hand_model: profile.model_id,
        joint_count: 16,
        control_mode: control_mode::POSITION,
        units: units::PHYSICAL,
        ..Default::default()
    };
    for (j, joint) in cmd.joints.iter_mut().zip(&profile.joints) {
        j.target = (joint.lower + joint.upper) / 2.0;
    }
    // Two joints past their limits, followed for five cycles: two clamps.
    let mut over = cmd;
    over.joints[0].target = 10.0;
    over.joints[1].target = -10.0;
    commands.publish(&over).unwrap();
    for _ in 0..5 {
        let followed = ports.command().unwrap();
        assert_eq!(followed.joints[0].target, profile.joints[0].upper);
        assert_eq!(followed.joints[1].target, profile.joints[1].lower);
    }
    assert_eq!(ports.health().counters().clamps, 2);
    // A refused sample, seen for three cycles: one error; the hand holds.
    let mut nan = cmd;
    nan.joints[3].target = f32::NAN;
    commands.publish(&nan).unwrap();
    for _ in 0..3 {
        assert!(ports.command().is_none());
    }
    assert_eq!(ports.health().counters().errors, 1);
    // A second refused sample is counted again.
    commands.publish(&nan).unwrap();
    assert!(ports.command().is_none());
    assert_eq!(ports.health().counters().errors, 2);
    // The commands stop: one timeout, however many cycles pass.
    std::thread::sleep(Duration::from_millis(150));
    for _ in 0..3 {
        assert!(ports.command().is_none());
    }
    assert_eq!(ports.health().counters().timeouts, 1);
    // They come back: followed, clamps unchanged.
    commands.publish(&cmd).unwrap();
    assert!(ports.command().is_some());
    assert_eq!(ports.health().counters().clamps, 2);
    assert_eq!(ports.health().counters().timeouts, 1);
    // As the targets of a hand that takes joint angles: the command's, then a hold once stale.
    let Target::Follow(targets) = ports.target::<16>() else {
        panic!("a fresh command is followed");
    };
    for (t, j) in targets.iter().zip(&cmd.joints) {
        assert_eq!(*t, f64::from(j.target));
    }
    std::thread::sleep(Duration::from_millis(150));
    assert_eq!(ports.target::<16>(), Target::Hold);
}
