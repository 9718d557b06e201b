//! The joint plant's mechanics every simulated hand shares: its clock, which integrates in
//! fixed sub-steps up to the time asked (so that a long gap between two looks stays stable),
//! a torque-driven joint against hard stops, and the first-order lag by which a value follows
//! its target.

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

/// A joint driven by torque, as a simulated hand's decoupled joints are (a geared joint as its
/// motor sees it: a diagonal inertia), with viscous damping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Joint {
    /// Inertia as the motor sees it, kg m^2.
    pub inertia: f64,
    /// Viscous damping, N m s/rad.
    pub damping: f64,
}

impl Joint {
    /// One step of `h` seconds (semi-implicit Euler) of the joint at `q` rad moving at `qd`
    /// rad/s under `torque` N m (motor and contact; the damping is added here), stopped hard
    /// at `limits` (lower, upper): at a stop it stays there, moving only away from it.
    pub fn step(self, q: &mut f64, qd: &mut f64, torque: f64, h: f64, limits: (f64, f64)) {
        let tau = torque - self.damping * *qd;
        *qd += tau / self.inertia * h;
        *q += *qd * h;
        let (lo, hi) = limits;
        if *q <= lo {
            *q = lo;
            *qd = qd.max(0.0);
        } else if *q >= hi {
            *q = hi;
            *qd = qd.min(0.0);
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
    fn a_joint_accelerates_under_torque_is_damped_and_stops_hard_at_its_limits() {
        let joint = Joint {
            inertia: 1.0e-3,
            damping: 0.01,
        };
        let (mut q, mut qd) = (0.0, 0.0);
        joint.step(&mut q, &mut qd, 0.1, 0.001, (-1.0, 1.0));
        assert!(
            (qd - 0.1).abs() < 1e-12 && (q - 1.0e-4).abs() < 1e-12,
            "{q} {qd}"
        );
        // Damped: the speed under a constant torque tends to torque / damping (10 rad/s),
        // but the stop comes first and holds the joint there.
        for _ in 0..5000 {
            joint.step(&mut q, &mut qd, 0.1, 0.001, (-1.0, 1.0));
        }
        assert_eq!(
            (q, qd),
            (1.0, 0.0),
            "at the upper stop, still pushed into it"
        );
        joint.step(&mut q, &mut qd, -0.1, 0.001, (-1.0, 1.0));
        assert!(
            q < 1.0 && qd < 0.0,
            "it leaves the stop when pulled away: {q} {qd}"
        );
        // Without torque a moving joint slows down.
        let (mut q, mut qd) = (0.0, 1.0);
        joint.step(&mut q, &mut qd, 0.0, 0.001, (-1.0, 1.0));
        assert!((qd - 0.99).abs() < 1e-12, "{qd}");
        joint.step(&mut q, &mut qd, 0.0, 0.001, (-1.0, -0.5));
        assert_eq!(
            (q, qd),
            (-0.5, 0.0),
            "a joint outside its limits is put at the nearer stop"
        );
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
