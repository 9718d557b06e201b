//! CAN frame transport: one trait, SocketCAN, slcan serial adapters, and a local bus.
//!
//! [`CanLink`] is a blocking CAN channel with timeouts: [`CanLink::send`] one frame,
//! [`CanLink::recv`] one frame or nothing within a timeout. Backends:
//!
//! - [`SlcanLink`]: a serial-line adapter speaking slcan (CANable, CANtact, USBtin, CAN232) over
//!   `serialport`; the codec is [`slcan`] (pure, no I/O).
//! - [`SocketCanLink`]: a Linux SocketCAN interface (`can0`) through the `socketcan` crate.
//! - [`local`]: an in-process bus ([`local::LocalBus`]) and a Unix-socket bus
//!   ([`local::BusServer`], [`local::SocketLink`]) for the simulator and tests, with optional
//!   frame-level timing from [`timing`].
//!
//! [`LinkSpec`] names a link in configuration (`slcan:/dev/ttyACM0`, `socketcan:can0`,
//! `local:/tmp/allegro.sock`) and [`open`] opens it. This crate knows nothing of any device's
//! protocol (that lives in e.g. `teleop-allegro-protocol`, generic over
//! [`embedded_can::Frame`], which [`CanFrame`] implements) and must not depend on one.
//!
//! ```
//! use std::time::Duration;
//! use teleop_can_link::{local::LocalBus, CanFrame, CanLink};
//!
//! let bus = LocalBus::new();
//! let (mut node, mut hand) = (bus.end(), bus.end());
//! node.send(&CanFrame::standard(0x04A, &[]).expect("an 11-bit id"))?;
//! let got = hand.recv(Duration::from_millis(100))?;
//! assert_eq!(got.map(|f| f.to_string()), Some("04A#".to_string()));
//! # Ok::<(), teleop_can_link::LinkError>(())
//! ```

mod error;
mod frame;
pub mod local;
pub mod slcan;
mod slcan_link;
mod socketcan_link;
mod spec;
pub mod timing;

use std::time::Duration;

pub use error::LinkError;
pub use frame::{CanFrame, MAX_EXTENDED_ID, MAX_STANDARD_ID};
pub use slcan_link::SlcanLink;
pub use socketcan_link::SocketCanLink;
pub use spec::{Bitrate, LinkSpec, DEFAULT_SERIAL_BAUD};

/// The CAN controller's error state (ISO 11898-1 fault confinement).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum BusState {
    /// Normal operation (both error counters below 96).
    #[default]
    ErrorActive,
    /// An error counter reached 96.
    ErrorWarning,
    /// An error counter reached 128: the controller sends only passive error flags.
    ErrorPassive,
    /// The transmit error counter passed 255: the controller left the bus.
    BusOff,
}

impl std::fmt::Display for BusState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            BusState::ErrorActive => "error-active",
            BusState::ErrorWarning => "error-warning",
            BusState::ErrorPassive => "error-passive",
            BusState::BusOff => "bus-off",
        })
    }
}

/// Counters of one link since it was opened.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct LinkCounters {
    /// Frames sent.
    pub tx: u64,
    /// Frames received.
    pub rx: u64,
    /// Errors: refused commands or frames (slcan BEL), bus error reports, unparsable lines,
    /// error frames.
    pub errors: u64,
    /// Frames lost because a receive queue was full (adapter overrun flags, local bus queue).
    pub overruns: u64,
}

/// One CAN channel. Implementations are blocking with timeouts; not shared between threads
/// (move it to the thread that uses it).
pub trait CanLink: Send {
    /// Sends one frame (queues it for transmission; does not wait for the bus).
    fn send(&mut self, frame: &CanFrame) -> Result<(), LinkError>;

    /// Waits at most `timeout` for one received frame; `Ok(None)` when none came. A zero
    /// timeout only takes what already arrived.
    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, LinkError>;

    /// The controller state as last reported.
    fn bus_state(&self) -> BusState;

    /// Counters since the link was opened.
    fn counters(&self) -> LinkCounters;

    /// What this link is, for logs and errors: `slcan:/dev/ttyACM0`, `socketcan:can0`,
    /// `local:/tmp/allegro.sock`.
    fn describe(&self) -> &str;

    /// When the frame the last [`recv`](Self::recv) returned was on the bus, by the link's own
    /// clock (an slcan adapter's `Z1` timestamp; the local bus's time): milliseconds modulo
    /// [`STAMP_WRAP_MS`]. `None` when the link gives none. A loaded host delays when a frame is
    /// read, not this: a caller tells a late frame from a missing one by it.
    fn rx_stamp_ms(&self) -> Option<u16> {
        None
    }
}

/// Receive timestamps wrap here (slcan's `Z1`: 0000..EA5F ms).
pub const STAMP_WRAP_MS: u16 = 60_000;

/// Milliseconds from stamp `from` to stamp `to` (both modulo [`STAMP_WRAP_MS`]).
pub fn stamp_gap_ms(from: u16, to: u16) -> u16 {
    let w = u32::from(STAMP_WRAP_MS);
    ((u32::from(to) % w + w - u32::from(from) % w) % w) as u16
}

impl<T: CanLink + ?Sized> CanLink for Box<T> {
    fn send(&mut self, frame: &CanFrame) -> Result<(), LinkError> {
        (**self).send(frame)
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, LinkError> {
        (**self).recv(timeout)
    }

    fn bus_state(&self) -> BusState {
        (**self).bus_state()
    }

    fn counters(&self) -> LinkCounters {
        (**self).counters()
    }

    fn describe(&self) -> &str {
        (**self).describe()
    }

    fn rx_stamp_ms(&self) -> Option<u16> {
        (**self).rx_stamp_ms()
    }
}

/// Opens the link `spec` names, at `bitrate` where the link sets it (slcan). SocketCAN
/// interfaces get their bit rate outside (`ip link set can0 type can bitrate 1000000`); the
/// local bus has no bit rate of its own (its server sets the timing).
pub fn open(spec: &LinkSpec, bitrate: Bitrate) -> Result<Box<dyn CanLink>, LinkError> {
    Ok(match spec {
        LinkSpec::Slcan { path, serial_baud } => {
            Box::new(SlcanLink::open(path, *serial_baud, bitrate)?)
        }
        LinkSpec::SocketCan { interface } => Box::new(SocketCanLink::open(interface)?),
        LinkSpec::Local { socket } => Box::new(local::SocketLink::connect(socket)?),
    })
}
