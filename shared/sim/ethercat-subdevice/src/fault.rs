//! Fault injection and counters.

/// Faults to inject; change them at any time through [`crate::SubDevice::faults`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Faults {
    /// Probability (0..=1) that a frame is lost before it reaches the ESC (no reply, no effect).
    pub drop_probability: f32,
    /// Probability (0..=1) that a process data datagram (LRD/LWR/LRW) comes back with a working
    /// counter off by one (one less if this SubDevice counted, else one more).
    pub wrong_wkc_probability: f32,
    /// The next upward state change request (INIT -> PRE-OP/BOOT, PRE-OP -> SAFE-OP,
    /// SAFE-OP -> OP) is refused with this AL status code; cleared when used.
    pub refuse_next_transition: Option<u16>,
    /// Drop every frame while set (cable pulled).
    pub link_down: bool,
    /// Seed of the random generator behind the probabilities (reseeded when it changes).
    pub seed: u64,
}

/// Counters of what the SubDevice did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// EtherCAT frames received (including dropped and malformed ones).
    pub frames: u64,
    /// Frames returned.
    pub replies: u64,
    /// Frames ignored because they were not EtherCAT (EtherType != 0x88A4).
    pub not_ethercat: u64,
    /// EtherCAT frames dropped because their datagram chain was malformed.
    pub malformed: u64,
    /// Datagrams executed.
    pub datagrams: u64,
    /// Mailbox requests received (SM0 written to its last byte).
    pub mailbox_requests: u64,
    /// Mailbox requests discarded as repeats (same counter as the previous request).
    pub mailbox_duplicates: u64,
    /// SDO aborts sent.
    pub sdo_aborts: u64,
    /// State transitions taken (requested ones; a watchdog trip is counted separately).
    pub transitions: u64,
    /// State change requests refused (invalid, failed checks, refused by the application or by
    /// fault injection).
    pub refused_transitions: u64,
    /// SM watchdog trips.
    pub watchdog_trips: u64,
    /// Injected: frames dropped (probability or link down).
    pub dropped_frames: u64,
    /// Injected: working counters falsified.
    pub wrong_wkc: u64,
    /// Injected: transitions refused through `Faults::refuse_next_transition`.
    pub injected_refusals: u64,
    /// Restarts (asked by the application or by the caller).
    pub restarts: u64,
    /// Frames lost because they came while the device restarted.
    pub frames_while_restarting: u64,
}

/// SplitMix64: small, seedable, good enough for fault injection.
#[derive(Debug, Clone)]
pub(crate) struct Rng {
    state: u64,
    seed: u64,
}

impl Rng {
    pub(crate) fn new(seed: u64) -> Self {
        Self { state: seed, seed }
    }

    fn next(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// True with probability `p`, reseeding first if `seed` changed.
    pub(crate) fn chance(&mut self, p: f32, seed: u64) -> bool {
        if seed != self.seed {
            *self = Self::new(seed);
        }
        if p.is_nan() || p <= 0.0 {
            return false;
        }
        if p >= 1.0 {
            return true;
        }
        // 24 random bits: exact in an f32.
        let r = (self.next() >> 40) as f32 / (1u32 << 24) as f32;
        r < p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probabilities() {
        let mut rng = Rng::new(1);
        assert!(!rng.chance(0.0, 1));
        assert!(rng.chance(1.0, 1));
        assert!(!rng.chance(f32::NAN, 1));
        let hits = (0..10_000).filter(|_| rng.chance(0.25, 1)).count();
        assert!((2_000..3_000).contains(&hits), "{hits}");
        // Same seed, same sequence.
        let a: Vec<bool> = {
            let mut r = Rng::new(7);
            (0..64).map(|_| r.chance(0.5, 7)).collect()
        };
        let b: Vec<bool> = {
            let mut r = Rng::new(0);
            (0..64).map(|_| r.chance(0.5, 7)).collect()
        };
        assert_eq!(a, b);
    }
}
