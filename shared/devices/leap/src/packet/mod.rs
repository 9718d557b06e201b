//! Protocol 2.0 framing (ROBOTIS e-manual, Protocol 2.0, "Instruction Packet", "Status Packet",
//! "Packet Process").
//!
//! A packet is `FF FF FD 00 | ID | LEN_L LEN_H | INST | P1..Pn | CRC_L CRC_H`, multi-byte fields
//! little-endian. LEN counts INST, the parameters and the CRC (after stuffing). A status packet's
//! INST is 0x55 and its first parameter the error byte. On transmit every `FF FF FD` in INST..Pn
//! gets an extra `FD` (byte stuffing) and the CRC ([`crate::crc`]) runs over the stuffed bytes;
//! the receiver checks the CRC over the stuffed bytes, then removes the extra `FD`. The combined
//! Fast Sync Read / Fast Bulk Read replies (status packets from ID 0xFE) are not stuffed.
//!
//! Receiving is two steps: [`scan`] says where the next whole packet is in a receive buffer (or
//! how many bytes before it are not a packet), [`parse`] checks and unstuffs it into the caller's
//! scratch. Then [`Status::from_packet`] (a host reading replies), [`FastSyncReply::new`] (the
//! combined reply) or [`Request::from_packet`] (a device reading instructions) interpret it.
//! Transmitting: [`encode`] and the builders on top of it write into the caller's buffer.

mod request;
mod status;

pub use request::{BulkReadItems, BulkWriteItems, Request, SyncWriteItems};
pub use status::{Block, ErrorByte, ErrorNumber, FastSyncReply, Status};

use crate::crc::crc16;
use crate::{DecodeError, EncodeError};

/// The packet header (the 4th byte is the reserved byte, always 0).
pub const HEADER: [u8; 4] = [0xFF, 0xFF, 0xFD, 0x00];
/// The broadcast ID: every device executes, only Ping and the (Fast) Sync/Bulk Reads answer.
pub const BROADCAST_ID: u8 = 0xFE;
/// The largest device ID.
pub const MAX_ID: u8 = 0xFC;
/// The largest LEN a receiver accepts: the ROBOTIS SDK's receive buffer bound (`RXPACKET_MAX_LEN`
/// in DynamixelSDK `protocol2_packet_handler.cpp`); larger is taken as line noise.
pub const MAX_LEN: usize = 1024;
/// The smallest LEN: INST and the CRC.
pub const MIN_LEN: usize = 3;
/// Bytes before INST: header, ID, LEN.
pub const PREFIX_LEN: usize = 7;
/// The smallest whole packet in bytes (no parameters).
pub const MIN_PACKET: usize = PREFIX_LEN + MIN_LEN;
/// The largest whole packet in bytes.
pub const MAX_PACKET: usize = PREFIX_LEN + MAX_LEN;

/// Instruction codes (ROBOTIS e-manual, Protocol 2.0, "Instruction").
pub mod instruction {
    /// Ping: the device answers its model number and firmware version.
    pub const PING: u8 = 0x01;
    /// Read: address and length.
    pub const READ: u8 = 0x02;
    /// Write: address and data.
    pub const WRITE: u8 = 0x03;
    /// Reg Write: a write held until Action.
    pub const REG_WRITE: u8 = 0x04;
    /// Action: executes the registered write.
    pub const ACTION: u8 = 0x05;
    /// Factory Reset: 0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate.
    pub const FACTORY_RESET: u8 = 0x06;
    /// Reboot.
    pub const REBOOT: u8 = 0x08;
    /// Clear: the multi-turn position (0x01 then 44 58 4C 22).
    pub const CLEAR: u8 = 0x10;
    /// Control Table Backup: 0x01 store, 0x02 restore, then 43 54 52 4C.
    pub const BACKUP: u8 = 0x20;
    /// A status packet (a device's reply).
    pub const STATUS: u8 = 0x55;
    /// Sync Read: one status packet per ID, in request order.
    pub const SYNC_READ: u8 = 0x82;
    /// Sync Write: the same item to several devices, no reply.
    pub const SYNC_WRITE: u8 = 0x83;
    /// Fast Sync Read: one combined reply from ID 0xFE.
    pub const FAST_SYNC_READ: u8 = 0x8A;
    /// Bulk Read: a different item per device, one status per ID.
    pub const BULK_READ: u8 = 0x92;
    /// Bulk Write: a different item per device, no reply.
    pub const BULK_WRITE: u8 = 0x93;
    /// Fast Bulk Read: one combined reply from ID 0xFE.
    pub const FAST_BULK_READ: u8 = 0x9A;
}

/// A checked, unstuffed packet: its ID, instruction and parameters (for a status packet the
/// parameters start with the error byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Packet<'a> {
    /// The ID byte (the addressed device, or the replying one; 0xFE broadcast).
    pub id: u8,
    /// The instruction byte (0x55 for a status packet).
    pub instruction: u8,
    /// The parameters, unstuffed.
    pub params: &'a [u8],
}

fn valid_id(id: u8) -> bool {
    id <= MAX_ID || id == BROADCAST_ID
}

/// The three bytes byte stuffing guards: `FF FF FD` in INST..Pn is followed by an extra `FD`.
const STUFF_PATTERN: [u8; 3] = [0xFF, 0xFF, 0xFD];

/// Whether `bytes` ends with `FF FF FD` at index `end` (inclusive).
fn pattern_ends_at(bytes: &[u8], end: usize) -> bool {
    end >= 2 && bytes[end - 2..=end] == STUFF_PATTERN
}

/// Stuffs `out[start..start + len]` in place (the unstuffed INST..Pn) and returns the stuffed
/// length, or (as the error) that length when `out` has no room for it.
fn stuff_in_place(out: &mut [u8], start: usize, len: usize) -> Result<usize, usize> {
    let region = &out[start..start + len];
    let extra = (2..len).filter(|&end| pattern_ends_at(region, end)).count();
    let stuffed = len + extra;
    if start + stuffed > out.len() {
        return Err(stuffed);
    }
    // Back to front: the write position never falls behind the read position, and the two bytes
    // a pattern check reads before `src` are not yet overwritten (a pattern ending at `src`
    // cannot also end at `src - 1` or `src - 2`).
    let mut dst = start + stuffed;
    for src in (start..start + len).rev() {
        if pattern_ends_at(&out[start..], src - start) {
            dst -= 1;
            out[dst] = 0xFD;
        }
        dst -= 1;
        out[dst] = out[src];
    }
    Ok(stuffed)
}

/// Finishes a packet whose unstuffed INST..Pn (`body_len` bytes) is already at
/// `out[PREFIX_LEN..]`: stuffing, then [`frame`] and [`seal`]. Returns the packet's length.
fn finish(id: u8, out: &mut [u8], body_len: usize) -> Result<usize, EncodeError> {
    let have = out.len();
    let body = stuff_in_place(out, PREFIX_LEN, body_len).map_err(|stuffed| {
        EncodeError::BufferTooSmall {
            need: PREFIX_LEN + stuffed + 2,
            have,
        }
    })?;
    let total = frame(id, out, body)?;
    seal(out, total);
    Ok(total)
}

/// Writes header, ID and LEN for a packet whose (stuffed) INST..Pn of `body` bytes is at
/// `out[PREFIX_LEN..]`; returns the packet's length.
fn frame(id: u8, out: &mut [u8], body: usize) -> Result<usize, EncodeError> {
    let len = body + 2;
    if len > MAX_LEN {
        return Err(EncodeError::TooLong { len, max: MAX_LEN });
    }
    let total = PREFIX_LEN + len;
    if total > out.len() {
        return Err(EncodeError::BufferTooSmall {
            need: total,
            have: out.len(),
        });
    }
    out[..4].copy_from_slice(&HEADER);
    out[4] = id;
    out[5..PREFIX_LEN].copy_from_slice(&(len as u16).to_le_bytes());
    Ok(total)
}

/// Writes the CRC of the framed packet `out[..total]` into its last two bytes.
fn seal(out: &mut [u8], total: usize) {
    let crc = crc16(0, &out[..total - 2]);
    out[total - 2..total].copy_from_slice(&crc.to_le_bytes());
}

/// Writes bytes after INST into `out`, tracking the position; fails when `out` is full.
struct Writer<'o> {
    out: &'o mut [u8],
    pos: usize,
}

impl<'o> Writer<'o> {
    /// Starts with INST at its place.
    fn new(id: u8, instruction: u8, out: &'o mut [u8]) -> Result<Self, EncodeError> {
        if !valid_id(id) {
            return Err(EncodeError::BadId(id));
        }
        if out.len() < MIN_PACKET {
            return Err(EncodeError::BufferTooSmall {
                need: MIN_PACKET,
                have: out.len(),
            });
        }
        out[PREFIX_LEN] = instruction;
        Ok(Writer {
            out,
            pos: PREFIX_LEN + 1,
        })
    }

    fn put(&mut self, bytes: &[u8]) -> Result<(), EncodeError> {
        let end = self.pos + bytes.len();
        // Room for the CRC too, so a full buffer is found here, not after the items.
        if end + 2 > self.out.len() {
            return Err(EncodeError::BufferTooSmall {
                need: end + 2,
                have: self.out.len(),
            });
        }
        self.out[self.pos..end].copy_from_slice(bytes);
        self.pos = end;
        Ok(())
    }

    fn finish(self, id: u8) -> Result<usize, EncodeError> {
        let body = self.pos - PREFIX_LEN;
        finish(id, self.out, body)
    }
}

/// Encodes a packet: header, ID, LEN, INST, the parameters (INST..Pn byte-stuffed), CRC over the
/// stuffed bytes. Returns the packet's length in `out`.
pub fn encode(
    id: u8,
    instruction: u8,
    params: &[u8],
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let mut w = Writer::new(id, instruction, out)?;
    w.put(params)?;
    w.finish(id)
}

/// A Ping of `id` (or of every device, with [`BROADCAST_ID`]).
pub fn ping(id: u8, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode(id, instruction::PING, &[], out)
}

/// A Read of `len` bytes at `addr`.
pub fn read(id: u8, addr: u16, len: u16, out: &mut [u8]) -> Result<usize, EncodeError> {
    let [a0, a1] = addr.to_le_bytes();
    let [l0, l1] = len.to_le_bytes();
    encode(id, instruction::READ, &[a0, a1, l0, l1], out)
}

/// A Write of `data` at `addr`.
pub fn write(id: u8, addr: u16, data: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut w = Writer::new(id, instruction::WRITE, out)?;
    w.put(&addr.to_le_bytes())?;
    w.put(data)?;
    w.finish(id)
}

/// A Reboot of `id`.
pub fn reboot(id: u8, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode(id, instruction::REBOOT, &[], out)
}

/// A Sync Write (to [`BROADCAST_ID`]) of `len` bytes at `addr`: each item is a device ID and
/// its `len` data bytes.
pub fn sync_write<'d>(
    addr: u16,
    len: u16,
    items: impl IntoIterator<Item = (u8, &'d [u8])>,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let mut w = Writer::new(BROADCAST_ID, instruction::SYNC_WRITE, out)?;
    w.put(&addr.to_le_bytes())?;
    w.put(&len.to_le_bytes())?;
    for (id, data) in items {
        if data.len() != usize::from(len) {
            return Err(EncodeError::ItemLength {
                id,
                expected: usize::from(len),
                got: data.len(),
            });
        }
        w.put(&[id])?;
        w.put(data)?;
    }
    w.finish(BROADCAST_ID)
}

fn sync_read_like(
    instruction: u8,
    addr: u16,
    len: u16,
    ids: &[u8],
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let mut w = Writer::new(BROADCAST_ID, instruction, out)?;
    w.put(&addr.to_le_bytes())?;
    w.put(&len.to_le_bytes())?;
    w.put(ids)?;
    w.finish(BROADCAST_ID)
}

/// A Sync Read (to [`BROADCAST_ID`]) of `len` bytes at `addr` from `ids`: each device answers
/// one status packet, in the order of `ids`.
pub fn sync_read(addr: u16, len: u16, ids: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    sync_read_like(instruction::SYNC_READ, addr, len, ids, out)
}

/// A Fast Sync Read (to [`BROADCAST_ID`]) of `len` bytes at `addr` from `ids`: the devices answer
/// together in one combined packet ([`FastSyncReply`]).
pub fn fast_sync_read(
    addr: u16,
    len: u16,
    ids: &[u8],
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    sync_read_like(instruction::FAST_SYNC_READ, addr, len, ids, out)
}

/// A status packet from `id`: the error byte, then `params` (ROBOTIS e-manual, Protocol 2.0,
/// "Status Packet").
pub fn status(id: u8, error: u8, params: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut w = Writer::new(id, instruction::STATUS, out)?;
    w.put(&[error])?;
    w.put(params)?;
    w.finish(id)
}

/// The combined Fast Sync Read reply (ROBOTIS e-manual, Protocol 2.0, "Fast Sync Read"): one
/// status packet from [`BROADCAST_ID`], not stuffed, holding per device `[ERR, ID, data, CRC]`;
/// the first block's ERR is the packet's error byte, each block's CRC the running CRC from the
/// header through that block's data, and the last block's CRC the packet's. Every block carries
/// the same number of data bytes (the first block's).
pub fn fast_sync_status<'d>(
    blocks: impl IntoIterator<Item = (u8, u8, &'d [u8])>,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let mut w = Writer::new(BROADCAST_ID, instruction::STATUS, out)?;
    let mut data_len = None;
    for (id, error, data) in blocks {
        let expected = *data_len.get_or_insert(data.len());
        if data.len() != expected {
            return Err(EncodeError::ItemLength {
                id,
                expected,
                got: data.len(),
            });
        }
        if w.pos > PREFIX_LEN + 1 {
            // The previous block's CRC, filled in below once LEN is known.
            w.put(&[0, 0])?;
        }
        w.put(&[error, id])?;
        w.put(data)?;
    }
    let data_len = data_len.ok_or(EncodeError::NoBlocks)?;
    let body = w.pos - PREFIX_LEN;
    let out = w.out;
    let total = frame(BROADCAST_ID, out, body)?;
    // Every block but the last carries the running CRC through its data; the last block's is
    // the packet's.
    let stride = data_len + 4;
    let blocks = (body - 1 + 2) / stride;
    let (mut crc, mut from) = (0, 0);
    for k in 0..blocks - 1 {
        let end = PREFIX_LEN + 1 + k * stride + 2 + data_len;
        crc = crc16(crc, &out[from..end]);
        out[end..end + 2].copy_from_slice(&crc.to_le_bytes());
        from = end;
    }
    seal(out, total);
    Ok(total)
}

/// Where the next packet is in a receive buffer (see [`scan`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scan {
    /// The first `n` bytes are not (the start of) a packet: drop them, and count them.
    Skip(usize),
    /// A header starts at 0; the whole packet is `n` bytes (or, before LEN is in, at least `n`
    /// bytes are needed to know): read more.
    Need(usize),
    /// A whole packet of `n` bytes starts at 0; its CRC is not yet checked ([`parse`]).
    Packet(usize),
}

/// Where the next packet is in `buf` (ROBOTIS e-manual, Protocol 2.0, "Packet Process"): a header
/// is `FF FF FD 00` (so the stuffed `FF FF FD FD` is none), followed by a valid ID and a LEN
/// of at least [`MIN_LEN`] and at most [`MAX_LEN`]; anything else is skipped. After [`parse`]
/// refuses a packet, drop its first byte and scan again: a real header inside it is then found.
pub fn scan(buf: &[u8]) -> Scan {
    let mut start = 0;
    while start < buf.len() {
        match candidate(&buf[start..]) {
            Candidate::No => start += 1,
            Candidate::Partial(need) => {
                return if start > 0 {
                    Scan::Skip(start)
                } else {
                    Scan::Need(need)
                }
            }
            Candidate::Whole(len) => {
                return if start > 0 {
                    Scan::Skip(start)
                } else {
                    Scan::Packet(len)
                }
            }
        }
    }
    if start > 0 {
        Scan::Skip(start)
    } else {
        Scan::Need(PREFIX_LEN)
    }
}

/// Whether a packet can start at `buf[0]`.
enum Candidate {
    /// It cannot.
    No,
    /// It may: the whole packet (or, before LEN is in, what is needed to know) is this long.
    Partial(usize),
    /// A whole packet of this length.
    Whole(usize),
}

fn candidate(buf: &[u8]) -> Candidate {
    let known = buf.len().min(HEADER.len());
    if buf[..known] != HEADER[..known] {
        return Candidate::No;
    }
    if buf.len() > 4 && !valid_id(buf[4]) {
        return Candidate::No;
    }
    if buf.len() < PREFIX_LEN {
        return Candidate::Partial(PREFIX_LEN);
    }
    let len = usize::from(u16::from_le_bytes([buf[5], buf[6]]));
    if !(MIN_LEN..=MAX_LEN).contains(&len) {
        return Candidate::No;
    }
    let total = PREFIX_LEN + len;
    if buf.len() < total {
        Candidate::Partial(total)
    } else {
        Candidate::Whole(total)
    }
}

/// Checks a whole packet `raw` (as [`scan`] delimits it: header, LEN matching the size, CRC over
/// the raw bytes), unstuffs its parameters into `scratch` and returns it. Status packets from
/// [`BROADCAST_ID`] (the combined Fast Sync/Bulk Read replies) are not stuffed and are copied as
/// they are. `scratch` needs the parameters' length ([`MAX_LEN`] always suffices).
pub fn parse<'s>(raw: &[u8], scratch: &'s mut [u8]) -> Result<Packet<'s>, DecodeError> {
    if raw.len() < MIN_PACKET {
        return Err(DecodeError::Short {
            len: raw.len(),
            min: MIN_PACKET,
        });
    }
    if raw[..4] != HEADER {
        return Err(DecodeError::Header);
    }
    let id = raw[4];
    if !valid_id(id) {
        return Err(DecodeError::BadId(id));
    }
    let field = u16::from_le_bytes([raw[5], raw[6]]);
    if usize::from(field) < MIN_LEN || PREFIX_LEN + usize::from(field) != raw.len() {
        return Err(DecodeError::Length {
            field,
            bytes: raw.len(),
        });
    }
    let crc_at = raw.len() - 2;
    let computed = crc16(0, &raw[..crc_at]);
    let received = u16::from_le_bytes([raw[crc_at], raw[crc_at + 1]]);
    if computed != received {
        return Err(DecodeError::Crc { computed, received });
    }
    let instruction = raw[PREFIX_LEN];
    let stuffed = &raw[PREFIX_LEN + 1..crc_at];
    let len = if instruction == instruction::STATUS && id == BROADCAST_ID {
        let have = scratch.len();
        let dst = scratch
            .get_mut(..stuffed.len())
            .ok_or(DecodeError::Scratch {
                need: stuffed.len(),
                have,
            })?;
        dst.copy_from_slice(stuffed);
        stuffed.len()
    } else {
        unstuff(&raw[PREFIX_LEN..crc_at], scratch)?
    };
    Ok(Packet {
        id,
        instruction,
        params: &scratch[..len],
    })
}

/// Removes the stuffing of `body` (INST..Pn) and writes the parameters (without INST) to
/// `scratch`; returns their length.
fn unstuff(body: &[u8], scratch: &mut [u8]) -> Result<usize, DecodeError> {
    let mut n = 0;
    let mut i = 1;
    while i < body.len() {
        if n >= scratch.len() {
            return Err(DecodeError::Scratch {
                need: n + 1,
                have: scratch.len(),
            });
        }
        scratch[n] = body[i];
        n += 1;
        if pattern_ends_at(body, i) {
            // The stuffed FD follows the pattern: drop it (it must be there).
            if body.get(i + 1) != Some(&0xFD) {
                return Err(DecodeError::Stuffing {
                    offset: PREFIX_LEN + i + 1,
                });
            }
            i += 1;
        }
        i += 1;
    }
    Ok(n)
}
