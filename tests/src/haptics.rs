//! The closed haptic loop across a delay, in one process on a simulated clock: the glove
//! simulator's operator, the glove node's exchange, the retargeting engine, a delay line for the
//! bridge towards the robot, the Revo2 node's command path and state and the Revo2 simulator
//! with an object in the hand, a delay line back, and the force-feedback engine, whose force
//! commands go back to the glove's actuators. Every stage's logic is the pipeline's own library
//! code (`teleop_retarget::RetargetEngine`, `teleop_hand_node::{Admission, Resume}`,
//! `teleop_feedback::FeedbackEngine`) or its simulators'; what the executables add around them
//! (their topics, serial line and EtherCAT frames) is reduced to what changes the loop's timing
//! and values, each emulation naming the code it follows. Deterministic: no processes, no
//! threads, no wall clock; a grasp (6 s of the loop) takes about 0.2 s in a release build.
//!
//! [`run`] runs one [`Case`] and records every millisecond ([`Tick`]); [`analyse`] turns a run
//! into the haptics benchmark's metrics ([`Metrics`]). `bench_haptics` prints them over delays,
//! objects and feedback modes; the `haptics` test asserts the loop's behaviour on a cut-down
//! case.
//!
//! Unlike the rest of this crate this module links node libraries: the loop is about their
//! logic and timing across a delay, which no test through topics could run deterministically.

use std::collections::VecDeque;
use std::path::Path;

use teleop_feedback::{Event, FeedbackEngine};
use teleop_force_feedback::PassivityMode;
use teleop_hand_node::{Admission, Modes, Resume};
use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    control_mode, device_model, fingertip_sensor, force_flags, link_kind, units, Fingertip,
    GloveForceCommand, GloveState, HandCommand, HandState, JointState, NodeHealth, Tactile,
};
use teleop_retarget::RetargetEngine;
use teleop_runtime::link::{
    stamp_over_link, LinkDelay, DEFAULT_MAX_LINK_DELAY_NS, LINK_DELAY_DETAIL, LINK_NODE,
};
use teleop_runtime::sample_time;
use teleop_sim_glove::hand::{self as glove_sim, Drive, HandModel, Script};
use teleop_sim_revo2::hand::{self as revo2_sim, HandParams, ObjectModel, ShapeObject};

/// The loop's clock step, ns: the Revo2 node's cycle (1 kHz) and the glove simulator's
/// integration step.
const TICK_NS: u64 = 1_000_000;

/// The bridge's health period, ns.
const REPORT_NS: u64 = 1_000_000_000;

/// Glove fingers (little, ring, middle, index, thumb).
pub const FINGERS: usize = glove_sim::FINGERS;

/// The glove fingers' names, in glove order.
pub const FINGER_NAMES: [&str; FINGERS] = teleop_msgs::GLOVE_FINGERS;

/// The index finger in glove order: the finger whose felt force the benchmark reports first.
pub const INDEX: usize = 3;

/// The grasp script's held squeeze, as fractions of its period (`Script::Grasp` in the glove
/// simulator: 55-80 % squeeze and hold).
const HOLD: (f64, f64) = (0.55, 0.8);

/// The object in the robot's hand: the Revo2 simulator's ball (about a third of a fist, touched
/// by the fingertip pads where the hand's kinematics put them) with a contact stiffness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Object {
    /// Short name for tables.
    pub name: &'static str,
    /// Contact stiffness, N/m.
    pub stiffness_n_per_m: f32,
}

impl Object {
    /// A sponge ball (300 N/m).
    pub const SPONGE: Object = Object {
        name: "sponge",
        stiffness_n_per_m: 300.0,
    };
    /// A rigid ball (1e5 N/m).
    pub const RIGID: Object = Object {
        name: "rigid",
        stiffness_n_per_m: 1e5,
    };

    /// The Revo2 simulator's hand with this object in it.
    fn robot_hand(&self) -> revo2_sim::Hand {
        revo2_sim::Hand::new(
            HandParams::default(),
            Some(ObjectModel::Shape(ShapeObject::ball(
                self.stiffness_n_per_m,
            ))),
        )
    }
}

/// Which force feedback runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feedback {
    /// The configured law with the passivity controller off.
    Plain,
    /// The configured law with the passivity controller on.
    Passivity,
}

impl Feedback {
    /// Short name for tables.
    pub fn name(&self) -> &'static str {
        match self {
            Feedback::Plain => "plain",
            Feedback::Passivity => "passivity",
        }
    }
}

/// One run of the loop.
#[derive(Debug, Clone, PartialEq)]
pub struct Case {
    /// Round-trip delay of the link, ms (half of it each way).
    pub round_trip_ms: u64,
    /// What the robot's hand holds.
    pub object: Object,
    /// Which feedback runs.
    pub feedback: Feedback,
    /// Grasp cycles to run (`Script::Grasp`).
    pub grasps: u32,
    /// Seconds per grasp cycle.
    pub grasp_period_s: f32,
    /// The operator's finger model.
    pub operator: HandModel,
}

impl Case {
    /// The benchmark's case: three grasps of the glove simulator's `grasp` script (6 s each)
    /// by the default operator.
    pub fn new(round_trip_ms: u64, object: Object, feedback: Feedback) -> Self {
        Self {
            round_trip_ms,
            object,
            feedback,
            grasps: 3,
            grasp_period_s: 6.0,
            operator: HandModel::default(),
        }
    }

    fn one_way_ns(&self) -> u64 {
        self.round_trip_ms * 1_000_000 / 2
    }
}

/// An operator who holds the fingers loosely: the glove simulator's finger with a quarter of its
/// relaxed stiffness (50 N/m) and without the stiffening while squeezing, the rest as
/// `HandModel::default()`. The full-scale force of the glove (3 N) then moves a finger about 6 cm,
/// about 350 raw units, instead of the default operator's 6 mm (stiffened to 500 N/m): the loop's gain is that much
/// higher, which is where delayed force feedback oscillates.
pub fn loose_operator() -> HandModel {
    let firm = HandModel::default();
    HandModel {
        stiffness_n_per_m: firm.stiffness_n_per_m / 4.0,
        stiffening_per_m: 0.0,
        ..firm
    }
}

/// The pipeline's configuration as the loop uses it, read from a repository's `config/`.
#[derive(Debug, Clone)]
pub struct Stations {
    retarget: teleop_retarget::Loaded,
    feedback: teleop_feedback::NodeConfig,
    feedback_profile: HandProfile,
    glove: GloveNode,
    revo2: Revo2Node,
    /// `max_age_ms` of `hand/command` at the robot station's bridge, ns.
    command_max_age_ns: Option<u64>,
    /// `max_age_ms` of `hand/state` and `hand/tactile` at the operator station's bridge, ns.
    state_max_age_ns: Option<u64>,
    tactile_max_age_ns: Option<u64>,
}

/// What the loop takes from `config/glove.toml`.
#[derive(Debug, Clone, serde::Deserialize)]
struct GloveFile {
    baud: u32,
    force_timeout_ms: u64,
    max_force: i16,
    diagnostics_hz: f32,
}

/// The glove node's exchange: its period, force path and diagnostic reads.
#[derive(Debug, Clone, Copy)]
struct GloveNode {
    /// One force exchange, ns.
    exchange_ns: u64,
    force_timeout_ns: u64,
    max_force: f32,
    /// One diagnostic register read takes the place of a force exchange this often, ns
    /// (`None`: never).
    diagnostic_ns: Option<u64>,
}

/// The registers the glove node reads in turn in its diagnostic slots; the first, the actual
/// forces, is what `glove/state`'s `force` reports (nodes/devices/glove/node/src/node.rs,
/// `DIAGNOSTICS` and `read_diagnostic`).
const DIAGNOSTIC_REGISTERS: usize = 5;

/// What the loop takes from `config/revo2.toml`.
#[derive(Debug, Clone, serde::Deserialize)]
struct Revo2File {
    cycle_hz: f64,
    stale_command_ms: u64,
    resume_speed: f64,
    tactile: String,
    tactile_poll_hz: f64,
    full_speed_travel_per_s: f32,
    hold_speed_per_mille: u16,
}

/// The Revo2 node's cycle and command conversion.
#[derive(Debug, Clone, Copy)]
struct Revo2Node {
    cycle_ns: u64,
    stale_command_ns: u64,
    resume_speed: f64,
    /// Tactile data every cycle (`None`: in the process data), every this many ns (polled), or
    /// never.
    tactile: Option<Option<u64>>,
    full_speed_travel_per_s: f32,
    hold_speed_per_mille: f32,
}

/// What the loop takes from a bridge's configuration: its topics.
#[derive(Debug, Clone, serde::Deserialize)]
struct BridgeFile {
    #[serde(default)]
    topic: Vec<BridgeTopic>,
}

#[derive(Debug, Clone, serde::Deserialize)]
struct BridgeTopic {
    name: String,
    max_age_ms: Option<u64>,
}

impl BridgeFile {
    fn max_age_ns(&self, topic: &str) -> Option<u64> {
        self.topic
            .iter()
            .find(|t| t.name == topic)
            .and_then(|t| t.max_age_ms)
            .map(|ms| ms * 1_000_000)
    }
}

/// Serial bytes of one force exchange: a 16-byte force frame and an 18-byte answer
/// (BENCHMARKS.md, "Glove").
const EXCHANGE_BYTES: u64 = 34;
/// What one exchange takes besides the line, ns: the simulated glove's 200 us of processing and
/// the node's turnaround (BENCHMARKS.md, "Glove": 302.6 exchanges/s at 115200 baud against a
/// line limit of 338.8, i.e. 3.305 ms against 2.951 ms per exchange).
const EXCHANGE_OVERHEAD_NS: u64 = 354_000;

impl Stations {
    /// Reads the Revo2 session's configuration under `repo`: `config/glove.toml`,
    /// `config/revo2/retarget.toml`, `config/revo2.toml`, `config/revo2/feedback.toml` and the
    /// bridges' `config/bridge/{operator,robot}.toml`. Errors name the file.
    pub fn load(repo: &Path) -> Result<Self, String> {
        let config = repo.join("config");
        let glove: GloveFile =
            teleop_runtime::load_toml(&config.join("glove.toml")).map_err(|e| e.to_string())?;
        let revo2: Revo2File =
            teleop_runtime::load_toml(&config.join("revo2.toml")).map_err(|e| e.to_string())?;
        let operator: BridgeFile = teleop_runtime::load_toml(&config.join("bridge/operator.toml"))
            .map_err(|e| e.to_string())?;
        let robot: BridgeFile = teleop_runtime::load_toml(&config.join("bridge/robot.toml"))
            .map_err(|e| e.to_string())?;
        let retarget = teleop_retarget::load(Some(&config.join("revo2/retarget.toml")), None, None)
            .map_err(|e| format!("{e:#}"))?;
        let (feedback, feedback_profile) =
            teleop_feedback::load(Some(&config.join("revo2/feedback.toml")), None)
                .map_err(|e| format!("{e:#}"))?;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if glove.baud == 0 || !positive(revo2.cycle_hz) || !positive(revo2.tactile_poll_hz) {
            return Err(format!(
                "{}: baud, cycle_hz and tactile_poll_hz must be positive",
                config.display()
            ));
        }
        let tactile = match revo2.tactile.as_str() {
            "pdo" => Some(None),
            "sdo" => Some(Some((1e9 / revo2.tactile_poll_hz) as u64)),
            "off" => None,
            other => {
                return Err(format!(
                    "{}: tactile = {other:?}: expected pdo, sdo or off",
                    config.join("revo2.toml").display()
                ))
            }
        };
        Ok(Self {
            retarget,
            feedback,
            feedback_profile,
            glove: GloveNode {
                exchange_ns: EXCHANGE_BYTES * 10 * 1_000_000_000 / u64::from(glove.baud)
                    + EXCHANGE_OVERHEAD_NS,
                force_timeout_ns: glove.force_timeout_ms * 1_000_000,
                max_force: f32::from(glove.max_force),
                diagnostic_ns: (glove.diagnostics_hz > 0.0).then(|| {
                    (1e9 / (f64::from(glove.diagnostics_hz) * DIAGNOSTIC_REGISTERS as f64)) as u64
                }),
            },
            revo2: Revo2Node {
                cycle_ns: (1e9 / revo2.cycle_hz) as u64,
                stale_command_ns: revo2.stale_command_ms * 1_000_000,
                resume_speed: revo2.resume_speed,
                tactile,
                full_speed_travel_per_s: revo2.full_speed_travel_per_s,
                hold_speed_per_mille: f32::from(revo2.hold_speed_per_mille),
            },
            command_max_age_ns: robot.max_age_ns("hand/command"),
            state_max_age_ns: operator.max_age_ns("hand/state"),
            tactile_max_age_ns: operator.max_age_ns("hand/tactile"),
        })
    }

    /// The repository's own configuration (this crate's parent folder).
    pub fn repository() -> Result<Self, String> {
        Self::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join(".."))
    }

    /// The force-feedback configuration (gain, threshold, saturation, per-finger gains).
    pub fn feedback(&self) -> &teleop_force_feedback::FeedbackConfig {
        &self.feedback.feedback
    }

    /// A one-line summary of the rates and limits the loop runs with, for a benchmark's method.
    pub fn describe(&self) -> String {
        let ms = |ns: u64| ns as f64 / 1e6;
        let age = |a: Option<u64>| a.map_or("none".to_string(), |ns| format!("{} ms", ms(ns)));
        format!(
            "glove exchange every {:.3} ms (force timeout {} ms, clamp {}), glove/state's \
             measured forces {}; Revo2 cycle {} ms, \
             command stale after {} ms, tactile {}; bridges drop samples older on arrival than \
             the link's one-way delay plus: hand/command {}, hand/state {}, hand/tactile {}; \
             feedback tick {} ms, timeouts tactile {} ms / hand {} ms (freshness in the hand \
             node and force feedback allows for the one-way delay the bridges report)",
            ms(self.glove.exchange_ns),
            ms(self.glove.force_timeout_ns),
            self.glove.max_force,
            match self.glove.diagnostic_ns {
                Some(ns) => format!(
                    "from the actual-force register read every {} ms (a diagnostic read takes \
                     an exchange's place every {} ms)",
                    ms(ns * DIAGNOSTIC_REGISTERS as u64),
                    ms(ns)
                ),
                None => "never read (diagnostics off)".to_string(),
            },
            ms(self.revo2.cycle_ns),
            ms(self.revo2.stale_command_ns),
            match self.revo2.tactile {
                Some(None) => "every cycle".to_string(),
                Some(Some(ns)) => format!("polled every {} ms", ms(ns)),
                None => "off".to_string(),
            },
            age(self.command_max_age_ns),
            age(self.state_max_age_ns),
            age(self.tactile_max_age_ns),
            self.feedback.tick_ms,
            self.feedback.tactile_timeout_ms,
            self.feedback.hand_timeout_ms,
        )
    }
}

/// One millisecond of a run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Tick {
    /// Time, s.
    pub t_s: f64,
    /// The operator's finger positions, raw (0 bent .. 1000 open), glove order.
    pub finger: [f32; FINGERS],
    /// The operator's finger velocities, raw units per second (positive opening), as the glove
    /// simulator integrates them.
    pub velocity: [f32; FINGERS],
    /// What the glove measures between finger and actuator (glove units, positive: the finger
    /// pushes towards a fist against the actuator): the felt force.
    pub felt: [f32; FINGERS],
    /// The force the glove's actuators apply (glove units, positive opens).
    pub drive: [f32; FINGERS],
    /// The robot's fingertip normal force that drives each glove finger (the hand profile's
    /// feedback source), N, as the Revo2 simulator has it now.
    pub robot_n: [f32; FINGERS],
    /// The newest force command's STALE flag.
    pub stale: bool,
    /// The passivity observer's energy per finger after the newest step of the law (glove
    /// units × travel).
    pub observed: [f32; FINGERS],
}

/// Pending samples of one direction of the link, in send order.
struct DelayLine<T> {
    delay_ns: u64,
    queue: VecDeque<(u64, T)>,
}

impl<T> DelayLine<T> {
    fn new(delay_ns: u64) -> Self {
        Self {
            delay_ns,
            queue: VecDeque::new(),
        }
    }

    fn push(&mut self, now_ns: u64, item: T) {
        self.queue.push_back((now_ns + self.delay_ns, item));
    }

    fn pop_due(&mut self, now_ns: u64) -> Option<T> {
        if self.queue.front().is_some_and(|(due, _)| *due <= now_ns) {
            return self.queue.pop_front().map(|(_, item)| item);
        }
        None
    }
}

/// A bridge's incoming port: a sample older on arrival than the topic's `max_age` plus the
/// link's measured one-way delay (`allowance_ns`) is not published (the bridge's `station.rs`
/// and `ports.rs`, `In::publish`; stamps keep the sender's time, one clock here).
fn bridge_passes(stamp_ns: u64, now_ns: u64, max_age_ns: Option<u64>, allowance_ns: u64) -> bool {
    max_age_ns.is_none_or(|max| now_ns.saturating_sub(stamp_ns) <= max + allowance_ns)
}

/// The Revo2 node at the robot station: the hand-node core's command path (freshness by stamp,
/// admission, the ramp back after a hold) and the driver's conversions, on the simulated hand.
struct RobotStation {
    node: Revo2Node,
    hand: revo2_sim::Hand,
    admission: Admission,
    resume: Resume,
    /// The newest command the bridge published, and when.
    command: Option<(HandCommand, u64)>,
    /// The station's bridge's newest report of the link.
    link: LinkDelay,
    /// Position targets of the last command applied, per mille (what a hold keeps).
    target: Option<[f32; revo2_sim::JOINTS]>,
    /// The parameters last applied per joint (the emulated device applies a command when its
    /// outputs change).
    applied: Option<[(u8, f32, f32); revo2_sim::JOINTS]>,
    last_cycle_ns: u64,
    next_tactile_ns: u64,
    seq: u64,
}

impl RobotStation {
    fn new(node: Revo2Node, object: Object) -> Result<Self, String> {
        let profile = HandProfile::builtin("revo2")
            .ok_or_else(|| "the shipped Revo2 hand profile does not load".to_string())?;
        // The Revo2 node's admission rule (nodes/devices/revo2/node/src/node.rs, `admission`).
        let modes = Modes {
            position: true,
            position_time: true,
            velocity: Some(node.full_speed_travel_per_s),
            effort: Some(1.0),
            duty: Some(1.0),
        };
        Ok(Self {
            node,
            hand: object.robot_hand(),
            admission: Admission::new(&profile, modes),
            resume: Resume::new(node.resume_speed),
            command: None,
            link: LinkDelay::new(DEFAULT_MAX_LINK_DELAY_NS),
            target: None,
            applied: None,
            last_cycle_ns: 0,
            next_tactile_ns: 0,
            seq: 0,
        })
    }

    /// One cycle at `now_ns`: the command to follow (or the hold) to the hand, then the hand
    /// state and tactile sample the node publishes.
    fn cycle(&mut self, now_ns: u64) -> (HandState, Option<Tactile>) {
        let dt = (now_ns - self.last_cycle_ns) as f64 * 1e-9;
        self.last_cycle_ns = now_ns;
        let measured = self.measured();
        // `HandPorts::command`: the newest command while fresh by its stamp less the link's
        // delay (`Subscriber::is_fresh_over_link`), admitted, ramped.
        let allowance = self.link.allowance_ns(now_ns);
        let fresh = self
            .command
            .filter(|(c, received)| {
                let made = sample_time(stamp_over_link(c.header.stamp_ns, allowance), *received);
                now_ns.saturating_sub(made) <= self.node.stale_command_ns
            })
            .map(|(c, _)| c);
        let follow = fresh.and_then(|mut cmd| {
            if self.admission.admit(&mut cmd, Some(&measured)).is_err() {
                // `HandPorts::refused`: a refused command leaves nothing to ramp from.
                self.resume.forget();
                return None;
            }
            self.resume.follow_command(&mut cmd, dt);
            Some(cmd)
        });
        let outputs = match follow {
            Some(cmd) => self.outputs_for(&cmd),
            None => {
                self.resume.hold();
                self.hold_outputs()
            }
        };
        if self.applied != Some(outputs) {
            for (j, (mode, p1, p2)) in outputs.iter().enumerate() {
                self.hand.command(j, *mode, *p1, *p2);
            }
            self.applied = Some(outputs);
        }
        self.publish(now_ns)
    }

    /// Normalised measured positions, as `HandPorts::publish` keeps them for admission and the
    /// ramp.
    fn measured(&mut self) -> [f32; revo2_sim::JOINTS] {
        let at = self
            .hand
            .positions()
            .map(|p| p.round().clamp(0.0, 1000.0) / 1000.0);
        self.resume.held_at(&at.map(f64::from));
        at
    }

    /// The driver's outputs for an admitted position command in the percent unit mode
    /// (nodes/devices/revo2/node/src/convert.rs, `outputs_for`): per mille of travel, and the
    /// speed limit as per mille of full speed (`full_speed_travel_per_s`), at least 1.
    fn outputs_for(&mut self, cmd: &HandCommand) -> [(u8, f32, f32); revo2_sim::JOINTS] {
        let full = self.node.full_speed_travel_per_s;
        let outputs: [(u8, f32, f32); revo2_sim::JOINTS] = core::array::from_fn(|j| {
            let joint = cmd.joints[j];
            let target = (joint.target * 1000.0).round();
            let of_full = if joint.speed_limit > 0.0 {
                (joint.speed_limit / full).min(1.0)
            } else {
                1.0
            };
            match cmd.control_mode {
                control_mode::POSITION_TIME => (
                    revo2_sim::mode::POSITION_TIME,
                    target,
                    joint.speed_limit.clamp(0.0, 65535.0),
                ),
                _ => (
                    revo2_sim::mode::POSITION_SPEED,
                    target,
                    (of_full * 1000.0).round().max(1.0),
                ),
            }
        });
        self.target = Some(outputs.map(|(_, target, _)| target));
        outputs
    }

    /// The driver's hold (`hold_outputs`): the last commanded targets, else where the joints
    /// are, at the hold speed.
    fn hold_outputs(&self) -> [(u8, f32, f32); revo2_sim::JOINTS] {
        let at = self
            .target
            .unwrap_or_else(|| self.hand.positions().map(|p| p.round()));
        at.map(|target| {
            (
                revo2_sim::mode::POSITION_SPEED,
                target,
                self.node.hold_speed_per_mille,
            )
        })
    }

    /// The hand state and tactile sample of this cycle, as the node fills them from the
    /// emulated device's inputs (nodes/devices/revo2/node/src/convert.rs `hand_state` and
    /// `tactile`, from nodes/devices/revo2/sim/src/device.rs `inputs`: whole per mille
    /// positions and speeds, whole mA, forces in hundredths of a newton up to 25 N).
    fn publish(&mut self, now_ns: u64) -> (HandState, Option<Tactile>) {
        self.seq += 1;
        let mut state = HandState {
            hand_model: device_model::REVO2,
            joint_count: revo2_sim::JOINTS as u8,
            units: units::NORMALISED,
            link_kind: link_kind::ETHERCAT,
            link_up: 1,
            ..Default::default()
        };
        state.header.seq = self.seq;
        state.header.stamp_ns = now_ns;
        state.header.origin_ns = now_ns;
        let (pos, speed, current) = (
            self.hand.positions(),
            self.hand.speeds(),
            self.hand.currents(),
        );
        // The simulator's full speed: 1000 per mille of speed is 2000 position units/s.
        let max_speed = HandParams::default().max_speed;
        for j in 0..revo2_sim::JOINTS {
            let per_mille = (speed[j] / max_speed * 1000.0).round();
            state.joints[j] = JointState {
                position: pos[j].round().clamp(0.0, 1000.0) / 1000.0,
                speed: per_mille / 1000.0 * self.node.full_speed_travel_per_s,
                effort: f32::NAN,
                current_ma: current[j].round(),
                status: 0,
            };
        }
        let tactile = match self.node.tactile {
            None => None,
            Some(None) => Some(self.tactile(now_ns)),
            Some(Some(period)) if now_ns >= self.next_tactile_ns => {
                self.next_tactile_ns = now_ns + period;
                Some(self.tactile(now_ns))
            }
            Some(Some(_)) => None,
        };
        (state, tactile)
    }

    fn tactile(&self, now_ns: u64) -> Tactile {
        let mut msg = Tactile {
            hand_model: device_model::REVO2,
            fingertip_count: revo2_sim::FINGERTIPS as u8,
            ..Default::default()
        };
        msg.header.seq = self.seq;
        msg.header.stamp_ns = now_ns;
        msg.header.origin_ns = now_ns;
        let hundredths = |n: f32| (n * 100.0).round().clamp(0.0, 2500.0) / 100.0;
        for (tip, touch) in msg.fingertips.iter_mut().zip(self.hand.touches()) {
            *tip = Fingertip {
                normal_n: hundredths(touch.normal_n),
                tangential_n: hundredths(touch.tangential_n),
                direction_deg: touch.direction_deg.map_or(0.0, f32::from),
                proximity: touch.proximity,
                status: 0,
                update_counter: self.hand.sensor_counter(),
                direction_valid: u8::from(touch.direction_deg.is_some()),
                pressure: 0,
                temperature: 0,
                sensor_kind: fingertip_sensor::REVO2_FORCE,
            };
        }
        msg
    }
}

/// Runs `case` on `stations` and returns one [`Tick`] per millisecond.
pub fn run(stations: &Stations, case: &Case) -> Result<Vec<Tick>, String> {
    let loaded = &stations.retarget;
    let mut retarget = RetargetEngine::new(&loaded.config, loaded.calibration, &loaded.profile)
        .map_err(|e| format!("retargeting: {e:#}"))?;
    let mut feedback_config = stations.feedback.clone();
    feedback_config.feedback.passivity.mode = match case.feedback {
        Feedback::Plain => PassivityMode::Off,
        Feedback::Passivity => PassivityMode::On,
    };
    let mut feedback = FeedbackEngine::new(&feedback_config, &stations.feedback_profile)
        .map_err(|e| format!("force feedback: {e:#}"))?;
    let sources: [Option<usize>; FINGERS] =
        core::array::from_fn(|g| stations.feedback_profile.feedback[g].tactile);
    let mut robot = RobotStation::new(stations.revo2, case.object)?;
    let mut operator = glove_sim::Hand::new(
        Script::Grasp {
            period_s: case.grasp_period_s,
        },
        case.operator,
    );
    let mut to_robot: DelayLine<HandCommand> = DelayLine::new(case.one_way_ns());
    let mut to_operator: DelayLine<(HandState, Option<Tactile>)> =
        DelayLine::new(case.one_way_ns());
    // The newest force command and when it was published, and the passivity observer's energy.
    let mut force = Force::default();
    let mut next_exchange = 0u64;
    let mut next_cycle = 0u64;
    let mut next_report = 0u64;
    // The glove node's diagnostic slots: the next, which register it reads, and the forces the
    // last actual-force read gave.
    let mut next_diagnostic = 0u64;
    let mut diagnostic_slot = 0usize;
    let mut glove_force = [0i16; FINGERS];
    // The bridges' measured one-way delay, allowed for on top of max_age_ms.
    let mut bridge_allowance = 0u64;
    let mut glove_seq = 0u64;
    let mut command_seq = 0u64;
    let end_ns = (f64::from(case.grasps) * f64::from(case.grasp_period_s) * 1e9) as u64;
    let mut ticks = Vec::with_capacity((end_ns / TICK_NS + 1) as usize);
    feedback.start(0);

    let mut now = 0u64;
    while now <= end_ns {
        let t_s = now as f64 * 1e-9;
        operator.advance_to(t_s as f32);
        robot.hand.advance_to(t_s as f32);

        // The robot station: the bridge publishes what is due and fresh enough, the node cycles.
        // Each station's bridge reports the link once a second (up, its one-way delay): the
        // nodes downstream allow for it, and so does the bridge's own max_age_ms from then on.
        if now >= next_report {
            next_report += REPORT_NS;
            let mut health = NodeHealth::default();
            health.set_name(LINK_NODE);
            health.header.stamp_ns = now;
            health.set_detail("link_state", 1.0);
            health.set_detail(LINK_DELAY_DETAIL, case.one_way_ns() as f64 / 1e6);
            bridge_allowance = case.one_way_ns();
            robot.link.report(&health, now);
            take(
                feedback.handle(&Event::Health(health), now),
                now,
                &mut force,
            );
        }
        while let Some(cmd) = to_robot.pop_due(now) {
            if bridge_passes(
                cmd.header.stamp_ns,
                now,
                stations.command_max_age_ns,
                bridge_allowance,
            ) {
                robot.command = Some((cmd, now));
            }
        }
        if now >= next_cycle {
            next_cycle += stations.revo2.cycle_ns;
            let sample = robot.cycle(now);
            to_operator.push(now, sample);
        }

        // The operator station: the bridge's hand data into force feedback.
        while let Some((state, tactile)) = to_operator.pop_due(now) {
            while let Some((_, out)) = feedback.poll(now) {
                take(out, now, &mut force);
            }
            if bridge_passes(
                state.header.stamp_ns,
                now,
                stations.state_max_age_ns,
                bridge_allowance,
            ) {
                take(feedback.handle(&Event::State(state), now), now, &mut force);
            }
            if let Some(t) = tactile.filter(|t| {
                bridge_passes(
                    t.header.stamp_ns,
                    now,
                    stations.tactile_max_age_ns,
                    bridge_allowance,
                )
            }) {
                take(feedback.handle(&Event::Tactile(t), now), now, &mut force);
            }
        }
        while let Some((_, out)) = feedback.poll(now) {
            take(out, now, &mut force);
        }

        // The glove node's exchange: in a diagnostic slot a register read (the actual forces,
        // then four others, in turn), else the force to send (fresh by its stamp, else zero;
        // clamped) and the answer's positions as glove/state into retargeting.
        let diagnostic = stations
            .glove
            .diagnostic_ns
            .filter(|_| now >= next_exchange && now >= next_diagnostic);
        if let Some(period) = diagnostic {
            next_exchange += stations.glove.exchange_ns;
            next_diagnostic = now + period;
            if diagnostic_slot == 0 {
                glove_force = operator.forces();
            }
            diagnostic_slot = (diagnostic_slot + 1) % DIAGNOSTIC_REGISTERS;
        } else if now >= next_exchange {
            next_exchange += stations.glove.exchange_ns;
            let max = stations.glove.max_force;
            let forces = match force.command {
                Some((cmd, at)) if now - at <= stations.glove.force_timeout_ns => {
                    cmd.force.map(|f| f32::from(f).clamp(-max, max))
                }
                _ => [0.0; FINGERS],
            };
            for (f, value) in forces.iter().enumerate() {
                operator.set_drive(f, Drive::Force(*value));
            }
            glove_seq += 1;
            let raw = operator.positions();
            let mut sample = GloveState {
                raw_position: raw,
                // The forces the glove measured at its last actual-force read, as the node
                // reports them (force feedback does not read them: the passivity observer
                // counts the force commanded).
                force: glove_force,
                position: raw.map(|p| (f32::from(p) / 1000.0).clamp(0.0, 1.0)),
                link_up: 1,
                exchanges: glove_seq as u32,
                ..Default::default()
            };
            sample.header.seq = glove_seq;
            sample.header.stamp_ns = now;
            sample.header.origin_ns = now;
            take(feedback.handle(&Event::Glove(sample), now), now, &mut force);
            let out = retarget.on_glove(&sample, now);
            if let Some(mut cmd) = out.command {
                command_seq += 1;
                cmd.header.seq = command_seq;
                cmd.header.stamp_ns = now;
                take(feedback.handle(&Event::Command(cmd), now), now, &mut force);
                to_robot.push(now, cmd);
            }
        }
        while let Some((_, out)) = retarget.poll(now) {
            if let Some(mut cmd) = out.command {
                command_seq += 1;
                cmd.header.seq = command_seq;
                cmd.header.stamp_ns = now;
                // The feedback node sees every hand/command, as from a glove sample above.
                take(feedback.handle(&Event::Command(cmd), now), now, &mut force);
                to_robot.push(now, cmd);
            }
        }

        // The record: what the operator feels and does, what the robot touches.
        let velocity = operator.velocities();
        let touches = robot.hand.touches();
        ticks.push(Tick {
            t_s,
            finger: core::array::from_fn(|f| f32::from(operator.positions()[f])),
            velocity: core::array::from_fn(|f| velocity[f]),
            felt: operator.forces().map(f32::from),
            drive: operator.drives().map(|d| match d {
                Drive::Force(f) => f,
                Drive::Position(_) => 0.0,
            }),
            robot_n: sources.map(|s| s.and_then(|i| touches.get(i)).map_or(0.0, |t| t.normal_n)),
            stale: force
                .command
                .is_some_and(|(cmd, _)| cmd.flags & force_flags::STALE != 0),
            observed: force.observed,
        });
        now += TICK_NS;
    }
    Ok(ticks)
}

/// What the force-feedback engine last said.
#[derive(Debug, Clone, Copy, Default)]
struct Force {
    /// The newest force command and when it was published.
    command: Option<(GloveForceCommand, u64)>,
    /// The passivity observer's newest energy per finger.
    observed: [f32; FINGERS],
}

/// The force-feedback engine's output at `now`: its command, if any, becomes the newest.
fn take(out: teleop_feedback::Output, now: u64, force: &mut Force) {
    if let Some(cmd) = out.command {
        force.command = Some((cmd, now));
    }
    if let Some(report) = out.passivity {
        force.observed = report.energy;
    }
}

/// Peak-to-peak felt force above which a held grasp may be oscillating, glove units (4 % of the
/// glove's full scale, about 0.12 N).
pub const CYCLE_FORCE_P2P: f32 = 40.0;
/// Peak-to-peak finger motion above which a held grasp may be oscillating, raw units (1 % of
/// the travel).
pub const CYCLE_FINGER_P2P: f32 = 10.0;
/// A limit cycle keeps at least this share of its amplitude from the first to the second half
/// of the window (it does not decay).
pub const CYCLE_KEEPS: f32 = 0.5;
/// Zero crossings (of the signal less its mean) a window needs to count as oscillating: two
/// whole periods.
pub const CYCLE_CROSSINGS: usize = 4;
/// The settling band: within this share of the final felt force, or [`SETTLE_BAND_MIN`].
pub const SETTLE_BAND: f32 = 0.1;
/// The settling band's least half-width, glove units.
pub const SETTLE_BAND_MIN: f32 = 20.0;
/// A finger is in contact in a hold when its expected felt force is at least this, glove units.
pub const CONTACT_MIN: f32 = 20.0;

/// One held grasp's figures.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Hold {
    /// Mean felt force on the index over the held part, glove units.
    pub felt_index: f32,
    /// Mean expected index force over the held part (the robot's measured fingertip force after
    /// the configured gain, threshold, per-finger gain and saturation), glove units.
    pub expected_index: f32,
    /// Index error, % of the expected (`None`: no contact expected).
    pub error_index_pct: Option<f32>,
    /// Mean of the errors of the fingers in contact, % (`None`: none in contact).
    pub error_mean_pct: Option<f32>,
    /// Mean felt force over the held part of the fingers in contact (expecting at least
    /// [`CONTACT_MIN`]), glove units (`None`: none in contact).
    pub felt_contact: Option<f32>,
    /// Peak-to-peak of the index's felt force over the held part, glove units.
    pub felt_p2p_index: f32,
    /// Largest peak-to-peak of a finger's felt force over the held part, glove units.
    pub felt_p2p: f32,
    /// Largest peak-to-peak of a finger's position over the held part, raw units.
    pub finger_p2p: f32,
    /// A sustained oscillation (see [`limit_cycle`]) of some finger's felt force or position:
    /// the finger (glove order) whose felt force swings most among those oscillating, and its
    /// period, s.
    pub cycle: Option<(usize, f32)>,
    /// From the first tactile force above the threshold on the index to the felt force staying
    /// within the settling band of its final value until the hold ends, s.
    pub settle_s: Option<f32>,
    /// Share of the whole hold (55-80 %) whose newest force command was flagged STALE.
    pub stale_share: f32,
}

/// A run's figures.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Metrics {
    /// Per grasp cycle.
    pub holds: Vec<Hold>,
    /// The most negative running sum over the run of `drive × closing velocity × dt` summed
    /// over the fingers (glove units × travel; 0 when it never went negative): the energy the
    /// feedback channel generated.
    pub generated: f32,
    /// The most negative energy the passivity observer saw on any finger (glove units ×
    /// travel; 0 when never negative).
    pub observed: f32,
}

/// The figures of a run of `case` (see [`Hold`] and [`Metrics`]).
pub fn analyse(stations: &Stations, case: &Case, ticks: &[Tick]) -> Metrics {
    let config = stations.feedback();
    let expected = |tick: &Tick, f: usize| {
        let above = (tick.robot_n[f] - config.contact_threshold_n).max(0.0);
        (config.gain_per_n * above * config.finger_gain[f]).clamp(0.0, f32::from(config.max_force))
    };
    let period = f64::from(case.grasp_period_s);
    let mut holds = Vec::new();
    for k in 0..case.grasps {
        let start = f64::from(k) * period;
        let range = |from: f64, to: f64| {
            let a = ticks.partition_point(|t| t.t_s < start + from * period);
            let b = ticks.partition_point(|t| t.t_s < start + to * period);
            &ticks[a..b]
        };
        let held = range((HOLD.0 + HOLD.1) / 2.0, HOLD.1);
        let hold = range(HOLD.0, HOLD.1);
        let approach = range(0.0, HOLD.1);
        if held.is_empty() {
            continue;
        }
        let mean = |f: &dyn Fn(&Tick) -> f32| held.iter().map(f).sum::<f32>() / held.len() as f32;
        let error = |f: usize| {
            let (felt, want) = (mean(&|t| t.felt[f]), mean(&|t| expected(t, f)));
            (want >= CONTACT_MIN).then(|| (felt - want) / want * 100.0)
        };
        let errors: Vec<f32> = (0..FINGERS).filter_map(error).collect();
        let touching: Vec<f32> = (0..FINGERS)
            .filter(|&f| mean(&|t| expected(t, f)) >= CONTACT_MIN)
            .map(|f| mean(&|t| t.felt[f]))
            .collect();
        let felt_index = mean(&|t| t.felt[INDEX]);
        let felt: [Vec<f32>; FINGERS] =
            core::array::from_fn(|f| held.iter().map(|t| t.felt[f]).collect());
        let finger: [Vec<f32>; FINGERS] =
            core::array::from_fn(|f| held.iter().map(|t| t.finger[f]).collect());
        let swing = |v: &[Vec<f32>; FINGERS]| v.iter().map(|s| p2p(s)).fold(0.0f32, f32::max);
        let cycle = (0..FINGERS)
            .filter_map(|f| {
                limit_cycle(&felt[f], CYCLE_FORCE_P2P)
                    .or_else(|| limit_cycle(&finger[f], CYCLE_FINGER_P2P))
                    .map(|ticks| (f, ticks as f32 * TICK_NS as f32 * 1e-9))
            })
            .max_by(|a, b| p2p(&felt[a.0]).total_cmp(&p2p(&felt[b.0])));
        let contact = approach
            .iter()
            .find(|t| t.robot_n[INDEX] > config.contact_threshold_n)
            .map(|t| t.t_s);
        let band = (SETTLE_BAND * felt_index.abs()).max(SETTLE_BAND_MIN);
        let settle_s = contact.and_then(|c| {
            let last_out = approach
                .iter()
                .rposition(|t| (t.felt[INDEX] - felt_index).abs() > band)?;
            let settled = approach.get(last_out + 1)?.t_s;
            Some((settled - c).max(0.0) as f32)
        });
        holds.push(Hold {
            felt_index,
            expected_index: mean(&|t| expected(t, INDEX)),
            error_index_pct: error(INDEX),
            error_mean_pct: (!errors.is_empty())
                .then(|| errors.iter().sum::<f32>() / errors.len() as f32),
            felt_contact: (!touching.is_empty())
                .then(|| touching.iter().sum::<f32>() / touching.len() as f32),
            felt_p2p_index: p2p(&felt[INDEX]),
            felt_p2p: swing(&felt),
            finger_p2p: swing(&finger),
            cycle,
            settle_s,
            stale_share: hold.iter().filter(|t| t.stale).count() as f32 / hold.len().max(1) as f32,
        });
    }
    let mut sum = 0.0f32;
    let mut generated = 0.0f32;
    for t in ticks {
        let dt = TICK_NS as f32 * 1e-9;
        for f in 0..FINGERS {
            // Closing velocity in travel per second: raw units per second / 1000, opening
            // positive in the record.
            sum += t.drive[f] * (-t.velocity[f] / 1000.0) * dt;
        }
        generated = generated.min(sum);
    }
    let observed = ticks.iter().flat_map(|t| t.observed).fold(0.0f32, f32::min);
    Metrics {
        holds,
        // `0.0 - x`, not `-x`: nothing generated is 0, not -0.
        generated: 0.0 - generated,
        observed: 0.0 - observed,
    }
}

fn p2p(v: &[f32]) -> f32 {
    let (lo, hi) = v
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    if v.is_empty() {
        0.0
    } else {
        hi - lo
    }
}

/// Whether `signal` (one sample per tick) oscillates in a sustained way: its peak-to-peak is
/// above `threshold`, its second half keeps at least [`CYCLE_KEEPS`] of the first half's
/// peak-to-peak, and it crosses its mean (with a hysteresis of a quarter of the threshold) at
/// least [`CYCLE_CROSSINGS`] times. Returns the dominant period in ticks: the lag of the
/// highest peak of the signal's autocorrelation after its first zero, within half the window
/// (so that two periods fit).
pub fn limit_cycle(signal: &[f32], threshold: f32) -> Option<usize> {
    if signal.len() < 4 || p2p(signal) <= threshold {
        return None;
    }
    let half = signal.len() / 2;
    let (first, second) = (p2p(&signal[..half]), p2p(&signal[half..]));
    if second < CYCLE_KEEPS * first || second <= threshold / 2.0 {
        return None;
    }
    let mean = signal.iter().sum::<f32>() / signal.len() as f32;
    let x: Vec<f32> = signal.iter().map(|v| v - mean).collect();
    let hysteresis = threshold / 4.0;
    let mut above: Option<bool> = None;
    let mut crossings = 0;
    for &v in &x {
        let side = (v.abs() > hysteresis).then_some(v > 0.0);
        if let Some(side) = side {
            crossings += usize::from(above.is_some_and(|a| a != side));
            above = Some(side);
        }
    }
    if crossings < CYCLE_CROSSINGS {
        return None;
    }
    let correlation = |lag: usize| -> f32 { x.iter().zip(&x[lag..]).map(|(a, b)| a * b).sum() };
    let zero = (1..half).find(|&lag| correlation(lag) <= 0.0)?;
    (zero..=half).max_by(|&a, &b| correlation(a).total_cmp(&correlation(b)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sustained_sine_is_a_limit_cycle_with_its_period_and_a_decaying_one_is_not() {
        let sine = |decay: f32| -> Vec<f32> {
            (0..1000)
                .map(|i| {
                    let t = i as f32 * 1e-3;
                    100.0 * (-decay * t).exp() * (core::f32::consts::TAU * t / 0.08).sin()
                })
                .collect()
        };
        let period = limit_cycle(&sine(0.0), 40.0).expect("a sustained sine oscillates");
        assert!((76..=84).contains(&period), "{period} ticks");
        assert_eq!(limit_cycle(&sine(5.0), 40.0), None, "decays");
        assert_eq!(limit_cycle(&[500.0; 1000], 40.0), None, "constant");
    }

    #[test]
    fn the_delay_line_delivers_in_order_when_due() {
        let mut line = DelayLine::new(5);
        line.push(0, 'a');
        line.push(2, 'b');
        assert_eq!(line.pop_due(4), None);
        assert_eq!(line.pop_due(7), Some('a'));
        assert_eq!(line.pop_due(7), Some('b'));
    }

    #[test]
    fn bridges_drop_only_samples_older_than_their_limit() {
        assert!(bridge_passes(0, 100, Some(100), 0));
        assert!(!bridge_passes(0, 101, Some(100), 0));
        assert!(bridge_passes(0, 151, Some(100), 51));
        assert!(bridge_passes(0, u64::MAX, None, 0));
    }

    #[test]
    fn the_figures_of_a_known_grasp() {
        let stations = Stations::repository().expect("the repository's configuration");
        let law = stations.feedback().clone();
        let case = Case {
            grasps: 1,
            grasp_period_s: 1.0,
            ..Case::new(0, Object::RIGID, Feedback::Plain)
        };
        // The robot's index touches at 0.3 s with a force the law turns into 500 units; the
        // glove's index feels 450 from 0.4 s on, after a swing that ends there. Meanwhile the
        // actuator pushes 100 while the finger opens at 1000 raw/s for 0.1 s (the channel gives
        // 100 x 1 travel/s x 0.1 s = 10), then as much while it closes (it takes 10 back).
        let newtons = law.contact_threshold_n + 500.0 / (law.gain_per_n * law.finger_gain[INDEX]);
        let ticks: Vec<Tick> = (0..=1000)
            .map(|ms| {
                let t_s = f64::from(ms) * 1e-3;
                let mut tick = Tick {
                    t_s,
                    ..Tick::default()
                };
                if t_s >= 0.3 {
                    tick.robot_n[INDEX] = newtons;
                    tick.felt[INDEX] = if t_s >= 0.4 { 450.0 } else { 900.0 };
                }
                if (0.1..0.2).contains(&t_s) {
                    (tick.drive[0], tick.velocity[0]) = (100.0, 1000.0);
                } else if (0.2..0.3).contains(&t_s) {
                    (tick.drive[0], tick.velocity[0]) = (100.0, -1000.0);
                }
                tick.finger[INDEX] = 500.0 + if ms % 20 < 10 { 10.0 } else { -10.0 };
                tick
            })
            .collect();
        let m = analyse(&stations, &case, &ticks);
        let hold = m.holds[0];
        assert!((hold.expected_index - 500.0).abs() < 0.5, "{hold:?}");
        let error = hold.error_index_pct.expect("the index in contact");
        assert!((error + 10.0).abs() < 0.1, "{hold:?}");
        assert_eq!(hold.felt_contact, Some(450.0));
        assert!(
            (hold.settle_s.expect("settles") - 0.1).abs() < 0.0015,
            "{hold:?}"
        );
        assert_eq!((hold.felt_p2p_index, hold.finger_p2p), (0.0, 20.0));
        let (finger, period) = hold.cycle.expect("the finger swings 20 raw every 20 ms");
        assert_eq!(finger, INDEX);
        assert!((period - 0.02).abs() < 0.0015, "{hold:?}");
        assert!((m.generated - 10.0).abs() < 0.05, "{m:?}");
    }
}
