//! How long a reply may take (pure): its bytes on the wire at the baud rate, each replying
//! servo's Return Delay Time, and a configured slack for the USB adapter and scheduling; never
//! the ROBOTIS SDK's fixed 2 x 16 ms latency allowance (docs/devices/leap.md, "What the SDK does").

use std::time::Duration;

use teleop_leap_protocol::wire;

/// The line's timing: byte time, return delay, slack.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timing {
    byte_ns: u64,
    return_delay_ns: u64,
    slack: Duration,
}

impl Timing {
    /// The timing at `baud` bits per second (8N1), with the servos' Return Delay Time register at
    /// `return_delay` (2 us units) and `slack` added to every reply's timeout.
    pub fn new(baud: u32, return_delay: u8, slack: Duration) -> Self {
        Self {
            byte_ns: wire::byte_time_ns(baud),
            return_delay_ns: u64::from(wire::return_delay_us(return_delay)) * 1000,
            slack,
        }
    }

    /// `bytes` on the wire.
    pub fn wire(&self, bytes: usize) -> Duration {
        Duration::from_nanos(self.byte_ns.saturating_mul(bytes as u64))
    }

    /// The timeout of a reply of `rx_bytes` from `repliers` servos to a request of `tx_bytes`,
    /// counted from the start of sending it. Each replier's return delay is counted: whether the
    /// servos of a Fast Sync Read chain each wait theirs is not documented (docs/devices/leap.md,
    /// "Unknown"), so the timeout allows it.
    pub fn reply(&self, tx_bytes: usize, rx_bytes: usize, repliers: usize) -> Duration {
        self.wire(tx_bytes + rx_bytes)
            + Duration::from_nanos(self.return_delay_ns.saturating_mul(repliers as u64))
            + self.slack
    }
}

/// Buckets of [`P99`]: 50 us wide, the last one 5 ms and more.
const BUCKETS: usize = 101;
/// Width of a [`P99`] bucket, microseconds.
const BUCKET_US: u128 = 50;

/// The 99th percentile of a run of durations, from a histogram (no allocation): every `window`
/// samples, the upper edge of the bucket holding it, in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct P99 {
    histogram: [u32; BUCKETS],
    count: u32,
    window: u32,
}

impl P99 {
    /// A percentile over windows of `window` samples (at least 1).
    pub fn new(window: u32) -> Self {
        Self {
            histogram: [0; BUCKETS],
            count: 0,
            window: window.max(1),
        }
    }

    /// Counts `d`; at the end of a window its 99th percentile (and a new window starts).
    pub fn add(&mut self, d: Duration) -> Option<u32> {
        let bucket = (d.as_micros() / BUCKET_US).min(BUCKETS as u128 - 1) as usize;
        self.histogram[bucket] += 1;
        self.count += 1;
        if self.count < self.window {
            return None;
        }
        // The top 1% (at least one sample): the bucket where they start.
        let mut top = self.count - self.count * 99 / 100;
        let mut p99 = BUCKETS - 1;
        for (b, n) in self.histogram.iter().enumerate().rev() {
            if *n >= top {
                p99 = b;
                break;
            }
            top -= n;
        }
        *self = Self::new(self.window);
        Some((p99 as u32 + 1) * BUCKET_US as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_state_cycle_at_4_mbit_fits_in_a_millisecond_on_the_wire() {
        let t = Timing::new(4_000_000, 0, Duration::ZERO);
        // 10 bits per byte at 4 Mbit/s: 2.5 us.
        assert_eq!(t.wire(4), Duration::from_micros(10));
        let write = wire::packet_len(4 + 16 * 5);
        let request = wire::packet_len(4 + 16);
        let reply = wire::fast_sync_reply_len(16, 10);
        assert_eq!((write, request, reply), (94, 30, 232));
        let total = t.wire(write) + t.reply(request, reply, 16);
        assert_eq!(total, Duration::from_nanos(2500 * (94 + 30 + 232)));
        assert!(total < Duration::from_millis(1), "{total:?}");
    }

    #[test]
    fn return_delay_and_slack_are_added_per_replier() {
        // The servos' default: 250 = 500 us each.
        let t = Timing::new(1_000_000, 250, Duration::from_micros(300));
        let ping = t.reply(10, 14, 1);
        assert_eq!(ping, Duration::from_micros(24 * 10 + 500 + 300));
        let all = t.reply(30, 232, 16);
        assert_eq!(all, Duration::from_micros(262 * 10 + 16 * 500 + 300));
        // Slow rates: 9600 baud is 1.0417 ms per byte.
        let slow = Timing::new(9600, 0, Duration::ZERO);
        assert_eq!(slow.wire(1), Duration::from_nanos(1_041_667), "rounded up");
    }

    #[test]
    fn the_99th_percentile_of_each_window() {
        let mut p = P99::new(200);
        let us = Duration::from_micros;
        // 197 fast cycles, 3 slow ones: the 99th percentile is a slow one.
        for i in 0..199 {
            let d = if i % 70 == 0 { us(2600) } else { us(400) };
            assert_eq!(p.add(d), None);
        }
        assert_eq!(p.add(us(420)), Some(2650));
        // A new window: 1 slow of 200 is beyond the 99th percentile.
        for i in 0..199 {
            assert_eq!(p.add(if i == 5 { us(9000) } else { us(120) }), None);
        }
        assert_eq!(p.add(us(100)), Some(150));
        // Beyond the last bucket: 5 ms and more.
        let mut p = P99::new(1);
        assert_eq!(p.add(Duration::from_secs(1)), Some(5050));
    }
}
