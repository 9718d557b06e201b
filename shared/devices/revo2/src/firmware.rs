//! FoE firmware upgrade (section 6): boards, authentication codes, file
//! names and the 16-byte firmware file header.

use core::fmt;

use crate::config::ConfigValue;
use crate::dictionary::obj;

/// Length of the firmware file header (section 6.5).
pub const HEADER_LEN: usize = 16;

/// 0x8000:15 `foe_file_type` (write before the FoE transfer).
pub const FOE_FILE_TYPE: (u16, u8) = (obj::CONFIG, 0x15);
/// 0x8000:16 `foe_auth_code` (write before the FoE transfer).
pub const FOE_AUTH_CODE: (u16, u8) = (obj::CONFIG, 0x16);

/// A firmware version (major, minor, patch).
pub type Version = (u8, u8, u8);

/// The board a firmware image is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Board {
    /// Wrist board: magic and auth code "BRCW2025", file
    /// `Revo2EC_x.x.x_$time.bin`, FoE file type 1.
    Wrist,
    /// Control board: magic and auth code "BRCC2025", file
    /// `Revo2_Vx.x.x_$time.bin`, FoE file type 2.
    Control,
}

impl Board {
    /// Both boards.
    pub const ALL: [Board; 2] = [Board::Wrist, Board::Control];

    /// The 8-byte magic number of the file header (section 6.5).
    pub const fn magic(self) -> &'static [u8; 8] {
        match self {
            Board::Wrist => b"BRCW2025",
            Board::Control => b"BRCC2025",
        }
    }

    /// The FoE authentication code for 0x8000:16 (section 6.1); the same
    /// text as the magic number.
    pub const fn auth_code(self) -> &'static str {
        match self {
            Board::Wrist => "BRCW2025",
            Board::Control => "BRCC2025",
        }
    }

    /// The value for `foe_file_type` 0x8000:15. The table of section 3.3
    /// and step 1 of section 6.2 agree: 1 = wrist board, 2 = control
    /// board (ambiguity 22).
    pub const fn foe_file_type(self) -> u8 {
        match self {
            Board::Wrist => 1,
            Board::Control => 2,
        }
    }

    /// The board of a `foe_file_type` value.
    pub const fn from_foe_file_type(v: u8) -> Option<Board> {
        match v {
            1 => Some(Board::Wrist),
            2 => Some(Board::Control),
            _ => None,
        }
    }

    /// The board whose magic number is `magic`.
    pub fn from_magic(magic: &[u8]) -> Option<Board> {
        Board::ALL.into_iter().find(|b| b.magic() == magic)
    }

    /// The fixed start of the board's firmware file names.
    pub const fn file_name_prefix(self) -> &'static str {
        match self {
            Board::Wrist => "Revo2EC_",
            Board::Control => "Revo2_V",
        }
    }

    /// The two SDO writes that precede the FoE transfer (section 6.2 step
    /// 1), in order: file type, then authentication code. The code is a
    /// string and needs a normal SDO download (8 bytes, not expedited).
    pub fn foe_prelude(self) -> [(u16, u8, ConfigValue); 2] {
        [
            (
                FOE_FILE_TYPE.0,
                FOE_FILE_TYPE.1,
                ConfigValue::U8(self.foe_file_type()),
            ),
            (
                FOE_AUTH_CODE.0,
                FOE_AUTH_CODE.1,
                ConfigValue::Str(self.auth_code().to_owned()),
            ),
        ]
    }
}

impl fmt::Display for Board {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Board::Wrist => "wrist board",
            Board::Control => "control board",
        })
    }
}

/// Byte order of the 4-byte version field of the file header.
///
/// Ambiguity 15: section 6.5 says "the highest byte is reserved (0x00), the
/// last three bytes are major, minor, patch; 1.2.3 is 0x00010203". Read as
/// a `uint32_t` written by the (PC) packaging tool and checked by the
/// (ARM) firmware, both little-endian, the file holds `03 02 01 00`:
/// [`VersionByteOrder::LittleEndian`], the default. If real files show
/// `00 01 02 03`, use [`VersionByteOrder::BigEndian`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum VersionByteOrder {
    /// File bytes `patch, minor, major, 0`.
    #[default]
    LittleEndian,
    /// File bytes `0, major, minor, patch`.
    BigEndian,
}

/// Why a firmware file or file name was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FirmwareError {
    /// Fewer than [`HEADER_LEN`] bytes.
    #[error("firmware file has {got} bytes, shorter than the {HEADER_LEN}-byte header")]
    TooShort {
        /// Bytes available.
        got: usize,
    },
    /// The magic number is neither "BRCW2025" nor "BRCC2025".
    #[error("unknown firmware magic {0:02X?}")]
    UnknownMagic([u8; 8]),
    /// The reserved (highest) byte of the version is not 0.
    #[error("reserved version byte is 0x{0:02X}, expected 0")]
    ReservedVersionByte(u8),
    /// The reserved field is not all zeros.
    #[error("reserved header field is {0:02X?}, expected zeros")]
    ReservedField([u8; 4]),
    /// The file (or its name) is for the other board.
    #[error("firmware is for the {found}, expected the {expected}")]
    WrongBoard {
        /// The board asked for.
        expected: Board,
        /// The board of the file.
        found: Board,
    },
    /// The file name does not follow section 6.1.
    #[error("bad firmware file name {name:?}: {reason}")]
    BadFileName {
        /// The name given.
        name: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// The version in the file name differs from the header's.
    #[error("file name says version {name:?}, header says {header:?}")]
    VersionMismatch {
        /// Version from the file name.
        name: Version,
        /// Version from the header.
        header: Version,
    },
}

/// The 16-byte header the packaging tool puts in front of every firmware
/// image (section 6.5): magic, version, reserved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FirmwareHeader {
    /// Board, from the magic number.
    pub board: Board,
    /// (major, minor, patch).
    pub version: Version,
    /// Reserved field, zeros (parsing refuses anything else).
    pub reserved: [u8; 4],
}

impl FirmwareHeader {
    /// A header with a zero reserved field.
    pub const fn new(board: Board, version: Version) -> FirmwareHeader {
        FirmwareHeader {
            board,
            version,
            reserved: [0; 4],
        }
    }

    /// Parses the header at the start of a firmware file (little-endian
    /// version, see [`VersionByteOrder`]). Bytes after the header are the
    /// image and are ignored.
    pub fn parse(bytes: &[u8]) -> Result<FirmwareHeader, FirmwareError> {
        FirmwareHeader::parse_with(bytes, VersionByteOrder::default())
    }

    /// Parses the header with an explicit version byte order.
    pub fn parse_with(
        bytes: &[u8],
        order: VersionByteOrder,
    ) -> Result<FirmwareHeader, FirmwareError> {
        let Some((header, _)) = bytes.split_first_chunk::<HEADER_LEN>() else {
            return Err(FirmwareError::TooShort { got: bytes.len() });
        };
        let [m0, m1, m2, m3, m4, m5, m6, m7, v0, v1, v2, v3, r0, r1, r2, r3] = *header;
        let magic = [m0, m1, m2, m3, m4, m5, m6, m7];
        let board = Board::from_magic(&magic).ok_or(FirmwareError::UnknownMagic(magic))?;
        let (high, major, minor, patch) = match order {
            VersionByteOrder::LittleEndian => (v3, v2, v1, v0),
            VersionByteOrder::BigEndian => (v0, v1, v2, v3),
        };
        if high != 0 {
            return Err(FirmwareError::ReservedVersionByte(high));
        }
        let reserved = [r0, r1, r2, r3];
        if reserved != [0; 4] {
            return Err(FirmwareError::ReservedField(reserved));
        }
        Ok(FirmwareHeader {
            board,
            version: (major, minor, patch),
            reserved,
        })
    }

    /// The header bytes (little-endian version).
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        self.to_bytes_with(VersionByteOrder::default())
    }

    /// The header bytes with an explicit version byte order.
    pub fn to_bytes_with(&self, order: VersionByteOrder) -> [u8; HEADER_LEN] {
        let (major, minor, patch) = self.version;
        let version = match order {
            VersionByteOrder::LittleEndian => [patch, minor, major, 0],
            VersionByteOrder::BigEndian => [0, major, minor, patch],
        };
        let mut out = [0; HEADER_LEN];
        for (dst, src) in out.iter_mut().zip(
            self.board
                .magic()
                .iter()
                .chain(&version)
                .chain(&self.reserved),
        ) {
            *dst = *src;
        }
        out
    }

    /// `Ok(self)` if the header is for `board`, else
    /// [`FirmwareError::WrongBoard`] (the device's own check, section 6.5).
    pub fn expect_board(self, board: Board) -> Result<FirmwareHeader, FirmwareError> {
        if self.board == board {
            Ok(self)
        } else {
            Err(FirmwareError::WrongBoard {
                expected: board,
                found: self.board,
            })
        }
    }
}

fn parse_version_part(part: &str) -> Option<u8> {
    if part.is_empty() || part.len() > 3 || !part.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    part.parse().ok()
}

/// Parses a firmware file name of section 6.1 (case-sensitive, exact):
/// `Revo2EC_x.x.x_$time.bin` (wrist board) or `Revo2_Vx.x.x_$time.bin`
/// (control board), giving the board and version.
///
/// Ambiguity 21: `x` is each 1 to 3 decimal digits (0..=255, a header
/// byte); `$time` is 10 digits (`YYMMDDhhmm` as in the example
/// `2506231346`) or 12 (`YYYYMMDDhhmm`), not checked as a date.
pub fn parse_file_name(name: &str) -> Result<(Board, Version), FirmwareError> {
    let bad = |reason| FirmwareError::BadFileName {
        name: name.to_owned(),
        reason,
    };
    let (board, rest) = Board::ALL
        .into_iter()
        .find_map(|b| name.strip_prefix(b.file_name_prefix()).map(|r| (b, r)))
        .ok_or_else(|| bad("must start with \"Revo2EC_\" (wrist) or \"Revo2_V\" (control)"))?;
    let rest = rest
        .strip_suffix(".bin")
        .ok_or_else(|| bad("must end with \".bin\""))?;
    let (version, time) = rest
        .split_once('_')
        .ok_or_else(|| bad("no \"_\" between version and time"))?;
    let mut parts = version.split('.').map(parse_version_part);
    let version = match (parts.next(), parts.next(), parts.next(), parts.next()) {
        (Some(Some(major)), Some(Some(minor)), Some(Some(patch)), None) => (major, minor, patch),
        _ => return Err(bad("version must be major.minor.patch, each 0..=255")),
    };
    if !(time.len() == 10 || time.len() == 12) || !time.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad("time must be 10 or 12 digits"));
    }
    Ok((board, version))
}

/// Checks that `name` is a valid firmware file name for `board` and gives
/// its version ([`FirmwareError::WrongBoard`] for a valid name of the
/// other board).
pub fn check_file_name(name: &str, board: Board) -> Result<Version, FirmwareError> {
    let (found, version) = parse_file_name(name)?;
    if found != board {
        return Err(FirmwareError::WrongBoard {
            expected: board,
            found,
        });
    }
    Ok(version)
}

/// Checks a firmware file before an FoE upload: its name, its header's
/// board, and that the name's version equals the header's. The whole file,
/// header included, is what the master sends over FoE (the device strips
/// the header itself, section 6.5; ambiguity 23).
pub fn check_firmware(
    name: &str,
    bytes: &[u8],
    board: Board,
    order: VersionByteOrder,
) -> Result<FirmwareHeader, FirmwareError> {
    let name_version = check_file_name(name, board)?;
    let header = FirmwareHeader::parse_with(bytes, order)?.expect_board(board)?;
    if header.version != name_version {
        return Err(FirmwareError::VersionMismatch {
            name: name_version,
            header: header.version,
        });
    }
    Ok(header)
}
