//! One Euro filter (Casiez, Roussel, Vogel: "1€ Filter", CHI 2012).

use crate::config::OneEuroParams;

/// State of one One Euro filter channel. State is kept in `f64` so that very
/// small smoothing factors still converge exactly.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct OneEuro {
    /// Previous filtered value and derivative estimate; `None` before the first sample.
    state: Option<(f64, f64)>,
}

/// Smoothing factor for a first-order low-pass at `cutoff_hz` over `dt` seconds.
fn alpha(cutoff_hz: f64, dt: f64) -> f64 {
    let tau = 1.0 / (2.0 * std::f64::consts::PI * cutoff_hz);
    let a = 1.0 / (1.0 + tau / dt);
    if a.is_finite() {
        a.clamp(0.0, 1.0)
    } else {
        // tau or dt degenerate: tau = inf -> 0 (no change); anything else -> pass through.
        if tau.is_infinite() {
            0.0
        } else {
            1.0
        }
    }
}

impl OneEuro {
    /// Filters `x` sampled `dt` seconds after the previous sample. The first
    /// sample initialises the filter to `x`; `dt <= 0` (or not finite) means no
    /// time elapsed and returns the previous value unchanged. A non-finite `x`
    /// is ignored. The output is a convex combination of inputs, so it stays
    /// within the range of the inputs seen.
    pub(crate) fn filter(&mut self, x: f32, dt: f32, p: &OneEuroParams) -> f32 {
        let x = f64::from(x);
        let Some((prev, dx_prev)) = self.state else {
            if !x.is_finite() {
                return 0.0;
            }
            self.state = Some((x, 0.0));
            return x as f32;
        };
        let dt = f64::from(dt);
        if !(dt > 0.0 && dt.is_finite() && x.is_finite()) {
            return prev as f32;
        }
        let dx = (x - prev) / dt;
        let a_d = alpha(f64::from(p.d_cutoff_hz), dt);
        let dx_hat = dx_prev + a_d * (dx - dx_prev);
        let cutoff = f64::from(p.min_cutoff_hz) + f64::from(p.beta) * dx_hat.abs();
        let a = alpha(cutoff, dt);
        let x_hat = prev + a * (x - prev);
        if x_hat.is_finite() && dx_hat.is_finite() {
            self.state = Some((x_hat, dx_hat));
            x_hat as f32
        } else {
            prev as f32
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn initialises_and_converges() {
        let p = OneEuroParams::default();
        let mut f = OneEuro::default();
        assert_eq!(f.filter(0.2, 0.0, &p), 0.2);
        let mut y = 0.0;
        for _ in 0..2000 {
            y = f.filter(0.8, 0.001, &p);
            assert!((0.2..=0.8).contains(&y));
        }
        assert!((y - 0.8).abs() < 1e-4, "{y}");
    }

    #[test]
    fn zero_dt_holds() {
        let p = OneEuroParams::default();
        let mut f = OneEuro::default();
        f.filter(0.2, 0.0, &p);
        assert_eq!(f.filter(0.9, 0.0, &p), 0.2);
        assert_eq!(f.filter(0.9, -1.0, &p), 0.2);
        assert_eq!(f.filter(0.9, f32::NAN, &p), 0.2);
        assert!(f.filter(0.9, 0.01, &p) > 0.2);
    }

    #[test]
    fn faster_motion_means_less_lag() {
        let slow = OneEuroParams {
            beta: 0.0,
            ..OneEuroParams::default()
        };
        let fast = OneEuroParams {
            beta: 5.0,
            ..OneEuroParams::default()
        };
        let (mut a, mut b) = (OneEuro::default(), OneEuro::default());
        a.filter(0.0, 0.0, &slow);
        b.filter(0.0, 0.0, &fast);
        let (mut ya, mut yb) = (0.0, 0.0);
        for _ in 0..50 {
            ya = a.filter(1.0, 0.001, &slow);
            yb = b.filter(1.0, 0.001, &fast);
        }
        assert!(yb > ya, "{yb} <= {ya}");
    }
}
