//! The Revo2 process: the hand as the first driver of `teleop-ecat-master`, whose MainDevice
//! (ethercrab), cycle, recovery and reconnect it runs.
//!
//! - [`bus`]: the Revo2 on the bus: identity check, configuration in PRE-OP with read-back, PDO
//!   assignment with an SDO-polling fallback for tactile data, string reads;
//! - [`driver`]: `impl Driver for Revo2`: pack, unpack, hold, the tactile SDO side channel;
//! - [`convert`]: pure conversions between hand commands/state/tactile messages and the Revo2
//!   process data;
//! - [`node`]: the node's ports as the master's host (commands in; hand state, tactile, health,
//!   device info out);
//! - [`flash`]: the Revo2 firmware upgrade (section 6): file checks, upgrade settings, BOOT on
//!   the bootstrap mailbox, FoE transfer, restart, version read-back.
//!
//! The Revo2's dictionary and process-data layout live in `teleop-revo2-protocol`; the bus, the
//! frame pump and the raw mailbox in `teleop-ecat-master`. Must not depend on the emulator
//! (outside tests).

pub mod bus;
pub mod config;
pub mod convert;
pub mod driver;
pub mod flash;
pub mod node;
pub mod service;

pub use teleop_ecat_master::mailbox;

pub use config::{Revo2Config, Transport};
pub use driver::Revo2;
pub use node::run;
