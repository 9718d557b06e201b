//! Gathering one period's four finger frames, pure.
//!
//! The hand streams the four position frames of a period back to back (finger 0 first: the
//! lowest id wins arbitration). A cycle is complete when all four have arrived (R1, R4: a mask
//! of fingers seen); a finger arriving again before the set is complete means the rest of the
//! previous period was lost, and a timeout without the set does too.

use teleop_allegro_protocol::{FINGERS, JOINTS};

/// Mask of all four fingers.
const ALL: u8 = (1 << FINGERS) - 1;

/// What one finger frame did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pushed {
    /// The set is not complete yet.
    Pending,
    /// All four fingers of the period have arrived: [`Gather::positions`] holds them.
    Complete,
    /// The finger came again before the set was complete: the previous period missed this
    /// many frames. The finger starts the next set.
    Missed(u8),
}

/// The positions of the fingers seen in the current period.
#[derive(Debug, Clone, PartialEq)]
pub struct Gather {
    mask: u8,
    q: [f64; JOINTS],
}

impl Default for Gather {
    fn default() -> Self {
        Self::new()
    }
}

impl Gather {
    /// Nothing seen yet.
    pub fn new() -> Self {
        Self {
            mask: 0,
            q: [0.0; JOINTS],
        }
    }

    /// Takes finger `finger`'s four joint positions (rad). Fingers outside 0..4 are ignored
    /// (the protocol's decoders never give one).
    pub fn push(&mut self, finger: u8, q: [f64; 4]) -> Pushed {
        let f = usize::from(finger);
        if f >= FINGERS {
            return Pushed::Pending;
        }
        let bit = 1u8 << f;
        let result = if self.mask & bit != 0 {
            let missed = (FINGERS as u32 - self.mask.count_ones()) as u8;
            self.mask = 0;
            Pushed::Missed(missed)
        } else {
            Pushed::Pending
        };
        self.q[f * 4..f * 4 + 4].copy_from_slice(&q);
        self.mask |= bit;
        if self.mask == ALL {
            self.mask = 0;
            // A missed set cannot complete with the same frame (the mask was just reset).
            return Pushed::Complete;
        }
        result
    }

    /// No frame for a whole timeout: the frames missing from the current set (all four when
    /// none came), and a fresh start.
    pub fn timeout(&mut self) -> u8 {
        let missed = (FINGERS as u32 - self.mask.count_ones()) as u8;
        self.mask = 0;
        missed
    }

    /// Forgets the current set (after a bring-up).
    pub fn reset(&mut self) {
        self.mask = 0;
    }

    /// The newest positions of every joint.
    pub fn positions(&self) -> &[f64; JOINTS] {
        &self.q
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_fingers_make_a_cycle() {
        let mut g = Gather::new();
        assert_eq!(g.push(0, [0.1; 4]), Pushed::Pending);
        assert_eq!(g.push(1, [0.2; 4]), Pushed::Pending);
        assert_eq!(g.push(2, [0.3; 4]), Pushed::Pending);
        assert_eq!(g.push(3, [0.4; 4]), Pushed::Complete);
        assert_eq!(g.positions()[4], 0.2);
        assert_eq!(g.positions()[15], 0.4);
        // Any order completes.
        for f in [3, 1, 0] {
            assert_eq!(g.push(f, [1.0; 4]), Pushed::Pending);
        }
        assert_eq!(g.push(2, [1.0; 4]), Pushed::Complete);
    }

    #[test]
    fn a_lost_frame_is_counted_when_the_next_period_starts() {
        let mut g = Gather::new();
        g.push(0, [0.0; 4]);
        g.push(1, [0.0; 4]);
        g.push(3, [0.0; 4]);
        // Finger 2 was lost; finger 0 of the next period arrives.
        assert_eq!(g.push(0, [0.5; 4]), Pushed::Missed(1));
        for f in 1..3 {
            assert_eq!(g.push(f, [0.5; 4]), Pushed::Pending);
        }
        assert_eq!(g.push(3, [0.5; 4]), Pushed::Complete);
        assert_eq!(g.positions(), &[0.5; JOINTS]);
    }

    #[test]
    fn timeouts_count_what_was_missing() {
        let mut g = Gather::new();
        assert_eq!(g.timeout(), 4);
        g.push(2, [0.0; 4]);
        assert_eq!(g.timeout(), 3);
        assert_eq!(g.push(2, [0.0; 4]), Pushed::Pending);
        assert_eq!(g.push(7, [0.0; 4]), Pushed::Pending);
        g.reset();
        assert_eq!(g.timeout(), 4);
    }
}
