//! The LEAP Hand's half-duplex bus: 16 servos ([`crate::servo`]) on one line, the hand they
//! drive ([`crate::hand`]) on the plant's clock, and the line's timing. Pure: bytes come in
//! with the time their first bit started on the line, status packets go out scheduled at the
//! time their last byte would have left the servo.
//!
//! What the bus does (ROBOTIS e-manual, Protocol 2.0; `docs/devices/leap.md, "Instructions"`,
//! `docs/devices/leap.md, "Fast Sync Read"`, `docs/devices/leap.md, "Timing"`; what the
//! documents leave open, `docs/devices/leap.md, "Unknown"`, is an option here):
//! - bytes are taken at the line's baud rate (10 bits a byte); a request is complete when its
//!   last byte is, and each status starts its servo's Return Delay Time after the request's
//!   end (and after the status before it on the line);
//! - a servo whose Baud Rate register differs from the line's hears garbage: it neither acts
//!   nor answers (counted per request as `baud_mismatches`);
//! - bytes that are not a packet are dropped (counted as `noise_bytes`), a packet with a bad
//!   CRC is dropped unanswered (`crc_errors`; [`BusOptions::crc_status`] answers it with CRC
//!   Error instead), and a partial packet whose next byte comes more than 1.5 ms later is
//!   dropped (`cut_packets`; e-manual, Protocol 2.0, "Byte to Byte Time");
//! - broadcast: Ping is answered by every servo in ID order, Sync Read / Fast Sync Read / Bulk
//!   Read by the servos named; every other broadcast instruction is carried out silently;
//! - Sync Read: one status per named servo, in request order; Fast Sync Read: one packet from
//!   ID 0xFE with a block per servo, each block's CRC the running CRC (the protocol crate's
//!   `fast_sync_status`); a servo that does not answer (silent, booting, deaf, firmware before
//!   46) is left out of
//!   the chain ([`Missing::Omit`]) or ends it there ([`Missing::Truncate`]: the bytes before its
//!   block go out, the rest never comes); the reply starts after the first answering servo's
//!   Return Delay Time (the chain's blocks follow without a delay of their own);
//! - Fast Bulk Read is not simulated (counted as `unsupported`, unanswered).
//!
//! Every request heard whole is noted in the [`Outbox`] with the time it ended ([`Heard`]), for
//! a wire tap.
//!
//! Faults (set by the control socket): a status lost (`drop P`), a status with one corrupted
//! byte (`crc P`), a servo silent (neither hears nor answers).

use teleop_leap_protocol::packet::{self, ErrorNumber, Request, Scan, BROADCAST_ID, MAX_PACKET};
use teleop_leap_protocol::{wire, xc330, DecodeError};
use teleop_sim_kit::dice::Dice;
use teleop_sim_kit::plant::Clock;

use crate::hand::{Hand, JOINTS};
use crate::servo::Servo;

/// Longest pause between two bytes of one packet before the servos drop it, s.
pub const BYTE_GAP: f64 = 0.0015;
/// The first firmware version that takes Fast Sync Read (XC330; ROBOTIS e-manual, Protocol 2.0,
/// "Fast Sync Read").
pub const FAST_SYNC_FIRMWARE: u8 = 46;
/// The slowest rate the servos take, bit/s: a host's port set slower (or to 0, hung up) is
/// timed as this (the servos understand neither).
pub const MIN_BAUD: u32 = 9600;
/// The plant's sub-step, s.
pub const PLANT_STEP: f64 = 0.000_25;

/// Seconds a byte takes on the line at `baud` (10 bits; at least [`MIN_BAUD`]'s).
fn byte_time(baud: u32) -> f64 {
    wire::byte_time_ns(baud.max(MIN_BAUD)) as f64 * 1e-9
}

/// What the servos after a missing one in a Fast Sync Read chain do (not documented).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Missing {
    /// The chain goes on without the missing servo's block.
    Omit,
    /// The chain ends at the missing servo: the bytes before its block go out, no more.
    Truncate,
}

impl std::str::FromStr for Missing {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "omit" => Ok(Self::Omit),
            "truncate" => Ok(Self::Truncate),
            other => Err(format!("{other:?}: use omit or truncate")),
        }
    }
}

/// The bus's behaviour where the documents leave it open.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusOptions {
    /// The Fast Sync Read chain around a missing servo.
    pub fast_sync_missing: Missing,
    /// A request with a bad CRC to one servo is answered with CRC Error (else: dropped).
    pub crc_status: bool,
}

/// Fault probabilities (0..1) and silenced servos.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Faults {
    /// A status is lost.
    pub drop: f64,
    /// A status gets one corrupted byte.
    pub crc: f64,
}

/// Requests by instruction, and what became of the bytes and statuses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Ping requests heard.
    pub ping: u64,
    /// Read requests heard.
    pub read: u64,
    /// Write requests heard.
    pub write: u64,
    /// Reg Write requests heard.
    pub reg_write: u64,
    /// Action requests heard.
    pub action: u64,
    /// Factory Reset requests heard.
    pub factory_reset: u64,
    /// Reboot requests heard.
    pub reboot: u64,
    /// Clear requests heard.
    pub clear: u64,
    /// Control Table Backup requests heard.
    pub backup: u64,
    /// Sync Read requests heard.
    pub sync_read: u64,
    /// Fast Sync Read requests heard.
    pub fast_sync_read: u64,
    /// Sync Write requests heard.
    pub sync_write: u64,
    /// Bulk Read requests heard.
    pub bulk_read: u64,
    /// Bulk Write requests heard.
    pub bulk_write: u64,
    /// Requests not simulated (Fast Bulk Read, an unknown instruction): unanswered.
    pub unsupported: u64,
    /// Packets with a good CRC that are no request (bad parameters, a status heard).
    pub malformed: u64,
    /// Status packets sent (a Fast Sync Read reply is one).
    pub replies: u64,
    /// Packets received with a bad CRC.
    pub crc_errors: u64,
    /// Bytes received that were no packet.
    pub noise_bytes: u64,
    /// Partial packets dropped after a pause longer than the byte-to-byte time.
    pub cut_packets: u64,
    /// Requests a servo did not hear because its baud rate differs from the line's.
    pub baud_mismatches: u64,
    /// Statuses lost on purpose (`drop`).
    pub dropped: u64,
    /// Statuses sent with a corrupted byte (`crc`).
    pub corrupted: u64,
    /// Statuses a silenced servo did not send.
    pub silenced: u64,
}

/// A request the servos heard whole, as a wire tap reports it ([`crate::serve::Tap`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Heard {
    /// When its last byte ended on the line, s.
    pub end: f64,
    /// Its instruction byte.
    pub instruction: u8,
    /// For a Sync Write of Goal Position (116, 4 bytes): the goal counts by ID (0..15; `None`
    /// for an ID it does not name).
    pub goals: Option<[Option<i32>; JOINTS]>,
}

/// Status packets to write, each at the time its last byte leaves the servo, and the requests
/// heard meanwhile.
#[derive(Debug, Default)]
pub struct Outbox {
    bytes: Vec<u8>,
    parts: Vec<(f64, usize)>,
    heard: Vec<Heard>,
}

impl Outbox {
    /// Empty.
    pub fn new() -> Self {
        Self::default()
    }

    /// The requests heard whole since the last [`Outbox::clear`], in order.
    pub fn heard(&self) -> &[Heard] {
        &self.heard
    }

    /// Each part to write: when (s) and its bytes, in order.
    pub fn parts(&self) -> impl Iterator<Item = (f64, &[u8])> {
        let mut from = 0;
        self.parts.iter().map(move |&(at, end)| {
            let part = &self.bytes[from..end];
            from = end;
            (at, part)
        })
    }

    /// Forgets what was written.
    pub fn clear(&mut self) {
        self.bytes.clear();
        self.parts.clear();
        self.heard.clear();
    }
}

/// The line: its timing, the status faults, the statuses going out.
struct Line {
    /// Seconds per byte at the line's baud rate.
    byte_time: f64,
    /// When the last status scheduled leaves the line free, s.
    free_at: f64,
    faults: Faults,
    dice: Dice,
    buf: Vec<u8>,
    /// The bus's counters (the line's and the requests').
    counters: Counters,
}

impl Line {
    /// Schedules the `n` bytes in `self.buf` as one status starting `delay` after `after`.
    fn send(&mut self, n: usize, after: f64, delay: f64, out: &mut Outbox) {
        let counters = &mut self.counters;
        if n == 0 {
            return;
        }
        if self.dice.roll(self.faults.drop) {
            counters.dropped += 1;
            return;
        }
        if self.dice.roll(self.faults.crc) {
            let at = 4 + usize::from(self.dice.byte()) % (n - 4).max(1);
            let flip = self.dice.byte() | 1;
            if let Some(b) = self.buf.get_mut(at.min(n - 1)) {
                *b ^= flip;
            }
            counters.corrupted += 1;
        }
        let start = after.max(self.free_at) + delay;
        let end = start + n as f64 * self.byte_time;
        self.free_at = end;
        out.bytes.extend_from_slice(&self.buf[..n]);
        out.parts.push((end, out.bytes.len()));
        counters.replies += 1;
    }

    /// Encodes and schedules a status from `id`.
    fn status(
        &mut self,
        id: u8,
        error: u8,
        params: &[u8],
        after: f64,
        delay: f64,
        out: &mut Outbox,
    ) {
        if let Ok(n) = packet::status(id, error, params, &mut self.buf) {
            self.send(n, after, delay, out);
        }
    }
}

/// The bus with its servos and the hand.
pub struct Bus {
    servos: Vec<Servo>,
    hand: Hand,
    clock: Clock,
    options: BusOptions,
    line: Line,
    rx: Vec<u8>,
    /// When the last byte in `rx` was complete, s.
    rx_last: f64,
    scratch: Vec<u8>,
    params: Vec<u8>,
    /// A Fast Sync Read's blocks: (id, error, answered).
    blocks: Vec<(u8, u8, bool)>,
    /// Per ID: silent until this time, s (`f64::INFINITY`: until told otherwise).
    silent_until: [f64; 256],
}

impl Bus {
    /// The servos (IDs as they are set) on a line, driving `hand`.
    pub fn new(servos: Vec<Servo>, hand: Hand, options: BusOptions, seed: u64) -> Self {
        Self {
            servos,
            hand,
            clock: Clock::new(PLANT_STEP),
            options,
            line: Line {
                byte_time: 0.0,
                free_at: 0.0,
                faults: Faults {
                    drop: 0.0,
                    crc: 0.0,
                },
                dice: Dice::new(seed),
                buf: vec![0; MAX_PACKET],
                counters: Counters::default(),
            },
            rx: Vec::with_capacity(2 * MAX_PACKET),
            rx_last: f64::NEG_INFINITY,
            scratch: vec![0; MAX_PACKET],
            params: vec![0; MAX_PACKET],
            blocks: Vec::with_capacity(usize::from(packet::MAX_ID) + 1),
            silent_until: [f64::NEG_INFINITY; 256],
        }
    }

    /// The servos, in the order they sit on the bus.
    pub fn servos(&self) -> &[Servo] {
        &self.servos
    }

    /// The servo with ID `id`, to change (faults).
    pub fn servo_mut(&mut self, id: u8) -> Option<&mut Servo> {
        self.servos.iter_mut().find(|s| s.id() == id)
    }

    /// The hand.
    pub fn hand(&self) -> &Hand {
        &self.hand
    }

    /// The hand, to change (its object).
    pub fn hand_mut(&mut self) -> &mut Hand {
        &mut self.hand
    }

    /// The counters.
    pub fn counters(&self) -> Counters {
        self.line.counters
    }

    /// The fault probabilities.
    pub fn faults(&self) -> Faults {
        self.line.faults
    }

    /// Replaces the fault probabilities.
    pub fn set_faults(&mut self, faults: Faults) {
        self.line.faults = faults;
    }

    /// Silences servo `id` until `until` s (`f64::INFINITY`: until told otherwise; a time
    /// past: it answers again).
    pub fn set_silent(&mut self, id: u8, until: f64) {
        self.silent_until[usize::from(id)] = until;
    }

    /// Lets every servo answer again.
    pub fn unsilence_all(&mut self) {
        self.silent_until = [f64::NEG_INFINITY; 256];
    }

    /// The IDs silent at `now`.
    pub fn silenced(&self, now: f64) -> impl Iterator<Item = u8> + '_ {
        (0..=255u8).filter(move |&id| self.is_silent(id, now))
    }

    fn is_silent(&self, id: u8, now: f64) -> bool {
        now < self.silent_until[usize::from(id)]
    }

    /// Runs the plant and the servos' control loops up to `t` s.
    pub fn advance(&mut self, t: f64) {
        let mut clock = self.clock;
        clock.advance_to(t, |now, h| {
            let (q, qd) = (self.hand.positions(), self.hand.velocities());
            let mut torque = [0.0; JOINTS];
            for (j, servo) in self.servos.iter_mut().enumerate().take(JOINTS) {
                torque[j] = servo.drive(q[j], qd[j], h, now);
            }
            self.hand.step(h, &torque);
        });
        self.clock = clock;
        for servo in &mut self.servos {
            servo.publish();
        }
    }

    /// The power goes off and on at `now` (every servo boots; EEPROM stays).
    pub fn power_cycle(&mut self, now: f64) {
        self.advance(now);
        for s in &mut self.servos {
            s.reboot(now);
        }
        self.rx.clear();
    }

    /// `n` random bytes on the line at `now` (both the host and the servos hear them).
    pub fn noise(&mut self, n: usize, baud: u32, now: f64, out: &mut Outbox) {
        let bytes: Vec<u8> = (0..n).map(|_| self.line.dice.byte()).collect();
        let byte_time = byte_time(baud);
        let start = now.max(self.rx_last).max(self.line.free_at);
        out.bytes.extend_from_slice(&bytes);
        out.parts
            .push((start + n as f64 * byte_time, out.bytes.len()));
        self.receive(&bytes, baud, start, out);
    }

    /// Bytes heard on the line at `baud` (10 bits each), read at `now`: the first started then
    /// or when the line's previous byte was done. Complete requests are carried out (the plant
    /// advanced to their end first) and their statuses scheduled in `out`.
    pub fn receive(&mut self, bytes: &[u8], baud: u32, now: f64, out: &mut Outbox) {
        if bytes.is_empty() {
            return;
        }
        let byte_time = byte_time(baud);
        self.line.byte_time = byte_time;
        if !self.rx.is_empty() && now - self.rx_last > BYTE_GAP {
            self.line.counters.cut_packets += 1;
            self.rx.clear();
        }
        let start = now.max(self.rx_last);
        // Bytes of earlier chunks in `rx` (negative once the packets taken reach into this one).
        let mut earlier = self.rx.len() as i64;
        self.rx.extend_from_slice(bytes);
        self.rx_last = start + bytes.len() as f64 * byte_time;
        loop {
            match packet::scan(&self.rx) {
                Scan::Need(_) => break,
                Scan::Skip(n) => {
                    self.line.counters.noise_bytes += n as u64;
                    self.take(n, &mut earlier);
                }
                Scan::Packet(n) => {
                    let end = start + (n as i64 - earlier) as f64 * byte_time;
                    let taken = self.packet(n, baud, end, out);
                    self.take(taken, &mut earlier);
                }
            }
            if self.rx.is_empty() {
                break;
            }
        }
    }

    fn take(&mut self, n: usize, earlier: &mut i64) {
        let n = n.min(self.rx.len());
        self.rx.drain(..n);
        *earlier -= n as i64;
    }

    /// The whole packet of `n` bytes at the start of `rx`, complete at `end`: carried out;
    /// returns the bytes to drop (the packet, or one byte of a refused one to look inside).
    fn packet(&mut self, n: usize, baud: u32, end: f64, out: &mut Outbox) -> usize {
        let mut scratch = std::mem::take(&mut self.scratch);
        let taken = match packet::parse(&self.rx[..n], &mut scratch) {
            Err(DecodeError::Crc { .. }) => {
                self.line.counters.crc_errors += 1;
                let id = self.rx.get(4).copied().unwrap_or(BROADCAST_ID);
                if self.options.crc_status && id != BROADCAST_ID {
                    self.advance(end);
                    self.crc_status(id, baud, end, out);
                }
                1
            }
            Err(_) => {
                self.line.counters.malformed += 1;
                1
            }
            Ok(p) => {
                match Request::from_packet(&p) {
                    Ok(request) => {
                        out.heard.push(Heard {
                            end,
                            instruction: p.instruction,
                            goals: goals(&request),
                        });
                        self.advance(end);
                        self.request(p.id, &request, baud, end, out);
                    }
                    Err(_) => self.line.counters.malformed += 1,
                }
                n
            }
        };
        self.scratch = scratch;
        taken
    }

    /// Whether servo `k` hears a request on the line at `baud` at `now` (counting a baud
    /// mismatch).
    fn hears(&mut self, k: usize, baud: u32, now: f64) -> bool {
        let s = &self.servos[k];
        if self.is_silent(s.id(), now) {
            return false;
        }
        if s.booting(now) {
            return false;
        }
        if xc330::BaudRate::from_code(s.baud_code()).map(|b| b.bps()) != Some(baud) {
            self.line.counters.baud_mismatches += 1;
            return false;
        }
        true
    }

    /// Index of the servo with ID `id` that hears the request, if any.
    fn hearing(&mut self, id: u8, baud: u32, now: f64) -> Option<usize> {
        let k = self.servos.iter().position(|s| s.id() == id)?;
        if self.hears(k, baud, now) {
            Some(k)
        } else {
            if self.is_silent(id, now) {
                self.line.counters.silenced += 1;
            }
            None
        }
    }

    fn crc_status(&mut self, id: u8, baud: u32, end: f64, out: &mut Outbox) {
        if let Some(k) = self.hearing(id, baud, end) {
            let s = &self.servos[k];
            if s.status_return_level() >= 2 {
                let alert = if s.hardware_error() != 0 { 0x80 } else { 0 };
                let error = alert | ErrorNumber::Crc.code();
                let delay = s.return_delay();
                self.line.status(id, error, &[], end, delay, out);
            }
        }
    }

    /// Carries out one request addressed to `id`, complete at `end`.
    fn request(&mut self, id: u8, request: &Request<'_>, baud: u32, end: f64, out: &mut Outbox) {
        let broadcast = id == BROADCAST_ID;
        let c = &mut self.line.counters;
        match request {
            Request::Ping => c.ping += 1,
            Request::Read { .. } => c.read += 1,
            Request::Write { .. } => c.write += 1,
            Request::RegWrite { .. } => c.reg_write += 1,
            Request::Action => c.action += 1,
            Request::FactoryReset(_) => c.factory_reset += 1,
            Request::Reboot => c.reboot += 1,
            Request::Clear { .. } => c.clear += 1,
            Request::Backup { .. } => c.backup += 1,
            Request::SyncRead { .. } => c.sync_read += 1,
            Request::FastSyncRead { .. } => c.fast_sync_read += 1,
            Request::SyncWrite { .. } => c.sync_write += 1,
            Request::BulkRead(_) => c.bulk_read += 1,
            Request::BulkWrite(_) => c.bulk_write += 1,
            Request::FastBulkRead(_) | Request::Unknown(_) => c.unsupported += 1,
        }
        match *request {
            Request::Ping if broadcast => {
                for target in 0..=packet::MAX_ID {
                    let Some(k) = self.servos.iter().position(|s| s.id() == target) else {
                        continue;
                    };
                    if self.hears(k, baud, end) {
                        self.answer_ping(k, end, out);
                    }
                }
            }
            Request::Ping => {
                if let Some(k) = self.hearing(id, baud, end) {
                    self.answer_ping(k, end, out);
                }
            }
            Request::Read { addr, len } => {
                if broadcast {
                    return;
                }
                if let Some(k) = self.hearing(id, baud, end) {
                    self.answer_read(k, addr, len, 1, end, out);
                }
            }
            Request::SyncRead { addr, len, ids } if broadcast => {
                for &i in ids {
                    if let Some(k) = self.hearing(i, baud, end) {
                        self.answer_read(k, addr, len, 1, end, out);
                    }
                }
            }
            Request::BulkRead(items) if broadcast => {
                for (i, addr, len) in items.iter() {
                    if let Some(k) = self.hearing(i, baud, end) {
                        self.answer_read(k, addr, len, 1, end, out);
                    }
                }
            }
            Request::FastSyncRead { addr, len, ids } if broadcast => {
                self.fast_sync_read(addr, len, ids, baud, end, out);
            }
            Request::SyncWrite { addr, items, .. } if broadcast => {
                for (i, data) in items.iter() {
                    if let Some(k) = self.hearing(i, baud, end) {
                        self.servos[k].write(addr, data);
                    }
                }
            }
            Request::BulkWrite(items) if broadcast => {
                for (i, addr, data) in items.iter() {
                    if let Some(k) = self.hearing(i, baud, end) {
                        self.servos[k].write(addr, data);
                    }
                }
            }
            Request::SyncRead { .. }
            | Request::BulkRead(_)
            | Request::FastSyncRead { .. }
            | Request::SyncWrite { .. }
            | Request::BulkWrite(_)
            | Request::FastBulkRead(_) => {}
            Request::FactoryReset(0xFF) if broadcast => {}
            _ if broadcast => {
                for k in 0..self.servos.len() {
                    if self.hears(k, baud, end) {
                        self.execute(k, request, end);
                    }
                }
            }
            _ => {
                let Some(k) = self.hearing(id, baud, end) else {
                    return;
                };
                // Answered as the servo was set when the request came (a Write of Status Return
                // Level or Return Delay Time takes effect after its status).
                let (level, delay) = {
                    let s = &self.servos[k];
                    (s.status_return_level(), s.return_delay())
                };
                let error = self.execute(k, request, end);
                if level >= 2 {
                    self.line.status(id, error, &[], end, delay, out);
                }
            }
        }
    }

    /// Carries out an instruction without data in its status on servo `k`: its error byte.
    fn execute(&mut self, k: usize, request: &Request<'_>, now: f64) -> u8 {
        let s = &mut self.servos[k];
        match *request {
            Request::Write { addr, data } => s.write(addr, data),
            Request::RegWrite { addr, data } => s.reg_write(addr, data),
            Request::Action => s.action(),
            Request::FactoryReset(what) => s.factory_reset(what, now),
            Request::Reboot => s.reboot_answer(now),
            Request::Clear { option, key } => {
                if option == 0x01 && key == [0x44, 0x58, 0x4C, 0x22] {
                    s.clear_turns()
                } else {
                    s.unknown_parameter()
                }
            }
            Request::Backup { option, key } => {
                if key == [0x43, 0x54, 0x52, 0x4C] {
                    s.backup(option)
                } else {
                    s.unknown_parameter()
                }
            }
            _ => s.unknown(),
        }
    }

    fn answer_ping(&mut self, k: usize, end: f64, out: &mut Outbox) {
        let s = &self.servos[k];
        let (error, len) = s.ping(&mut self.params);
        let (id, delay) = (s.id(), s.return_delay());
        self.line
            .status(id, error, &self.params[..len], end, delay, out);
    }

    /// A Read's status from servo `k`, if its Status Return Level is at least `level`.
    fn answer_read(
        &mut self,
        k: usize,
        addr: u16,
        len: u16,
        level: i64,
        end: f64,
        out: &mut Outbox,
    ) {
        let s = &self.servos[k];
        if s.status_return_level() < level {
            return;
        }
        let (error, n) = s.read(addr, len, &mut self.params);
        let (id, delay) = (s.id(), s.return_delay());
        self.line
            .status(id, error, &self.params[..n], end, delay, out);
    }

    /// The combined reply of a Fast Sync Read.
    fn fast_sync_read(
        &mut self,
        addr: u16,
        len: u16,
        ids: &[u8],
        baud: u32,
        end: f64,
        out: &mut Outbox,
    ) {
        let x = usize::from(len);
        if ids.is_empty() || x == 0 || ids.len() * x > self.params.len() {
            return;
        }
        // Per named servo: (id, error, answered); data at params[i * x..].
        let mut blocks = std::mem::take(&mut self.blocks);
        blocks.clear();
        let mut delay = None;
        for (i, &id) in ids.iter().enumerate() {
            let answered = match self.hearing(id, baud, end) {
                Some(k)
                    if self.servos[k].status_return_level() >= 1
                        && self.servos[k].firmware() >= FAST_SYNC_FIRMWARE =>
                {
                    let s = &self.servos[k];
                    let (error, n) = s.read(addr, len, &mut self.params[i * x..(i + 1) * x]);
                    if n < x {
                        self.params[i * x + n..(i + 1) * x].fill(0);
                    }
                    delay.get_or_insert(s.return_delay());
                    blocks.push((id, error, true));
                    true
                }
                _ => false,
            };
            if !answered {
                self.params[i * x..(i + 1) * x].fill(0);
                blocks.push((id, 0, false));
            }
        }
        let Some(delay) = delay else {
            self.blocks = blocks;
            return;
        };
        let (n, cut) = match self.options.fast_sync_missing {
            Missing::Omit => {
                let data = &self.params;
                let sent = blocks
                    .iter()
                    .enumerate()
                    .filter(|(_, b)| b.2)
                    .map(|(i, &(id, error, _))| (id, error, &data[i * x..(i + 1) * x]));
                (packet::fast_sync_status(sent, &mut self.line.buf), None)
            }
            Missing::Truncate => {
                let data = &self.params;
                let all = blocks
                    .iter()
                    .enumerate()
                    .map(|(i, &(id, error, _))| (id, error, &data[i * x..(i + 1) * x]));
                let first_missing = blocks.iter().position(|b| !b.2);
                (
                    packet::fast_sync_status(all, &mut self.line.buf),
                    first_missing.map(|i| packet::PREFIX_LEN + 1 + i * (x + 4)),
                )
            }
        };
        self.blocks = blocks;
        if let Ok(n) = n {
            let n = cut.map_or(n, |c| c.min(n));
            if cut == Some(packet::PREFIX_LEN + 1) {
                return;
            }
            self.line.send(n, end, delay, out);
        }
    }
}

/// The goal counts by ID of a Sync Write of Goal Position (4 bytes each, IDs 0..15).
fn goals(request: &Request<'_>) -> Option<[Option<i32>; JOINTS]> {
    let Request::SyncWrite {
        addr,
        len: 4,
        items,
    } = request
    else {
        return None;
    };
    if *addr != xc330::GOAL_POSITION {
        return None;
    }
    let mut goals = [None; JOINTS];
    for (id, data) in items.iter() {
        if let (Some(goal), Ok(bytes)) = (goals.get_mut(usize::from(id)), data.try_into()) {
            *goal = Some(i32::from_le_bytes(bytes));
        }
    }
    Some(goals)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use proptest::prelude::*;

    use super::*;
    use crate::hand::{leap_limits, HandParams};
    use crate::servo::ServoOptions;
    use crate::table::Model;
    use teleop_leap_protocol::packet::Status;

    const BAUD: u32 = 4_000_000;

    fn bus() -> Bus {
        let servos = (0..16)
            .map(|id| Servo::new(Model::Xc330M288, id, 6, 250, ServoOptions::default()))
            .collect();
        let hand = Hand::new(HandParams::default(), leap_limits().unwrap(), None);
        let options = BusOptions {
            fast_sync_missing: Missing::Omit,
            crc_status: false,
        };
        Bus::new(servos, hand, options, 1)
    }

    /// The statuses in `out`, parsed: (id, error).
    fn statuses(out: &Outbox) -> Vec<(u8, u8)> {
        let mut scratch = vec![0u8; MAX_PACKET];
        out.parts()
            .filter_map(|(_, bytes)| {
                let p = packet::parse(bytes, &mut scratch).ok()?;
                let s = Status::from_packet(&p).ok()?;
                Some((s.id, s.error.0))
            })
            .collect()
    }

    proptest! {
        #[test]
        fn any_bytes_are_taken_without_a_panic_and_the_servos_still_answer(
            chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..8),
            baud in proptest::sample::select(vec![0u32, 57_600, 1_000_000, BAUD]),
        ) {
            let mut b = bus();
            let mut out = Outbox::new();
            let mut t = 0.0;
            for c in &chunks {
                b.receive(c, baud, t, &mut out);
                t += 0.000_5;
            }
            prop_assert!(out.parts().all(|(at, _)| at.is_finite() && at < t + 1.0));
            out.clear();
            let mut request = [0u8; 16];
            let n = packet::ping(3, &mut request).unwrap();
            b.receive(&request[..n], BAUD, t + 0.01, &mut out);
            prop_assert_eq!(statuses(&out), vec![(3, 0)]);
        }
    }

    #[test]
    fn a_status_leaves_after_the_request_the_return_delay_and_its_own_bytes() {
        let mut b = bus();
        let mut out = Outbox::new();
        let mut request = [0u8; 16];
        let n = packet::ping(BROADCAST_ID, &mut request).unwrap();
        b.receive(&request[..n], BAUD, 1.0, &mut out);
        let times: Vec<f64> = out.parts().map(|(at, _)| at).collect();
        assert_eq!(times.len(), 16);
        let byte = 10.0 / f64::from(BAUD);
        // Request (10 bytes), then per status 500 us and 14 bytes, one after the other.
        for (k, at) in times.iter().enumerate() {
            let due = 1.0 + 10.0 * byte + (k + 1) as f64 * (0.000_5 + 14.0 * byte);
            assert!((at - due).abs() < 1e-9, "status {k}: {at} vs {due}");
        }
    }
}
