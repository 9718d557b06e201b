//! The force-feedback process's logic without its plumbing: its configuration file and the
//! [`FeedbackEngine`] that turns tactile, hand-state, hand-command, glove-state, health and
//! e-stop samples (each with its receive time), its ticks and its inputs' watchdogs (a
//! [`Schedule`](teleop_runtime::schedule::Schedule)) into glove force commands. The
//! `teleop-feedback` executable feeds it from the live topics and the clock; `teleop reprocess`
//! feeds it from a recording and its log times, so both run the same code, schedule included.

use std::path::{Path, PathBuf};

use teleop_force_feedback::{
    FeedbackConfig, ForceFeedback, HandInput, Inputs, OperatorInput, PassivityReport, PstConfig,
    Tactile, TactileInput, GLOVE_FINGERS,
};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    fingertip_sensor, force_flags, units, EStop, GloveForceCommand, GloveState, HandCommand,
    HandState, NodeHealth, Tactile as TactileMsg,
};
use teleop_runtime::link::{stamp_over_link, LinkDelay};
use teleop_runtime::sample_time;
use teleop_runtime::schedule::Schedule;

/// The node's configuration file.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NodeConfig {
    /// The hand profile (`config/hands/<hand>.toml`), relative to the configuration file.
    pub hand_profile: Option<PathBuf>,
    /// Tactile data older than this is stale (forces ramp to zero).
    pub tactile_timeout_ms: u64,
    /// Hand state older than this is stale.
    pub hand_timeout_ms: u64,
    /// Longest time between two published force commands.
    pub tick_ms: u64,
    /// Health report period.
    pub health_period_ms: u64,
    /// The glove's positions older than this are stale (the passivity observer waits).
    pub glove_timeout_ms: u64,
    /// Most link delay the freshness of hand data may allow for: a delay measured above it
    /// counts as this much.
    pub max_link_delay_ms: u64,
    /// The force-feedback law.
    pub feedback: FeedbackConfig,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            hand_profile: None,
            tactile_timeout_ms: 100,
            hand_timeout_ms: 100,
            tick_ms: 10,
            health_period_ms: 500,
            glove_timeout_ms: 100,
            max_link_delay_ms: 1000,
            feedback: FeedbackConfig::default(),
        }
    }
}

impl NodeConfig {
    /// Checks the node's timeouts and periods; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        use teleop_runtime::check_ms;
        check_ms("tactile_timeout_ms", self.tactile_timeout_ms)?;
        check_ms("hand_timeout_ms", self.hand_timeout_ms)?;
        check_ms("tick_ms", self.tick_ms)?;
        check_ms("health_period_ms", self.health_period_ms)?;
        check_ms("glove_timeout_ms", self.glove_timeout_ms)?;
        check_ms("max_link_delay_ms", self.max_link_delay_ms)
    }
}

/// Loads and checks the configuration (defaults without a file) and the hand profile (`profile`
/// when given, else the file the configuration names); errors name the file.
pub fn load(
    path: Option<&Path>,
    profile: Option<HandProfile>,
) -> anyhow::Result<(NodeConfig, HandProfile)> {
    let (config, origin, base) = match path {
        Some(path) => {
            let config: NodeConfig = teleop_runtime::load_toml(path)?;
            config
                .feedback
                .validate()
                .map_err(|e| e.with_origin(&path.display().to_string()))?;
            config
                .validate()
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            let base = path.parent().map(PathBuf::from).unwrap_or_default();
            (config, path.display().to_string(), base)
        }
        None => (
            NodeConfig::default(),
            "defaults".to_string(),
            PathBuf::new(),
        ),
    };
    let profile = match (profile, &config.hand_profile) {
        (Some(p), _) => p,
        (None, Some(file)) => HandProfile::load(&base.join(file))?,
        (None, None) => anyhow::bail!(
            "{origin}: no hand profile: set `hand_profile` (e.g. \"hands/revo2.toml\") or pass --profile"
        ),
    };
    Ok((config, profile))
}

/// One input of the engine.
// The variants are the samples themselves, handled by value on the stack; boxing the large
// ones would allocate per sample.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A tactile sample.
    Tactile(TactileMsg),
    /// A hand state sample.
    State(HandState),
    /// A hand command sample (remembered for the position-error estimate).
    Command(HandCommand),
    /// An e-stop sample.
    EStop(EStop),
    /// A glove state sample: the operator's fingers, for the passivity observer.
    Glove(GloveState),
    /// A health report: the link node's gives the link's delay (others are ignored).
    Health(NodeHealth),
}

/// What one event did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Output {
    /// The force command to publish, if the event stepped the law.
    pub command: Option<GloveForceCommand>,
    /// Inputs just went stale (log it, count a timeout).
    pub became_stale: bool,
    /// Inputs are fresh again.
    pub became_fresh: bool,
    /// The e-stop was just engaged (`Some(true)`) or released (`Some(false)`).
    pub estop_changed: Option<bool>,
    /// Fingers saturated at `max_force`.
    pub clamped: u8,
    /// The passivity observer's energy and what its controller did, if the event stepped the
    /// law.
    pub passivity: Option<PassivityReport>,
}

/// Force feedback with its input state.
pub struct FeedbackEngine {
    profile: HandProfile,
    law: ForceFeedback,
    /// The newest tactile sample and when it was made.
    tactile: Option<(TactileMsg, u64)>,
    /// The newest hand state and when it was made.
    state: Option<(HandState, u64)>,
    command: Option<HandCommand>,
    /// The newest glove sample and when it was made.
    glove: Option<(GloveState, u64)>,
    /// The station's bridge's newest report of the link.
    link: LinkDelay,
    glove_timeout_ns: u64,
    /// Steps at which the passivity controller changed a force, and the lowest finger's
    /// observed energy at the newest step (health details).
    passivity_acted: u64,
    passivity_energy: f32,
    estop: bool,
    stale: bool,
    /// The tick (`tick_ms`) and the watchdogs of tactile (`tactile_timeout_ms`) and hand state
    /// (`hand_timeout_ms`).
    schedule: Schedule,
}

/// The tactile input's index in the engine's schedule.
const TACTILE: usize = 0;
/// The hand state input's index in the engine's schedule.
const STATE: usize = 1;

impl FeedbackEngine {
    /// An engine for the hand `profile` with this configuration.
    pub fn new(config: &NodeConfig, profile: &HandProfile) -> anyhow::Result<Self> {
        Ok(Self {
            profile: profile.clone(),
            law: ForceFeedback::new(config.feedback.clone(), profile)?,
            tactile: None,
            state: None,
            command: None,
            glove: None,
            link: LinkDelay::new(config.max_link_delay_ms.saturating_mul(1_000_000)),
            glove_timeout_ns: config.glove_timeout_ms.saturating_mul(1_000_000),
            passivity_acted: 0,
            passivity_energy: 0.0,
            estop: false,
            stale: false,
            schedule: {
                let mut schedule = Schedule::new();
                let tactile = schedule.watch(config.tactile_timeout_ms);
                let state = schedule.watch(config.hand_timeout_ms);
                debug_assert_eq!((tactile, state), (TACTILE, STATE));
                schedule.tick_every(config.tick_ms);
                schedule
            },
        })
    }

    /// Starts the ticks: the first is due `tick_ms` after `at_ns`, the next every `tick_ms` after
    /// that (absolute deadlines). The node starts them when its loop starts; reprocessing with
    /// the recording's first hand sample.
    pub fn start(&mut self, at_ns: u64) {
        self.schedule.start_ticks(at_ns);
    }

    /// When the next tick or input watchdog is due, if no sample comes before.
    pub fn next_due(&self) -> Option<u64> {
        self.schedule.next_due()
    }

    /// What the ticks and the input watchdogs did by `now_ns`: a deadline and the output there,
    /// the earliest first (call until `None`). Both step the law at their deadline, so stale
    /// inputs ramp the force down even when nothing arrives, and an input is found stale as soon
    /// as it is.
    pub fn poll(&mut self, now_ns: u64) -> Option<(u64, Output)> {
        let (at, _) = self.schedule.pop(now_ns)?;
        Some((at, self.step(at)))
    }

    /// True while the e-stop is engaged.
    pub fn estop(&self) -> bool {
        self.estop
    }

    /// The link delay freshness allows for at `now_ns` ([`LinkDelay::allowance_ns`]).
    pub fn link_allowance_ns(&self, now_ns: u64) -> u64 {
        self.link.allowance_ns(now_ns)
    }

    /// Whether a link between stations is up in the path at `now_ns` (the passivity
    /// controller's `auto` mode).
    pub fn link_up(&self, now_ns: u64) -> bool {
        self.link.up(now_ns)
    }

    /// Steps at which the passivity controller changed a force, since the engine started.
    pub fn passivity_acted(&self) -> u64 {
        self.passivity_acted
    }

    /// The lowest finger's observed energy at the newest step (glove units × travel; negative:
    /// the channel generated that much before the controller took it out).
    pub fn passivity_energy(&self) -> f32 {
        self.passivity_energy
    }

    /// Takes `event`, received at `now_ns` (CLOCK_MONOTONIC, or the log time when reprocessing).
    /// Tactile and hand-state samples are as old as their stamps say (never newer than their
    /// receipt, see [`sample_time`]), less the link's measured delay where the station's
    /// bridge reports one ([`teleop_runtime::link`]): a sample from a topic's history, made
    /// before a restart, is stale when it arrives, while samples delayed by the link but still
    /// arriving are fresh; a link that stops makes them stale by their receipt, a timeout after
    /// the last one.
    /// Steps the law on tactile samples, on hand state when the hand has no tactile data and on
    /// e-stop changes (and on ticks, see [`poll`](Self::poll)).
    pub fn handle(&mut self, event: &Event, now_ns: u64) -> Output {
        let allowance = self.link_allowance_ns(now_ns);
        // The stamp moved later by the link's delay, never past the receipt (`sample_time`):
        // fresh while `now <= min(stamp + allowance, received) + timeout`.
        let made_by = |stamp: u64| stamp_over_link(stamp, allowance);
        let step = match *event {
            Event::Tactile(t) => {
                let stamp = made_by(t.header.stamp_ns);
                self.schedule.sample(TACTILE, stamp, now_ns);
                self.tactile = Some((t, sample_time(stamp, now_ns)));
                true
            }
            Event::State(s) => {
                let stamp = made_by(s.header.stamp_ns);
                self.schedule.sample(STATE, stamp, now_ns);
                self.state = Some((s, sample_time(stamp, now_ns)));
                self.tactile.is_none()
            }
            Event::Glove(g) => {
                self.glove = Some((g, sample_time(g.header.stamp_ns, now_ns)));
                false
            }
            Event::Health(h) => {
                self.link.report(&h, now_ns);
                false
            }
            Event::Command(c) => {
                self.command = Some(c);
                false
            }
            Event::EStop(e) => {
                let engaged = e.engaged != 0;
                let changed = (engaged != self.estop).then_some(engaged);
                self.estop = engaged;
                let mut out = self.step(now_ns);
                out.estop_changed = changed;
                return out;
            }
        };
        if step {
            self.step(now_ns)
        } else {
            Output::default()
        }
    }

    /// Steps the law at `now_ns`.
    fn step(&mut self, now_ns: u64) -> Output {
        let (inputs, origin) = self.inputs(now_ns);
        let law = self.law.step(&inputs);
        let became_stale = law.stale && !self.stale;
        let became_fresh = !law.stale && self.stale;
        self.stale = law.stale;
        let mut msg = GloveForceCommand {
            force: law.force,
            ..Default::default()
        };
        if law.passivity.acted.iter().any(|&a| a) {
            self.passivity_acted += 1;
        }
        self.passivity_energy = law
            .passivity
            .energy
            .iter()
            .copied()
            .fold(f32::INFINITY, f32::min);
        msg.header.origin_ns = origin;
        for (slot, source) in msg.source.iter_mut().zip(law.source) {
            *slot = source as u8;
        }
        if law.stale {
            msg.flags |= force_flags::STALE;
        }
        if self.estop {
            msg.flags |= force_flags::ESTOP;
        }
        if law.clamped > 0 {
            msg.flags |= force_flags::CLAMPED;
        }
        Output {
            command: Some(msg),
            became_stale,
            became_fresh,
            estop_changed: None,
            clamped: law.clamped,
            passivity: Some(law.passivity),
        }
    }

    /// The law's inputs at `now_ns`, and the origin stamp of the newest device sample used.
    fn inputs(&self, now_ns: u64) -> (Inputs, u64) {
        let fresh = |input: usize, made: u64| !self.schedule.stale(input, made, now_ns);
        let mut origin = 0;
        let tactile = match &self.tactile {
            None => Tactile::Absent,
            Some((_, made)) if !fresh(TACTILE, *made) => Tactile::Stale,
            Some((msg, _)) => {
                origin = msg.header.origin_ns;
                Tactile::Fresh(tactile_from_msg(msg, &self.law.config().pst))
            }
        };
        let hand = match &self.state {
            Some((msg, made)) if fresh(STATE, *made) && msg.link_up != 0 => {
                if origin == 0 {
                    origin = msg.header.origin_ns;
                }
                Some(hand_from_msgs(msg, self.command.as_ref(), &self.profile))
            }
            _ => None,
        };
        let operator = self
            .glove
            .as_ref()
            .filter(|(g, made)| {
                g.link_up != 0
                    && !teleop_runtime::schedule::is_stale(*made, now_ns, self.glove_timeout_ns)
            })
            .map(|(g, made)| OperatorInput {
                t_ns: *made,
                position: core::array::from_fn::<_, GLOVE_FINGERS, _>(|f| g.position[f]),
            });
        (
            Inputs {
                t_ns: now_ns,
                tactile,
                hand,
                estop: self.estop,
                operator,
                remote: self.link_up(now_ns),
            },
            origin,
        )
    }
}

/// The law's tactile input: normal force and validity per fingertip (a PST fingertip's raw
/// pressure converted by `pst`).
pub fn tactile_from_msg(msg: &TactileMsg, pst: &PstConfig) -> TactileInput {
    let mut input = TactileInput::default();
    for (i, tip) in msg
        .active_fingertips()
        .iter()
        .enumerate()
        .take(input.valid.len())
    {
        input.normal_n[i] = if tip.sensor_kind == fingertip_sensor::PST_PRESSURE {
            pst.force_n(tip.pressure)
        } else {
            tip.normal_n
        };
        input.valid[i] = tip.is_valid();
    }
    input
}

/// Joint state plus the commanded positions, normalised with the profile's open and closed
/// angles when they come in radians; without a usable command the measured positions stand in
/// (no position error). Joints the profile does not have are left out.
pub fn hand_from_msgs(
    state: &HandState,
    command: Option<&HandCommand>,
    profile: &HandProfile,
) -> HandInput {
    let mut input = HandInput::default();
    let normalise = |value: f32, unit: u8, joint: usize| match unit {
        units::NORMALISED => value,
        _ => profile.joints[joint].normalised(value),
    };
    let count = profile.joints.len().min(input.measured.len());
    for (i, joint) in state.active_joints().iter().enumerate().take(count) {
        input.measured[i] = normalise(joint.position, state.units, i);
        input.commanded[i] = input.measured[i];
        input.current_ma[i] = joint.current_ma;
        input.effort_nm[i] = joint.effort;
        input.speed_rad_s[i] = match state.units {
            // Travel per second: the joint's open..closed span per second.
            units::NORMALISED => {
                let j = &profile.joints[i];
                joint.speed * (j.closed - j.open)
            }
            _ => joint.speed,
        };
    }
    if let Some(cmd) = command.filter(|c| c.hand_model == state.hand_model) {
        for (i, joint) in cmd.active_joints().iter().enumerate().take(count) {
            input.commanded[i] = normalise(joint.target, cmd.units, i);
        }
    }
    input
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_force_feedback::ContactSource;

    fn revo2() -> HandProfile {
        HandProfile::builtin("revo2").unwrap()
    }
    use teleop_msgs::contact_source;

    #[test]
    fn contact_source_codes_match_the_contract() {
        assert_eq!(ContactSource::None as u8, contact_source::NONE);
        assert_eq!(ContactSource::Tactile as u8, contact_source::TACTILE);
        assert_eq!(
            ContactSource::PositionError as u8,
            contact_source::POSITION_ERROR
        );
        assert_eq!(ContactSource::Current as u8, contact_source::CURRENT);
        assert_eq!(ContactSource::Ramping as u8, contact_source::RAMPING);
        assert_eq!(ContactSource::EStop as u8, contact_source::ESTOP);
        assert_eq!(ContactSource::Effort as u8, contact_source::EFFORT);
    }

    #[test]
    fn tactile_validity_follows_status_bits_and_count() {
        let mut msg = TactileMsg {
            fingertip_count: 4,
            ..Default::default()
        };
        msg.fingertips[0].normal_n = 2.0;
        msg.fingertips[1].status = teleop_msgs::touch_status::INVALID;
        let t = tactile_from_msg(&msg, &PstConfig::default());
        assert_eq!(t.valid, [true, false, true, true, false]);
        assert_eq!(t.normal_n[0], 2.0);
    }

    #[test]
    fn pst_pressure_becomes_a_normal_force() {
        let mut msg = TactileMsg {
            fingertip_count: 5,
            ..Default::default()
        };
        for (tip, pressure) in msg.fingertips.iter_mut().zip([10, 310, 0, 510, 9]) {
            tip.sensor_kind = fingertip_sensor::PST_PRESSURE;
            tip.normal_n = f32::NAN;
            tip.pressure = pressure;
        }
        let pst = PstConfig {
            zero: 10.0,
            counts_per_n: 100.0,
        };
        let t = tactile_from_msg(&msg, &pst);
        assert_eq!(t.normal_n, [0.0, 3.0, 0.0, 5.0, 0.0]);
        assert_eq!(t.valid, [true; 5]);
    }

    #[test]
    fn hand_input_uses_command_targets_when_units_match() {
        let mut state = HandState {
            joint_count: 6,
            units: units::NORMALISED,
            ..Default::default()
        };
        state.joints[2].position = 0.4;
        state.joints[2].current_ma = 350.0;
        let mut cmd = HandCommand {
            joint_count: 6,
            units: units::NORMALISED,
            ..Default::default()
        };
        cmd.joints[2].target = 0.9;
        let h = hand_from_msgs(&state, Some(&cmd), &revo2());
        assert_eq!(
            (h.measured[2], h.commanded[2], h.current_ma[2]),
            (0.4, 0.9, 350.0)
        );
        let h = hand_from_msgs(&state, None, &revo2());
        assert_eq!(h.commanded[2], 0.4, "no command: no position error");
    }

    #[test]
    fn engine_steps_on_tactile_and_ticks_and_goes_stale_by_sample_time() {
        let mut e = FeedbackEngine::new(&NodeConfig::default(), &revo2()).unwrap();
        let mut t = TactileMsg {
            fingertip_count: 5,
            ..Default::default()
        };
        t.fingertips[1].normal_n = 2.3;
        let ms = 1_000_000;
        assert!(e
            .handle(&Event::Command(HandCommand::default()), 0)
            .command
            .is_none());
        e.start(0);
        for i in 0..200 {
            t.header.stamp_ns = i * ms;
            while e.poll(i * ms).is_some() {}
            let out = e.handle(&Event::Tactile(t), i * ms);
            assert!(out.command.is_some());
        }
        let (at, out) = e.poll(205 * ms).unwrap();
        assert_eq!(at, 200 * ms, "ticks every tick_ms from the start");
        assert!(
            out.command.unwrap().force[3] > 400,
            "index force {:?}",
            out.command
        );
        assert_eq!(e.next_due(), Some(210 * ms));
        // The tactile watchdog steps the law at the first instant the input is stale (its
        // newest sample was made at 199 ms), between two ticks.
        let mut steps = std::iter::from_fn(|| e.poll(400 * ms));
        let stale = steps.find(|(_, out)| out.became_stale).unwrap();
        assert_eq!(
            stale.0,
            299 * ms + 1,
            "100 ms after the newest sample was made"
        );
        let engaged = e.handle(
            &Event::EStop(EStop {
                engaged: 1,
                ..Default::default()
            }),
            401 * ms,
        );
        assert_eq!(engaged.estop_changed, Some(true));
        assert_eq!(engaged.command.unwrap().force, [0; 5]);
    }

    /// The bridge's health report made at `made_ns`: the link up (or not) with this one-way
    /// delay.
    fn bridge(name: &str, one_way_ms: f64, up: bool, made_ns: u64) -> Event {
        let mut h = NodeHealth::default();
        h.header.stamp_ns = made_ns;
        h.set_name(name);
        h.set_detail("link_state", if up { 1.0 } else { 0.0 });
        h.set_detail(teleop_runtime::link::LINK_DELAY_DETAIL, one_way_ms);
        Event::Health(h)
    }

    #[test]
    fn delayed_but_continuous_data_stays_fresh_and_a_stopped_link_still_goes_stale() {
        let ms = 1_000_000;
        let mut t = TactileMsg {
            fingertip_count: 5,
            ..Default::default()
        };
        t.fingertips[1].normal_n = 2.3;
        let delay = 250 * ms;
        let run = |e: &mut FeedbackEngine, from: u64, to: u64| {
            let mut t = t;
            let mut stale = false;
            for i in from..to {
                let now = 10_000 * ms + i * 10 * ms;
                t.header.stamp_ns = now - delay; // made one link delay ago
                while let Some((_, out)) = e.poll(now) {
                    stale |= out.command.unwrap().flags & force_flags::STALE != 0;
                }
                let out = e.handle(&Event::Tactile(t), now);
                stale |= out.command.unwrap().flags & force_flags::STALE != 0;
            }
            stale
        };
        // Without a bridge's report, 250 ms old samples are stale however regularly they come.
        let mut e = FeedbackEngine::new(&NodeConfig::default(), &revo2()).unwrap();
        e.start(10_000 * ms);
        assert!(run(&mut e, 0, 50));
        // With it (a report names the link's one-way p99), they drive the glove.
        let mut e = FeedbackEngine::new(&NodeConfig::default(), &revo2()).unwrap();
        e.start(10_000 * ms);
        e.handle(&bridge("bridge", 252.0, true, 10_000 * ms), 10_000 * ms);
        assert!(e.link_up(10_000 * ms));
        assert!(!run(&mut e, 0, 50), "delayed samples judged stale");
        // The link stops after the sample received at 10 490 ms: stale 100 ms (the timeout)
        // after that receipt, not 100 ms plus the link's delay.
        let mut steps = std::iter::from_fn(|| e.poll(11_000 * ms));
        let stale = steps.find(|(_, out)| out.became_stale).unwrap();
        assert_eq!(stale.0, 10_590 * ms + 1);
        // Which reports count, the cap and the lapse: teleop_runtime::link's tests.
    }

    #[test]
    fn the_glove_feeds_the_passivity_observer_and_the_link_switches_it_on() {
        let ms = 1_000_000;
        let mut e = FeedbackEngine::new(&NodeConfig::default(), &revo2()).unwrap();
        let mut t = TactileMsg {
            fingertip_count: 5,
            ..Default::default()
        };
        t.fingertips[1].normal_n = 4.0;
        let mut g = GloveState {
            link_up: 1,
            ..Default::default()
        };
        let mut last = None;
        for i in 0..300u64 {
            let now = i * ms;
            // The index finger closes steadily into the contact against the glove's push: the
            // channel absorbs.
            g.header.stamp_ns = now;
            g.position[3] = 0.9 - i as f32 * 0.001;
            e.handle(&Event::Glove(g), now);
            t.header.stamp_ns = now;
            last = e.handle(&Event::Tactile(t), now).passivity;
        }
        let report = last.unwrap();
        assert!(report.energy[3] > 0.0, "{report:?}");
        assert!(!report.active, "auto without a link: off");
        e.handle(&bridge("bridge", 20.0, true, 300 * ms), 300 * ms);
        t.header.stamp_ns = 300 * ms;
        let report = e.handle(&Event::Tactile(t), 300 * ms).passivity.unwrap();
        assert!(report.active, "auto with a link: on");
    }

    #[test]
    fn samples_made_before_the_timeout_are_stale_when_they_arrive() {
        let mut e = FeedbackEngine::new(&NodeConfig::default(), &revo2()).unwrap();
        let ms = 1_000_000;
        let mut t = TactileMsg {
            fingertip_count: 5,
            ..Default::default()
        };
        t.fingertips[1].normal_n = 2.3;
        let mut s = HandState {
            joint_count: 6,
            link_up: 1,
            ..Default::default()
        };
        s.joints[2].current_ma = 900.0;
        // Made 1 s ago (a topic's history after a restart), received now: no force.
        t.header.stamp_ns = 1000 * ms;
        s.header.stamp_ns = 1000 * ms;
        e.handle(&Event::State(s), 2000 * ms);
        let out = e.handle(&Event::Tactile(t), 2000 * ms);
        let cmd = out.command.unwrap();
        assert_eq!(cmd.force, [0; 5]);
        assert_ne!(cmd.flags & force_flags::STALE, 0, "{cmd:?}");
        // The same sample made just now drives the glove.
        t.header.stamp_ns = 2001 * ms;
        let out = e.handle(&Event::Tactile(t), 2001 * ms);
        assert_eq!(out.command.unwrap().flags & force_flags::STALE, 0);
        assert!(out.became_fresh);
    }
}
