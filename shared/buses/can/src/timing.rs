//! Frame-level bus timing: how many bits a frame occupies on the wire and how long that takes.
//!
//! First principles (docs/devices/allegro.md, "Bus timing at 1 Mbit/s"): a standard data frame with
//! n bytes is 44 + 8n bits plus 3 bits of intermission = 47 + 8n; bit stuffing covers the 34 + 8n
//! bits from SOF to the end of the CRC and adds at most floor((33 + 8n) / 4) bits. An extended
//! frame has 20 more bits (SRR, IDE, 18 id bits), all inside the stuffed part. A remote frame
//! carries no data bytes whatever its DLC. [`frame_bits_exact`] builds the actual bit stream (with
//! the CRC-15) and counts the stuff bits the frame really needs.

use std::time::Duration;

use crate::{Bitrate, CanFrame};

/// Bits after the CRC that are never stuffed: CRC delimiter, ACK slot, ACK delimiter, 7 bits
/// end of frame, 3 bits intermission.
const TAIL_BITS: u32 = 1 + 2 + 7 + 3;

/// Bits from SOF to the end of the CRC, the part that is stuffed. Standard: SOF 1 + id 11 +
/// RTR 1 + IDE 1 + r0 1 + DLC 4 + CRC 15 = 34; extended: SOF 1 + base id 11 + SRR 1 + IDE 1 +
/// id 18 + RTR 1 + r1 r0 2 + DLC 4 + CRC 15 = 54; plus 8 per data byte.
fn stuffed_bits(frame: &CanFrame) -> u32 {
    let header = if frame.is_extended() { 54 } else { 34 };
    header + 8 * frame.data().len() as u32
}

/// Bits on the wire, including the 3-bit intermission: (no stuff bits, worst-case stuffing).
/// Standard data frame with n bytes: 47 + 8n .. 47 + 8n + floor((33 + 8n) / 4).
pub fn frame_bits(frame: &CanFrame) -> (u32, u32) {
    let stuffed = stuffed_bits(frame);
    let min = stuffed + TAIL_BITS;
    (min, min + (stuffed - 1) / 4)
}

/// Bits on the wire for this very frame: its bit stream (SOF to CRC, CRC-15 included) with the
/// stuff bits it needs, plus the fixed tail and intermission. Always within [`frame_bits`].
pub fn frame_bits_exact(frame: &CanFrame) -> u32 {
    // The stuffed part, most significant bit first, at most 54 + 64 = 118 bits.
    let mut bits = Bits::default();
    bits.push(0, 1); // SOF
    let id = frame.raw_id();
    let rtr = u32::from(frame.is_remote());
    if frame.is_extended() {
        bits.push(id >> 18, 11); // base id
        bits.push(1, 1); // SRR
        bits.push(1, 1); // IDE
        bits.push(id & 0x3_FFFF, 18);
        bits.push(rtr, 1);
        bits.push(0, 2); // r1, r0
    } else {
        bits.push(id, 11);
        bits.push(rtr, 1);
        bits.push(0, 1); // IDE
        bits.push(0, 1); // r0
    }
    bits.push(frame.dlc() as u32, 4);
    for &b in frame.data() {
        bits.push(u32::from(b), 8);
    }
    let crc = bits.crc15();
    bits.push(u32::from(crc), 15);
    bits.len + bits.stuff_count() + TAIL_BITS
}

/// A bit string of up to 128 bits, first bit in the most significant used position.
#[derive(Default)]
struct Bits {
    value: u128,
    len: u32,
}

impl Bits {
    fn push(&mut self, value: u32, n: u32) {
        let mask = (1u32 << n) - 1;
        self.value = (self.value << n) | u128::from(value & mask);
        self.len += n;
    }

    fn bit(&self, i: u32) -> bool {
        (self.value >> (self.len - 1 - i)) & 1 == 1
    }

    /// CAN's CRC-15 (polynomial 0x4599) over the bits so far.
    fn crc15(&self) -> u16 {
        let mut crc: u16 = 0;
        for i in 0..self.len {
            let next = self.bit(i) ^ (crc >> 14 & 1 == 1);
            crc = (crc << 1) & 0x7FFF;
            if next {
                crc ^= 0x4599;
            }
        }
        crc
    }

    /// Stuff bits a transmitter inserts: after five equal bits, one of the other value, which
    /// counts towards the next run.
    fn stuff_count(&self) -> u32 {
        let mut count = 0;
        let mut run = 0;
        let mut last = None;
        for i in 0..self.len {
            let b = self.bit(i);
            if Some(b) == last {
                run += 1;
            } else {
                run = 1;
                last = Some(b);
            }
            if run == 5 {
                count += 1;
                last = Some(!b);
                run = 1;
            }
        }
        count
    }
}

/// Worst-case time the frame occupies the bus at `bitrate` (stuffing included, intermission
/// included). A zero bit rate gives zero.
pub fn frame_time(frame: &CanFrame, bitrate: Bitrate) -> Duration {
    bits_time(frame_bits(frame).1, bitrate)
}

/// Time the frame occupies the bus at `bitrate` with the stuff bits it really needs.
pub fn frame_time_exact(frame: &CanFrame, bitrate: Bitrate) -> Duration {
    bits_time(frame_bits_exact(frame), bitrate)
}

fn bits_time(bits: u32, bitrate: Bitrate) -> Duration {
    if bitrate.0 == 0 {
        return Duration::ZERO;
    }
    Duration::from_nanos(u64::from(bits) * 1_000_000_000 / u64::from(bitrate.0))
}

/// Bus load over a window: the frames' bits (exact, see [`frame_bits_exact`]) divided by
/// what the bus could carry in the window (bit rate x window).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadMeter {
    bitrate: Bitrate,
    bits: u64,
    frames: u64,
}

impl LoadMeter {
    /// An empty meter for a bus at `bitrate`.
    pub fn new(bitrate: Bitrate) -> Self {
        Self {
            bitrate,
            bits: 0,
            frames: 0,
        }
    }

    /// Counts one frame.
    pub fn add(&mut self, frame: &CanFrame) {
        self.bits += u64::from(frame_bits_exact(frame));
        self.frames += 1;
    }

    /// Bits counted so far.
    pub fn bits(&self) -> u64 {
        self.bits
    }

    /// Frames counted so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Load (0..1 on a bus that kept up; more means the frames could not have fitted) when the
    /// counted frames were sent within `window`. Zero for an empty window or bit rate.
    pub fn load(&self, window: Duration) -> f64 {
        let capacity = f64::from(self.bitrate.0) * window.as_secs_f64();
        if capacity <= 0.0 {
            return 0.0;
        }
        self.bits as f64 / capacity
    }

    /// Starts a new window.
    pub fn reset(&mut self) {
        self.bits = 0;
        self.frames = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn std8() -> CanFrame {
        CanFrame::standard(0x3D3, &[0, 0x80, 0, 0x80, 0, 0x80, 0, 0x80]).expect("valid")
    }

    #[test]
    fn frame_lengths_match_the_documented_bit_counts() {
        // docs/devices/allegro.md: 8 bytes 111..135 bits; DLC 0 or RTR 47..55.
        assert_eq!(frame_bits(&std8()), (111, 135));
        let empty = CanFrame::standard(0x04A, &[]).expect("valid");
        assert_eq!(frame_bits(&empty), (47, 55));
        let rtr = CanFrame::standard_remote(0x200, 0).expect("valid");
        assert_eq!(frame_bits(&rtr), (47, 55));
        assert_eq!(
            frame_time(&std8(), Bitrate::MBIT_1),
            Duration::from_micros(135)
        );
        // Extended, 0 bytes: 67 bits + floor(53/4) = 13.
        let ext = CanFrame::extended(0x1234, &[]).expect("valid");
        assert_eq!(frame_bits(&ext), (67, 80));
    }

    #[test]
    fn period_budget() {
        // Four position and four torque frames per 3 ms: 0.89..1.08 ms, 30..36 % load.
        let (min, max) = frame_bits(&std8());
        assert_eq!((8 * min, 8 * max), (888, 1080));
        let mut meter = LoadMeter::new(Bitrate::MBIT_1);
        for _ in 0..8 {
            meter.add(&std8());
        }
        let load = meter.load(Duration::from_millis(3));
        assert!((0.29..=0.37).contains(&load), "{load}");
        meter.reset();
        assert_eq!(meter.load(Duration::from_millis(3)), 0.0);
    }

    #[test]
    fn crc_known_answer() {
        // All-zero standard frame id 0, DLC 0: SOF + 18 zero bits: a long run of zeros that
        // needs stuffing; exact count within bounds and above the minimum.
        let zero = CanFrame::standard(0, &[]).expect("valid");
        let exact = frame_bits_exact(&zero);
        let (min, max) = frame_bits(&zero);
        assert!(exact > min && exact <= max, "{exact}");
    }

    proptest! {
        #[test]
        fn exact_within_bounds(id in 0u32..=0x1FFF_FFFF, ext: bool, remote: bool,
                               data in proptest::collection::vec(any::<u8>(), 0..=8)) {
            let f = match (ext, remote) {
                (false, false) => CanFrame::standard((id & 0x7FF) as u16, &data),
                (false, true) => CanFrame::standard_remote((id & 0x7FF) as u16, data.len() as u8),
                (true, false) => CanFrame::extended(id, &data),
                (true, true) => CanFrame::extended_remote(id, data.len() as u8),
            }.expect("valid");
            let (min, max) = frame_bits(&f);
            let exact = frame_bits_exact(&f);
            prop_assert!(min <= exact && exact <= max, "{} {} {}", min, exact, max);
        }
    }
}
