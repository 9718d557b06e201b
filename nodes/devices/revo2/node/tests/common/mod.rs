//! Helpers shared by the tests that run the `teleop-revo2` binary and talk to it over IPC
//! (`against_sim`, `veth`).

use std::time::{Duration, Instant};

use teleop_msgs::{control_mode, device_model, units, HandCommand, HandState};
use teleop_runtime::Subscriber;

/// A normalised position command for the Revo2's six joints, speed limit 2.0 per second.
pub fn position_command(targets: [f32; 6]) -> HandCommand {
    let mut c = HandCommand {
        hand_model: device_model::REVO2,
        joint_count: 6,
        control_mode: control_mode::POSITION,
        units: units::NORMALISED,
        ..Default::default()
    };
    for (j, t) in c.joints.iter_mut().zip(targets) {
        j.target = t;
        j.speed_limit = 2.0;
    }
    c
}

/// The reported joint positions.
pub fn positions(s: &HandState) -> Vec<f32> {
    s.active_joints().iter().map(|j| j.position).collect()
}

/// Drains `states` every 2 ms until one satisfies `ok` and returns it; panics after `timeout`
/// naming `what`, with `logs()` (the processes' logs) in the message.
pub fn wait_state(
    states: &Subscriber<HandState>,
    timeout: Duration,
    what: &str,
    mut ok: impl FnMut(&HandState) -> bool,
    logs: impl Fn() -> String,
) -> HandState {
    let start = Instant::now();
    loop {
        let mut found = None;
        states.drain(|s| {
            if found.is_none() && ok(s) {
                found = Some(*s);
            }
        });
        if let Some(s) = found {
            return s;
        }
        assert!(
            start.elapsed() < timeout,
            "timed out waiting for {what}\n{}",
            logs()
        );
        std::thread::sleep(Duration::from_millis(2));
    }
}
