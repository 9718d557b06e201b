//! The Dynamixel bus: request and reply over a serial line, every byte through
//! `teleop-leap-protocol`. A [`Line`] moves bytes (the serial port, [`SerialLine`], or a test's
//! script); the [`Bus`] sends a request and waits for its reply until the reply's timeout
//! ([`crate::timing`]), and counts what else it finds on the line: bytes that are no packet,
//! replies with a bad CRC, packets nobody asked for (or not the reply asked for: another
//! length), bytes that came after their request gave up. Nothing is dropped uncounted.
//!
//! A packet that does not check (a bad CRC, or noise that looks like a header and claims a
//! length) loses only its first byte: the scan goes on from the next one until the reply's
//! deadline, so a good reply behind noise is still found. A Fast Sync Read reply cut short or
//! damaged keeps the blocks at its start whose running CRC checks
//! (`teleop_leap_protocol::packet::FastSyncReply::prefix`). A request's deadline counts from
//! when the line is free of the Sync Write sent before it (which no status follows).
//!
//! Allocation-free: requests are encoded into, and replies scanned and unstuffed in, buffers the
//! bus owns.

use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::path::Path;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use teleop_leap_protocol::packet::{self, ErrorByte, FastSyncReply, Scan, Status, PREFIX_LEN};
use teleop_leap_protocol::{wire, DecodeError, EncodeError};
use teleop_runtime::serial_latency;

use crate::timing::Timing;

/// Bytes the receive buffer holds (more than the longest packet a servo sends).
const RX_CAP: usize = 1024;
/// Bytes the transmit buffer holds (a Sync Write of 16 goals is 94 before stuffing).
const TX_CAP: usize = 512;
/// Most parameter bytes a single servo's reply carries here (the service's reads).
pub const MAX_REPLY: usize = 64;
/// Most servos a Fast Sync Read asks.
pub const MAX_SERVOS: usize = 16;
/// Most data bytes a Fast Sync Read asks of each servo.
pub const MAX_BLOCK: usize = 16;

/// Moves bytes to and from the servos.
pub trait Line {
    /// Writes all of `bytes`.
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()>;
    /// Reads what arrives within `timeout` into `buf` (at least one byte, or 0 when nothing
    /// came in time).
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize>;
}

/// Why a request got no usable reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BusError {
    /// No (complete) reply within its timeout.
    #[error("no reply in time")]
    Timeout,
    /// A reply with a bad CRC, or one that does not decode (counted).
    #[error("a corrupt reply ({0})")]
    Corrupt(DecodeError),
    /// The line failed (the adapter is gone): reopen it.
    #[error("serial line: {0}")]
    Io(std::io::ErrorKind),
    /// The request could not be encoded.
    #[error("request not encoded: {0}")]
    Encode(EncodeError),
}

/// What the bus found on the line, since it was opened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BusCounters {
    /// Requests sent.
    pub requests: u64,
    /// Replies with a bad CRC (a packet's, or a Fast Sync Read block's).
    pub crc_errors: u64,
    /// Replies with a good CRC that do not decode as the reply asked for.
    pub malformed: u64,
    /// Bytes that were not part of any packet.
    pub garbage_bytes: u64,
    /// Runs of such bytes (each run one error).
    pub garbage_runs: u64,
    /// Bytes that came after their request had given up, dropped before the next request.
    pub late_bytes: u64,
    /// Whole packets nobody waited for (another ID, not a status packet, or a status of
    /// another length than the reply asked for: a late one to an earlier request).
    pub unexpected: u64,
    /// Replies not there (complete) in time.
    pub timeouts: u64,
}

/// One servo's status reply: its error byte and parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reply {
    /// The error byte.
    pub error: ErrorByte,
    len: usize,
    data: [u8; MAX_REPLY],
}

impl Reply {
    /// The parameters (at most [`MAX_REPLY`] bytes of them).
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len]
    }
}

/// One servo's block of a Fast Sync Read reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Block {
    /// The block's error byte.
    pub error: ErrorByte,
    /// Its data (the first `len` bytes).
    pub data: [u8; MAX_BLOCK],
}

/// The blocks of one Fast Sync Read, in the order of the IDs asked (`None`: no block from it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FastRead {
    /// Per ID asked, its block.
    pub blocks: [Option<Block>; MAX_SERVOS],
    /// Blocks from an ID not asked (counted in `unexpected`).
    pub foreign_blocks: u32,
}

impl FastRead {
    /// Nothing read.
    pub const EMPTY: Self = Self {
        blocks: [None; MAX_SERVOS],
        foreign_blocks: 0,
    };
}

/// A request and reply bus over a [`Line`].
pub struct Bus<L> {
    line: L,
    timing: Timing,
    tx: [u8; TX_CAP],
    rx: [u8; RX_CAP],
    rx_len: usize,
    scratch: [u8; RX_CAP],
    counters: BusCounters,
    /// When the bytes of the last request sent without a reply (a Sync Write, a broadcast
    /// Write) have left the line.
    line_free: Instant,
    /// Bytes of a packet that did not check, still ahead in the scan (not counted again as
    /// garbage when they are skipped).
    suspect: usize,
}

impl<L: Line> Bus<L> {
    /// A bus on `line` with `timing`.
    pub fn new(line: L, timing: Timing) -> Self {
        Self {
            line,
            timing,
            tx: [0; TX_CAP],
            rx: [0; RX_CAP],
            rx_len: 0,
            scratch: [0; RX_CAP],
            counters: BusCounters::default(),
            line_free: Instant::now(),
            suspect: 0,
        }
    }

    /// What the bus found so far.
    pub fn counters(&self) -> &BusCounters {
        &self.counters
    }

    /// Goes on counting from `counters` (a reopened line's bus counts on from the last one's).
    pub fn set_counters(&mut self, counters: BusCounters) {
        self.counters = counters;
    }

    /// Sets the timing (after the servos' return delay was written).
    pub fn set_timing(&mut self, timing: Timing) {
        self.timing = timing;
    }

    /// Pings `id`: its Model Number and firmware version.
    pub fn ping(&mut self, id: u8) -> Result<(u16, u8), BusError> {
        let reply = self.transact(id, 3, |out| packet::ping(id, out))?;
        match reply.data() {
            [lo, hi, fw, ..] => Ok((u16::from_le_bytes([*lo, *hi]), *fw)),
            _ => {
                self.counters.malformed += 1;
                Err(BusError::Corrupt(DecodeError::DataLength {
                    what: "ping reply",
                    expected: 3,
                    got: reply.data().len(),
                }))
            }
        }
    }

    /// Reads `len` bytes at `addr` of `id` (the reply's error byte is the caller's to judge;
    /// with an error number the data may be absent or of another length).
    pub fn read(&mut self, id: u8, addr: u16, len: u16) -> Result<Reply, BusError> {
        self.transact(id, usize::from(len), |out| packet::read(id, addr, len, out))
    }

    /// Writes `data` at `addr` of `id`; its status.
    pub fn write(&mut self, id: u8, addr: u16, data: &[u8]) -> Result<Reply, BusError> {
        self.transact(id, 0, |out| packet::write(id, addr, data, out))
    }

    /// Reboots `id`; its status (sent before it restarts).
    pub fn reboot(&mut self, id: u8) -> Result<Reply, BusError> {
        self.transact(id, 0, |out| packet::reboot(id, out))
    }

    /// Sync Write of `len` bytes at `addr` to each `(id, data)` (no reply).
    pub fn sync_write<'a>(
        &mut self,
        addr: u16,
        len: u16,
        items: impl IntoIterator<Item = (u8, &'a [u8])>,
    ) -> Result<(), BusError> {
        let n = packet::sync_write(addr, len, items, &mut self.tx).map_err(BusError::Encode)?;
        self.send_unanswered(n)
    }

    /// Writes `data` at `addr` of every servo at once (broadcast ID 0xFE: every servo that
    /// hears it carries it out, none answers; ROBOTIS e-manual, Protocol 2.0, "Instruction").
    pub fn broadcast_write(&mut self, addr: u16, data: &[u8]) -> Result<(), BusError> {
        let n = packet::write(packet::BROADCAST_ID, addr, data, &mut self.tx)
            .map_err(BusError::Encode)?;
        self.send_unanswered(n)
    }

    /// Sends `tx[..n]`, which nothing answers: its bytes take their time on the wire before
    /// the next request's.
    fn send_unanswered(&mut self, n: usize) -> Result<(), BusError> {
        let start = self.send_start();
        self.send(n)?;
        self.line_free = start + self.timing.wire(n);
        Ok(())
    }

    /// When a request sent now starts on the wire: now, or when the line is free of the
    /// unanswered request before it.
    fn send_start(&self) -> Instant {
        Instant::now().max(self.line_free)
    }

    /// One Fast Sync Read of `len` bytes at `addr` from `ids`: the blocks found, in the order
    /// of `ids`. `Ok` when the whole reply came; otherwise `Timeout` (nothing, or a reply cut
    /// short) or `Corrupt` (a reply that does not check), with the blocks at its start whose
    /// running CRC checks in `out`.
    pub fn fast_sync_read(
        &mut self,
        addr: u16,
        len: u16,
        ids: &[u8],
        out: &mut FastRead,
    ) -> Result<(), BusError> {
        *out = FastRead::EMPTY;
        let n = packet::fast_sync_read(addr, len, ids, &mut self.tx).map_err(BusError::Encode)?;
        let start = self.send_start();
        self.send(n)?;
        let expect = wire::fast_sync_reply_len(ids.len(), usize::from(len));
        let deadline = start + self.timing.reply(n, expect, ids.len());
        let mut corrupt = None;
        loop {
            let Some(raw_len) = self.next_packet(deadline)? else {
                // What arrived of a reply cut short: its whole blocks.
                let reply = FastSyncReply::prefix(&self.rx[..self.rx_len], len);
                if reply.len() > count(out) {
                    *out = FastRead::EMPTY;
                    take_blocks(&reply, ids, out);
                    self.consume(PREFIX_LEN + 1 + reply.len() * (usize::from(len) + 4));
                }
                self.counters.unexpected += u64::from(out.foreign_blocks);
                return Err(self.gave_up(corrupt));
            };
            let parsed = packet::parse(&self.rx[..raw_len], &mut self.scratch);
            match parsed.and_then(|p| FastSyncReply::new(&p, len)) {
                Ok(reply) => {
                    *out = FastRead::EMPTY;
                    take_blocks(&reply, ids, out);
                    self.counters.unexpected += u64::from(out.foreign_blocks);
                    self.consume(raw_len);
                    return Ok(());
                }
                Err(DecodeError::NotFastSync(_)) | Err(DecodeError::NotStatus(_)) => {
                    // A whole packet, but another one (a late single reply, an echo).
                    self.counters.unexpected += 1;
                    self.consume(raw_len);
                }
                Err(e) => {
                    // Its good blocks are kept; the scan goes on from its next byte.
                    let reply = FastSyncReply::prefix(&self.rx[..raw_len], len);
                    if reply.len() > count(out) {
                        *out = FastRead::EMPTY;
                        take_blocks(&reply, ids, out);
                    }
                    corrupt = Some(e);
                    self.reject(raw_len, e);
                }
            }
        }
    }

    /// Sends the request `encode` writes and waits for `id`'s status with `params` bytes of
    /// data (or any, with an error number: a refusal may carry none). A status of another
    /// length is not this request's reply (a late one to an earlier request): counted, skipped.
    fn transact(
        &mut self,
        id: u8,
        params: usize,
        encode: impl FnOnce(&mut [u8]) -> Result<usize, EncodeError>,
    ) -> Result<Reply, BusError> {
        let n = encode(&mut self.tx).map_err(BusError::Encode)?;
        let start = self.send_start();
        self.send(n)?;
        let deadline = start + self.timing.reply(n, wire::status_len(params), 1);
        let mut corrupt = None;
        loop {
            let Some(raw_len) = self.next_packet(deadline)? else {
                return Err(self.gave_up(corrupt));
            };
            let decoded = packet::parse(&self.rx[..raw_len], &mut self.scratch)
                .and_then(|p| Status::from_packet(&p).map(|s| (s.id, s.error, s.params)));
            let (from, error, data) = match decoded {
                Ok(s) => s,
                Err(DecodeError::NotStatus(_)) => {
                    // Our own request echoed by a line that echoes, or another master's.
                    self.counters.unexpected += 1;
                    self.consume(raw_len);
                    continue;
                }
                Err(e) => {
                    corrupt = Some(e);
                    self.reject(raw_len, e);
                    continue;
                }
            };
            if from != id || (data.len() != params && error.number().is_none()) {
                self.counters.unexpected += 1;
                self.consume(raw_len);
                continue;
            }
            let len = data.len().min(MAX_REPLY);
            let mut reply = Reply {
                error,
                len,
                data: [0; MAX_REPLY],
            };
            reply.data[..len].copy_from_slice(&data[..len]);
            self.consume(raw_len);
            return Ok(reply);
        }
    }

    /// A packet of `raw_len` bytes at the front did not decode: counted, and only its first
    /// byte dropped (it may be noise that looks like a header, with the reply inside what it
    /// claims); the rest is scanned again without being counted as garbage.
    fn reject(&mut self, raw_len: usize, e: DecodeError) {
        self.count_decode(e);
        self.consume(1);
        self.suspect = raw_len - 1;
    }

    /// The deadline passed without a reply: `Corrupt` when one that did not check came
    /// (counted then), else `Timeout` (counted).
    fn gave_up(&mut self, corrupt: Option<DecodeError>) -> BusError {
        match corrupt {
            Some(e) => BusError::Corrupt(e),
            None => {
                self.counters.timeouts += 1;
                BusError::Timeout
            }
        }
    }

    /// Counts a reply that did not decode.
    fn count_decode(&mut self, e: DecodeError) {
        match e {
            DecodeError::Crc { .. } | DecodeError::BlockCrc { .. } => self.counters.crc_errors += 1,
            _ => self.counters.malformed += 1,
        }
    }

    /// Drops what is left from earlier requests (counted as late), then sends `tx[..n]`.
    fn send(&mut self, n: usize) -> Result<(), BusError> {
        self.counters.late_bytes += self.rx_len as u64;
        self.rx_len = 0;
        self.suspect = 0;
        loop {
            let got = self
                .line
                .recv(&mut self.rx, Duration::ZERO)
                .map_err(|e| BusError::Io(e.kind()))?;
            if got == 0 {
                break;
            }
            self.counters.late_bytes += got as u64;
        }
        self.counters.requests += 1;
        self.line
            .send(&self.tx[..n])
            .map_err(|e| BusError::Io(e.kind()))
    }

    /// Receives until a whole packet starts the buffer (bytes before it counted as garbage,
    /// unless they are what is left of a packet that did not check); its length. `None` at
    /// `deadline` (the buffer then starts with what arrived of a packet, if anything).
    fn next_packet(&mut self, deadline: Instant) -> Result<Option<usize>, BusError> {
        loop {
            match packet::scan(&self.rx[..self.rx_len]) {
                Scan::Packet(len) => {
                    self.suspect = 0;
                    return Ok(Some(len));
                }
                Scan::Skip(n) if n > 0 => {
                    let garbage = n - n.min(self.suspect);
                    self.suspect -= n.min(self.suspect);
                    if garbage > 0 {
                        self.counters.garbage_bytes += garbage as u64;
                        self.counters.garbage_runs += 1;
                    }
                    self.consume(n);
                    continue;
                }
                Scan::Skip(_) | Scan::Need(_) => {}
            }
            if self.rx_len == RX_CAP {
                // Cannot happen with packets shorter than the buffer; never spin on it.
                self.counters.garbage_bytes += RX_CAP as u64;
                self.rx_len = 0;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            let got = self
                .line
                .recv(&mut self.rx[self.rx_len..], left)
                .map_err(|e| BusError::Io(e.kind()))?;
            self.rx_len += got;
        }
    }

    /// Drops the first `n` received bytes.
    fn consume(&mut self, n: usize) {
        let n = n.min(self.rx_len);
        self.rx.copy_within(n..self.rx_len, 0);
        self.rx_len -= n;
    }
}

/// How many blocks `read` holds.
fn count(read: &FastRead) -> usize {
    read.blocks.iter().filter(|b| b.is_some()).count()
}

/// The blocks of `reply` into `out`, in the order of the `ids` asked (the others counted in
/// `foreign_blocks`).
fn take_blocks(reply: &FastSyncReply<'_>, ids: &[u8], out: &mut FastRead) {
    for block in reply.blocks() {
        let Some(slot) = ids.iter().position(|id| *id == block.id) else {
            out.foreign_blocks += 1;
            continue;
        };
        let mut data = [0u8; MAX_BLOCK];
        let k = block.data.len().min(MAX_BLOCK);
        data[..k].copy_from_slice(&block.data[..k]);
        out.blocks[slot] = Some(Block {
            error: block.error,
            data,
        });
    }
}

/// The serial port as a [`Line`]: 8N1, no flow control, opened exclusively, in low-latency mode
/// where the driver has one.
pub struct SerialLine {
    port: TTYPort,
}

/// How long writing a request may block before the line counts as stuck.
const WRITE_TIMEOUT: Duration = Duration::from_millis(100);

impl SerialLine {
    /// Opens `path` at `baud`: asks the driver for `ASYNC_LOW_LATENCY` (a pseudo-terminal
    /// refuses: a debug note) and warns once, naming the fix, when a USB adapter's latency
    /// timer is above 1 ms (`teleop_runtime::serial_latency::tune`, as the glove's link does).
    pub fn open(path: &str, baud: u32) -> Result<Self, serialport::Error> {
        let port = serialport::new(path, baud)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            .timeout(Duration::from_millis(10))
            .open_native()?;
        serial_latency::tune(port.as_raw_fd(), Path::new(path));
        Ok(Self { port })
    }
}

impl Line for SerialLine {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        // The driver takes a request at once unless the line is stuck (a stalled adapter).
        self.port
            .set_timeout(WRITE_TIMEOUT)
            .map_err(std::io::Error::from)?;
        self.port.write_all(bytes)
    }

    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        self.port
            .set_timeout(timeout)
            .map_err(std::io::Error::from)?;
        match self.port.read(buf) {
            Ok(n) => Ok(n),
            // Nothing in time; or a signal (SIGINT: the loop stops after this turn).
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            Err(e) => Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use std::collections::VecDeque;

    use proptest::prelude::*;
    use teleop_leap_protocol::xc330::State;

    use super::*;

    /// A line that answers each request with the next scripted bytes (and records requests,
    /// and the deadline of every wait).
    #[derive(Default)]
    struct Script {
        replies: VecDeque<Vec<u8>>,
        pending: Vec<u8>,
        sent: Vec<Vec<u8>>,
        waits: Vec<Instant>,
    }

    impl Line for Script {
        fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
            self.sent.push(bytes.to_vec());
            if let Some(r) = self.replies.pop_front() {
                self.pending.extend(r);
            }
            Ok(())
        }
        fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
            self.waits.push(Instant::now() + timeout);
            let n = self.pending.len().min(buf.len());
            buf[..n].copy_from_slice(&self.pending[..n]);
            self.pending.drain(..n);
            Ok(n)
        }
    }

    fn bus(replies: Vec<Vec<u8>>) -> Bus<Script> {
        let line = Script {
            replies: replies.into(),
            ..Default::default()
        };
        Bus::new(line, Timing::new(4_000_000, 0, Duration::from_millis(1)))
    }

    /// The Fast Sync Read reply of `ids`, each at `position`.
    fn reply(ids: &[u8], position: i32) -> Vec<u8> {
        let states: Vec<[u8; 10]> = ids
            .iter()
            .map(|_| {
                State {
                    current_ma: 12,
                    velocity: -1,
                    position,
                }
                .encode()
            })
            .collect();
        let blocks = ids.iter().zip(&states).map(|(id, s)| (*id, 0u8, &s[..]));
        let mut out = [0u8; 512];
        let n = packet::fast_sync_status(blocks, &mut out).unwrap();
        out[..n].to_vec()
    }

    #[test]
    fn a_fast_sync_read_gives_every_block_and_counts_what_else_came() {
        let ids: Vec<u8> = (0..16).collect();
        let mut noisy = vec![0x00, 0xFF, 0x13];
        noisy.extend(reply(&ids, 2048));
        let mut bus = bus(vec![noisy]);
        let mut read = FastRead::EMPTY;
        bus.fast_sync_read(126, 10, &ids, &mut read).unwrap();
        assert!(read.blocks.iter().all(|b| b.is_some()));
        let state = State::decode(&read.blocks[7].unwrap().data[..10]).unwrap();
        assert_eq!((state.current_ma, state.position), (12, 2048));
        assert_eq!(bus.counters().garbage_bytes, 3);
        assert_eq!(bus.counters().crc_errors, 0);
    }

    #[test]
    fn a_corrupt_reply_is_counted_and_lost_whole_a_missing_block_is_none() {
        let ids: Vec<u8> = (0..16).collect();
        for at in [8usize, 20, 100, 229, 230, 231] {
            let mut bad = reply(&ids, 2048);
            bad[at] ^= 0x41;
            let mut bus = bus(vec![bad]);
            let mut read = FastRead::EMPTY;
            let e = bus.fast_sync_read(126, 10, &ids, &mut read).unwrap_err();
            assert!(matches!(e, BusError::Corrupt(_)), "byte {at}: {e:?}");
            assert_eq!(bus.counters().crc_errors, 1, "byte {at}");
            assert_eq!(bus.counters().garbage_runs, 0, "byte {at}: counted once");
            // The blocks before the damaged one are kept (each 14 bytes from byte 8 on).
            let good = (at - 8) / 14;
            let kept: Vec<bool> = read.blocks.iter().map(Option::is_some).collect();
            assert_eq!(
                kept,
                (0..16).map(|k| k < good).collect::<Vec<_>>(),
                "byte {at}"
            );
        }
        // Servo 11 silent: its block is missing from a good reply.
        let without: Vec<u8> = ids.iter().copied().filter(|i| *i != 11).collect();
        let mut bus = bus(vec![reply(&without, 100)]);
        let mut read = FastRead::EMPTY;
        bus.fast_sync_read(126, 10, &ids, &mut read).unwrap();
        assert!(read.blocks[11].is_none());
        assert_eq!(read.blocks.iter().filter(|b| b.is_some()).count(), 15);
    }

    #[test]
    fn a_reply_cut_short_keeps_its_whole_blocks() {
        let ids: Vec<u8> = (0..16).collect();
        // A chain that ends at servo 5: its header announced all 16.
        let cut = reply(&ids, 300)[..8 + 5 * 14 + 6].to_vec();
        let mut bus = bus(vec![cut]);
        let mut read = FastRead::EMPTY;
        let e = bus.fast_sync_read(126, 10, &ids, &mut read).unwrap_err();
        assert_eq!(e, BusError::Timeout);
        let kept: Vec<bool> = read.blocks.iter().map(Option::is_some).collect();
        assert_eq!(kept, (0..16).map(|k| k < 5).collect::<Vec<_>>());
        let state = State::decode(&read.blocks[4].unwrap().data[..10]).unwrap();
        assert_eq!(state.position, 300);
        assert_eq!(bus.counters().timeouts, 1);
        // The part of block 5 that came is late when the next request goes out.
        let _ = bus.ping(1);
        assert_eq!(bus.counters().late_bytes, 6);
    }

    #[test]
    fn noise_that_looks_like_a_header_does_not_hide_the_reply_behind_it() {
        // A header claiming 17 bytes in all, then the real status (14 bytes): the claim takes
        // in part of the reply, whose CRC does not check; dropping one byte and scanning on
        // finds the reply.
        let mut status = [0u8; 32];
        let n = packet::status(3, 0, &[0xD8, 0x04, 52], &mut status).unwrap();
        let mut line = vec![0xFF, 0xFF, 0xFD, 0x00, 0x03, 0x0A, 0x00];
        line.extend_from_slice(&status[..n]);
        let mut bus = bus(vec![line]);
        assert_eq!(bus.ping(3), Ok((1240, 52)));
        assert_eq!(bus.counters().crc_errors, 1);
        assert_eq!(
            (bus.counters().garbage_runs, bus.counters().timeouts),
            (0, 0)
        );
    }

    #[test]
    fn a_late_status_of_another_length_is_not_the_reply() {
        // The empty status of an earlier Write to servo 3 comes before the Read's reply.
        let mut late = [0u8; 32];
        let n = packet::status(3, 0, &[], &mut late).unwrap();
        let mut line = late[..n].to_vec();
        let mut data = [0u8; 32];
        let m = packet::status(3, 0, &1234i32.to_le_bytes(), &mut data).unwrap();
        line.extend_from_slice(&data[..m]);
        let mut bus = bus(vec![line]);
        let r = bus.read(3, 132, 4).unwrap();
        assert_eq!(r.data(), 1234i32.to_le_bytes());
        assert_eq!(bus.counters().unexpected, 1);
        // A refusal may carry no data: it is the reply.
        let mut refused = [0u8; 32];
        let n = packet::status(3, 0x07, &[], &mut refused).unwrap();
        let mut bus = self::bus(vec![refused[..n].to_vec()]);
        let r = bus.read(3, 300, 4).unwrap();
        assert!(r.error.number().is_some() && r.data().is_empty());
    }

    #[test]
    fn a_fast_sync_read_waits_for_the_sync_write_before_it_to_leave_the_line() {
        let ids: Vec<u8> = (0..16).collect();
        let mut bus = bus(vec![Vec::new(), reply(&ids, 2048)]);
        let goals = [[0u8; 4]; 16];
        let t0 = Instant::now();
        bus.sync_write(116, 4, ids.iter().zip(&goals).map(|(id, g)| (*id, &g[..])))
            .unwrap();
        let mut read = FastRead::EMPTY;
        bus.fast_sync_read(126, 10, &ids, &mut read).unwrap();
        let timing = Timing::new(4_000_000, 0, Duration::from_millis(1));
        let (write, request, answer) = (94, 30, 232);
        let earliest = t0 + timing.wire(write) + timing.reply(request, answer, 16);
        // The longest wait is the reply's (sending drains the line without waiting).
        let waited = bus.line.waits.iter().copied().max().unwrap();
        assert!(
            waited >= earliest,
            "the reply's deadline is {:?} short",
            earliest - waited
        );
    }

    proptest! {
        /// Whatever bytes come back, a request ends with a reply or a typed error, and every
        /// byte is accounted for.
        #[test]
        fn any_bytes_give_a_reply_or_an_error(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let ids: Vec<u8> = (0..16).collect();
            let mut b = bus(vec![bytes.clone(), bytes.clone()]);
            let mut read = FastRead::EMPTY;
            let _ = b.fast_sync_read(126, 10, &ids, &mut read);
            let _ = b.ping(3);
            let c = *b.counters();
            prop_assert!(c.garbage_bytes + c.late_bytes <= 2 * bytes.len() as u64);
        }
    }
}
