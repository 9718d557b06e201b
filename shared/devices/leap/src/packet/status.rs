//! Status packets (ROBOTIS e-manual, Protocol 2.0, "Status Packet"): the error byte and its
//! words, and the combined Fast Sync Read reply with its per-device blocks
//! (ROBOTIS e-manual, Protocol 2.0, "Fast Sync Read").

use super::{instruction, Packet, BROADCAST_ID, HEADER, PREFIX_LEN};
use crate::crc::crc16;
use crate::DecodeError;

/// A status packet: who answered, its error byte and the data after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status<'a> {
    /// The replying device.
    pub id: u8,
    /// The error byte.
    pub error: ErrorByte,
    /// The data after the error byte (a Ping's model and firmware, a Read's bytes). The ROBOTIS
    /// SDK hands out bytes here even when the error byte is set; callers should ignore data
    /// whenever [`ErrorByte::number`] is some.
    pub params: &'a [u8],
}

impl<'a> Status<'a> {
    /// Reads a parsed packet as a status packet.
    pub fn from_packet(packet: &Packet<'a>) -> Result<Self, DecodeError> {
        if packet.instruction != instruction::STATUS {
            return Err(DecodeError::NotStatus(packet.instruction));
        }
        let (&error, params) = packet
            .params
            .split_first()
            .ok_or(DecodeError::NoErrorByte)?;
        Ok(Status {
            id: packet.id,
            error: ErrorByte(error),
            params,
        })
    }
}

/// A status packet's error byte: bit 7 the alert (a hardware problem: read Hardware Error
/// Status), bits 6..0 the error number of the instruction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct ErrorByte(pub u8);

impl ErrorByte {
    /// No alert, no error.
    pub const OK: ErrorByte = ErrorByte(0);
    /// The alert bit.
    pub const ALERT: u8 = 0x80;

    /// The byte for an alert flag and an error number.
    pub fn new(alert: bool, number: Option<ErrorNumber>) -> Self {
        let alert = if alert { Self::ALERT } else { 0 };
        ErrorByte(alert | number.map_or(0, |n| n.code() & 0x7F))
    }

    /// Bit 7: the device has a hardware error; read Hardware Error Status (70) to know which.
    pub fn alert(self) -> bool {
        self.0 & Self::ALERT != 0
    }

    /// The error number of bits 6..0, `None` when the instruction succeeded.
    pub fn number(self) -> Option<ErrorNumber> {
        ErrorNumber::from_code(self.0 & 0x7F)
    }

    /// Neither alert nor error.
    pub fn is_ok(self) -> bool {
        self.0 == 0
    }
}

impl std::fmt::Display for ErrorByte {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.number(), self.alert()) {
            (None, false) => f.write_str("no error"),
            (None, true) => f.write_str("alert: hardware error (read Hardware Error Status)"),
            (Some(n), false) => write!(f, "{n}"),
            (Some(n), true) => {
                write!(f, "{n}; alert: hardware error (read Hardware Error Status)")
            }
        }
    }
}

/// The error numbers of bits 6..0 (ROBOTIS e-manual, Protocol 2.0, "Status Packet", Error).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorNumber {
    /// 0x01: the instruction failed.
    ResultFail,
    /// 0x02: an undefined instruction, or Action without Reg Write.
    Instruction,
    /// 0x03: the packet's CRC did not match.
    Crc,
    /// 0x04: the value is outside the item's range.
    DataRange,
    /// 0x05: the data is shorter than the item.
    DataLength,
    /// 0x06: the value is outside the configured limit.
    DataLimit,
    /// 0x07: a write to a read-only or undefined address, a read of an undefined one, or a write
    /// to EEPROM while Torque Enable is 1.
    Access,
    /// Any other number (not documented).
    Other(u8),
}

impl ErrorNumber {
    /// The number for bits 6..0 (0: none).
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            0 => return None,
            1 => ErrorNumber::ResultFail,
            2 => ErrorNumber::Instruction,
            3 => ErrorNumber::Crc,
            4 => ErrorNumber::DataRange,
            5 => ErrorNumber::DataLength,
            6 => ErrorNumber::DataLimit,
            7 => ErrorNumber::Access,
            other => ErrorNumber::Other(other),
        })
    }

    /// Its code.
    pub fn code(self) -> u8 {
        match self {
            ErrorNumber::ResultFail => 1,
            ErrorNumber::Instruction => 2,
            ErrorNumber::Crc => 3,
            ErrorNumber::DataRange => 4,
            ErrorNumber::DataLength => 5,
            ErrorNumber::DataLimit => 6,
            ErrorNumber::Access => 7,
            ErrorNumber::Other(code) => code,
        }
    }
}

impl std::fmt::Display for ErrorNumber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let words = match self {
            ErrorNumber::ResultFail => "result fail: the instruction failed",
            ErrorNumber::Instruction => {
                "instruction error: undefined instruction, or Action without Reg Write"
            }
            ErrorNumber::Crc => "CRC error: the packet's CRC did not match",
            ErrorNumber::DataRange => "data range error: the value is outside the item's range",
            ErrorNumber::DataLength => "data length error: shorter than the item",
            ErrorNumber::DataLimit => "data limit error: the value is outside the set limit",
            ErrorNumber::Access => {
                "access error: read-only or undefined address, or EEPROM written under torque"
            }
            ErrorNumber::Other(code) => return write!(f, "error number {code} (undocumented)"),
        };
        write!(f, "{words} ({})", self.code())
    }
}

/// The combined reply to a Fast Sync Read: a status packet from [`BROADCAST_ID`], not stuffed,
/// whose parameters are N blocks `[ERR, ID, data (X bytes), CRC_L, CRC_H]`, the last block's
/// CRC being the packet's own (so LEN = 1 + N (X + 4)). Each block's CRC is the running CRC over
/// every byte from the header through that block's data (earlier blocks' CRCs included);
/// [`FastSyncReply::new`] checks every one (the ROBOTIS SDK checks only the last).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FastSyncReply<'a> {
    params: &'a [u8],
    data_len: usize,
}

/// One device's block of a [`FastSyncReply`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Block<'a> {
    /// The device.
    pub id: u8,
    /// Its error byte.
    pub error: ErrorByte,
    /// Its data (the requested length).
    pub data: &'a [u8],
}

impl<'a> FastSyncReply<'a> {
    /// Reads a parsed packet as the reply to a Fast Sync Read of `data_len` bytes per device:
    /// a status from ID 0xFE, a whole number of blocks, every block's CRC right.
    pub fn new(packet: &Packet<'a>, data_len: u16) -> Result<Self, DecodeError> {
        if packet.instruction != instruction::STATUS {
            return Err(DecodeError::NotStatus(packet.instruction));
        }
        if packet.id != BROADCAST_ID {
            return Err(DecodeError::NotFastSync(packet.id));
        }
        let x = usize::from(data_len);
        let stride = x + 4;
        // The parameters lack the last block's CRC (it is the packet's).
        let span = packet.params.len() + 2;
        if !span.is_multiple_of(stride) {
            return Err(DecodeError::FastSyncLength {
                len: span + 1,
                data_len,
            });
        }
        let reply = FastSyncReply {
            params: packet.params,
            data_len: x,
        };
        reply.check_block_crcs()?;
        Ok(reply)
    }

    fn check_block_crcs(&self) -> Result<(), DecodeError> {
        let len = (self.params.len() + 3) as u16;
        let [l0, l1] = len.to_le_bytes();
        let prefix = [
            HEADER[0],
            HEADER[1],
            HEADER[2],
            HEADER[3],
            BROADCAST_ID,
            l0,
            l1,
            instruction::STATUS,
        ];
        debug_assert_eq!(prefix.len(), PREFIX_LEN + 1);
        let mut crc = crc16(0, &prefix);
        let mut from = 0;
        let stride = self.data_len + 4;
        for index in 0..self.len().saturating_sub(1) {
            let end = index * stride + 2 + self.data_len;
            crc = crc16(crc, &self.params[from..end]);
            let received = u16::from_le_bytes([self.params[end], self.params[end + 1]]);
            if crc != received {
                return Err(DecodeError::BlockCrc {
                    index,
                    id: self.params[index * stride + 1],
                    computed: crc,
                    received,
                });
            }
            from = end;
        }
        Ok(())
    }

    /// The blocks at the start of `raw`, the bytes of a Fast Sync Read reply of `data_len`
    /// bytes per device from its header on, that arrived whole with their running CRC right:
    /// what is left of a reply cut short (a chain that ends at a silent device, not
    /// documented) or damaged further on. Each block's CRC covers every byte from the header
    /// through its data, so a block whose CRC checks vouches for everything before it; the
    /// first block that is cut, or whose CRC does not check, ends the prefix (none: empty). Not
    /// beyond the length the header announces. Total: any bytes give a (possibly empty) reply.
    pub fn prefix(raw: &'a [u8], data_len: u16) -> Self {
        let x = usize::from(data_len);
        let stride = x + 4;
        let start = PREFIX_LEN + 1;
        let empty = FastSyncReply {
            params: &[],
            data_len: x,
        };
        let ours = raw.len() >= start
            && raw[..HEADER.len()] == HEADER
            && raw[4] == BROADCAST_ID
            && raw[PREFIX_LEN] == instruction::STATUS;
        if !ours {
            return empty;
        }
        // The packet ends at PREFIX_LEN + LEN; its last block's CRC is the packet's.
        let announced = PREFIX_LEN + usize::from(u16::from_le_bytes([raw[5], raw[6]]));
        let raw = &raw[..raw.len().min(announced)];
        let mut crc = 0;
        let mut from = 0;
        let mut good = 0;
        loop {
            let end = start + good * stride + 2 + x;
            let Some(received) = raw.get(end..end + 2) else {
                break;
            };
            crc = crc16(crc, &raw[from..end]);
            if crc != u16::from_le_bytes([received[0], received[1]]) {
                break;
            }
            from = end;
            good += 1;
        }
        FastSyncReply {
            params: &raw[start..start + good * stride],
            data_len: x,
        }
    }

    /// The number of blocks (devices that answered).
    pub fn len(&self) -> usize {
        (self.params.len() + 2) / (self.data_len + 4)
    }

    /// Whether there is no block (never, for a reply [`FastSyncReply::new`] accepted).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Block `index`.
    pub fn block(&self, index: usize) -> Option<Block<'a>> {
        let start = index.checked_mul(self.data_len + 4)?;
        let bytes = self.params.get(start..start + 2 + self.data_len)?;
        Some(Block {
            error: ErrorByte(bytes[0]),
            id: bytes[1],
            data: &bytes[2..],
        })
    }

    /// The blocks, in the order the devices answered.
    pub fn blocks(&self) -> impl Iterator<Item = Block<'a>> + 'a {
        let reply = *self;
        (0..reply.len()).filter_map(move |i| reply.block(i))
    }
}
