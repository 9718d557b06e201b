//! A motor board's PIC18F2580 with the document's CAN bootloader (E11 `boot.c`, the document's
//! "CAN bootloader commands"): 32 KiB of flash (the bootloader below 0x04C0), 256 bytes of
//! EEPROM, and the commands MAGIC, ERASE, ADDRESS, DATA (32-byte rows), READ, VERSION and RESET
//! on SIDs `0x600 | id << 5 | command`, answered with the ACK bit (0x10) set.
//!
//! Behaviour as the bootloader has it:
//! - at start: EEPROM[0x00] is the board's id on its bus; EEPROM[0xFF] other than 0xFF means a
//!   valid application: run it; else stay and send the unsolicited MAGIC acknowledgement
//!   (`0x600 | id << 5 | 0x1A`, 55 AA x 4);
//! - DATA buffers 8 bytes; the fourth programs the 32-byte row at the pointer's row. Flash
//!   programming only clears bits (a row not erased keeps its zeros), as on the chip;
//! - ERASE erases 0x04C0..0x7DBF and takes time ([`Board::erase_ms`]); its echo comes after;
//! - RESET writes EEPROM[0xFF] = 0x42 and starts the application;
//! - the application (not emulated beyond this) answers MAGIC by writing EEPROM[0xFF] = 0xFF
//!   and restarting into the bootloader (the document), and ignores the other commands.
//!
//! Faults for the flasher's tests: a board that answers nothing ([`Board::silent`]) and one that
//! stops answering after a number of messages ([`Board::stop_after`]).

use teleop_shadow_protocol::can::{
    BootCommand, BootMessage, ACK, APP_END, APP_START, BOOT_VERSION, MAGIC, ROW,
};

/// Flash size, bytes.
pub const FLASH: usize = 0x8000;

/// What the board is running.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// The bootloader.
    Bootloader,
    /// The application at 0x04C0.
    Application,
}

/// One motor board.
#[derive(Debug, Clone)]
pub struct Board {
    flash: Vec<u8>,
    eeprom: [u8; 256],
    mode: Mode,
    pointer: u32,
    buffer: [u8; ROW],
    position: usize,
    /// Milliseconds an ERASE takes before its echo.
    pub erase_ms: u64,
    /// Answer nothing at all.
    pub silent: bool,
    /// Stop answering after this many more messages addressed to the board.
    pub stop_after: Option<u64>,
    /// Replies not yet due: (due time ms, message).
    outbox: Vec<(u64, BootMessage)>,
    /// Rows programmed since start.
    pub rows_programmed: u64,
}

impl Board {
    /// A board with id `id` on its bus, running `application` (bytes from 0x04C0; empty: no
    /// valid application, so it starts in its bootloader).
    pub fn new(id: u8, application: &[u8]) -> Self {
        let mut flash = vec![0xFF; FLASH];
        // The bootloader's own code: anything but erased flash.
        for (k, b) in flash[..APP_START as usize].iter_mut().enumerate() {
            *b = (k % 251) as u8;
        }
        let end = (APP_START as usize + application.len()).min(APP_END as usize);
        flash[APP_START as usize..end].copy_from_slice(&application[..end - APP_START as usize]);
        let mut eeprom = [0xFF; 256];
        eeprom[0] = id;
        if !application.is_empty() {
            eeprom[0xFF] = 0x42;
        }
        let mut board = Self {
            flash,
            eeprom,
            mode: Mode::Bootloader,
            pointer: 0,
            buffer: [0xFF; ROW],
            position: 0,
            erase_ms: 40,
            silent: false,
            stop_after: None,
            outbox: Vec::new(),
            rows_programmed: 0,
        };
        board.restart(0);
        board
    }

    /// The board's id on its bus.
    pub fn id(&self) -> u8 {
        self.eeprom[0]
    }

    /// What it runs.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The flash memory.
    pub fn flash(&self) -> &[u8] {
        &self.flash
    }

    /// Restart: the bootloader runs the application when EEPROM[0xFF] says it is valid, else
    /// stays and announces itself.
    fn restart(&mut self, now_ms: u64) {
        self.position = 0;
        if self.eeprom[0xFF] != 0xFF {
            self.mode = Mode::Application;
        } else {
            self.mode = Mode::Bootloader;
            let id = 0x600 | u16::from(self.id() & 0xF) << 5 | ACK | BootCommand::Magic as u16;
            self.send(
                now_ms,
                BootMessage {
                    id,
                    len: 8,
                    data: MAGIC,
                },
            );
        }
    }

    fn send(&mut self, due_ms: u64, msg: BootMessage) {
        if !self.silent {
            self.outbox.push((due_ms, msg));
        }
    }

    /// Messages the board has sent by `now_ms`, in order.
    pub fn take_sent(&mut self, now_ms: u64) -> Vec<BootMessage> {
        let (due, later): (Vec<_>, Vec<_>) = self.outbox.drain(..).partition(|(t, _)| *t <= now_ms);
        self.outbox = later;
        due.into_iter().map(|(_, m)| m).collect()
    }

    /// A message on the bus at `now_ms`.
    pub fn receive(&mut self, msg: &BootMessage, now_ms: u64) {
        // Bootloader SIDs only (direction bits 11), addressed to this board, not an ACK.
        if msg.id & 0x7E0 != 0x600 | u16::from(self.id() & 0xF) << 5 || msg.id & ACK != 0 {
            return;
        }
        if let Some(n) = self.stop_after.as_mut() {
            if *n == 0 {
                return;
            }
            *n -= 1;
        }
        let Some(command) = BootCommand::from_bits((msg.id & 0xF) as u8) else {
            return;
        };
        if self.mode == Mode::Application {
            if command == BootCommand::Magic {
                // The application: mark itself invalid and restart into the bootloader.
                self.eeprom[0xFF] = 0xFF;
                self.restart(now_ms);
            }
            return;
        }
        let address = |m: &BootMessage| {
            u32::from(m.data[0]) | u32::from(m.data[1]) << 8 | u32::from(m.data[2]) << 16
        };
        match command {
            BootCommand::Address => {
                self.pointer = address(msg);
                self.position = 0;
                self.send(now_ms, msg.echo());
            }
            BootCommand::WriteData => {
                self.buffer[self.position..self.position + 8].copy_from_slice(&msg.data);
                self.position += 8;
                if self.position == ROW {
                    self.program_row();
                    self.position = 0;
                }
                self.send(now_ms, msg.echo());
            }
            BootCommand::Read => {
                let a = address(msg) as usize;
                let mut bytes = [0xFF; 8];
                for (k, b) in bytes.iter_mut().enumerate() {
                    *b = self.flash.get(a + k).copied().unwrap_or(0xFF);
                }
                self.send(now_ms, msg.reply(&bytes));
            }
            BootCommand::Erase => {
                self.flash[APP_START as usize..APP_END as usize].fill(0xFF);
                self.send(now_ms + self.erase_ms, msg.echo());
            }
            BootCommand::Reset => {
                self.send(now_ms, msg.echo());
                self.eeprom[0xFF] = 0x42;
                self.restart(now_ms);
            }
            BootCommand::Version => self.send(now_ms, msg.reply(&BOOT_VERSION)),
            BootCommand::Magic => self.restart(now_ms),
        }
    }

    /// Programs the buffered row at the pointer's row: flash bits can only be cleared, and
    /// the bootloader's own rows are not written (the chip's write protection).
    fn program_row(&mut self) {
        let row = (self.pointer as usize) / ROW * ROW;
        if row < APP_START as usize || row + ROW > FLASH {
            return;
        }
        for (cell, b) in self.flash[row..row + ROW].iter_mut().zip(self.buffer) {
            *cell &= b;
        }
        self.rows_programmed += 1;
    }
}

/// A pseudo-random application image of `len` bytes (xorshift from `seed`), to flash in tests
/// and benchmarks: the emulated board reports its first word as its firmware revision.
pub fn generated_application(len: usize, seed: u32) -> Vec<u8> {
    let mut x = seed.wrapping_mul(2_654_435_761).max(1);
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u8
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use teleop_shadow_protocol::can::EraseLength;

    #[test]
    fn a_blank_board_waits_in_its_bootloader_and_says_so() {
        let mut b = Board::new(3, &[]);
        assert_eq!(b.mode(), Mode::Bootloader);
        let sent = b.take_sent(0);
        assert_eq!(sent.len(), 1);
        assert_eq!(sent[0].id, 0x600 | 3 << 5 | 0x1A);
        assert_eq!(sent[0].data, MAGIC);
        b.receive(&BootMessage::version(3), 1);
        assert_eq!(b.take_sent(1)[0].payload(), &BOOT_VERSION);
        // Another board's message is not for it.
        b.receive(&BootMessage::version(4), 2);
        assert!(b.take_sent(2).is_empty());
    }

    #[test]
    fn rows_are_programmed_by_four_data_messages_and_only_clear_bits() {
        let mut b = Board::new(0, &[]);
        b.take_sent(0);
        b.receive(&BootMessage::address(0, 0x0500), 0);
        for k in 0..4u8 {
            b.receive(&BootMessage::write(0, [k; 8]), 0);
        }
        assert_eq!(&b.flash()[0x0500..0x0508], &[0; 8]);
        assert_eq!(&b.flash()[0x0518..0x0520], &[3; 8]);
        // Not erased: programming 0xFF over it changes nothing.
        b.receive(&BootMessage::address(0, 0x0500), 0);
        for _ in 0..4 {
            b.receive(&BootMessage::write(0, [0xFF; 8]), 0);
        }
        assert_eq!(&b.flash()[0x0518..0x0520], &[3; 8]);
        // ERASE answers after its erase time.
        b.take_sent(0);
        b.receive(&BootMessage::erase(0, EraseLength::Shipped), 10);
        assert!(b.take_sent(49).is_empty());
        assert_eq!(b.take_sent(50).len(), 1);
        assert_eq!(&b.flash()[0x0518..0x0520], &[0xFF; 8]);
        // The bootloader's own rows are never written.
        b.receive(&BootMessage::address(0, 0x0400), 60);
        for _ in 0..4 {
            b.receive(&BootMessage::write(0, [0; 8]), 60);
        }
        assert_ne!(&b.flash()[0x0400..0x0408], &[0; 8]);
    }

    #[test]
    fn reset_runs_the_application_and_magic_brings_the_bootloader_back() {
        let mut b = Board::new(1, &[]);
        b.receive(&BootMessage::reset(1), 0);
        assert_eq!(b.mode(), Mode::Application);
        b.take_sent(0);
        b.receive(&BootMessage::version(1), 1);
        assert!(
            b.take_sent(1).is_empty(),
            "the application ignores the bootloader"
        );
        b.receive(&BootMessage::magic(1), 2);
        assert_eq!(b.mode(), Mode::Bootloader);
        assert_eq!(b.take_sent(2)[0].id, 0x600 | 1 << 5 | 0x1A);
    }
}
