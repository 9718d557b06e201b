//! The CAN side: the 11-bit SID of motor and bootloader messages, and the PIC18F bootloader's
//! commands (document, "CAN SID bit mapping" and "CAN bootloader commands";
//! docs/devices/shadow.md, "CAN SIDs and the PIC18F bootloader").
//!
//! SID: bits 10-9 direction, 8-5 the motor's id on its bus (0..9), 4 ACK (bootloader replies), 3-0
//! the data type or bootloader command. Motors 0-9 are on bus 1, 10-19 on bus 2 as id n - 10.
//!
//! Direction bits. The document: `10` to the PIC18F, `01` from it, `11` bootloader, `00`
//! reserved. The shipped driver and firmware (E): 0 data request (start of frame), 1 to the motor,
//! 2 from the motor, 3 bootloader: the two swap "to" and "from". [`SidDirections`] chooses;
//! bootloader messages (3) are the same in both, so flashing works either way.

use crate::DecodeError;

/// What a message is, by its direction bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// The palm's start-of-frame data request (shipped only; reserved in the document).
    DataRequest,
    /// Host (palm) to motor.
    ToMotor,
    /// Motor to host (palm).
    FromMotor,
    /// Bootloader protocol.
    Bootloader,
}

/// How direction bits are read: the shipped code's, or the document's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SidDirections {
    /// E: 0 data request, 1 to motor, 2 from motor, 3 bootloader.
    #[default]
    Shipped,
    /// The document: 2 (`10`) to the PIC18F, 1 (`01`) from it, 3 bootloader, 0 reserved.
    Document,
}

impl SidDirections {
    /// The two direction bits of `d` (`None`: the document reserves 0, so it has no data request).
    pub fn bits(self, d: Direction) -> Option<u16> {
        Some(match (self, d) {
            (_, Direction::Bootloader) => 3,
            (SidDirections::Shipped, Direction::DataRequest) => 0,
            (SidDirections::Document, Direction::DataRequest) => return None,
            (SidDirections::Shipped, Direction::ToMotor) => 1,
            (SidDirections::Shipped, Direction::FromMotor) => 2,
            (SidDirections::Document, Direction::ToMotor) => 2,
            (SidDirections::Document, Direction::FromMotor) => 1,
        })
    }

    /// The direction of two bits (`None`: reserved).
    pub fn direction(self, bits: u16) -> Option<Direction> {
        [
            Direction::DataRequest,
            Direction::ToMotor,
            Direction::FromMotor,
            Direction::Bootloader,
        ]
        .into_iter()
        .find(|d| self.bits(*d) == Some(bits & 3))
    }
}

/// A decoded SID.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Sid {
    /// Direction.
    pub direction: Direction,
    /// The motor's id on its bus, 0..9.
    pub motor: u8,
    /// The ACK bit (bootloader replies).
    pub ack: bool,
    /// Data type or bootloader command, 0..15.
    pub kind: u8,
}

/// The largest motor id on one bus.
pub const MAX_MOTOR_ON_BUS: u8 = 9;
/// The ACK bit.
pub const ACK: u16 = 0x10;

impl Sid {
    /// The 11-bit id (`None`: a direction `directions` cannot say, or a motor id above 9).
    pub fn encode(&self, directions: SidDirections) -> Option<u16> {
        if self.motor > MAX_MOTOR_ON_BUS {
            return None;
        }
        let dir = directions.bits(self.direction)?;
        Some(
            dir << 9
                | u16::from(self.motor) << 5
                | if self.ack { ACK } else { 0 }
                | u16::from(self.kind & 0xF),
        )
    }

    /// The SID's fields (any 16-bit value: bits above 10 are refused).
    pub fn decode(id: u16, directions: SidDirections) -> Result<Sid, DecodeError> {
        if id > 0x7FF {
            return Err(DecodeError::Unknown {
                what: "11-bit SID",
                value: u32::from(id),
            });
        }
        let direction = directions.direction(id >> 9).ok_or(DecodeError::Unknown {
            what: "SID direction bits",
            value: u32::from(id >> 9),
        })?;
        let motor = ((id >> 5) & 0xF) as u8;
        if motor > MAX_MOTOR_ON_BUS {
            return Err(DecodeError::Unknown {
                what: "SID motor id",
                value: u32::from(motor),
            });
        }
        Ok(Sid {
            direction,
            motor,
            ack: id & ACK != 0,
            kind: (id & 0xF) as u8,
        })
    }
}

/// The CAN bus (1 or 2) and id on it of motor 0..19.
pub fn bus_of_motor(motor: u8) -> Option<(u8, u8)> {
    match motor {
        0..=9 => Some((1, motor)),
        10..=19 => Some((2, motor - 10)),
        _ => None,
    }
}

/// The bootloader's commands (the SID's low four bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum BootCommand {
    /// 8 bytes into the row buffer; the 4th programs the 32-byte row.
    WriteData = 0x0,
    /// Read 8 bytes at a 3-byte address.
    Read = 0x1,
    /// Erase 0x04C0..0x7DBF.
    Erase = 0x2,
    /// Mark the application valid (EEPROM[0xFF] = 0x42) and restart into it.
    Reset = 0x3,
    /// Answered with 40 41 42 43.
    Version = 0x4,
    /// Set the write pointer to a 3-byte address (little-endian).
    Address = 0x5,
    /// 55 AA 55 AA 55 AA 55 AA: restart into the bootloader.
    Magic = 0xA,
}

impl BootCommand {
    /// The command with these four bits.
    pub fn from_bits(bits: u8) -> Option<Self> {
        use BootCommand::*;
        [WriteData, Read, Erase, Reset, Version, Address, Magic]
            .into_iter()
            .find(|c| *c as u8 == bits & 0xF)
    }
}

/// The MAGIC packet's data (and the bootloader's boot-time acknowledgement).
pub const MAGIC: [u8; 8] = [0x55, 0xAA, 0x55, 0xAA, 0x55, 0xAA, 0x55, 0xAA];
/// The VERSION reply's data.
pub const BOOT_VERSION: [u8; 4] = [0x40, 0x41, 0x42, 0x43];
/// The first address the bootloader lets an application use.
pub const APP_START: u32 = 0x04C0;
/// The first address past the erased range (0x7DC0 onwards is never erased).
pub const APP_END: u32 = 0x7DC0;
/// Bytes the bootloader programs at a time.
pub const ROW: usize = 32;

/// How ERASE is sent: the document gives length 0; the shipped flasher sends length 1 (its byte
/// 0 left over from MAGIC: 0x55), which the bootloader echoes (E). Both erase.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum EraseLength {
    /// E: one byte, 0x55.
    #[default]
    Shipped,
    /// The document: no data.
    Document,
}

/// One bootloader message on a bus: SID, length and data (`len` bytes of `data` are sent).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct BootMessage {
    /// The SID.
    pub id: u16,
    /// Data length, 0..8.
    pub len: u8,
    /// Data (bytes past `len` are 0).
    pub data: [u8; 8],
}

impl BootMessage {
    /// The message `command` to `board` (0..9 on its bus) with `data` (at most 8 bytes used).
    pub fn new(board: u8, command: BootCommand, data: &[u8]) -> Self {
        let len = data.len().min(8);
        let mut d = [0u8; 8];
        d[..len].copy_from_slice(&data[..len]);
        Self {
            id: 0x600 | u16::from(board & 0xF) << 5 | command as u16,
            len: len as u8,
            data: d,
        }
    }

    /// MAGIC.
    pub fn magic(board: u8) -> Self {
        Self::new(board, BootCommand::Magic, &MAGIC)
    }

    /// ERASE as `how` sends it.
    pub fn erase(board: u8, how: EraseLength) -> Self {
        match how {
            EraseLength::Shipped => Self::new(board, BootCommand::Erase, &[0x55]),
            EraseLength::Document => Self::new(board, BootCommand::Erase, &[]),
        }
    }

    /// ADDRESS: the write pointer (3 bytes, little-endian).
    pub fn address(board: u8, address: u32) -> Self {
        Self::new(board, BootCommand::Address, &address.to_le_bytes()[..3])
    }

    /// DATA: 8 bytes for the row buffer.
    pub fn write(board: u8, bytes: [u8; 8]) -> Self {
        Self::new(board, BootCommand::WriteData, &bytes)
    }

    /// READ: 8 bytes at `address`.
    pub fn read(board: u8, address: u32) -> Self {
        Self::new(board, BootCommand::Read, &address.to_le_bytes()[..3])
    }

    /// VERSION.
    pub fn version(board: u8) -> Self {
        Self::new(board, BootCommand::Version, &[])
    }

    /// RESET.
    pub fn reset(board: u8) -> Self {
        Self::new(board, BootCommand::Reset, &[])
    }

    /// The data bytes.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(8))]
    }

    /// The usual acknowledgement a bootloader sends: same SID with the ACK bit, same length,
    /// same data (READ and VERSION answer with data instead: [`BootMessage::reply`]).
    pub fn echo(&self) -> Self {
        Self {
            id: self.id | ACK,
            ..*self
        }
    }

    /// A reply with the ACK bit and `data`.
    pub fn reply(&self, data: &[u8]) -> Self {
        let mut r = Self::new(((self.id >> 5) & 0xF) as u8, self.command_bits(), data);
        r.id |= ACK;
        r
    }

    fn command_bits(&self) -> BootCommand {
        BootCommand::from_bits((self.id & 0xF) as u8).unwrap_or(BootCommand::Magic)
    }

    /// Whether `reply` acknowledges this message as the shipped flasher checks (E): same
    /// length and data, the ACK bit, and `id & 0x1EF` equal (the direction bits ignored, so the
    /// boot-time MAGIC acknowledgement matches a MAGIC). READ is acknowledged by its 8-byte
    /// reply ([`BootMessage::read_reply_matches`]).
    pub fn acknowledged_by(&self, reply: &BootMessage) -> bool {
        reply.id & ACK != 0
            && reply.id & 0x1EF == self.id & 0x1EF
            && reply.len == self.len
            && reply.payload() == self.payload()
    }

    /// Whether `reply` answers this READ with `expected` (E: `id & 0x7FF == 0x600 | board << 5 |
    /// 0x11` and the 8 bytes equal).
    pub fn read_reply_matches(&self, reply: &BootMessage, expected: &[u8; 8]) -> bool {
        reply.id & 0x7FF == (self.id | ACK) & 0x7FF && reply.len == 8 && reply.data == *expected
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use proptest::prelude::*;

    #[test]
    fn bootloader_sids_as_the_document_builds_them() {
        // 0x600 | (motor_id << 5) | command.
        assert_eq!(BootMessage::magic(3).id, 0x600 | 3 << 5 | 0xA);
        assert_eq!(BootMessage::magic(3).payload(), &MAGIC);
        assert_eq!(
            BootMessage::erase(0, EraseLength::Document).payload(),
            &[] as &[u8]
        );
        assert_eq!(
            BootMessage::erase(0, EraseLength::Shipped).payload(),
            &[0x55]
        );
        let a = BootMessage::address(9, 0x0004C0);
        assert_eq!((a.id, a.payload()), (0x725, &[0xC0, 0x04, 0x00][..]));
        let r = BootMessage::read(1, 0x7D40);
        assert_eq!((r.id, r.payload()), (0x621, &[0x40, 0x7D, 0x00][..]));
        assert_eq!(BootMessage::reset(0).id, 0x603);
        assert_eq!(BootMessage::version(0).id, 0x604);
    }

    #[test]
    fn acknowledgements() {
        let m = BootMessage::write(2, [1, 2, 3, 4, 5, 6, 7, 8]);
        assert!(m.acknowledged_by(&m.echo()));
        assert!(!m.acknowledged_by(&m));
        let mut wrong = m.echo();
        wrong.data[0] = 9;
        assert!(!m.acknowledged_by(&wrong));
        // The boot-time MAGIC ack (0x600 | id << 5 | 0x1A, 55 AA x4) matches a MAGIC.
        let boot_ack = BootMessage {
            id: 0x600 | 2 << 5 | 0x1A,
            len: 8,
            data: MAGIC,
        };
        assert!(BootMessage::magic(2).acknowledged_by(&boot_ack));
        let read = BootMessage::read(2, 0x500);
        let reply = read.reply(&[0xFF; 8]);
        assert_eq!(reply.id, 0x651);
        assert!(read.read_reply_matches(&reply, &[0xFF; 8]));
        assert!(!read.read_reply_matches(&reply, &[0; 8]));
        assert_eq!(
            BootMessage::version(0).reply(&BOOT_VERSION).payload(),
            &BOOT_VERSION
        );
    }

    #[test]
    fn the_two_readings_of_the_direction_bits() {
        let to = Sid {
            direction: Direction::ToMotor,
            motor: 4,
            ack: false,
            kind: 1,
        };
        assert_eq!(to.encode(SidDirections::Shipped), Some(0x200 | 4 << 5 | 1));
        assert_eq!(to.encode(SidDirections::Document), Some(0x400 | 4 << 5 | 1));
        // The same wire id means the opposite direction to the other reading.
        let id = to.encode(SidDirections::Shipped).unwrap();
        assert_eq!(
            Sid::decode(id, SidDirections::Document).unwrap().direction,
            Direction::FromMotor
        );
        // Data requests are reserved in the document.
        assert!(Sid::decode(0x020, SidDirections::Document).is_err());
        assert_eq!(
            Sid::decode(0x020, SidDirections::Shipped)
                .unwrap()
                .direction,
            Direction::DataRequest
        );
        assert!(
            Sid::decode(0x1A0, SidDirections::Shipped).is_err(),
            "motor 13"
        );
        assert_eq!(bus_of_motor(13), Some((2, 3)));
        assert_eq!(bus_of_motor(20), None);
    }

    proptest! {
        #[test]
        fn sids_round_trip_and_never_panic(id in any::<u16>(), doc in any::<bool>()) {
            let dirs = if doc { SidDirections::Document } else { SidDirections::Shipped };
            if let Ok(sid) = Sid::decode(id, dirs) {
                prop_assert_eq!(sid.encode(dirs), Some(id));
            }
        }
    }
}
