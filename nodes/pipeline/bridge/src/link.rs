//! The link's bookkeeping, pure so tests drive it with made-up times: the peer's clock (round
//! trip and offset from heartbeats), whether the link is up, the one-way latencies of samples,
//! sequence gaps across the link, and the fault injector (delay line and loss) tests and
//! benchmarks use where this kernel has no netem.

use std::collections::VecDeque;

/// How the bridge relates the peer's stamps to its own clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClockMode {
    /// Both stations read the same CLOCK_MONOTONIC (one machine, or clocks locked by PTP): stamps
    /// cross unchanged and one-way latency is measured directly.
    Shared,
    /// Separate machines: the offset between the clocks is estimated from the heartbeats' round
    /// trips (the exchange with the shortest round trip of the last [`OFFSET_WINDOW`]), stamps
    /// are moved into this station's clock, and one-way latency is only as good as that
    /// estimate (half the round trip's asymmetry).
    Estimate,
}

/// Heartbeat exchanges the offset estimate chooses from.
pub const OFFSET_WINDOW: usize = 64;

/// The peer's clock as seen from here.
#[derive(Debug, Clone)]
pub struct PeerClock {
    mode: ClockMode,
    /// (round trip, offset = peer clock - local clock), newest last.
    exchanges: VecDeque<(u64, i64)>,
    offset_ns: i64,
    rtt_ns: Option<u64>,
}

impl PeerClock {
    /// No exchange yet: offset 0.
    pub fn new(mode: ClockMode) -> Self {
        Self {
            mode,
            exchanges: VecDeque::with_capacity(OFFSET_WINDOW),
            offset_ns: 0,
            rtt_ns: None,
        }
    }

    /// One heartbeat exchange: we sent at `t0` (local), the peer received it `hold_ns` before it
    /// sent its reply at `t2` (peer clock), which arrived here at `t3` (local). Ignored when the
    /// times do not fit together (an echo of something we never sent).
    pub fn exchange(&mut self, t0: u64, hold_ns: u64, t2: u64, t3: u64) {
        let Some(rtt) = t3.checked_sub(t0).and_then(|d| d.checked_sub(hold_ns)) else {
            return;
        };
        self.rtt_ns = Some(rtt);
        let t1 = i128::from(t2) - i128::from(hold_ns);
        let offset = ((t1 - i128::from(t0)) + (i128::from(t2) - i128::from(t3))) / 2;
        let offset = i64::try_from(offset).unwrap_or(0);
        if self.exchanges.len() == OFFSET_WINDOW {
            self.exchanges.pop_front();
        }
        self.exchanges.push_back((rtt, offset));
        if self.mode == ClockMode::Estimate {
            if let Some((_, best)) = self.exchanges.iter().min_by_key(|(rtt, _)| *rtt) {
                self.offset_ns = *best;
            }
        }
    }

    /// The peer restarted (its heartbeats count from 1 again): the exchanges with its former
    /// clock are forgotten, the offset is 0 until the next exchange.
    pub fn restart(&mut self) {
        self.exchanges.clear();
        self.offset_ns = 0;
        self.rtt_ns = None;
    }

    /// The newest round trip (None before the first exchange).
    pub fn rtt_ns(&self) -> Option<u64> {
        self.rtt_ns
    }

    /// Peer clock minus local clock, ns (0 in [`ClockMode::Shared`]).
    pub fn offset_ns(&self) -> i64 {
        self.offset_ns
    }

    /// A peer stamp in the local clock; 0 (unstamped) stays 0.
    pub fn to_local(&self, peer_ns: u64) -> u64 {
        if peer_ns == 0 {
            return 0;
        }
        let local = i128::from(peer_ns) - i128::from(self.offset_ns);
        u64::try_from(local.max(1)).unwrap_or(u64::MAX)
    }
}

/// The peer's heartbeat sequence: it counts up from 1 per bridge start, so a number not above
/// the last one means the peer's bridge restarted (and, between machines, its clock may have).
#[derive(Debug, Clone, Copy, Default)]
pub struct PeerRun {
    last: Option<u64>,
}

impl PeerRun {
    /// Takes a heartbeat's `seq`; true when the peer restarted since the previous one.
    pub fn restarted(&mut self, seq: u64) -> bool {
        let restarted = self.last.is_some_and(|last| seq <= last);
        self.last = Some(seq);
        restarted
    }
}

/// Heartbeats this bridge sent that a peer's echo may name.
pub const SENT_WINDOW: usize = 1024;

/// The send stamps of this bridge's newest [`SENT_WINDOW`] heartbeats: an echo that names none of
/// them (forged, or from before a restart) is no exchange.
#[derive(Debug, Clone)]
pub struct SentBeats {
    stamps: Vec<u64>,
    next: usize,
}

impl Default for SentBeats {
    fn default() -> Self {
        Self {
            stamps: vec![0; SENT_WINDOW],
            next: 0,
        }
    }
}

impl SentBeats {
    /// A heartbeat sent with this stamp (ns, never 0).
    pub fn record(&mut self, send_ns: u64) {
        self.stamps[self.next] = send_ns;
        self.next = (self.next + 1) % SENT_WINDOW;
    }

    /// True when `send_ns` is the stamp of one of the newest heartbeats sent.
    pub fn contains(&self, send_ns: u64) -> bool {
        send_ns != 0 && self.stamps.contains(&send_ns)
    }
}

/// Link state, as the bridge reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkState {
    /// No accepted heartbeat within the link timeout (or none yet).
    Down = 0,
    /// Heartbeats arrive.
    Up = 1,
    /// The peer speaks another contract: everything from it is refused.
    Refused = 2,
}

impl LinkState {
    /// Name for logs.
    pub fn name(self) -> &'static str {
        match self {
            Self::Down => "down",
            Self::Up => "up",
            Self::Refused => "refused",
        }
    }
}

/// Sequence gaps of one topic's samples across the link (one publisher per topic, as the
/// pipeline has; a restarted publisher starts at 1 again and is not a gap).
#[derive(Debug, Clone, Copy, Default)]
pub struct GapCounter {
    last: Option<(u32, u64)>,
    /// Samples missing so far.
    pub missing: u64,
}

impl GapCounter {
    /// Counts the sample `(source, seq)`; returns the samples missing before it.
    pub fn count(&mut self, source: u32, seq: u64) -> u64 {
        let gap = match self.last {
            // Saturating: a sequence number at u64::MAX is followed by no gap, not an overflow.
            Some((s, last)) if s == source && seq > last.saturating_add(1) => seq - last - 1,
            _ => 0,
        };
        self.last = Some((source, seq));
        self.missing += gap;
        gap
    }
}

/// The newest one-way latencies (us), for p50/p99/max reports.
#[derive(Debug, Clone)]
pub struct LatencyWindow {
    values: Vec<u32>,
    next: usize,
    filled: bool,
}

impl LatencyWindow {
    /// Keeps the newest `capacity` values.
    pub fn new(capacity: usize) -> Self {
        Self {
            values: vec![0; capacity.max(1)],
            next: 0,
            filled: false,
        }
    }

    /// Forgets every value (the link went down, or the peer restarted: what comes next is
    /// another link's delay).
    pub fn clear(&mut self) {
        self.next = 0;
        self.filled = false;
    }

    /// Adds one latency.
    pub fn push(&mut self, us: u32) {
        self.values[self.next] = us;
        self.next += 1;
        if self.next == self.values.len() {
            self.next = 0;
            self.filled = true;
        }
    }

    /// p50, p99 and max of the window (None when empty).
    pub fn percentiles(&self) -> Option<(u32, u32, u32)> {
        let n = if self.filled {
            self.values.len()
        } else {
            self.next
        };
        if n == 0 {
            return None;
        }
        let mut v = self.values[..n].to_vec();
        v.sort_unstable();
        let at = |q: f64| v[((n - 1) as f64 * q).round() as usize];
        Some((at(0.5), at(0.99), v[n - 1]))
    }
}

/// Faults injected on what this bridge receives: a fixed extra delay and random loss.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Faults {
    /// Extra one-way delay, ns.
    pub delay_ns: u64,
    /// Frames lost per million.
    pub loss_ppm: u32,
}

/// The delay line: frames wait here until due; loss decided on entry (xorshift, seeded).
#[derive(Debug)]
pub struct DelayLine<T> {
    queue: VecDeque<(u64, T)>,
    rng: u64,
    /// Frames the injector dropped.
    pub lost: u64,
    /// Frames dropped because [`MAX_DELAYED`] were waiting.
    pub overflow: u64,
}

/// Most frames the delay line holds.
pub const MAX_DELAYED: usize = 4096;

impl<T> DelayLine<T> {
    /// An empty line.
    pub fn new(seed: u64) -> Self {
        Self {
            queue: VecDeque::new(),
            rng: seed | 1,
            lost: 0,
            overflow: 0,
        }
    }

    /// Puts `item`, received at `now_ns`, into the line (or loses it; or, with
    /// [`MAX_DELAYED`] already waiting, drops it and counts it in `overflow`).
    pub fn push(&mut self, faults: Faults, now_ns: u64, item: T) {
        if self.queue.len() >= MAX_DELAYED {
            self.overflow += 1;
            return;
        }
        if faults.loss_ppm > 0 {
            self.rng ^= self.rng << 13;
            self.rng ^= self.rng >> 7;
            self.rng ^= self.rng << 17;
            if (self.rng % 1_000_000) < u64::from(faults.loss_ppm) {
                self.lost += 1;
                return;
            }
        }
        self.queue
            .push_back((now_ns.saturating_add(faults.delay_ns), item));
    }

    /// The next item due at `now_ns`, in arrival order.
    pub fn pop_due(&mut self, now_ns: u64) -> Option<T> {
        match self.queue.front() {
            Some((due, _)) if *due <= now_ns => self.queue.pop_front().map(|(_, item)| item),
            _ => None,
        }
    }

    /// When the next item is due (None: empty).
    pub fn next_due(&self) -> Option<u64> {
        self.queue.front().map(|(due, _)| *due)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn offset_and_round_trip_from_an_exchange() {
        // The peer's clock is 5 s ahead; 2 ms each way; the peer held the heartbeat 1 ms.
        let mut clock = PeerClock::new(ClockMode::Estimate);
        let t0 = 1_000_000_000;
        let t1 = t0 + 2_000_000 + 5_000_000_000;
        let t2 = t1 + 1_000_000;
        let t3 = t0 + 5_000_000;
        clock.exchange(t0, 1_000_000, t2, t3);
        assert_eq!(clock.rtt_ns(), Some(4_000_000));
        assert_eq!(clock.offset_ns(), 5_000_000_000);
        assert_eq!(clock.to_local(t2), t3 - 2_000_000);
        assert_eq!(clock.to_local(0), 0);
    }

    #[test]
    fn the_shortest_round_trip_sets_the_offset_and_shared_clocks_keep_zero() {
        let mut clock = PeerClock::new(ClockMode::Estimate);
        // Symmetric 1 ms each way: offset 0.
        clock.exchange(0, 0, 1_000_000, 2_000_000);
        // Asymmetric and slow (9 ms out, 1 ms back): would say +4 ms.
        clock.exchange(10_000_000, 0, 19_000_000, 20_000_000);
        assert_eq!(clock.offset_ns(), 0);
        assert_eq!(clock.rtt_ns(), Some(10_000_000));
        let mut shared = PeerClock::new(ClockMode::Shared);
        shared.exchange(10_000_000, 0, 19_000_000, 20_000_000);
        assert_eq!(shared.offset_ns(), 0);
        // An echo that does not fit is ignored.
        shared.exchange(30_000_000, 0, 1, 20_000_000);
        assert_eq!(shared.rtt_ns(), Some(10_000_000));
    }

    #[test]
    fn gaps_count_missing_samples_not_restarts() {
        let mut gaps = GapCounter::default();
        assert_eq!(gaps.count(7, 1), 0);
        assert_eq!(gaps.count(7, 2), 0);
        assert_eq!(gaps.count(7, 5), 2);
        assert_eq!(gaps.count(7, 1), 0, "a restarted publisher");
        assert_eq!(gaps.count(9, 40), 0, "another publisher");
        assert_eq!(gaps.missing, 2);
    }

    #[test]
    fn latency_percentiles_over_the_newest_values() {
        let mut w = LatencyWindow::new(100);
        assert_eq!(w.percentiles(), None);
        for v in 1..=200 {
            w.push(v);
        }
        assert_eq!(w.percentiles(), Some((151, 199, 200)));
    }

    #[test]
    fn the_delay_line_delays_and_loses() {
        let mut line = DelayLine::new(42);
        let delay = Faults {
            delay_ns: 20,
            loss_ppm: 0,
        };
        line.push(delay, 100, 'a');
        line.push(delay, 105, 'b');
        assert_eq!(line.pop_due(119), None);
        assert_eq!(line.next_due(), Some(120));
        assert_eq!(line.pop_due(125), Some('a'));
        assert_eq!(line.pop_due(125), Some('b'));
        let lossy = Faults {
            delay_ns: 0,
            loss_ppm: 100_000,
        };
        for i in 0..10_000 {
            line.push(lossy, i, 'x');
            let _ = line.pop_due(i);
        }
        assert!((800..1200).contains(&line.lost), "{}", line.lost);
        // A delay beyond any clock never overflows.
        let mut far = DelayLine::new(1);
        far.push(
            Faults {
                delay_ns: u64::MAX,
                loss_ppm: 0,
            },
            5,
            'z',
        );
        assert_eq!(far.next_due(), Some(u64::MAX));
    }

    #[test]
    fn gaps_near_the_end_of_u64_do_not_overflow() {
        let mut gaps = GapCounter::default();
        assert_eq!(gaps.count(7, u64::MAX - 3), 0);
        assert_eq!(gaps.count(7, u64::MAX), 2);
        assert_eq!(gaps.count(7, u64::MAX), 0, "a repeat is no gap");
        assert_eq!(gaps.count(7, 1), 0, "a restarted publisher");
        assert_eq!(gaps.missing, 2);
    }

    #[test]
    fn a_restarted_peer_clock_is_estimated_afresh() {
        let mut run = PeerRun::default();
        let mut clock = PeerClock::new(ClockMode::Estimate);
        assert!(!run.restarted(1));
        // The peer's clock 5 s ahead, 1 ms round trip.
        clock.exchange(0, 0, 5_000_500_000, 1_000_000);
        assert_eq!(clock.offset_ns(), 5_000_000_000);
        assert!(!run.restarted(2));
        // Its machine restarted: its clock now 3 s behind, a slower exchange (4 ms).
        assert!(run.restarted(1), "seq back to 1");
        clock.restart();
        assert_eq!((clock.offset_ns(), clock.rtt_ns()), (0, None));
        clock.exchange(10_000_000_000, 0, 7_002_000_000, 10_004_000_000);
        assert_eq!(clock.offset_ns(), -3_000_000_000);
        assert!(!run.restarted(2));
    }

    #[test]
    fn only_echoes_of_heartbeats_sent_count() {
        let mut sent = SentBeats::default();
        assert!(!sent.contains(0) && !sent.contains(7));
        sent.record(7);
        assert!(sent.contains(7) && !sent.contains(8));
        for ns in 100..100 + SENT_WINDOW as u64 {
            sent.record(ns);
        }
        assert!(!sent.contains(7), "forgotten after {SENT_WINDOW} more");
        assert!(sent.contains(100) && sent.contains(99 + SENT_WINDOW as u64));
    }

    #[test]
    fn the_delay_line_is_bounded() {
        let mut line = DelayLine::new(3);
        let hold = Faults {
            delay_ns: 1_000_000_000,
            loss_ppm: 0,
        };
        for i in 0..MAX_DELAYED as u64 + 10 {
            line.push(hold, i, i);
        }
        assert_eq!(line.overflow, 10);
        assert_eq!(line.pop_due(u64::MAX), Some(0));
    }
}
