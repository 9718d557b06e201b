//! The CRC-16 of Protocol 2.0 (ROBOTIS e-manual, Protocol 2.0, "CRC").
//!
//! Polynomial 0x8005 (x^16 + x^15 + x^2 + 1), initial value 0, most significant bit first, no
//! reflection, no final XOR (the catalogue's CRC-16/UMTS, also called CRC-16/BUYPASS). It covers
//! every byte of a packet from the header's first 0xFF to the last parameter, after byte
//! stuffing, and is sent low byte first.

/// The table of the e-manual's (and the ROBOTIS SDK's `updateCRC`) byte-wise algorithm, built at
/// compile time from the polynomial.
const TABLE: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ POLYNOMIAL
            } else {
                crc << 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
};

/// The generator polynomial, without its x^16 term.
pub const POLYNOMIAL: u16 = 0x8005;

/// Continues the CRC `crc` over `bytes` (start a packet with 0). Running: `crc16(crc16(0, a), b)`
/// equals `crc16(0, a ++ b)`, which is how the Fast Sync Read reply's per-block CRCs are made.
pub fn crc16(crc: u16, bytes: &[u8]) -> u16 {
    bytes.iter().fold(crc, |crc, &byte| {
        (crc << 8) ^ TABLE[usize::from((crc >> 8) as u8 ^ byte)]
    })
}
