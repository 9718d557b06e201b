//! The per-sample retargeting pipeline.

use teleop_hand_profile::{HandProfile, RetargetMode, MAX_JOINTS};
use teleop_kinematics::{OperatorHand, OperatorPose};

use crate::calibration::Calibration;
use crate::config::{JointConfig, RetargetConfig};
use crate::error::{ConfigError, RETARGET_ORIGIN};
use crate::filter::OneEuro;
use crate::solver::{SolveReport, Solver};
use crate::GLOVE_CHANNELS;

/// Longest time step (seconds) a single [`Retargeter::step`] accounts for.
///
/// A larger gap between consecutive glove stamps (a hiccup that the caller
/// did not treat as stale) is treated as this long, so one late sample cannot
/// open the filter or the slew limit wide: at most `max_speed * MAX_STEP_DT_S`
/// of motion per step.
pub const MAX_STEP_DT_S: f32 = 0.1;

/// One glove sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GloveInput {
    /// Monotonic stamp of the glove sample, nanoseconds.
    pub t_ns: u64,
    /// Raw positions, glove order (little, ring, middle, index, thumb,
    /// thumb_rotation). Any `u16` is accepted; values are clamped.
    pub raw: [u16; GLOVE_CHANNELS],
}

/// Joint targets for the hand, in the profile's joint order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointTargets {
    /// Normalised targets (0 = the joint's open angle, 1 = its closed angle),
    /// always finite and within each joint's `[min, max]` (a joint the
    /// fingertip solver drives and the configuration does not name: within its
    /// limits, which may lie beyond 0 and 1); the first `count` entries are
    /// used, the rest are 0.
    pub position: [f32; MAX_JOINTS],
    /// How many joints the hand has.
    pub count: usize,
    /// The configured slew limit (normalised/s), for the driver's speed field.
    pub max_speed: f32,
    /// True when this is a held command because the input is stale.
    pub held: bool,
    /// How many joints were clamped to their limits this step (slew limiting
    /// not counted).
    pub clamped: u8,
    /// How many joints were slew limited this step.
    pub slew_limited: u8,
}

impl JointTargets {
    /// The used targets.
    pub fn positions(&self) -> &[f32] {
        &self.position[..self.count.min(MAX_JOINTS)]
    }
}

/// How one joint is driven, resolved from the profile and the configuration.
#[derive(Debug, Clone, PartialEq)]
enum Drive {
    /// From the glove: `offset + Σ gain × closure(channel)`.
    Glove {
        /// `(channel, gain)`; at most one entry per glove channel is useful.
        channels: [(usize, f32); GLOVE_CHANNELS],
        /// Entries of `channels` in use.
        used: usize,
        /// Added to the sum.
        offset: f32,
    },
    /// Follows joint `to`: `angle = ratio × angle(to)` (radians), clamped.
    Coupled {
        /// The driven joint.
        to: usize,
        /// Radians per radian.
        ratio: f32,
    },
}

/// One joint of the retargeter: its drive, shaping, limits and the angles
/// its normalised range spans.
#[derive(Debug, Clone, PartialEq)]
struct JointPlan {
    drive: Drive,
    config: JointConfig,
    /// The configuration names this joint (its `[min, max]` then also bounds the fingertip
    /// solver).
    configured: bool,
    open: f32,
    closed: f32,
    lower: f32,
    upper: f32,
}

impl JointPlan {
    /// Normalised value of an angle (not clamped).
    fn normalised(&self, angle: f32) -> f32 {
        (angle - self.open) / (self.closed - self.open)
    }

    /// The joint's limits, normalised, lower first.
    fn travel(&self) -> (f32, f32) {
        let (a, b) = (self.normalised(self.lower), self.normalised(self.upper));
        (a.min(b), a.max(b))
    }

    /// Normalised value of the angle `ratio × angle(leader)`, clamped to
    /// this joint's limits (in radians, then in normalised units).
    fn follow(&self, leader: &JointPlan, leader_n: f32, ratio: f32) -> f32 {
        let angle = ratio * (leader.open + (leader.closed - leader.open) * leader_n);
        let angle = if angle.is_nan() {
            self.open
        } else {
            angle.clamp(self.lower, self.upper)
        };
        self.normalised(angle)
    }
}

/// Turns glove samples into joint targets for the hand a [`HandProfile`]
/// describes: glove map (calibrated channel closures, gains, offset) → curve
/// → One Euro filter → deadband → limits → slew limit, per driven joint;
/// coupled joints follow their joint.
#[derive(Debug, Clone)]
pub struct Retargeter {
    config: RetargetConfig,
    calibration: Calibration,
    mode: RetargetMode,
    /// The operator's hand model (the calibration's fit, or the default).
    operator: OperatorHand,
    /// Fingertip retargeting (modes `vector` and `pinch`).
    solver: Option<Solver>,
    plans: Vec<JointPlan>,
    filters: [OneEuro; MAX_JOINTS],
    /// Last filtered value accepted through the deadband, per joint.
    anchor: [f32; MAX_JOINTS],
    /// Stamp of the previous step; `None` before the first step / after reset.
    last_t_ns: Option<u64>,
    /// Last output (kept across [`Retargeter::reset`] so `hold` keeps working).
    last: Option<JointTargets>,
}

impl Retargeter {
    /// Validates the configuration (also against the profile's joint names)
    /// and the calibration.
    pub fn new(
        config: RetargetConfig,
        calibration: Calibration,
        profile: &HandProfile,
    ) -> Result<Self, ConfigError> {
        config.validate()?;
        config.check_joints(profile)?;
        calibration.validate()?;
        let mode = config.mode.unwrap_or(profile.retarget.mode);
        // A joint the configuration limits keeps its [min, max] in the fingertip modes too;
        // the others have their whole travel.
        let narrowed: Vec<Option<(f32, f32)>> = profile
            .joints
            .iter()
            .map(|j| {
                config.joints.get(&j.name).map(|c| {
                    let (a, b) = (j.radians(c.min), j.radians(c.max));
                    (a.min(b), a.max(b))
                })
            })
            .collect();
        let solver = match mode {
            RetargetMode::Joint => None,
            RetargetMode::Vector | RetargetMode::Pinch => Some(
                Solver::new(
                    profile,
                    config.fingertip,
                    mode == RetargetMode::Pinch,
                    &narrowed,
                )
                .ok_or_else(|| {
                    ConfigError::invalid(
                        RETARGET_ORIGIN,
                        "mode",
                        format!(
                            "`{}` needs fingers that follow operator fingers (`operator` in \
                             the hand profile); `{}` has none: use mode `joint`",
                            mode.name(),
                            profile.name
                        ),
                    )
                })?,
            ),
        };
        let operator = calibration.operator_hand();
        let plans = profile
            .joints
            .iter()
            .take(MAX_JOINTS)
            .map(|j| {
                let drive = match j.coupling {
                    Some(c) => Drive::Coupled {
                        to: c.to,
                        ratio: c.ratio,
                    },
                    None => {
                        let mut channels = [(0, 0.0); GLOVE_CHANNELS];
                        let used = j.glove.channels.len().min(GLOVE_CHANNELS);
                        channels[..used].copy_from_slice(&j.glove.channels[..used]);
                        Drive::Glove {
                            channels,
                            used,
                            offset: j.glove.offset,
                        }
                    }
                };
                JointPlan {
                    drive,
                    config: config.joint(&j.name),
                    configured: config.joints.contains_key(&j.name),
                    open: j.open,
                    closed: j.closed,
                    lower: j.lower,
                    upper: j.upper,
                }
            })
            .collect();
        Ok(Retargeter {
            config,
            calibration,
            mode,
            operator,
            solver,
            plans,
            filters: [OneEuro::default(); MAX_JOINTS],
            anchor: [0.0; MAX_JOINTS],
            last_t_ns: None,
            last: None,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &RetargetConfig {
        &self.config
    }

    /// The calibration in use.
    pub fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    /// The mode in use (the configuration's, else the hand profile's).
    pub fn mode(&self) -> RetargetMode {
        self.mode
    }

    /// The operator's hand model fingertip retargeting follows.
    pub fn operator(&self) -> &OperatorHand {
        &self.operator
    }

    /// What the last fingertip solve did (`None` in mode `joint`).
    pub fn solve_report(&self) -> Option<SolveReport> {
        self.solver.as_ref().map(Solver::report)
    }

    /// The operator's pose for glove closures (0 = open .. 1 = closed; thumb rotation 0 =
    /// outermost .. 1 = innermost).
    pub fn operator_pose(closure: &[f32; GLOVE_CHANNELS]) -> OperatorPose {
        OperatorPose::from_glove(&Calibration::position_of(closure))
    }

    /// Processes one glove sample. Allocates nothing.
    ///
    /// `dt` is the time since the previous sample's stamp, capped at
    /// [`MAX_STEP_DT_S`]; a stamp that is not later than the previous one
    /// counts as no time elapsed (the filter and the output do not move), and
    /// becomes the reference for the next step. The first step after
    /// construction or [`reset`](Self::reset) initialises the filter to the
    /// input and jumps straight to it (no deadband, no slew limit).
    ///
    /// Deadband: a filtered value is accepted only when it differs from the
    /// last accepted value by at least `deadband`; otherwise the last accepted
    /// value stays the target. In steady state the last accepted value is the
    /// previous output; while the slew limit is still catching up, measuring
    /// against it lets the move finish instead of stopping one deadband short.
    ///
    /// A coupled joint is computed after all driven joints, from its leader's
    /// output, and then clamped to its own `[min, max]`.
    pub fn step(&mut self, input: &GloveInput) -> JointTargets {
        let dt = match self.last_t_ns {
            Some(prev) if input.t_ns > prev => {
                let secs = (input.t_ns - prev) as f64 * 1e-9;
                secs.min(f64::from(MAX_STEP_DT_S)) as f32
            }
            _ => 0.0,
        };
        let fresh = self.last_t_ns.is_none();
        self.last_t_ns = Some(input.t_ns);
        let previous = if fresh {
            None
        } else {
            self.last.map(|t| t.position)
        };

        let closure = self.calibration.closure(&input.raw);
        if let Some(solver) = self.solver.as_mut() {
            let pads = self.operator.pads(&Self::operator_pose(&closure));
            solver.solve(&pads);
        }
        let max_step = self.config.max_speed * dt;
        let mut position = [0.0_f32; MAX_JOINTS];
        let mut clamped = 0_u8;
        let mut slew_limited = 0_u8;

        for (j, plan) in self.plans.iter().enumerate() {
            let Drive::Glove {
                channels,
                used,
                offset,
            } = &plan.drive
            else {
                continue;
            };
            let jc = &plan.config;
            let solved = self.solver.as_ref().filter(|s| s.drives(j));
            // The fingertip solver has the joint's whole travel; the glove map its [min, max].
            let (min, max) = match solved {
                Some(_) if !plan.configured => plan.travel(),
                _ => (jc.min, jc.max),
            };
            let shaped = match solved {
                // The fingertip solution, normalised (curves shape glove channels only).
                Some(solver) => plan.normalised(solver.solution()[j] as f32),
                None => {
                    let mut raw = *offset;
                    for &(ch, gain) in &channels[..*used] {
                        raw += gain * closure[ch];
                    }
                    jc.curve.apply(raw)
                }
            };
            let filtered = self.filters[j].filter(shaped, dt, &self.config.filter);
            let out = &mut position[j];

            let Some(prev) = previous.map(|p| p[j]) else {
                // Fresh start: jump to the (clamped) value.
                self.anchor[j] = filtered;
                let (v, c) = clamp_count(filtered, min, max);
                clamped += u8::from(c);
                *out = v;
                continue;
            };

            // Deadband: ignore changes smaller than the deadband relative to
            // the last accepted value (equal to the previous output unless
            // the slew limit is still catching up with it).
            if (filtered - self.anchor[j]).abs() >= self.config.deadband {
                self.anchor[j] = filtered;
            }
            let (target, c) = clamp_count(self.anchor[j], min, max);
            clamped += u8::from(c);

            // Slew limit relative to the previous output.
            let delta = target - prev;
            let v = if delta.abs() > max_step {
                slew_limited += 1;
                prev + max_step.copysign(delta)
            } else {
                target
            };
            // prev and target are both within limits, so v is too; guard rounding / NaN.
            *out = if v.is_finite() {
                v.clamp(min, max)
            } else {
                prev
            };
        }

        for (j, plan) in self.plans.iter().enumerate() {
            if let Drive::Coupled { to, ratio } = plan.drive {
                let followed = plan.follow(&self.plans[to], position[to], ratio);
                let (min, max) = match self.solver.as_ref().filter(|s| s.drives(j)) {
                    Some(_) if !plan.configured => plan.travel(),
                    _ => (plan.config.min, plan.config.max),
                };
                let (v, c) = clamp_count(followed, min, max);
                clamped += u8::from(c);
                position[j] = v;
            }
        }

        let targets = JointTargets {
            position,
            count: self.plans.len(),
            max_speed: self.config.max_speed,
            held: false,
            clamped,
            slew_limited,
        };
        self.last = Some(targets);
        targets
    }

    /// Input is stale: repeat the last output with `held = true` (never
    /// drift); `None` before the first step. `clamped` and `slew_limited` are
    /// 0 in a held command. Still available after [`reset`](Self::reset).
    pub fn hold(&self) -> Option<JointTargets> {
        self.last.map(|t| JointTargets {
            held: true,
            clamped: 0,
            slew_limited: 0,
            ..t
        })
    }

    /// Forgets the filter state and the previous stamp (e.g. after a long
    /// stale period): the next step starts fresh, like the first one (it
    /// jumps to the new value; the driver's speed field, `max_speed`, still
    /// bounds the physical motion). [`hold`](Self::hold) keeps returning the
    /// last output until then.
    pub fn reset(&mut self) {
        if let Some(solver) = self.solver.as_mut() {
            solver.reset();
        }
        self.filters = [OneEuro::default(); MAX_JOINTS];
        self.last_t_ns = None;
    }
}

/// Clamps `v` to `[min, max]` and says whether it had to (NaN -> `min`, counted).
fn clamp_count(v: f32, min: f32, max: f32) -> (f32, bool) {
    if v.is_nan() || v < min {
        (min, true)
    } else if v > max {
        (max, true)
    } else {
        (v, false)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::config::{Curve, OneEuroParams};

    const MS: u64 = 1_000_000;

    /// The Revo2 on its glove map: these tests are about mode `joint` (the fingertip modes
    /// have theirs in `solver` and the node's tests).
    fn revo2() -> HandProfile {
        let mut p = HandProfile::builtin("revo2").unwrap();
        p.retarget.mode = RetargetMode::Joint;
        p
    }

    fn input(t_ns: u64, raw: [u16; 6]) -> GloveInput {
        GloveInput { t_ns, raw }
    }

    fn default_rt() -> Retargeter {
        Retargeter::new(RetargetConfig::default(), Calibration::default(), &revo2()).unwrap()
    }

    #[test]
    fn first_step_jumps_with_default_calibration() {
        let mut rt = default_rt();
        let t = rt.step(&input(5, [1000; 6]));
        assert_eq!(t.positions(), [0.0; 6]);
        assert!(!t.held);
        assert_eq!(t.max_speed, 3.0);
        let mut rt = default_rt();
        let t = rt.step(&input(5, [0; 6]));
        assert_eq!(t.positions(), [1.0; 6]);
        assert_eq!(t.slew_limited, 0);
    }

    #[test]
    fn joint_order_and_thumb_rotation_sign() {
        let mut rt = default_rt();
        // glove: little, ring, middle, index, thumb, thumb_rotation
        let t = rt.step(&input(0, [900, 800, 700, 600, 500, 100]));
        // Revo2: thumb_flex, thumb_abduct, index, middle, ring, pinky
        let expect = [0.5, 0.9, 0.4, 0.3, 0.2, 0.1];
        for (a, b) in t.positions().iter().zip(expect) {
            assert!((a - b).abs() < 1e-6, "{:?}", t.position);
        }
        // thumb rotated to the outermost position -> abduct 0 (thumb out)
        let mut rt = default_rt();
        let t = rt.step(&input(0, [0, 0, 0, 0, 0, 1000]));
        assert_eq!(t.position[1], 0.0);
    }

    #[test]
    fn curves_apply_per_joint() {
        let mut cfg = RetargetConfig::default();
        cfg.joints.entry("index".into()).or_default().curve = Curve::Gamma { gamma: 2.0 };
        cfg.joints.entry("middle".into()).or_default().curve = Curve::Piecewise {
            points: vec![[0.0, 0.0], [0.5, 0.3], [1.0, 1.0]],
        };
        let mut rt = Retargeter::new(cfg, Calibration::default(), &revo2()).unwrap();
        let t = rt.step(&input(0, [500; 6]));
        assert!((t.position[2] - 0.25).abs() < 1e-6);
        assert!((t.position[3] - 0.3).abs() < 1e-6);
        assert!((t.position[4] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn limits_clamp_and_count() {
        let mut cfg = RetargetConfig::default();
        cfg.joints.entry("pinky".into()).or_default().min = 0.2;
        cfg.joints.entry("ring".into()).or_default().max = 0.7;
        let mut rt = Retargeter::new(cfg, Calibration::default(), &revo2()).unwrap();
        let t = rt.step(&input(0, [1000, 0, 500, 500, 500, 500]));
        assert_eq!(t.position[5], 0.2);
        assert_eq!(t.position[4], 0.7);
        assert_eq!(t.clamped, 2);
    }

    #[test]
    fn deadband_holds_small_changes() {
        // Nearly transparent filter so the deadband is what we observe.
        let cfg = RetargetConfig {
            deadband: 0.05,
            filter: OneEuroParams {
                min_cutoff_hz: 1.0e4,
                ..OneEuroParams::default()
            },
            ..RetargetConfig::default()
        };
        let mut rt = Retargeter::new(cfg, Calibration::default(), &revo2()).unwrap();
        let t0 = rt.step(&input(0, [500; 6]));
        let mut t = 0;
        for _ in 0..100 {
            t += MS;
            // 0.03 change: inside the deadband
            let out = rt.step(&input(t, [470; 6]));
            assert_eq!(out.position, t0.position);
        }
        // 0.1 change: outside the deadband, output moves to it
        for _ in 0..100 {
            t += MS;
            rt.step(&input(t, [400; 6]));
        }
        let out = rt.step(&input(t + MS, [400; 6]));
        for &p in out.positions() {
            // accepted once it crossed the deadband: within one deadband of 0.6
            assert!((0.55..=0.6 + 1e-6).contains(&p), "{:?}", out.position);
        }
    }

    #[test]
    fn slew_limit_bounds_speed() {
        // Nearly transparent filter: let the slew limit dominate.
        let cfg = RetargetConfig {
            max_speed: 2.0,
            filter: OneEuroParams {
                min_cutoff_hz: 1.0e4,
                ..OneEuroParams::default()
            },
            ..RetargetConfig::default()
        };
        let mut rt = Retargeter::new(cfg, Calibration::default(), &revo2()).unwrap();
        let mut prev = rt.step(&input(0, [1000; 6])).position;
        assert_eq!(prev, [0.0; 24]);
        let mut t = 0;
        let mut reached_at = None;
        let mut saw_limit = false;
        for _ in 0..2000 {
            t += MS;
            let out = rt.step(&input(t, [0; 6]));
            saw_limit |= out.slew_limited == 6;
            for (a, b) in out.positions().iter().zip(prev) {
                assert!(a - b <= 2.0 * 0.001 + 1e-6, "moved {} in 1 ms", a - b);
            }
            prev = out.position;
            if reached_at.is_none() && out.positions().iter().all(|&p| p >= 1.0 - 0.005) {
                reached_at = Some(t);
            }
        }
        assert!(saw_limit);
        let reached_at = reached_at.expect("reaches closed");
        // open -> closed takes at least 1 / max_speed seconds
        assert!(
            reached_at as f64 * 1e-9 >= (1.0 - 0.005) / 2.0,
            "{reached_at}"
        );
        assert!(reached_at as f64 * 1e-9 <= 0.6, "{reached_at}");
    }

    #[test]
    fn large_gap_is_capped() {
        let mut cfg = RetargetConfig::default();
        cfg.filter.min_cutoff_hz = 1.0e4;
        let mut rt = Retargeter::new(cfg, Calibration::default(), &revo2()).unwrap();
        rt.step(&input(0, [1000; 6]));
        let out = rt.step(&input(10_000 * MS, [0; 6]));
        for &p in out.positions() {
            assert!((p - 3.0 * MAX_STEP_DT_S).abs() < 1e-4, "{p}");
        }
    }

    #[test]
    fn non_monotonic_stamps_do_not_move_or_nan() {
        let mut rt = default_rt();
        let a = rt.step(&input(100 * MS, [800; 6]));
        let b = rt.step(&input(50 * MS, [0; 6]));
        assert_eq!(a.position, b.position);
        let c = rt.step(&input(50 * MS, [0; 6]));
        assert_eq!(a.position, c.position);
        // time moves on from the new reference
        let d = rt.step(&input(60 * MS, [0; 6]));
        assert!(d.position.iter().all(|p| p.is_finite()));
        assert!(d.position[0] > a.position[0]);
    }

    #[test]
    fn hold_before_and_after_first_step() {
        let mut rt = default_rt();
        assert_eq!(rt.hold(), None);
        let t = rt.step(&input(0, [300; 6]));
        let h = rt.hold().unwrap();
        assert!(h.held);
        assert_eq!(h.position, t.position);
        assert_eq!(h.max_speed, t.max_speed);
        // hold never drifts
        assert_eq!(rt.hold(), Some(h));
        // hold does not disturb the state: the next step continues from it
        let n = rt.step(&input(MS, [300; 6]));
        assert!(!n.held);
        assert_eq!(n.position, t.position);
    }

    #[test]
    fn reset_starts_fresh_but_hold_survives() {
        let mut rt = default_rt();
        let t = rt.step(&input(0, [1000; 6]));
        rt.reset();
        assert_eq!(rt.hold().unwrap().position, t.position);
        let n = rt.step(&input(0, [0; 6]));
        assert_eq!(n.positions(), [1.0; 6]);
        assert_eq!(n.slew_limited, 0);
    }

    #[test]
    fn new_validates_both() {
        let cfg = RetargetConfig {
            max_speed: -1.0,
            ..RetargetConfig::default()
        };
        let err = Retargeter::new(cfg, Calibration::default(), &revo2()).unwrap_err();
        assert!(
            err.to_string().starts_with("retarget config: max_speed: "),
            "{err}"
        );
        let mut cal = Calibration::default();
        cal.fingers[0].closed = 990;
        let err = Retargeter::new(RetargetConfig::default(), cal, &revo2()).unwrap_err();
        assert!(
            err.to_string().starts_with("calibration: [little]: "),
            "{err}"
        );
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod fingertip_tests {
    use super::*;
    use crate::config::JointConfig;

    #[test]
    fn a_configured_joint_keeps_its_limits_in_the_fingertip_modes() {
        let profile = HandProfile::builtin("allegro").unwrap();
        let mut config = RetargetConfig::default();
        config.joints.insert(
            "index_1".into(),
            JointConfig {
                max: 0.3,
                ..JointConfig::default()
            },
        );
        let index_1 = profile.joint_index("index_1").unwrap();
        for mode in [RetargetMode::Vector, RetargetMode::Pinch] {
            config.mode = Some(mode);
            let mut rt = Retargeter::new(config.clone(), Calibration::default(), &profile).unwrap();
            let mut highest: f32 = 0.0;
            // A fist, then open, then a fist.
            for k in 0..600u64 {
                let raw = if (k / 200) % 2 == 0 {
                    [0; 6]
                } else {
                    [1000; 6]
                };
                let out = rt.step(&GloveInput {
                    t_ns: k * 3_500_000,
                    raw,
                });
                highest = highest.max(out.position[index_1]);
            }
            assert!(highest <= 0.3, "{}: index_1 reached {highest}", mode.name());
            assert!(highest > 0.25, "{}: index_1 reached {highest}", mode.name());
        }
    }
}
