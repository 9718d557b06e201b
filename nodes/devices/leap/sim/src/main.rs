//! `teleop-sim-leap`: the simulated LEAP Hand.

fn main() {}
