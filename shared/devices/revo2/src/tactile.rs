//! Units of the tactile process data 0x6010 (section 2.4).

/// Newtons per raw force unit: the document's "unit is 100 * N" with the
/// example 1000 = 10 N, i.e. 0.01 N per unit.
pub const NEWTONS_PER_RAW: f32 = 0.01;
/// Upper end of the documented force range, N (normal and tangential).
pub const MAX_FORCE_N: f32 = 25.0;
/// Raw direction value marking an invalid tangential-force direction.
pub const DIRECTION_INVALID: u16 = 0xFFFF;
/// Largest valid direction, degrees.
pub const DIRECTION_MAX_DEG: u16 = 359;

/// Force in newtons of a raw normal or tangential force (0.01 N units).
///
/// Both are decoded unsigned: the table and the text ("16-bit unsigned")
/// say UINT16, only the bullet list says INT16 (ambiguity 4). Values above
/// the documented 25 N are returned as they are.
pub fn newtons(raw: u16) -> f32 {
    f32::from(raw) * NEWTONS_PER_RAW
}

/// Direction of the tangential force in degrees (0 = towards the
/// fingertip, increasing clockwise), or `None` when invalid.
///
/// 0xFFFF is the documented "invalid"; 360..=0xFFFE are undocumented and
/// also treated as invalid (ambiguity 5).
pub fn direction(raw: u16) -> Option<u16> {
    (raw <= DIRECTION_MAX_DEG).then_some(raw)
}

/// Tactile status word (0x6010:05): the low byte holds status flags, the
/// high byte a sequence number that changes whenever the sensor's data is
/// updated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct TouchStatus(pub u16);

impl TouchStatus {
    /// Low-byte flag: the raw value is invalid (bit 0).
    pub const INVALID_RAW: u8 = 1 << 0;
    /// Low-byte flag: the raw value has not been updated (bit 1).
    pub const NOT_UPDATED: u8 = 1 << 1;
    /// Low-byte flag: trigger time-out (bit 2).
    pub const TIMEOUT: u8 = 1 << 2;
    /// All documented flags.
    pub const KNOWN_FLAGS: u8 = Self::INVALID_RAW | Self::NOT_UPDATED | Self::TIMEOUT;

    /// The status flags (low byte).
    pub const fn bits(self) -> u8 {
        self.0 as u8
    }

    /// The update sequence number (high byte).
    pub const fn counter(self) -> u8 {
        (self.0 >> 8) as u8
    }

    /// Whether the raw value is flagged invalid (bit 0).
    pub const fn invalid_raw(self) -> bool {
        self.bits() & Self::INVALID_RAW != 0
    }

    /// Whether the raw value is flagged not updated (bit 1).
    pub const fn not_updated(self) -> bool {
        self.bits() & Self::NOT_UPDATED != 0
    }

    /// Whether a trigger time-out is flagged (bit 2).
    pub const fn timed_out(self) -> bool {
        self.bits() & Self::TIMEOUT != 0
    }

    /// Whether the reading can be used: none of the three documented flags
    /// is set (ambiguity 6: "not updated" counts as not valid, since the
    /// value may be stale). Undocumented bits 3..=7 are ignored.
    pub const fn is_valid(self) -> bool {
        self.bits() & Self::KNOWN_FLAGS == 0
    }

    /// Whether the sensor data changed since a previous status word (the
    /// sequence number differs).
    pub const fn updated_since(self, previous: TouchStatus) -> bool {
        self.counter() != previous.counter()
    }
}
