//! File access over EtherCAT (FoE, ETG.1000.6): writing a file (typically a firmware image) to
//! a SubDevice through its mailbox.
//!
//! # What this crate owns
//!
//! - [`mailbox`]: the 6-byte mailbox header (length, address, channel/priority, type,
//!   counter) and mailbox error replies, as pure encode/decode functions;
//! - [`packet`]: the FoE packets (RRQ, WRQ, DATA, ACK, ERR, BUSY) and error codes, pure
//!   encode/decode; the decoders are total (any bytes give a value or a typed error);
//! - [`client`]: the write client ([`Client::write`]): write request, data packets sized to the
//!   receive mailbox, acknowledges, BUSY (the packet is sent again after a delay), the server's
//!   ERR packets, reply timeouts and repeats, and an ERR to the server when the client gives up.
//!
//! The client talks to the SubDevice through a [`MailboxPort`]: "put this message in the
//! receive mailbox" and "take what is in the send mailbox". Getting the SubDevice into a state
//! where FoE works (usually BOOT, with its sync managers on the bootstrap mailbox) and what the
//! file means are the caller's business.
//!
//! # What it must not depend on
//!
//! No EtherCAT MainDevice (ethercrab implements [`MailboxPort`] in the node that owns the bus),
//! no device (the Revo2's file names, codes and checks live elsewhere), no I/O of its own.
//!
//! # Example
//!
//! ```
//! use teleop_foe::packet::{ErrorCode, Packet};
//!
//! let ack = Packet::Ack { packet: 7 }.to_vec();
//! assert_eq!(ack, [4, 0, 7, 0, 0, 0]);
//! assert_eq!(Packet::decode(&ack), Ok(Packet::Ack { packet: 7 }));
//! let err = Packet::decode(&[5, 0, 0x0A, 0x80, 0, 0, b'n', b'o']).unwrap();
//! assert_eq!(err, Packet::Error { code: ErrorCode::NO_RIGHTS, text: b"no" });
//! ```

pub mod client;
pub mod mailbox;
pub mod packet;

pub use client::{
    Busy, Client, ClientConfig, FoeError, MailboxPort, PortError, Progress, Summary, OVERHEAD,
};
pub use packet::{ErrorCode, Packet};
