//! Process-data layouts: the palm's command and status, the CAN bridge message after each, and
//! where each protocol puts them in the palm's memory (docs/devices/shadow.md, "Layouts" and "Sync
//! managers and FMMUs"; packed, little-endian, enums as u32).
//!
//! Protocol 0220 (the SR06 palm, product code 6) is what shipped Hand E palms speak and is complete
//! here. 0230 (SR08) and 0240 (SR09) are given by their areas only: docs/devices/shadow.md gives
//! their field offsets (0230's tactile and aux data, 0240's IMU command) but no palm of theirs is
//! emulated or driven here. The document's structures ([`DocumentCommand`], [`DocumentStatus`]) are
//! older than any shipped palm; its `TACTILE_SENSOR_OUT` is not defined in the document, so its
//! status is decoded up to the motors.

use crate::{i16_at, need, u16_at, u32_at, DecodeError};

/// Motors on a Hand E.
pub const MOTORS: usize = 20;
/// Joint sensor words in a 0220 status (36 used, the last unused).
pub const SENSORS: usize = 37;
/// Fingertip tactile sensors.
pub const TACTILE: usize = 5;

/// A palm protocol, from its SII product code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Protocol {
    /// SR06, Hand E palm (product code 6).
    P0220,
    /// SR08 right/left with tactile (product codes 0x01000000 / 0x01000001).
    P0230,
    /// SR09 with IMU (product code 9).
    P0240,
}

/// Where a protocol's process data sits in the palm's memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Area {
    /// The command (SM0).
    pub command: u16,
    /// Its length.
    pub command_len: u16,
    /// The CAN bridge command (SM1), [`CanBridge::SIZE`] bytes.
    pub bridge_command: u16,
    /// The status (SM2).
    pub status: u16,
    /// Its length.
    pub status_len: u16,
    /// The CAN bridge status (SM3).
    pub bridge_status: u16,
}

/// Product code of the bridge SubDevice (no process data).
pub const PRODUCT_BRIDGE: u32 = 0;
/// Product code of a development board ("dummy").
pub const PRODUCT_DUMMY: u32 = 5;
/// Product code of the SR06 (Hand E) palm.
pub const PRODUCT_SR06: u32 = 6;

impl Protocol {
    /// The protocol of a palm's product code (R picks the driver by it alone).
    pub fn from_product_code(code: u32) -> Option<Self> {
        match code {
            PRODUCT_SR06 => Some(Protocol::P0220),
            0x0100_0000 | 0x0100_0001 => Some(Protocol::P0230),
            9 => Some(Protocol::P0240),
            _ => None,
        }
    }

    /// Its areas.
    pub fn area(self) -> Area {
        match self {
            Protocol::P0220 => Area {
                command: 0x1000,
                command_len: 58,
                bridge_command: 0x103A,
                status: 0x1046,
                status_len: 220,
                bridge_status: 0x1122,
            },
            Protocol::P0230 => Area {
                command: 0x1000,
                command_len: 62,
                bridge_command: 0x103E,
                status: 0x104A,
                status_len: 416,
                bridge_status: 0x11EA,
            },
            Protocol::P0240 => Area {
                command: 0x1000,
                command_len: 62,
                bridge_command: 0x103E,
                status: 0x104A,
                status_len: 220,
                bridge_status: 0x1126,
            },
        }
    }
}

/// One CAN message through the palm (after the command, and after the status), 12 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct CanBridge {
    /// Bus 1 or 2 (0 in an idle message).
    pub can_bus: u8,
    /// Data length.
    pub length: u8,
    /// SID (0 in an idle message).
    pub id: u16,
    /// Data.
    pub data: [u8; 8],
}

impl CanBridge {
    /// Bytes on the wire.
    pub const SIZE: usize = 12;

    /// The 12 bytes.
    pub fn pack(&self) -> [u8; 12] {
        let mut b = [0u8; 12];
        b[0] = self.can_bus;
        b[1] = self.length;
        b[2..4].copy_from_slice(&self.id.to_le_bytes());
        b[4..12].copy_from_slice(&self.data);
        b
    }

    /// From at least 12 bytes.
    pub fn unpack(b: &[u8]) -> Result<Self, DecodeError> {
        need("CAN bridge message", b, Self::SIZE)?;
        let mut data = [0u8; 8];
        data.copy_from_slice(&b[4..12]);
        Ok(Self {
            can_bus: b[0],
            length: b[1],
            id: u16_at(b, 2),
            data,
        })
    }

    /// Whether it carries a message (an idle bridge has id 0 and length 0).
    pub fn is_idle(&self) -> bool {
        self.id == 0 && self.length == 0
    }
}

/// The 0220 command (58 bytes at 0x1000).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Command {
    /// The EDC command, raw ([`crate::data::EdcCommand::value`]).
    pub edc_command: u32,
    /// What the motors asked this cycle return ([`crate::data::FromMotor`]).
    pub from_motor_data_type: u32,
    /// Which motors are asked: 0 even, 1 odd.
    pub which_motors: i16,
    /// What `motor_data` is ([`crate::data::ToMotor`]).
    pub to_motor_data_type: u32,
    /// One word per motor, by motor number.
    pub motor_data: [i16; MOTORS],
    /// The tactile data type asked for.
    pub tactile_data_type: u32,
}

impl Command {
    /// Bytes on the wire.
    pub const SIZE: usize = 58;

    /// The command that puts the palm in CAN direct mode (the motors' CAN buses bridged), in
    /// `numbering`; every other field zero.
    pub fn can_direct_mode(numbering: crate::data::EdcNumbering) -> Self {
        Self {
            edc_command: crate::data::EdcCommand::CanDirectMode
                .value(numbering)
                .expect("CAN direct mode has a value in every numbering"),
            ..Self::default()
        }
    }

    /// The 58 bytes.
    pub fn pack(&self) -> [u8; 58] {
        let mut b = [0u8; 58];
        b[0..4].copy_from_slice(&self.edc_command.to_le_bytes());
        b[4..8].copy_from_slice(&self.from_motor_data_type.to_le_bytes());
        b[8..10].copy_from_slice(&self.which_motors.to_le_bytes());
        b[10..14].copy_from_slice(&self.to_motor_data_type.to_le_bytes());
        for (i, v) in self.motor_data.iter().enumerate() {
            b[14 + 2 * i..16 + 2 * i].copy_from_slice(&v.to_le_bytes());
        }
        b[54..58].copy_from_slice(&self.tactile_data_type.to_le_bytes());
        b
    }

    /// From at least 58 bytes.
    pub fn unpack(b: &[u8]) -> Result<Self, DecodeError> {
        need("0220 command", b, Self::SIZE)?;
        Ok(Self {
            edc_command: u32_at(b, 0),
            from_motor_data_type: u32_at(b, 4),
            which_motors: i16_at(b, 8),
            to_motor_data_type: u32_at(b, 10),
            motor_data: std::array::from_fn(|i| i16_at(b, 14 + 2 * i)),
            tactile_data_type: u32_at(b, 54),
        })
    }
}

/// One motor's reply in a status: torque and the requested type's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct MotorPacket {
    /// Measured torque (or, for slow data and config readback, which item).
    pub torque: i16,
    /// The value of the status's `motor_data_type`.
    pub misc: u16,
}

/// The 0220 status (220 bytes at 0x1046). The status read in a cycle answers the previous
/// cycle's command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Status {
    /// The EDC command (0: nothing valid; [`crate::data::EDC_BOOTING`] while booting).
    pub edc_command: u32,
    /// 12-bit ADC joint sensors (or channel numbers), [36] unused.
    pub sensors: [u16; SENSORS],
    /// The type of the motor packets.
    pub motor_data_type: u32,
    /// 0: the even motors answered, 1: the odd.
    pub which_motors: i16,
    /// Bit n: motor n's data arrived.
    pub which_motor_data_arrived: u32,
    /// Bit n: motor n's data had errors (or was of the wrong type).
    pub which_motor_data_had_errors: u32,
    /// Replies, slot = motor number / 2.
    pub packets: [MotorPacket; MOTORS / 2],
    /// Tactile data type.
    pub tactile_data_type: u32,
    /// Bit n (0 FF .. 4 TH): fingertip n's data is valid.
    pub tactile_data_valid: u16,
    /// Per fingertip, 8 words of the tactile type.
    pub tactile: [[u16; 8]; TACTILE],
    /// Microseconds since the palm last wrote a status (healthy: over 50).
    pub idle_time_us: u16,
}

impl Default for Status {
    /// All zeros: what an unwritten sync manager reads as.
    fn default() -> Self {
        Self {
            edc_command: 0,
            sensors: [0; SENSORS],
            motor_data_type: 0,
            which_motors: 0,
            which_motor_data_arrived: 0,
            which_motor_data_had_errors: 0,
            packets: [MotorPacket::default(); MOTORS / 2],
            tactile_data_type: 0,
            tactile_data_valid: 0,
            tactile: [[0; 8]; TACTILE],
            idle_time_us: 0,
        }
    }
}

impl Status {
    /// Bytes on the wire.
    pub const SIZE: usize = 220;

    /// The 220 bytes.
    pub fn pack(&self) -> [u8; 220] {
        let mut b = [0u8; 220];
        b[0..4].copy_from_slice(&self.edc_command.to_le_bytes());
        for (i, v) in self.sensors.iter().enumerate() {
            b[4 + 2 * i..6 + 2 * i].copy_from_slice(&v.to_le_bytes());
        }
        b[78..82].copy_from_slice(&self.motor_data_type.to_le_bytes());
        b[82..84].copy_from_slice(&self.which_motors.to_le_bytes());
        b[84..88].copy_from_slice(&self.which_motor_data_arrived.to_le_bytes());
        b[88..92].copy_from_slice(&self.which_motor_data_had_errors.to_le_bytes());
        for (i, p) in self.packets.iter().enumerate() {
            b[92 + 4 * i..94 + 4 * i].copy_from_slice(&p.torque.to_le_bytes());
            b[94 + 4 * i..96 + 4 * i].copy_from_slice(&p.misc.to_le_bytes());
        }
        b[132..136].copy_from_slice(&self.tactile_data_type.to_le_bytes());
        b[136..138].copy_from_slice(&self.tactile_data_valid.to_le_bytes());
        for (f, words) in self.tactile.iter().enumerate() {
            for (k, w) in words.iter().enumerate() {
                let at = 138 + 16 * f + 2 * k;
                b[at..at + 2].copy_from_slice(&w.to_le_bytes());
            }
        }
        b[218..220].copy_from_slice(&self.idle_time_us.to_le_bytes());
        b
    }

    /// From at least 220 bytes.
    pub fn unpack(b: &[u8]) -> Result<Self, DecodeError> {
        need("0220 status", b, Self::SIZE)?;
        Ok(Self {
            edc_command: u32_at(b, 0),
            sensors: std::array::from_fn(|i| u16_at(b, 4 + 2 * i)),
            motor_data_type: u32_at(b, 78),
            which_motors: i16_at(b, 82),
            which_motor_data_arrived: u32_at(b, 84),
            which_motor_data_had_errors: u32_at(b, 88),
            packets: std::array::from_fn(|i| MotorPacket {
                torque: i16_at(b, 92 + 4 * i),
                misc: u16_at(b, 94 + 4 * i),
            }),
            tactile_data_type: u32_at(b, 132),
            tactile_data_valid: u16_at(b, 136),
            tactile: std::array::from_fn(|f| {
                std::array::from_fn(|k| u16_at(b, 138 + 16 * f + 2 * k))
            }),
            idle_time_us: u16_at(b, 218),
        })
    }

    /// Motor `motor`'s reply, if it is one of this status's motors (its parity is `which_motors`),
    /// arrived and had no error. The error bit is read at bit `motor`, as the firmware sets it; the
    /// shipped host reads bit `motor / 2` (a host bug: docs/devices/shadow.md, "One 1 kHz cycle").
    pub fn reply(&self, motor: usize) -> Option<MotorPacket> {
        if motor >= MOTORS || motor % 2 != usize::from(self.which_motors & 1 != 0) {
            return None;
        }
        let bit = 1u32 << motor;
        (self.which_motor_data_arrived & bit != 0 && self.which_motor_data_had_errors & bit == 0)
            .then(|| self.packets[motor / 2])
    }
}

/// The document's command: EDC command and one torque demand per motor (44 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct DocumentCommand {
    /// The EDC command, raw (document numbering).
    pub edc_command: u32,
    /// Torque demand per motor.
    pub motor_torque_demand: [i16; MOTORS],
}

impl DocumentCommand {
    /// Bytes on the wire.
    pub const SIZE: usize = 44;

    /// The 44 bytes.
    pub fn pack(&self) -> [u8; 44] {
        let mut b = [0u8; 44];
        b[0..4].copy_from_slice(&self.edc_command.to_le_bytes());
        for (i, v) in self.motor_torque_demand.iter().enumerate() {
            b[4 + 2 * i..6 + 2 * i].copy_from_slice(&v.to_le_bytes());
        }
        b
    }

    /// From at least 44 bytes.
    pub fn unpack(b: &[u8]) -> Result<Self, DecodeError> {
        need("document command", b, Self::SIZE)?;
        Ok(Self {
            edc_command: u32_at(b, 0),
            motor_torque_demand: std::array::from_fn(|i| i16_at(b, 4 + 2 * i)),
        })
    }
}

/// The document's `MOTOR_DATA_OUT`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct DocumentMotor {
    /// Torque.
    pub torque: i16,
    /// Left strain gauge.
    pub sg_l: u16,
    /// Right strain gauge.
    pub sg_r: u16,
    /// Temperature.
    pub temperature: i16,
    /// Current.
    pub current: i16,
    /// Flags.
    pub flags: u16,
}

/// The document's status up to its motors: EDC command, 36 sensor words (FFJ1 .. AN_3 and two
/// unused), 20 motors. Its tactile part follows, of a size the document does not give.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DocumentStatus {
    /// The EDC command, raw (document numbering).
    pub edc_command: u32,
    /// Sensor words.
    pub sensors: [i16; 36],
    /// Motors.
    pub motors: [DocumentMotor; MOTORS],
}

impl DocumentStatus {
    /// Bytes decoded (the tactile part after them is not).
    pub const SIZE: usize = 4 + 72 + 12 * MOTORS;

    /// From at least [`DocumentStatus::SIZE`] bytes.
    pub fn unpack(b: &[u8]) -> Result<Self, DecodeError> {
        need("document status", b, Self::SIZE)?;
        Ok(Self {
            edc_command: u32_at(b, 0),
            sensors: std::array::from_fn(|i| i16_at(b, 4 + 2 * i)),
            motors: std::array::from_fn(|m| {
                let at = 76 + 12 * m;
                DocumentMotor {
                    torque: i16_at(b, at),
                    sg_l: u16_at(b, at + 2),
                    sg_r: u16_at(b, at + 4),
                    temperature: i16_at(b, at + 6),
                    current: i16_at(b, at + 8),
                    flags: u16_at(b, at + 10),
                }
            }),
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use proptest::prelude::*;

    #[test]
    fn areas_add_up_to_the_agreed_sizes() {
        // "Agreed sizes" 232 / 70 for 0220 include the bridges.
        let a = Protocol::P0220.area();
        assert_eq!(a.command + a.command_len, a.bridge_command);
        assert_eq!(a.bridge_command + CanBridge::SIZE as u16, a.status);
        assert_eq!(a.status + a.status_len, a.bridge_status);
        assert_eq!(a.bridge_status + CanBridge::SIZE as u16, 0x112E);
        assert_eq!(usize::from(a.command_len) + CanBridge::SIZE, 70);
        assert_eq!(usize::from(a.status_len) + CanBridge::SIZE, 232);
        let c = Protocol::P0240.area();
        assert_eq!(c.bridge_status + CanBridge::SIZE as u16, 0x1132);
        assert_eq!(Protocol::from_product_code(6), Some(Protocol::P0220));
        assert_eq!(Protocol::from_product_code(0), None);
    }

    #[test]
    fn command_fields_at_their_offsets() {
        let mut c = Command {
            edc_command: 1,
            from_motor_data_type: 5,
            which_motors: 1,
            to_motor_data_type: 2,
            tactile_data_type: 1,
            ..Default::default()
        };
        c.motor_data[0] = 0x0102;
        c.motor_data[19] = -2;
        let b = c.pack();
        assert_eq!(&b[0..4], &[1, 0, 0, 0]);
        assert_eq!(&b[4..8], &[5, 0, 0, 0]);
        assert_eq!(&b[8..10], &[1, 0]);
        assert_eq!(&b[10..14], &[2, 0, 0, 0]);
        assert_eq!(&b[14..16], &[0x02, 0x01]);
        assert_eq!(&b[52..54], &[0xFE, 0xFF]);
        assert_eq!(&b[54..58], &[1, 0, 0, 0]);
        assert_eq!(Command::unpack(&b).unwrap(), c);
    }

    #[test]
    fn status_fields_at_their_offsets() {
        let mut s = Status {
            edc_command: 1,
            motor_data_type: 4,
            which_motors: 1,
            which_motor_data_arrived: 1 << 3,
            which_motor_data_had_errors: 0,
            idle_time_us: 300,
            ..Default::default()
        };
        s.sensors[0] = 0x0ABC;
        s.packets[1] = MotorPacket {
            torque: -5,
            misc: 0x8000,
        };
        s.tactile[4][7] = 0x1234;
        let b = s.pack();
        assert_eq!(&b[4..6], &[0xBC, 0x0A]);
        assert_eq!(&b[78..82], &[4, 0, 0, 0]);
        assert_eq!(&b[84..88], &[8, 0, 0, 0]);
        assert_eq!(&b[96..100], &[0xFB, 0xFF, 0x00, 0x80]);
        assert_eq!(&b[216..218], &[0x34, 0x12]);
        assert_eq!(&b[218..220], &[0x2C, 0x01]);
        let back = Status::unpack(&b).unwrap();
        assert_eq!(back, s);
        // Motor 3 (odd, slot 1) arrived; motor 2 is not in this status; motor 5 did not arrive.
        assert_eq!(back.reply(3), Some(s.packets[1]));
        assert_eq!(back.reply(2), None);
        assert_eq!(back.reply(5), None);
    }

    #[test]
    fn the_documents_structures() {
        let mut c = DocumentCommand {
            edc_command: 5,
            ..Default::default()
        };
        c.motor_torque_demand[1] = 7;
        let b = c.pack();
        assert_eq!(&b[6..8], &[7, 0]);
        assert_eq!(DocumentCommand::unpack(&b).unwrap(), c);
        let mut raw = vec![0u8; DocumentStatus::SIZE];
        raw[76 + 12 * 19 + 10] = 0x80; // motor 19's flags, low byte
        let s = DocumentStatus::unpack(&raw).unwrap();
        assert_eq!(s.motors[19].flags, 0x80);
        assert_eq!(DocumentStatus::SIZE, 316);
    }

    #[test]
    fn short_input_is_an_error() {
        assert!(matches!(
            Status::unpack(&[0; 219]),
            Err(DecodeError::Short {
                need: 220,
                got: 219,
                ..
            })
        ));
        assert!(CanBridge::unpack(&[0; 11]).is_err());
    }

    proptest! {
        #[test]
        fn decoders_never_panic_and_round_trip(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
            if let Ok(s) = Status::unpack(&bytes) {
                prop_assert_eq!(&s.pack()[..], &bytes[..Status::SIZE]);
            }
            if let Ok(c) = Command::unpack(&bytes) {
                prop_assert_eq!(&c.pack()[..], &bytes[..Command::SIZE]);
            }
            if let Ok(m) = CanBridge::unpack(&bytes) {
                prop_assert_eq!(&m.pack()[..], &bytes[..CanBridge::SIZE]);
            }
            let _ = DocumentStatus::unpack(&bytes);
            let _ = DocumentCommand::unpack(&bytes);
        }
    }
}
