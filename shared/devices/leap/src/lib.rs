//! Dynamixel Protocol 2.0 and the XC330 servos of the LEAP Hand: pure, total codecs.
//!
//! The LEAP Hand is 16 Dynamixel XC330-M288-T servos (the Lite hand: XL330-M077-T) on one
//! half-duplex serial bus. This crate owns what both ends of that bus must agree on:
//! - [`crc`]: the CRC-16 of Protocol 2.0;
//! - [`packet`]: framing, byte stuffing, the instruction and status packets, the receive-buffer
//!   scanner, requests as a device reads them ([`packet::Request`]), status packets and the
//!   error byte, and the combined Fast Sync Read reply with its per-servo blocks;
//! - [`xc330`]: the XC330-M288-T control table (and the XL330-M077-T's differences), operating
//!   modes, baud rates, hardware error bits, units, the 10-byte state read at 126;
//! - [`wire`]: packet sizes and byte times, for timeouts and wire-time budgets.
//!
//! Sources are public and cited where used: "ROBOTIS e-manual, Protocol 2.0, (section)" and
//! "e-manual, XC330-M288, control table" (and its shared includes).
//!
//! Everything is pure (no I/O, no clocks) and total: every decoder takes any bytes and returns a
//! value or a typed error ([`DecodeError`]), never panics. Encoders write into a caller's buffer
//! and decoders unstuff into a caller's scratch, so a control loop allocates nothing.
//!
//! Must not depend on: any transport or serial port, iceoryx2, messages.

pub mod crc;
mod error;
pub mod packet;
pub mod wire;
pub mod xc330;

pub use error::{DecodeError, EncodeError};
