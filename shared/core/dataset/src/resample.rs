//! Samples of several topics, each at its own rate, to frames at one fixed rate: zero-order
//! hold without look-ahead, over the time windows of the episodes.
//!
//! Frame `k` of a window starting at `start_ns` is due at `start_ns + k / fps` (rounded to the
//! nanosecond) while that instant is not after the window's end. It holds, per topic (a
//! *slot*), the newest sample whose stamp is at or before that instant, and nothing newer.
//! A frame due before every slot has had a sample is dropped: an episode's frames begin at the
//! first due instant at which every topic has spoken, and its frames are numbered from there.
//!
//! Samples arrive in the recording's order (the recorder's log time, or file order), which is not exactly
//! stamp order across topics: a sample may be logged after a later-stamped sample of another
//! topic. A frame is therefore settled only when each slot has shown a sample stamped after it
//! (its stamps only grow, so none older can follow), or when the log time has passed the frame
//! by [`Resampler::late_ns`] (a topic that fell silent), or at the end of the input. Until then
//! the slot keeps the samples stamped after the next due frame; older ones collapse into the
//! one it holds. What is kept is bounded by that lateness, not by the recording's length. A
//! sample stamped before the one a slot holds (logged after its frame settled, a restarted
//! recorder's history, a next file starting with an older stamp) is dropped: a frame never goes
//! back in time.
//!
//! At each window's end the resampler says, per slot, how many samples fell in it, their first
//! and last stamps (for a rate over their intervals) and the longest silence in it: the greatest
//! age the slot's newest sample reached at an instant of the window. The caller decides what
//! is too slow or too silent.
//!
//! Pure: no I/O, no clock; the caller gives every time.

use std::collections::VecDeque;

/// One episode's time window (stamps, ns, both ends included).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// The first frame is due here.
    pub start_ns: u64,
    /// No frame is due after this.
    pub stop_ns: u64,
}

/// What the resampler hands out, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// One frame of window `window`: every slot's values, in slot order, concatenated.
    Frame {
        /// Index of the window in the list given to [`Resampler::new`].
        window: usize,
        /// When it is due (ns).
        at_ns: u64,
        /// The row.
        values: Vec<f32>,
    },
    /// Window `window` has no more frames.
    WindowEnd {
        /// Index of the window.
        window: usize,
        /// What each slot did within the window, in slot order.
        slots: Vec<SlotInWindow>,
    },
}

/// What one slot did within one window.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SlotInWindow {
    /// Samples stamped within the window.
    pub samples: u64,
    /// The first and the last of their stamps (ns).
    pub stamps: Option<(u64, u64)>,
    /// The longest silence within the window (ns): the greatest age the slot's newest sample
    /// reached at an instant of the window, counted from that sample's stamp (which may be
    /// before the window). 0 for a slot without a sample at or before the window's end.
    pub longest_silence_ns: u64,
}

impl SlotInWindow {
    /// Samples per second over the intervals between the samples within the window (n - 1
    /// intervals over the first to the last stamp): not biased by where the window's ends fall
    /// between two samples. `None` with fewer than two samples.
    pub fn rate_hz(&self) -> Option<f64> {
        let (first, last) = self.stamps?;
        (self.samples >= 2 && last > first)
            .then(|| (self.samples - 1) as f64 * 1e9 / (last - first) as f64)
    }
}

#[derive(Debug, Clone, Default)]
struct Slot {
    width: usize,
    held: Option<(u64, Vec<f32>)>,
    pending: VecDeque<(u64, Vec<f32>)>,
    /// The newest stamp seen.
    newest: Option<u64>,
}

/// The zero-order-hold resampler (see the module's documentation).
#[derive(Debug, Clone)]
pub struct Resampler {
    slots: Vec<Slot>,
    windows: Vec<Window>,
    period_ns: f64,
    /// The window whose frames are being made, and the next frame's number in it.
    window: usize,
    k: u64,
    /// Per window, per slot: what it did there so far.
    seen: Vec<Vec<SlotInWindow>>,
    newest_log_ns: u64,
    finished: bool,
    /// How long after a frame's instant (in log time) it is settled even if a slot has not yet
    /// shown a later sample.
    pub late_ns: u64,
}

impl Resampler {
    /// A resampler for slots of `widths` values each, making frames at `fps` over `windows`
    /// (sorted by start, not overlapping). `late_ns` defaults to one second.
    pub fn new(widths: &[usize], fps: u32, windows: Vec<Window>) -> Self {
        let seen = vec![vec![SlotInWindow::default(); widths.len()]; windows.len()];
        Self {
            slots: widths
                .iter()
                .map(|&width| Slot {
                    width,
                    ..Slot::default()
                })
                .collect(),
            windows,
            period_ns: 1e9 / f64::from(fps.max(1)),
            window: 0,
            k: 0,
            seen,
            newest_log_ns: 0,
            finished: false,
            late_ns: 1_000_000_000,
        }
    }

    /// Values of one row (the sum of the slots' widths).
    pub fn row_width(&self) -> usize {
        self.slots.iter().map(|s| s.width).sum()
    }

    /// When the next frame is due, if any window is left.
    fn due(&self) -> Option<u64> {
        let w = self.windows.get(self.window)?;
        Some(w.start_ns + (self.k as f64 * self.period_ns).round() as u64)
    }

    /// One sample of `slot` stamped `stamp_ns`, logged at `log_ns`; `values` must be the
    /// slot's width (shorter is padded with NaN, longer cut).
    pub fn push(&mut self, slot: usize, stamp_ns: u64, log_ns: u64, values: &[f32]) {
        self.newest_log_ns = self.newest_log_ns.max(log_ns);
        let due = self.due();
        let Some(s) = self.slots.get_mut(slot) else {
            return;
        };
        let mut row = vec![f32::NAN; s.width];
        for (out, v) in row.iter_mut().zip(values) {
            *out = *v;
        }
        // Count it in the window its stamp falls in (windows are sorted).
        let at = self.windows.partition_point(|w| w.start_ns <= stamp_ns);
        if at > 0 && stamp_ns <= self.windows[at - 1].stop_ns {
            let seen = &mut self.seen[at - 1][slot];
            seen.samples += 1;
            seen.stamps = Some(match seen.stamps {
                Some((first, last)) => (first.min(stamp_ns), last.max(stamp_ns)),
                None => (stamp_ns, stamp_ns),
            });
        }
        // The silence since the slot's newest sample, in every window it reaches into that
        // has not ended yet (an older sample is no news: it is dropped).
        if let Some(last) = s.newest.filter(|&last| last < stamp_ns) {
            note_silence(
                &self.windows,
                &mut self.seen,
                self.window,
                slot,
                last,
                stamp_ns,
            );
        }
        if s.newest.is_none_or(|last| last < stamp_ns) {
            s.newest = Some(stamp_ns);
        }
        // Keep pending in stamp order (a publisher's stamps only grow; tolerate one that
        // does not).
        let pos = s.pending.partition_point(|(t, _)| *t <= stamp_ns);
        s.pending.insert(pos, (stamp_ns, row));
        if let Some(due) = due {
            collapse(s, due);
        } else {
            // No frame is due any more: only the newest sample could matter.
            while s.pending.len() > 1 {
                s.pending.pop_front();
            }
        }
    }

    /// No more samples: every frame left can be settled.
    pub fn finish(&mut self) {
        self.finished = true;
    }

    /// The next event, if one is settled.
    pub fn next_event(&mut self) -> Option<Event> {
        loop {
            let w = *self.windows.get(self.window)?;
            let due = self.due()?;
            if due > w.stop_ns {
                let window = self.window;
                // The silence from each slot's newest sample to the window's end.
                for (slot, s) in self.slots.iter().enumerate() {
                    if let Some(last) = s.newest.filter(|&last| last < w.stop_ns) {
                        note_silence(&self.windows, &mut self.seen, window, slot, last, w.stop_ns);
                    }
                }
                let slots = self.seen[window].clone();
                self.window += 1;
                self.k = 0;
                if let Some(next) = self.due() {
                    for s in &mut self.slots {
                        collapse(s, next);
                    }
                }
                return Some(Event::WindowEnd { window, slots });
            }
            let late = self.newest_log_ns > due.saturating_add(self.late_ns);
            let settled = self.finished
                || late
                || self
                    .slots
                    .iter()
                    .all(|s| s.pending.front().is_some_and(|(t, _)| *t > due));
            if !settled {
                return None;
            }
            let mut values = Vec::with_capacity(self.row_width());
            let complete = self.slots.iter().all(|s| s.held.is_some());
            if complete {
                for s in &self.slots {
                    if let Some((_, v)) = &s.held {
                        values.extend_from_slice(v);
                    }
                }
            }
            let window = self.window;
            self.k += 1;
            if let Some(next) = self.due() {
                for s in &mut self.slots {
                    collapse(s, next);
                }
            }
            if complete {
                return Some(Event::Frame {
                    window,
                    at_ns: due,
                    values,
                });
            }
            // Dropped: not every topic has spoken yet.
        }
    }
}

/// Notes that a slot was silent from `last` to `next` (stamps): in each window from `from` on
/// that the span reaches into, the age its held sample reaches there (up to the window's end).
fn note_silence(
    windows: &[Window],
    seen: &mut [Vec<SlotInWindow>],
    from: usize,
    slot: usize,
    last: u64,
    next: u64,
) {
    for (w, seen) in windows.iter().zip(seen.iter_mut()).skip(from) {
        if w.start_ns > next {
            break;
        }
        if w.stop_ns < last {
            continue;
        }
        let age = next.min(w.stop_ns) - last;
        let gap = &mut seen[slot].longest_silence_ns;
        *gap = (*gap).max(age);
    }
}

/// Moves the samples stamped at or before `due` into the held one (only the newest counts). A
/// sample stamped before the held one (logged after its frame settled, or a restarted
/// recorder's history) is dropped: a frame never goes back in time.
fn collapse(s: &mut Slot, due: u64) {
    while s.pending.front().is_some_and(|(t, _)| *t <= due) {
        let Some(sample) = s.pending.pop_front() else {
            break;
        };
        if s.held.as_ref().is_none_or(|(held, _)| sample.0 >= *held) {
            s.held = Some(sample);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn drain(r: &mut Resampler) -> Vec<Event> {
        std::iter::from_fn(|| r.next_event()).collect()
    }

    fn frames(events: &[Event]) -> Vec<(u64, Vec<f32>)> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Frame { at_ns, values, .. } => Some((*at_ns / MS, values.clone())),
                Event::WindowEnd { .. } => None,
            })
            .collect()
    }

    /// A resampler of two one-value slots at `fps` over one window from `start_ms` to
    /// `stop_ms`.
    fn two_slots(fps: u32, start_ms: u64, stop_ms: u64) -> Resampler {
        Resampler::new(
            &[1, 1],
            fps,
            vec![Window {
                start_ns: start_ms * MS,
                stop_ns: stop_ms * MS,
            }],
        )
    }

    #[test]
    fn zero_order_hold_takes_the_newest_sample_at_or_before_each_frame() {
        // 10 fps over [100, 400] ms; slot 0 at 7 ms steps, slot 1 at 50 ms steps.
        let mut r = two_slots(10, 100, 400);
        let mut samples: Vec<(u64, usize)> = (0..80).map(|i| (i * 7, 0)).collect();
        samples.extend((0..12).map(|i| (i * 50, 1)));
        samples.sort();
        let mut events = Vec::new();
        for (t, slot) in samples {
            // Logged 2 ms after its stamp.
            r.push(slot, t * MS, (t + 2) * MS, &[t as f32]);
            events.extend(drain(&mut r));
        }
        r.finish();
        events.extend(drain(&mut r));
        let got = frames(&events);
        // Frame at 100: slot 0's newest at or before 100 is 98, slot 1's is 100 (no look-ahead
        // past it: 105 and 150 came later).
        assert_eq!(got[0], (100, vec![98.0, 100.0]));
        assert_eq!(got[1], (200, vec![196.0, 200.0]));
        assert_eq!(got[2], (300, vec![294.0, 300.0]));
        assert_eq!(got[3], (400, vec![399.0, 400.0]));
        assert_eq!(got.len(), 4);
        assert!(matches!(
            events.last(),
            Some(Event::WindowEnd { window: 0, slots })
                if slots.iter().map(|s| s.samples).collect::<Vec<_>>() == [43, 7]
                    && slots[0].stamps == Some((105 * MS, 399 * MS))
                    && slots.iter().map(|s| s.longest_silence_ns).collect::<Vec<_>>()
                        == [7 * MS, 50 * MS]
        ));
    }

    #[test]
    fn frames_before_every_topic_has_spoken_are_dropped() {
        let mut r = Resampler::new(
            &[1, 2],
            100,
            vec![Window {
                start_ns: 0,
                stop_ns: 50 * MS,
            }],
        );
        r.push(0, 0, 0, &[1.0]);
        r.push(1, 25 * MS, 25 * MS, &[2.0, 3.0]);
        r.push(0, 60 * MS, 60 * MS, &[9.0]);
        r.push(1, 60 * MS, 60 * MS, &[9.0, 9.0]);
        let got = frames(&drain(&mut r));
        assert_eq!(
            got.iter().map(|(t, _)| *t).collect::<Vec<_>>(),
            [30, 40, 50]
        );
        assert_eq!(got[0].1, [1.0, 2.0, 3.0]);
    }

    #[test]
    fn a_window_reports_each_slots_longest_silence_and_its_rate_over_its_intervals() {
        // Two windows: [0, 1000] and [2000, 2500] ms; slot 0 every 10 ms but silent from 300 to
        // 900 ms; slot 1 every 100 ms, its last sample at 2300 ms.
        let mut r = Resampler::new(
            &[1, 1],
            10,
            vec![
                Window {
                    start_ns: 0,
                    stop_ns: 1_000 * MS,
                },
                Window {
                    start_ns: 2_000 * MS,
                    stop_ns: 2_500 * MS,
                },
            ],
        );
        let mut samples: Vec<(u64, usize)> = (0..=300)
            .step_by(10)
            .chain((900..=3_000).step_by(10))
            .map(|t| (t, 0))
            .collect();
        samples.extend((0..=2_300).step_by(100).map(|t| (t, 1)));
        samples.sort();
        let mut ends = Vec::new();
        for (t, slot) in samples {
            r.push(slot, t * MS, t * MS, &[t as f32]);
            ends.extend(drain(&mut r));
        }
        r.finish();
        ends.extend(drain(&mut r));
        let ends: Vec<Vec<SlotInWindow>> = ends
            .into_iter()
            .filter_map(|e| match e {
                Event::WindowEnd { slots, .. } => Some(slots),
                Event::Frame { .. } => None,
            })
            .collect();
        assert_eq!(ends.len(), 2);
        let silences = |w: usize| {
            ends[w]
                .iter()
                .map(|s| s.longest_silence_ns / MS)
                .collect::<Vec<_>>()
        };
        assert_eq!(silences(0), [600, 100]);
        // Slot 1 fell silent at 2300 ms: its value is 200 ms old at the window's end.
        assert_eq!(silences(1), [10, 200]);
        // Rates over the intervals: slot 0 in window 1, 51 samples over 500 ms.
        assert_eq!(ends[1][0].samples, 51);
        assert_eq!(ends[1][0].rate_hz(), Some(100.0));
        assert_eq!(ends[1][1].rate_hz(), Some(10.0));
        assert_eq!(SlotInWindow::default().rate_hz(), None);
    }

    #[test]
    fn a_sample_older_than_the_held_one_never_takes_its_place() {
        let mut r = two_slots(10, 0, 3_000);
        r.push(0, 0, 0, &[0.0]);
        r.push(1, 0, 0, &[0.0]);
        r.push(0, 250 * MS, 250 * MS, &[250.0]);
        // Slot 0 falls silent; slot 1 runs on until frames up to 300 settle by lateness.
        for t in (10..=1_350).step_by(10) {
            r.push(1, t * MS, t * MS, &[t as f32]);
        }
        let got = frames(&drain(&mut r));
        assert_eq!(got.last(), Some(&(300, vec![250.0, 300.0])));
        // A slot 0 sample stamped 120 ms, logged now (over a second late, a restarted
        // recorder's history, the next file of a session): older than the 250 ms one held,
        // it must not take its place.
        r.push(0, 120 * MS, 1_360 * MS, &[120.0]);
        r.finish();
        let got = frames(&drain(&mut r));
        assert_eq!(got.first(), Some(&(400, vec![250.0, 400.0])));
        assert!(got.iter().all(|(_, v)| v[0] == 250.0), "{got:?}");
    }

    #[test]
    fn a_sample_logged_late_still_counts_and_a_silent_topic_does_not_stall() {
        let mut r = two_slots(10, 0, 2_000);
        r.push(0, 0, 0, &[0.0]);
        r.push(1, 0, 0, &[0.0]);
        // Slot 0 runs on; slot 1's sample stamped 95 ms is logged after slot 0's 150 ms.
        r.push(0, 150 * MS, 150 * MS, &[150.0]);
        assert!(
            frames(&drain(&mut r)).is_empty(),
            "slot 1 may still say something"
        );
        r.push(1, 95 * MS, 160 * MS, &[95.0]);
        r.push(1, 180 * MS, 180 * MS, &[180.0]);
        let got = frames(&drain(&mut r));
        assert_eq!(got, [(0, vec![0.0, 0.0]), (100, vec![0.0, 95.0])]);
        // Slot 1 falls silent: frames settle once the log time is a second past them.
        for t in (200..1_500).step_by(10) {
            r.push(0, t * MS, t * MS, &[t as f32]);
        }
        let got = frames(&drain(&mut r));
        assert_eq!(got.first(), Some(&(200, vec![200.0, 180.0])));
        assert_eq!(got.last().map(|f| f.0), Some(400));
    }
}
