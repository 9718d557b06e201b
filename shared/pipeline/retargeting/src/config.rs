//! Retargeting parameters: mode, fingertip objective, filter, deadband, slew limit, per-joint curves
//! and limits.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use teleop_hand_profile::{HandProfile, RetargetMode};

use crate::error::{ConfigError, RETARGET_ORIGIN};

/// Largest accepted [`RetargetConfig::deadband`].
pub const MAX_DEADBAND: f32 = 0.2;

/// One Euro filter parameters (Casiez et al. 2012), in normalised units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OneEuroParams {
    /// Cutoff frequency at rest (Hz); lower = smoother but laggier. Default 1.5.
    pub min_cutoff_hz: f32,
    /// Speed coefficient: how fast the cutoff rises with speed (per normalised
    /// unit/s); higher = less lag during fast motion. Default 0.5. `0` makes a
    /// plain first-order low-pass at `min_cutoff_hz`.
    pub beta: f32,
    /// Cutoff frequency (Hz) of the derivative estimate. Default 1.0.
    pub d_cutoff_hz: f32,
}

impl Default for OneEuroParams {
    fn default() -> Self {
        OneEuroParams {
            min_cutoff_hz: 1.5,
            beta: 0.5,
            d_cutoff_hz: 1.0,
        }
    }
}

/// Response curve applied to a normalised joint value in `[0, 1]`.
///
/// TOML: `curve = { kind = "linear" }`, `curve = { kind = "gamma", gamma = 0.8 }`,
/// `curve = { kind = "piecewise", points = [[0, 0], [0.5, 0.3], [1, 1]] }`.
/// Every valid curve maps `[0, 1]` monotonically (non-decreasing) into `[0, 1]`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(from = "CurveToml", into = "CurveToml")]
pub enum Curve {
    /// Identity.
    #[default]
    Linear,
    /// `x.powf(gamma)`: `gamma < 1` makes the joint respond more at the start
    /// of the glove motion, `gamma > 1` less.
    Gamma {
        /// The exponent; finite and `> 0`.
        gamma: f32,
    },
    /// Linear interpolation through `[x, y]` points.
    Piecewise {
        /// At least two points; the first has `x = 0`, the last `x = 1`, `x`
        /// strictly increasing, `y` in `[0, 1]` and non-decreasing.
        points: Vec<[f32; 2]>,
    },
}

/// Serde mirror of [`Curve`]: `Linear {}` is a struct variant so that
/// unknown keys next to `kind = "linear"` are rejected too.
#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
enum CurveToml {
    Linear {},
    Gamma { gamma: f32 },
    Piecewise { points: Vec<[f32; 2]> },
}

impl From<CurveToml> for Curve {
    fn from(c: CurveToml) -> Self {
        match c {
            CurveToml::Linear {} => Curve::Linear,
            CurveToml::Gamma { gamma } => Curve::Gamma { gamma },
            CurveToml::Piecewise { points } => Curve::Piecewise { points },
        }
    }
}

impl From<Curve> for CurveToml {
    fn from(c: Curve) -> Self {
        match c {
            Curve::Linear => CurveToml::Linear {},
            Curve::Gamma { gamma } => CurveToml::Gamma { gamma },
            Curve::Piecewise { points } => CurveToml::Piecewise { points },
        }
    }
}

impl Curve {
    /// Applies the curve to `x` (clamped to `[0, 1]` first). The result is in
    /// `[0, 1]` for a valid curve; a non-finite result is mapped to 0.
    pub fn apply(&self, x: f32) -> f32 {
        let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
        let y = match self {
            Curve::Linear => x,
            Curve::Gamma { gamma } => x.powf(*gamma),
            Curve::Piecewise { points } => piecewise(points, x),
        };
        if y.is_finite() {
            y.clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    fn validate(&self, field: &str) -> Result<(), ConfigError> {
        let bad = |reason: String| Err(ConfigError::invalid(RETARGET_ORIGIN, field, reason));
        match self {
            Curve::Linear => Ok(()),
            Curve::Gamma { gamma } => {
                if gamma.is_finite() && *gamma > 0.0 {
                    Ok(())
                } else {
                    bad(format!("gamma ({gamma}) must be finite and > 0"))
                }
            }
            Curve::Piecewise { points } => {
                if points.len() < 2 {
                    return bad(format!(
                        "piecewise curve needs at least 2 points, got {}",
                        points.len()
                    ));
                }
                for (i, [x, y]) in points.iter().enumerate() {
                    if !x.is_finite() || !y.is_finite() {
                        return bad(format!("point {i} ([{x}, {y}]) is not finite"));
                    }
                    if !(0.0..=1.0).contains(y) {
                        return bad(format!("point {i} ([{x}, {y}]): y must be in [0, 1]"));
                    }
                }
                let first = points[0][0];
                let last = points[points.len() - 1][0];
                if first != 0.0 {
                    return bad(format!("the first point must have x = 0, got {first}"));
                }
                if last != 1.0 {
                    return bad(format!("the last point must have x = 1, got {last}"));
                }
                for (i, w) in points.windows(2).enumerate() {
                    let ([x0, y0], [x1, y1]) = (w[0], w[1]);
                    if x1 <= x0 {
                        return bad(format!(
                            "x must be strictly increasing: point {} has x = {x1} after x = {x0}",
                            i + 1
                        ));
                    }
                    if y1 < y0 {
                        return bad(format!(
                            "y must be non-decreasing (monotone map): point {} has y = {y1} after y = {y0}",
                            i + 1
                        ));
                    }
                }
                Ok(())
            }
        }
    }
}

fn piecewise(points: &[[f32; 2]], x: f32) -> f32 {
    let Some(&[x_first, y_first]) = points.first() else {
        return x;
    };
    if x <= x_first {
        return y_first;
    }
    for w in points.windows(2) {
        let ([x0, y0], [x1, y1]) = (w[0], w[1]);
        if x <= x1 {
            let span = x1 - x0;
            if span <= 0.0 {
                return y1;
            }
            let t = ((x - x0) / span).clamp(0.0, 1.0);
            // Convex combination: stays within [y0, y1].
            return (y0 + t * (y1 - y0)).clamp(y0.min(y1), y0.max(y1));
        }
    }
    points.last().map_or(x, |p| p[1])
}

/// Per-joint shaping and limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JointConfig {
    /// Response curve. Default linear.
    pub curve: Curve,
    /// Lower position limit (normalised). Default 0.0.
    pub min: f32,
    /// Upper position limit (normalised). Default 1.0.
    pub max: f32,
}

impl Default for JointConfig {
    fn default() -> Self {
        JointConfig {
            curve: Curve::Linear,
            min: 0.0,
            max: 1.0,
        }
    }
}

/// Fingertip retargeting (modes `vector` and `pinch`): the objective's parameters, defaults after
/// dex-retargeting's `DexPilotOptimizer` (0.5.0, `optimizer.py`): Huber loss on each vector's
/// error, a smoothness term towards the previous solution, and the pinch switch's distances.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FingertipConfig {
    /// Robot vector length per operator vector length; default: the hand profile's
    /// `[retarget] scaling`.
    pub scaling: Option<f32>,
    /// Huber loss: quadratic below this vector error, linear above, metres. Default 0.03.
    pub huber_delta: f32,
    /// Weight of the squared change from the previous solution, per rad². Default 0.004.
    pub smoothness: f32,
    /// Weight of the squared distance from the middle of each joint's range, per rad² (not in
    /// DexPilot: it makes the solution forget its history). Default 0.001.
    pub posture: f32,
    /// A thumb-finger pair is pinched when the operator's pads' centres come closer than this,
    /// metres. Default 0.03.
    pub pinch_engage: f32,
    /// ... and released when they are farther apart than this (hysteresis), metres. Default
    /// 0.05.
    pub pinch_release: f32,
    /// While pinched, the robot's pads are driven this far apart (surface to surface, or centre
    /// to centre without `pad_contact`), metres. Default 0.0001.
    pub pinch_gap: f32,
    /// Two fingers both pinched with the thumb and closer than 3 cm are kept this far apart
    /// (centre to centre), metres. Default 0.03.
    pub finger_gap: f32,
    /// Weight of a pinched thumb-finger vector (1 otherwise). Default 200.
    pub pinch_weight: f32,
    /// Weight of a kept-apart finger pair (1 otherwise). Default 400.
    pub finger_gap_weight: f32,
    /// `pinch_gap` is measured between the pads' surfaces (their radii from the hand profile),
    /// not their centres. Default true (dex-retargeting measures between link origins: false).
    pub pad_contact: bool,
    /// Most Gauss-Newton iterations per descent. Default 20.
    pub max_iterations: u32,
    /// A descent from the previous solution that ends with the objective's vector part above
    /// this is tried again (see [`crate::Solver::solve`]). Default 0.0001 (about a 2.5 mm
    /// error on one wrist vector).
    pub restart_above: f32,
}

impl Default for FingertipConfig {
    fn default() -> Self {
        Self {
            scaling: None,
            huber_delta: 0.03,
            smoothness: 0.004,
            posture: 0.001,
            pinch_engage: 0.03,
            pinch_release: 0.05,
            pinch_gap: 0.0001,
            finger_gap: 0.03,
            pinch_weight: 200.0,
            finger_gap_weight: 400.0,
            pad_contact: true,
            max_iterations: 20,
            restart_above: 0.0001,
        }
    }
}

impl FingertipConfig {
    fn validate(&self) -> Result<(), ConfigError> {
        if let Some(s) = self.scaling {
            positive("fingertip.scaling", s)?;
        }
        positive("fingertip.huber_delta", self.huber_delta)?;
        non_negative("fingertip.smoothness", self.smoothness)?;
        non_negative("fingertip.posture", self.posture)?;
        positive("fingertip.pinch_engage", self.pinch_engage)?;
        positive("fingertip.pinch_release", self.pinch_release)?;
        if self.pinch_release <= self.pinch_engage {
            return Err(ConfigError::invalid(
                RETARGET_ORIGIN,
                "fingertip.pinch_release",
                format!(
                    "{} must be above pinch_engage ({}): the switch needs hysteresis",
                    self.pinch_release, self.pinch_engage
                ),
            ));
        }
        non_negative("fingertip.pinch_gap", self.pinch_gap)?;
        non_negative("fingertip.finger_gap", self.finger_gap)?;
        non_negative("fingertip.pinch_weight", self.pinch_weight)?;
        non_negative("fingertip.finger_gap_weight", self.finger_gap_weight)?;
        non_negative("fingertip.restart_above", self.restart_above)?;
        if self.max_iterations == 0 || self.max_iterations > 1000 {
            return Err(ConfigError::invalid(
                RETARGET_ORIGIN,
                "fingertip.max_iterations",
                format!("{} must be in 1..=1000", self.max_iterations),
            ));
        }
        Ok(())
    }
}

/// Retargeting parameters (a TOML table; every field has a sensible default;
/// unknown keys are rejected).
///
/// In TOML, `joints` is a table keyed by the hand profile's joint names
/// (checked by [`RetargetConfig::check_joints`]); joints left out get
/// [`JointConfig::default`]. See the crate documentation for an example.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RetargetConfig {
    /// `joint`, `vector` or `pinch`; default: the hand profile's `[retarget] mode`.
    pub mode: Option<RetargetMode>,
    /// Fingertip retargeting's parameters (modes `vector` and `pinch`).
    pub fingertip: FingertipConfig,
    /// One Euro filter parameters (shared by all joints).
    pub filter: OneEuroParams,
    /// Normalised; the output does not change for filtered-input changes
    /// smaller than this. In `[0, 0.2]`. Default 0.005.
    pub deadband: f32,
    /// Slew limit per joint in normalised units per second. Default 3.0.
    pub max_speed: f32,
    /// Per-joint configuration by joint name.
    pub joints: BTreeMap<String, JointConfig>,
}

impl Default for RetargetConfig {
    fn default() -> Self {
        RetargetConfig {
            mode: None,
            fingertip: FingertipConfig::default(),
            filter: OneEuroParams::default(),
            deadband: 0.005,
            max_speed: 3.0,
            joints: BTreeMap::new(),
        }
    }
}

fn positive(field: &str, v: f32) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(ConfigError::invalid(
            RETARGET_ORIGIN,
            field,
            format!("{v} must be finite and > 0"),
        ))
    }
}

fn non_negative(field: &str, v: f32) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(ConfigError::invalid(
            RETARGET_ORIGIN,
            field,
            format!("{v} must be finite and >= 0"),
        ))
    }
}

impl RetargetConfig {
    /// Parses and validates a TOML table. `origin` (normally the file path)
    /// prefixes every error message.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let cfg: RetargetConfig =
            toml::from_str(text).map_err(|e| ConfigError::parse(origin, &e))?;
        cfg.validate().map_err(|e| e.with_origin(origin))?;
        Ok(cfg)
    }

    /// Checks ranges: `0 <= min < max <= 1` per joint, curves valid (gamma
    /// finite and `> 0`, piecewise points monotone from x = 0 to x = 1),
    /// `min_cutoff_hz` and `d_cutoff_hz` finite and `> 0`, `beta` finite and
    /// `>= 0`, `deadband` in `[0, 0.2]`, `max_speed` finite and `> 0`. The error
    /// names the field (e.g. `joints.index.min`); its origin is
    /// `"retarget config"`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("filter.min_cutoff_hz", self.filter.min_cutoff_hz)?;
        positive("filter.d_cutoff_hz", self.filter.d_cutoff_hz)?;
        let beta = self.filter.beta;
        if !(beta.is_finite() && beta >= 0.0) {
            return Err(ConfigError::invalid(
                RETARGET_ORIGIN,
                "filter.beta",
                format!("{beta} must be finite and >= 0"),
            ));
        }
        let db = self.deadband;
        if !(0.0..=MAX_DEADBAND).contains(&db) {
            return Err(ConfigError::invalid(
                RETARGET_ORIGIN,
                "deadband",
                format!("{db} must be in [0, {MAX_DEADBAND}]"),
            ));
        }
        positive("max_speed", self.max_speed)?;
        self.fingertip.validate()?;
        for (name, j) in &self.joints {
            let field = format!("joints.{name}");
            for (what, v) in [("min", j.min), ("max", j.max)] {
                if !(0.0..=1.0).contains(&v) {
                    return Err(ConfigError::invalid(
                        RETARGET_ORIGIN,
                        format!("{field}.{what}"),
                        format!("{v} must be in [0, 1]"),
                    ));
                }
            }
            if j.min >= j.max {
                return Err(ConfigError::invalid(
                    RETARGET_ORIGIN,
                    field,
                    format!("min ({}) must be less than max ({})", j.min, j.max),
                ));
            }
            j.curve.validate(&format!("{field}.curve"))?;
        }
        Ok(())
    }

    /// Checks that every key of `joints` names a joint of `profile`; the error
    /// names the field (`joints.<name>`) and lists the profile's joints.
    pub fn check_joints(&self, profile: &HandProfile) -> Result<(), ConfigError> {
        for name in self.joints.keys() {
            if profile.joint_index(name).is_none() {
                return Err(ConfigError::invalid(
                    RETARGET_ORIGIN,
                    format!("joints.{name}"),
                    format!(
                        "hand profile `{}` has no joint `{name}` (joints: {})",
                        profile.name,
                        profile.joint_names().collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The configuration of the joint called `name` (the default when not set).
    pub fn joint(&self, name: &str) -> JointConfig {
        self.joints.get(name).cloned().unwrap_or_default()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn empty_text_is_default() {
        let cfg = RetargetConfig::from_toml_str("", "r.toml").unwrap();
        assert_eq!(cfg, RetargetConfig::default());
        cfg.validate().unwrap();
    }

    #[test]
    fn parses_full_example() {
        let text = r#"
deadband = 0.01
max_speed = 2

[filter]
min_cutoff_hz = 2.0
beta = 0.3

[joints.index]
curve = { kind = "gamma", gamma = 0.8 }
max = 0.9

[joints.thumb_abduct]
min = 0.1
curve = { kind = "piecewise", points = [[0, 0], [0.5, 0.3], [1, 1]] }
"#;
        let cfg = RetargetConfig::from_toml_str(text, "r.toml").unwrap();
        assert_eq!(cfg.deadband, 0.01);
        assert_eq!(cfg.max_speed, 2.0);
        assert_eq!(cfg.filter.min_cutoff_hz, 2.0);
        assert_eq!(cfg.filter.beta, 0.3);
        assert_eq!(cfg.filter.d_cutoff_hz, 1.0);
        assert_eq!(cfg.joint("index").curve, Curve::Gamma { gamma: 0.8 });
        assert_eq!(cfg.joint("index").max, 0.9);
        assert_eq!(cfg.joint("index").min, 0.0);
        assert_eq!(cfg.joint("thumb_abduct").min, 0.1);
        assert_eq!(
            cfg.joint("thumb_abduct").curve,
            Curve::Piecewise {
                points: vec![[0.0, 0.0], [0.5, 0.3], [1.0, 1.0]]
            }
        );
        assert_eq!(cfg.joint("thumb_flex"), JointConfig::default());
        assert_eq!(cfg.joint("pinky"), JointConfig::default());

        // serde round trip
        let back = toml::to_string(&cfg).unwrap();
        assert_eq!(RetargetConfig::from_toml_str(&back, "x").unwrap(), cfg);
    }

    #[test]
    fn curves() {
        assert_eq!(Curve::Linear.apply(0.25), 0.25);
        assert_eq!(Curve::Linear.apply(2.0), 1.0);
        assert_eq!(Curve::Linear.apply(f32::NAN), 0.0);
        let g = Curve::Gamma { gamma: 2.0 };
        assert!((g.apply(0.5) - 0.25).abs() < 1e-6);
        assert_eq!(g.apply(0.0), 0.0);
        assert_eq!(g.apply(1.0), 1.0);
        let g = Curve::Gamma { gamma: 0.5 };
        assert!((g.apply(0.25) - 0.5).abs() < 1e-6);
        let p = Curve::Piecewise {
            points: vec![[0.0, 0.0], [0.5, 0.3], [1.0, 1.0]],
        };
        assert_eq!(p.apply(0.0), 0.0);
        assert!((p.apply(0.25) - 0.15).abs() < 1e-6);
        assert!((p.apply(0.5) - 0.3).abs() < 1e-6);
        assert!((p.apply(0.75) - 0.65).abs() < 1e-6);
        assert_eq!(p.apply(1.0), 1.0);
        let flat = Curve::Piecewise {
            points: vec![[0.0, 0.2], [1.0, 0.2]],
        };
        assert_eq!(flat.apply(0.7), 0.2);
    }

    fn err_of(text: &str) -> String {
        RetargetConfig::from_toml_str(text, "r.toml")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn errors_name_origin_and_field() {
        let m = err_of("[joints.index]\nmin = 0.6\nmax = 0.5\n");
        assert_eq!(
            m,
            "r.toml: joints.index: min (0.6) must be less than max (0.5)"
        );
        let m = err_of("[joints.ring]\nmax = 1.5\n");
        assert!(m.starts_with("r.toml: joints.ring.max: "), "{m}");
        let m = err_of("[joints.pinky]\ncurve = { kind = \"gamma\", gamma = 0 }\n");
        assert!(
            m.starts_with("r.toml: joints.pinky.curve: gamma (0)"),
            "{m}"
        );
        let m = err_of("[joints.pinky]\ncurve = { kind = \"gamma\", gamma = nan }\n");
        assert!(m.starts_with("r.toml: joints.pinky.curve: "), "{m}");
        let m = err_of(
            "[joints.middle]\ncurve = { kind = \"piecewise\", points = [[0, 0], [0.5, 0.6], [0.4, 0.7], [1, 1]] }\n",
        );
        assert!(
            m.starts_with("r.toml: joints.middle.curve: x must be strictly"),
            "{m}"
        );
        let m = err_of(
            "[joints.middle]\ncurve = { kind = \"piecewise\", points = [[0, 0], [0.5, 0.6], [1, 0.5]] }\n",
        );
        assert!(m.contains("non-decreasing"), "{m}");
        let m = err_of(
            "[joints.middle]\ncurve = { kind = \"piecewise\", points = [[0.1, 0], [1, 1]] }\n",
        );
        assert!(m.contains("x = 0"), "{m}");
        let m = err_of(
            "[joints.middle]\ncurve = { kind = \"piecewise\", points = [[0, 0], [0.9, 1]] }\n",
        );
        assert!(m.contains("x = 1"), "{m}");
        let m = err_of(
            "[joints.middle]\ncurve = { kind = \"piecewise\", points = [[0, 0], [1, 1.5]] }\n",
        );
        assert!(m.contains("y must be in [0, 1]"), "{m}");
        let m = err_of("deadband = 0.5\n");
        assert!(m.starts_with("r.toml: deadband: "), "{m}");
        let m = err_of("deadband = -0.1\n");
        assert!(m.starts_with("r.toml: deadband: "), "{m}");
        let m = err_of("max_speed = 0\n");
        assert!(m.starts_with("r.toml: max_speed: "), "{m}");
        let m = err_of("max_speed = inf\n");
        assert!(m.starts_with("r.toml: max_speed: "), "{m}");
        let m = err_of("[filter]\nmin_cutoff_hz = -1\n");
        assert!(m.starts_with("r.toml: filter.min_cutoff_hz: "), "{m}");
        let m = err_of("[filter]\nd_cutoff_hz = 0\n");
        assert!(m.starts_with("r.toml: filter.d_cutoff_hz: "), "{m}");
        let m = err_of("[filter]\nbeta = -1\n");
        assert!(m.starts_with("r.toml: filter.beta: "), "{m}");
    }

    #[test]
    fn joints_must_exist_in_the_profile() {
        let cfg = RetargetConfig::from_toml_str("[joints.thumb]\nmin = 0.1\n", "r.toml").unwrap();
        let revo2 = HandProfile::builtin("revo2").unwrap();
        let m = cfg.check_joints(&revo2).unwrap_err().to_string();
        assert!(
            m.starts_with(
                "retarget config: joints.thumb: hand profile `revo2` has no joint `thumb`"
            ),
            "{m}"
        );
        let cfg = RetargetConfig::from_toml_str("[joints.index_1]\nmax = 0.5\n", "r.toml").unwrap();
        assert!(cfg.check_joints(&revo2).is_err());
        cfg.check_joints(&HandProfile::builtin("allegro").unwrap())
            .unwrap();
    }

    #[test]
    fn unknown_keys_are_errors() {
        let m = err_of("dead_band = 0.1\n");
        assert!(
            m.starts_with("r.toml: ") && m.contains("unknown field `dead_band`"),
            "{m}"
        );
        let m = err_of("[joints.index]\nmaximum = 0.1\n");
        assert!(m.contains("unknown field `maximum`"), "{m}");
        let m = err_of("[filter]\ncutoff = 1\n");
        assert!(m.contains("unknown field `cutoff`"), "{m}");
        let m = err_of("[joints.index]\ncurve = { kind = \"gamma\", gamma = 1, extra = 2 }\n");
        assert!(m.contains("extra"), "{m}");
        let m = err_of("[joints.index]\ncurve = { kind = \"linear\", gamma = 0.5 }\n");
        assert!(m.contains("unknown field `gamma`"), "{m}");
        let m = err_of("[joints.index]\ncurve = { kind = \"cubic\" }\n");
        assert!(m.contains("cubic"), "{m}");
        let m = err_of("[joints.index]\ncurve = { kind = \"gamma\" }\n");
        assert!(m.contains("missing field `gamma`"), "{m}");
    }
}
