//! Configuration objects 0x8000 (section 3) and 0x8010 (section 4): typed
//! values for `teleop revo2 set NAME VALUE` / `get NAME`, their SDO bytes
//! and their decoding.
//!
//! Not used in the cyclic loop; values may allocate.

use core::fmt;

use crate::dictionary::{config_entry, DataType, Entry};

/// Largest value an expedited SDO download carries, bytes (the master's
/// `sdo_write` can only do expedited transfers).
pub const EXPEDITED_MAX: usize = 4;

/// A typed configuration value.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum ConfigValue {
    /// `UINT8` entries (switches, modes, calibration triggers).
    U8(u8),
    /// `UINT16` entries (protection currents).
    U16(u16),
    /// `2xUINT16` (`turbo_param`).
    U16x2([u16; 2]),
    /// `UINT32` entries (identity object, device type; read only).
    U32(u32),
    /// `STRING(n)` entries (versions, serial numbers, auth code).
    Str(String),
}

impl ConfigValue {
    /// The SDO data: little-endian integers, or the string's bytes without
    /// terminator or padding (see [`ConfigValue::to_bytes_padded`]).
    pub fn to_bytes(&self) -> Vec<u8> {
        match self {
            ConfigValue::U8(v) => vec![*v],
            ConfigValue::U16(v) => v.to_le_bytes().to_vec(),
            ConfigValue::U16x2([a, b]) => {
                let mut out = a.to_le_bytes().to_vec();
                out.extend_from_slice(&b.to_le_bytes());
                out
            }
            ConfigValue::U32(v) => v.to_le_bytes().to_vec(),
            ConfigValue::Str(s) => s.as_bytes().to_vec(),
        }
    }

    /// Like [`ConfigValue::to_bytes`], but strings are padded with NULs to
    /// `len` bytes (an entry's [`Entry::byte_len`]); never truncates.
    ///
    /// Ambiguity 19: the document does not say whether a shorter string
    /// may be downloaded. Slave stacks commonly accept a string up to the
    /// declared size, so the bare bytes are the default; use this for a
    /// device that insists on the declared size.
    pub fn to_bytes_padded(&self, len: usize) -> Vec<u8> {
        let mut out = self.to_bytes();
        if matches!(self, ConfigValue::Str(_)) && out.len() < len {
            out.resize(len, 0);
        }
        out
    }

    /// Length of [`ConfigValue::to_bytes`].
    pub fn byte_len(&self) -> usize {
        match self {
            ConfigValue::U8(_) => 1,
            ConfigValue::U16(_) => 2,
            ConfigValue::U16x2(_) | ConfigValue::U32(_) => 4,
            ConfigValue::Str(s) => s.len(),
        }
    }

    /// Whether the value can be written with an expedited SDO download
    /// (at most [`EXPEDITED_MAX`] bytes, e.g. ethercrab's `sdo_write`).
    ///
    /// Strings never are: the string objects are 8 to 20 bytes and the
    /// master must use a normal (segmented if needed) SDO download for
    /// them, even for a short value.
    pub fn fits_expedited(&self) -> bool {
        !matches!(self, ConfigValue::Str(_)) && self.byte_len() <= EXPEDITED_MAX
    }
}

impl fmt::Display for ConfigValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConfigValue::U8(v) => write!(f, "{v}"),
            ConfigValue::U16(v) => write!(f, "{v}"),
            ConfigValue::U16x2([a, b]) => write!(f, "{a},{b}"),
            ConfigValue::U32(v) => write!(f, "0x{v:08X}"),
            ConfigValue::Str(s) => f.write_str(s),
        }
    }
}

/// Why a configuration value could not be parsed or decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// No configuration entry has this name.
    #[error("unknown configuration parameter {0:?}")]
    UnknownName(String),
    /// The entry is read only.
    #[error("{0} is read only")]
    ReadOnly(&'static str),
    /// The text is not a number (decimal or 0x-hex; `a,b` for pairs).
    #[error("{name}: {text:?} is not a valid number")]
    InvalidNumber {
        /// Entry name.
        name: &'static str,
        /// The text given.
        text: String,
    },
    /// The number is outside the entry's type or documented values.
    #[error("{name}: {text} outside {min}..={max}")]
    OutOfRange {
        /// Entry name.
        name: &'static str,
        /// The text given.
        text: String,
        /// Smallest accepted value.
        min: u32,
        /// Largest accepted value.
        max: u32,
    },
    /// The string is longer than the entry.
    #[error("{name}: {got} bytes, at most {max}")]
    StringTooLong {
        /// Entry name.
        name: &'static str,
        /// Capacity of the entry, bytes.
        max: usize,
        /// Length given.
        got: usize,
    },
    /// A `VISIBLE_STRING` may only hold printable ASCII (0x20..=0x7E).
    #[error("{name}: character {ch:?} is not printable ASCII")]
    InvalidCharacter {
        /// Entry name.
        name: &'static str,
        /// The offending character.
        ch: char,
    },
    /// SDO data of the wrong size for the entry.
    #[error("{name}: {got} bytes, expected {expected}")]
    WrongLength {
        /// Entry name.
        name: &'static str,
        /// Size of the entry.
        expected: usize,
        /// Size received.
        got: usize,
    },
    /// A string read from the device is not UTF-8.
    #[error("{name}: string is not valid UTF-8")]
    InvalidUtf8 {
        /// Entry name.
        name: &'static str,
    },
    /// The entry's type has no [`ConfigValue`] form (e.g. PDO arrays).
    #[error("0x{index:04X}:{sub:02X} has no configuration value type")]
    Unsupported {
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
}

/// The shape of value an entry takes.
enum Shape {
    U8,
    U16,
    U16x2,
    U32,
    Str,
}

fn shape(entry: &Entry) -> Result<Shape, ConfigError> {
    match (entry.data_type, entry.bit_len) {
        (DataType::Uint8, 8) => Ok(Shape::U8),
        (DataType::Uint16, 16) => Ok(Shape::U16),
        (DataType::Uint16, 32) => Ok(Shape::U16x2),
        (DataType::Uint32, 32) => Ok(Shape::U32),
        (DataType::VisibleString, _) => Ok(Shape::Str),
        _ => Err(ConfigError::Unsupported {
            index: entry.index,
            sub: entry.sub,
        }),
    }
}

/// Values an entry accepts: the document's enumerations where it gives one
/// (`hand_type` 0/1, `unit_mode` 0/1, `foe_file_type` 1/2), else the
/// type's range. Switches and calibration triggers have no documented
/// values, so any byte is passed on (ambiguity 24).
fn accepted_range(entry: &Entry, type_max: u32) -> (u32, u32) {
    match entry.name {
        "hand_type" | "unit_mode" => (0, 1),
        "foe_file_type" => (1, 2),
        _ => (0, type_max),
    }
}

fn parse_number(entry: &Entry, text: &str, type_max: u32) -> Result<u32, ConfigError> {
    let t = text.trim();
    let invalid = || ConfigError::InvalidNumber {
        name: entry.name,
        text: text.to_owned(),
    };
    let value: i128 = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u64::from_str_radix(hex, 16).map_err(|_| invalid())?.into(),
        None => t.parse().map_err(|_| invalid())?,
    };
    let (min, max) = accepted_range(entry, type_max);
    match u32::try_from(value) {
        Ok(v) if (min..=max).contains(&v) => Ok(v),
        _ => Err(ConfigError::OutOfRange {
            name: entry.name,
            text: t.to_owned(),
            min,
            max,
        }),
    }
}

fn parse_u8(entry: &Entry, text: &str) -> Result<u8, ConfigError> {
    let v = parse_number(entry, text, u8::MAX.into())?;
    Ok(u8::try_from(v).unwrap_or_default())
}

fn parse_u16(entry: &Entry, text: &str) -> Result<u16, ConfigError> {
    let v = parse_number(entry, text, u16::MAX.into())?;
    Ok(u16::try_from(v).unwrap_or_default())
}

fn parse_string(entry: &Entry, text: &str) -> Result<String, ConfigError> {
    if let Some(ch) = text.chars().find(|c| !(' '..='~').contains(c)) {
        return Err(ConfigError::InvalidCharacter {
            name: entry.name,
            ch,
        });
    }
    if text.len() > entry.byte_len() {
        return Err(ConfigError::StringTooLong {
            name: entry.name,
            max: entry.byte_len(),
            got: text.len(),
        });
    }
    Ok(text.to_owned())
}

/// Parses `teleop revo2 set NAME VALUE`: finds the configuration entry
/// (0x8000 or 0x8010) with the document's parameter name `name`, refuses
/// read-only entries (write-only ones are fine) and converts `text` to the
/// entry's type, returning `(index, sub, value)`.
///
/// Numbers are decimal or `0x` hex; `turbo_param` takes two as `a,b`;
/// strings are taken verbatim (printable ASCII, at most the entry's size).
/// Strings do not fit an expedited SDO download
/// ([`ConfigValue::fits_expedited`]): the master must use a normal or
/// segmented download.
pub fn parse_config_value(name: &str, text: &str) -> Result<(u16, u8, ConfigValue), ConfigError> {
    let entry = config_entry(name).ok_or_else(|| ConfigError::UnknownName(name.to_owned()))?;
    if !entry.access.is_writable() {
        return Err(ConfigError::ReadOnly(entry.name));
    }
    let value = match shape(entry)? {
        Shape::U8 => ConfigValue::U8(parse_u8(entry, text)?),
        Shape::U16 => ConfigValue::U16(parse_u16(entry, text)?),
        Shape::U16x2 => {
            let mut parts = text.split(',');
            match (parts.next(), parts.next(), parts.next()) {
                (Some(a), Some(b), None) => {
                    ConfigValue::U16x2([parse_u16(entry, a)?, parse_u16(entry, b)?])
                }
                _ => {
                    return Err(ConfigError::InvalidNumber {
                        name: entry.name,
                        text: text.to_owned(),
                    })
                }
            }
        }
        Shape::U32 => ConfigValue::U32(parse_number(entry, text, u32::MAX)?),
        Shape::Str => ConfigValue::Str(parse_string(entry, text)?),
    };
    Ok((entry.index, entry.sub, value))
}

fn exact<const N: usize>(entry: &Entry, bytes: &[u8]) -> Result<[u8; N], ConfigError> {
    bytes.try_into().map_err(|_| ConfigError::WrongLength {
        name: entry.name,
        expected: N,
        got: bytes.len(),
    })
}

/// Decodes the data of an SDO upload of `entry` (any entry of type
/// `UINT8`, `UINT16`, `2xUINT16`, `UINT32` or `STRING`).
///
/// Integers need exactly the entry's size. Strings are read as C strings
/// (ambiguity 20): everything from the first NUL on is dropped, trailing
/// spaces are trimmed, the rest must be UTF-8; any length is accepted.
pub fn decode_config_value(entry: &Entry, bytes: &[u8]) -> Result<ConfigValue, ConfigError> {
    Ok(match shape(entry)? {
        Shape::U8 => ConfigValue::U8(u8::from_le_bytes(exact(entry, bytes)?)),
        Shape::U16 => ConfigValue::U16(u16::from_le_bytes(exact(entry, bytes)?)),
        Shape::U16x2 => {
            let [a0, a1, b0, b1] = exact::<4>(entry, bytes)?;
            ConfigValue::U16x2([u16::from_le_bytes([a0, a1]), u16::from_le_bytes([b0, b1])])
        }
        Shape::U32 => ConfigValue::U32(u32::from_le_bytes(exact(entry, bytes)?)),
        Shape::Str => {
            let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
            let text = core::str::from_utf8(bytes.get(..end).unwrap_or_default())
                .map_err(|_| ConfigError::InvalidUtf8 { name: entry.name })?;
            ConfigValue::Str(text.trim_end_matches(' ').to_owned())
        }
    })
}
