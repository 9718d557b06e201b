//! The XC330-M288-T control table (e-manual, XC330-M288, control table), the XL330-M077-T's
//! differences (e-manual, XL330-M077, control table), and the values its items hold: operating
//! modes, baud rates, hardware error bits, units, and the 10-byte state at Present Current.
//!
//! Addresses 0..=63 are EEPROM, written only while Torque Enable (64) is 0 (else Access Error);
//! 64 and up are RAM. Multi-byte items are little-endian; the "Present" and "Goal" items and the
//! Homing Offset are signed.

use crate::DecodeError;

/// Model Number (R).
pub const MODEL_NUMBER: u16 = 0;
/// Model Information (R).
pub const MODEL_INFORMATION: u16 = 2;
/// Firmware Version (R).
pub const FIRMWARE_VERSION: u16 = 6;
/// ID (EEPROM).
pub const ID: u16 = 7;
/// Baud Rate code (EEPROM, [`BaudRate`]).
pub const BAUD_RATE: u16 = 8;
/// Return Delay Time, 2 us per unit (EEPROM).
pub const RETURN_DELAY_TIME: u16 = 9;
/// Drive Mode bits (EEPROM).
pub const DRIVE_MODE: u16 = 10;
/// Operating Mode (EEPROM, [`OperatingMode`]).
pub const OPERATING_MODE: u16 = 11;
/// Secondary (Shadow) ID (EEPROM).
pub const SECONDARY_ID: u16 = 12;
/// Protocol Type (EEPROM).
pub const PROTOCOL_TYPE: u16 = 13;
/// Homing Offset (EEPROM).
pub const HOMING_OFFSET: u16 = 20;
/// Moving Threshold (EEPROM).
pub const MOVING_THRESHOLD: u16 = 24;
/// Temperature Limit, degC (EEPROM).
pub const TEMPERATURE_LIMIT: u16 = 31;
/// Max Voltage Limit, 0.1 V (EEPROM).
pub const MAX_VOLTAGE_LIMIT: u16 = 32;
/// Min Voltage Limit, 0.1 V (EEPROM).
pub const MIN_VOLTAGE_LIMIT: u16 = 34;
/// PWM Limit (EEPROM).
pub const PWM_LIMIT: u16 = 36;
/// Current Limit, mA (EEPROM).
pub const CURRENT_LIMIT: u16 = 38;
/// Velocity Limit (EEPROM).
pub const VELOCITY_LIMIT: u16 = 44;
/// Max Position Limit (EEPROM).
pub const MAX_POSITION_LIMIT: u16 = 48;
/// Min Position Limit (EEPROM).
pub const MIN_POSITION_LIMIT: u16 = 52;
/// Startup Configuration (EEPROM).
pub const STARTUP_CONFIGURATION: u16 = 60;
/// PWM Slope (EEPROM).
pub const PWM_SLOPE: u16 = 62;
/// Shutdown: which [`HardwareError`] bits turn the torque off (EEPROM).
pub const SHUTDOWN: u16 = 63;
/// Torque Enable (RAM; 1 locks the EEPROM).
pub const TORQUE_ENABLE: u16 = 64;
/// LED.
pub const LED: u16 = 65;
/// Status Return Level: 0 Ping only, 1 Ping and Read, 2 all.
pub const STATUS_RETURN_LEVEL: u16 = 68;
/// Registered Instruction (R).
pub const REGISTERED_INSTRUCTION: u16 = 69;
/// Hardware Error Status (R, [`HardwareError`]).
pub const HARDWARE_ERROR_STATUS: u16 = 70;
/// Velocity I Gain.
pub const VELOCITY_I_GAIN: u16 = 76;
/// Velocity P Gain.
pub const VELOCITY_P_GAIN: u16 = 78;
/// Position D Gain.
pub const POSITION_D_GAIN: u16 = 80;
/// Position I Gain.
pub const POSITION_I_GAIN: u16 = 82;
/// Position P Gain.
pub const POSITION_P_GAIN: u16 = 84;
/// Feedforward 2nd Gain.
pub const FEEDFORWARD_2ND_GAIN: u16 = 88;
/// Feedforward 1st Gain.
pub const FEEDFORWARD_1ST_GAIN: u16 = 90;
/// Bus Watchdog, 20 ms per unit.
pub const BUS_WATCHDOG: u16 = 98;
/// Goal PWM.
pub const GOAL_PWM: u16 = 100;
/// Goal Current, mA.
pub const GOAL_CURRENT: u16 = 102;
/// Goal Velocity.
pub const GOAL_VELOCITY: u16 = 104;
/// Profile Acceleration.
pub const PROFILE_ACCELERATION: u16 = 108;
/// Profile Velocity.
pub const PROFILE_VELOCITY: u16 = 112;
/// Goal Position, counts.
pub const GOAL_POSITION: u16 = 116;
/// Realtime Tick, ms (R).
pub const REALTIME_TICK: u16 = 120;
/// Moving (R).
pub const MOVING: u16 = 122;
/// Moving Status (R).
pub const MOVING_STATUS: u16 = 123;
/// Present PWM (R).
pub const PRESENT_PWM: u16 = 124;
/// Present Current, mA (R, signed).
pub const PRESENT_CURRENT: u16 = 126;
/// Present Velocity, 0.229 rpm (R, signed).
pub const PRESENT_VELOCITY: u16 = 128;
/// Present Position, counts (R, signed).
pub const PRESENT_POSITION: u16 = 132;
/// Velocity Trajectory (R).
pub const VELOCITY_TRAJECTORY: u16 = 136;
/// Position Trajectory (R).
pub const POSITION_TRAJECTORY: u16 = 140;
/// Present Input Voltage, 0.1 V (R).
pub const PRESENT_INPUT_VOLTAGE: u16 = 144;
/// Present Temperature, degC (R).
pub const PRESENT_TEMPERATURE: u16 = 146;
/// Backup Ready (R).
pub const BACKUP_READY: u16 = 147;
/// Indirect Address 1 (of [`INDIRECT_COUNT`], 2 bytes each).
pub const INDIRECT_ADDRESS_1: u16 = 168;
/// Indirect Data 1 (of [`INDIRECT_COUNT`], 1 byte each).
pub const INDIRECT_DATA_1: u16 = 208;
/// Indirect Address/Data pairs.
pub const INDIRECT_COUNT: u16 = 20;
/// The first RAM address: below it is EEPROM.
pub const RAM_START: u16 = 64;
/// One past the table's last byte.
pub const TABLE_END: u16 = 228;

/// Model numbers of the X330 family (e-manual product pages; DynamixelSDK `dynamixel.model`).
pub const MODEL_XL330_M077: u16 = 1190;
/// XL330-M288-T.
pub const MODEL_XL330_M288: u16 = 1200;
/// XC330-T181-T.
pub const MODEL_XC330_T181: u16 = 1210;
/// XC330-T288-T.
pub const MODEL_XC330_T288: u16 = 1220;
/// XC330-M181-T.
pub const MODEL_XC330_M181: u16 = 1230;
/// XC330-M288-T: the LEAP Hand's servo.
pub const MODEL_XC330_M288: u16 = 1240;

/// The name of an X330 model number.
pub fn model_name(model: u16) -> Option<&'static str> {
    Some(match model {
        MODEL_XL330_M077 => "XL330-M077-T",
        MODEL_XL330_M288 => "XL330-M288-T",
        MODEL_XC330_T181 => "XC330-T181-T",
        MODEL_XC330_T288 => "XC330-T288-T",
        MODEL_XC330_M181 => "XC330-M181-T",
        MODEL_XC330_M288 => "XC330-M288-T",
        _ => return None,
    })
}

/// Who may access an item.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Access {
    /// Read only.
    R,
    /// Read and write.
    RW,
}

/// Where an item lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Area {
    /// Kept over power cycles; written only with Torque Enable 0.
    Eeprom,
    /// Reset at power-up and Reboot.
    Ram,
}

/// The values an item takes, as the control table prints them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Range {
    /// None printed: any value of its size (a read-only item, a bit mask).
    Any,
    /// `min..=max`.
    Span(i32, i32),
    /// One of these values.
    OneOf(&'static [i32]),
    /// `-v..=v`, `v` the value of the item at this address (a Goal bounded by its Limit).
    PlusMinus(u16),
    /// From the value at the first address to the value at the second (Goal Position in
    /// position mode, 3; in modes 4 and 5 it is `-EXTENDED_POSITION..=EXTENDED_POSITION`).
    Between(u16, u16),
}

/// Goal Position's bound in extended (4) and current-based (5) position modes: +-256 turns.
pub const EXTENDED_POSITION: i32 = 1_048_575;

/// One control table item.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Item {
    /// Its name, as the e-manual writes it.
    pub name: &'static str,
    /// Its address.
    pub addr: u16,
    /// Its size in bytes (1, 2 or 4).
    pub size: u8,
    /// Read only or read-write.
    pub access: Access,
    /// EEPROM or RAM.
    pub area: Area,
    /// Whether its value is signed (two's complement).
    pub signed: bool,
    /// Its initial value; `None` where the e-manual prints none (measured values, the firmware
    /// version, the Goals, which follow their limits or the present state).
    pub init: Option<i32>,
    /// The values it takes.
    pub range: Range,
    /// Its unit, in words (empty: none).
    pub unit: &'static str,
}

impl Item {
    /// One past its last byte.
    pub fn end(&self) -> u16 {
        self.addr + u16::from(self.size)
    }

    /// Whether byte `addr` belongs to it.
    pub fn contains(&self, addr: u16) -> bool {
        (self.addr..self.end()).contains(&addr)
    }

    /// Its value from its little-endian bytes (sign-extended if it is signed).
    pub fn decode(&self, bytes: &[u8]) -> Result<i32, DecodeError> {
        if bytes.len() != usize::from(self.size) {
            return Err(DecodeError::DataLength {
                what: self.name,
                expected: usize::from(self.size),
                got: bytes.len(),
            });
        }
        let mut le = [0u8; 4];
        le[..bytes.len()].copy_from_slice(bytes);
        let raw = u32::from_le_bytes(le);
        let shift = 32 - 8 * u32::from(self.size);
        Ok(if self.signed {
            ((raw << shift) as i32) >> shift
        } else {
            raw as i32
        })
    }

    /// `value`'s little-endian bytes; the item's are the first [`Item::size`].
    pub fn encode(&self, value: i32) -> [u8; 4] {
        value.to_le_bytes()
    }
}

macro_rules! item {
    ($addr:expr, $size:expr, $name:expr, $access:ident, $signed:expr, $init:expr, $range:expr, $unit:expr) => {
        Item {
            name: $name,
            addr: $addr,
            size: $size,
            access: Access::$access,
            area: if $addr < RAM_START {
                Area::Eeprom
            } else {
                Area::Ram
            },
            signed: $signed,
            init: $init,
            range: $range,
            unit: $unit,
        }
    };
}

macro_rules! indirect {
    ($n:literal) => {
        [
            item!(
                INDIRECT_ADDRESS_1 + 2 * ($n - 1),
                2,
                concat!("Indirect Address ", $n),
                RW,
                false,
                Some(INDIRECT_DATA_1 as i32 + $n - 1),
                Range::Span(RAM_START as i32, TABLE_END as i32 - 1),
                ""
            ),
            item!(
                INDIRECT_DATA_1 + ($n - 1),
                1,
                concat!("Indirect Data ", $n),
                RW,
                false,
                Some(0),
                Range::Span(0, 255),
                ""
            ),
        ]
    };
}

/// The operating modes' values, for [`OPERATING_MODE`]'s range.
const OPERATING_MODES: [i32; 6] = [0, 1, 3, 4, 5, 16];
/// Items before the indirect ones.
const DIRECT: usize = 54;
/// Every item.
const COUNT: usize = DIRECT + 2 * INDIRECT_COUNT as usize;

const RPM: &str = "0.229 rev/min";
const PULSE: &str = "1 pulse (0.088 deg)";
const MA: &str = "1.0 mA";
const PWM: &str = "0.113 %";

/// The items of the XC330-M288-T other than the indirect ones, in address order.
const DIRECT_ITEMS: [Item; DIRECT] = [
    item!(
        MODEL_NUMBER,
        2,
        "Model Number",
        R,
        false,
        Some(MODEL_XC330_M288 as i32),
        Range::Any,
        ""
    ),
    item!(
        MODEL_INFORMATION,
        4,
        "Model Information",
        R,
        false,
        None,
        Range::Any,
        ""
    ),
    item!(
        FIRMWARE_VERSION,
        1,
        "Firmware Version",
        R,
        false,
        None,
        Range::Any,
        ""
    ),
    item!(ID, 1, "ID", RW, false, Some(1), Range::Span(0, 252), ""),
    item!(
        BAUD_RATE,
        1,
        "Baud Rate",
        RW,
        false,
        Some(1),
        Range::Span(0, 6),
        ""
    ),
    item!(
        RETURN_DELAY_TIME,
        1,
        "Return Delay Time",
        RW,
        false,
        Some(250),
        Range::Span(0, 254),
        "2 us"
    ),
    item!(
        DRIVE_MODE,
        1,
        "Drive Mode",
        RW,
        false,
        Some(0),
        Range::Span(0, 13),
        ""
    ),
    item!(
        OPERATING_MODE,
        1,
        "Operating Mode",
        RW,
        false,
        Some(3),
        Range::OneOf(&OPERATING_MODES),
        ""
    ),
    item!(
        SECONDARY_ID,
        1,
        "Secondary(Shadow) ID",
        RW,
        false,
        Some(255),
        Range::Span(0, 252),
        ""
    ),
    item!(
        PROTOCOL_TYPE,
        1,
        "Protocol Type",
        RW,
        false,
        Some(2),
        Range::Span(2, 22),
        ""
    ),
    item!(
        HOMING_OFFSET,
        4,
        "Homing Offset",
        RW,
        true,
        Some(0),
        Range::Span(-1_044_479, 1_044_479),
        PULSE
    ),
    item!(
        MOVING_THRESHOLD,
        4,
        "Moving Threshold",
        RW,
        false,
        Some(10),
        Range::Span(0, 1023),
        RPM
    ),
    item!(
        TEMPERATURE_LIMIT,
        1,
        "Temperature Limit",
        RW,
        false,
        Some(70),
        Range::Span(0, 100),
        "1 degC"
    ),
    item!(
        MAX_VOLTAGE_LIMIT,
        2,
        "Max Voltage Limit",
        RW,
        false,
        Some(70),
        Range::Span(31, 70),
        "0.1 V"
    ),
    item!(
        MIN_VOLTAGE_LIMIT,
        2,
        "Min Voltage Limit",
        RW,
        false,
        Some(35),
        Range::Span(31, 70),
        "0.1 V"
    ),
    item!(
        PWM_LIMIT,
        2,
        "PWM Limit",
        RW,
        false,
        Some(885),
        Range::Span(0, 885),
        PWM
    ),
    item!(
        CURRENT_LIMIT,
        2,
        "Current Limit",
        RW,
        false,
        Some(2352),
        Range::Span(0, 2352),
        MA
    ),
    item!(
        VELOCITY_LIMIT,
        4,
        "Velocity Limit",
        RW,
        false,
        Some(350),
        Range::Span(0, 2047),
        RPM
    ),
    item!(
        MAX_POSITION_LIMIT,
        4,
        "Max Position Limit",
        RW,
        false,
        Some(4095),
        Range::Span(0, 4095),
        PULSE
    ),
    item!(
        MIN_POSITION_LIMIT,
        4,
        "Min Position Limit",
        RW,
        false,
        Some(0),
        Range::Span(0, 4095),
        PULSE
    ),
    item!(
        STARTUP_CONFIGURATION,
        1,
        "Startup Configuration",
        RW,
        false,
        Some(0),
        Range::Span(0, 3),
        ""
    ),
    item!(
        PWM_SLOPE,
        1,
        "PWM Slope",
        RW,
        false,
        Some(140),
        Range::Span(1, 255),
        "1.977 mV/ms"
    ),
    item!(SHUTDOWN, 1, "Shutdown", RW, false, Some(52), Range::Any, ""),
    item!(
        TORQUE_ENABLE,
        1,
        "Torque Enable",
        RW,
        false,
        Some(0),
        Range::Span(0, 1),
        ""
    ),
    item!(LED, 1, "LED", RW, false, Some(0), Range::Span(0, 1), ""),
    item!(
        STATUS_RETURN_LEVEL,
        1,
        "Status Return Level",
        RW,
        false,
        Some(2),
        Range::Span(0, 2),
        ""
    ),
    item!(
        REGISTERED_INSTRUCTION,
        1,
        "Registered Instruction",
        R,
        false,
        Some(0),
        Range::Span(0, 1),
        ""
    ),
    item!(
        HARDWARE_ERROR_STATUS,
        1,
        "Hardware Error Status",
        R,
        false,
        Some(0),
        Range::Any,
        ""
    ),
    item!(
        VELOCITY_I_GAIN,
        2,
        "Velocity I Gain",
        RW,
        false,
        Some(1600),
        Range::Span(0, 16383),
        ""
    ),
    item!(
        VELOCITY_P_GAIN,
        2,
        "Velocity P Gain",
        RW,
        false,
        Some(50),
        Range::Span(0, 16383),
        ""
    ),
    item!(
        POSITION_D_GAIN,
        2,
        "Position D Gain",
        RW,
        false,
        Some(500),
        Range::Span(0, 16383),
        ""
    ),
    item!(
        POSITION_I_GAIN,
        2,
        "Position I Gain",
        RW,
        false,
        Some(0),
        Range::Span(0, 16383),
        ""
    ),
    item!(
        POSITION_P_GAIN,
        2,
        "Position P Gain",
        RW,
        false,
        Some(1100),
        Range::Span(0, 16383),
        ""
    ),
    item!(
        FEEDFORWARD_2ND_GAIN,
        2,
        "Feedforward 2nd Gain",
        RW,
        false,
        Some(0),
        Range::Span(0, 16383),
        ""
    ),
    item!(
        FEEDFORWARD_1ST_GAIN,
        2,
        "Feedforward 1st Gain",
        RW,
        false,
        Some(0),
        Range::Span(0, 16383),
        ""
    ),
    // The table prints 1..127; 0 (the initial value) disables the watchdog.
    item!(
        BUS_WATCHDOG,
        1,
        "Bus Watchdog",
        RW,
        false,
        Some(0),
        Range::Span(0, 127),
        "20 ms"
    ),
    item!(
        GOAL_PWM,
        2,
        "Goal PWM",
        RW,
        true,
        None,
        Range::PlusMinus(PWM_LIMIT),
        PWM
    ),
    item!(
        GOAL_CURRENT,
        2,
        "Goal Current",
        RW,
        true,
        None,
        Range::PlusMinus(CURRENT_LIMIT),
        MA
    ),
    item!(
        GOAL_VELOCITY,
        4,
        "Goal Velocity",
        RW,
        true,
        None,
        Range::PlusMinus(VELOCITY_LIMIT),
        RPM
    ),
    item!(
        PROFILE_ACCELERATION,
        4,
        "Profile Acceleration",
        RW,
        false,
        Some(0),
        Range::Span(0, 32767),
        "214.577 rev/min^2 (1 ms time-based)"
    ),
    item!(
        PROFILE_VELOCITY,
        4,
        "Profile Velocity",
        RW,
        false,
        Some(0),
        Range::Span(0, 32767),
        RPM
    ),
    item!(
        GOAL_POSITION,
        4,
        "Goal Position",
        RW,
        true,
        None,
        Range::Between(MIN_POSITION_LIMIT, MAX_POSITION_LIMIT),
        PULSE
    ),
    item!(
        REALTIME_TICK,
        2,
        "Realtime Tick",
        R,
        false,
        None,
        Range::Span(0, 32767),
        "1 ms"
    ),
    item!(
        MOVING,
        1,
        "Moving",
        R,
        false,
        Some(0),
        Range::Span(0, 1),
        ""
    ),
    item!(
        MOVING_STATUS,
        1,
        "Moving Status",
        R,
        false,
        Some(0),
        Range::Any,
        ""
    ),
    item!(
        PRESENT_PWM,
        2,
        "Present PWM",
        R,
        true,
        None,
        Range::Any,
        PWM
    ),
    item!(
        PRESENT_CURRENT,
        2,
        "Present Current",
        R,
        true,
        None,
        Range::Any,
        MA
    ),
    item!(
        PRESENT_VELOCITY,
        4,
        "Present Velocity",
        R,
        true,
        None,
        Range::Any,
        RPM
    ),
    item!(
        PRESENT_POSITION,
        4,
        "Present Position",
        R,
        true,
        None,
        Range::Any,
        PULSE
    ),
    item!(
        VELOCITY_TRAJECTORY,
        4,
        "Velocity Trajectory",
        R,
        true,
        None,
        Range::Any,
        RPM
    ),
    item!(
        POSITION_TRAJECTORY,
        4,
        "Position Trajectory",
        R,
        true,
        None,
        Range::Any,
        PULSE
    ),
    item!(
        PRESENT_INPUT_VOLTAGE,
        2,
        "Present Input Voltage",
        R,
        false,
        None,
        Range::Any,
        "0.1 V"
    ),
    item!(
        PRESENT_TEMPERATURE,
        1,
        "Present Temperature",
        R,
        false,
        None,
        Range::Any,
        "1 degC"
    ),
    item!(
        BACKUP_READY,
        1,
        "Backup Ready",
        R,
        false,
        None,
        Range::Span(0, 1),
        ""
    ),
];

/// The indirect items, pairs (address n, data n) in n's order.
const INDIRECT_PAIRS: [[Item; 2]; INDIRECT_COUNT as usize] = [
    indirect!(1),
    indirect!(2),
    indirect!(3),
    indirect!(4),
    indirect!(5),
    indirect!(6),
    indirect!(7),
    indirect!(8),
    indirect!(9),
    indirect!(10),
    indirect!(11),
    indirect!(12),
    indirect!(13),
    indirect!(14),
    indirect!(15),
    indirect!(16),
    indirect!(17),
    indirect!(18),
    indirect!(19),
    indirect!(20),
];

/// Every item of the XC330-M288-T in address order: the direct items, the 20 Indirect
/// Addresses (168..=207), the 20 Indirect Data (208..=227).
const fn all_items() -> [Item; COUNT] {
    let mut items = [DIRECT_ITEMS[0]; COUNT];
    let mut i = 0;
    while i < DIRECT {
        items[i] = DIRECT_ITEMS[i];
        i += 1;
    }
    let n = INDIRECT_COUNT as usize;
    let mut k = 0;
    while k < n {
        items[DIRECT + k] = INDIRECT_PAIRS[k][0];
        items[DIRECT + n + k] = INDIRECT_PAIRS[k][1];
        k += 1;
    }
    items
}

/// An item of another model that differs from the XC330-M288-T's.
struct Difference {
    addr: u16,
    init: Option<i32>,
    range: Range,
}

/// The XL330-M077-T's differences (e-manual, XL330-M077, control table).
const XL330_M077_DIFFERENCES: [Difference; 10] = [
    Difference {
        addr: MODEL_NUMBER,
        init: Some(MODEL_XL330_M077 as i32),
        range: Range::Any,
    },
    Difference {
        addr: DRIVE_MODE,
        init: Some(0),
        range: Range::Span(0, 5),
    },
    Difference {
        addr: CURRENT_LIMIT,
        init: Some(1750),
        range: Range::Span(0, 1750),
    },
    Difference {
        addr: VELOCITY_LIMIT,
        init: Some(1620),
        range: Range::Span(0, 2047),
    },
    Difference {
        addr: SHUTDOWN,
        init: Some(53),
        range: Range::Any,
    },
    Difference {
        addr: VELOCITY_I_GAIN,
        init: Some(400),
        range: Range::Span(0, 16383),
    },
    Difference {
        addr: VELOCITY_P_GAIN,
        init: Some(40),
        range: Range::Span(0, 16383),
    },
    Difference {
        addr: POSITION_D_GAIN,
        init: Some(0),
        range: Range::Span(0, 16383),
    },
    Difference {
        addr: POSITION_I_GAIN,
        init: Some(400),
        range: Range::Span(0, 16383),
    },
    Difference {
        addr: POSITION_P_GAIN,
        init: Some(400),
        range: Range::Span(0, 16383),
    },
];

const fn with_differences(mut items: [Item; COUNT], diffs: &[Difference]) -> [Item; COUNT] {
    let mut d = 0;
    while d < diffs.len() {
        let mut i = 0;
        while i < COUNT {
            if items[i].addr == diffs[d].addr {
                items[i].init = diffs[d].init;
                items[i].range = diffs[d].range;
            }
            i += 1;
        }
        d += 1;
    }
    items
}

const XC330_M288_ITEMS: [Item; COUNT] = all_items();
const XL330_M077_ITEMS: [Item; COUNT] = with_differences(all_items(), &XL330_M077_DIFFERENCES);

/// A model's control table: its items in address order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Table {
    /// The model number.
    pub model: u16,
    /// The items, in address order.
    pub items: &'static [Item],
}

/// The XC330-M288-T's control table (the LEAP Hand's servo).
pub const XC330_M288: Table = Table {
    model: MODEL_XC330_M288,
    items: &XC330_M288_ITEMS,
};

/// The XL330-M077-T's control table (same items; other initial values and ranges).
pub const XL330_M077: Table = Table {
    model: MODEL_XL330_M077,
    items: &XL330_M077_ITEMS,
};

/// The XC330-M288-T's items in address order.
pub const ITEMS: &[Item] = &XC330_M288_ITEMS;

impl Table {
    /// The table of a model number this crate knows.
    pub fn for_model(model: u16) -> Option<Table> {
        [XC330_M288, XL330_M077]
            .into_iter()
            .find(|table| table.model == model)
    }

    /// The item starting at `addr`.
    pub fn item_at(&self, addr: u16) -> Option<&'static Item> {
        let items = self.items;
        items.iter().find(|item| item.addr == addr)
    }

    /// The item that byte `addr` belongs to.
    pub fn item_containing(&self, addr: u16) -> Option<&'static Item> {
        let items = self.items;
        items.iter().find(|item| item.contains(addr))
    }

    /// The items that bytes `addr..addr + len` touch, in address order (a contiguous run of the
    /// table; bytes between items belong to none).
    pub fn items_covering(&self, addr: u16, len: u16) -> &'static [Item] {
        let items = self.items;
        let end = u32::from(addr) + u32::from(len);
        let first = items.partition_point(|item| item.end() <= addr);
        let last = items.partition_point(|item| u32::from(item.addr) < end);
        items.get(first..last.max(first)).unwrap_or(&[])
    }
}

/// The XC330-M288-T's item starting at `addr`.
pub fn item_at(addr: u16) -> Option<&'static Item> {
    XC330_M288.item_at(addr)
}

/// The XC330-M288-T's item that byte `addr` belongs to.
pub fn item_containing(addr: u16) -> Option<&'static Item> {
    XC330_M288.item_containing(addr)
}

/// The XC330-M288-T's items that bytes `addr..addr + len` touch.
pub fn items_covering(addr: u16, len: u16) -> &'static [Item] {
    XC330_M288.items_covering(addr, len)
}

/// Operating Mode (11) values (e-manual, X series, Operating Mode(11)). Switching mode resets
/// the gains and profiles to that mode's defaults and the Goal PWM/Current to their limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OperatingMode {
    /// 0: current (torque) control.
    Current,
    /// 1: velocity control.
    Velocity,
    /// 3: position control within the position limits (the default).
    Position,
    /// 4: extended (multi-turn) position control, +-256 turns.
    ExtendedPosition,
    /// 5: current-based position control: position control with the current bounded by Goal
    /// Current (the LEAP Hand's mode), +-256 turns.
    CurrentBasedPosition,
    /// 16: PWM (voltage) control.
    Pwm,
}

impl OperatingMode {
    /// The mode of a register value.
    pub fn from_value(value: u8) -> Option<Self> {
        Some(match value {
            0 => OperatingMode::Current,
            1 => OperatingMode::Velocity,
            3 => OperatingMode::Position,
            4 => OperatingMode::ExtendedPosition,
            5 => OperatingMode::CurrentBasedPosition,
            16 => OperatingMode::Pwm,
            _ => return None,
        })
    }

    /// Its register value.
    pub fn value(self) -> u8 {
        match self {
            OperatingMode::Current => 0,
            OperatingMode::Velocity => 1,
            OperatingMode::Position => 3,
            OperatingMode::ExtendedPosition => 4,
            OperatingMode::CurrentBasedPosition => 5,
            OperatingMode::Pwm => 16,
        }
    }
}

impl std::fmt::Display for OperatingMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OperatingMode::Current => "current control",
            OperatingMode::Velocity => "velocity control",
            OperatingMode::Position => "position control",
            OperatingMode::ExtendedPosition => "extended position control",
            OperatingMode::CurrentBasedPosition => "current-based position control",
            OperatingMode::Pwm => "PWM control",
        })
    }
}

/// Baud Rate (8) codes of the X330 (e-manual, X330 Baud Rate(8)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BaudRate {
    /// 0: 9600 bps.
    B9600,
    /// 1: 57 600 bps (the default).
    B57600,
    /// 2: 115 200 bps.
    B115200,
    /// 3: 1 Mbps.
    B1M,
    /// 4: 2 Mbps.
    B2M,
    /// 5: 3 Mbps.
    B3M,
    /// 6: 4 Mbps (the LEAP Hand's).
    B4M,
}

impl BaudRate {
    /// Every rate, by code.
    pub const ALL: [BaudRate; 7] = [
        BaudRate::B9600,
        BaudRate::B57600,
        BaudRate::B115200,
        BaudRate::B1M,
        BaudRate::B2M,
        BaudRate::B3M,
        BaudRate::B4M,
    ];

    /// The rate of a register code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(usize::from(code)).copied()
    }

    /// Its register code.
    pub fn code(self) -> u8 {
        self as u8
    }

    /// Bits per second.
    pub fn bps(self) -> u32 {
        match self {
            BaudRate::B9600 => 9_600,
            BaudRate::B57600 => 57_600,
            BaudRate::B115200 => 115_200,
            BaudRate::B1M => 1_000_000,
            BaudRate::B2M => 2_000_000,
            BaudRate::B3M => 3_000_000,
            BaudRate::B4M => 4_000_000,
        }
    }

    /// The rate of a bits-per-second value, if it is one of them.
    pub fn from_bps(bps: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|rate| rate.bps() == bps)
    }
}

/// Hardware Error Status (70) bits, also the Shutdown (63) mask (e-manual, X series,
/// Shutdown(63)). A bit set in Shutdown turns the torque off when its error occurs, status
/// packets carry the alert bit, and only a reboot (Reboot instruction or power cycle) lets the
/// torque on again.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct HardwareError(pub u8);

impl HardwareError {
    /// Bit 0: input voltage outside the voltage limits.
    pub const INPUT_VOLTAGE: u8 = 1 << 0;
    /// Bit 2: Present Temperature above the Temperature Limit.
    pub const OVERHEATING: u8 = 1 << 2;
    /// Bit 3: the motor encoder malfunctions.
    pub const MOTOR_ENCODER: u8 = 1 << 3;
    /// Bit 4: an electrical shock on the circuit, or too little input power.
    pub const ELECTRICAL_SHOCK: u8 = 1 << 4;
    /// Bit 5: a persistent load above the maximum output.
    pub const OVERLOAD: u8 = 1 << 5;

    /// Each bit with its words, bit order.
    pub const BITS: [(u8, &'static str); 5] = [
        (Self::INPUT_VOLTAGE, "input voltage error"),
        (Self::OVERHEATING, "overheating"),
        (Self::MOTOR_ENCODER, "motor encoder error"),
        (Self::ELECTRICAL_SHOCK, "electrical shock"),
        (Self::OVERLOAD, "overload"),
    ];

    /// Whether every bit of `bits` is set.
    pub fn contains(self, bits: u8) -> bool {
        self.0 & bits == bits
    }

    /// No error.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The words of the set bits.
    pub fn words(self) -> impl Iterator<Item = &'static str> {
        Self::BITS
            .into_iter()
            .filter(move |&(bit, _)| self.0 & bit != 0)
            .map(|(_, words)| words)
    }
}

impl std::fmt::Display for HardwareError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.is_empty() {
            return f.write_str("no hardware error");
        }
        let mut first = true;
        for words in self.words() {
            if !first {
                f.write_str(", ")?;
            }
            f.write_str(words)?;
            first = false;
        }
        let unknown = self.0 & !Self::BITS.iter().fold(0, |all, (bit, _)| all | bit);
        if unknown != 0 {
            if !first {
                f.write_str(", ")?;
            }
            write!(f, "undocumented bits 0x{unknown:02X}")?;
        }
        Ok(())
    }
}

/// Position counts per revolution.
pub const COUNTS_PER_REV: i32 = 4096;
/// Radians per position count (2 pi / 4096; 0.088 deg).
pub const RAD_PER_COUNT: f64 = std::f64::consts::TAU / COUNTS_PER_REV as f64;
/// Revolutions per minute per velocity unit.
pub const RPM_PER_VELOCITY_UNIT: f64 = 0.229;
/// Radians per second per velocity unit.
pub const RAD_S_PER_VELOCITY_UNIT: f64 = RPM_PER_VELOCITY_UNIT * std::f64::consts::TAU / 60.0;
/// Milliamperes per current unit (XC330-M288 and XL330-M077 alike). The XC330 measures the
/// current at its input supply, not the motor's phase current (e-manual, XC330-M288,
/// Current Limit(38)).
pub const MA_PER_CURRENT_UNIT: f64 = 1.0;
/// Volts per voltage unit.
pub const VOLTS_PER_VOLTAGE_UNIT: f64 = 0.1;
/// Percent per PWM unit.
pub const PERCENT_PER_PWM_UNIT: f64 = 0.113;

/// Where the state read starts: Present Current, then Present Velocity and Present Position,
/// contiguous.
pub const STATE_ADDR: u16 = PRESENT_CURRENT;
/// The state read's length: current (2), velocity (4), position (4).
pub const STATE_LEN: u16 = 10;

/// One servo's state from the 10 bytes at [`STATE_ADDR`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct State {
    /// Present Current, mA.
    pub current_ma: i16,
    /// Present Velocity, 0.229 rpm units.
    pub velocity: i32,
    /// Present Position, counts.
    pub position: i32,
}

impl State {
    /// Decodes the 10 bytes read at [`STATE_ADDR`].
    pub fn decode(bytes: &[u8]) -> Result<State, DecodeError> {
        let b: &[u8; STATE_LEN as usize] =
            bytes.try_into().map_err(|_| DecodeError::DataLength {
                what: "servo state (Present Current, Velocity, Position)",
                expected: usize::from(STATE_LEN),
                got: bytes.len(),
            })?;
        Ok(State {
            current_ma: i16::from_le_bytes([b[0], b[1]]),
            velocity: i32::from_le_bytes([b[2], b[3], b[4], b[5]]),
            position: i32::from_le_bytes([b[6], b[7], b[8], b[9]]),
        })
    }

    /// Its 10 bytes as the servo sends them.
    pub fn encode(&self) -> [u8; STATE_LEN as usize] {
        let mut out = [0u8; STATE_LEN as usize];
        out[..2].copy_from_slice(&self.current_ma.to_le_bytes());
        out[2..6].copy_from_slice(&self.velocity.to_le_bytes());
        out[6..].copy_from_slice(&self.position.to_le_bytes());
        out
    }

    /// Position in radians (count x 2 pi / 4096; 2048 counts = pi).
    pub fn position_rad(&self) -> f64 {
        f64::from(self.position) * RAD_PER_COUNT
    }

    /// Velocity in radians per second.
    pub fn velocity_rad_s(&self) -> f64 {
        f64::from(self.velocity) * RAD_S_PER_VELOCITY_UNIT
    }
}
