//! What the viewer shows, independent of rerun: each [`Sample`] becomes a [`Frame`] of
//! [`Entry`]s (an entity path and a plain value to draw there), on two timelines.
//!
//! [`Scene`] keeps what a sample alone does not carry (the robot hand's model and latest pose,
//! where the fingertip contacts are drawn) and decimates: per topic and publisher, scalars at
//! most at [`SceneConfig::scalar_hz`], 3D poses and bar charts at most at
//! [`SceneConfig::pose_hz`] (by the samples' own stamps, so a recording and the live pipeline
//! give the same picture).
//!
//! The robot hand is whichever hand profile the scene is given ([`RobotHand`]); without one, the
//! first hand sample (`hand/command`, `hand/state` or `hand/tactile`) with a known `hand_model`
//! picks the builtin profile of that model, and its frame carries the hand's timeless entries
//! ([`Frame::statics`]) and the layout for it ([`Frame::layout`]). Hand samples of another
//! model, or with another joint or fingertip count than the profile, are not drawn (with one
//! warning each).
//!
//! Entity paths (`{c}` a glove channel of [`GLOVE_CHANNELS`], `{g}` a glove finger of
//! [`FINGERS`]; `{f}`, `{j}` and `{t}` a finger, joint and fingertip of the robot's profile):
//! - `hands/operator/{bones,joints,tips}`: the operator's hand from the glove
//!   ([`OperatorHand`]); `hands/robot/{bones,joints,tips}`: the robot hand from its joint state;
//!   `hands/robot/contacts`: fingertips in contact, radius growing with the normal force;
//!   `hands/robot/tangential`: tangential force arrows.
//! - `glove/position/{c}`: the glove's closure 0 (open) .. 1 (closed), `1 - position`.
//! - `robot/{f}/{j}/{command,measured}`: the joint's normalised position 0 (its `open` angle)
//!   .. 1 (its `closed` angle), commanded and measured.
//! - `robot/{t}/tactile/{normal_n,pressure}`: the fingertip's normal force (N; force sensors)
//!   or raw pressure (pressure sensors); `glove/force/{g}`: the glove force command.
//! - `bars/{tactile,glove_force}`: the current values, fingertips in `hand/tactile` order and
//!   glove fingers thumb .. little.
//! - `health/...`: link and node counters; `latency/...`: milliseconds from the headers.
//! - `diagnostics/glove/...`, `devices/{glove,revo2,other,hand_profile}`.

use std::collections::{HashMap, HashSet};

use glam::Vec3;
use teleop_hand_profile::TipSensor;
use teleop_msgs::{
    control_mode, device_model, episode_event, episode_outcome, units, DeviceInfo, Episode,
    GloveDiagnostics, GloveForceCommand, GloveState, HandCommand, HandState, Message, NodeHealth,
    Tactile, GLOVE_CHANNELS,
};

use crate::kinematics::{
    OperatorHand, OperatorPose, RobotHand, Skeleton, FINGERS, GLOVE_CHANNEL_OF_FINGER,
    GLOVE_THUMB_ROTATION,
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

/// A colour per finger: the glove's fingers in [`FINGERS`] order, the robot's in its
/// profile's order (repeating after five).
pub const FINGER_COLORS: [Rgba; 5] = [
    [230, 80, 60, 255],
    [240, 160, 40, 255],
    [90, 180, 70, 255],
    [60, 130, 220, 255],
    [160, 90, 200, 255],
];
/// A colour per glove channel ([`GLOVE_CHANNELS`] order): shades of the glove's blue.
const GLOVE_CHANNEL_COLORS: [Rgba; 6] = [
    [60, 110, 200, 255],
    [80, 140, 230, 255],
    [100, 170, 240, 255],
    [60, 190, 220, 255],
    [120, 200, 250, 255],
    [40, 90, 160, 255],
];
/// A colour per joint of one robot finger (repeating): measured in full, commanded paler.
const JOINT_COLORS: [Rgba; 5] = [
    [240, 150, 40, 255],
    [60, 170, 90, 255],
    [200, 70, 160, 255],
    [150, 110, 60, 255],
    [90, 90, 200, 255],
];
const COMMAND_ALPHA: u8 = 130;
const GLOVE_COLOR: Rgba = [90, 160, 230, 255];
const COMMAND_COLOR: Rgba = [240, 150, 40, 255];
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
    /// Timeless entries this sample made known (the robot hand's, when it picked the profile).
    pub statics: Vec<Entry>,
    /// What to log.
    pub entries: Vec<Entry>,
    /// The layout to show from now on (when this sample picked the robot hand's profile).
    pub layout: Option<Layout>,
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

/// A time series view of the layout: its title and the entity paths it shows.
#[derive(Debug, Clone, PartialEq)]
pub struct Plot {
    /// Title.
    pub title: String,
    /// Entity paths (a trailing `/**` takes the subtree).
    pub contents: Vec<String>,
}

/// What the default layout (`layout::default_blueprint`) shows that depends on the robot hand.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Title of the 3D view.
    pub hands_title: String,
    /// The closure plots: per robot finger its joints (commanded and measured) and the glove
    /// channels that drive them; the glove's channels alone while no robot hand is known.
    pub closures: Vec<Plot>,
    /// The tactile views (bar chart title, time series), `None` without fingertip sensors.
    pub tactile: Option<(String, Plot)>,
}

/// What a fingertip sensor measures, as the viewer shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TactileQuantity {
    /// Normal force in newtons (`Fingertip::normal_n`): drawn as contacts too.
    NormalForce,
    /// Raw pressure (`Fingertip::pressure`).
    Pressure,
}

impl TactileQuantity {
    fn of(sensor: TipSensor) -> Self {
        match sensor {
            TipSensor::Revo2 | TipSensor::None => Self::NormalForce,
            TipSensor::Pst | TipSensor::Biotac => Self::Pressure,
        }
    }

    /// Its entity path part.
    pub fn name(self) -> &'static str {
        match self {
            Self::NormalForce => "normal_n",
            Self::Pressure => "pressure",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Self::NormalForce => "normal force (N)",
            Self::Pressure => "pressure (raw)",
        }
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

/// The robot hand of a scene: its model, latest pose and the paths of its series.
#[derive(Debug, Clone)]
struct Robot {
    hand: RobotHand,
    /// The latest measured pose (open until a hand state arrives).
    pose: Skeleton,
    /// Per joint: the paths of its commanded and measured series.
    joint_paths: Vec<[String; 2]>,
    /// Per fingertip (`hand/tactile` order): what it measures and the path of its series.
    tips: Vec<(TactileQuantity, String)>,
}

impl Robot {
    fn new(hand: RobotHand) -> Self {
        let profile = hand.profile();
        let joint_paths = profile
            .joints
            .iter()
            .map(|j| {
                let finger = &profile.fingers[j.finger].name;
                ["command", "measured"].map(|w| joint_path(finger, &j.name, w))
            })
            .collect();
        let tips = hand
            .tip_fingers()
            .iter()
            .map(|&f| {
                let finger = &profile.fingers[f];
                let q = TactileQuantity::of(finger.tip_sensor);
                (q, tactile_path(&finger.name, q))
            })
            .collect();
        let pose = hand.pose(&hand.open_angles());
        Self {
            hand,
            pose,
            joint_paths,
            tips,
        }
    }

    /// The radians and the normalised positions of a sample's joint values in `unit`
    /// (`None` for a unit the contract does not define).
    fn convert(&self, values: &[f32], unit: u8) -> Option<(Vec<f32>, Vec<f32>)> {
        let joints = &self.hand.profile().joints;
        let pairs = values.iter().zip(joints).map(|(&v, j)| match unit {
            units::NORMALISED => Some((j.radians(v), v)),
            units::PHYSICAL => Some((v, j.normalised(v))),
            _ => None,
        });
        pairs
            .collect::<Option<Vec<_>>>()
            .map(|p| p.into_iter().unzip())
    }

    /// The normalised positions as the `which` series (0 command, 1 measured); NaN is left out.
    fn series(&self, normalised: &[f32], which: usize, out: &mut Vec<Entry>) {
        for (q, paths) in normalised.iter().zip(&self.joint_paths) {
            if q.is_finite() {
                out.push(Entry::scalar(paths[which].clone(), f64::from(*q)));
            }
        }
    }
}

/// The viewer's content: turns samples into frames.
#[derive(Debug, Clone)]
pub struct Scene {
    config: SceneConfig,
    operator: OperatorHand,
    robot: Option<Robot>,
    scalars: Decimator,
    poses: Decimator,
    /// Problems already warned about (once each).
    warned: HashSet<String>,
}

fn arr(v: Vec3) -> [f32; 3] {
    v.to_array()
}

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

/// An entity path part from a name: letters, digits, `_` and `-`; anything else `_`.
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

/// The path of a glove channel's closure ([`GLOVE_CHANNELS`] name).
pub fn glove_position_path(channel: &str) -> String {
    format!("glove/position/{channel}")
}

/// The path of a glove finger's force command ([`FINGERS`] name).
pub fn glove_force_path(finger: &str) -> String {
    format!("glove/force/{finger}")
}

/// The path of a robot joint's normalised position, `which` = `command` or `measured`.
pub fn joint_path(finger: &str, joint: &str, which: &str) -> String {
    format!("robot/{}/{}/{which}", path_part(finger), path_part(joint))
}

/// The path of a robot fingertip's tactile series.
pub fn tactile_path(finger: &str, quantity: TactileQuantity) -> String {
    format!("robot/{}/tactile/{}", path_part(finger), quantity.name())
}

fn series(path: String, name: &str, color: Rgba) -> Entry {
    Entry::new(
        path,
        Visual::Series {
            name: name.to_string(),
            color,
        },
    )
}

/// Which count of a hand sample must match the profile.
#[derive(Debug, Clone, Copy)]
enum Count {
    Joints(u8),
    Fingertips(u8),
}

impl Scene {
    /// A scene drawing `robot`, or (`None`) the builtin profile of the first hand sample's
    /// model.
    pub fn new(config: SceneConfig, robot: Option<RobotHand>) -> Self {
        Self {
            config,
            operator: OperatorHand::default(),
            robot: robot.map(Robot::new),
            scalars: Decimator::new(config.scalar_hz),
            poses: Decimator::new(config.pose_hz),
            warned: HashSet::new(),
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

    /// The robot hand model, once known.
    pub fn robot_model(&self) -> Option<&RobotHand> {
        self.robot.as_ref().map(|r| &r.hand)
    }

    fn time(&self, ns: u64) -> i64 {
        ns as i64 - self.config.time_origin_ns as i64
    }

    /// What is logged once, timeless: the coordinate convention, where each hand sits, and
    /// the name and colour of every time series (the robot hand's once it is known).
    pub fn static_entries(&self) -> Vec<Entry> {
        let mut out = vec![
            Entry::new("hands", Visual::ZUp),
            Entry::new("hands/operator", Visual::Translation(OPERATOR_PLACEMENT)),
            Entry::new("hands/robot", Visual::Translation(ROBOT_PLACEMENT)),
            label("operator", "operator (glove)", OPERATOR_COLOR),
        ];
        for (i, c) in GLOVE_CHANNELS.iter().enumerate() {
            out.push(series(
                glove_position_path(c),
                &format!("glove {} (1 - position)", c.replace('_', " ")),
                GLOVE_CHANNEL_COLORS[i],
            ));
        }
        for (f, color) in FINGERS.iter().zip(FINGER_COLORS) {
            out.push(series(glove_force_path(f), f, color));
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
        out.extend(self.robot_static_entries());
        out
    }

    /// The robot hand's timeless entries: its label, profile and series.
    fn robot_static_entries(&self) -> Vec<Entry> {
        let Some(robot) = &self.robot else {
            return vec![];
        };
        let profile = robot.hand.profile();
        let mut out = vec![
            label("robot", &format!("robot ({})", profile.model), ROBOT_COLOR),
            Entry::new(
                "devices/hand_profile",
                Visual::Markdown(format!(
                    "**{}** (`{}`, hand model {})\n\n- profile: {}\n- joints: {}\n- fingers: {}",
                    profile.model,
                    profile.name,
                    profile.model_id,
                    robot.hand.source(),
                    profile.joint_names().collect::<Vec<_>>().join(", "),
                    profile
                        .fingers
                        .iter()
                        .map(|f| f.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                )),
            ),
        ];
        let mut in_finger = vec![0usize; profile.fingers.len()];
        for (j, paths) in profile.joints.iter().zip(&robot.joint_paths) {
            let color = JOINT_COLORS[in_finger[j.finger] % JOINT_COLORS.len()];
            in_finger[j.finger] += 1;
            let [r, g, b, _] = color;
            out.push(series(
                paths[0].clone(),
                &format!("{} commanded", j.name),
                [r, g, b, COMMAND_ALPHA],
            ));
            out.push(series(
                paths[1].clone(),
                &format!("{} measured", j.name),
                color,
            ));
        }
        for (i, (&f, (_, path))) in robot.hand.tip_fingers().iter().zip(&robot.tips).enumerate() {
            out.push(series(
                path.clone(),
                &profile.fingers[f].name,
                FINGER_COLORS[i % FINGER_COLORS.len()],
            ));
        }
        out
    }

    /// What the default layout shows: the robot hand's closure and tactile plots once it is
    /// known, else the glove's closures.
    pub fn layout(&self) -> Layout {
        let Some(robot) = &self.robot else {
            return Layout {
                hands_title: "Hands: operator (left), robot (right)".into(),
                closures: vec![Plot {
                    title: "glove closure".into(),
                    contents: vec!["glove/position/**".into()],
                }],
                tactile: None,
            };
        };
        let profile = robot.hand.profile();
        let closures = profile
            .fingers
            .iter()
            .enumerate()
            .map(|(f, finger)| {
                let joints = profile.joints.iter().filter(|j| j.finger == f);
                let mut channels: Vec<usize> = joints
                    .flat_map(|j| j.glove.channels.iter().map(|(c, _)| *c))
                    .collect();
                channels.sort_unstable();
                channels.dedup();
                let mut contents = vec![format!("robot/{}/**", path_part(&finger.name))];
                contents.extend(
                    channels
                        .iter()
                        .filter_map(|&c| GLOVE_CHANNELS.get(c))
                        .map(|c| glove_position_path(c)),
                );
                Plot {
                    title: format!("{} closure", finger.name),
                    contents,
                }
            })
            .collect();
        let tactile = (!robot.tips.is_empty()).then(|| {
            let names: Vec<&str> = robot
                .hand
                .tip_fingers()
                .iter()
                .map(|&f| profile.fingers[f].name.as_str())
                .collect();
            let mut quantities: Vec<&str> = robot.tips.iter().map(|(q, _)| q.label()).collect();
            quantities.dedup();
            let quantity = quantities.join(", ");
            (
                format!("Tactile {quantity} now, {}", names.join(", ")),
                Plot {
                    title: format!("Tactile {quantity}"),
                    contents: robot.tips.iter().map(|(_, p)| p.clone()).collect(),
                },
            )
        });
        Layout {
            hands_title: format!("Hands: operator (left), {} (right)", profile.model),
            closures,
            tactile,
        }
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
        let had_robot = self.robot.is_some();
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
            Sample::EStopAck(m) => {
                entries.push(Entry::scalar("health/estop_ack", f64::from(m.engaged)));
            }
            Sample::Episode(m) => episode_mark(m, &mut entries),
        }
        let picked = !had_robot && self.robot.is_some();
        Some(Frame {
            recording_time_ns: self.time(received_ns),
            sample_time_ns: self.time(header.stamp_ns),
            statics: if picked {
                self.robot_static_entries()
            } else {
                vec![]
            },
            entries,
            layout: picked.then(|| self.layout()),
        })
    }

    /// The viewer's own drop counters at `now_ns` (both timelines at `now_ns`).
    pub fn viewer_stats(&self, now_ns: u64, queue_full: u64, missed: u64) -> Frame {
        Frame {
            recording_time_ns: self.time(now_ns),
            sample_time_ns: self.time(now_ns),
            statics: vec![],
            entries: vec![
                Entry::scalar("health/viewer/queue_full", queue_full as f64),
                Entry::scalar("health/viewer/missed", missed as f64),
            ],
            layout: None,
        }
    }

    /// The operator's pose drawn from glove positions.
    pub fn operator_pose(&self, position: &[f32; 6]) -> Skeleton {
        self.operator.pose(&OperatorPose::from_glove(position))
    }

    fn glove_state(&mut self, m: &GloveState, visuals: bool, out: &mut Vec<Entry>) {
        let pose = OperatorPose::from_glove(&m.position);
        for (i, &channel) in GLOVE_CHANNEL_OF_FINGER.iter().enumerate() {
            out.push(Entry::scalar(
                glove_position_path(GLOVE_CHANNELS[channel]),
                f64::from(pose.flexion[i]),
            ));
        }
        out.push(Entry::scalar(
            glove_position_path(GLOVE_CHANNELS[GLOVE_THUMB_ROTATION]),
            f64::from(pose.thumb_opposition),
        ));
        out.push(Entry::scalar("health/glove/errors", f64::from(m.errors)));
        out.push(Entry::scalar("health/glove/link_up", f64::from(m.link_up)));
        if visuals {
            let skeleton = self.operator.pose(&pose);
            skeleton_entries("operator", &skeleton, OPERATOR_COLOR, out);
        }
    }

    /// Warns once about `problem`.
    fn warn_once(&mut self, problem: String) {
        if self.warned.insert(problem.clone()) {
            tracing::warn!("{problem}");
        }
    }

    /// The robot hand a hand sample of `topic` is drawn on: picked by `model` when none is
    /// yet; `None` (with a warning, once) when there is no profile for the model, the sample
    /// is of another model, or its count differs from the profile's.
    fn robot_for(&mut self, topic: &str, model: u8, count: Count) -> Option<&mut Robot> {
        if self.robot.is_none() {
            match RobotHand::builtin_for_model(model) {
                Some(hand) => {
                    tracing::info!(
                        "drawing the robot hand with the builtin profile `{}` (hand_model {model} \
                         of {topic})",
                        hand.profile().name
                    );
                    self.robot = Some(Robot::new(hand));
                }
                None => {
                    self.warn_once(format!(
                        "{topic}: no builtin hand profile for hand_model {model}; not drawing \
                         the robot hand (give one with --profile FILE)"
                    ));
                    return None;
                }
            }
        }
        let profile = self.robot.as_ref()?.hand.profile();
        let (name, model_id) = (profile.name.clone(), profile.model_id);
        let (what, got, want) = match count {
            Count::Joints(n) => ("joints", n, profile.joints.len()),
            Count::Fingertips(n) => ("fingertips", n, profile.fingertips().count()),
        };
        if model != device_model::UNKNOWN && model != model_id {
            self.warn_once(format!(
                "{topic}: hand_model {model} is not the profile's ({name}, hand_model \
                 {model_id}); not drawn"
            ));
            return None;
        }
        if usize::from(got) != want {
            self.warn_once(format!(
                "{topic}: {got} {what}, but the profile `{name}` has {want}; not drawn"
            ));
            return None;
        }
        self.robot.as_mut()
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
        if !positional {
            return;
        }
        let targets: Vec<f32> = m.active_joints().iter().map(|j| j.target).collect();
        let Some((_, normalised)) =
            self.convert(HandCommand::TOPIC, m.hand_model, &targets, m.units)
        else {
            return;
        };
        if let Some(robot) = &self.robot {
            robot.series(&normalised, 0, out);
        }
    }

    /// The radians and normalised positions of a hand sample's joint values, on the robot
    /// hand `robot_for` picks (`None`: not drawn).
    fn convert(
        &mut self,
        topic: &str,
        model: u8,
        values: &[f32],
        unit: u8,
    ) -> Option<(Vec<f32>, Vec<f32>)> {
        let count = Count::Joints(u8::try_from(values.len()).unwrap_or(u8::MAX));
        let converted = self.robot_for(topic, model, count)?.convert(values, unit);
        if converted.is_none() {
            self.warn_once(format!("{topic}: unknown units {unit}; not drawn"));
        }
        converted
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
        let positions: Vec<f32> = m.active_joints().iter().map(|j| j.position).collect();
        let Some((radians, normalised)) =
            self.convert(HandState::TOPIC, m.hand_model, &positions, m.units)
        else {
            return;
        };
        let Some(robot) = &mut self.robot else {
            return;
        };
        robot.series(&normalised, 1, out);
        robot.pose = robot.hand.pose(&radians);
        if visuals {
            skeleton_entries("robot", &robot.pose, ROBOT_COLOR, out);
        }
    }

    fn tactile(&mut self, m: &Tactile, visuals: bool, out: &mut Vec<Entry>) {
        let Some(robot) = self.robot_for(
            Tactile::TOPIC,
            m.hand_model,
            Count::Fingertips(m.fingertip_count),
        ) else {
            return;
        };
        let tips = m.active_fingertips();
        if tips.is_empty() {
            return;
        }
        let values: Vec<Option<f32>> = tips
            .iter()
            .zip(&robot.tips)
            .map(|(tip, (quantity, _))| {
                let value = match quantity {
                    TactileQuantity::NormalForce => tip.normal_n,
                    TactileQuantity::Pressure => tip.pressure as f32,
                };
                (tip.is_valid() && value.is_finite()).then_some(value)
            })
            .collect();
        for (value, (_, path)) in values.iter().zip(&robot.tips) {
            if let Some(v) = value {
                out.push(Entry::scalar(path.clone(), f64::from(*v)));
            }
        }
        if !visuals {
            return;
        }
        out.push(Entry::new(
            "bars/tactile",
            Visual::Bars {
                values: values.iter().map(|v| v.unwrap_or(0.0)).collect(),
                color: TACTILE_BAR_COLOR,
            },
        ));
        let positions = robot.pose.tips();
        let directions = robot.pose.tip_directions();
        let (mut at, mut radii, mut origins, mut vectors) = (vec![], vec![], vec![], vec![]);
        for (i, tip) in tips.iter().enumerate() {
            if robot.tips[i].0 != TactileQuantity::NormalForce {
                continue;
            }
            let f = robot.hand.tip_fingers()[i];
            let normal = values[i].unwrap_or(0.0);
            if normal >= CONTACT_THRESHOLD_N {
                at.push(arr(positions[f]));
                radii.push(contact_radius(normal));
            }
            if tip.is_valid()
                && tip.direction_valid == 1
                && tip.tangential_n.is_finite()
                && tip.tangential_n > CONTACT_THRESHOLD_N
            {
                let along = directions[f];
                let side = along.cross(Vec3::Z).normalize_or(Vec3::X);
                let angle = tip.direction_deg.to_radians();
                let dir = along * angle.cos() + side * angle.sin();
                origins.push(arr(positions[f]));
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

/// A hand's label above it.
fn label(who: &str, text: &str, color: Rgba) -> Entry {
    Entry::new(
        format!("hands/{who}/label"),
        Visual::Points {
            positions: vec![[0.0, 0.1, 0.07]],
            radii: vec![0.002],
            colors: vec![color],
            labels: vec![text.to_string()],
        },
    )
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
    let tips = s.tips();
    out.push(Entry::new(
        format!("hands/{who}/tips"),
        Visual::Points {
            colors: (0..tips.len())
                .map(|i| FINGER_COLORS[i % FINGER_COLORS.len()])
                .collect(),
            positions: tips.into_iter().map(arr).collect(),
            radii: vec![0.006],
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
        out.push(Entry::scalar(glove_force_path(f), f64::from(value)));
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
    for (name, value) in m.details() {
        out.push(Entry::scalar(
            format!("health/nodes/{node}/{}", path_part(&name)),
            value,
        ));
    }
}

/// An operator's episode mark, as a line of text at the time it was made.
fn episode_mark(m: &Episode, out: &mut Vec<Entry>) {
    let text = match m.event {
        episode_event::START => format!("**episode started**: {}", m.task()),
        episode_event::STOP => format!("**episode stopped**: {}", episode_outcome::name(m.outcome)),
        episode_event::DISCARD => "**episode discarded**".to_string(),
        other => format!("episode mark {other}"),
    };
    out.push(Entry::new("episode", Visual::Markdown(text)));
}

fn device_info(m: &DeviceInfo, out: &mut Vec<Entry>) {
    let kind = device_model::name(m.device_model);
    let fields = m.named_fields();
    let model = fields
        .iter()
        .find(|(name, _)| *name == "model_name")
        .map_or("", |(_, value)| value.as_str());
    let mut text = format!("**{model}**\n");
    for (name, value) in fields.iter().filter(|(name, _)| *name != "model_name") {
        text.push_str(&format!("\n- {name}: {value}"));
    }
    out.push(Entry::new(
        format!("devices/{kind}"),
        Visual::Markdown(text),
    ));
}

#[cfg(test)]
mod tests {
    use super::*;
    use teleop_hand_profile::HandProfile;
    use teleop_msgs::{fingertip_sensor, Fingertip, JointCommand, SampleHeader};

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

    fn revo2() -> Option<RobotHand> {
        RobotHand::builtin_for_model(device_model::REVO2)
    }

    fn scene(robot: Option<RobotHand>) -> Scene {
        Scene::new(SceneConfig::default(), robot)
    }

    fn open_pose(scene: &Scene) -> Skeleton {
        let hand = scene.robot_model().expect("a robot hand");
        hand.pose(&hand.open_angles())
    }

    fn paths(frame: &Frame, prefix: &str) -> Vec<String> {
        frame
            .entries
            .iter()
            .filter(|e| e.path.starts_with(prefix))
            .map(|e| e.path.clone())
            .collect()
    }

    #[test]
    fn glove_state_becomes_closures_and_an_operator_pose() {
        let mut scene = Scene::new(
            SceneConfig {
                time_origin_ns: 1_000,
                ..SceneConfig::default()
            },
            None,
        );
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
        for (c, v) in expect {
            assert_eq!(
                frame.get(&glove_position_path(c)),
                Some(&Visual::Scalar(v)),
                "{c}"
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
        let tips: Vec<[f32; 3]> = scene
            .operator_pose(&m.position)
            .tips()
            .into_iter()
            .map(arr)
            .collect();
        assert_eq!(positions, &tips);
        // The little finger is straight out, the thumb curled.
        let little_base = scene.operator_model().fingers[3].base;
        assert!((positions[4][2] - little_base.z).abs() < 1e-6);
        assert!(positions[0][2] < scene.operator_model().thumb.base.z);
        // The glove alone picks no robot hand.
        assert!(scene.robot_model().is_none() && frame.layout.is_none());
    }

    #[test]
    fn tactile_becomes_bars_contacts_and_arrows() {
        let mut scene = scene(None);
        let mut m = Tactile {
            header: header(1, 1_000),
            hand_model: device_model::REVO2,
            fingertip_count: 5,
            ..Default::default()
        };
        m.fingertips[0] = Fingertip {
            normal_n: 2.0,
            tangential_n: 1.0,
            direction_deg: 0.0,
            direction_valid: 1,
            sensor_kind: fingertip_sensor::REVO2_FORCE,
            ..Default::default()
        };
        m.fingertips[1].normal_n = 4.0;
        m.fingertips[2].normal_n = 9.0;
        m.fingertips[2].status = teleop_msgs::touch_status::INVALID;
        let frame = scene.frame(&Sample::Tactile(m), 1_000).unwrap();
        // The Revo2 model id picked the Revo2 profile.
        assert_eq!(
            scene.robot_model().map(|r| r.profile().name.as_str()),
            Some("revo2")
        );
        assert_eq!(
            frame.get("bars/tactile"),
            Some(&Visual::Bars {
                values: vec![2.0, 4.0, 0.0, 0.0, 0.0],
                color: TACTILE_BAR_COLOR
            })
        );
        assert_eq!(
            frame.get("robot/index/tactile/normal_n"),
            Some(&Visual::Scalar(4.0))
        );
        assert_eq!(
            frame.get("robot/middle/tactile/normal_n"),
            None,
            "invalid sensor"
        );
        let Some(Visual::Points {
            positions, radii, ..
        }) = frame.get("hands/robot/contacts")
        else {
            panic!("no contacts");
        };
        let open = open_pose(&scene);
        let tips: Vec<[f32; 3]> = open.tips().into_iter().map(arr).collect();
        assert_eq!(positions, &vec![tips[0], tips[1]]);
        assert_eq!(radii, &vec![contact_radius(2.0), contact_radius(4.0)]);
        assert!((radii[1] - (0.007 + 4.0 * 0.003)).abs() < 1e-6);
        let Some(Visual::Arrows {
            origins, vectors, ..
        }) = frame.get("hands/robot/tangential")
        else {
            panic!("no arrows");
        };
        assert_eq!(origins, &vec![tips[0]]);
        // 0 degrees: along the distal phalanx, 1 N long.
        let along = open.tip_directions()[0];
        assert!(Vec3::from(vectors[0]).abs_diff_eq(along * TANGENTIAL_M_PER_N, 1e-6));
    }

    #[test]
    fn hand_state_moves_the_robot_and_the_contacts() {
        let mut scene = scene(revo2());
        let mut s = HandState {
            header: header(1, 1_000),
            hand_model: device_model::REVO2,
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
            frame.get("robot/pinky/pinky/measured"),
            Some(&Visual::Scalar(f64::from(0.6f32)))
        );
        assert_eq!(
            frame.get("robot/thumb/thumb_abduct/measured"),
            Some(&Visual::Scalar(f64::from(0.2f32)))
        );
        assert_eq!(
            frame.get("health/hand/link_errors"),
            Some(&Visual::Scalar(4.0))
        );
        // Given a profile, the first hand sample changes no layout.
        assert!(frame.layout.is_none() && frame.statics.is_empty());
        let hand = scene.robot_model().unwrap();
        let radians: Vec<f32> = hand
            .profile()
            .joints
            .iter()
            .zip([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
            .map(|(j, q)| j.radians(q))
            .collect();
        let posed = hand.pose(&radians);
        let Some(Visual::Points { positions, .. }) = frame.get("hands/robot/tips") else {
            panic!("no tips");
        };
        assert_eq!(
            positions,
            &posed.tips().into_iter().map(arr).collect::<Vec<_>>()
        );
        // The same pose in radians (physical units).
        let mut physical = s;
        physical.units = units::PHYSICAL;
        physical.header = header(2, 500_000_000);
        for (j, r) in radians.iter().enumerate() {
            physical.joints[j].position = *r;
        }
        let frame = scene.frame(&Sample::HandState(physical), 0).unwrap();
        let Some(Visual::Points {
            positions: again, ..
        }) = frame.get("hands/robot/tips")
        else {
            panic!("no tips");
        };
        for (a, b) in again.iter().zip(positions) {
            assert!(Vec3::from(*a).abs_diff_eq(Vec3::from(*b), 1e-6));
        }
        let Some(Visual::Scalar(pinky)) = frame.get("robot/pinky/pinky/measured") else {
            panic!("no pinky");
        };
        assert!((pinky - 0.6).abs() < 1e-6);
        // A tactile sample of an unknown model on a known hand: contacts at the posed tips.
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
    fn the_first_hand_sample_picks_the_builtin_profile_of_its_model() {
        let mut scene = scene(None);
        assert_eq!(
            scene.layout().closures.len(),
            1,
            "the glove's closures only"
        );
        // An Allegro command in radians: 16 joints.
        let allegro = HandProfile::builtin("allegro").unwrap();
        let mut c = HandCommand {
            header: header(1, 1_000),
            hand_model: device_model::ALLEGRO,
            joint_count: 16,
            control_mode: control_mode::POSITION,
            units: units::PHYSICAL,
            ..Default::default()
        };
        let index_1 = allegro.joint_index("index_1").unwrap();
        c.joints[index_1] = JointCommand {
            target: allegro.joints[index_1].radians(0.25),
            ..Default::default()
        };
        let frame = scene.frame(&Sample::HandCommand(c), 1_000).unwrap();
        let Some(Visual::Scalar(q)) = frame.get("robot/index/index_1/command") else {
            panic!("no index_1 command: {:?}", paths(&frame, "robot"));
        };
        assert!((q - 0.25).abs() < 1e-6);
        assert_eq!(paths(&frame, "robot/").len(), 16);
        // That frame carries the hand's series and the layout for it; later ones do not.
        let layout = frame.layout.expect("a layout");
        assert_eq!(layout.closures.len(), 4);
        assert_eq!(layout.closures[0].title, "index closure");
        assert_eq!(
            layout.closures[0].contents,
            vec![
                "robot/index/**".to_string(),
                "glove/position/index".to_string()
            ]
        );
        assert!(
            layout.tactile.is_none(),
            "the Allegro has no fingertip sensors"
        );
        assert!(layout.hands_title.contains("Allegro"));
        assert!(frame
            .statics
            .iter()
            .any(|e| e.path == "robot/thumb/thumb_3/measured"));
        assert!(frame.statics.iter().any(|e| e.path == "hands/robot/label"));
        c.header = header(2, 500_000_000);
        let next = scene.frame(&Sample::HandCommand(c), 0).unwrap();
        assert!(next.layout.is_none() && next.statics.is_empty());
        assert_eq!(
            scene.static_entries().len(),
            Scene::new(SceneConfig::default(), None)
                .static_entries()
                .len()
                + frame.statics.len()
        );
    }

    #[test]
    fn hand_samples_that_do_not_fit_the_profile_are_not_drawn() {
        let mut scene = scene(revo2());
        let mut s = HandState {
            header: header(1, 1_000),
            hand_model: device_model::ALLEGRO,
            joint_count: 16,
            link_errors: 2,
            ..Default::default()
        };
        let frame = scene.frame(&Sample::HandState(s), 1_000).unwrap();
        assert!(paths(&frame, "robot/").is_empty() && paths(&frame, "hands/").is_empty());
        assert_eq!(
            frame.get("health/hand/link_errors"),
            Some(&Visual::Scalar(2.0))
        );
        // The right model with the wrong joint count, or unknown units.
        s.hand_model = device_model::REVO2;
        s.joint_count = 5;
        s.header = header(2, 500_000_000);
        let frame = scene.frame(&Sample::HandState(s), 0).unwrap();
        assert!(paths(&frame, "robot/").is_empty());
        s.joint_count = 6;
        s.units = 7;
        s.header = header(3, 1_000_000_000);
        let frame = scene.frame(&Sample::HandState(s), 0).unwrap();
        assert!(paths(&frame, "robot/").is_empty());
        s.units = units::NORMALISED;
        s.header = header(4, 1_500_000_000);
        let frame = scene.frame(&Sample::HandState(s), 0).unwrap();
        assert_eq!(paths(&frame, "robot/").len(), 6);
        // No builtin profile for the model: nothing is picked.
        let mut unknown = scene_without_profile_after(device_model::UNKNOWN);
        assert!(unknown.robot_model().is_none());
        unknown = scene_without_profile_after(42);
        assert!(unknown.robot_model().is_none());
    }

    fn scene_without_profile_after(model: u8) -> Scene {
        let mut scene = scene(None);
        let s = HandState {
            header: header(1, 1_000),
            hand_model: model,
            joint_count: 6,
            ..Default::default()
        };
        let frame = scene.frame(&Sample::HandState(s), 1_000).unwrap();
        assert!(frame.layout.is_none() && paths(&frame, "robot/").is_empty());
        scene
    }

    #[test]
    fn pressure_fingertips_plot_pressure_without_contacts() {
        let shadow = RobotHand::builtin_for_model(device_model::SHADOW).unwrap();
        let mut scene = scene(Some(shadow));
        let layout = scene.layout();
        assert_eq!(layout.closures.len(), 6, "ff, mf, rf, lf, th and the wrist");
        let (bars, plot) = layout.tactile.expect("five PST sensors");
        assert!(
            bars.contains("pressure") && bars.contains("ff, mf, rf, lf, th"),
            "{bars}"
        );
        assert_eq!(plot.contents[0], "robot/ff/tactile/pressure");
        let mut t = Tactile {
            header: header(1, 1_000),
            hand_model: device_model::SHADOW,
            fingertip_count: 5,
            ..Default::default()
        };
        for (i, tip) in t.fingertips.iter_mut().enumerate() {
            *tip = Fingertip {
                normal_n: f32::NAN,
                pressure: 100 * i as i32,
                sensor_kind: fingertip_sensor::PST_PRESSURE,
                ..Default::default()
            };
        }
        let frame = scene.frame(&Sample::Tactile(t), 1_000).unwrap();
        assert_eq!(
            frame.get("robot/th/tactile/pressure"),
            Some(&Visual::Scalar(400.0))
        );
        assert_eq!(
            frame.get("bars/tactile"),
            Some(&Visual::Bars {
                values: vec![0.0, 100.0, 200.0, 300.0, 400.0],
                color: TACTILE_BAR_COLOR
            })
        );
        let Some(Visual::Points { positions, .. }) = frame.get("hands/robot/contacts") else {
            panic!("no contacts entry");
        };
        assert!(positions.is_empty(), "no force, no contact spheres");
    }

    #[test]
    fn commands_health_and_latency() {
        let mut scene = scene(revo2());
        let mut c = HandCommand {
            header: SampleHeader {
                seq: 1,
                stamp_ns: 3_500_000,
                origin_ns: 1_000_000,
                source_id: 1,
                reserved: 0,
            },
            hand_model: device_model::REVO2,
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
            frame.get("robot/index/index/command"),
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
        h.set_detail("rtt_ms", 0.5);
        let frame = scene.frame(&Sample::Health(h), 10).unwrap();
        assert_eq!(
            frame.get("health/nodes/revo2_node/rtt_ms"),
            Some(&Visual::Scalar(0.5))
        );
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

        // A device's identity by field name; what it lacks is left out.
        let device = DeviceInfo {
            header: header(1, 10),
            device_model: device_model::ALLEGRO,
            link_kind: teleop_msgs::link_kind::CAN,
            model_name: teleop_msgs::fixed_text("Wonik Allegro Hand v4"),
            protocol: teleop_msgs::fixed_text("v4"),
            link: teleop_msgs::fixed_text("slcan:/dev/ttyACM0"),
            ..Default::default()
        };
        let frame = scene.frame(&Sample::DeviceInfo(device), 10).unwrap();
        assert_eq!(
            frame.get("devices/allegro"),
            Some(&Visual::Markdown(
                "**Wonik Allegro Hand v4**\n\n- device_model: allegro\n- link_kind: can\n\
                 - bus_address: 0\n- protocol: v4\n- link: slcan:/dev/ttyACM0"
                    .to_string()
            ))
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
        assert_eq!(frame.get("glove/force/thumb"), Some(&Visual::Scalar(5.0)));
    }

    #[test]
    fn static_entries_name_every_series() {
        let scene = scene(revo2());
        let stat = scene.static_entries();
        let named = |path: &str| {
            stat.iter()
                .any(|e| e.path == path && matches!(e.visual, Visual::Series { .. }))
        };
        for c in GLOVE_CHANNELS {
            assert!(named(&glove_position_path(c)), "{c}");
        }
        let profile = scene.robot_model().unwrap().profile();
        for j in &profile.joints {
            let finger = &profile.fingers[j.finger].name;
            for which in ["command", "measured"] {
                let path = joint_path(finger, &j.name, which);
                assert!(named(&path), "{path}");
            }
        }
        for f in profile.fingertips() {
            let path = tactile_path(&f.name, TactileQuantity::NormalForce);
            assert!(named(&path), "{path}");
        }
        assert!(stat
            .iter()
            .any(|e| e.path == "hands" && e.visual == Visual::ZUp));
        // The Revo2's closure plots: its five fingers, each with the glove channels driving it.
        let layout = scene.layout();
        let titles: Vec<&str> = layout.closures.iter().map(|p| p.title.as_str()).collect();
        assert_eq!(
            titles,
            [
                "thumb closure",
                "index closure",
                "middle closure",
                "ring closure",
                "pinky closure"
            ]
        );
        assert_eq!(
            layout.closures[0].contents,
            [
                "robot/thumb/**",
                "glove/position/thumb",
                "glove/position/thumb_rotation"
            ]
        );
        assert_eq!(
            layout.closures[4].contents,
            ["robot/pinky/**", "glove/position/little"]
        );
    }
}
