//! Fault dice: xorshift64*, deterministic and seedable, good enough for deciding which frame a
//! fault hits.

/// A seeded die.
#[derive(Debug, Clone)]
pub struct Dice(u64);

impl Dice {
    /// Dice from `seed` (0 is taken as 1: xorshift has no zero state).
    pub fn new(seed: u64) -> Self {
        Self(seed.max(1))
    }

    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// True with probability `p` (never for `p <= 0`, always for `p >= 1`).
    pub fn roll(&mut self, p: f64) -> bool {
        if p <= 0.0 {
            return false;
        }
        ((self.next() >> 11) as f64 / (1u64 << 53) as f64) < p
    }

    /// A random byte.
    pub fn byte(&mut self) -> u8 {
        (self.next() >> 32) as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rolls_hit_about_as_often_as_asked_and_repeat_with_the_seed() {
        let mut d = Dice::new(7);
        let hits = (0..10_000).filter(|_| d.roll(0.25)).count();
        assert!((2_200..2_800).contains(&hits), "{hits}");
        let (mut a, mut b) = (Dice::new(3), Dice::new(3));
        assert!((0..100).all(|_| a.byte() == b.byte()));
        assert!(!(0..1000).any(|_| d.roll(0.0)));
        assert!((0..1000).all(|_| d.roll(1.0)));
    }
}
