//! EDC commands, the motor data types and their units, slow data, motor flags and the config
//! CRC (docs/devices/shadow.md, "Enums and flags": E's headers, HEAD generation).

/// What the palm is asked to do (the command's first word; also the status's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EdcCommand {
    /// 0: nothing valid (an unwritten sync manager reads as zeros).
    Invalid,
    /// Normal operation: motor data requests, demands, joint sensors.
    SensorData,
    /// Like `SensorData`, but each joint sensor reports its ADC and channel number (tests).
    SensorChannelNumbers,
    /// The ADCs' chip selects (tests).
    SensorAdcChannelCs,
    /// The document only: test results.
    TestResults,
    /// CAN direct mode (the document's CAN_TEST_MODE): the palm only bridges CAN messages.
    CanDirectMode,
}

/// How EDC commands are numbered. The document lists INVALID 0, SENSOR_DATA 1,
/// SENSOR_CHANNEL_NUMBERS 2, SENSOR_ADC_CHANNEL_CS 3, TEST_RESULTS 4, CAN_TEST_MODE 5; the shipped
/// driver, headers and firmware have no TEST_RESULTS and put CAN_DIRECT_MODE at 4 (E). A palm
/// running the shipped firmware must be sent 4 to flash; the shipped numbering is the default.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum EdcNumbering {
    /// E: CAN_DIRECT_MODE = 4.
    #[default]
    Shipped,
    /// The device document: TEST_RESULTS = 4, CAN_TEST_MODE = 5.
    Document,
}

/// The EDC_command a palm writes while it boots (E11 `Platform_Init_Callback`: 0xCC, then every
/// 16-bit word of the status from the second on 0xDEAD, EDC_command's upper half included, so
/// the whole word reads [`EDC_BOOTING_WORD`]).
pub const EDC_BOOTING: u32 = 0xCC;
/// EDC_command as a booting palm's status carries it: 0xCC with 0xDEAD in the upper half.
pub const EDC_BOOTING_WORD: u32 = 0xDEAD_0000 | EDC_BOOTING;

impl EdcCommand {
    /// The command's value in `numbering` (`None`: not in that numbering, e.g. TEST_RESULTS in
    /// the shipped one).
    pub fn value(self, numbering: EdcNumbering) -> Option<u32> {
        Some(match (self, numbering) {
            (EdcCommand::Invalid, _) => 0,
            (EdcCommand::SensorData, _) => 1,
            (EdcCommand::SensorChannelNumbers, _) => 2,
            (EdcCommand::SensorAdcChannelCs, _) => 3,
            (EdcCommand::TestResults, EdcNumbering::Document) => 4,
            (EdcCommand::TestResults, EdcNumbering::Shipped) => return None,
            (EdcCommand::CanDirectMode, EdcNumbering::Shipped) => 4,
            (EdcCommand::CanDirectMode, EdcNumbering::Document) => 5,
        })
    }

    /// The command with `value` in `numbering`, if any.
    pub fn from_value(value: u32, numbering: EdcNumbering) -> Option<Self> {
        [
            EdcCommand::Invalid,
            EdcCommand::SensorData,
            EdcCommand::SensorChannelNumbers,
            EdcCommand::SensorAdcChannelCs,
            EdcCommand::TestResults,
            EdcCommand::CanDirectMode,
        ]
        .into_iter()
        .find(|c| c.value(numbering) == Some(value))
    }
}

/// What a motor sends back (the status's `motor_data_type`, the command's
/// `from_motor_data_type`). Except for the types below that say otherwise, the packet's torque
/// word is the measured torque and its misc word the value of the type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum FromMotor {
    /// Left strain gauge, raw.
    StrainGaugeLeft = 1,
    /// Right strain gauge, raw.
    StrainGaugeRight = 2,
    /// PWM, raw.
    Pwm = 3,
    /// Flags ([`flags`]).
    Flags = 4,
    /// Current, mA.
    Current = 5,
    /// Voltage, 1/256 V.
    Voltage = 6,
    /// Temperature, 8.8 fixed point deg C (1/256 deg C).
    Temperature = 7,
    /// CAN messages received.
    CanRx = 8,
    /// CAN messages sent.
    CanTx = 9,
    /// Slow data: the torque word says which ([`SlowData`]).
    SlowMisc = 0xA,
    /// The last config word read back: the torque word says which ([`ToMotor`]).
    ReadbackLastConfig = 0xB,
    /// CAN error counters (low byte transmit, high byte receive).
    CanErrorCounters = 0xC,
    /// The controller's P term, 1/256.
    PTerm = 0xD,
    /// The controller's I term, 1/256.
    ITerm = 0xE,
    /// The controller's D term, 1/256.
    DTerm = 0xF,
}

impl FromMotor {
    /// Every type, in value order.
    pub const ALL: [FromMotor; 15] = [
        FromMotor::StrainGaugeLeft,
        FromMotor::StrainGaugeRight,
        FromMotor::Pwm,
        FromMotor::Flags,
        FromMotor::Current,
        FromMotor::Voltage,
        FromMotor::Temperature,
        FromMotor::CanRx,
        FromMotor::CanTx,
        FromMotor::SlowMisc,
        FromMotor::ReadbackLastConfig,
        FromMotor::CanErrorCounters,
        FromMotor::PTerm,
        FromMotor::ITerm,
        FromMotor::DTerm,
    ];

    /// The type with this value.
    pub fn from_value(value: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|t| *t as u32 == value)
    }

    /// The misc word in its unit: mA, V, deg C, or the raw value (as f64) for the others.
    pub fn scaled(self, misc: u16) -> f64 {
        match self {
            FromMotor::Voltage => f64::from(misc) / 256.0,
            FromMotor::Temperature => f64::from(misc as i16) / 256.0,
            FromMotor::PTerm | FromMotor::ITerm | FromMotor::DTerm => {
                f64::from(misc as i16) / 256.0
            }
            FromMotor::Current => f64::from(misc),
            _ => f64::from(misc),
        }
    }
}

/// Slow data a motor returns with [`FromMotor::SlowMisc`] (the motor picks which).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u16)]
pub enum SlowData {
    /// Firmware SVN revision.
    SvnRevision = 1,
    /// The server's revision at build time.
    ServerRevision = 2,
    /// Built from modified sources.
    Modified = 3,
    /// Serial number, low word.
    SerialLow = 4,
    /// Serial number, high word.
    SerialHigh = 5,
    /// Gear ratio.
    GearRatio = 6,
    /// Build year.
    Year = 7,
    /// Build month and day (0x0A1F = Oct 31).
    MonthDay = 8,
    /// Controller F gain.
    F = 9,
    /// Controller P gain.
    P = 0xA,
    /// Controller I gain.
    I = 0xB,
    /// Controller integral limit.
    Imax = 0xC,
    /// Controller D gain.
    D = 0xD,
    /// Deadband (low byte) and sign (high byte).
    DeadbandSign = 0xE,
    /// Control frequency (5000).
    Frequency = 0xF,
    /// Strain gauge type (0x0C coupled, 0x0D decoupled).
    GaugeType = 0x10,
}

impl SlowData {
    /// Every slow type, in value order.
    pub const ALL: [SlowData; 16] = [
        SlowData::SvnRevision,
        SlowData::ServerRevision,
        SlowData::Modified,
        SlowData::SerialLow,
        SlowData::SerialHigh,
        SlowData::GearRatio,
        SlowData::Year,
        SlowData::MonthDay,
        SlowData::F,
        SlowData::P,
        SlowData::I,
        SlowData::Imax,
        SlowData::D,
        SlowData::DeadbandSign,
        SlowData::Frequency,
        SlowData::GaugeType,
    ];

    /// The slow type with this value.
    pub fn from_value(value: u16) -> Option<Self> {
        Self::ALL.into_iter().find(|t| *t as u16 == value)
    }
}

/// What the host sends the motors (the command's `to_motor_data_type`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum ToMotor {
    /// Torque demand, ±0x7FFF.
    TorqueDemand = 1,
    /// PWM demand, ±0x3FF.
    PwmDemand = 2,
    /// Reset: the word is `0x5200 | id on its bus`.
    SystemReset = 3,
    /// System controls ([`controls`]).
    SystemControls = 4,
    /// Torque limit.
    TorqueLimit = 5,
    /// Limiter gain, ±0x200.
    LimiterGain = 6,
    /// Largest PWM.
    MaxPwm = 7,
    /// Strain gauge references (low byte left, high byte right).
    StrainGaugeRefs = 8,
    /// Config: F gain, 0..0x7FFF.
    ConfigF = 9,
    /// Config: P gain.
    ConfigP = 0xA,
    /// Config: I gain.
    ConfigI = 0xB,
    /// Config: D gain.
    ConfigD = 0xC,
    /// Config: integral limit, 0..0x3FFF.
    ConfigImax = 0xD,
    /// Config: deadband (low byte, 0..0xFF) and sign (high byte, 0..1).
    ConfigDeadbandSign = 0xE,
    /// The CRC of config words 5..0xE ([`config_crc`]); sends them into effect.
    ConfigCrc = 0xF,
}

impl ToMotor {
    /// The type with this value (1..0xF).
    pub fn from_value(value: u32) -> Option<Self> {
        use ToMotor::*;
        [
            TorqueDemand,
            PwmDemand,
            SystemReset,
            SystemControls,
            TorqueLimit,
            LimiterGain,
            MaxPwm,
            StrainGaugeRefs,
            ConfigF,
            ConfigP,
            ConfigI,
            ConfigD,
            ConfigImax,
            ConfigDeadbandSign,
            ConfigCrc,
        ]
        .into_iter()
        .find(|t| *t as u32 == value)
    }
}

/// The reset word of the motor with `id_on_bus` (0..9).
pub fn reset_word(id_on_bus: u8) -> u16 {
    0x5200 | u16::from(id_on_bus)
}

/// Bits of a [`ToMotor::SystemControls`] word.
pub mod controls {
    /// Backlash compensation on.
    pub const BACKLASH_ON: u16 = 0x01;
    /// Backlash compensation off.
    pub const BACKLASH_OFF: u16 = 0x02;
    /// Left strain gauge tracking +.
    pub const SGL_TRACKING_INC: u16 = 0x04;
    /// Left strain gauge tracking -.
    pub const SGL_TRACKING_DEC: u16 = 0x08;
    /// Right strain gauge tracking +.
    pub const SGR_TRACKING_INC: u16 = 0x10;
    /// Right strain gauge tracking -.
    pub const SGR_TRACKING_DEC: u16 = 0x20;
    /// Start jiggling.
    pub const JIGGLE: u16 = 0x40;
    /// Write the configuration to EEPROM.
    pub const WRITE_EEPROM: u16 = 0x80;
}

/// Motor flags ([`FromMotor::Flags`]).
pub mod flags {
    /// Current choke (4 bits).
    pub const CURRENT_CHOKE: u16 = 0x000F;
    /// EEPROM being written.
    pub const EEPROM_WRITING: u16 = 0x0010;
    /// The last config's CRC failed.
    pub const LAST_CONFIG_CRC_FAILED: u16 = 0x0020;
    /// A value out of range.
    pub const OUT_OF_RANGE: u16 = 0x0040;
    /// Jiggling.
    pub const JIGGLING: u16 = 0x0080;
    /// The motor's id is invalid.
    pub const ID_INVALID: u16 = 0x0200;
    /// No demand seen (the motor's 20 ms no-demand stop).
    pub const NO_DEMAND_SEEN: u16 = 0x0400;
    /// Left strain gauge fault.
    pub const SGL_FAULT: u16 = 0x0800;
    /// Right strain gauge fault.
    pub const SGR_FAULT: u16 = 0x1000;
    /// The A3950 driver's nFault.
    pub const A3950_FAULT: u16 = 0x2000;
    /// EEPROM with a bad CRC.
    pub const EEPROM_BAD_CRC: u16 = 0x4000;
    /// Over temperature.
    pub const OVER_TEMPERATURE: u16 = 0x8000;
    /// The flags that switch the motor off (E).
    pub const SERIOUS: u16 = NO_DEMAND_SEEN | A3950_FAULT | EEPROM_BAD_CRC | OVER_TEMPERATURE;

    /// Every named flag bit with its name (the choke is a field, not listed).
    pub const NAMES: [(u16, &str); 11] = [
        (EEPROM_WRITING, "EEPROM writing"),
        (LAST_CONFIG_CRC_FAILED, "last config CRC failed"),
        (OUT_OF_RANGE, "out of range"),
        (JIGGLING, "jiggling"),
        (ID_INVALID, "motor id invalid"),
        (NO_DEMAND_SEEN, "no demand seen"),
        (SGL_FAULT, "left strain gauge fault"),
        (SGR_FAULT, "right strain gauge fault"),
        (A3950_FAULT, "motor driver fault (A3950 nFault)"),
        (EEPROM_BAD_CRC, "EEPROM bad CRC"),
        (OVER_TEMPERATURE, "over temperature"),
    ];

    /// The names of the set flags, serious ones first.
    pub fn names(word: u16) -> Vec<&'static str> {
        let mut out: Vec<&'static str> = NAMES
            .iter()
            .filter(|(bit, _)| word & bit != 0 && SERIOUS & bit != 0)
            .map(|(_, n)| *n)
            .collect();
        out.extend(
            NAMES
                .iter()
                .filter(|(bit, _)| word & bit != 0 && SERIOUS & bit == 0)
                .map(|(_, n)| *n),
        );
        out
    }

    /// Whether the word has a flag that switches the motor off.
    pub fn serious(word: u16) -> bool {
        word & SERIOUS != 0
    }
}

/// Tactile sensor types.
pub mod tactile {
    /// PST3 pressure sensors (the Hand E's fingertips).
    pub const PST3: u32 = 1;
    /// BioTac.
    pub const BIOTAC: u32 = 2;
    /// UBI0.
    pub const UBI0: u32 = 3;
    /// MST.
    pub const MST: u32 = 4;
    /// The first generic request (which sensors); generic requests run 0xFFF9..0xFFFF (reset).
    pub const GENERIC_FIRST: u32 = 0xFFF9;
}

/// The CRC a motor checks config words with (docs/devices/shadow.md, "Enums and flags": 16
/// bit, start 0, over config words
/// 5..0xE, each word low byte then high; per byte `i = (crc & 0xFF) ^ byte`, `crc >>= 8`, then
/// for each set bit k of i, crc ^= TABLE[k]). A CRC of 0 means "ignore" to the motor, so 0 is
/// sent as 1.
pub fn config_crc(words: &[u16]) -> u16 {
    const TABLE: [u16; 8] = [
        0x3096, 0x612C, 0xC419, 0x8832, 0x1064, 0x20C8, 0x4190, 0x8320,
    ];
    let mut crc: u16 = 0;
    for w in words {
        for byte in w.to_le_bytes() {
            let i = (crc & 0xFF) as u8 ^ byte;
            crc >>= 8;
            for (k, t) in TABLE.iter().enumerate() {
                if i & (1 << k) != 0 {
                    crc ^= t;
                }
            }
        }
    }
    if crc == 0 {
        1
    } else {
        crc
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn the_two_numberings_of_edc_commands() {
        assert_eq!(
            EdcCommand::CanDirectMode.value(EdcNumbering::Shipped),
            Some(4)
        );
        assert_eq!(
            EdcCommand::CanDirectMode.value(EdcNumbering::Document),
            Some(5)
        );
        assert_eq!(EdcCommand::TestResults.value(EdcNumbering::Shipped), None);
        assert_eq!(
            EdcCommand::from_value(4, EdcNumbering::Document),
            Some(EdcCommand::TestResults)
        );
        assert_eq!(
            EdcCommand::from_value(4, EdcNumbering::Shipped),
            Some(EdcCommand::CanDirectMode)
        );
        assert_eq!(EdcCommand::from_value(5, EdcNumbering::Shipped), None);
        assert_eq!(
            EdcCommand::from_value(1, EdcNumbering::Shipped),
            Some(EdcCommand::SensorData)
        );
    }

    #[test]
    fn units_and_words() {
        assert_eq!(FromMotor::Temperature.scaled(0x2480), 36.5);
        assert_eq!(FromMotor::Voltage.scaled(24 * 256), 24.0);
        assert_eq!(
            FromMotor::from_value(0xB),
            Some(FromMotor::ReadbackLastConfig)
        );
        assert_eq!(FromMotor::from_value(0x10), None);
        assert_eq!(SlowData::from_value(0x10), Some(SlowData::GaugeType));
        assert_eq!(ToMotor::from_value(0xF), Some(ToMotor::ConfigCrc));
        assert_eq!(reset_word(7), 0x5207);
    }

    #[test]
    fn serious_flags_are_named_first() {
        let w = flags::OVER_TEMPERATURE | flags::JIGGLING | 0x3;
        assert!(flags::serious(w));
        assert_eq!(flags::names(w), vec!["over temperature", "jiggling"]);
        assert!(!flags::serious(flags::SGL_FAULT));
        assert!(flags::serious(flags::NO_DEMAND_SEEN));
    }

    #[test]
    fn config_crc_by_hand() {
        // One word 0x0001: byte 0x01 -> i = 1 -> crc = 0 ^ TABLE[0] = 0x3096; byte 0x00 ->
        // i = 0x96 (bits 1, 2, 4, 7), crc = 0x30 ^ 0x612C ^ 0xC419 ^ 0x1064 ^ 0x8320.
        let expected = 0x0030 ^ 0x612C ^ 0xC419 ^ 0x1064 ^ 0x8320;
        assert_eq!(config_crc(&[0x0001]), expected);
        // Nothing: 0, sent as 1.
        assert_eq!(config_crc(&[]), 1);
    }
}
