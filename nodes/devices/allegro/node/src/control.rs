//! The host's joint controller, pure: the velocity filter and the PD law with its limits.
//!
//! `PWM = kp (target - q) - kd q̇_f` (R4, gains in PWM counts per rad and per rad/s), limited to
//! the joint's PWM limit (itself capped at the hand's PWM per N m, the global limit in
//! docs/devices/allegro.md) and to the absolute torque limit; the torque sent is that PWM over the
//! PWM per N m. NaN or infinite inputs give zero torque, never a saturated one.

use teleop_allegro_protocol::JOINTS;

use crate::config::VelocityFilterKind;

/// The limits of one hand's torques.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// PWM counts per N m.
    pub pwm_per_nm: f64,
    /// PWM limit per joint (positive).
    pub pwm: [i16; JOINTS],
    /// Absolute torque limit, N m.
    pub max_torque_nm: f64,
}

impl Limits {
    /// The torque limit of joint `j`: the smaller of its PWM limit (capped at the PWM per N m)
    /// in N m and the absolute limit.
    pub fn torque_limit(&self, j: usize) -> f64 {
        let k = self.pwm_per_nm;
        if !(k.is_finite() && k > 0.0) {
            return 0.0;
        }
        let pwm = f64::from(self.pwm[j].max(0)).min(k);
        (pwm / k).min(self.max_torque_nm.max(0.0))
    }
}

/// The PD torque of one joint, N m, and whether it was limited. Never above `limit` in
/// magnitude; zero for non-finite inputs.
pub fn pd_torque(
    kp: f64,
    kd: f64,
    target: f64,
    q: f64,
    qdot: f64,
    pwm_per_nm: f64,
    limit: f64,
) -> (f64, bool) {
    let pwm = kp * (target - q) - kd * qdot;
    let torque = pwm / pwm_per_nm;
    if !torque.is_finite() || !limit.is_finite() {
        return (0.0, false);
    }
    let limit = limit.max(0.0);
    if torque > limit {
        (limit, true)
    } else if torque < -limit {
        (-limit, true)
    } else {
        (torque, false)
    }
}

/// Joint velocity estimation from positions sampled every `dt`.
#[derive(Debug, Clone)]
pub struct VelocityFilter {
    kind: VelocityFilterKind,
    cutoff_hz: f64,
    started: bool,
    q_prev: [f64; JOINTS],
    q_f: [f64; JOINTS],
    v_prev: [f64; JOINTS],
    v_f: [f64; JOINTS],
}

impl VelocityFilter {
    /// A filter of the given kind (`cutoff_hz` for the low-pass).
    pub fn new(kind: VelocityFilterKind, cutoff_hz: f64) -> Self {
        Self {
            kind,
            cutoff_hz,
            started: false,
            q_prev: [0.0; JOINTS],
            q_f: [0.0; JOINTS],
            v_prev: [0.0; JOINTS],
            v_f: [0.0; JOINTS],
        }
    }

    /// Forgets the past (after a bring-up): the next sample starts at rest.
    pub fn reset(&mut self) {
        self.started = false;
    }

    /// Takes the positions of one cycle, `dt` seconds after the previous, and returns the
    /// filtered velocities (rad/s).
    pub fn update(&mut self, q: &[f64; JOINTS], dt: f64) -> [f64; JOINTS] {
        if !(self.started && dt.is_finite() && dt > 0.0) {
            self.started = true;
            self.q_prev = *q;
            self.q_f = *q;
            self.v_prev = [0.0; JOINTS];
            self.v_f = [0.0; JOINTS];
            return self.v_f;
        }
        match self.kind {
            VelocityFilterKind::R4 => {
                // docs/devices/allegro.md: R4's q_f = 0.6 q_f + 0.198 (q_prev + q), same on
                // velocity.
                for (j, &qj) in q.iter().enumerate() {
                    let q_f = 0.6 * self.q_f[j] + 0.198 * (self.q_prev[j] + qj);
                    let v = (q_f - self.q_f[j]) / dt;
                    self.v_f[j] = 0.6 * self.v_f[j] + 0.198 * (self.v_prev[j] + v);
                    self.q_f[j] = q_f;
                    self.v_prev[j] = v;
                }
            }
            VelocityFilterKind::LowPass => {
                let tau = 1.0 / (2.0 * std::f64::consts::PI * self.cutoff_hz);
                let alpha = dt / (dt + tau);
                for (j, &qj) in q.iter().enumerate() {
                    let v = (qj - self.q_prev[j]) / dt;
                    self.v_f[j] += alpha * (v - self.v_f[j]);
                }
            }
        }
        for v in &mut self.v_f {
            if !v.is_finite() {
                *v = 0.0;
            }
        }
        self.q_prev = *q;
        self.v_f
    }
}

/// One cycle's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output {
    /// Filtered joint velocities, rad/s.
    pub qdot: [f64; JOINTS],
    /// Commanded torques, N m (within the limits).
    pub torque: [f64; JOINTS],
    /// Joints whose torque was limited.
    pub limited: u32,
}

/// The 16-joint PD controller.
#[derive(Debug, Clone)]
pub struct Controller {
    kp: [f64; JOINTS],
    kd: [f64; JOINTS],
    limits: Limits,
    torque_limit: [f64; JOINTS],
    filter: VelocityFilter,
}

impl Controller {
    /// A controller with these gains, limits and velocity filter.
    pub fn new(
        kp: [f64; JOINTS],
        kd: [f64; JOINTS],
        limits: Limits,
        filter: VelocityFilter,
    ) -> Self {
        let mut torque_limit = [0.0; JOINTS];
        for (j, l) in torque_limit.iter_mut().enumerate() {
            *l = limits.torque_limit(j);
        }
        Self {
            kp,
            kd,
            limits,
            torque_limit,
            filter,
        }
    }

    /// The limits in use.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// Restarts the velocity estimate (after a bring-up).
    pub fn reset(&mut self) {
        self.filter.reset();
    }

    /// One cycle: positions `q` measured `dt` seconds after the previous ones, toward `target`.
    pub fn step(&mut self, q: &[f64; JOINTS], dt: f64, target: &[f64; JOINTS]) -> Output {
        let qdot = self.filter.update(q, dt);
        let mut torque = [0.0; JOINTS];
        let mut limited = 0;
        for j in 0..JOINTS {
            let (t, lim) = pd_torque(
                self.kp[j],
                self.kd[j],
                target[j],
                q[j],
                qdot[j],
                self.limits.pwm_per_nm,
                self.torque_limit[j],
            );
            torque[j] = t;
            limited += u32::from(lim);
        }
        Output {
            qdot,
            torque,
            limited,
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use proptest::prelude::*;
    use teleop_allegro_protocol::torque_to_pwm;

    fn limits() -> Limits {
        Limits {
            pwm_per_nm: 1200.0,
            pwm: crate::config::AllegroConfig::default().pwm_limit,
            max_torque_nm: 1.0,
        }
    }

    #[test]
    fn limits_are_the_smallest_of_the_three() {
        let l = limits();
        assert!((l.torque_limit(1) - 675.0 / 1200.0).abs() < 1e-12);
        let low = Limits {
            max_torque_nm: 0.1,
            ..l
        };
        assert!((low.torque_limit(1) - 0.1).abs() < 1e-12);
        // The global cap: a joint limit above the PWM per N m is cut to it.
        let small_k = Limits {
            pwm_per_nm: 500.0,
            max_torque_nm: 10.0,
            ..l
        };
        assert!((small_k.torque_limit(1) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn pd_pushes_toward_the_target_and_damps() {
        let (t, lim) = pd_torque(600.0, 15.0, 0.1, 0.0, 0.0, 1200.0, 1.0);
        assert!((t - 0.05).abs() < 1e-12 && !lim);
        let (t, _) = pd_torque(600.0, 15.0, 0.0, 0.0, 2.0, 1200.0, 1.0);
        assert!((t + 0.025).abs() < 1e-12);
        let (t, lim) = pd_torque(600.0, 15.0, 10.0, 0.0, 0.0, 1200.0, 0.3);
        assert!(t == 0.3 && lim);
        assert_eq!(
            pd_torque(600.0, 15.0, f64::NAN, 0.0, 0.0, 1200.0, 0.3),
            (0.0, false)
        );
    }

    #[test]
    fn velocity_estimates_settle_on_a_ramp() {
        for kind in [VelocityFilterKind::R4, VelocityFilterKind::LowPass] {
            let mut f = VelocityFilter::new(kind, 30.0);
            let dt = 0.003;
            let mut v = [0.0; JOINTS];
            for i in 0..300 {
                let q = [0.5 * dt * f64::from(i); JOINTS];
                v = f.update(&q, dt);
            }
            // R4's filter has a DC gain of 0.396/0.4 = 0.99.
            assert!((v[3] - 0.5).abs() < 0.01, "{kind:?}: {}", v[3]);
            f.reset();
            assert_eq!(f.update(&[1.0; JOINTS], dt), [0.0; JOINTS]);
        }
    }

    proptest! {
        /// Whatever the targets, positions, velocities and gains, the torque (and the PWM sent)
        /// is never above the configured limit.
        #[test]
        fn torque_never_exceeds_the_limit(
            target in prop::array::uniform16(prop_oneof![any::<f64>(), -10.0..10.0f64]),
            q in prop::array::uniform16(prop_oneof![any::<f64>(), -3.0..3.0f64]),
            kp in prop::array::uniform16(prop_oneof![0.0..1e6f64, Just(f64::INFINITY)]),
            kd in prop::array::uniform16(0.0..1e4f64),
            dt in prop_oneof![0.0..0.1f64, Just(f64::NAN)],
            pwm in prop::array::uniform16(1i16..=i16::MAX),
            k in 1.0..5000.0f64,
            max_torque in 0.0..5.0f64,
            steps in 1usize..4,
        ) {
            let limits = Limits { pwm_per_nm: k, pwm, max_torque_nm: max_torque };
            let mut c = Controller::new(kp, kd, limits, VelocityFilter::new(VelocityFilterKind::R4, 30.0));
            for _ in 0..steps {
                let out = c.step(&q, dt, &target);
                for (j, (&t, &limit)) in out.torque.iter().zip(&pwm).enumerate() {
                    prop_assert!(t.is_finite());
                    prop_assert!(t.abs() <= max_torque, "joint {j}: {t} > {max_torque}");
                    prop_assert!(t.abs() * k <= f64::from(limit) + 1e-6);
                    let sent = torque_to_pwm(t, k, 1, limit);
                    prop_assert!(sent.unsigned_abs() <= limit.unsigned_abs());
                }
            }
        }
    }
}
