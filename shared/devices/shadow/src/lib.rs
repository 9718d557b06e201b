//! The Shadow Dexterous Hand's EDC palm protocol, as pure and total codecs.
//!
//! A Hand E is two EtherCAT SubDevices, a bridge without process data and the palm (product
//! code 6, protocol 0220), whose PIC32 talks to 20 PIC18F motor boards on two CAN buses. The host
//! writes a command (and a CAN-bridge message) into the palm's sync managers every millisecond
//! and reads back a status (and a bridge message).
//!
//! - [`layout`]: the command, status and CAN-bridge layouts of protocol 0220 (what shipped
//!   palms speak), of the layout the device document shows, and the areas of 0230 and 0240;
//! - [`data`]: EDC commands, motor data types (from and to the motors) with their units, slow
//!   data, motor flags (and which are serious), the config CRC;
//! - [`can`]: the CAN SID of motor and bootloader messages and the bootloader's commands;
//! - [`hex`]: Intel HEX firmware images, checked against the bootloader's address rules and cut
//!   into the 32-byte rows it writes;
//! - [`flash`]: the flashing sequence as a sans-I/O state machine;
//! - [`mapping`]: the Hand E's joint -> motor tables.
//!
//! Where the device document (`003_399e148eac7910e7.txt`) and the shipped driver and firmware
//! disagree, the choice is a value the caller passes ([`data::EdcNumbering`],
//! [`can::SidDirections`], [`can::EraseLength`]) and the default is the shipped one, because
//! that is what palms in the field speak. Facts beyond the document come from
//! `docs/devices/shadow.md`, whose sources are cited by their letters there (E: the vendor's
//! EtherCAT driver and headers, E11: its 2011 palm and bootloader sources, M: the eml master, C:
//! the hand configurations).
//!
//! Must not depend on: ethercrab, iceoryx2, messages, any I/O.

pub mod can;
pub mod data;
pub mod flash;
pub mod hex;
pub mod layout;
pub mod mapping;

/// Why bytes were not decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Fewer bytes than the structure needs.
    #[error("{what}: {got} bytes, need {need}")]
    Short {
        /// What was being decoded.
        what: &'static str,
        /// Bytes it needs.
        need: usize,
        /// Bytes there were.
        got: usize,
    },
    /// A field with a value the protocol does not define.
    #[error("{what}: unknown value {value:#x}")]
    Unknown {
        /// The field.
        what: &'static str,
        /// Its value.
        value: u32,
    },
}

/// Little-endian reads that the callers have bounds-checked.
pub(crate) fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

pub(crate) fn i16_at(b: &[u8], at: usize) -> i16 {
    i16::from_le_bytes([b[at], b[at + 1]])
}

pub(crate) fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Fails with [`DecodeError::Short`] unless `bytes` holds `need`.
pub(crate) fn need(what: &'static str, bytes: &[u8], need: usize) -> Result<(), DecodeError> {
    if bytes.len() < need {
        Err(DecodeError::Short {
            what,
            need,
            got: bytes.len(),
        })
    } else {
        Ok(())
    }
}
