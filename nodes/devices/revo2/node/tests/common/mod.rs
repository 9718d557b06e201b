//! Helpers shared by the tests that run the `teleop-revo2` binary and talk to it over IPC
//! (`against_sim`, `veth`): the Revo2's commands and positions.

use teleop_msgs::{control_mode, device_model, units, HandCommand, HandState};

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
