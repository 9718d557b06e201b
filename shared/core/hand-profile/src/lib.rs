//! Robot hand profiles: what the pipeline needs to know about a hand, as data.
//!
//! # What this crate owns
//!
//! The [`HandProfile`] loaded from `config/hands/<hand>.toml`: the hand's joints in its own
//! order (name, finger, [`Role`], limits in radians, the open and closed angles that normalised
//! commands span, the linear map to device units, couplings such as the Shadow Hand's J1 that
//! follows J2), its fingers (which carry a fingertip sensor and of which kind, a kinematic
//! chain, the pad where the fingertip touches things and the operator's finger it follows), the
//! default glove → joint map, the fingertip-retargeting defaults, and per glove finger the
//! force-feedback source (a fingertip's tactile force and/or the effort / position error of named
//! joints). Retargeting, force feedback, the hand nodes, reprocessing and the viewer all read
//! the hand from here, so a new hand is a new file, not a new code path.
//!
//! Loading checks everything once; an error names the file, the line and the field
//! (`config/hands/allegro.toml:31: joint[4].limits: lower (1.2) must be below upper (0.3)`).
//! The four shipped profiles are also compiled in ([`HandProfile::builtin`]) for recordings
//! made before profiles existed.
//!
//! # What it must not depend on
//!
//! No iceoryx2, no message crate, no device protocol, no runtime: it is plain data read from
//! TOML, shared by pure libraries (`teleop-retarget`, `teleop-feedback`) and the nodes.
//!
//! # Conventions
//!
//! * Glove channels [`GLOVE_CHANNELS`] (`little, ring, middle, index, thumb, thumb_rotation`) and
//!   glove fingers [`GLOVE_FINGERS`] (the first five), as the EH55BF1 reports them.
//! * A joint's *normalised* value is 0 at its `open` angle and 1 at its `closed` angle (linear in
//!   between); `hand/command` carries normalised values when the profile's `command_units` is
//!   `normalised`, radians when it is `radians`.
//! * Device units: `device = offset + scale * radians`.
//! * Kinematics: metres and radians in the hand frame (x towards the little finger side of a
//!   right hand, y from the wrist towards the fingertips, z out of the back of the hand), each link
//!   rotating about its `axis` after translating by its `origin` from the previous link's frame.

mod error;
mod raw;
pub mod urdf;

use std::collections::BTreeMap;
use std::path::Path;

pub use error::ProfileError;

/// Glove position channels in the EH55BF1's order: the five fingers, then the thumb's rotation.
pub const GLOVE_CHANNELS: [&str; 6] = [
    "little",
    "ring",
    "middle",
    "index",
    "thumb",
    "thumb_rotation",
];
/// Glove fingers (force-feedback actuators) in the EH55BF1's order.
pub const GLOVE_FINGERS: [&str; 5] = ["little", "ring", "middle", "index", "thumb"];
/// Most joints a profile may have (the size of the contract's joint arrays; the Shadow Hand with
/// its wrist has 24).
pub const MAX_JOINTS: usize = 24;
/// Most fingertip sensors a profile may have (the size of the contract's fingertip array).
pub const MAX_FINGERTIPS: usize = 5;

/// What a joint does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Bends a finger towards the palm.
    Flex,
    /// Spreads a finger sideways.
    Abduct,
    /// Turns a finger (a thumb's opposition) about its own length.
    Rotate,
    /// Moves the wrist.
    Wrist,
}

/// The kind of sensor on a fingertip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TipSensor {
    /// No fingertip sensor.
    None,
    /// The Revo2's tactile sensor: normal and tangential force in newtons, proximity.
    Revo2,
    /// Shadow's PST pressure sensor (raw pressure and temperature).
    Pst,
    /// SynTouch BioTac.
    Biotac,
}

/// What the retargeting node publishes in `hand/command`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CommandUnits {
    /// 0 = the joint's `open` angle .. 1 = its `closed` angle.
    Normalised,
    /// Radians.
    Radians,
}

/// Linear map between radians and the device's own unit: `device = offset + scale * radians`.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceMap {
    /// The device's unit, for messages (`"permille"`, `"count"`, `"rad"`, ...).
    pub unit: String,
    /// Device units per radian (finite, non-zero).
    pub scale: f32,
    /// Device value at 0 rad.
    pub offset: f32,
}

/// How a joint follows the glove: `normalised = offset + Σ gain × closure(channel)`, where a
/// channel's closure is its calibrated value, 0 = open (thumb rotation: outermost) .. 1 = closed
/// (innermost). No channels makes the joint rest at `offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct GloveMap {
    /// `(channel index in GLOVE_CHANNELS, gain)` pairs.
    pub channels: Vec<(usize, f32)>,
    /// Added to the weighted sum.
    pub offset: f32,
}

/// A joint that is not driven on its own but follows another (the Shadow Hand's J1, moved by the
/// same tendon as J2): `angle = ratio × angle(to)`, clamped to this joint's limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coupling {
    /// Index of the joint it follows (which is itself not coupled).
    pub to: usize,
    /// Radians of this joint per radian of the other.
    pub ratio: f32,
}

/// One joint, in the hand's joint order.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// Unique name.
    pub name: String,
    /// Index of its finger in [`HandProfile::fingers`].
    pub finger: usize,
    /// What it does.
    pub role: Role,
    /// Lower limit, radians.
    pub lower: f32,
    /// Upper limit, radians (above `lower`).
    pub upper: f32,
    /// Angle at normalised 0 (within the limits).
    pub open: f32,
    /// Angle at normalised 1 (within the limits, not equal to `open`).
    pub closed: f32,
    /// Radians to device units.
    pub device: DeviceMap,
    /// The glove channels that drive it (empty for a coupled joint).
    pub glove: GloveMap,
    /// Set when the joint follows another.
    pub coupling: Option<Coupling>,
}

impl Joint {
    /// Radians of a normalised value (not clamped).
    pub fn radians(&self, normalised: f32) -> f32 {
        self.open + (self.closed - self.open) * normalised
    }

    /// Normalised value of an angle (not clamped).
    pub fn normalised(&self, radians: f32) -> f32 {
        (radians - self.open) / (self.closed - self.open)
    }

    /// `radians` clamped to the joint's limits (NaN becomes `open`).
    pub fn clamp(&self, radians: f32) -> f32 {
        if radians.is_nan() {
            self.open
        } else {
            radians.clamp(self.lower, self.upper)
        }
    }

    /// The device's value for an angle.
    pub fn to_device(&self, radians: f32) -> f32 {
        self.device.offset + self.device.scale * radians
    }

    /// The angle of a device value.
    pub fn from_device(&self, value: f32) -> f32 {
        (value - self.device.offset) / self.device.scale
    }
}

/// One link of a finger's kinematic chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link {
    /// The joint whose angle turns this link (`None`: fixed).
    pub joint: Option<usize>,
    /// Link angle per radian of that joint (1 for the joint itself; other values for links a
    /// linkage drives passively, such as the Revo2's distal phalanges).
    pub ratio: f32,
    /// Rotation axis in the link's frame (unit length).
    pub axis: [f32; 3],
    /// Translation from the previous link's frame (or the finger's base) to this joint, metres.
    pub origin: [f32; 3],
}

/// One finger.
#[derive(Debug, Clone, PartialEq)]
pub struct Finger {
    /// Unique name.
    pub name: String,
    /// Its fingertip sensor.
    pub tip_sensor: TipSensor,
    /// Base position in the hand frame, metres.
    pub base: [f32; 3],
    /// Base orientation (roll, pitch, yaw about x, y, z in that order), radians.
    pub base_rpy: [f32; 3],
    /// The chain from the base to the last joint.
    pub links: Vec<Link>,
    /// The fingertip in the last link's frame, metres.
    pub tip: [f32; 3],
    /// Centre of the fingertip's contact surface (its pad) in the last link's frame, metres
    /// (`tip` unless the profile says otherwise).
    pub pad: [f32; 3],
    /// Radius of the pad about [`pad`](Self::pad), metres: two pads touch when their centres are
    /// the sum of their radii apart.
    pub pad_radius: f32,
    /// The operator's finger it follows in fingertip retargeting ([`GLOVE_FINGERS`] index);
    /// `None` for a chain no operator finger drives (the Shadow Hand's wrist).
    pub operator: Option<usize>,
}

/// How glove motion becomes joint targets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RetargetMode {
    /// Each joint from the profile's glove map (per-joint, no kinematics).
    Joint,
    /// Fingertip optimisation: the robot's fingertip vectors (wrist to tip, tip to tip) follow the
    /// operator model's, scaled.
    Vector,
    /// As `vector`, with a pinch switch: a thumb-finger pair the operator closes is brought
    /// together until the robot's pads touch.
    Pinch,
}

impl RetargetMode {
    /// Every mode, in the order above.
    pub const ALL: [RetargetMode; 3] = [Self::Joint, Self::Vector, Self::Pinch];

    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Joint => "joint",
            Self::Vector => "vector",
            Self::Pinch => "pinch",
        }
    }

    /// The mode called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// The hand's fingertip-retargeting defaults (`[retarget]` in the profile).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RetargetDefaults {
    /// The mode a session uses unless its retargeting configuration says otherwise.
    pub mode: RetargetMode,
    /// Robot vector length per operator vector length (the hand's size over a human hand's).
    pub scaling: f32,
}

/// Where one glove finger's force feedback comes from.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FeedbackSource {
    /// Index into [`HandProfile::fingertips`] of the fingertip whose tactile force drives it.
    pub tactile: Option<usize>,
    /// Joints whose effort, current or position error estimate contact (when tactile is absent
    /// or invalid); the largest estimate wins.
    pub joints: Vec<usize>,
}

impl FeedbackSource {
    /// True when nothing drives this glove finger (a finger the hand does not have).
    pub fn is_none(&self) -> bool {
        self.tactile.is_none() && self.joints.is_empty()
    }
}

/// A checked hand profile.
#[derive(Debug, Clone, PartialEq)]
pub struct HandProfile {
    /// Short name (`revo2`, `allegro`, `shadow`, `leap`).
    pub name: String,
    /// Human-readable model.
    pub model: String,
    /// The contract's hand model id (`hand_model` fields).
    pub model_id: u8,
    /// What `hand/command` carries.
    pub command_units: CommandUnits,
    /// Joints in the hand's order (at most [`MAX_JOINTS`]).
    pub joints: Vec<Joint>,
    /// Fingers.
    pub fingers: Vec<Finger>,
    /// Per glove finger ([`GLOVE_FINGERS`] order).
    pub feedback: [FeedbackSource; 5],
    /// Fingertip-retargeting defaults.
    pub retarget: RetargetDefaults,
}

/// The metadata record in which the recorder embeds the hand profile of a session
/// (`teleop-recorder --metadata hand_profile=FILE`): fields `file` (its path) and `text`.
pub const RECORDING_METADATA: &str = "hand_profile";

/// The profiles shipped in `config/hands/`, compiled in: `(name, file name, text)`.
const BUILTIN: [(&str, &str, &str); 4] = [
    (
        "revo2",
        "config/hands/revo2.toml",
        include_str!("../../../../config/hands/revo2.toml"),
    ),
    (
        "allegro",
        "config/hands/allegro.toml",
        include_str!("../../../../config/hands/allegro.toml"),
    ),
    (
        "shadow",
        "config/hands/shadow.toml",
        include_str!("../../../../config/hands/shadow.toml"),
    ),
    (
        "leap",
        "config/hands/leap.toml",
        include_str!("../../../../config/hands/leap.toml"),
    ),
];

impl HandProfile {
    /// Reads and checks the profile at `path`.
    pub fn load(path: &Path) -> Result<Self, ProfileError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ProfileError::Read {
            origin: origin.clone(),
            reason: e.to_string(),
        })?;
        Self::from_toml_str(&text, &origin)
    }

    /// Parses and checks profile text; `origin` (the file path) starts every error message.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ProfileError> {
        raw::parse(text, origin)
    }

    /// A shipped profile by name (`revo2`, `allegro`, `shadow`, `leap`), as compiled into this
    /// binary.
    pub fn builtin(name: &str) -> Option<Self> {
        let (_, file, text) = BUILTIN.iter().find(|(n, _, _)| *n == name)?;
        // The shipped files are checked by this crate's tests; a broken one is reported by
        // `builtin_names` users as missing rather than by a panic.
        Self::from_toml_str(text, file).ok()
    }

    /// The shipped profile of a contract hand model id (`hand_model` fields), if there is one.
    pub fn builtin_for_model(model_id: u8) -> Option<Self> {
        Self::builtin_names()
            .filter_map(Self::builtin)
            .find(|p| p.model_id == model_id)
    }

    /// The profile embedded in a recording's metadata records (`(name, fields)` pairs) under
    /// [`RECORDING_METADATA`]; `None` when there is none (recordings made before profiles). Errors
    /// name the recording, the embedded file, the line and the field.
    pub fn from_recording_metadata<'a>(
        recording: &str,
        metadata: impl IntoIterator<Item = &'a (String, BTreeMap<String, String>)>,
    ) -> Option<Result<Self, ProfileError>> {
        let (_, fields) = metadata
            .into_iter()
            .find(|(name, _)| name == RECORDING_METADATA)?;
        let Some(text) = fields.get("text") else {
            return Some(Err(ProfileError::Read {
                origin: recording.to_string(),
                reason: format!("metadata `{RECORDING_METADATA}` has no `text` field"),
            }));
        };
        let origin = format!(
            "{recording} (metadata {RECORDING_METADATA}, from {})",
            fields.get("file").map_or("?", String::as_str)
        );
        Some(Self::from_toml_str(text, &origin))
    }

    /// Names of the shipped profiles.
    pub fn builtin_names() -> impl Iterator<Item = &'static str> {
        BUILTIN.iter().map(|(n, _, _)| *n)
    }

    /// Index of the joint called `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The fingers with a fingertip sensor, in finger order: the order of `hand/tactile`.
    pub fn fingertips(&self) -> impl Iterator<Item = &Finger> {
        self.fingers
            .iter()
            .filter(|f| f.tip_sensor != TipSensor::None)
    }

    /// Joint names in the hand's order.
    pub fn joint_names(&self) -> impl Iterator<Item = &str> {
        self.joints.iter().map(|j| j.name.as_str())
    }
}
