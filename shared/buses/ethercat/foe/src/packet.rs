//! FoE packets (ETG.1000.6, FoE: the FoE header and its services), the data of a mailbox
//! message of type 4.
//!
//! ```text
//! byte 0      OpCode   1 RRQ, 2 WRQ, 3 DATA, 4 ACK, 5 ERR, 6 BUSY
//! byte 1      reserved (0)
//! byte 2..6   RRQ/WRQ: Password u32 LE      then the file name (rest of the data)
//!             DATA:    PacketNo u32 LE      then the file data
//!             ACK:     PacketNo u32 LE
//!             ERR:     ErrorCode u32 LE     then an optional error text
//!             BUSY:    Done u16 LE, Entire u16 LE, then an optional busy text
//! ```
//!
//! A write: the client sends WRQ, the server answers ACK 0; then DATA 1, 2, .. each answered by
//! the ACK of its number. The DATA packet shorter than the largest the mailbox carries ends the
//! file (an empty one if the file fills its last packet exactly). Instead of an ACK the server may
//! answer BUSY (the client repeats the packet later) or ERR (the transfer ends); the client
//! aborts with ERR, which is not answered.

use core::fmt;

/// Length of the FoE header (OpCode, reserved, 4-byte field).
pub const HEADER_LEN: usize = 6;

/// FoE OpCodes.
pub mod opcode {
    /// Read request.
    pub const RRQ: u8 = 1;
    /// Write request.
    pub const WRQ: u8 = 2;
    /// Data.
    pub const DATA: u8 = 3;
    /// Acknowledge.
    pub const ACK: u8 = 4;
    /// Error.
    pub const ERR: u8 = 5;
    /// Busy.
    pub const BUSY: u8 = 6;
}

/// An FoE error code (ETG.1000.6 table "FoE error codes"; the names and the additions 0x800C..
/// as in the ESC vendors' slave stacks).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ErrorCode(pub u32);

impl ErrorCode {
    /// Not defined (see the error text).
    pub const NOT_DEFINED: Self = Self(0x8000);
    /// Not found: the file asked for (by a read) does not exist.
    pub const NOT_FOUND: Self = Self(0x8001);
    /// Access denied: reading or writing this file is not allowed (e.g. local control).
    pub const ACCESS_DENIED: Self = Self(0x8002);
    /// Disk full: no room to store the file.
    pub const DISK_FULL: Self = Self(0x8003);
    /// Illegal: an FoE operation that is not allowed here (e.g. DATA without a request).
    pub const ILLEGAL: Self = Self(0x8004);
    /// Packet number wrong.
    pub const PACKET_NUMBER: Self = Self(0x8005);
    /// Already exists.
    pub const ALREADY_EXISTS: Self = Self(0x8006);
    /// No user.
    pub const NO_USER: Self = Self(0x8007);
    /// Bootstrap only: this file can only be written in BOOT.
    pub const BOOTSTRAP_ONLY: Self = Self(0x8008);
    /// Not in bootstrap: this file name is not valid in BOOT.
    pub const NOT_IN_BOOTSTRAP: Self = Self(0x8009);
    /// No rights: password (or authentication) invalid.
    pub const NO_RIGHTS: Self = Self(0x800A);
    /// Program error: generic, when no other code fits.
    pub const PROGRAM_ERROR: Self = Self(0x800B);
    /// Invalid checksum: the checksum in the file is wrong.
    pub const INVALID_CHECKSUM: Self = Self(0x800C);
    /// Invalid firmware: the firmware does not fit this hardware.
    pub const INVALID_FIRMWARE: Self = Self(0x800D);
    /// No file to read.
    pub const NO_FILE: Self = Self(0x800F);

    /// What the code means, if it is a standard one.
    pub fn description(self) -> Option<&'static str> {
        Some(match self.0 {
            0x8000 => "not defined",
            0x8001 => "not found",
            0x8002 => "access denied",
            0x8003 => "disk full",
            0x8004 => "illegal",
            0x8005 => "packet number wrong",
            0x8006 => "already exists",
            0x8007 => "no user",
            0x8008 => "bootstrap only",
            0x8009 => "not in bootstrap",
            0x800A => "no rights (password or authentication invalid)",
            0x800B => "program error",
            0x800C => "invalid checksum",
            0x800D => "invalid firmware (does not fit the hardware)",
            0x800F => "no file to read",
            _ => return None,
        })
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.description() {
            Some(d) => write!(f, "{:#06x} ({d})", self.0),
            None => write!(f, "{:#06x}", self.0),
        }
    }
}

/// One FoE packet, borrowing its variable part (name, data or text) from the decoded bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Packet<'a> {
    /// Read request: password and file name.
    ReadRequest {
        /// Password (0: none).
        password: u32,
        /// File name, as bytes (the standard does not fix an encoding).
        name: &'a [u8],
    },
    /// Write request: password and file name.
    WriteRequest {
        /// Password (0: none).
        password: u32,
        /// File name, as bytes.
        name: &'a [u8],
    },
    /// File data.
    Data {
        /// Packet number, 1 for the first.
        packet: u32,
        /// The data.
        data: &'a [u8],
    },
    /// Acknowledge of a packet (0: of the write request).
    Ack {
        /// Number of the packet acknowledged.
        packet: u32,
    },
    /// Error: ends the transfer.
    Error {
        /// Error code.
        code: ErrorCode,
        /// Optional text (often NUL-terminated).
        text: &'a [u8],
    },
    /// Busy: the server needs time; the client repeats its last packet later.
    Busy {
        /// Progress so far, out of `entire`.
        done: u16,
        /// Progress at the end.
        entire: u16,
        /// Optional text.
        text: &'a [u8],
    },
}

/// Why bytes are not an FoE packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PacketDecodeError {
    /// Fewer than the 6 header bytes.
    #[error("FoE packet of {0} bytes is shorter than the 6-byte header")]
    TooShort(usize),
    /// An OpCode other than 1..=6.
    #[error("unknown FoE OpCode {0}")]
    UnknownOpcode(u8),
}

impl<'a> Packet<'a> {
    /// The packet's OpCode.
    pub fn opcode(&self) -> u8 {
        match self {
            Self::ReadRequest { .. } => opcode::RRQ,
            Self::WriteRequest { .. } => opcode::WRQ,
            Self::Data { .. } => opcode::DATA,
            Self::Ack { .. } => opcode::ACK,
            Self::Error { .. } => opcode::ERR,
            Self::Busy { .. } => opcode::BUSY,
        }
    }

    /// The 4-byte field after the OpCode and the variable part.
    fn parts(&self) -> ([u8; 4], &'a [u8]) {
        match *self {
            Self::ReadRequest { password, name } | Self::WriteRequest { password, name } => {
                (password.to_le_bytes(), name)
            }
            Self::Data { packet, data } => (packet.to_le_bytes(), data),
            Self::Ack { packet } => (packet.to_le_bytes(), &[]),
            Self::Error { code, text } => (code.0.to_le_bytes(), text),
            Self::Busy { done, entire, text } => {
                let [d0, d1] = done.to_le_bytes();
                let [e0, e1] = entire.to_le_bytes();
                ([d0, d1, e0, e1], text)
            }
        }
    }

    /// Encoded length in bytes.
    pub fn encoded_len(&self) -> usize {
        HEADER_LEN + self.parts().1.len()
    }

    /// Appends the encoded packet to `out`.
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        let (field, rest) = self.parts();
        out.reserve(HEADER_LEN + rest.len());
        out.extend_from_slice(&[self.opcode(), 0]);
        out.extend_from_slice(&field);
        out.extend_from_slice(rest);
    }

    /// The encoded packet.
    pub fn to_vec(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.encoded_len());
        self.encode_into(&mut out);
        out
    }

    /// Decodes the data of an FoE mailbox message. Total: any bytes give a packet or an error.
    /// The reserved byte is ignored, and so are bytes after an ACK's packet number.
    pub fn decode(bytes: &'a [u8]) -> Result<Self, PacketDecodeError> {
        let Some((head, rest)) = bytes.split_first_chunk::<HEADER_LEN>() else {
            return Err(PacketDecodeError::TooShort(bytes.len()));
        };
        let [op, _reserved, f0, f1, f2, f3] = *head;
        let field = u32::from_le_bytes([f0, f1, f2, f3]);
        Ok(match op {
            opcode::RRQ => Self::ReadRequest {
                password: field,
                name: rest,
            },
            opcode::WRQ => Self::WriteRequest {
                password: field,
                name: rest,
            },
            opcode::DATA => Self::Data {
                packet: field,
                data: rest,
            },
            opcode::ACK => Self::Ack { packet: field },
            opcode::ERR => Self::Error {
                code: ErrorCode(field),
                text: rest,
            },
            opcode::BUSY => Self::Busy {
                done: u16::from_le_bytes([f0, f1]),
                entire: u16::from_le_bytes([f2, f3]),
                text: rest,
            },
            other => return Err(PacketDecodeError::UnknownOpcode(other)),
        })
    }
}

/// A text field (name, error or busy text) for display: up to the first NUL, invalid UTF-8
/// replaced.
pub fn text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}
