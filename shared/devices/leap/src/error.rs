//! The crate's two error types: why a packet was not encoded, and why bytes were not decoded.
//! Both are small and `Copy`, so a control loop can count them without allocating.

/// Why a packet was not encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// The output buffer is too small (`need` is the size known when it ran out: at least that
    /// much is needed).
    #[error("output buffer of {have} bytes is too small: at least {need} needed")]
    BufferTooSmall {
        /// Bytes needed (a lower bound when the packet's items come from an iterator).
        need: usize,
        /// Bytes given.
        have: usize,
    },
    /// An ID no packet may carry: 0xFD and 0xFF are unused (0..=0xFC devices, 0xFE broadcast).
    #[error("ID {0} (0x{0:02X}) is not a device ID (0..=252) nor broadcast (254)")]
    BadId(u8),
    /// The packet's LEN field would exceed [`crate::packet::MAX_LEN`].
    #[error("packet LEN {len} exceeds the maximum {max}")]
    TooLong {
        /// The LEN the packet would have.
        len: usize,
        /// The maximum.
        max: usize,
    },
    /// A Sync Write item or Fast Sync Read block whose data is not the common length.
    #[error("ID {id}: {got} data bytes, the packet's items carry {expected}")]
    ItemLength {
        /// The item's ID.
        id: u8,
        /// The common length.
        expected: usize,
        /// The item's length.
        got: usize,
    },
    /// A Fast Sync Read reply without any block.
    #[error("a Fast Sync Read reply needs at least one block")]
    NoBlocks,
}

/// Why bytes were not decoded. Every decoder of this crate returns a value or one of these,
/// for any input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Fewer bytes than the smallest packet (or than the header, LEN and instruction need).
    #[error("{len} bytes are too short for a packet (at least {min})")]
    Short {
        /// Bytes given.
        len: usize,
        /// The minimum.
        min: usize,
    },
    /// The first four bytes are not `FF FF FD 00`.
    #[error("no packet header (FF FF FD 00) at the start")]
    Header,
    /// An ID byte no packet carries (0xFD, 0xFF).
    #[error("ID byte 0x{0:02X} is not a device ID nor broadcast")]
    BadId(u8),
    /// The LEN field disagrees with the packet's size, or is below the minimum of 3.
    #[error("LEN field {field} does not fit a packet of {bytes} bytes")]
    Length {
        /// The LEN field.
        field: u16,
        /// The packet's size in bytes.
        bytes: usize,
    },
    /// The CRC does not match the bytes.
    #[error("CRC mismatch: computed 0x{computed:04X}, received 0x{received:04X}")]
    Crc {
        /// CRC computed over the received bytes.
        computed: u16,
        /// CRC in the packet.
        received: u16,
    },
    /// `FF FF FD` inside the instruction and parameters not followed by the stuffed `FD`.
    #[error("FF FF FD not followed by a stuffing FD at byte {offset}")]
    Stuffing {
        /// Offset in the packet of the byte after `FF FF FD`.
        offset: usize,
    },
    /// The caller's scratch buffer is too small for the parameters.
    #[error("scratch of {have} bytes is too small for {need} parameter bytes")]
    Scratch {
        /// Bytes needed.
        need: usize,
        /// Bytes given.
        have: usize,
    },
    /// A packet that is not a status packet where one is expected.
    #[error("instruction 0x{0:02X} where a status packet (0x55) is expected")]
    NotStatus(u8),
    /// A status packet where an instruction packet is expected.
    #[error("a status packet where an instruction packet is expected")]
    NotInstruction,
    /// A status packet without its error byte.
    #[error("status packet without an error byte")]
    NoErrorByte,
    /// An instruction whose parameters have the wrong length for it.
    #[error("instruction 0x{instruction:02X}: {len} parameter bytes do not fit its layout")]
    Params {
        /// The instruction.
        instruction: u8,
        /// Parameter bytes received.
        len: usize,
    },
    /// A status packet that is not a combined Fast Sync Read reply (ID 0xFE).
    #[error("status from ID {0}: a Fast Sync Read reply comes from ID 254")]
    NotFastSync(u8),
    /// A Fast Sync Read reply whose length is not a whole number of blocks of the requested data
    /// length.
    #[error("Fast Sync Read reply LEN {len} is not 1 + N x ({data_len} + 4)")]
    FastSyncLength {
        /// The reply's LEN field.
        len: usize,
        /// The data length requested.
        data_len: u16,
    },
    /// A Fast Sync Read block whose own CRC does not match.
    #[error("Fast Sync Read block {index} (ID {id}): CRC computed 0x{computed:04X}, received 0x{received:04X}")]
    BlockCrc {
        /// Index of the block in the reply.
        index: usize,
        /// The block's ID byte.
        id: u8,
        /// CRC computed from the header through the block's data.
        computed: u16,
        /// CRC in the block.
        received: u16,
    },
    /// A value of the wrong size (a state read, a control table item).
    #[error("{what}: {got} bytes, expected {expected}")]
    DataLength {
        /// What was decoded.
        what: &'static str,
        /// Bytes expected.
        expected: usize,
        /// Bytes given.
        got: usize,
    },
}
