//! The Revo2's firmware upgrade, device side (document section 6): the FoE server of the boot
//! loader, its checks, the simulated flash and its write time.
//!
//! - A write request is taken in BOOT only (else FoE error 0x8008 "bootstrap only"), once the
//!   upgrade type (0x8000:15) names a board (else 0x8002 "access denied"), with that board's
//!   authentication code in 0x8000:16 (else 0x800A "no rights") and a file name of section 6.1
//!   for that board, case-sensitive (else 0x8009 "not in bootstrap", the code for a file name
//!   that BOOT does not take).
//! - Data packets are acknowledged in order (a repeated packet is acknowledged again, a wrong
//!   number ends the transfer with 0x8005); the short packet ends the file.
//! - The file is then checked (section 6.5: the magic number must be the upgrade type's board,
//!   and a file shorter than its 16-byte header is no firmware: 0x800D "invalid firmware"),
//!   erased and written: the last packet is answered with BUSY until the write time is over,
//!   then acknowledged.
//! - Shortly after that acknowledge the device restarts ([`Upgrade::poll`]) with the new version
//!   in 0x8000:11 (control board) or 0x8000:13 (wrist board).
//!
//! Fault injection: [`Upgrade::stall_after`] makes the loader stop answering in the middle of a
//! transfer (until the device leaves BOOT).

use std::time::Duration;

use teleop_ecat_sim::{AlState, MailboxContext, MailboxReply};
use teleop_foe::packet::{self, ErrorCode, Packet};
use teleop_foe::OVERHEAD;
use teleop_revo2_protocol::{check_file_name, Board, FirmwareError, FirmwareHeader, Version};

/// The largest image the simulated flash takes.
pub const FLASH_SIZE: usize = 1 << 20;

/// How long the boot loader takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FlashTiming {
    /// Erasing the board's flash area.
    pub erase: Duration,
    /// Writing each started KiB of the file.
    pub per_kib: Duration,
    /// From the acknowledge of the last packet to the restart.
    pub restart_delay: Duration,
    /// The restart: the device answers no frame for this long.
    pub reboot: Duration,
}

impl Default for FlashTiming {
    fn default() -> Self {
        Self {
            erase: Duration::from_millis(150),
            per_kib: Duration::from_millis(10),
            restart_delay: Duration::from_millis(30),
            reboot: Duration::from_millis(300),
        }
    }
}

impl FlashTiming {
    /// Erase and write time of a file of `len` bytes.
    pub fn write_time(&self, len: usize) -> Duration {
        let kib = u32::try_from(len.div_ceil(1024)).unwrap_or(u32::MAX);
        self.erase + self.per_kib.saturating_mul(kib)
    }
}

/// A firmware written to the simulated flash.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Flashed {
    /// The board.
    pub board: Board,
    /// The version from the header.
    pub version: Version,
    /// The file name it came with.
    pub name: String,
    /// The whole file, header included.
    pub file: Vec<u8>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum State {
    Idle,
    Receiving {
        board: Board,
        name: String,
        next: u32,
        max_data: usize,
        file: Vec<u8>,
    },
    Writing {
        image: Flashed,
        last: u32,
        started: Duration,
        until: Duration,
    },
    Done {
        last: u32,
        restart_at: Duration,
    },
}

/// The boot loader's FoE server and the simulated flash.
#[derive(Debug, Clone)]
pub struct Upgrade {
    state: State,
    /// Timing of erase, write and restart.
    pub timing: FlashTiming,
    /// Fault: stop answering after this many data packets of the next transfer (then cleared).
    pub stall_after: Option<u32>,
    stalled: bool,
    flash: Vec<Flashed>,
    pending: Option<(Board, Version)>,
    /// Data packets received (all transfers).
    pub data_packets: u64,
    /// BUSY answers sent.
    pub busy_answers: u64,
    /// Transfers refused with an FoE error.
    pub refusals: u64,
}

impl Default for Upgrade {
    fn default() -> Self {
        Self::new(FlashTiming::default())
    }
}

fn error(code: ErrorCode, text: &str) -> MailboxReply {
    tracing::warn!(code = %code, "FoE: {text}");
    MailboxReply::Reply(
        Packet::Error {
            code,
            text: text.as_bytes(),
        }
        .to_vec(),
    )
}

fn ack(packet: u32) -> MailboxReply {
    MailboxReply::Reply(Packet::Ack { packet }.to_vec())
}

impl Upgrade {
    /// An idle loader with an empty flash.
    pub fn new(timing: FlashTiming) -> Self {
        Self {
            state: State::Idle,
            timing,
            stall_after: None,
            stalled: false,
            flash: Vec::new(),
            pending: None,
            data_packets: 0,
            busy_answers: 0,
            refusals: 0,
        }
    }

    /// The last firmware written for `board`.
    pub fn flashed(&self, board: Board) -> Option<&Flashed> {
        self.flash.iter().rev().find(|f| f.board == board)
    }

    /// True while a transfer or a flash write is under way.
    pub fn busy(&self) -> bool {
        matches!(self.state, State::Receiving { .. } | State::Writing { .. })
    }

    /// True once the loader stopped answering (fault), until the device leaves BOOT.
    pub fn stalled(&self) -> bool {
        self.stalled
    }

    /// The device leaves (or enters) BOOT: an unfinished transfer is dropped (the flash keeps
    /// the old firmware) and a stalled loader answers again. A finished one still restarts.
    pub fn reset(&mut self) {
        if matches!(self.state, State::Receiving { .. } | State::Writing { .. }) {
            tracing::warn!("FoE transfer abandoned: the device left BOOT");
            self.state = State::Idle;
        }
        self.stalled = false;
    }

    /// Time passes: after the last acknowledge and the restart delay, the new firmware runs.
    /// Returns the board and version to show once the device restarts.
    pub fn poll(&mut self, now: Duration) -> Option<(Board, Version)> {
        match self.state {
            State::Done { restart_at, .. } if now >= restart_at => {
                self.state = State::Idle;
                self.pending.take()
            }
            _ => None,
        }
    }

    /// An FoE request. `file_type` and `auth_code` are the values of 0x8000:15 and 0x8000:16.
    pub fn handle(
        &mut self,
        payload: &[u8],
        cx: &MailboxContext,
        file_type: u8,
        auth_code: &[u8],
    ) -> MailboxReply {
        if self.stalled {
            return MailboxReply::Silent;
        }
        let reply = match Packet::decode(payload) {
            Err(e) => error(ErrorCode::ILLEGAL, &e.to_string()),
            Ok(Packet::WriteRequest { name, .. }) => {
                self.write_request(name, cx, file_type, auth_code)
            }
            Ok(Packet::Data { packet, data }) => self.data(packet, data, cx),
            Ok(Packet::Error { code, text }) => {
                tracing::info!(%code, text = %packet::text(text), "FoE transfer aborted by the master");
                if !matches!(self.state, State::Done { .. }) {
                    self.state = State::Idle;
                }
                return MailboxReply::Silent;
            }
            Ok(Packet::ReadRequest { .. }) => {
                error(ErrorCode::NOT_FOUND, "the Revo2 has no file to read")
            }
            Ok(other) => error(
                ErrorCode::ILLEGAL,
                &format!("FoE OpCode {} is not a request", other.opcode()),
            ),
        };
        if let MailboxReply::Reply(bytes) = &reply {
            if bytes.first() == Some(&packet::opcode::ERR) {
                self.refusals += 1;
                if !matches!(self.state, State::Done { .. }) {
                    self.state = State::Idle;
                }
            }
        }
        reply
    }

    fn write_request(
        &mut self,
        name: &[u8],
        cx: &MailboxContext,
        file_type: u8,
        auth_code: &[u8],
    ) -> MailboxReply {
        if cx.state != AlState::Boot {
            return error(ErrorCode::BOOTSTRAP_ONLY, "firmware is only taken in BOOT");
        }
        if matches!(self.state, State::Writing { .. } | State::Done { .. }) {
            return error(ErrorCode::ILLEGAL, "a firmware is being written");
        }
        let Some(board) = Board::from_foe_file_type(file_type) else {
            return error(
                ErrorCode::ACCESS_DENIED,
                "upgrade type (0x8000:15) not written: 1 = wrist board, 2 = control board",
            );
        };
        if auth_code != board.auth_code().as_bytes() {
            return error(
                ErrorCode::NO_RIGHTS,
                &format!("authentication code (0x8000:16) is not the {}'s", board),
            );
        }
        let name = packet::text(name);
        if let Err(e) = check_file_name(&name, board) {
            return error(ErrorCode::NOT_IN_BOOTSTRAP, &e.to_string());
        }
        let Some(max_data) = cx.request_size.checked_sub(OVERHEAD).filter(|&n| n > 0) else {
            return error(ErrorCode::ILLEGAL, "mailbox too small");
        };
        tracing::info!(%board, %name, "FoE write request");
        self.state = State::Receiving {
            board,
            name,
            next: 1,
            max_data,
            file: Vec::new(),
        };
        ack(0)
    }

    fn data(&mut self, packet: u32, data: &[u8], cx: &MailboxContext) -> MailboxReply {
        let now = cx.now;
        match &mut self.state {
            State::Idle => error(ErrorCode::ILLEGAL, "data without a write request"),
            State::Receiving {
                board,
                name,
                next,
                max_data,
                file,
            } => {
                if packet.wrapping_add(1) == *next {
                    // Our acknowledge was lost: the master sent it again.
                    return ack(packet);
                }
                if packet != *next {
                    return error(
                        ErrorCode::PACKET_NUMBER,
                        &format!("expected packet {next}, got {packet}"),
                    );
                }
                if let Some(n) = self.stall_after {
                    if packet > n {
                        tracing::warn!(packet, "fault: the boot loader stops answering");
                        self.stall_after = None;
                        self.stalled = true;
                        return MailboxReply::Silent;
                    }
                }
                self.data_packets += 1;
                if data.len() > *max_data {
                    return error(ErrorCode::ILLEGAL, "data packet longer than the mailbox");
                }
                if file.len() + data.len() > FLASH_SIZE {
                    return error(
                        ErrorCode::DISK_FULL,
                        &format!("the flash takes at most {FLASH_SIZE} bytes"),
                    );
                }
                file.extend_from_slice(data);
                *next += 1;
                if data.len() == *max_data {
                    return ack(packet);
                }
                // The short packet: the file is complete.
                let (board, name, file) = (*board, std::mem::take(name), std::mem::take(file));
                let header = match check_image(&file, board) {
                    Ok(h) => h,
                    Err(reply) => return reply,
                };
                let until = now + self.timing.write_time(file.len());
                tracing::info!(%board, version = ?header.version, bytes = file.len(), "erasing and writing flash");
                self.state = State::Writing {
                    image: Flashed {
                        board,
                        version: header.version,
                        name,
                        file,
                    },
                    last: packet,
                    started: now,
                    until,
                };
                self.writing(now)
            }
            State::Writing { last, .. } if packet == *last => self.writing(now),
            State::Done { last, .. } if packet == *last => ack(packet),
            State::Writing { .. } | State::Done { .. } => {
                error(ErrorCode::ILLEGAL, "a firmware is being written")
            }
        }
    }

    /// The answer to the last packet while the flash is written: BUSY, then (once the write
    /// time is over) the flash holds the new firmware and the packet is acknowledged.
    fn writing(&mut self, now: Duration) -> MailboxReply {
        let State::Writing {
            image,
            last,
            started,
            until,
        } = &self.state
        else {
            return error(ErrorCode::PROGRAM_ERROR, "not writing");
        };
        if now >= *until {
            let last = *last;
            tracing::info!(board = %image.board, version = ?image.version, "firmware written; restarting");
            self.pending = Some((image.board, image.version));
            self.flash.push(image.clone());
            self.state = State::Done {
                last,
                restart_at: now + self.timing.restart_delay,
            };
            return ack(last);
        }
        self.busy_answers += 1;
        let total = until.saturating_sub(*started).as_secs_f64().max(1e-6);
        let done = (now.saturating_sub(*started).as_secs_f64() / total * 100.0).min(99.0) as u16;
        let text: &[u8] = if now < *started + self.timing.erase {
            b"erasing flash"
        } else {
            b"writing flash"
        };
        MailboxReply::Reply(
            Packet::Busy {
                done,
                entire: 100,
                text,
            }
            .to_vec(),
        )
    }
}

/// The device's check of a received file (section 6.5): header present, magic number of the
/// upgrade type's board, reserved fields zero.
fn check_image(file: &[u8], board: Board) -> Result<FirmwareHeader, MailboxReply> {
    let invalid = |text: String| error(ErrorCode::INVALID_FIRMWARE, &text);
    match FirmwareHeader::parse(file) {
        Ok(h) if h.board == board => Ok(h),
        Ok(h) => Err(invalid(format!(
            "magic number {} is the {}'s, the upgrade type is the {}",
            String::from_utf8_lossy(h.board.magic()),
            h.board,
            board
        ))),
        Err(FirmwareError::UnknownMagic(m)) => Err(invalid(format!(
            "magic number {:?} is not the {}'s {}",
            String::from_utf8_lossy(&m),
            board,
            String::from_utf8_lossy(board.magic())
        ))),
        Err(e) => Err(invalid(e.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cx(ms: u64) -> MailboxContext {
        MailboxContext {
            state: AlState::Boot,
            now: Duration::from_millis(ms),
            request_size: 44,
            reply_capacity: 250,
        }
    }

    fn reply(r: MailboxReply) -> Vec<u8> {
        match r {
            MailboxReply::Reply(b) => b,
            other => panic!("{other:?}"),
        }
    }

    fn decode(r: MailboxReply) -> (u8, u32) {
        let b = reply(r);
        let p = Packet::decode(&b).expect("FoE");
        match p {
            Packet::Ack { packet } => (4, packet),
            Packet::Error { code, .. } => (5, code.0),
            Packet::Busy { done, .. } => (6, u32::from(done)),
            other => panic!("{other:?}"),
        }
    }

    fn wrq(name: &str) -> Vec<u8> {
        Packet::WriteRequest {
            password: 0,
            name: name.as_bytes(),
        }
        .to_vec()
    }

    fn data(n: u32, d: &[u8]) -> Vec<u8> {
        Packet::Data { packet: n, data: d }.to_vec()
    }

    const WRIST: &str = "Revo2EC_1.2.3_2506231346.bin";

    #[test]
    fn a_whole_upgrade() {
        let mut u = Upgrade::default();
        let auth = b"BRCW2025";
        assert_eq!(decode(u.handle(&wrq(WRIST), &cx(0), 1, auth)), (4, 0));
        let mut file = FirmwareHeader::new(Board::Wrist, (1, 2, 3))
            .to_bytes()
            .to_vec();
        file.extend_from_slice(&[0xAB; 40]);
        // 32 bytes per packet: 32 + 24.
        assert_eq!(
            decode(u.handle(&data(1, &file[..32]), &cx(1), 1, auth)),
            (4, 1)
        );
        assert_eq!(
            decode(u.handle(&data(1, &file[..32]), &cx(2), 1, auth)),
            (4, 1)
        );
        assert!(u.busy());
        assert_eq!(
            decode(u.handle(&data(2, &file[32..]), &cx(3), 1, auth)).0,
            6
        );
        assert_eq!(
            decode(u.handle(&data(2, &file[32..]), &cx(80), 1, auth)),
            (6, 48)
        );
        assert_eq!(u.poll(Duration::from_millis(100)), None);
        assert_eq!(
            decode(u.handle(&data(2, &file[32..]), &cx(163), 1, auth)),
            (4, 2)
        );
        assert_eq!(u.flashed(Board::Wrist).map(|f| &f.file), Some(&file));
        assert_eq!(u.poll(Duration::from_millis(170)), None);
        assert_eq!(
            u.poll(Duration::from_millis(193)),
            Some((Board::Wrist, (1, 2, 3)))
        );
        assert_eq!(u.busy_answers, 2);
    }

    #[test]
    fn refusals() {
        let mut u = Upgrade::default();
        let w = b"BRCW2025";
        let code = |r| decode(r).1;
        let outside = MailboxContext {
            state: AlState::PreOp,
            ..cx(0)
        };
        assert_eq!(code(u.handle(&wrq(WRIST), &outside, 1, w)), 0x8008);
        assert_eq!(code(u.handle(&wrq(WRIST), &cx(0), 0, w)), 0x8002);
        assert_eq!(code(u.handle(&wrq(WRIST), &cx(0), 1, b"BRCC2025")), 0x800A);
        assert_eq!(
            code(u.handle(&wrq("revo2EC_1.2.3_2506231346.bin"), &cx(0), 1, w)),
            0x8009
        );
        assert_eq!(
            code(u.handle(&wrq("Revo2_V1.2.3_2506231346.bin"), &cx(0), 1, w)),
            0x8009
        );
        assert_eq!(code(u.handle(&data(1, &[]), &cx(0), 1, w)), 0x8004);
        // Wrong packet number.
        u.handle(&wrq(WRIST), &cx(0), 1, w);
        assert_eq!(code(u.handle(&data(2, &[0; 32]), &cx(0), 1, w)), 0x8005);
        // The other board's magic, a short file.
        for file in [
            FirmwareHeader::new(Board::Control, (1, 2, 3))
                .to_bytes()
                .to_vec(),
            vec![b'B'; 10],
            b"XXXXXXXX\x03\x02\x01\x00\0\0\0\0".to_vec(),
        ] {
            u.handle(&wrq(WRIST), &cx(0), 1, w);
            assert_eq!(code(u.handle(&data(1, &file), &cx(0), 1, w)), 0x800D);
        }
        assert_eq!(u.refusals, 10);
        assert!(u.flashed(Board::Wrist).is_none());
        assert!(!u.busy());
    }

    #[test]
    fn a_stalled_loader_answers_again_after_leaving_boot() {
        let mut u = Upgrade {
            stall_after: Some(1),
            ..Upgrade::default()
        };
        let w = b"BRCW2025";
        u.handle(&wrq(WRIST), &cx(0), 1, w);
        assert_eq!(decode(u.handle(&data(1, &[0; 32]), &cx(0), 1, w)), (4, 1));
        assert_eq!(
            u.handle(&data(2, &[0; 32]), &cx(0), 1, w),
            MailboxReply::Silent
        );
        assert_eq!(u.handle(&wrq(WRIST), &cx(0), 1, w), MailboxReply::Silent);
        assert!(u.stalled());
        u.reset();
        assert!(!u.stalled() && !u.busy());
        assert_eq!(decode(u.handle(&wrq(WRIST), &cx(0), 1, w)), (4, 0));
        assert_eq!(decode(u.handle(&data(1, &[0; 32]), &cx(0), 1, w)), (4, 1));
        assert_eq!(decode(u.handle(&data(2, &[0; 32]), &cx(0), 1, w)), (4, 2));
    }
}
