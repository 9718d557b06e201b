//! The simulator kit: the mechanics every device simulator shares, so that a simulator's own
//! code is its device's behaviour (firmware timing, state machines, the wire protocol).
//!
//! - [`command`]: the fault vocabulary, parsed once and totally (any line gives a command or
//!   a [`ParseError`] naming the word and what was expected); the common words (`unplug MS`,
//!   `drop P`, `clear`, `stats`, `object NAME`) are the same on every simulator, and a
//!   device's own words parse through the same [`command::Args`];
//! - [`control`]: the [`Simulator`] a control socket drives, the one answer format (`ok ...` or
//!   `error: ...`, one line) and the one `stats` shape (`ok key=value ...`, [`Stats`], also
//!   read back by tests), served on `teleop_runtime::control`'s socket;
//! - [`process`]: the simulator process's `main` (logging, stop signals, the common
//!   [`SimArgs`], the control socket, exit status);
//! - [`ethercat`]: where an emulated EtherCAT device serves (a local socket or an interface);
//! - [`pty`]: the pseudo-terminal device behind a stable link, unplugged and plugged back in;
//! - [`outage`]: a fault that lasts a while (link down, bus off), a later one replacing the end;
//! - [`dice`]: seedable fault dice;
//! - [`plant`]: the joint plant's clock (fixed sub-steps up to a time), a torque-driven joint
//!   against hard stops, and first-order lags;
//! - [`object`]: the virtual objects a simulated hand can hold, one name each;
//! - [`testing`]: a simulator process under test (its directory, announce line, control
//!   socket, SIGINT at the end).
//!
//! Must not depend on: any device protocol (buses only: `teleop-ecat-link`), any node (a driver bug must not hide behind code
//! the simulator shares with it).

pub mod command;
pub mod control;
pub mod dice;
pub mod ethercat;
pub mod object;
pub mod outage;
pub mod plant;
pub mod process;
pub mod pty;
pub mod testing;

pub use command::{Args, Command, Common, DeviceCommand, ParseError};
pub use control::{answer, Simulator, Stats};
pub use object::Object;
pub use process::SimArgs;

/// Locks `m`, taking the value of a poisoned lock as it is (a simulator's state stays usable
/// after a panicking client thread).
pub fn lock<T>(m: &std::sync::Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
