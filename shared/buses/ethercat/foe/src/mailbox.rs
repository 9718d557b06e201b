//! The EtherCAT mailbox header (ETG.1000.4 5.6.1, table 29) and mailbox error replies
//! (ETG.1000.4 table 30).
//!
//! ```text
//! byte 0..2  Length     u16 LE: bytes of mailbox data after this header
//! byte 2..4  Address    u16 LE: station address of the originator (0 from a MainDevice)
//! byte 4     Channel    bits 0..=5 (0: reserved for future use), Priority bits 6..=7
//! byte 5     Type       bits 0..=3 (0 error, 1 AoE, 2 EoE, 3 CoE, 4 FoE, 5 SoE, 15 VoE),
//!            Cnt        bits 4..=6 (1..=7, 0 only as the start value), bit 7 reserved
//! ```

use core::fmt;

/// Length of the mailbox header.
pub const HEADER_LEN: usize = 6;

/// Mailbox types (the low nibble of header byte 5).
pub mod mailbox_type {
    /// Mailbox error reply (ETG.1000.4 table 30).
    pub const ERR: u8 = 0x00;
    /// ADS over EtherCAT.
    pub const AOE: u8 = 0x01;
    /// Ethernet over EtherCAT.
    pub const EOE: u8 = 0x02;
    /// CAN application protocol over EtherCAT.
    pub const COE: u8 = 0x03;
    /// File access over EtherCAT.
    pub const FOE: u8 = 0x04;
    /// Servo drive profile over EtherCAT.
    pub const SOE: u8 = 0x05;
    /// Vendor specific.
    pub const VOE: u8 = 0x0F;
}

/// A decoded mailbox header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct MailboxHeader {
    /// Bytes of mailbox data after the header.
    pub length: u16,
    /// Station address of the originator (0 in requests from a MainDevice).
    pub address: u16,
    /// Channel, 6 bits (0).
    pub channel: u8,
    /// Priority, 2 bits (0 lowest .. 3 highest).
    pub priority: u8,
    /// Mailbox type, 4 bits: see [`mailbox_type`].
    pub mailbox_type: u8,
    /// Counter, 3 bits: 1..=7 in turn, so that a SubDevice can drop a repeated request; 0 is
    /// only the start value (SubDevices do not check it for repeats).
    pub counter: u8,
}

/// Why bytes are not a mailbox message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum MailboxDecodeError {
    /// Fewer than the 6 header bytes.
    #[error("mailbox message of {0} bytes is shorter than the 6-byte header")]
    TooShort(usize),
    /// The header's length goes beyond the bytes available.
    #[error("mailbox header announces {length} bytes of data, only {available} follow")]
    Length {
        /// Length from the header.
        length: u16,
        /// Bytes after the header.
        available: usize,
    },
}

impl MailboxHeader {
    /// A request header of `mailbox_type` from a MainDevice (address 0, channel 0, priority 0).
    pub fn request(mailbox_type: u8, length: u16, counter: u8) -> Self {
        Self {
            length,
            address: 0,
            channel: 0,
            priority: 0,
            mailbox_type,
            counter,
        }
    }

    /// The 6 header bytes. Fields wider than their bit fields are truncated to them.
    pub fn encode(&self) -> [u8; HEADER_LEN] {
        let [l0, l1] = self.length.to_le_bytes();
        let [a0, a1] = self.address.to_le_bytes();
        [
            l0,
            l1,
            a0,
            a1,
            (self.channel & 0x3F) | ((self.priority & 0x03) << 6),
            (self.mailbox_type & 0x0F) | ((self.counter & 0x07) << 4),
        ]
    }

    /// Decodes a mailbox message: its header and its data (exactly `length` bytes; the rest of
    /// the mailbox buffer, padding, is ignored). Total: any bytes give a value or an error.
    pub fn decode(bytes: &[u8]) -> Result<(Self, &[u8]), MailboxDecodeError> {
        let Some((head, rest)) = bytes.split_first_chunk::<HEADER_LEN>() else {
            return Err(MailboxDecodeError::TooShort(bytes.len()));
        };
        let [l0, l1, a0, a1, cp, tc] = *head;
        let length = u16::from_le_bytes([l0, l1]);
        let Some(data) = rest.get(..usize::from(length)) else {
            return Err(MailboxDecodeError::Length {
                length,
                available: rest.len(),
            });
        };
        let header = Self {
            length,
            address: u16::from_le_bytes([a0, a1]),
            channel: cp & 0x3F,
            priority: cp >> 6,
            mailbox_type: tc & 0x0F,
            counter: (tc >> 4) & 0x07,
        };
        Ok((header, data))
    }
}

/// The counter after `counter`: 1, 2, .., 7, 1, .. (ETG.1000.4: 0 is only the start value).
pub fn next_counter(counter: u8) -> u8 {
    if counter >= 7 {
        1
    } else {
        counter + 1
    }
}

/// A whole request message: header (`mailbox_type`, `counter`) and `data`. `None` if `data` is
/// longer than a mailbox header can announce (65535 bytes).
pub fn request(mailbox_type: u8, counter: u8, data: &[u8]) -> Option<Vec<u8>> {
    let length = u16::try_from(data.len()).ok()?;
    let mut m = Vec::with_capacity(HEADER_LEN + data.len());
    m.extend_from_slice(&MailboxHeader::request(mailbox_type, length, counter).encode());
    m.extend_from_slice(data);
    Some(m)
}

/// The detail of a mailbox error reply (a message of type [`mailbox_type::ERR`]), ETG.1000.4
/// table 30.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MailboxError(pub u16);

impl MailboxError {
    /// Syntax of the 6-byte mailbox header is wrong.
    pub const SYNTAX: Self = Self(0x0001);
    /// The mailbox protocol is not supported.
    pub const UNSUPPORTED_PROTOCOL: Self = Self(0x0002);
    /// Channel field contains a wrong value.
    pub const INVALID_CHANNEL: Self = Self(0x0003);
    /// The service in the mailbox protocol is not supported.
    pub const SERVICE_NOT_SUPPORTED: Self = Self(0x0004);
    /// The mailbox protocol header is wrong.
    pub const INVALID_HEADER: Self = Self(0x0005);
    /// Length of received mailbox data is too short.
    pub const SIZE_TOO_SHORT: Self = Self(0x0006);
    /// Mailbox protocol cannot be processed because of limited resources.
    pub const NO_MORE_MEMORY: Self = Self(0x0007);
    /// The length of the data is inconsistent.
    pub const INVALID_SIZE: Self = Self(0x0008);

    /// Decodes the data of a mailbox error reply: type 0x0001 (mailbox command), then the
    /// detail. `None` if the data is shorter than 4 bytes.
    pub fn decode(data: &[u8]) -> Option<Self> {
        match data {
            [_, _, d0, d1, ..] => Some(Self(u16::from_le_bytes([*d0, *d1]))),
            _ => None,
        }
    }

    /// The data of a mailbox error reply with this detail.
    pub fn encode(self) -> [u8; 4] {
        let [d0, d1] = self.0.to_le_bytes();
        [0x01, 0x00, d0, d1]
    }

    /// The standard's name of the detail, if it has one.
    pub fn description(self) -> Option<&'static str> {
        Some(match self.0 {
            0x0001 => "mailbox header syntax wrong",
            0x0002 => "mailbox protocol not supported",
            0x0003 => "invalid channel",
            0x0004 => "service not supported",
            0x0005 => "invalid protocol header",
            0x0006 => "mailbox data too short",
            0x0007 => "no more memory",
            0x0008 => "inconsistent data length",
            _ => return None,
        })
    }
}

impl fmt::Display for MailboxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.description() {
            Some(d) => write!(f, "{:#06x} ({d})", self.0),
            None => write!(f, "{:#06x}", self.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_layout() {
        let h = MailboxHeader {
            length: 0x0102,
            address: 0x1001,
            channel: 5,
            priority: 2,
            mailbox_type: mailbox_type::FOE,
            counter: 3,
        };
        assert_eq!(h.encode(), [0x02, 0x01, 0x01, 0x10, 0x85, 0x34]);
        let mut m = h.encode().to_vec();
        m.extend(core::iter::repeat_n(0xAA, 0x0102 + 4));
        let (back, data) = MailboxHeader::decode(&m).expect("header");
        assert_eq!(back, h);
        assert_eq!(data.len(), 0x0102);
    }

    #[test]
    fn counters_cycle_without_zero() {
        let mut c = 0;
        let seq: Vec<u8> = (0..9)
            .map(|_| {
                c = next_counter(c);
                c
            })
            .collect();
        assert_eq!(seq, [1, 2, 3, 4, 5, 6, 7, 1, 2]);
    }

    #[test]
    fn mailbox_errors() {
        assert_eq!(
            MailboxError::decode(&[1, 0, 2, 0]),
            Some(MailboxError::UNSUPPORTED_PROTOCOL)
        );
        assert_eq!(MailboxError::decode(&[1, 0, 2]), None);
        assert_eq!(
            MailboxError::UNSUPPORTED_PROTOCOL.to_string(),
            "0x0002 (mailbox protocol not supported)"
        );
        assert_eq!(MailboxError(0x0042).to_string(), "0x0042");
        assert_eq!(MailboxError::INVALID_SIZE.encode(), [1, 0, 8, 0]);
    }
}
