//! The Shadow Hand node, built up from its parts. So far the host side of the palm's 1 kHz
//! exchange, pure and tested without a bus:
//! - [`schedule`]: what each cycle's command asks of the motors (which motors, which data type,
//!   which demand), as the shipped driver schedules it;
//! - [`motors`]: what a status says about each motor: its replies by type, its flags by name,
//!   and whether a serious flag stops its demand.
//!
//! Still to come (issue 14): the `Driver` on `teleop-ecat-master` (identity by product code,
//! SM/FMMU programming), position control and calibration from the profile, `hand/state` and
//! tactile, the `teleop-shadow` executable and `teleop shadow`.
//!
//! Must not depend on: the emulator.

pub mod motors;
pub mod schedule;
