//! Instruction packets as a device reads them (ROBOTIS e-manual, Protocol 2.0, "Instruction
//! Details"): what the simulator executes. Layouts are checked here once, so the item
//! iterators of the Sync and Bulk instructions cannot fail.

use super::{instruction, Packet};
use crate::DecodeError;

/// An instruction packet's request, parameters decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request<'a> {
    /// Ping: answer model number and firmware version.
    Ping,
    /// Read `len` bytes at `addr`.
    Read {
        /// Start address.
        addr: u16,
        /// Bytes.
        len: u16,
    },
    /// Write `data` at `addr`.
    Write {
        /// Start address.
        addr: u16,
        /// The bytes.
        data: &'a [u8],
    },
    /// Register a write of `data` at `addr`, executed by Action.
    RegWrite {
        /// Start address.
        addr: u16,
        /// The bytes.
        data: &'a [u8],
    },
    /// Execute the registered write.
    Action,
    /// Factory reset: 0xFF everything, 0x01 all but ID, 0x02 all but ID and baud rate.
    FactoryReset(u8),
    /// Reboot.
    Reboot,
    /// Clear: `option` (0x01 the multi-turn position) then its key bytes (44 58 4C 22).
    Clear {
        /// The first parameter.
        option: u8,
        /// The parameters after it.
        key: &'a [u8],
    },
    /// Control Table Backup: `option` (0x01 store, 0x02 restore) then its key (43 54 52 4C).
    Backup {
        /// The first parameter.
        option: u8,
        /// The parameters after it.
        key: &'a [u8],
    },
    /// Sync Read of `len` bytes at `addr` from `ids`: one status per ID, in this order.
    SyncRead {
        /// Start address.
        addr: u16,
        /// Bytes per device.
        len: u16,
        /// The devices, in reply order.
        ids: &'a [u8],
    },
    /// Fast Sync Read: as Sync Read, one combined reply.
    FastSyncRead {
        /// Start address.
        addr: u16,
        /// Bytes per device.
        len: u16,
        /// The devices, in reply order.
        ids: &'a [u8],
    },
    /// Sync Write of `len` bytes at `addr`, per device.
    SyncWrite {
        /// Start address.
        addr: u16,
        /// Bytes per device.
        len: u16,
        /// `(id, data)` per device.
        items: SyncWriteItems<'a>,
    },
    /// Bulk Read: per device an address and a length; one status per ID, in this order.
    BulkRead(BulkReadItems<'a>),
    /// Fast Bulk Read: as Bulk Read, one combined reply.
    FastBulkRead(BulkReadItems<'a>),
    /// Bulk Write: per device an address and data.
    BulkWrite(BulkWriteItems<'a>),
    /// An instruction this crate does not know (a device answers Instruction Error).
    Unknown(u8),
}

impl<'a> Request<'a> {
    /// Reads a parsed instruction packet. A status packet is [`DecodeError::NotInstruction`];
    /// parameters that do not fit the instruction's layout are [`DecodeError::Params`].
    pub fn from_packet(packet: &Packet<'a>) -> Result<Self, DecodeError> {
        let p = packet.params;
        let inst = packet.instruction;
        let bad = || DecodeError::Params {
            instruction: inst,
            len: p.len(),
        };
        let empty = |request| {
            if p.is_empty() {
                Ok(request)
            } else {
                Err(bad())
            }
        };
        let word = |at: usize| u16::from_le_bytes([p[at], p[at + 1]]);
        Ok(match inst {
            instruction::STATUS => return Err(DecodeError::NotInstruction),
            instruction::PING => empty(Request::Ping)?,
            instruction::ACTION => empty(Request::Action)?,
            instruction::REBOOT => empty(Request::Reboot)?,
            instruction::READ => {
                if p.len() != 4 {
                    return Err(bad());
                }
                Request::Read {
                    addr: word(0),
                    len: word(2),
                }
            }
            instruction::WRITE | instruction::REG_WRITE => {
                if p.len() < 2 {
                    return Err(bad());
                }
                let (addr, data) = (word(0), &p[2..]);
                if inst == instruction::WRITE {
                    Request::Write { addr, data }
                } else {
                    Request::RegWrite { addr, data }
                }
            }
            instruction::FACTORY_RESET => match p {
                [option] => Request::FactoryReset(*option),
                _ => return Err(bad()),
            },
            instruction::CLEAR | instruction::BACKUP => {
                let (&option, key) = p.split_first().ok_or_else(bad)?;
                if inst == instruction::CLEAR {
                    Request::Clear { option, key }
                } else {
                    Request::Backup { option, key }
                }
            }
            instruction::SYNC_READ | instruction::FAST_SYNC_READ => {
                if p.len() < 4 {
                    return Err(bad());
                }
                let (addr, len, ids) = (word(0), word(2), &p[4..]);
                if inst == instruction::SYNC_READ {
                    Request::SyncRead { addr, len, ids }
                } else {
                    Request::FastSyncRead { addr, len, ids }
                }
            }
            instruction::SYNC_WRITE => {
                if p.len() < 4 {
                    return Err(bad());
                }
                let (addr, len, bytes) = (word(0), word(2), &p[4..]);
                if !bytes.len().is_multiple_of(usize::from(len) + 1) {
                    return Err(bad());
                }
                Request::SyncWrite {
                    addr,
                    len,
                    items: SyncWriteItems {
                        len: usize::from(len),
                        bytes,
                    },
                }
            }
            instruction::BULK_READ | instruction::FAST_BULK_READ => {
                if !p.len().is_multiple_of(BulkReadItems::STRIDE) {
                    return Err(bad());
                }
                let items = BulkReadItems { bytes: p };
                if inst == instruction::BULK_READ {
                    Request::BulkRead(items)
                } else {
                    Request::FastBulkRead(items)
                }
            }
            instruction::BULK_WRITE => {
                let items = BulkWriteItems { bytes: p };
                let mut rest = p;
                while !rest.is_empty() {
                    rest = BulkWriteItems::split(rest).ok_or_else(bad)?.1;
                }
                Request::BulkWrite(items)
            }
            other => Request::Unknown(other),
        })
    }
}

/// The items of a Sync Write: `(id, data)`, every data the same length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncWriteItems<'a> {
    len: usize,
    bytes: &'a [u8],
}

impl<'a> SyncWriteItems<'a> {
    /// The number of devices.
    pub fn len(&self) -> usize {
        self.bytes.len() / (self.len + 1)
    }

    /// Whether no device is addressed.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// `(id, data)` per device, in packet order.
    pub fn iter(&self) -> impl Iterator<Item = (u8, &'a [u8])> + 'a {
        self.bytes
            .chunks_exact(self.len + 1)
            .map(|item| (item[0], &item[1..]))
    }
}

/// The items of a Bulk Read or Fast Bulk Read: `(id, addr, len)` per device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BulkReadItems<'a> {
    bytes: &'a [u8],
}

impl<'a> BulkReadItems<'a> {
    /// Bytes per item: ID, address, length.
    const STRIDE: usize = 5;

    /// The number of devices.
    pub fn len(&self) -> usize {
        self.bytes.len() / Self::STRIDE
    }

    /// Whether no device is addressed.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// `(id, addr, len)` per device, in reply order.
    pub fn iter(&self) -> impl Iterator<Item = (u8, u16, u16)> + 'a {
        self.bytes.chunks_exact(Self::STRIDE).map(|item| {
            (
                item[0],
                u16::from_le_bytes([item[1], item[2]]),
                u16::from_le_bytes([item[3], item[4]]),
            )
        })
    }
}

/// The items of a Bulk Write: `(id, addr, data)` per device, each with its own length.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BulkWriteItems<'a> {
    bytes: &'a [u8],
}

impl<'a> BulkWriteItems<'a> {
    /// Splits the first item `[id, addr16, len16, data]` off `bytes`.
    #[allow(clippy::type_complexity)]
    fn split(bytes: &'a [u8]) -> Option<((u8, u16, &'a [u8]), &'a [u8])> {
        let head = bytes.get(..5)?;
        let len = usize::from(u16::from_le_bytes([head[3], head[4]]));
        let data = bytes.get(5..5 + len)?;
        let item = (head[0], u16::from_le_bytes([head[1], head[2]]), data);
        Some((item, &bytes[5 + len..]))
    }

    /// `(id, addr, data)` per device, in packet order.
    pub fn iter(&self) -> impl Iterator<Item = (u8, u16, &'a [u8])> + 'a {
        let mut rest = self.bytes;
        std::iter::from_fn(move || {
            let (item, next) = Self::split(rest)?;
            rest = next;
            Some(item)
        })
    }
}
