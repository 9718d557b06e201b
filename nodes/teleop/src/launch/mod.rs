//! `teleop launch`: the topology file and the supervisor that runs it.

pub mod config;
pub mod summary;
pub mod supervisor;
