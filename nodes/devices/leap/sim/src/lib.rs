//! The simulated LEAP Hand, for running the LEAP pipeline without hardware: 16 Dynamixel XC330
//! servos on one half-duplex serial bus behind a pseudo-terminal, as the node sees a U2D2.
//!
//! It speaks Protocol 2.0 with the protocol crate's codecs (`teleop-leap-protocol`: framing,
//! CRC, the control table's items) and implements the servos' behaviour on its own:
//!
//! - [`table`]: one servo's control table and the firmware's checks of reads and writes;
//! - [`servo`]: one servo's firmware: instructions, operating modes and their control loops,
//!   hardware errors and shutdown, reboot (pure);
//! - [`hand`]: the 16 joints the servos drive, with hard stops and a virtual object (pure);
//! - [`bus`]: the servos on one line: byte timing at the baud rate, return delays, broadcast,
//!   sync and fast sync reads, baud mismatches, noise, CRC errors and status faults (pure);
//! - [`serve`]: the bus on the simulator kit's pseudo-terminal behind a stable link, in real
//!   time, with its cable and the faults injected at run time;
//! - [`control`]: the control socket's commands (the kit's vocabulary and the hand's own).
//!
//! Must not depend on: the LEAP node (a driver bug must not hide behind shared driver code).

pub mod bus;
pub mod control;
pub mod hand;
pub mod serve;
pub mod servo;
pub mod table;

pub use serve::{Sim, SimOptions};
