//! Flashing a motor board through its PIC18F bootloader, as a sans-I/O state machine: the
//! caller sends what [`Flasher::poll`] asks for (through the palm's CAN bridge in CAN direct
//! mode), hands every bootloader message it receives to [`Flasher::receive`], and calls `poll`
//! again on each message and when the wait it was given runs out.
//!
//! The sequence is the shipped flasher's (docs/devices/shadow.md, "Flashing": E `sr_edc.cpp`):
//! MAGIC (100 ms, one retry), ERASE (3 s), then per 32-byte row ADDRESS and four DATA (100 ms each;
//! a DATA without its acknowledgement redoes the row), then a READ of every 8 bytes compared with
//! the image (100 ms, at most 20 tries), then RESET (1 s). Where the shipped flasher retries
//! forever (ERASE, ADDRESS, RESET), this one gives up after [`Settings::tries`] and says which
//! step, address and reply; the board stays in its bootloader and can be flashed again.

use crate::can::{BootCommand, BootMessage, EraseLength};
use crate::hex::Image;

/// How the flasher talks to a board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Settings {
    /// How ERASE is sent.
    pub erase: EraseLength,
    /// Tries of one step before giving up (MAGIC always has two, as the shipped flasher).
    pub tries: u32,
    /// Wait for an acknowledgement, ms (ERASE and RESET wait longer: 3000 and 1000 ms).
    pub timeout_ms: u64,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            erase: EraseLength::Shipped,
            tries: 20,
            timeout_ms: 100,
        }
    }
}

/// A step of the sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// MAGIC: restart into the bootloader.
    Magic,
    /// ERASE the application area.
    Erase,
    /// ADDRESS of a row.
    Address(u32),
    /// The k-th DATA (0..3) of the row at this address.
    Data(u32, u8),
    /// READ back 8 bytes at this address.
    Verify(u32),
    /// RESET into the new application.
    Reset,
}

impl std::fmt::Display for Step {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Step::Magic => write!(f, "MAGIC"),
            Step::Erase => write!(f, "ERASE"),
            Step::Address(a) => write!(f, "ADDRESS {a:#06x}"),
            Step::Data(a, k) => write!(f, "DATA {}/4 of the row at {a:#06x}", k + 1),
            Step::Verify(a) => write!(f, "READ-back at {a:#06x}"),
            Step::Reset => write!(f, "RESET"),
        }
    }
}

/// Why flashing stopped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FlashError {
    /// A step was not acknowledged.
    #[error("board {board}: no acknowledgement of {step} after {tries} tries{}", last.map_or(String::new(), |m| format!(" (last message from the board: {:03X}#{})", m.id, hex(m.payload()))))]
    NoAnswer {
        /// The board.
        board: u8,
        /// The step.
        step: Step,
        /// Tries made.
        tries: u32,
        /// The last bootloader message that came back (not an acknowledgement), if any.
        last: Option<BootMessage>,
    },
    /// The read-back differs from the image.
    #[error(
        "board {board}: read-back at {address:#06x} is {} where the image has {}",
        hex(got),
        hex(expected)
    )]
    Mismatch {
        /// The board.
        board: u8,
        /// The address.
        address: u32,
        /// The image's bytes.
        expected: [u8; 8],
        /// What the board returned.
        got: [u8; 8],
    },
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect()
}

/// What to do now.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Poll {
    /// Send this message, then wait for an answer until `until_ms`.
    Send(BootMessage),
    /// Nothing to send: poll again on a message or at `until_ms`.
    Wait(u64),
    /// The board runs the new image.
    Done,
    /// Flashing failed.
    Failed(FlashError),
}

/// The flasher of one board.
#[derive(Debug, Clone)]
pub struct Flasher {
    board: u8,
    image: Image,
    settings: Settings,
    step: Step,
    /// The message in flight and when it was sent.
    pending: Option<(BootMessage, u64)>,
    tries: u32,
    last_other: Option<BootMessage>,
    last_read: Option<[u8; 8]>,
    result: Option<Result<(), FlashError>>,
    rows_written: usize,
}

impl Flasher {
    /// Flashes `image` into `board` (0..9, its id on its bus).
    pub fn new(board: u8, image: Image, settings: Settings) -> Self {
        Self {
            board,
            image,
            settings,
            step: Step::Magic,
            pending: None,
            tries: 0,
            last_other: None,
            last_read: None,
            result: None,
            rows_written: 0,
        }
    }

    /// The step under way.
    pub fn step(&self) -> Step {
        self.step
    }

    /// (rows written, rows) for a progress bar; verifying counts as done.
    pub fn progress(&self) -> (usize, usize) {
        (self.rows_written, self.image.rows.len())
    }

    fn timeout(&self) -> u64 {
        match self.step {
            Step::Erase => 3000,
            Step::Reset => 1000,
            _ => self.settings.timeout_ms,
        }
    }

    fn max_tries(&self) -> u32 {
        match self.step {
            Step::Magic => 2,
            _ => self.settings.tries.max(1),
        }
    }

    fn message(&self) -> BootMessage {
        let b = self.board;
        match self.step {
            Step::Magic => BootMessage::magic(b),
            Step::Erase => BootMessage::erase(b, self.settings.erase),
            Step::Address(a) => BootMessage::address(b, a),
            Step::Data(a, k) => {
                let mut bytes = [0xFF; 8];
                bytes.copy_from_slice(&self.image.bytes_at(a + 8 * u32::from(k)));
                BootMessage::write(b, bytes)
            }
            Step::Verify(a) => BootMessage::read(b, a),
            Step::Reset => BootMessage::reset(b),
        }
    }

    /// What to do at `now_ms` (any monotonic millisecond clock).
    pub fn poll(&mut self, now_ms: u64) -> Poll {
        if let Some(result) = &self.result {
            return match result {
                Ok(()) => Poll::Done,
                Err(e) => Poll::Failed(e.clone()),
            };
        }
        if let Some((_, sent)) = self.pending {
            let until = sent + self.timeout();
            if now_ms < until {
                return Poll::Wait(until);
            }
            // No acknowledgement in time.
            if self.tries >= self.max_tries() {
                let e = match (self.step, self.last_read) {
                    (Step::Verify(address), Some(got)) => FlashError::Mismatch {
                        board: self.board,
                        address,
                        expected: self.image.bytes_at(address),
                        got,
                    },
                    _ => FlashError::NoAnswer {
                        board: self.board,
                        step: self.step,
                        tries: self.tries,
                        last: self.last_other,
                    },
                };
                self.result = Some(Err(e.clone()));
                return Poll::Failed(e);
            }
            // A DATA without its acknowledgement redoes the row from its ADDRESS.
            if let Step::Data(a, _) = self.step {
                self.step = Step::Address(a);
            }
        }
        let msg = self.message();
        self.tries += 1;
        self.pending = Some((msg, now_ms));
        Poll::Send(msg)
    }

    /// A bootloader message from the bus (anything: others are ignored).
    pub fn receive(&mut self, reply: &BootMessage) {
        let Some((sent, _)) = self.pending else {
            return;
        };
        let ok = match self.step {
            Step::Verify(address) => {
                let expected = self.image.bytes_at(address);
                if sent.read_reply_matches(reply, &expected) {
                    true
                } else {
                    if reply.id & 0x7FF == (sent.id | crate::can::ACK) & 0x7FF && reply.len == 8 {
                        // A read-back that differs: try again (up to the limit).
                        self.last_read = Some(reply.data);
                        self.pending = Some((sent, 0));
                    }
                    false
                }
            }
            _ => sent.acknowledged_by(reply),
        };
        if !ok {
            if BootCommand::from_bits((reply.id & 0xF) as u8).is_some() {
                self.last_other = Some(*reply);
            }
            return;
        }
        self.pending = None;
        self.tries = 0;
        self.last_other = None;
        self.last_read = None;
        let rows = &self.image.rows;
        let first_row = rows.first().map(|r| r.address).unwrap_or_default();
        self.step = match self.step {
            Step::Magic => Step::Erase,
            Step::Erase => Step::Address(first_row),
            Step::Address(a) => Step::Data(a, 0),
            Step::Data(a, k) if k < 3 => Step::Data(a, k + 1),
            Step::Data(a, _) => {
                self.rows_written += 1;
                match rows
                    .iter()
                    .position(|r| r.address == a)
                    .and_then(|i| rows.get(i + 1))
                {
                    Some(next) => Step::Address(next.address),
                    None => Step::Verify(first_row),
                }
            }
            Step::Verify(a) => {
                let next = a + 8;
                if rows
                    .iter()
                    .any(|r| (r.address..r.address + 32).contains(&next))
                {
                    Step::Verify(next)
                } else if let Some(r) = rows.iter().find(|r| r.address > a) {
                    Step::Verify(r.address)
                } else {
                    Step::Reset
                }
            }
            Step::Reset => {
                self.result = Some(Ok(()));
                Step::Reset
            }
        };
    }
}
