//! The joint plant's mechanics every simulated hand shares: its clock, which integrates in
//! fixed sub-steps up to the time asked (so that a long gap between two looks stays stable),
//! and the first-order lag by which a value follows its target.

/// The plant's time, advanced in sub-steps of at most `max_step` seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clock {
    t: f64,
    max_step: f64,
}

impl Clock {
    /// A clock at 0 s taking sub-steps of at most `max_step` seconds.
    pub fn new(max_step: f64) -> Self {
        Self { t: 0.0, max_step }
    }

    /// The plant's time, s.
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Advances to `t` seconds, calling `step(now, h)` for each sub-step of `h` seconds ending
    /// at `now`. Earlier times (and NaN) do nothing.
    pub fn advance_to(&mut self, t: f64, mut step: impl FnMut(f64, f64)) {
        while self.t + 1e-12 < t {
            let h = (t - self.t).min(self.max_step);
            self.t += h;
            step(self.t, h);
        }
    }
}

/// A number a plant integrates (`f32` or `f64`).
pub trait Real:
    Copy
    + PartialOrd
    + core::ops::Add<Output = Self>
    + core::ops::Sub<Output = Self>
    + core::ops::Mul<Output = Self>
    + core::ops::Div<Output = Self>
{
    /// One.
    const ONE: Self;
}

impl Real for f32 {
    const ONE: Self = 1.0;
}

impl Real for f64 {
    const ONE: Self = 1.0;
}

/// `value` one step of `h` seconds closer to `target` with time constant `tau` seconds (first
/// order; a step longer than `tau` arrives).
pub fn lag<T: Real>(value: T, target: T, h: T, tau: T) -> T {
    let share = h / tau;
    let share = if share < T::ONE { share } else { T::ONE };
    value + (target - value) * share
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_clock_steps_up_to_the_time_asked_and_not_back() {
        let mut clock = Clock::new(0.001);
        let mut steps = Vec::new();
        clock.advance_to(0.0025, |now, h| steps.push((now, h)));
        assert_eq!(steps.len(), 3);
        assert!((steps[2].0 - 0.0025).abs() < 1e-12 && (steps[2].1 - 0.0005).abs() < 1e-12);
        let mut more = 0;
        clock.advance_to(0.001, |_, _| more += 1);
        clock.advance_to(f64::NAN, |_, _| more += 1);
        assert_eq!(more, 0);
        assert!((clock.time() - 0.0025).abs() < 1e-12);
    }

    #[test]
    fn a_lag_approaches_its_target_and_never_overshoots() {
        let mut v = 0.0f64;
        for _ in 0..1000 {
            v = lag(v, 1.0, 0.001, 0.1);
        }
        assert!(v > 0.99 && v < 1.0, "{v}");
        assert_eq!(lag(0.0f32, 5.0, 2.0, 1.0), 5.0);
    }
}
