//! What the viewer shows, independent of rerun: each [`Sample`] becomes a [`Frame`] of
//! [`Entry`]s (an entity path and a plain value to draw there), on two timelines.
//!
//! [`Scene`] keeps what a sample alone does not carry (the robot hand's latest pose, where the
//! fingertip contacts are drawn) and decimates: per topic and publisher, scalars at most at
//! [`SceneConfig::scalar_hz`], 3D poses and bar charts at most at [`SceneConfig::pose_hz`]
//! (by the samples' own stamps, so a recording and the live pipeline give the same picture).
//!
//! Entity paths (`{f}` is a finger of [`FINGERS`], or `thumb_rotation` for positions):
//! - `hands/operator/{bones,joints,tips}`: the operator's hand from the glove
//!   ([`OperatorHand`]); `hands/robot/{bones,joints,tips}`: the Revo2 from its joint state
//!   ([`Revo2Hand`]); `hands/robot/contacts`: fingertips in contact, radius growing with the
//!   normal force; `hands/robot/tangential`: tangential force arrows.
//! - `fingers/{f}/position/{glove,command,measured}`: finger closure 0 (open) .. 1 (closed):
//!   the glove's `1 - position`, the hand command and the measured hand joint.
//! - `fingers/{f}/force/{tactile_normal,glove_command}`: newtons, glove units.
//! - `bars/{tactile_normal,glove_force}`: the current values, thumb .. little.
//! - `health/...`: link and node counters; `latency/...`: milliseconds from the headers.
//! - `diagnostics/glove/...`, `devices/{glove,revo2}`.

use std::collections::HashMap;

use glam::Vec3;
use teleop_msgs::{
    control_mode, device_kind, hand_model, text_of, units, DeviceInfo, GloveDiagnostics,
    GloveForceCommand, GloveState, HandCommand, HandState, NodeHealth, Tactile, MAX_FINGERTIPS,
};

use crate::kinematics::{
    OperatorHand, OperatorPose, Revo2Hand, Skeleton, FINGERS, GLOVE_CHANNEL_OF_FINGER,
    REVO2_JOINT_OF_FINGER, REVO2_THUMB_ABDUCT,
};
use crate::sample::Sample;

/// The timeline of when a sample was received (by the recorder for a recording, by the viewer
/// live), relative to [`SceneConfig::time_origin_ns`].
pub const RECORDING_TIME: &str = "recording_time";
/// The timeline of the samples' own stamps (`header.stamp_ns`), same origin.
pub const SAMPLE_TIME: &str = "sample_time";

/// Where the operator's hand sits in the 3D view (left), and the robot's (right), metres.
pub const OPERATOR_PLACEMENT: [f32; 3] = [-0.12, 0.0, 0.0];
/// See [`OPERATOR_PLACEMENT`].
pub const ROBOT_PLACEMENT: [f32; 3] = [0.12, 0.0, 0.0];

/// Contact sphere radius per newton of normal force, metres.
pub const CONTACT_RADIUS_PER_N: f32 = 0.003;
/// Radius of a contact sphere at zero force, metres (just larger than a fingertip marker).
pub const CONTACT_RADIUS_MIN: f32 = 0.007;
/// Largest contact sphere drawn, metres.
pub const CONTACT_RADIUS_MAX: f32 = 0.025;
/// Normal force from which a fingertip counts as in contact, newtons.
pub const CONTACT_THRESHOLD_N: f32 = 0.05;
/// Tangential arrow length per newton, metres.
pub const TANGENTIAL_M_PER_N: f32 = 0.01;

/// The per-finger position series: the five fingers, then the thumb rotation.
pub const POSITION_SERIES: [&str; 6] = [
    "thumb",
    "index",
    "middle",
    "ring",
    "little",
    "thumb_rotation",
];

/// The topics whose delivery latency (receipt minus stamp) is shown: the control data, not
/// the slow reports (a late subscriber gets `device/info` from history, seconds old).
pub const DELIVERY_TOPICS: [&str; 5] = [
    "glove/state",
    "hand/command",
    "hand/state",
    "hand/tactile",
    "glove/force_command",
];

/// RGBA.
pub type Rgba = [u8; 4];

/// A colour per finger ([`FINGERS`] order).
pub const FINGER_COLORS: [Rgba; 5] = [
    [230, 80, 60, 255],
    [240, 160, 40, 255],
    [90, 180, 70, 255],
    [60, 130, 220, 255],
    [160, 90, 200, 255],
];
const GLOVE_COLOR: Rgba = [90, 160, 230, 255];
const COMMAND_COLOR: Rgba = [240, 150, 40, 255];
const MEASURED_COLOR: Rgba = [60, 170, 90, 255];
const OPERATOR_COLOR: Rgba = [100, 170, 240, 255];
const ROBOT_COLOR: Rgba = [190, 190, 200, 255];
const CONTACT_COLOR: Rgba = [255, 60, 40, 255];
const CONTACT_FILL: Rgba = [255, 60, 40, 190];
const TANGENTIAL_COLOR: Rgba = [250, 210, 40, 255];
const TACTILE_BAR_COLOR: Rgba = [255, 110, 70, 255];
const GLOVE_BAR_COLOR: Rgba = [90, 160, 230, 255];

/// Something to draw at one entity path.
#[derive(Debug, Clone, PartialEq)]
pub enum Visual {
    /// One value of a time series.
    Scalar(f64),
    /// 3D points; `radii` and `colors` hold one value for all points or one per point.
    Points {
        /// Positions, metres.
        positions: Vec<[f32; 3]>,
        /// Radii, metres.
        radii: Vec<f32>,
        /// Colours.
        colors: Vec<Rgba>,
        /// Labels (empty: none).
        labels: Vec<String>,
    },
    /// 3D line strips of one colour.
    Strips {
        /// Each strip's points, metres.
        strips: Vec<Vec<[f32; 3]>>,
        /// Line radius, metres.
        radius: f32,
        /// Colour.
        color: Rgba,
    },
    /// 3D arrows of one colour.
    Arrows {
        /// Where each arrow starts, metres.
        origins: Vec<[f32; 3]>,
        /// Each arrow's vector, metres.
        vectors: Vec<[f32; 3]>,
        /// Colour.
        color: Rgba,
    },
    /// A bar chart's current values.
    Bars {
        /// Bar heights, left to right.
        values: Vec<f32>,
        /// Colour.
        color: Rgba,
    },
    /// A Markdown text document.
    Markdown(String),
    /// (static) How a time series is drawn: its legend name and colour.
    Series {
        /// Legend name.
        name: String,
        /// Line colour.
        color: Rgba,
    },
    /// (static) Translation of an entity's frame relative to its parent, metres.
    Translation([f32; 3]),
    /// (static) The 3D coordinate convention: right-handed, Z up.
    ZUp,
}

/// A value at an entity path.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// Entity path, e.g. `fingers/index/position/glove`.
    pub path: String,
    /// What to draw there.
    pub visual: Visual,
}

impl Entry {
    /// An entry.
    pub fn new(path: impl Into<String>, visual: Visual) -> Self {
        Self {
            path: path.into(),
            visual,
        }
    }

    fn scalar(path: impl Into<String>, value: f64) -> Self {
        Self::new(path, Visual::Scalar(value))
    }
}

/// Everything one sample shows, at one point of both timelines.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// [`RECORDING_TIME`], nanoseconds from the origin.
    pub recording_time_ns: i64,
    /// [`SAMPLE_TIME`], nanoseconds from the origin.
    pub sample_time_ns: i64,
    /// What to log.
    pub entries: Vec<Entry>,
}

impl Frame {
    /// The entry at `path`, if any.
    pub fn get(&self, path: &str) -> Option<&Visual> {
        self.entries
            .iter()
            .find(|e| e.path == path)
            .map(|e| &e.visual)
    }
}

/// At most one sample per interval and per (topic, publisher), by the samples' stamps.
#[derive(Debug, Clone)]
pub struct Decimator {
    interval_ns: u64,
    last: HashMap<(&'static str, u32), u64>,
}

impl Decimator {
    /// At most `max_hz` samples per second per topic and publisher (`0` or less, or not
    /// finite: every sample).
    pub fn new(max_hz: f64) -> Self {
        let interval_ns = if max_hz.is_finite() && max_hz > 0.0 {
            (1e9 / max_hz) as u64
        } else {
            0
        };
        Self {
            interval_ns,
            last: HashMap::new(),
        }
    }

    /// Whether a sample of `topic` from `source_id` stamped `stamp_ns` is shown. A stamp
    /// earlier than the last one shown (a restarted publisher, a looped replay) starts over.
    pub fn admit(&mut self, topic: &'static str, source_id: u32, stamp_ns: u64) -> bool {
        match self.last.get_mut(&(topic, source_id)) {
            Some(last) if stamp_ns >= *last && stamp_ns - *last < self.interval_ns => false,
            Some(last) => {
                *last = stamp_ns;
                true
            }
            None => {
                self.last.insert((topic, source_id), stamp_ns);
                true
            }
        }
    }
}

/// Rates and the time origin of a [`Scene`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneConfig {
    /// Most samples per second per topic and publisher turned into scalars (0: all).
    pub scalar_hz: f64,
    /// Most 3D poses and bar chart updates per second per topic (0: all; never more often
    /// than `scalar_hz`).
    pub pose_hz: f64,
    /// CLOCK_MONOTONIC nanoseconds that both timelines count from.
    pub time_origin_ns: u64,
}

impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            scalar_hz: 100.0,
            pose_hz: 30.0,
            time_origin_ns: 0,
        }
    }
}

/// The viewer's content: turns samples into frames.
#[derive(Debug, Clone)]
pub struct Scene {
    config: SceneConfig,
    operator: OperatorHand,
    robot: Revo2Hand,
    /// The robot hand's latest pose (open until a hand state arrives).
    robot_pose: Skeleton,
    scalars: Decimator,
    poses: Decimator,
}

fn arr(v: Vec3) -> [f32; 3] {
    v.to_array()
}

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

/// An entity path part from a node name: letters, digits, `_` and `-`; anything else `_`.
pub fn path_part(name: &str) -> String {
    let part: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if part.is_empty() {
        "unnamed".to_string()
    } else {
        part
    }
}

/// The path of a finger position series.
pub fn position_path(finger: &str, which: &str) -> String {
    format!("fingers/{finger}/position/{which}")
}

/// The path of a finger force series.
pub fn force_path(finger: &str, which: &str) -> String {
    format!("fingers/{finger}/force/{which}")
}

impl Scene {
    /// A scene with the default hand models.
    pub fn new(config: SceneConfig) -> Self {
        let robot = Revo2Hand::default();
        let robot_pose = robot.pose(&[0.0; 6]);
        Self {
            config,
            operator: OperatorHand::default(),
            robot,
            robot_pose,
            scalars: Decimator::new(config.scalar_hz),
            poses: Decimator::new(config.pose_hz),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SceneConfig {
        &self.config
    }

    /// The operator's hand model.
    pub fn operator_model(&self) -> &OperatorHand {
        &self.operator
    }

    /// The robot hand model.
    pub fn robot_model(&self) -> &Revo2Hand {
        &self.robot
    }

    fn time(&self, ns: u64) -> i64 {
        ns as i64 - self.config.time_origin_ns as i64
    }

    /// What is logged once, timeless: the coordinate convention, where each hand sits, and
    /// the name and colour of every time series.
    pub fn static_entries(&self) -> Vec<Entry> {
        let mut out = vec![
            Entry::new("hands", Visual::ZUp),
            Entry::new("hands/operator", Visual::Translation(OPERATOR_PLACEMENT)),
            Entry::new("hands/robot", Visual::Translation(ROBOT_PLACEMENT)),
        ];
        for (who, label, color) in [
            ("operator", "operator (glove)", OPERATOR_COLOR),
            ("robot", "robot (Revo2)", ROBOT_COLOR),
        ] {
            out.push(Entry::new(
                format!("hands/{who}/label"),
                Visual::Points {
                    positions: vec![[0.0, 0.1, 0.07]],
                    radii: vec![0.002],
                    colors: vec![color],
                    labels: vec![label.to_string()],
                },
            ));
        }
        let series = |path: String, name: &str, color: Rgba| {
            Entry::new(
                path,
                Visual::Series {
                    name: name.to_string(),
                    color,
                },
            )
        };
        for f in POSITION_SERIES {
            out.push(series(
                position_path(f, "glove"),
                "glove (1 - position)",
                GLOVE_COLOR,
            ));
            out.push(series(
                position_path(f, "command"),
                "commanded",
                COMMAND_COLOR,
            ));
            out.push(series(
                position_path(f, "measured"),
                "measured",
                MEASURED_COLOR,
            ));
        }
        for (f, color) in FINGERS.iter().zip(FINGER_COLORS) {
            out.push(series(force_path(f, "tactile_normal"), f, color));
            out.push(series(force_path(f, "glove_command"), f, color));
            out.push(series(
                format!("diagnostics/glove/temperature_c/{f}"),
                f,
                color,
            ));
            out.push(series(
                format!("diagnostics/glove/current_ma/{f}"),
                f,
                color,
            ));
        }
        for (path, name, color) in [
            (
                "latency/retarget",
                "glove sample -> hand command",
                COMMAND_COLOR,
            ),
            (
                "latency/feedback",
                "hand sample -> glove force",
                CONTACT_COLOR,
            ),
            ("health/glove/errors", "glove link errors", GLOVE_COLOR),
            (
                "health/hand/link_errors",
                "hand link errors (EtherCAT: wrong working counter)",
                COMMAND_COLOR,
            ),
            (
                "health/hand/lost_frames",
                "hand link lost frames",
                CONTACT_COLOR,
            ),
            (
                "health/viewer/queue_full",
                "viewer: dropped (queue full)",
                ROBOT_COLOR,
            ),
            (
                "health/viewer/missed",
                "viewer: missed (sequence gaps)",
                [120, 120, 120, 255],
            ),
            (
                "health/glove/link_up",
                "glove link up (1/0)",
                [150, 200, 250, 255],
            ),
            (
                "health/glove/actuators_in_error",
                "glove actuators in error",
                [200, 60, 60, 255],
            ),
            (
                "health/hand/link_up",
                "hand link up (1/0)",
                [250, 200, 150, 255],
            ),
            (
                "health/hand/holding",
                "hand holding (1/0)",
                [200, 150, 60, 255],
            ),
            ("health/estop", "e-stop engaged (1/0)", [255, 0, 0, 255]),
            (
                "health/feedback/estop",
                "glove forces held by e-stop (1/0)",
                [180, 0, 0, 255],
            ),
        ] {
            out.push(series(path.to_string(), name, color));
        }
        for (topic, color) in DELIVERY_TOPICS.iter().zip(FINGER_COLORS) {
            out.push(series(
                format!("latency/delivery/{}", path_part(topic)),
                &format!("delivery of {topic}"),
                color,
            ));
        }
        out
    }

    /// What `sample` shows, received at `received_ns` (CLOCK_MONOTONIC: the recorder's log
    /// time, or when the viewer took it). `None` when decimation skips it.
    pub fn frame(&mut self, sample: &Sample, received_ns: u64) -> Option<Frame> {
        let header = *sample.header();
        let topic = sample.topic();
        if !self.scalars.admit(topic, header.source_id, header.stamp_ns) {
            return None;
        }
        let visuals = self.poses.admit(topic, header.source_id, header.stamp_ns);
        let mut entries = Vec::new();
        if DELIVERY_TOPICS.contains(&topic)
            && received_ns >= header.stamp_ns
            && header.stamp_ns != 0
        {
            entries.push(Entry::scalar(
                format!("latency/delivery/{}", path_part(topic)),
                ms(received_ns - header.stamp_ns),
            ));
        }
        match sample {
            Sample::GloveState(m) => self.glove_state(m, visuals, &mut entries),
            Sample::GloveDiagnostics(m) => glove_diagnostics(m, &mut entries),
            Sample::GloveForceCommand(m) => glove_force(m, visuals, &mut entries),
            Sample::HandCommand(m) => self.hand_command(m, &mut entries),
            Sample::HandState(m) => self.hand_state(m, visuals, &mut entries),
            Sample::Tactile(m) => self.tactile(m, visuals, &mut entries),
            Sample::Health(m) => node_health(m, &mut entries),
            Sample::EStop(m) => {
                entries.push(Entry::scalar("health/estop", f64::from(m.engaged)));
            }
            Sample::DeviceInfo(m) => device_info(m, &mut entries),
        }
        Some(Frame {
            recording_time_ns: self.time(received_ns),
            sample_time_ns: self.time(header.stamp_ns),
            entries,
        })
    }

    /// The viewer's own drop counters at `now_ns` (both timelines at `now_ns`).
    pub fn viewer_stats(&self, now_ns: u64, queue_full: u64, missed: u64) -> Frame {
        Frame {
            recording_time_ns: self.time(now_ns),
            sample_time_ns: self.time(now_ns),
            entries: vec![
                Entry::scalar("health/viewer/queue_full", queue_full as f64),
                Entry::scalar("health/viewer/missed", missed as f64),
            ],
        }
    }

    /// The operator's pose drawn from glove positions.
    pub fn operator_pose(&self, position: &[f32; 6]) -> Skeleton {
        self.operator.pose(&OperatorPose::from_glove(position))
    }

    fn glove_state(&mut self, m: &GloveState, visuals: bool, out: &mut Vec<Entry>) {
        let pose = OperatorPose::from_glove(&m.position);
        for (i, f) in FINGERS.iter().enumerate() {
            out.push(Entry::scalar(
                position_path(f, "glove"),
                f64::from(pose.flexion[i]),
            ));
        }
        out.push(Entry::scalar(
            position_path("thumb_rotation", "glove"),
            f64::from(pose.thumb_opposition),
        ));
        out.push(Entry::scalar("health/glove/errors", f64::from(m.errors)));
        out.push(Entry::scalar("health/glove/link_up", f64::from(m.link_up)));
        if visuals {
            let skeleton = self.operator.pose(&pose);
            skeleton_entries("operator", &skeleton, OPERATOR_COLOR, out);
        }
    }

    /// Normalised positions (0 open .. 1 closed) of a Revo2 joint array in `units`.
    fn revo2_normalised(&self, values: [f32; 6], unit: u8) -> [f32; 6] {
        if unit == units::PHYSICAL {
            self.robot.normalise(&values)
        } else {
            values
        }
    }

    fn hand_command(&mut self, m: &HandCommand, out: &mut Vec<Entry>) {
        if m.header.origin_ns != 0 && m.header.stamp_ns >= m.header.origin_ns {
            out.push(Entry::scalar(
                "latency/retarget",
                ms(m.header.stamp_ns - m.header.origin_ns),
            ));
        }
        let positional = matches!(
            m.control_mode,
            control_mode::POSITION | control_mode::POSITION_TIME
        );
        if !positional || !is_revo2_layout(m.hand_model, m.joint_count) {
            return;
        }
        let q = self.revo2_normalised(core::array::from_fn(|j| m.joints[j].target), m.units);
        revo2_position_series(&q, "command", out);
    }

    fn hand_state(&mut self, m: &HandState, visuals: bool, out: &mut Vec<Entry>) {
        out.push(Entry::scalar(
            "health/hand/link_errors",
            f64::from(m.link_errors),
        ));
        out.push(Entry::scalar(
            "health/hand/lost_frames",
            f64::from(m.lost_frames),
        ));
        out.push(Entry::scalar("health/hand/link_up", f64::from(m.link_up)));
        out.push(Entry::scalar("health/hand/holding", f64::from(m.holding)));
        if !is_revo2_layout(m.hand_model, m.joint_count) {
            return;
        }
        let q = self.revo2_normalised(core::array::from_fn(|j| m.joints[j].position), m.units);
        revo2_position_series(&q, "measured", out);
        self.robot_pose = self.robot.pose(&q);
        if visuals {
            skeleton_entries("robot", &self.robot_pose, ROBOT_COLOR, out);
        }
    }

    fn tactile(&mut self, m: &Tactile, visuals: bool, out: &mut Vec<Entry>) {
        let tips = m.active_fingertips();
        let mut normal = [0f32; MAX_FINGERTIPS];
        for (i, tip) in tips.iter().enumerate().take(FINGERS.len()) {
            if tip.is_valid() && tip.normal_n.is_finite() {
                normal[i] = tip.normal_n;
                out.push(Entry::scalar(
                    force_path(FINGERS[i], "tactile_normal"),
                    f64::from(tip.normal_n),
                ));
            }
        }
        if !visuals {
            return;
        }
        out.push(Entry::new(
            "bars/tactile_normal",
            Visual::Bars {
                values: normal.to_vec(),
                color: TACTILE_BAR_COLOR,
            },
        ));
        let positions = self.robot_pose.tips();
        let directions = self.robot_pose.tip_directions();
        let (mut at, mut radii, mut origins, mut vectors) = (vec![], vec![], vec![], vec![]);
        for (i, tip) in tips.iter().enumerate().take(FINGERS.len()) {
            if normal[i] >= CONTACT_THRESHOLD_N {
                at.push(arr(positions[i]));
                radii.push(contact_radius(normal[i]));
            }
            if tip.is_valid()
                && tip.direction_valid == 1
                && tip.tangential_n.is_finite()
                && tip.tangential_n > CONTACT_THRESHOLD_N
            {
                let along = directions[i];
                let side = along.cross(Vec3::Z).normalize_or(Vec3::X);
                let angle = tip.direction_deg.to_radians();
                let dir = along * angle.cos() + side * angle.sin();
                origins.push(arr(positions[i]));
                vectors.push(arr(dir * tip.tangential_n * TANGENTIAL_M_PER_N));
            }
        }
        out.push(Entry::new(
            "hands/robot/contacts",
            Visual::Points {
                positions: at,
                radii,
                colors: vec![CONTACT_FILL],
                labels: vec![],
            },
        ));
        out.push(Entry::new(
            "hands/robot/tangential",
            Visual::Arrows {
                origins,
                vectors,
                color: TANGENTIAL_COLOR,
            },
        ));
    }
}

/// The drawn radius of a contact with `normal_n` newtons.
pub fn contact_radius(normal_n: f32) -> f32 {
    (CONTACT_RADIUS_MIN + normal_n.max(0.0) * CONTACT_RADIUS_PER_N).min(CONTACT_RADIUS_MAX)
}

/// Whether a hand message uses the Revo2's six-joint layout.
fn is_revo2_layout(model: u8, joint_count: u8) -> bool {
    (model == hand_model::REVO2 || model == hand_model::UNKNOWN) && joint_count >= 6
}

fn revo2_position_series(q: &[f32; 6], which: &str, out: &mut Vec<Entry>) {
    for (i, f) in FINGERS.iter().enumerate() {
        out.push(Entry::scalar(
            position_path(f, which),
            f64::from(q[REVO2_JOINT_OF_FINGER[i]]),
        ));
    }
    out.push(Entry::scalar(
        position_path("thumb_rotation", which),
        f64::from(q[REVO2_THUMB_ABDUCT]),
    ));
}

fn skeleton_entries(who: &str, s: &Skeleton, color: Rgba, out: &mut Vec<Entry>) {
    out.push(Entry::new(
        format!("hands/{who}/bones"),
        Visual::Strips {
            strips: s
                .strips()
                .into_iter()
                .map(|strip| strip.into_iter().map(arr).collect())
                .collect(),
            radius: 0.0025,
            color,
        },
    ));
    out.push(Entry::new(
        format!("hands/{who}/joints"),
        Visual::Points {
            positions: s.joints().into_iter().map(arr).collect(),
            radii: vec![0.004],
            colors: vec![color],
            labels: vec![],
        },
    ));
    out.push(Entry::new(
        format!("hands/{who}/tips"),
        Visual::Points {
            positions: s.tips().into_iter().map(arr).collect(),
            radii: vec![0.006],
            colors: FINGER_COLORS.to_vec(),
            labels: vec![],
        },
    ));
}

fn glove_force(m: &GloveForceCommand, visuals: bool, out: &mut Vec<Entry>) {
    if m.header.origin_ns != 0 && m.header.stamp_ns >= m.header.origin_ns {
        out.push(Entry::scalar(
            "latency/feedback",
            ms(m.header.stamp_ns - m.header.origin_ns),
        ));
    }
    let force: [f32; 5] = core::array::from_fn(|i| f32::from(m.force[GLOVE_CHANNEL_OF_FINGER[i]]));
    for (f, value) in FINGERS.iter().zip(force) {
        out.push(Entry::scalar(
            force_path(f, "glove_command"),
            f64::from(value),
        ));
    }
    out.push(Entry::scalar(
        "health/feedback/estop",
        f64::from(m.flags & teleop_msgs::force_flags::ESTOP != 0),
    ));
    if visuals {
        out.push(Entry::new(
            "bars/glove_force",
            Visual::Bars {
                values: force.to_vec(),
                color: GLOVE_BAR_COLOR,
            },
        ));
    }
}

fn glove_diagnostics(m: &GloveDiagnostics, out: &mut Vec<Entry>) {
    for (i, f) in FINGERS.iter().enumerate() {
        let ch = GLOVE_CHANNEL_OF_FINGER[i];
        out.push(Entry::scalar(
            format!("diagnostics/glove/temperature_c/{f}"),
            f64::from(m.temperature_c[ch]),
        ));
        out.push(Entry::scalar(
            format!("diagnostics/glove/current_ma/{f}"),
            f64::from(m.current_ma[ch]),
        ));
    }
    let errors = m.error_bits.iter().filter(|b| **b != 0).count();
    out.push(Entry::scalar(
        "health/glove/actuators_in_error",
        errors as f64,
    ));
}

fn node_health(m: &NodeHealth, out: &mut Vec<Entry>) {
    let node = path_part(&m.name());
    for (what, value) in [
        ("timeouts", m.timeouts),
        ("errors", m.errors),
        ("dropped", m.dropped),
    ] {
        out.push(Entry::scalar(
            format!("health/nodes/{node}/{what}"),
            value as f64,
        ));
    }
}

fn device_info(m: &DeviceInfo, out: &mut Vec<Entry>) {
    let kind = match m.kind {
        device_kind::GLOVE => "glove",
        device_kind::REVO2 => "revo2",
        _ => "other",
    };
    let mut text = format!("**{}** (id {})\n", text_of(&m.model), m.id);
    for (name, field) in [
        ("firmware", &m.firmware_a),
        ("firmware 2", &m.firmware_b),
        ("serial", &m.serial_a),
        ("serial 2", &m.serial_b),
    ] {
        let value = text_of(field);
        if !value.is_empty() {
            text.push_str(&format!("\n- {name}: {value}"));
        }
    }
    out.push(Entry::new(
        format!("devices/{kind}"),
        Visual::Markdown(text),
    ));
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_msgs::{Fingertip, SampleHeader};

    fn header(seq: u64, stamp_ns: u64) -> SampleHeader {
        SampleHeader {
            seq,
            stamp_ns,
            origin_ns: stamp_ns,
            source_id: 7,
            reserved: 0,
        }
    }

    #[test]
    fn decimation_per_topic_and_source() {
        let mut d = Decimator::new(100.0);
        let ms = 1_000_000;
        let admitted = (0..1000)
            .filter(|i| d.admit("hand/state", 1, 5_000 * ms + i * ms))
            .count();
        assert_eq!(admitted, 100, "1 kHz for 1 s at <= 100 Hz");
        // Another publisher of the same topic is gated on its own.
        assert!(d.admit("hand/state", 2, 5_000 * ms));
        // A stamp going back (restarted publisher) starts over.
        assert!(d.admit("hand/state", 1, ms));
        assert!(Decimator::new(0.0).admit("x", 0, 1) && Decimator::new(0.0).admit("x", 0, 1));
    }

    #[test]
    fn glove_state_becomes_closures_and_an_operator_pose() {
        let mut scene = Scene::new(SceneConfig {
            time_origin_ns: 1_000,
            ..SceneConfig::default()
        });
        let mut m = GloveState {
            header: header(1, 11_000),
            link_up: 1,
            errors: 3,
            ..Default::default()
        };
        // little, ring, middle, index, thumb, thumb rotation (1 = open / outermost)
        m.position = [1.0, 0.75, 0.5, 0.25, 0.0, 1.0];
        let frame = scene.frame(&Sample::GloveState(m), 21_000).unwrap();
        assert_eq!(
            (frame.recording_time_ns, frame.sample_time_ns),
            (20_000, 10_000)
        );
        let expect = [
            ("thumb", 1.0),
            ("index", 0.75),
            ("middle", 0.5),
            ("ring", 0.25),
            ("little", 0.0),
            ("thumb_rotation", 0.0),
        ];
        for (f, v) in expect {
            assert_eq!(
                frame.get(&position_path(f, "glove")),
                Some(&Visual::Scalar(v)),
                "{f}"
            );
        }
        assert_eq!(frame.get("health/glove/errors"), Some(&Visual::Scalar(3.0)));
        assert_eq!(
            frame.get("latency/delivery/glove_state"),
            Some(&Visual::Scalar(0.01))
        );
        let Some(Visual::Points { positions, .. }) = frame.get("hands/operator/tips") else {
            panic!("no tips");
        };
        let tips = scene.operator_pose(&m.position).tips().map(arr);
        assert_eq!(positions.as_slice(), tips.as_slice());
        // The little finger is straight out, the thumb curled.
        let little_base = scene.operator_model().fingers[3].base;
        assert!((positions[4][2] - little_base.z).abs() < 1e-6);
        assert!(positions[0][2] < scene.operator_model().thumb.base.z);
    }

    #[test]
    fn tactile_becomes_bars_contacts_and_arrows() {
        let mut scene = Scene::new(SceneConfig::default());
        let mut m = Tactile {
            header: header(1, 1_000),
            hand_model: hand_model::REVO2,
            fingertip_count: 5,
            ..Default::default()
        };
        m.fingertips[0] = Fingertip {
            normal_n: 2.0,
            tangential_n: 1.0,
            direction_deg: 0.0,
            direction_valid: 1,
            ..Default::default()
        };
        m.fingertips[1].normal_n = 4.0;
        m.fingertips[2].normal_n = 9.0;
        m.fingertips[2].status = teleop_msgs::touch_status::INVALID;
        let frame = scene.frame(&Sample::Tactile(m), 1_000).unwrap();
        assert_eq!(
            frame.get("bars/tactile_normal"),
            Some(&Visual::Bars {
                values: vec![2.0, 4.0, 0.0, 0.0, 0.0],
                color: TACTILE_BAR_COLOR
            })
        );
        assert_eq!(
            frame.get("fingers/index/force/tactile_normal"),
            Some(&Visual::Scalar(4.0))
        );
        assert_eq!(
            frame.get("fingers/middle/force/tactile_normal"),
            None,
            "invalid sensor"
        );
        let Some(Visual::Points {
            positions, radii, ..
        }) = frame.get("hands/robot/contacts")
        else {
            panic!("no contacts");
        };
        let open = scene.robot_model().pose(&[0.0; 6]).tips().map(arr);
        assert_eq!(positions, &vec![open[0], open[1]]);
        assert_eq!(radii, &vec![contact_radius(2.0), contact_radius(4.0)]);
        assert!((radii[1] - (0.007 + 4.0 * 0.003)).abs() < 1e-6);
        let Some(Visual::Arrows {
            origins, vectors, ..
        }) = frame.get("hands/robot/tangential")
        else {
            panic!("no arrows");
        };
        assert_eq!(origins, &vec![open[0]]);
        // 0 degrees: along the distal phalanx, 1 N long.
        let along = scene.robot_model().pose(&[0.0; 6]).tip_directions()[0];
        assert!(Vec3::from(vectors[0]).abs_diff_eq(along * TANGENTIAL_M_PER_N, 1e-6));
    }

    #[test]
    fn hand_state_moves_the_robot_and_the_contacts() {
        let mut scene = Scene::new(SceneConfig::default());
        let mut s = HandState {
            header: header(1, 1_000),
            hand_model: hand_model::REVO2,
            joint_count: 6,
            link_up: 1,
            link_errors: 4,
            ..Default::default()
        };
        for (j, q) in [0.1, 0.2, 0.3, 0.4, 0.5, 0.6].into_iter().enumerate() {
            s.joints[j].position = q;
        }
        let frame = scene.frame(&Sample::HandState(s), 2_000).unwrap();
        assert_eq!(
            frame.get("fingers/little/position/measured"),
            Some(&Visual::Scalar(f64::from(0.6f32)))
        );
        assert_eq!(
            frame.get("fingers/thumb_rotation/position/measured"),
            Some(&Visual::Scalar(f64::from(0.2f32)))
        );
        assert_eq!(
            frame.get("health/hand/link_errors"),
            Some(&Visual::Scalar(4.0))
        );
        let posed = scene.robot_model().pose(&[0.1, 0.2, 0.3, 0.4, 0.5, 0.6]);
        let Some(Visual::Points { positions, .. }) = frame.get("hands/robot/tips") else {
            panic!("no tips");
        };
        assert_eq!(positions, &posed.tips().map(arr).to_vec());
        let mut t = Tactile {
            header: header(1, 5_000),
            fingertip_count: 5,
            ..Default::default()
        };
        t.fingertips[4].normal_n = 1.0;
        let frame = scene.frame(&Sample::Tactile(t), 5_000).unwrap();
        let Some(Visual::Points { positions, .. }) = frame.get("hands/robot/contacts") else {
            panic!("no contacts");
        };
        assert_eq!(positions, &vec![arr(posed.tips()[4])]);
    }

    #[test]
    fn commands_health_and_latency() {
        let mut scene = Scene::new(SceneConfig::default());
        let mut c = HandCommand {
            header: SampleHeader {
                seq: 1,
                stamp_ns: 3_500_000,
                origin_ns: 1_000_000,
                source_id: 1,
                reserved: 0,
            },
            hand_model: hand_model::REVO2,
            joint_count: 6,
            control_mode: control_mode::POSITION,
            ..Default::default()
        };
        c.joints[2].target = 0.5;
        let frame = scene.frame(&Sample::HandCommand(c), 4_000_000).unwrap();
        assert_eq!(frame.get("latency/retarget"), Some(&Visual::Scalar(2.5)));
        assert_eq!(
            frame.get("latency/delivery/hand_command"),
            Some(&Visual::Scalar(0.5))
        );
        assert_eq!(
            frame.get("fingers/index/position/command"),
            Some(&Visual::Scalar(0.5))
        );

        let mut h = NodeHealth {
            header: header(1, 10),
            timeouts: 2,
            errors: 5,
            dropped: 9,
            ..Default::default()
        };
        h.set_name("revo2 node");
        let frame = scene.frame(&Sample::Health(h), 10).unwrap();
        assert_eq!(
            frame.get("health/nodes/revo2_node/timeouts"),
            Some(&Visual::Scalar(2.0))
        );
        assert_eq!(
            frame.get("health/nodes/revo2_node/errors"),
            Some(&Visual::Scalar(5.0))
        );
        assert_eq!(
            frame.get("health/nodes/revo2_node/dropped"),
            Some(&Visual::Scalar(9.0))
        );

        let mut f = GloveForceCommand {
            header: header(1, 10),
            ..Default::default()
        };
        f.force = [1, 2, 3, 4, 5]; // little .. thumb
        let frame = scene.frame(&Sample::GloveForceCommand(f), 10).unwrap();
        assert_eq!(
            frame.get("bars/glove_force"),
            Some(&Visual::Bars {
                values: vec![5.0, 4.0, 3.0, 2.0, 1.0],
                color: GLOVE_BAR_COLOR
            })
        );
        assert_eq!(
            frame.get("fingers/thumb/force/glove_command"),
            Some(&Visual::Scalar(5.0))
        );
    }

    #[test]
    fn static_entries_name_every_series() {
        let scene = Scene::new(SceneConfig::default());
        let stat = scene.static_entries();
        for f in POSITION_SERIES {
            for which in ["glove", "command", "measured"] {
                let path = position_path(f, which);
                assert!(stat.iter().any(|e| e.path == path), "{path}");
            }
        }
        assert!(stat
            .iter()
            .any(|e| e.path == "hands" && e.visual == Visual::ZUp));
    }
}
