//! Time-domain passivity of the force-feedback channel, per glove finger: an observer of the
//! energy that flows between the operator's finger and everything behind the glove (the
//! network, the robot hand and what it touches), and a controller that dissipates what that
//! channel would otherwise generate.
//!
//! The method is Hannaford and Ryu's (IEEE Transactions on Robotics and Automation, 2002,
//! "Time-domain passivity control of haptic interfaces"): a one-port is passive when the energy
//! that has flowed into it never goes negative; the passivity observer sums force times velocity
//! at the port every sample, and the passivity controller, an adaptive damper, takes out exactly
//! the deficit when the sum goes negative. Here the port is the glove finger: the motion is the
//! operator's finger closing, from the glove's positions, and the force the one the glove
//! applied meanwhile: the glove node sends the newest force command in each exchange and reads
//! the positions in the same exchange, so the force acting between two glove samples is the
//! command that was newest when the first of them arrived (the glove's measured force comes
//! only with its slow diagnostic reads). The observer needs nothing from the robot station and
//! holds whatever delay the link adds.
//!
//! # Units and signs
//!
//! Force in glove units (positive pushes the finger open), position in the glove's normalised
//! travel (1 open .. 0 bent), so the closing velocity is `-d position / dt` in travel per
//! second and energy is in glove units × travel: 1000 is the glove's full-scale force (about
//! 3 N) over a finger's full travel. Power into the channel is `force × closing velocity`:
//! positive while the operator presses against the push (the channel absorbs, like a spring
//! being compressed), negative while the push drives the finger open (the channel gives back).
//! A passive channel never gives back more than it took: the observed energy stays `>= 0`.
//!
//! # What the controller does
//!
//! When the energy at the end of the next glove sample would fall below the tolerance `-T`,
//! `E + f v Δt < -T` (`Δt` the glove's sample interval), it adds a damper `alpha` to the
//! commanded force, `f + alpha × v`, with `alpha = -(E + f v Δt + T) / (v² Δt)`, capped at
//! `max_damping`. It acts only while the push drives the finger open, where the channel gives
//! energy back: there the damper lowers the push, at most to zero. Closing, the push absorbs
//! energy by itself and the damper leaves it alone (a two-sided damper would have to push
//! harder on a closing finger, and a glove that slams to full force throws the finger open
//! again). While the energy stays above `-T` (and nothing it lowered earlier is still climbing
//! back, below) it leaves the force alone, so an undelayed contact feels as before.
//!
//! Hannaford and Ryu's controller takes the whole deficit out in one sample; on a delayed rigid
//! contact that is a chatter: the push is cut to zero as soon as the finger opens, climbs back
//! at the law's rate limit while it closes, and throws it open again (bench_haptics, the loose
//! operator: a 340-unit force buzz at about 26 ms at every delay). Two changes make the force
//! smooth instead, in the spirit of the literature's remedies for this chattering, though
//! neither paper's algorithm is implemented as such (Ryu, Preusche, Hannaford and Hirzinger,
//! IEEE Transactions on Control Systems Technology 2005, "Time domain passivity control with
//! reference energy following": dissipate gradually instead of all at once when the observer
//! crosses its bound; Kim and Ryu, IEEE Haptics Symposium 2004, "Energy bounding algorithm
//! based on passivity theorem for stable haptic interaction control": bound per sample what
//! the force may do, so that the energy it can generate stays bounded):
//!
//! - the damper is capped low (`max_damping`, default 300 units per travel/s: a finger opening
//!   at 0.1 travel/s loses 30 units a sample), so the deficit is taken out over several samples
//!   while the finger opens, and what is left of it is carried in the sum to the next ones;
//! - the force the damper left is a ceiling that climbs back at `recovery_per_s` (default 1000
//!   units/s, against the default law's rate limit of 20000), not at the law's rate: the push
//!   returns slowly enough for the finger to follow it without being thrown, and the ceiling is
//!   lifted once it reaches the force limit or the finger's energy sum restarts.
//!
//! So the force is never above the law's and never outside the limits; where the damper acts,
//! its change opposes the motion (`Δf × v >= 0`); elsewhere the force is the law's or the
//! ceiling, which only climbs. What the controller gives up for it: with a loose operator on a
//! rigid object across a delay, the finger has closed past where the delayed contact would have
//! stopped it before any force arrives, and pushing it back out is exactly the energy a passive
//! channel may not generate, so the felt force settles near zero there (BENCHMARKS.md).
//!
//! # Resets
//!
//! A sum over a whole session would let energy absorbed in one grasp pay for energy generated
//! much later, and a deficit left from one contact would damp the next; both are known problems
//! of a plain running sum. Two rules bound it: the sum is reset to zero once the finger has had
//! no force (the law's demand, before the controller) for `reset_after_s`, so each contact
//! starts afresh, and the stored energy is capped at `max_stored`, so a long squeeze cannot
//! bank energy for a later burst.

use serde::{Deserialize, Serialize};

use crate::GLOVE_FINGERS;

/// When the passivity controller acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PassivityMode {
    /// While a link between stations is in the path (a bridge reports its delay): on at the
    /// operator station of a remote session, off where glove and hand share a machine.
    Auto,
    /// Always.
    On,
    /// Never (the observer still runs and reports).
    Off,
}

/// The passivity layer's configuration (`[feedback.passivity]`).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct PassivityConfig {
    /// When the controller acts. Default `auto`.
    pub mode: PassivityMode,
    /// Largest damping the controller adds, glove units per (travel per second). Default 300:
    /// a finger opening at 0.1 travel/s loses 30 units per sample, so a deficit is taken out
    /// over several samples rather than by cutting the push to zero (with 20000 the force
    /// chattered, bench_haptics: a 340-unit buzz at 26 ms with the loose operator).
    pub max_damping: f32,
    /// The observer's sum restarts after the finger's demand has been zero this long (s).
    /// Default 0.2.
    pub reset_after_s: f32,
    /// Most energy the observer keeps (glove units × travel). Default 50: full-scale force over
    /// a twentieth of the travel, more than a firm grasp stores.
    pub max_stored: f32,
    /// The deficit the controller lets pass (glove units × travel). Default 10: full-scale
    /// force over 1.25 % of the travel, about 5 mJ. A contact force rising on a finger that
    /// gives way under it does a little work on the finger; the tolerance lets that pass, so
    /// the simulator's operator feels the whole force at every delay up to 500 ms round trip
    /// (bench_haptics: with 0, the index on the sponge at 500 ms lost 98 % of its force and the
    /// fingers' mean on the rigid ball 20 %). What it lets through: a deficit that grows a
    /// little each cycle (a contact force hunting between two quantised values drains a few
    /// tenths of a unit a cycle) is taken out only once it reaches the tolerance; the law's
    /// `hysteresis` is what keeps such hunting from starting.
    pub tolerance: f32,
    /// How fast the force climbs back after the controller lowered it, glove units per second.
    /// Default 1000: from zero to the default saturation (800) in 0.8 s. The law's own rate
    /// limit (20000) threw the finger open again as the push came back (bench_haptics: 4000
    /// kept the buzz, 2000 left a 54-unit swing on the loose operator's thumb).
    pub recovery_per_s: f32,
}

impl Default for PassivityConfig {
    fn default() -> Self {
        Self {
            mode: PassivityMode::Auto,
            max_damping: 300.0,
            reset_after_s: 0.2,
            max_stored: 50.0,
            tolerance: 10.0,
            recovery_per_s: 1000.0,
        }
    }
}

/// One sample of the operator's fingers, from the glove.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatorInput {
    /// When the glove measured them (ns, the same clock as [`crate::Inputs::t_ns`]).
    pub t_ns: u64,
    /// Finger positions in glove order, normalised travel (1 open .. 0 bent).
    pub position: [f32; GLOVE_FINGERS],
}

/// What the passivity layer saw and did at one step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PassivityReport {
    /// The observer's energy per glove finger (glove units × travel); negative: the channel
    /// generated that much (before the controller took it out).
    pub energy: [f32; GLOVE_FINGERS],
    /// Fingers whose force the controller changed at this step.
    pub acted: [bool; GLOVE_FINGERS],
    /// Whether the controller was on at this step (its mode, and the link for `auto`).
    pub active: bool,
}

/// The observer and controller of every glove finger.
#[derive(Debug, Clone)]
pub struct Passivity {
    config: PassivityConfig,
    /// The newest glove sample taken into the sum.
    last: Option<OperatorInput>,
    /// Observed energy per finger.
    energy: [f32; GLOVE_FINGERS],
    /// Closing velocity per finger over the last glove sample interval, travel per second. Not
    /// filtered: the glove's whole-unit positions make it noisy, but a filter's lag made the
    /// controller cut the push a fraction of the finger's oscillation late, which fed it
    /// (bench_haptics with a 10 ms low-pass: the felt force swinging full scale at 20-40 ms).
    velocity: [f32; GLOVE_FINGERS],
    /// The glove's sample interval, s (the controller's `Δt`).
    interval_s: f32,
    /// How long each finger's demand has been zero, s.
    idle_s: [f32; GLOVE_FINGERS],
    /// The newest force commanded, per finger (glove units).
    applied: [f32; GLOVE_FINGERS],
    /// The force acting since the newest glove sample: the command newest when it came.
    latched: [f32; GLOVE_FINGERS],
    /// Per finger, the most force allowed while it climbs back after the damper acted (glove
    /// units); `None`: the law's force passes.
    ceiling: [Option<f32>; GLOVE_FINGERS],
}

impl Passivity {
    /// A layer with nothing observed yet.
    pub fn new(config: PassivityConfig) -> Self {
        Self {
            config,
            last: None,
            energy: [0.0; GLOVE_FINGERS],
            velocity: [0.0; GLOVE_FINGERS],
            interval_s: 0.0,
            idle_s: [0.0; GLOVE_FINGERS],
            applied: [0.0; GLOVE_FINGERS],
            latched: [0.0; GLOVE_FINGERS],
            ceiling: [None; GLOVE_FINGERS],
        }
    }

    /// The configuration in use.
    pub fn config(&self) -> &PassivityConfig {
        &self.config
    }

    /// Forgets everything observed (e-stop, reset).
    pub fn reset(&mut self) {
        *self = Self::new(self.config.clone());
    }

    /// The observer's energy per finger.
    pub fn energy(&self) -> [f32; GLOVE_FINGERS] {
        self.energy
    }

    /// Takes a glove sample into the sum: the force acting since the previous sample times the
    /// finger's closing displacement since then; the newest command then acts until the next
    /// sample. A sample not newer than the last one changes nothing; the first one only sets
    /// the reference.
    pub fn observe(&mut self, operator: &OperatorInput) {
        let Some(last) = self.last else {
            self.last = Some(*operator);
            self.latched = self.applied;
            return;
        };
        if operator.t_ns <= last.t_ns {
            return;
        }
        let dt = (operator.t_ns - last.t_ns) as f32 * 1e-9;
        for f in 0..GLOVE_FINGERS {
            let closing = last.position[f] - operator.position[f];
            if !closing.is_finite() {
                continue;
            }
            let e = self.energy[f] + self.latched[f] * closing;
            self.energy[f] = if e.is_finite() {
                e.min(self.config.max_stored)
            } else {
                0.0
            };
            let v = closing / dt;
            // Positions far apart a few nanoseconds apart make no velocity.
            self.velocity[f] = if v.is_finite() { v } else { 0.0 };
        }
        self.interval_s = dt;
        self.last = Some(*operator);
        self.latched = self.applied;
    }

    /// The glove's positions are stale or absent: the fingers' velocity is unknown, so the
    /// controller has nothing to act on until the next sample (the sum is kept).
    pub fn no_operator(&mut self) {
        self.velocity = [0.0; GLOVE_FINGERS];
    }

    /// The force to command for each finger given the law's `force` (within `0..=max`), after
    /// `dt` seconds since the previous step: the controller's damper where the energy would
    /// fall below the tolerance while the push opens the finger, if `active`; elsewhere the
    /// law's force, held below the ceiling the damper left while that climbs back at
    /// `recovery_per_s` (only ever lowered, so a finger ramping to zero on stale inputs still
    /// does). `demand` is the law's demand per finger, for the reset. The result is rounded to
    /// whole glove units, as commanded.
    pub fn control(
        &mut self,
        force: [f32; GLOVE_FINGERS],
        demand: [f32; GLOVE_FINGERS],
        max: f32,
        dt: f32,
        active: bool,
    ) -> ([f32; GLOVE_FINGERS], PassivityReport) {
        let mut out = force;
        let mut report = PassivityReport {
            active,
            ..PassivityReport::default()
        };
        for f in 0..GLOVE_FINGERS {
            // The reset: a finger without demand long enough starts its next contact afresh.
            if demand[f] > 0.0 {
                self.idle_s[f] = 0.0;
            } else {
                self.idle_s[f] += dt;
                if self.idle_s[f] >= self.config.reset_after_s {
                    self.energy[f] = 0.0;
                    self.ceiling[f] = None;
                }
            }
            // The ceiling climbs back; at the force limit there is nothing left to hold.
            if let Some(ceiling) = self.ceiling[f] {
                let climbed = ceiling + self.config.recovery_per_s * dt;
                self.ceiling[f] = (climbed.is_finite() && climbed < max).then_some(climbed);
            }
            // A controller switched off (auto mode without a link) holds nothing back.
            if !active {
                self.ceiling[f] = None;
            }
            let allowed = self.ceiling[f].map_or(force[f], |c| force[f].min(c));
            // The energy at the end of the next sample if the law's force were applied at the
            // finger's present velocity (Hannaford and Ryu's observer includes the present
            // sample's f(n) v(n) before the controller acts on it).
            let (v, dt_sample) = (self.velocity[f], self.interval_s);
            let predicted = self.energy[f] + allowed * v * dt_sample + self.config.tolerance;
            // Only while the push drives the finger open (v < 0): that is where the channel
            // gives energy back. Closing, the push itself absorbs energy and pays the deficit
            // back; a damper there would have to push harder, and a glove that slams to full
            // force on a closing finger throws it open again (the chatter a two-sided
            // controller showed in bench_haptics).
            out[f] = allowed;
            if active && predicted < 0.0 && v < 0.0 && dt_sample > 0.0 {
                let alpha = (-predicted / (v * v * dt_sample)).min(self.config.max_damping);
                let damped = allowed + alpha * v;
                if damped.is_finite() {
                    out[f] = damped.clamp(0.0, allowed.clamp(0.0, max));
                }
                // What is left of the deficit stays in the sum for the next samples; the push
                // comes back no faster than the recovery rate.
                self.ceiling[f] = Some(out[f]);
            }
            out[f] = out[f].round();
            report.acted[f] = out[f] != force[f].round();
            self.applied[f] = out[f];
        }
        report.energy = self.energy;
        (out, report)
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    const MS: u64 = 1_000_000;

    /// A layer that keeps whatever energy it sees, tolerates no deficit and may take all of it
    /// out in one sample (Hannaford and Ryu's controller: a damper cap high enough never to
    /// bind here).
    fn exact() -> Passivity {
        Passivity::new(PassivityConfig {
            max_stored: f32::MAX,
            tolerance: 0.0,
            max_damping: 1e6,
            ..PassivityConfig::default()
        })
    }

    /// Every finger at `p`, sampled at `t_ms`.
    fn at(t_ms: u64, p: f32) -> OperatorInput {
        OperatorInput {
            t_ns: t_ms * MS,
            position: [p; GLOVE_FINGERS],
        }
    }

    /// Commands `force` on every finger (a demand, the controller off) and then moves every
    /// finger from `from` to `to` in `steps` glove samples of 1 ms from `*t`.
    fn push_and_move(pc: &mut Passivity, t: &mut u64, force: f32, from: f32, to: f32, steps: u32) {
        pc.control([force; 5], [force; 5], 1000.0, 0.001, false);
        // The glove takes the command in its next exchange.
        *t += 1;
        pc.observe(&at(*t, from));
        for k in 1..=steps {
            *t += 1;
            pc.observe(&at(*t, from + (to - from) * k as f32 / steps as f32));
        }
    }

    #[test]
    fn the_observer_sums_force_times_closing_displacement() {
        let mut pc = exact();
        let mut t = 0;
        pc.observe(&at(t, 0.9));
        // Pressing 0.1 of the travel closed against 500: the channel absorbs 50.
        push_and_move(&mut pc, &mut t, 500.0, 0.9, 0.8, 10);
        assert!((pc.energy()[3] - 50.0).abs() < 1e-3, "{:?}", pc.energy());
        // Released under the same force: all of it comes back, nothing more (a spring).
        push_and_move(&mut pc, &mut t, 500.0, 0.8, 0.9, 10);
        assert!(pc.energy()[3].abs() < 1e-3, "{:?}", pc.energy());
        // Pressed under 300 and thrown back open under 800 (the force of a delayed wall): the
        // channel generated 80 - 30 = 50.
        push_and_move(&mut pc, &mut t, 300.0, 0.9, 0.8, 10);
        push_and_move(&mut pc, &mut t, 800.0, 0.8, 0.9, 10);
        assert!((pc.energy()[3] + 50.0).abs() < 1e-3, "{:?}", pc.energy());
        // Without motion nothing flows, whatever the force.
        push_and_move(&mut pc, &mut t, 800.0, 0.9, 0.9, 10);
        assert!((pc.energy()[3] + 50.0).abs() < 1e-3, "{:?}", pc.energy());
        // Old or repeated samples change nothing.
        pc.observe(&at(t - 5, 0.2));
        pc.observe(&at(t, 0.2));
        assert!((pc.energy()[3] + 50.0).abs() < 1e-3, "{:?}", pc.energy());
    }

    #[test]
    fn the_controller_takes_out_the_deficit_over_one_sample() {
        let mut pc = exact();
        let mut t = 0;
        pc.observe(&at(t, 0.8));
        // Generated 10 while the finger opens at 1 travel/s: any push would generate more, so
        // the force goes to zero.
        push_and_move(&mut pc, &mut t, 1000.0, 0.8, 0.81, 10);
        assert!((pc.energy()[0] + 10.0).abs() < 1e-3);
        let (out, report) = pc.control([600.0; 5], [600.0; 5], 800.0, 0.001, true);
        assert_eq!(out, [0.0; 5]);
        assert_eq!(report.acted, [true; 5]);
        assert!(report.active);
        // With 0.3 stored, opening at 1 travel/s for one more 1 ms sample under 600 would
        // generate 0.6: the controller lets through exactly what is stored, 0.3 / 0.001 = 300.
        let mut pc = exact();
        t = 0;
        pc.observe(&at(t, 0.81));
        push_and_move(&mut pc, &mut t, 100.0, 0.81, 0.807, 3); // absorbs 0.3
        push_and_move(&mut pc, &mut t, 0.0, 0.807, 0.817, 10); // opens at 1 travel/s, no force
        assert!((pc.energy()[0] - 0.3).abs() < 1e-3, "{:?}", pc.energy());
        let (out, _) = pc.control([600.0; 5], [600.0; 5], 800.0, 0.001, false);
        assert_eq!(out, [600.0; 5], "off: unchanged");
        let (out, _) = pc.control([600.0; 5], [600.0; 5], 800.0, 0.001, true);
        assert!((out[0] - 300.0).abs() < 1.0, "{out:?}");
        // Applied for that sample (the glove measures it from its next exchange), the sum ends
        // at zero: passive, not beyond.
        t += 1;
        pc.observe(&at(t, 0.817));
        t += 1;
        pc.observe(&at(t, 0.818));
        assert!(pc.energy()[0].abs() < 0.01, "{:?}", pc.energy());
        // Closing, the push absorbs energy: the force is left alone even with a deficit the
        // sample pays back.
        push_and_move(&mut pc, &mut t, 0.0, 0.818, 0.808, 10);
        let (out, report) = pc.control([600.0; 5], [600.0; 5], 800.0, 0.001, true);
        assert_eq!((out[0], report.acted[0]), (600.0, false));
    }

    /// With the shipped cap the deficit is taken out over several samples while the finger
    /// opens, the rest carried in the sum; once it stops, the push climbs back at the recovery
    /// rate, not at once, up to the law's force; the finger's reset lifts what is left.
    #[test]
    fn the_default_controller_spreads_the_deficit_and_the_push_climbs_back_slowly() {
        // The default cap and recovery; no tolerance, so that a small deficit already acts.
        let config = PassivityConfig {
            tolerance: 0.0,
            ..PassivityConfig::default()
        };
        let mut pc = Passivity::new(config.clone());
        let mut t = 0;
        pc.observe(&at(t, 0.5));
        // Generated 5 while the finger opens at 1 travel/s under 500.
        push_and_move(&mut pc, &mut t, 500.0, 0.5, 0.51, 10);
        assert!((pc.energy()[0] + 5.0).abs() < 1e-3, "{:?}", pc.energy());
        // The finger keeps opening, now at 0.1 travel/s: each sample lowers the push by the cap
        // times the velocity (30), so it falls in steps, not at once; meanwhile the lowered
        // pushes give back a little more (what is not taken out stays in the sum).
        let mut position = 0.5101;
        t += 1;
        pc.observe(&at(t, position));
        let mut force = 600.0;
        let mut steps = 0;
        while force > 0.0 {
            let (out, report) = pc.control([600.0; 5], [600.0; 5], 800.0, 0.001, true);
            assert!(report.acted[0], "{out:?}");
            assert!(
                out[0] < force && out[0] >= force - 31.0,
                "{force} -> {}",
                out[0]
            );
            force = out[0];
            t += 1;
            position += 0.0001;
            pc.observe(&at(t, position));
            steps += 1;
        }
        assert!(steps >= 20, "{steps} samples");
        // 500 over the first two 0.0001 (the glove takes a command in its next exchange), then
        // 570, 540, ... 30 over 0.0001 each: 0.67 more (within the f32 positions' rounding).
        assert!((pc.energy()[0] + 5.67).abs() < 0.05, "{:?}", pc.energy());
        // Still: the push climbs back by the recovery rate (1 per ms) up to the law's 600.
        let mut before = 0.0;
        for _ in 0..1000 {
            t += 1;
            pc.observe(&at(t, position));
            let (out, _) = pc.control([600.0; 5], [600.0; 5], 800.0, 0.001, true);
            let climb = config.recovery_per_s * 0.001;
            assert!(
                out[0] >= before && out[0] <= before + climb + 1.0,
                "{before} -> {out:?}"
            );
            before = out[0];
        }
        assert_eq!(before, 600.0);
        // Lowered again, then no demand for the reset time: the next contact starts afresh.
        t += 1;
        pc.observe(&at(t, position + 0.001));
        let (out, _) = pc.control([600.0; 5], [600.0; 5], 800.0, 0.001, true);
        assert!(out[0] < 600.0, "{out:?}");
        for _ in 0..250 {
            pc.control([0.0; 5], [0.0; 5], 800.0, 0.001, true);
        }
        t += 1;
        pc.observe(&at(t, position + 0.001));
        let (out, report) = pc.control([600.0; 5], [600.0; 5], 800.0, 0.001, true);
        assert_eq!((out[0], report.acted[0]), (600.0, false));
    }

    #[test]
    fn the_sum_restarts_after_a_finger_has_had_no_demand() {
        let mut pc = exact();
        let mut t = 0;
        pc.observe(&at(t, 0.8));
        push_and_move(&mut pc, &mut t, 500.0, 0.8, 0.81, 10);
        assert!(pc.energy()[0] < 0.0);
        // 0.15 s without demand: kept; 0.2 s: restarted.
        for _ in 0..150 {
            pc.control([0.0; 5], [0.0; 5], 800.0, 0.001, true);
        }
        assert!(pc.energy()[0] < 0.0);
        for _ in 0..60 {
            pc.control([0.0; 5], [0.0; 5], 800.0, 0.001, true);
        }
        assert_eq!(pc.energy(), [0.0; 5]);
        // Stored energy is capped.
        let mut pc = Passivity::new(PassivityConfig::default());
        pc.observe(&at(0, 0.9));
        let mut t = 0;
        push_and_move(&mut pc, &mut t, 1000.0, 0.9, 0.5, 40);
        assert_eq!(pc.energy()[0], PassivityConfig::default().max_stored);
    }

    proptest! {
        /// Whatever the motion, forces and energy, the controller only lowers the force, so it
        /// stays within the limits (a finger ramping to zero keeps ramping), and it lowers the
        /// push only while the finger opens: on a finger closing or still, the force is never
        /// below the previous one plus the recovery (or the law's, if that is lower), so the
        /// controller never takes a push away from a finger that presses into it.
        #[test]
        fn prop_the_controller_only_dissipates_and_never_exceeds_the_limits(
            samples in prop::collection::vec(
                (prop::array::uniform5(-0.2f32..1.2), prop::array::uniform5(0.0f32..=800.0),
                 1u64..20),
                1..100),
            max in 0.0f32..=1000.0,
        ) {
            let config = PassivityConfig::default();
            let climb = config.recovery_per_s * 0.001;
            let mut pc = Passivity::new(config);
            let mut t = 0;
            let mut before = [0.0f32; GLOVE_FINGERS];
            for (position, force, gap) in samples {
                t += gap;
                pc.observe(&at(t, 0.0)); // reference the filter on the first sample
                pc.observe(&OperatorInput { t_ns: t * MS + 1, position });
                let force = force.map(|f| f.min(max));
                let (out, report) = pc.control(force, force, max, 0.001, true);
                for f in 0..GLOVE_FINGERS {
                    prop_assert!((0.0..=max.round()).contains(&out[f]), "{out:?} max {max}");
                    prop_assert!(out[f] <= force[f].round(), "only ever lowered");
                    if pc.velocity[f] >= 0.0 {
                        let least = force[f].round().min(before[f] + climb - 1.0);
                        prop_assert!(out[f] >= least,
                            "finger {f} not opening: {} -> {} (law {})", before[f], out[f], force[f]);
                    }
                    prop_assert!(report.energy[f].is_finite());
                }
                before = out;
            }
        }
    }
}
