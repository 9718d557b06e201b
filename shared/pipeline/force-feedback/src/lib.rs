//! Force-feedback law of the teleoperation pipeline: a robot hand's fingertip
//! tactile forces (or, as a fallback, contact estimated from the hand's joint
//! state) become per-finger force commands for the EH55BF1 exoskeleton glove.
//! Which fingertip and which joints drive each glove finger comes from the
//! hand's profile (`teleop-hand-profile`); no hand is named in this crate.
//!
//! # What this crate owns
//!
//! Only the pure control law ([`ForceFeedback::step`]) and its configuration
//! ([`FeedbackConfig`]): contact thresholds and gains, the joint-state contact
//! estimate (position error, motor current, joint effort), the hysteresis,
//! smoothing, rate limiting, saturation, the stale-input ramp and the e-stop, applied through
//! the profile's per-glove-finger [`FeedbackSource`]s; and the time-domain
//! passivity layer on its output ([`Passivity`]). It does no I/O,
//! reads no clock and does no IPC: the caller hands in configuration text
//! (with its origin for error messages) and timestamped inputs, and gets a
//! force command back.
//!
//! # What it must not depend on
//!
//! No iceoryx2, no message/IPC crate (`teleop-msgs`), no runtime crate, no
//! logging, no clock. Converting wire messages into [`Inputs`] and
//! [`FeedbackOutput`] into the glove command is the feedback node's job.
//!
//! # Conventions
//!
//! * Glove order `[little, ring, middle, index, thumb]`; force in glove units
//!   `-1000..=1000` (about 3 N at 1000), **positive pushes the operator's hand
//!   open**, i.e. resists closing on an object. This law only outputs
//!   `0..=max_force`.
//! * Tactile: the profile's fingertip order, normal force in newtons.
//! * Joints: the profile's joint order, positions normalised (0 = the joint's
//!   open angle .. 1 = its closed angle), current in mA, effort in N m.
//! * A glove finger whose source is empty (a finger the hand does not have,
//!   like the Allegro's missing little finger) always gets zero force.
//!
//! # Configuration
//!
//! Every key is optional (defaults shown); unknown keys are errors.
//!
//! ```
//! use teleop_force_feedback::FeedbackConfig;
//!
//! let text = r#"
//! contact_threshold_n = 0.3   # N; below it no contact from tactile
//! gain_per_n = 250.0          # glove units per N above the threshold
//! max_force = 800             # saturation, 0..=1000 glove units
//! rate_limit_per_s = 20000.0  # glove units per second
//! smoothing_tau_s = 0.01      # s, 0 disables the low-pass
//! stale_ramp_s = 0.1          # s from max_force to 0 when inputs are stale
//! hysteresis = 0.0            # glove units of backlash on the demand (0: off)
//! finger_gain = [1.0, 1.0, 1.0, 1.0, 1.0]  # glove order, each in [0, 2]
//!
//! [estimate]                  # fallback when tactile is absent/invalid
//! use_position_error = true
//! position_error_threshold = 0.05  # normalised commanded - measured
//! position_gain = 4000.0           # glove units per normalised error
//! use_current = true
//! current_threshold_ma = 300.0     # mA, on |current|
//! current_gain_per_ma = 1.0        # glove units per mA
//! current_toward_closing = false   # true: only current toward the closed angle counts
//! current_stall_speed_rad_s = 0.0  # current counts only below this joint speed (0: always)
//! use_effort = true
//! effort_threshold_nm = 0.05       # N m, of the effort toward the closed angle
//! effort_gain_per_nm = 2000.0      # glove units per N m
//! effort_stall_speed_rad_s = 0.0   # effort counts only below this joint speed (0: always)
//!
//! [passivity]                 # time-domain passivity per glove finger (see `Passivity`)
//! mode = "auto"               # auto (while a bridge is in the path), on, off
//! max_damping = 300.0         # glove units per (travel per second)
//! reset_after_s = 0.2         # s without demand before a finger's energy sum restarts
//! max_stored = 50.0           # glove units x travel the observer keeps at most
//! tolerance = 10.0            # the deficit (glove units x travel) the controller lets pass
//! recovery_per_s = 1000.0     # glove units per second the force climbs back after it acted
//! "#;
//! let config = FeedbackConfig::from_toml_str(text, "feedback.toml")?;
//! assert_eq!(config, FeedbackConfig::default());
//! # Ok::<(), teleop_force_feedback::ConfigError>(())
//! ```
//!
//! # Timing
//!
//! `dt` comes from consecutive [`Inputs::t_ns`]. The first step after
//! construction has `dt = 0`, so the output starts at 0 and can only move from
//! the second step on, by at most `rate_limit_per_s * dt`. A timestamp that
//! does not advance (equal or going backwards) also counts as `dt = 0` (the
//! output holds) and becomes the new reference, so the law re-synchronises
//! instead of freezing until the clock catches up.

mod config;
mod passivity;
#[cfg(test)]
mod tests;

pub use config::{
    ConfigError, EstimateConfig, FeedbackConfig, PstConfig, GLOVE_FULL_SCALE, IN_MEMORY_ORIGIN,
};
pub use passivity::{OperatorInput, Passivity, PassivityConfig, PassivityMode, PassivityReport};
pub use teleop_hand_profile::{FeedbackSource, HandProfile, MAX_FINGERTIPS, MAX_JOINTS};

/// Number of glove fingers (`[little, ring, middle, index, thumb]`).
pub const GLOVE_FINGERS: usize = 5;

/// One tactile sample, in the profile's fingertip order.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TactileInput {
    /// Fingertip normal force in newtons.
    pub normal_n: [f32; MAX_FINGERTIPS],
    /// False when the device flagged the fingertip's value as invalid,
    /// not updated or timed out (or the fingertip is not in the sample).
    pub valid: [bool; MAX_FINGERTIPS],
}

/// One hand joint-state sample, in the profile's joint order (unused entries
/// are ignored).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HandInput {
    /// Commanded positions, normalised 0 = open .. 1 = closed.
    pub commanded: [f32; MAX_JOINTS],
    /// Measured positions, normalised 0 = open .. 1 = closed.
    pub measured: [f32; MAX_JOINTS],
    /// Motor currents in mA (signed; the magnitude is used; NaN = unknown).
    pub current_ma: [f32; MAX_JOINTS],
    /// Joint efforts in N m (signed, positive toward larger angles; the part toward the joint's
    /// closed angle is used; NaN = unknown).
    pub effort_nm: [f32; MAX_JOINTS],
    /// Joint speeds in rad/s (signed; NaN = unknown).
    pub speed_rad_s: [f32; MAX_JOINTS],
}

/// State of the tactile input at this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tactile {
    /// A fresh tactile sample.
    Fresh(TactileInput),
    /// The hand has tactile sensing but its input timed out: forces ramp to
    /// zero.
    Stale,
    /// This hand has no tactile sensing (never received): contact is
    /// estimated from the joint state.
    Absent,
}

/// Everything [`ForceFeedback::step`] needs for one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inputs {
    /// Timestamp of this step in nanoseconds (any monotonic clock).
    pub t_ns: u64,
    /// Tactile input.
    pub tactile: Tactile,
    /// Hand joint state; `None` when stale or never received.
    pub hand: Option<HandInput>,
    /// Emergency stop: all forces zero at once.
    pub estop: bool,
    /// The operator's finger positions, for the passivity observer; `None` when the glove's
    /// samples are stale or absent (the observer waits).
    pub operator: Option<OperatorInput>,
    /// A link between stations is in the path (the passivity controller's `auto` mode).
    pub remote: bool,
}

/// Where a finger's force demand came from at this step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum ContactSource {
    /// No contact (zero demand). The output may still be decaying through
    /// the smoothing/rate limit from an earlier contact.
    None = 0,
    /// Fingertip tactile force above the threshold.
    Tactile = 1,
    /// Joint position error (commanded - measured) above the threshold.
    PositionError = 2,
    /// Motor current magnitude above the threshold.
    Current = 3,
    /// Inputs stale: the force is ramping toward (or held at) zero.
    Ramping = 4,
    /// Emergency stop: force forced to zero.
    EStop = 5,
    /// Joint effort toward the closed angle above the threshold.
    Effort = 6,
}

/// Result of one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedbackOutput {
    /// Force command per glove finger (glove order), glove units, positive
    /// pushes the hand open. Always within `0..=max_force`.
    pub force: [i16; GLOVE_FINGERS],
    /// Source of each finger's demand.
    pub source: [ContactSource; GLOVE_FINGERS],
    /// Number of fingers whose demand (after `finger_gain`) exceeded
    /// `max_force` this step and was saturated.
    pub clamped: u8,
    /// True when at least one finger ramped toward zero this step because of
    /// stale input.
    pub stale: bool,
    /// The passivity observer's energy and what its controller did.
    pub passivity: PassivityReport,
}

/// Per-finger demand chosen at one step.
enum Demand {
    /// Drive the filter toward this value (glove units, finite, >= 0, before
    /// `finger_gain`).
    Value(f32, ContactSource),
    /// Inputs stale: ramp toward zero.
    Ramp,
}

/// The force-feedback law with its state (filter, rate limiter, last
/// timestamp). One instance per glove/hand pair.
#[derive(Debug, Clone)]
pub struct ForceFeedback {
    config: FeedbackConfig,
    /// Per glove finger, what drives it (from the hand profile).
    sources: [FeedbackSource; GLOVE_FINGERS],
    /// Per joint, +1 or -1: the sign of an effort toward the joint's closed angle (profile).
    closing: [f32; MAX_JOINTS],
    /// Low-pass filter state per glove finger, in `[0, max_force]`.
    filtered: [f32; GLOVE_FINGERS],
    /// Each finger's demand after the backlash (`hysteresis`).
    held: [f32; GLOVE_FINGERS],
    /// Rate-limited output per glove finger, in `[0, max_force]`.
    output: [f32; GLOVE_FINGERS],
    /// Timestamp of the previous step.
    last_t_ns: Option<u64>,
    /// The passivity observer and controller.
    passivity: Passivity,
}

/// `x` if finite and positive, else 0. For values that come from outside.
fn positive_or_zero(x: f32) -> f32 {
    if x.is_finite() && x > 0.0 {
        x
    } else {
        0.0
    }
}

/// `x` if positive (including `+inf`, which later saturates), else 0
/// (negative, zero or NaN). For products of validated gains and sanitised
/// inputs, which may overflow to `+inf` but then still mean "a lot".
fn non_negative(x: f32) -> f32 {
    if x > 0.0 {
        x
    } else {
        0.0
    }
}

impl ForceFeedback {
    /// Creates the law for `profile`'s feedback sources after validating
    /// `config`; all forces start at zero.
    pub fn new(config: FeedbackConfig, profile: &HandProfile) -> Result<Self, ConfigError> {
        config.validate()?;
        let mut sources = profile.feedback.clone();
        // Indices beyond the contract's arrays cannot occur in a checked
        // profile; drop them rather than index out of bounds.
        for s in &mut sources {
            s.tactile = s.tactile.filter(|&t| t < MAX_FINGERTIPS);
            s.joints.retain(|&j| j < MAX_JOINTS);
        }
        let mut closing = [1.0; MAX_JOINTS];
        for (c, joint) in closing.iter_mut().zip(&profile.joints) {
            if joint.closed < joint.open {
                *c = -1.0;
            }
        }
        Ok(Self {
            passivity: Passivity::new(config.passivity.clone()),
            config,
            sources,
            closing,
            filtered: [0.0; GLOVE_FINGERS],
            held: [0.0; GLOVE_FINGERS],
            output: [0.0; GLOVE_FINGERS],
            last_t_ns: None,
        })
    }

    /// The configuration in use.
    pub fn config(&self) -> &FeedbackConfig {
        &self.config
    }

    /// Forgets all state: forces back to zero and the next step is treated
    /// as the first (`dt = 0`).
    pub fn reset(&mut self) {
        self.filtered = [0.0; GLOVE_FINGERS];
        self.held = [0.0; GLOVE_FINGERS];
        self.output = [0.0; GLOVE_FINGERS];
        self.last_t_ns = None;
        self.passivity.reset();
    }

    /// Seconds since the previous step; 0 on the first step and when the
    /// timestamp does not advance. Updates the reference timestamp.
    fn advance_clock(&mut self, t_ns: u64) -> f32 {
        let dt = match self.last_t_ns {
            Some(last) if t_ns > last => (t_ns - last) as f64 * 1e-9,
            _ => 0.0,
        };
        self.last_t_ns = Some(t_ns);
        dt as f32
    }

    /// Demand from the joint-state estimate: the largest over `joints`.
    fn estimate(&self, hand: &HandInput, joints: &[usize]) -> Demand {
        let mut best = (0.0_f32, ContactSource::None);
        for &joint in joints {
            let d = self.estimate_joint(hand, joint);
            if d.0 > best.0 {
                best = d;
            }
        }
        Demand::Value(best.0, best.1)
    }

    /// The estimate of one joint: the largest of its position error, current
    /// and effort terms.
    fn estimate_joint(&self, hand: &HandInput, joint: usize) -> (f32, ContactSource) {
        let e = &self.config.estimate;
        let mut best = (0.0_f32, ContactSource::None);
        let (commanded, measured) = (hand.commanded[joint], hand.measured[joint]);
        if e.use_position_error && commanded.is_finite() && measured.is_finite() {
            let above = non_negative(commanded - measured - e.position_error_threshold);
            let d = non_negative(e.position_gain * above);
            if d > best.0 {
                best = (d, ContactSource::PositionError);
            }
        }
        let speed = hand.speed_rad_s[joint];
        // A joint slower than `stall` is stopped by something (0: any speed counts; an unknown
        // speed counts too).
        let stalled = |stall: f32| stall <= 0.0 || !speed.is_finite() || speed.abs() < stall;
        // A joint more open than its open angle is being pulled back from an overshoot or its
        // stop, not pressed by something in the hand (seen when a starved host let a finger fly
        // open into its joint limit and its PD then pushed it back).
        // (Unknown, NaN, counts: nothing says it is beyond.)
        let not_beyond_open = hand.measured[joint] >= 0.0 || hand.measured[joint].is_nan();
        let current = hand.current_ma[joint];
        if e.use_current && current.is_finite() && stalled(e.current_stall_speed_rad_s) {
            // Toward closing (as effort below), or the magnitude for a hand whose current has
            // no direction.
            let pushing = if e.current_toward_closing {
                if not_beyond_open {
                    current * self.closing[joint]
                } else {
                    0.0
                }
            } else {
                current.abs()
            };
            let above = non_negative(pushing - e.current_threshold_ma);
            let d = non_negative(e.current_gain_per_ma * above);
            if d > best.0 {
                best = (d, ContactSource::Current);
            }
        }
        let effort = hand.effort_nm[joint];
        if e.use_effort
            && effort.is_finite()
            && stalled(e.effort_stall_speed_rad_s)
            && not_beyond_open
        {
            // Only an effort toward the closed angle: something resists the finger closing,
            // which is what the glove renders (it pushes the operator's finger open). The
            // effort of a finger pulled open, or held against a push from outside, is not.
            let above = non_negative(effort * self.closing[joint] - e.effort_threshold_nm);
            let d = non_negative(e.effort_gain_per_nm * above);
            if d > best.0 {
                best = (d, ContactSource::Effort);
            }
        }
        best
    }

    /// Chooses the raw demand of glove finger `finger`.
    fn demand(&self, inputs: &Inputs, finger: usize) -> Demand {
        let source = &self.sources[finger];
        if source.is_none() {
            // The hand has no such finger: nothing to feel.
            return Demand::Value(0.0, ContactSource::None);
        }
        let estimate = || match &inputs.hand {
            Some(hand) if !source.joints.is_empty() => self.estimate(hand, &source.joints),
            Some(_) => Demand::Value(0.0, ContactSource::None),
            None => Demand::Ramp,
        };
        let Some(tip) = source.tactile else {
            return estimate();
        };
        match &inputs.tactile {
            Tactile::Stale => Demand::Ramp,
            Tactile::Fresh(t) if t.valid[tip] && t.normal_n[tip].is_finite() => {
                let above = non_negative(t.normal_n[tip] - self.config.contact_threshold_n);
                let d = non_negative(self.config.gain_per_n * above);
                if d > 0.0 {
                    Demand::Value(d, ContactSource::Tactile)
                } else {
                    Demand::Value(0.0, ContactSource::None)
                }
            }
            // Absent, or fresh but invalid (or non-finite) for this finger.
            Tactile::Fresh(_) | Tactile::Absent => estimate(),
        }
    }

    /// Runs one step of the law.
    ///
    /// Per glove finger: e-stop zeroes everything at once (and resets the
    /// state); a finger with no source gets no force; otherwise the demand
    /// comes from its fingertip's tactile force if fresh and valid, else from
    /// the joint-state estimate of its joints (tactile absent or invalid, or no
    /// fingertip; hand state present); with stale tactile (for a finger with a
    /// fingertip), or no hand state when it is needed, the force ramps to
    /// zero at
    /// `max_force / stale_ramp_s` per second. A demand is scaled by
    /// `finger_gain`, saturated to `[0, max_force]`, held within `hysteresis` of
    /// where it last went (see [`backlash`]), low-pass filtered
    /// (`smoothing_tau_s`) and rate limited (`rate_limit_per_s`).
    ///
    /// Saturation is applied to the demand before the filter (anti-windup:
    /// a demand far above `max_force` does not keep the force saturated
    /// after contact ends); the result is identical in steady state.
    ///
    /// The output is within `0..=max_force` for any input, including NaN or
    /// infinite values, which count as invalid (tactile) or zero demand
    /// (joint state).
    pub fn step(&mut self, inputs: &Inputs) -> FeedbackOutput {
        let dt = self.advance_clock(inputs.t_ns);

        if inputs.estop {
            self.filtered = [0.0; GLOVE_FINGERS];
            self.held = [0.0; GLOVE_FINGERS];
            self.output = [0.0; GLOVE_FINGERS];
            self.passivity.reset();
            return FeedbackOutput {
                force: [0; GLOVE_FINGERS],
                source: [ContactSource::EStop; GLOVE_FINGERS],
                clamped: 0,
                stale: false,
                passivity: PassivityReport::default(),
            };
        }
        match &inputs.operator {
            Some(operator) => self.passivity.observe(operator),
            // The glove's positions are stale: no motion known, nothing to act on.
            None => self.passivity.no_operator(),
        }

        let max = f32::from(self.config.max_force);
        let max_step = self.config.rate_limit_per_s * dt;
        // Guarded so a huge ramp rate times dt = 0 cannot make NaN.
        let ramp_step = if dt > 0.0 {
            max / self.config.stale_ramp_s * dt
        } else {
            0.0
        };
        let tau = self.config.smoothing_tau_s;
        // Weight of the new demand in the low-pass; 0 when dt = 0.
        let alpha = if tau > 0.0 {
            let a = 1.0 - (-dt / tau).exp();
            if a.is_finite() {
                a.clamp(0.0, 1.0)
            } else {
                1.0
            }
        } else {
            1.0
        };

        let mut out = FeedbackOutput {
            force: [0; GLOVE_FINGERS],
            source: [ContactSource::None; GLOVE_FINGERS],
            clamped: 0,
            stale: false,
            passivity: PassivityReport::default(),
        };
        // What the law wants per finger, for the passivity layer's reset.
        let mut demand = [0.0; GLOVE_FINGERS];

        for (finger, wanted) in demand.iter_mut().enumerate() {
            let value = match self.demand(inputs, finger) {
                Demand::Ramp => {
                    let next = positive_or_zero(self.output[finger] - ramp_step);
                    // Bumpless restart: the filter resumes from the output.
                    self.filtered[finger] = next;
                    self.held[finger] = next;
                    out.source[finger] = ContactSource::Ramping;
                    out.stale = true;
                    next
                }
                Demand::Value(raw, source) => {
                    out.source[finger] = source;
                    // inf * 0 (finger disabled) is NaN -> 0.
                    let mut d = non_negative(raw * self.config.finger_gain[finger]);
                    if d > max {
                        d = max;
                        out.clamped += 1;
                    }
                    *wanted = d;
                    let d = backlash(self.held[finger], d, self.config.hysteresis, max);
                    self.held[finger] = d;
                    // Written as a weighted sum so it is monotone in both
                    // arguments even with float rounding.
                    let f = (1.0 - alpha) * self.filtered[finger] + alpha * d;
                    let f = if f.is_finite() {
                        f.clamp(0.0, max)
                    } else {
                        0.0
                    };
                    self.filtered[finger] = f;
                    let prev = self.output[finger];
                    // max/min rather than clamp: never panics, monotone.
                    f.max(prev - max_step).min(prev + max_step)
                }
            };
            // Safety net: state and output stay finite and within limits.
            let value = if value.is_finite() {
                value.clamp(0.0, max)
            } else {
                0.0
            };
            self.output[finger] = value;
        }
        // The passivity controller lowers what is commanded, and the law restarts from there
        // (the controller's own ceiling then brings the force back, slower than the rate
        // limit): a force that jumped back to the law's value once the finger stops opening
        // would throw it open again.
        let active = match self.config.passivity.mode {
            PassivityMode::On => true,
            PassivityMode::Off => false,
            PassivityMode::Auto => inputs.remote,
        };
        let (force, report) = self.passivity.control(self.output, demand, max, dt, active);
        for (f, (slot, value)) in out.force.iter_mut().zip(force).enumerate() {
            if report.acted[f] {
                self.output[f] = value.min(self.output[f]);
            }
            *slot = (value as i16).clamp(0, self.config.max_force);
        }
        out.passivity = report;
        out
    }
}

/// A demand `d` (within `0..=max`) through a backlash of width `h` that last gave `held`:
/// unchanged while `d` stays within `h` of it, else trailing `d` by `h`, and never below `h` (so
/// more demand never gives less force than a demand of `h`); a demand at or below `h` is passed
/// as it is, so a contact that ends gives zero, and a saturated one (`max`) too, so a firm grasp
/// is felt at full force. Total: a non-finite result gives `d`.
fn backlash(held: f32, d: f32, h: f32, max: f32) -> f32 {
    if !h.is_finite() || h <= 0.0 || d <= h || d >= max {
        return d;
    }
    let out = held.max(d - h).min(d + h).max(h);
    if out.is_finite() {
        out
    } else {
        d
    }
}
