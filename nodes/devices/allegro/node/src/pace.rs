//! Telling a late period from a missing one, pure.
//!
//! The loop waits `frame_timeout` for the hand's next finger frame. On a loaded host that wait
//! can run out while the hand streams without a gap: its frames wait on the way (in the
//! adapter's serial line or pty, in the kernel, in a simulator's threads that were not
//! scheduled) and come later in a burst. A link that stamps each frame with the time it was on
//! the bus (an slcan adapter's `Z1` clock, the local bus) tells the two apart: when the frame
//! after a silence comes, its stamp says whether the hand was silent too. So, with stamps, a
//! timeout is only a suspicion; the next finger frame settles it (the hand's own gap longer
//! than a timeout: the suspected periods were missed; else none was), and a silence that goes
//! on past [`Pace::late_limit`] counts as missed from then on (the hand, or its link, stopped).
//! Without stamps every timeout is a missed period, as before.

use std::time::Duration;

use teleop_can_link::stamp_gap_ms;

/// What a timeout without a finger frame means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Timeout {
    /// A missed period, now.
    Missed,
    /// Perhaps only late: the next finger frame's stamp will tell.
    Suspected,
}

/// The stamps of the hand's finger frames and the timeouts not settled yet.
#[derive(Debug, Clone)]
pub struct Pace {
    timeout_ms: u64,
    late_limit: Duration,
    /// Stamp of the last finger frame, if the link gave one.
    last: Option<u16>,
    /// Timeouts since then, not yet counted as missed.
    suspected: u32,
    /// Time waited since the last finger frame (timeouts only).
    silent: Duration,
}

impl Pace {
    /// With `frame_timeout` per wait; a silence longer than `late_limit` is no longer thought
    /// late.
    pub fn new(frame_timeout: Duration, late_limit: Duration) -> Self {
        Self {
            timeout_ms: frame_timeout.as_millis().max(1) as u64,
            late_limit,
            last: None,
            suspected: 0,
            silent: Duration::ZERO,
        }
    }

    /// How long a silence may be thought late.
    pub fn late_limit(&self) -> Duration {
        self.late_limit
    }

    /// Timeouts suspected since the last finger frame, not settled yet.
    pub fn suspected(&self) -> u32 {
        self.suspected
    }

    /// The wait of `frame_timeout` ran out without a finger frame.
    pub fn timeout(&mut self, frame_timeout: Duration) -> Timeout {
        self.silent += frame_timeout;
        if self.last.is_none() || self.silent > self.late_limit {
            return Timeout::Missed;
        }
        self.suspected += 1;
        Timeout::Suspected
    }

    /// A finger frame came, stamped `stamp` by the link: how many of the suspected timeouts
    /// were missed periods (0: the frame continues the hand's stream; the wait was the host's).
    pub fn frame(&mut self, stamp: Option<u16>) -> u32 {
        let suspected = std::mem::take(&mut self.suspected);
        self.silent = Duration::ZERO;
        let previous = std::mem::replace(&mut self.last, stamp);
        match (previous, stamp) {
            (Some(a), Some(b)) if u64::from(stamp_gap_ms(a, b)) <= self.timeout_ms => 0,
            _ => suspected,
        }
    }

    /// A fresh start (after a bring-up).
    pub fn reset(&mut self) {
        self.last = None;
        self.suspected = 0;
        self.silent = Duration::ZERO;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: Duration = Duration::from_millis(10);

    #[test]
    fn a_burst_stamped_on_time_missed_nothing() {
        let mut p = Pace::new(T, Duration::from_millis(500));
        assert_eq!(p.frame(Some(100)), 0);
        // 60 ms of waiting on the host ...
        for _ in 0..6 {
            assert_eq!(p.timeout(T), Timeout::Suspected);
        }
        // ... then the stream's next frames, stamped every 3 ms from where it was.
        assert_eq!(p.frame(Some(103)), 0);
        assert_eq!(p.frame(Some(106)), 0);
    }

    #[test]
    fn a_gap_in_the_hands_stamps_is_missed_periods() {
        let mut p = Pace::new(T, Duration::from_millis(500));
        p.frame(Some(59_990));
        for _ in 0..3 {
            p.timeout(T);
        }
        // Across the stamps' wrap: 40 ms of silence on the bus too.
        assert_eq!(p.frame(Some(30)), 3);
    }

    #[test]
    fn without_stamps_or_past_the_limit_a_timeout_is_missed_at_once() {
        let mut p = Pace::new(T, Duration::from_millis(30));
        p.frame(None);
        assert_eq!(p.timeout(T), Timeout::Missed);
        let mut p = Pace::new(T, Duration::from_millis(30));
        p.frame(Some(0));
        for _ in 0..3 {
            assert_eq!(p.timeout(T), Timeout::Suspected);
        }
        assert_eq!(p.timeout(T), Timeout::Missed, "40 ms > 30 ms");
        // The suspected ones are settled by the next frame's stamp.
        assert_eq!(p.frame(Some(45)), 3);
        p.reset();
        assert_eq!(p.timeout(T), Timeout::Missed, "no stamp since the reset");
    }
}
