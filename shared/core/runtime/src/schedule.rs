//! When a pipeline engine's inputs go stale and when it ticks: pure, given the samples' stamps
//! and the clock (CLOCK_MONOTONIC live, the log time when reprocessing a recording), so the
//! nodes and `teleop reprocess` schedule the engines with the same code.
//!
//! - An input is stale once its newest sample is older than the input's timeout, judged by the
//!   sample's own stamp ([`sample_time`]: when it was made, never later than its receipt), not by
//!   when it arrived: [`is_stale`].
//! - Its watchdog fires at the first instant the input is stale, and again every timeout while
//!   nothing newer arrives (an input that never had a sample has no watchdog running).
//! - Ticks fall at absolute deadlines, `start + k × period`: a late caller gets every tick it
//!   missed, each at its own deadline, and the grid never drifts.
//!
//! [`Schedule::pop`] hands out what is due at or before a time, earliest first, so a caller
//! that pops before handling each input sees everything in time order. It never reads a clock.

use crate::sample_time;

/// True when a sample made at `made_ns` is too old at `now_ns` for an input with this timeout:
/// older than `timeout_ns` (a sample exactly `timeout_ns` old is still fresh).
pub fn is_stale(made_ns: u64, now_ns: u64, timeout_ns: u64) -> bool {
    now_ns.saturating_sub(made_ns) > timeout_ns
}

/// What a [`Schedule`] says is due.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Due {
    /// Input `i` (in the order of [`Schedule::watch`]) went stale, or is still stale one more
    /// timeout later.
    Stale(usize),
    /// The periodic tick.
    Tick,
}

#[derive(Debug, Clone, Copy)]
struct Watchdog {
    timeout_ns: u64,
    /// When it fires next (`None`: no sample yet).
    due_ns: Option<u64>,
}

#[derive(Debug, Clone, Copy)]
struct Ticker {
    period_ns: u64,
    /// The next deadline (`None`: not started).
    due_ns: Option<u64>,
}

/// The watchdogs of an engine's inputs and its periodic tick.
#[derive(Debug, Clone, Default)]
pub struct Schedule {
    watchdogs: Vec<Watchdog>,
    ticker: Option<Ticker>,
}

impl Schedule {
    /// A schedule with no inputs and no tick.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds an input whose samples are stale after `timeout_ms` (at least 1 ms); returns its
    /// index for [`sample`](Self::sample) and [`Due::Stale`].
    pub fn watch(&mut self, timeout_ms: u64) -> usize {
        self.watchdogs.push(Watchdog {
            timeout_ns: ms_to_ns(timeout_ms),
            due_ns: None,
        });
        self.watchdogs.len() - 1
    }

    /// Adds a tick every `period_ms` (at least 1 ms), from [`start_ticks`](Self::start_ticks) on.
    pub fn tick_every(&mut self, period_ms: u64) {
        self.ticker = Some(Ticker {
            period_ns: ms_to_ns(period_ms),
            due_ns: None,
        });
    }

    /// Starts the ticks: the first is due one period after `at_ns`. Once started, later calls
    /// change nothing.
    pub fn start_ticks(&mut self, at_ns: u64) {
        if let Some(t) = &mut self.ticker {
            t.due_ns.get_or_insert(at_ns.saturating_add(t.period_ns));
        }
    }

    /// A sample of input `input` stamped `stamp_ns` arrived at `received_ns`: its watchdog
    /// restarts from when the sample was made. Returns whether the sample is stale already.
    pub fn sample(&mut self, input: usize, stamp_ns: u64, received_ns: u64) -> bool {
        let made = sample_time(stamp_ns, received_ns);
        let Some(w) = self.watchdogs.get_mut(input) else {
            return false;
        };
        w.due_ns = Some(made.saturating_add(w.timeout_ns).saturating_add(1));
        is_stale(made, received_ns, w.timeout_ns)
    }

    /// Whether input `input`'s sample made at `made_ns` is stale at `now_ns` (unknown inputs
    /// never are).
    pub fn stale(&self, input: usize, made_ns: u64, now_ns: u64) -> bool {
        self.watchdogs
            .get(input)
            .is_some_and(|w| is_stale(made_ns, now_ns, w.timeout_ns))
    }

    /// The earliest time something is due (`None`: nothing will be until a sample arrives or
    /// the ticks start).
    pub fn next_due(&self) -> Option<u64> {
        self.watchdogs
            .iter()
            .filter_map(|w| w.due_ns)
            .chain(self.ticker.and_then(|t| t.due_ns))
            .min()
    }

    /// The earliest thing due at or before `now_ns` and its deadline, rescheduled (a watchdog
    /// one timeout later, the tick one period later); `None` when nothing is due. At equal
    /// deadlines, watchdogs in their order come before the tick.
    pub fn pop(&mut self, now_ns: u64) -> Option<(u64, Due)> {
        let (at, due) = self
            .watchdogs
            .iter()
            .enumerate()
            .filter_map(|(i, w)| w.due_ns.map(|d| (d, Due::Stale(i))))
            .chain(self.ticker.and_then(|t| t.due_ns).map(|d| (d, Due::Tick)))
            .min_by_key(|&(d, _)| d)
            .filter(|&(d, _)| d <= now_ns)?;
        match due {
            Due::Stale(i) => {
                let w = &mut self.watchdogs[i];
                w.due_ns = Some(at.saturating_add(w.timeout_ns));
            }
            Due::Tick => {
                if let Some(t) = &mut self.ticker {
                    t.due_ns = Some(at.saturating_add(t.period_ns));
                }
            }
        }
        Some((at, due))
    }
}

fn ms_to_ns(ms: u64) -> u64 {
    ms.max(1).saturating_mul(1_000_000)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn drain(s: &mut Schedule, now: u64) -> Vec<(u64, Due)> {
        std::iter::from_fn(|| s.pop(now)).collect()
    }

    #[test]
    fn an_input_is_stale_when_older_than_its_timeout_by_its_own_stamp() {
        let mut s = Schedule::new();
        let glove = s.watch(100);
        // Made 150 ms before it arrived: stale on arrival, and its watchdog runs from when it
        // was made, not from its arrival.
        assert!(s.sample(glove, 1000 * MS, 1150 * MS));
        assert_eq!(s.next_due(), Some(1100 * MS + 1));
        // Made 100 ms ago exactly: still fresh; a nanosecond later: stale.
        assert!(!s.stale(glove, 1000 * MS, 1100 * MS));
        assert!(s.stale(glove, 1000 * MS, 1100 * MS + 1));
        // A stamp later than its receipt (another clock) counts from the receipt.
        assert!(!s.sample(glove, 5000 * MS, 2000 * MS));
        assert_eq!(s.next_due(), Some(2100 * MS + 1));
    }

    #[test]
    fn a_watchdog_fires_when_the_input_goes_stale_and_every_timeout_after() {
        let mut s = Schedule::new();
        let glove = s.watch(100);
        assert_eq!(s.pop(u64::MAX), None, "no sample, no watchdog");
        s.sample(glove, 10 * MS, 12 * MS);
        assert_eq!(s.pop(110 * MS), None, "exactly 100 ms old: fresh");
        assert_eq!(
            drain(&mut s, 300 * MS),
            [
                (110 * MS + 1, Due::Stale(glove)),
                (210 * MS + 1, Due::Stale(glove)),
            ]
        );
        // A new sample restarts it.
        s.sample(glove, 300 * MS, 300 * MS);
        assert_eq!(drain(&mut s, 400 * MS), []);
        assert_eq!(drain(&mut s, 401 * MS), [(400 * MS + 1, Due::Stale(glove))]);
    }

    #[test]
    fn ticks_fall_at_absolute_deadlines_however_late_the_caller() {
        let mut s = Schedule::new();
        s.tick_every(10);
        assert_eq!(s.pop(u64::MAX), None, "not started");
        s.start_ticks(1000 * MS);
        s.start_ticks(1003 * MS); // already started: no effect
        assert_eq!(s.pop(1009 * MS), None);
        assert_eq!(drain(&mut s, 1010 * MS), [(1010 * MS, Due::Tick)]);
        // Called late (at 1037 ms): every missed tick at its own deadline, on the same grid.
        assert_eq!(
            drain(&mut s, 1037 * MS),
            [(1020 * MS, Due::Tick), (1030 * MS, Due::Tick)]
        );
        assert_eq!(s.next_due(), Some(1040 * MS));
    }

    #[test]
    fn everything_due_comes_out_in_time_order() {
        let mut s = Schedule::new();
        let tactile = s.watch(25);
        let state = s.watch(20);
        s.tick_every(10);
        s.start_ticks(0);
        s.sample(tactile, 0, 0);
        s.sample(state, 5 * MS, 6 * MS);
        let popped = drain(&mut s, 30 * MS);
        assert_eq!(
            popped,
            [
                (10 * MS, Due::Tick),
                (20 * MS, Due::Tick),
                (25 * MS + 1, Due::Stale(tactile)),
                (25 * MS + 1, Due::Stale(state)),
                (30 * MS, Due::Tick),
            ]
        );
        assert!(popped.windows(2).all(|w| w[0].0 <= w[1].0));
    }
}
