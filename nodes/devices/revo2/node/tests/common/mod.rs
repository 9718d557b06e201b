//! Helpers shared by the tests that run the `teleop-revo2` binary and talk to it over IPC
//! (`against_sim`, `veth`): the Revo2's commands and positions.

use teleop_msgs::{HandCommand, HandState};

/// A normalised position command for the Revo2's six joints, speed limit 2.0 per second.
pub fn position_command(targets: [f32; 6]) -> HandCommand {
    teleop_e2e::revo2_position_command(targets, 2.0)
}

/// The reported joint positions.
pub fn positions(s: &HandState) -> Vec<f32> {
    s.active_joints().iter().map(|j| j.position).collect()
}
