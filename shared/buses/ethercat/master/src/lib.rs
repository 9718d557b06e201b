//! The EtherCAT master of every EtherCAT hand: ethercrab's MainDevice on a `teleop-ecat-link`
//! link, bring-up to OP, and the cyclic loop, with the device behind a small [`Driver`] trait.
//!
//! # What this crate owns
//!
//! - [`pump`]: carries ethercrab's frames over a `teleop-ecat-link` link (in-process, Unix
//!   socket, raw AF_PACKET) and survives link loss;
//! - [`bus`]: the bus's lifetime (the pump or ethercrab's own raw-socket task, reopened after
//!   that task ends), the bus scan, the AL error acknowledge, and the working counter a healthy
//!   cycle returns, computed from the SubDevices' process data;
//! - [`driver`]: what a device provides (identity check, PRE-OP configuration, pack, unpack,
//!   hold, an optional side channel, and for a device without PDOs its own process data
//!   layout, exchanged with one LRW of the master's);
//! - [`cycle`]: bring-up with a driver and the cycle (absolute deadlines, the driver's hold
//!   whenever the host gives no command (its policy: `teleop-hand-node`), working-counter and
//!   AL-state checks of every SubDevice, recovery, counters), reporting to a [`Host`] (the
//!   node's ports), run as a transport under `teleop-hand-node`'s session loop (reconnect,
//!   back-off, link-down reports, the hold on stop once per session);
//! - [`mailbox`]: raw mailbox access on ethercrab's `Command` API (any device): the FoE mailbox
//!   port of `teleop-foe` and the normal SDO download ethercrab lacks;
//! - [`transport`]: where the bus is (`sim:`, `interface:`, `ethercrab:`).
//!
//! # What it must not depend on
//!
//! Any device (its protocol crate, its conversions: those are the driver's), the message
//! contract and iceoryx2 ports (those are the host's; `teleop-runtime` is used for its clock
//! only, `teleop-hand-node` for its session loop only), and the emulators (only in tests).

pub mod bus;
pub mod cycle;
pub mod driver;
pub mod mailbox;
pub mod pump;
pub mod transport;

pub use bus::{
    connector, expected_wkc, recover_op, scan, Bus, CurrentBus, Found, OpGroup, PreOpGroup,
    MAX_PDI, MAX_SUBDEVICES,
};
pub use cycle::{
    bring_up, discover, leave_op, run, Counters, Event, Exchange, Host, Settings, WrongDevice,
    FIRST_BACKOFF, MAX_BACKOFF,
};
pub use driver::{Driver, Image, OwnExchange, OwnLayout};
pub use pump::{Connect, Pump, PumpStatus};
pub use transport::Transport;
