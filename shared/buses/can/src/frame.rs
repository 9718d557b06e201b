//! The transport-neutral CAN frame: classic CAN 2.0, 11- or 29-bit id, data or remote, DLC 0..8.
//!
//! Plain data (`Copy`, 16 bytes of payload and header, no heap), so the hot path moves frames by
//! value. Implements [`embedded_can::Frame`], which is what the protocol codecs are generic over.

use std::fmt;

use embedded_can::{ExtendedId, Id, StandardId};

/// Largest 11-bit identifier.
pub const MAX_STANDARD_ID: u16 = 0x7FF;
/// Largest 29-bit identifier.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;

/// A classic CAN frame (11- or 29-bit id, data or remote, DLC 0..8).
///
/// Invariants kept by every constructor: the id fits its width, `dlc <= 8`, the data bytes past
/// the DLC (and all of them for a remote frame) are zero, so the derived equality compares
/// frames as the bus sees them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct CanFrame {
    id: u32,
    extended: bool,
    remote: bool,
    dlc: u8,
    data: [u8; 8],
}

impl CanFrame {
    /// A standard (11-bit) data frame; `None` when `id > 0x7FF` or more than 8 bytes.
    pub fn standard(id: u16, data: &[u8]) -> Option<Self> {
        (id <= MAX_STANDARD_ID).then_some(())?;
        Self::with_data(u32::from(id), false, data)
    }

    /// A standard (11-bit) remote frame asking for `dlc` bytes; `None` when `id > 0x7FF` or
    /// `dlc > 8`.
    pub fn standard_remote(id: u16, dlc: u8) -> Option<Self> {
        (id <= MAX_STANDARD_ID).then_some(())?;
        Self::remote_frame(u32::from(id), false, dlc)
    }

    /// An extended (29-bit) data frame; `None` when `id > 0x1FFF_FFFF` or more than 8 bytes.
    pub fn extended(id: u32, data: &[u8]) -> Option<Self> {
        (id <= MAX_EXTENDED_ID).then_some(())?;
        Self::with_data(id, true, data)
    }

    /// An extended (29-bit) remote frame; `None` when `id > 0x1FFF_FFFF` or `dlc > 8`.
    pub fn extended_remote(id: u32, dlc: u8) -> Option<Self> {
        (id <= MAX_EXTENDED_ID).then_some(())?;
        Self::remote_frame(id, true, dlc)
    }

    fn with_data(id: u32, extended: bool, data: &[u8]) -> Option<Self> {
        if data.len() > 8 {
            return None;
        }
        let mut bytes = [0u8; 8];
        bytes[..data.len()].copy_from_slice(data);
        Some(Self {
            id,
            extended,
            remote: false,
            // At most 8, checked above.
            dlc: data.len() as u8,
            data: bytes,
        })
    }

    fn remote_frame(id: u32, extended: bool, dlc: u8) -> Option<Self> {
        (dlc <= 8).then_some(Self {
            id,
            extended,
            remote: true,
            dlc,
            data: [0; 8],
        })
    }

    /// The identifier as a number (11 or 29 bits; see [`Self::is_extended`]).
    pub fn raw_id(&self) -> u32 {
        self.id
    }

    /// True for a 29-bit identifier.
    pub fn is_extended(&self) -> bool {
        self.extended
    }

    /// True for a remote (RTR) frame.
    pub fn is_remote(&self) -> bool {
        self.remote
    }

    /// The data length code, 0..=8 (for a remote frame: the length asked for).
    pub fn dlc(&self) -> usize {
        usize::from(self.dlc)
    }

    /// The payload; empty for remote frames.
    pub fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..usize::from(self.dlc)]
        }
    }
}

impl embedded_can::Frame for CanFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        match id.into() {
            Id::Standard(id) => Self::standard(id.as_raw(), data),
            Id::Extended(id) => Self::extended(id.as_raw(), data),
        }
    }

    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        let dlc = u8::try_from(dlc).ok()?;
        match id.into() {
            Id::Standard(id) => Self::standard_remote(id.as_raw(), dlc),
            Id::Extended(id) => Self::extended_remote(id.as_raw(), dlc),
        }
    }

    fn is_extended(&self) -> bool {
        self.extended
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> Id {
        // The constructors keep the id within its width, so these never fall back.
        if self.extended {
            Id::Extended(ExtendedId::new(self.id).unwrap_or(ExtendedId::ZERO))
        } else {
            let id = u16::try_from(self.id).unwrap_or(0);
            Id::Standard(StandardId::new(id).unwrap_or(StandardId::ZERO))
        }
    }

    fn dlc(&self) -> usize {
        usize::from(self.dlc)
    }

    fn data(&self) -> &[u8] {
        CanFrame::data(self)
    }
}

/// candump style: `3D3#0080008000800080`, `12345678#11` (29-bit ids with 8 digits), `200#R`
/// (remote, DLC 0) or `200#R3` (remote asking for 3 bytes). Upper-case hex.
impl fmt::Display for CanFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.extended {
            write!(f, "{:08X}#", self.id)?;
        } else {
            write!(f, "{:03X}#", self.id)?;
        }
        if self.remote {
            f.write_str("R")?;
            if self.dlc > 0 {
                write!(f, "{}", self.dlc)?;
            }
            return Ok(());
        }
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_can::Frame as _;

    #[test]
    fn constructors_check_ranges() {
        assert!(CanFrame::standard(0x7FF, &[1; 8]).is_some());
        assert!(CanFrame::standard(0x800, &[]).is_none());
        assert!(CanFrame::standard(0x100, &[0; 9]).is_none());
        assert!(CanFrame::standard_remote(0x200, 9).is_none());
        assert!(CanFrame::extended(0x1FFF_FFFF, &[]).is_some());
        assert!(CanFrame::extended(0x2000_0000, &[]).is_none());
        let r = CanFrame::standard_remote(0x200, 7).expect("valid");
        assert!(r.is_remote());
        assert_eq!(r.dlc(), 7);
        assert!(r.data().is_empty());
    }

    #[test]
    fn embedded_can_frame_round_trip() {
        let id = StandardId::new(0x3D3).expect("11 bits");
        let f = CanFrame::new(id, &[1, 2, 3]).expect("valid");
        assert_eq!(f.id(), Id::Standard(id));
        assert_eq!(embedded_can::Frame::data(&f), &[1, 2, 3]);
        let e =
            CanFrame::new_remote(ExtendedId::new(0x1234_5678).expect("29 bits"), 2).expect("valid");
        assert!(e.is_extended() && e.is_remote_frame());
        assert_eq!(e.raw_id(), 0x1234_5678);
        assert!(CanFrame::new_remote(id, 9).is_none());
    }

    #[test]
    fn display_is_candump_style() {
        let f = CanFrame::standard(0x3D3, &[0, 0x80, 0, 0x80, 0, 0x80, 0, 0x80]).expect("valid");
        assert_eq!(f.to_string(), "3D3#0080008000800080");
        assert_eq!(
            CanFrame::standard_remote(0x200, 0)
                .expect("valid")
                .to_string(),
            "200#R"
        );
        assert_eq!(
            CanFrame::standard_remote(0x200, 3)
                .expect("valid")
                .to_string(),
            "200#R3"
        );
        assert_eq!(
            CanFrame::extended(0xABCDE, &[0x11])
                .expect("valid")
                .to_string(),
            "000ABCDE#11"
        );
        assert_eq!(
            CanFrame::standard(0x4A, &[]).expect("valid").to_string(),
            "04A#"
        );
    }
}
