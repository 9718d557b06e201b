//! Sizes and times on the wire: what a host needs for timeouts and wire-time budgets.
//!
//! UART 8N1 carries 10 bits per byte (ROBOTIS e-manual, Protocol 2.0, "Instruction Packet");
//! a device answers after its Return Delay Time, register value x 2 us (e-manual, XC330-M288,
//! control table, Return Delay Time(9)). Sizes here are before byte stuffing, which adds one
//! byte per `FF FF FD` in an instruction packet (none in a Fast Sync Read reply).

use crate::packet::{MIN_PACKET, PREFIX_LEN};

/// Bits per byte on the line: start, 8 data, stop.
pub const BITS_PER_BYTE: u64 = 10;

/// Nanoseconds one byte takes at `baud` bits per second (rounded up; 0 baud gives `u64::MAX`).
pub fn byte_time_ns(baud: u32) -> u64 {
    if baud == 0 {
        return u64::MAX;
    }
    (BITS_PER_BYTE * 1_000_000_000).div_ceil(u64::from(baud))
}

/// Nanoseconds `bytes` take at `baud` (saturating).
pub fn wire_time_ns(bytes: usize, baud: u32) -> u64 {
    byte_time_ns(baud).saturating_mul(bytes as u64)
}

/// Bytes of an instruction packet with `n_params` parameter bytes (before stuffing).
pub fn packet_len(n_params: usize) -> usize {
    MIN_PACKET + n_params
}

/// Bytes of a status packet with `n_params` data bytes after the error byte (before stuffing).
pub fn status_len(n_params: usize) -> usize {
    packet_len(1 + n_params)
}

/// Bytes of a Sync Read or Fast Sync Read request for `n` devices.
pub fn sync_read_len(n: usize) -> usize {
    packet_len(4 + n)
}

/// Bytes of a Sync Write of `data_len` bytes to `n` devices (before stuffing).
pub fn sync_write_len(n: usize, data_len: usize) -> usize {
    packet_len(4 + n * (1 + data_len))
}

/// Bytes of the combined Fast Sync Read reply of `n` devices with `data_len` bytes each:
/// header, ID, LEN, INST, then `n` blocks of ERR, ID, data and CRC.
pub fn fast_sync_reply_len(n: usize, data_len: usize) -> usize {
    PREFIX_LEN + 1 + n * (data_len + 4)
}

/// The Return Delay Time register's value in microseconds (value x 2 us).
pub fn return_delay_us(register: u8) -> u32 {
    u32::from(register) * 2
}
