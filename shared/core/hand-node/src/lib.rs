//! The hand-node core: the safety policy every hand node shares, written once.
//!
//! # What this crate owns
//!
//! - [`admission`]: the one rule by which a hand takes or refuses a `hand/command` (model,
//!   units, mode, joint count, finiteness, then the hand profile's joint limits in every mode),
//!   set up from the hand's profile, the only source of joint limits; and [`HandKind`], the
//!   check a hand node makes of its profile before it starts (model, joint count);
//! - [`HandPorts`] ([`ports`]): the hand node's ports and policy around it: commands followed
//!   only while fresh by their stamp and while the latched e-stop is released, stale -> hold
//!   (counted once per loss), refusals and clamps counted once per command sample and logged
//!   rate-limited, the ramp back after any hold, `hand/state` and `hand/tactile` out, health and
//!   device info periodically, also while the link is down;
//! - [`Resume`] ([`resume`]): the ramp from a held target back to the operator's pose (pure);
//! - [`RampedMove`] ([`moves`]): a service command's move (`home`, `move J DEG`) toward an
//!   [`Aim`], ramped with [`Resume`] from where the hand was first seen, ending after a time,
//!   and its report;
//! - [`session`]: the one session loop a device runs under, through its [`Transport`]: connect
//!   with typed errors (a lost link retried with back-off, a wrong device or setting looked at
//!   again slowly), one turn of the device's clock at a time, the device's hold on stop once per
//!   session on every way out, reconnect, and link-down reports while the hand is away.
//!
//! A device plugs in below this as a [`Transport`] (the EtherCAT master's cycle with a driver,
//! the Allegro's CAN stream): each turn asks
//! [`HandPorts::command`] for the command to follow (`None`: hold; [`HandPorts::target`] for
//! a hand that takes joint angles: its [`Target`]) and hands the turn's state
//! to [`HandPorts::publish`]; its link-down reports go to [`HandPorts::publish_down`].
//!
//! # What it must not depend on
//!
//! Any device protocol, bus or transport (they depend on it: the EtherCAT master uses
//! [`session`], which itself uses no message types); the retargeting and force-feedback logic.

pub mod admission;
pub mod moves;
pub mod ports;
pub mod resume;
pub mod session;

pub use admission::{Admission, HandKind, Modes, ProfileMismatch, Refusal};
pub use moves::{Aim, RampedMove};
pub use ports::{HandPorts, Target, Timing, REFUSAL_LOG_PERIOD};
pub use resume::Resume;
pub use session::{Backoff, Cause, ConnectError, Down, Ending, Fault, Transport};
