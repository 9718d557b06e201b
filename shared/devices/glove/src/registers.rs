//! Register map of section 2.3 as typed entries, with element encoding and
//! decoding, error bits, baud rates and calibration steps.

use core::fmt;
use core::time::Duration;

use crate::frame::{Data, EncodeError, Request, MAX_DATA};

/// Element type of a register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Width {
    /// One unsigned byte per element.
    U8,
    /// One signed little-endian 16-bit word per element.
    I16,
    /// One unsigned little-endian 16-bit word per element.
    U16,
}

impl Width {
    /// Bytes per element.
    pub fn bytes(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
        }
    }
}

/// Who may write a register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Read only ("R").
    ReadOnly,
    /// Read and write ("W/R").
    ReadWrite,
}

/// One register (or register group of `count` adjacent elements).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Register {
    /// Short name, also used in errors.
    pub name: &'static str,
    /// First byte address.
    pub address: u16,
    /// Element type.
    pub width: Width,
    /// Number of elements (fingers / DoFs).
    pub count: u8,
    /// Who may write it.
    pub access: Access,
    /// Smallest regular value of an element.
    pub min: i32,
    /// Largest regular value of an element.
    pub max: i32,
    /// A value outside `min..=max` that is still accepted, with a special
    /// meaning (-1 = "leave this finger alone" for the position set-points).
    pub special: Option<i32>,
    /// Default value when the manual gives one.
    pub default: Option<i32>,
    /// Whether the value survives a save to flash ("it can be saved").
    pub savable: bool,
    /// Unit of an element, empty when the manual gives none.
    pub unit: &'static str,
    /// What the register means (paraphrased from the manual).
    pub meaning: &'static str,
}

impl Register {
    /// Number of bytes of the whole register group.
    pub fn byte_len(&self) -> usize {
        self.width.bytes() * usize::from(self.count)
    }

    /// First address after the register group (exclusive end).
    pub fn end(&self) -> u16 {
        let len = u16::try_from(self.byte_len()).unwrap_or(u16::MAX);
        self.address.saturating_add(len)
    }

    /// Whether the register may be written.
    pub fn is_writable(&self) -> bool {
        self.access == Access::ReadWrite
    }

    /// Whether `value` may be written to one element.
    pub fn accepts(&self, value: i32) -> bool {
        (self.min..=self.max).contains(&value) || self.special == Some(value)
    }
}

/// The registers of section 2.3.
pub mod reg {
    use super::{Access, Register, Width};

    const fn byte_rw(
        name: &'static str,
        address: u16,
        default: Option<i32>,
        savable: bool,
        meaning: &'static str,
    ) -> Register {
        Register {
            name,
            address,
            width: Width::U8,
            count: 1,
            access: Access::ReadWrite,
            min: 0,
            max: 1,
            special: None,
            default,
            savable,
            unit: "",
            meaning,
        }
    }

    /// 1000: device ID, 1..=254, default 1, savable (2.3.1).
    pub const ID: Register = Register {
        min: 1,
        max: 254,
        ..byte_rw(
            "id",
            1000,
            Some(1),
            true,
            "device ID; each glove on one bus needs its own",
        )
    };

    /// 1001: baud rate code (see [`BaudRate`](super::BaudRate)), 0..=2,
    /// default 0 (115200), savable (2.3.2). The manual does not say when a
    /// new rate takes effect.
    pub const BAUD_RATE: Register = Register {
        max: 2,
        ..byte_rw(
            "baud_rate",
            1001,
            Some(0),
            true,
            "baud rate: 0 = 115200, 1 = 57600, 2 = 19200",
        )
    };

    /// 1004: write 1 to clear clearable actuator errors (all but
    /// over-temperature), default 0, not savable (2.3.3).
    pub const ERROR_CLEAR: Register = byte_rw(
        "error_clear",
        1004,
        Some(0),
        false,
        "write 1 to clear locked-rotor, over-current, abnormal-operation and communication errors",
    );

    /// 1005: write 1 to save the current parameters to flash, default 0,
    /// not savable (2.3.4).
    pub const SAVE: Register = byte_rw(
        "save",
        1005,
        Some(0),
        false,
        "write 1 to save the current parameters to flash",
    );

    /// 1006: write 1 to restore factory defaults, default 0, not savable
    /// (2.3.5).
    ///
    /// Ambiguity: the register table of 2.3 omits this register although
    /// 2.3.5 describes it. 1006 is where the Inspire RH56 actuator family,
    /// whose register map this glove shares (1000 ID, 1001 baud, 1004 clear,
    /// 1005 save, 1009 calibration ...), restores defaults, so we use it.
    pub const FACTORY_RESET: Register = byte_rw(
        "factory_reset",
        1006,
        Some(0),
        false,
        "write 1 to restore the factory defaults",
    );

    /// 1009: write 1 to start the calibration of 2.3.6 (see
    /// [`CALIBRATION_STEPS`](super::CALIBRATION_STEPS)); the manual gives no
    /// default and does not say it is savable.
    pub const CALIBRATION: Register = byte_rw(
        "calibration",
        1009,
        None,
        false,
        "write 1 to start the 5-step calibration (the glove must be worn)",
    );

    /// 1472: system voltage, one 16-bit word, read-only. The manual gives
    /// neither unit nor range ("1short"); decoded as unsigned.
    pub const VOLTAGE: Register = Register {
        name: "voltage",
        address: 1472,
        width: Width::U16,
        count: 1,
        access: Access::ReadOnly,
        min: 0,
        max: u16::MAX as i32,
        special: None,
        default: None,
        savable: false,
        unit: "",
        meaning: "system voltage (unit not given by the manual)",
    };

    /// 1486..1496: position set-points little, ring, middle, index, thumb,
    /// 0..=1000 (0 = bent, 1000 = open), -1 = leave the finger alone (2.3.7).
    pub const POSITION_SET: Register = Register {
        name: "position_set",
        address: 1486,
        width: Width::I16,
        count: 5,
        access: Access::ReadWrite,
        min: 0,
        max: 1000,
        special: Some(-1),
        default: None,
        savable: false,
        unit: "",
        meaning: "position set-points (0 bent .. 1000 open, -1 = no action)",
    };

    /// 1498..1508: force set-points little, ring, middle, index, thumb,
    /// -1000..=1000; positive pushes the hand open (2.3.8).
    pub const FORCE_SET: Register = Register {
        name: "force_set",
        address: 1498,
        min: -1000,
        max: 1000,
        special: None,
        meaning: "force set-points (positive pushes the hand open)",
        ..POSITION_SET
    };

    /// 1546..1558: actual positions little, ring, middle, index, thumb,
    /// thumb rotation, 0..=1000 (2.3.9).
    pub const POSITION_ACTUAL: Register = Register {
        name: "position_actual",
        address: 1546,
        width: Width::I16,
        count: 6,
        access: Access::ReadOnly,
        min: 0,
        max: 1000,
        special: None,
        default: None,
        savable: false,
        unit: "",
        meaning:
            "actual positions of the 6 DoFs (0 bent .. 1000 open; rotation 0 inner .. 1000 outer)",
    };

    /// 1582..1592: actual forces little, ring, middle, index, thumb,
    /// -1000..=1000 (2.3.10).
    pub const FORCE_ACTUAL: Register = Register {
        name: "force_actual",
        address: 1582,
        count: 5,
        min: -1000,
        max: 1000,
        meaning: "actual forces (positive: the finger pushes towards a fist)",
        ..POSITION_ACTUAL
    };

    /// 1594..1604: actuator currents little, ring, middle, index, thumb,
    /// 0..=1000 mA (2.3.11). The manual types them "short"; the range is
    /// non-negative, so they are decoded unsigned.
    pub const CURRENT: Register = Register {
        name: "current",
        address: 1594,
        width: Width::U16,
        count: 5,
        min: 0,
        max: 1000,
        unit: "mA",
        meaning: "actuator currents",
        ..POSITION_ACTUAL
    };

    /// 1606..1611: actuator error bits (see [`ErrorBits`](super::ErrorBits))
    /// little, ring, middle, index, thumb (2.3.12).
    ///
    /// Ambiguity: the manual's table names 1609 "thumb" and 1610 "bending of
    /// the thumb", but every other table orders little, ring, middle, index,
    /// thumb and its own example calls ERROR(3) the index finger; we use
    /// little, ring, middle, index, thumb for 1606..=1610.
    pub const ERROR_CODE: Register = Register {
        name: "error_code",
        address: 1606,
        width: Width::U8,
        count: 5,
        min: 0,
        max: 0x1F,
        unit: "",
        meaning: "actuator error bits (locked rotor, over-temperature, over-current, abnormal, communication)",
        ..POSITION_ACTUAL
    };

    /// 1618..1623: actuator temperatures little, ring, middle, index, thumb,
    /// 0..=100 degC (2.3.13).
    pub const TEMPERATURE: Register = Register {
        name: "temperature",
        address: 1618,
        width: Width::U8,
        count: 5,
        min: 0,
        max: 100,
        unit: "degC",
        meaning: "actuator temperatures",
        ..POSITION_ACTUAL
    };
}

/// Every register of the map, in ascending address order.
pub const REGISTERS: &[Register] = &[
    reg::ID,
    reg::BAUD_RATE,
    reg::ERROR_CLEAR,
    reg::SAVE,
    reg::FACTORY_RESET,
    reg::CALIBRATION,
    reg::VOLTAGE,
    reg::POSITION_SET,
    reg::FORCE_SET,
    reg::POSITION_ACTUAL,
    reg::FORCE_ACTUAL,
    reg::CURRENT,
    reg::ERROR_CODE,
    reg::TEMPERATURE,
];

/// The register starting exactly at `address`.
pub fn register_at(address: u16) -> Option<&'static Register> {
    REGISTERS.iter().find(|r| r.address == address)
}

/// The register whose bytes include `address`, with the byte offset of
/// `address` inside it.
pub fn register_containing(address: u16) -> Option<(&'static Register, usize)> {
    REGISTERS
        .iter()
        .find(|r| (r.address..r.end()).contains(&address))
        .map(|r| (r, usize::from(address - r.address)))
}

/// Encodes a write of `values` (one per element) to `reg`: checks access,
/// count and range (or the special value), and returns the request.
pub fn write_request(reg: &Register, values: &[i32]) -> Result<Request, EncodeError> {
    if !reg.is_writable() {
        return Err(EncodeError::ReadOnly(reg.name));
    }
    if values.len() != usize::from(reg.count) {
        return Err(EncodeError::WrongCount {
            register: reg.name,
            expected: usize::from(reg.count),
            got: values.len(),
        });
    }
    let mut bytes = [0u8; MAX_DATA];
    let mut len = 0;
    for (index, &value) in values.iter().enumerate() {
        let out_of_range = EncodeError::ValueOutOfRange {
            register: reg.name,
            index,
            value,
        };
        if !reg.accepts(value) {
            return Err(out_of_range);
        }
        let word: [u8; 2];
        let element: &[u8] = match reg.width {
            Width::U8 => {
                word = [u8::try_from(value).map_err(|_| out_of_range)?, 0];
                &word[..1]
            }
            Width::I16 => {
                word = i16::try_from(value)
                    .map_err(|_| out_of_range)?
                    .to_le_bytes();
                &word
            }
            Width::U16 => {
                word = u16::try_from(value)
                    .map_err(|_| out_of_range)?
                    .to_le_bytes();
                &word
            }
        };
        let end = len + element.len();
        let dst = bytes
            .get_mut(len..end)
            .ok_or(EncodeError::TooMuchData(reg.byte_len()))?;
        dst.copy_from_slice(element);
        len = end;
    }
    Ok(Request::WriteRegister {
        address: reg.address,
        data: Data::new(&bytes[..len])?,
    })
}

/// The request reading the whole of `reg`. (For a hand-made register longer
/// than 255 bytes the length saturates and [`crate::encode_request`] refuses
/// it.)
pub fn read_request(reg: &Register) -> Request {
    Request::ReadRegister {
        address: reg.address,
        len: u8::try_from(reg.byte_len()).unwrap_or(u8::MAX),
    }
}

/// Most elements in one register of the map (the 6 DoF positions).
pub const MAX_VALUES: usize = 6;

/// Per-element values of one register, fixed capacity, no heap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Values {
    /// Values; only the first `count` are meaningful.
    pub values: [i32; MAX_VALUES],
    /// Number of meaningful values.
    pub count: usize,
}

impl Values {
    /// The meaningful values.
    pub fn as_slice(&self) -> &[i32] {
        &self.values[..self.count.min(MAX_VALUES)]
    }
}

/// Why a register answer could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RegisterError {
    /// The answer carries a byte count other than the register's.
    #[error("register {register} is {expected} bytes, got {got}")]
    WrongLength {
        /// Register name.
        register: &'static str,
        /// The register's byte length.
        expected: usize,
        /// Bytes received.
        got: usize,
    },
    /// A hand-made register with more elements than [`Values`] holds.
    #[error("register {register} has {count} elements, at most 6 are supported")]
    TooManyElements {
        /// Register name.
        register: &'static str,
        /// Its element count.
        count: usize,
    },
}

/// Decodes a read answer's bytes into per-element values. Values out of the
/// register's range are returned as read; only the byte count is checked.
pub fn decode_values(reg: &Register, data: &[u8]) -> Result<Values, RegisterError> {
    let count = usize::from(reg.count);
    if count > MAX_VALUES {
        return Err(RegisterError::TooManyElements {
            register: reg.name,
            count,
        });
    }
    if data.len() != reg.byte_len() {
        return Err(RegisterError::WrongLength {
            register: reg.name,
            expected: reg.byte_len(),
            got: data.len(),
        });
    }
    let mut values = Values {
        values: [0; MAX_VALUES],
        count,
    };
    let chunks = data.chunks_exact(reg.width.bytes());
    for (value, chunk) in values.values.iter_mut().zip(chunks) {
        *value = match (reg.width, chunk) {
            (Width::U8, &[b]) => i32::from(b),
            (Width::I16, &[lo, hi]) => i32::from(i16::from_le_bytes([lo, hi])),
            (Width::U16, &[lo, hi]) => i32::from(u16::from_le_bytes([lo, hi])),
            _ => 0, // unreachable: chunks_exact(width.bytes())
        };
    }
    Ok(values)
}

/// Error bits of one actuator (register [`reg::ERROR_CODE`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct ErrorBits(pub u8);

/// Names of bits 0..=7; bits 5..=7 are not defined by the manual.
const ERROR_BIT_NAMES: [&str; 8] = [
    "locked rotor",
    "over-temperature",
    "over-current",
    "abnormal motor operation",
    "communication",
    "undefined bit 5",
    "undefined bit 6",
    "undefined bit 7",
];

impl ErrorBits {
    /// Bit 0: locked-rotor error.
    pub const LOCKED_ROTOR: u8 = 1;
    /// Bit 1: over-temperature error (not clearable; clears itself when the
    /// actuator cools down).
    pub const OVER_TEMPERATURE: u8 = 2;
    /// Bit 2: over-current error.
    pub const OVER_CURRENT: u8 = 4;
    /// Bit 3: abnormal operation of the motor.
    pub const ABNORMAL: u8 = 8;
    /// Bit 4: communication error.
    pub const COMMUNICATION: u8 = 16;
    /// The bits a write of 1 to [`reg::ERROR_CLEAR`] clears (2.3.3).
    pub const CLEARABLE: u8 =
        Self::LOCKED_ROTOR | Self::OVER_CURRENT | Self::ABNORMAL | Self::COMMUNICATION;

    /// Names of the set bits, lowest bit first (bits 5..=7, undefined by the
    /// manual, are named "undefined bit N").
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        ERROR_BIT_NAMES
            .into_iter()
            .enumerate()
            .filter(move |(bit, _)| self.0 & (1 << bit) != 0)
            .map(|(_, name)| name)
    }

    /// Whether no bit is set.
    pub fn is_ok(self) -> bool {
        self.0 == 0
    }

    /// Whether writing [`reg::ERROR_CLEAR`] would clear every set bit, i.e.
    /// only clearable bits are set (true for no error). Over-temperature and
    /// the undefined bits make it false.
    pub fn is_clearable(self) -> bool {
        self.0 & !Self::CLEARABLE == 0
    }
}

impl fmt::Display for ErrorBits {
    /// The set bits' names separated by ", ", or "ok".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_ok() {
            return f.write_str("ok");
        }
        for (i, name) in self.names().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            f.write_str(name)?;
        }
        Ok(())
    }
}

/// Baud-rate codes of register [`reg::BAUD_RATE`] (2.3.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum BaudRate {
    /// Code 0: 115200 bit/s (factory default).
    B115200 = 0,
    /// Code 1: 57600 bit/s.
    B57600 = 1,
    /// Code 2: 19200 bit/s.
    B19200 = 2,
}

impl BaudRate {
    /// The rate for a register code.
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(Self::B115200),
            1 => Some(Self::B57600),
            2 => Some(Self::B19200),
            _ => None,
        }
    }

    /// The register code.
    pub fn code(self) -> u8 {
        self as u8
    }

    /// Bits per second.
    pub fn bits_per_second(self) -> u32 {
        match self {
            Self::B115200 => 115_200,
            Self::B57600 => 57_600,
            Self::B19200 => 19_200,
        }
    }

    /// The rate for a bit/s value, `None` for a rate the glove does not have.
    pub fn from_bps(bps: u32) -> Option<Self> {
        match bps {
            115_200 => Some(Self::B115200),
            57_600 => Some(Self::B57600),
            19_200 => Some(Self::B19200),
            _ => None,
        }
    }
}

/// Bits on the wire per byte: start + 8 data + stop (2.1).
pub const BITS_PER_BYTE: u64 = 10;

/// Time on the wire for `bytes` at `bps` with 10 bits per byte (start + 8
/// data + stop), rounded up to the nanosecond. `bps` 0 gives
/// [`Duration::MAX`].
pub fn wire_time(bytes: usize, bps: u32) -> Duration {
    if bps == 0 {
        return Duration::MAX;
    }
    let bits = u128::try_from(bytes).unwrap_or(u128::MAX) * u128::from(BITS_PER_BYTE);
    let nanos = bits.saturating_mul(1_000_000_000).div_ceil(u128::from(bps));
    let secs = u64::try_from(nanos / 1_000_000_000).unwrap_or(u64::MAX);
    // < 1e9, fits u32.
    let sub = (nanos % 1_000_000_000) as u32;
    Duration::new(secs, sub)
}

/// The calibration procedure started by writing 1 to
/// [`reg::CALIBRATION`] (2.3.6), paraphrased: what the operator wearing the
/// glove does at each step, and how long the step lasts (about 9 s in all).
pub const CALIBRATION_STEPS: [(&str, Duration); 5] = [
    (
        "Relax your fingers so they put no force on the glove.",
        Duration::from_secs(1),
    ),
    (
        "Let the glove open your hand; adjust until all five fingers are naturally straight.",
        Duration::from_secs(2),
    ),
    (
        "Let the glove close four fingers; adjust until they are fully clenched.",
        Duration::from_secs(2),
    ),
    (
        "Straighten the four fingers; rotate the thumb inwards to the palm and bend it as far as it goes.",
        Duration::from_secs(2),
    ),
    (
        "Pinch: thumb tip on the index finger, little, ring and middle bent like the index.",
        Duration::from_secs(2),
    ),
];
