//! Configuration of the force-feedback law: TOML parsing and validation.

use serde::{Deserialize, Serialize};

use crate::{PassivityConfig, GLOVE_FINGERS};

/// Origin reported by [`FeedbackConfig::validate`] when the configuration was
/// not read from a file (for example built in code and handed to
/// [`crate::ForceFeedback::new`]).
pub const IN_MEMORY_ORIGIN: &str = "<feedback config>";

/// Largest `max_force` the glove accepts (glove units, full scale).
pub const GLOVE_FULL_SCALE: i16 = 1000;

/// Tuning of the force-feedback law.
///
/// Every field has a default (see [`FeedbackConfig::default`]), so a TOML file
/// only needs the keys it changes; unknown keys are rejected.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeedbackConfig {
    /// Fingertip normal force (N) below which the tactile sensor reports no
    /// contact. Default 0.3 N.
    pub contact_threshold_n: f32,
    /// Glove units per newton above `contact_threshold_n`. Default 250
    /// (4 N above the threshold gives full scale, 1000).
    pub gain_per_n: f32,
    /// Saturation of the force command in glove units, `0..=1000`.
    /// Default 800.
    pub max_force: i16,
    /// Largest change of the output per second, in glove units per second.
    /// Default 20000 (full scale in 50 ms).
    pub rate_limit_per_s: f32,
    /// Time constant (s) of the first-order low-pass on the demand.
    /// Default 0.01; 0 disables smoothing.
    pub smoothing_tau_s: f32,
    /// When inputs go stale, the force ramps to zero at
    /// `max_force / stale_ramp_s` units per second, so from `max_force` it
    /// reaches zero within this time (s). Default 0.1; must be > 0.
    pub stale_ramp_s: f32,
    /// Backlash on each finger's demand, glove units: the demand passed on trails the law's
    /// by up to this much and holds still while the law's turns back within it, so the force
    /// does not hunt between neighbouring values of a quantised contact force; a demand at or
    /// below it, and a saturated one, is passed exactly, so a contact that ends still goes to
    /// zero and a firm grasp is felt at `max_force`. What it costs: below saturation the felt
    /// force is up to this much off the law's (below it after a rise). Default 0 (off); else
    /// below `max_force`. With a position-controlled hand, set it to about the force one step
    /// of the retargeting's deadband makes on a rigid object: in bench_haptics the Revo2
    /// simulator's force on the rigid ball moved in steps of 0.134-0.16 N (34-40 units at the
    /// default gain) as the retargeting's 5 per mille deadband let the target move, and the
    /// loose operator's finger, giving way more than a step's travel under one step's force,
    /// made it hunt between two steps with the passivity controller on (a 42-unit, 15-raw
    /// swing at 0 and 10 ms round trip without hysteresis; a slower 27-unit one with 20; none
    /// with 35). It does not stop plain feedback's delay-driven cycles: that is the passivity
    /// controller's work.
    pub hysteresis: f32,
    /// Contact estimation from joint state, used when tactile data is absent
    /// or invalid for a finger.
    pub estimate: EstimateConfig,
    /// Per glove finger scale (operator preference), glove order
    /// `[little, ring, middle, index, thumb]`, each in `[0, 2]`. Default 1.
    pub finger_gain: [f32; GLOVE_FINGERS],
    /// How a PST fingertip's raw pressure becomes a normal force (Shadow Hand).
    pub pst: PstConfig,
    /// The passivity observer and controller (`[passivity]`).
    pub passivity: PassivityConfig,
}

/// A PST fingertip's raw pressure as a normal force: `(pressure - zero) / counts_per_n`, never
/// below 0. The palm reports the pressure uncalibrated: each lab measures its own sensors (the
/// defaults are the emulated hand's).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct PstConfig {
    /// The pressure reading without contact. Default 10.
    pub zero: f32,
    /// Pressure counts per newton on the fingertip. Default 100; must be > 0.
    pub counts_per_n: f32,
}

impl Default for PstConfig {
    fn default() -> Self {
        Self {
            zero: 10.0,
            counts_per_n: 100.0,
        }
    }
}

impl PstConfig {
    /// The normal force (N) of a raw pressure reading.
    pub fn force_n(&self, pressure: i32) -> f32 {
        ((pressure as f32 - self.zero) / self.counts_per_n).max(0.0)
    }
}

impl Default for FeedbackConfig {
    fn default() -> Self {
        Self {
            contact_threshold_n: 0.3,
            gain_per_n: 250.0,
            max_force: 800,
            rate_limit_per_s: 20_000.0,
            smoothing_tau_s: 0.01,
            stale_ramp_s: 0.1,
            hysteresis: 0.0,
            estimate: EstimateConfig::default(),
            finger_gain: [1.0; GLOVE_FINGERS],
            pst: PstConfig::default(),
            passivity: PassivityConfig::default(),
        }
    }
}

/// Contact estimation from the hand's joint state, the fallback when a
/// fingertip has no valid tactile reading.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimateConfig {
    /// Estimate contact from `commanded - measured` joint position.
    /// Default true.
    pub use_position_error: bool,
    /// Position error (normalised, 0 = open .. 1 = closed) below which there
    /// is no contact. Default 0.05.
    pub position_error_threshold: f32,
    /// Glove units per normalised position error above the threshold.
    /// Default 4000.
    pub position_gain: f32,
    /// Estimate contact from the magnitude of the motor current.
    /// Default true.
    pub use_current: bool,
    /// Motor current magnitude (mA) below which there is no contact.
    /// Default 300.
    pub current_threshold_ma: f32,
    /// Glove units per mA above the threshold. Default 1.0.
    pub current_gain_per_ma: f32,
    /// Current counts only toward the joint's closed angle, as effort does (a hand whose
    /// current is signed like its joint angle: the servo pushes the finger closed against
    /// something), and not while the joint is beyond its open angle. Default false: the
    /// current's magnitude counts.
    pub current_toward_closing: bool,
    /// Current counts as contact only while the joint moves slower than this (rad/s), as
    /// [`EstimateConfig::effort_stall_speed_rad_s`] for effort: the current a servo draws to
    /// move a finger through free space is not contact. 0 (the default) counts it at any
    /// speed; a joint whose speed is unknown counts too.
    pub current_stall_speed_rad_s: f32,
    /// Estimate contact from the magnitude of the joint effort (hands that
    /// measure or command torque). Default true.
    pub use_effort: bool,
    /// Joint effort toward the closed angle (N m) below which there is no contact.
    /// Default 0.05.
    pub effort_threshold_nm: f32,
    /// Glove units per N m above the threshold. Default 2000.
    pub effort_gain_per_nm: f32,
    /// Effort counts as contact only while the joint moves slower than this (rad/s): a joint
    /// that pushes and does not move is stopped by something, while the effort of a joint in
    /// motion is what moving it takes (Drake's Allegro example calls a joint in contact below
    /// 0.07 rad/s, docs/devices/allegro.md). 0 (the default) counts effort at any speed; a
    /// joint whose speed is unknown counts too.
    pub effort_stall_speed_rad_s: f32,
}

impl Default for EstimateConfig {
    fn default() -> Self {
        Self {
            use_position_error: true,
            position_error_threshold: 0.05,
            position_gain: 4000.0,
            use_current: true,
            current_threshold_ma: 300.0,
            current_gain_per_ma: 1.0,
            current_toward_closing: false,
            current_stall_speed_rad_s: 0.0,
            use_effort: true,
            effort_threshold_nm: 0.05,
            effort_gain_per_nm: 2000.0,
            effort_stall_speed_rad_s: 0.0,
        }
    }
}

/// Error reading or validating a [`FeedbackConfig`].
///
/// `Display` always starts with the origin (normally the file path), then
/// names the offending field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    /// The text is not valid TOML, has an unknown key or a value of the wrong
    /// type. The message keeps toml's line and column and the offending line.
    #[error("{origin}: {source}")]
    Parse {
        /// Where the text came from (file path).
        origin: String,
        /// The underlying toml error (message, line/column, snippet).
        #[source]
        source: toml::de::Error,
    },
    /// A value parsed but is out of its allowed range.
    #[error("{origin}: invalid `{field}` = {value}: {reason}")]
    Invalid {
        /// Where the configuration came from (file path, or
        /// [`IN_MEMORY_ORIGIN`]).
        origin: String,
        /// Dotted field path, e.g. `estimate.position_gain` or
        /// `finger_gain[3]`.
        field: String,
        /// The rejected value, formatted.
        value: String,
        /// What the value must satisfy.
        reason: &'static str,
    },
}

impl ConfigError {
    /// The origin (file path) this error refers to.
    pub fn origin(&self) -> &str {
        match self {
            Self::Parse { origin, .. } | Self::Invalid { origin, .. } => origin,
        }
    }

    /// The same error attributed to `new_origin` (e.g. the file the configuration came from).
    pub fn with_origin(self, new_origin: &str) -> Self {
        match self {
            Self::Parse { source, .. } => Self::Parse {
                origin: new_origin.to_owned(),
                source,
            },
            Self::Invalid {
                field,
                value,
                reason,
                ..
            } => Self::Invalid {
                origin: new_origin.to_owned(),
                field,
                value,
                reason,
            },
        }
    }
}

fn invalid(field: impl Into<String>, value: impl ToString, reason: &'static str) -> ConfigError {
    ConfigError::Invalid {
        origin: IN_MEMORY_ORIGIN.to_owned(),
        field: field.into(),
        value: value.to_string(),
        reason,
    }
}

/// Finite and `>= 0`.
fn check_non_negative(field: &str, value: f32) -> Result<(), ConfigError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(invalid(field, value, "must be finite and >= 0"))
    }
}

/// Finite and `> 0`.
fn check_positive(field: &str, value: f32) -> Result<(), ConfigError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(invalid(field, value, "must be finite and > 0"))
    }
}

impl FeedbackConfig {
    /// Parses a TOML document and validates it.
    ///
    /// `origin` (normally the file path) is put at the start of every error
    /// message. Missing keys take their defaults; unknown keys are errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let config: Self = toml::from_str(text).map_err(|source| ConfigError::Parse {
            origin: origin.to_owned(),
            source,
        })?;
        config.validate().map_err(|e| e.with_origin(origin))?;
        Ok(config)
    }

    /// Checks every value is in range: all floats finite, thresholds and
    /// gains `>= 0`, `rate_limit_per_s > 0`, `stale_ramp_s > 0`,
    /// `max_force` in `0..=1000`, `hysteresis` 0 or in `(0, max_force)`, each
    /// `finger_gain` in `[0, 2]`.
    ///
    /// Errors carry the origin [`IN_MEMORY_ORIGIN`].
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_non_negative("contact_threshold_n", self.contact_threshold_n)?;
        check_non_negative("gain_per_n", self.gain_per_n)?;
        if !(0..=GLOVE_FULL_SCALE).contains(&self.max_force) {
            return Err(invalid("max_force", self.max_force, "must be in 0..=1000"));
        }
        check_positive("rate_limit_per_s", self.rate_limit_per_s)?;
        check_non_negative("smoothing_tau_s", self.smoothing_tau_s)?;
        check_positive("stale_ramp_s", self.stale_ramp_s)?;
        check_non_negative("hysteresis", self.hysteresis)?;
        if self.hysteresis > 0.0 && self.hysteresis >= f32::from(self.max_force) {
            return Err(invalid(
                "hysteresis",
                self.hysteresis,
                "must be below max_force (or 0): every demand would pass unchanged",
            ));
        }
        let e = &self.estimate;
        check_non_negative(
            "estimate.position_error_threshold",
            e.position_error_threshold,
        )?;
        check_non_negative("estimate.position_gain", e.position_gain)?;
        check_non_negative("estimate.current_threshold_ma", e.current_threshold_ma)?;
        check_non_negative("estimate.current_gain_per_ma", e.current_gain_per_ma)?;
        check_non_negative(
            "estimate.current_stall_speed_rad_s",
            e.current_stall_speed_rad_s,
        )?;
        check_non_negative("estimate.effort_threshold_nm", e.effort_threshold_nm)?;
        check_non_negative("estimate.effort_gain_per_nm", e.effort_gain_per_nm)?;
        check_non_negative(
            "estimate.effort_stall_speed_rad_s",
            e.effort_stall_speed_rad_s,
        )?;
        check_positive("pst.counts_per_n", self.pst.counts_per_n)?;
        if !self.pst.zero.is_finite() {
            return Err(invalid("pst.zero", self.pst.zero, "must be finite"));
        }
        let p = &self.passivity;
        check_non_negative("passivity.max_damping", p.max_damping)?;
        check_positive("passivity.reset_after_s", p.reset_after_s)?;
        check_non_negative("passivity.max_stored", p.max_stored)?;
        check_non_negative("passivity.tolerance", p.tolerance)?;
        check_non_negative("passivity.recovery_per_s", p.recovery_per_s)?;
        for (i, &g) in self.finger_gain.iter().enumerate() {
            if !(g.is_finite() && (0.0..=2.0).contains(&g)) {
                return Err(invalid(format!("finger_gain[{i}]"), g, "must be in [0, 2]"));
            }
        }
        Ok(())
    }
}
