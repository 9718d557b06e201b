//! The glove process and its serial link to the EH55BF1 exoskeleton glove.
//!
//! - [`link`]: request/answer exchanges over `serialport` (USB serial, Bluetooth SPP or a
//!   pseudo-terminal), with timeouts, resynchronisation and counters; also used by
//!   `teleop glove`.
//!   The port is tuned on opening with `teleop_runtime::serial_latency` (low-latency mode, the
//!   USB-serial adapter's latency timer checked).
//! - [`node`]: the node's loop: force command in, glove state and diagnostics out, link-down
//!   handling with reopen and backoff, zero force on stop.
//!
//! The wire protocol itself lives in `teleop-glove-protocol`; this crate does the I/O.

pub mod link;
pub mod node;
pub mod service;

pub use link::{GloveLink, LinkError, LinkStats};
pub use node::{run, GloveConfig};
