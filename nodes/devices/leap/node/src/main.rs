//! `teleop-leap`: the LEAP Hand node.

fn main() {}
