//! The Revo2 process: the hand's EtherCAT cycle on `ethercrab`'s real MainDevice state machine.
//!
//! - [`pump`]: carries ethercrab's frames over a `teleop-ecat-link` link (socket to the emulator,
//!   or a raw socket on an interface) and survives link loss;
//! - [`bus`]: bring-up to OP (identity check, configuration in PRE-OP with read-back, PDO
//!   assignment with an SDO-polling fallback for tactile data) and AL error acknowledge;
//! - [`convert`]: pure conversions between hand commands/state/tactile messages and the Revo2
//!   process data;
//! - [`node`]: the cycle (absolute deadlines, stale command -> hold, working-counter checks,
//!   recovery, reconnect) and publishing;
//! - [`mailbox`]: raw mailbox access on ethercrab's `Command` API (any device): the FoE
//!   mailbox port of `teleop-foe` and the normal SDO download ethercrab lacks;
//! - [`flash`]: the Revo2 firmware upgrade (section 6): file checks, upgrade settings, BOOT on
//!   the bootstrap mailbox, FoE transfer, restart, version read-back.
//!
//! The Revo2's dictionary and process-data layout live in `teleop-revo2-protocol`.

pub mod bus;
pub mod config;
pub mod convert;
pub mod flash;
pub mod mailbox;
pub mod node;
pub mod pump;

pub use config::{Revo2Config, Transport};
pub use node::run;
