//! The Shadow Hand node: the Hand E's palm (protocol 0220) on the shared EtherCAT master at
//! 1 kHz, driven from `hand/command` with position control on the host.
//! - [`config`]: the configuration file (transport, mapping, demand mode, gains, calibration);
//! - [`schedule`]: what each cycle's command asks of the motors (which motors, which data type,
//!   which demand), as the shipped driver schedules it;
//! - [`motors`]: what a status says about each motor: its replies by type, its flags by name,
//!   and whether a serious flag stops its demand;
//! - [`joints`]: sensor words to calibrated joint angles;
//! - [`driver`]: the `teleop-ecat-master` driver: identity by product code, the palm's sync
//!   managers and FMMUs programmed in PRE-OP, the LRW layout, position control every cycle;
//! - [`node`]: the ports (`hand/command` in; `hand/state`, `hand/tactile`, device info and
//!   health out);
//! - [`service`]: the palm's service modes for `teleop shadow` (info, ADC channel numbers, a
//!   crafted CAN message, motor-board flashing), one cycle at a time.
//!
//! Must not depend on: the emulator.

pub mod config;
pub mod driver;
pub mod joints;
pub mod motors;
pub mod node;
pub mod schedule;
pub mod service;

pub use config::{Checked, ShadowConfig};
pub use node::run;
