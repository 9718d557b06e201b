//! Ethernet / EtherCAT framing: validation and datagram layout (pure, no ESC state).

/// EtherType of EtherCAT frames.
pub const ETHERCAT_ETHERTYPE: u16 = 0x88A4;

/// Ethernet II header length (no VLAN tag).
pub(crate) const ETH_HEADER: usize = 14;
/// EtherCAT frame header length.
pub(crate) const ECAT_HEADER: usize = 2;
/// Datagram header length (command, index, address, length/flags, IRQ).
pub(crate) const DGRAM_HEADER: usize = 10;
/// Working counter length.
pub(crate) const WKC_LEN: usize = 2;
/// EtherCAT frame type "DLPDU" (datagrams).
const TYPE_DLPDU: u16 = 1;

/// Datagram commands (ETG.1000.4 table 11).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Cmd {
    Nop,
    Aprd,
    Apwr,
    Aprw,
    Fprd,
    Fpwr,
    Fprw,
    Brd,
    Bwr,
    Brw,
    Lrd,
    Lwr,
    Lrw,
    Armw,
    Frmw,
    Unknown,
}

impl Cmd {
    pub(crate) fn from_code(code: u8) -> Self {
        match code {
            0x00 => Self::Nop,
            0x01 => Self::Aprd,
            0x02 => Self::Apwr,
            0x03 => Self::Aprw,
            0x04 => Self::Fprd,
            0x05 => Self::Fpwr,
            0x06 => Self::Fprw,
            0x07 => Self::Brd,
            0x08 => Self::Bwr,
            0x09 => Self::Brw,
            0x0A => Self::Lrd,
            0x0B => Self::Lwr,
            0x0C => Self::Lrw,
            0x0D => Self::Armw,
            0x0E => Self::Frmw,
            _ => Self::Unknown,
        }
    }

    /// Logical (FMMU-mapped) command: process data.
    pub(crate) fn is_logical(self) -> bool {
        matches!(self, Self::Lrd | Self::Lwr | Self::Lrw)
    }
}

/// Why a frame was not processed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FrameError {
    /// Not an Ethernet II frame with EtherType 0x88A4.
    NotEthercat,
    /// EtherCAT frame whose header or datagram chain does not fit the frame.
    Malformed,
}

/// True for an Ethernet II frame with EtherType 0x88A4 (no VLAN tag).
pub(crate) fn is_ethercat(frame: &[u8]) -> bool {
    frame.len() >= ETH_HEADER && u16::from_be_bytes([frame[12], frame[13]]) == ETHERCAT_ETHERTYPE
}

/// Checks the EtherCAT header and the whole datagram chain before anything is executed, so that
/// a malformed frame has no side effect (a real ESC would corrupt its FCS and the MainDevice
/// would drop it). Returns the number of datagrams.
pub(crate) fn validate(frame: &[u8]) -> Result<usize, FrameError> {
    if !is_ethercat(frame) {
        return Err(FrameError::NotEthercat);
    }
    let header = frame
        .get(ETH_HEADER..ETH_HEADER + ECAT_HEADER)
        .ok_or(FrameError::Malformed)?;
    let header = u16::from_le_bytes([header[0], header[1]]);
    let len = usize::from(header & 0x07FF);
    if header >> 12 != TYPE_DLPDU {
        return Err(FrameError::Malformed);
    }
    let start = ETH_HEADER + ECAT_HEADER;
    let end = start + len;
    if end > frame.len() {
        return Err(FrameError::Malformed);
    }
    let mut offset = start;
    let mut count = 0;
    loop {
        let h = frame
            .get(offset..offset + DGRAM_HEADER)
            .ok_or(FrameError::Malformed)?;
        let flags = u16::from_le_bytes([h[6], h[7]]);
        let total = DGRAM_HEADER + usize::from(flags & 0x07FF) + WKC_LEN;
        if offset + total > end {
            return Err(FrameError::Malformed);
        }
        offset += total;
        count += 1;
        if flags & 0x8000 == 0 {
            return Ok(count);
        }
    }
}

/// Position of one datagram inside a validated frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Datagram {
    /// Offset of the datagram header in the frame.
    pub(crate) offset: usize,
    /// Data length.
    pub(crate) len: usize,
    /// More datagrams follow.
    pub(crate) more: bool,
}

impl Datagram {
    /// Reads the datagram at `offset` of a frame that passed [`validate`].
    pub(crate) fn at(frame: &[u8], offset: usize) -> Option<Self> {
        let h = frame.get(offset..offset + DGRAM_HEADER)?;
        let flags = u16::from_le_bytes([h[6], h[7]]);
        let len = usize::from(flags & 0x07FF);
        if offset + DGRAM_HEADER + len + WKC_LEN > frame.len() {
            return None;
        }
        Some(Self {
            offset,
            len,
            more: flags & 0x8000 != 0,
        })
    }

    /// Offset of the next datagram.
    pub(crate) fn next_offset(&self) -> usize {
        self.offset + DGRAM_HEADER + self.len + WKC_LEN
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(datagrams: &[u8], ecat_len: u16) -> Vec<u8> {
        let mut f = vec![0xff; 6];
        f.extend_from_slice(&[0x10; 6]);
        f.extend_from_slice(&ETHERCAT_ETHERTYPE.to_be_bytes());
        f.extend_from_slice(&(ecat_len | 0x1000).to_le_bytes());
        f.extend_from_slice(datagrams);
        f
    }

    #[test]
    fn validates_chains() {
        let one = [7, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0];
        assert_eq!(validate(&frame(&one, 13)), Ok(1));
        // More-follows set but nothing follows.
        let dangling = [7, 0, 0, 0, 0, 0, 1, 0x80, 0, 0, 0, 0, 0];
        assert_eq!(validate(&frame(&dangling, 13)), Err(FrameError::Malformed));
        // Length field beyond the frame.
        assert_eq!(validate(&frame(&one, 14)), Err(FrameError::Malformed));
        // Datagram longer than the EtherCAT length.
        assert_eq!(validate(&frame(&one, 12)), Err(FrameError::Malformed));
        // Two datagrams, with trailing padding.
        let mut two = vec![7, 0, 0, 0, 0, 0, 1, 0x80, 0, 0, 0, 0, 0];
        two.extend_from_slice(&one);
        two.extend_from_slice(&[0; 10]);
        assert_eq!(validate(&frame(&two, 26)), Ok(2));
    }

    #[test]
    fn rejects_other_ethertypes_and_types() {
        let one = [7, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0];
        let mut f = frame(&one, 13);
        f[12] = 0x08;
        f[13] = 0x00;
        assert_eq!(validate(&f), Err(FrameError::NotEthercat));
        let mut f = frame(&one, 13);
        f[15] = 0x40; // type 4 (network variables)
        assert_eq!(validate(&f), Err(FrameError::Malformed));
        assert_eq!(validate(&[0u8; 3]), Err(FrameError::NotEthercat));
    }
}
