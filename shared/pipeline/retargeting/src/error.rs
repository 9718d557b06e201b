//! Configuration errors shared by [`crate::Calibration`] and [`crate::RetargetConfig`].

/// Origin used by [`crate::Calibration::validate`] when no file path is known.
pub const CALIBRATION_ORIGIN: &str = "calibration";
/// Origin used by [`crate::Calibration::from_poses`].
pub const POSES_ORIGIN: &str = "calibration poses";
/// Origin used by [`crate::RetargetConfig::validate`] when no file path is known.
pub const RETARGET_ORIGIN: &str = "retarget config";

/// An invalid calibration profile or retargeting configuration.
///
/// The `Display` form always starts with the origin (usually the file path the
/// text came from) followed by the offending field, e.g.
/// `calibration.toml: [ring]: open (500) and closed (480) are only 20 apart; need at least 50`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// The text is not valid TOML, or does not have the expected shape (missing
    /// or unknown keys, wrong types). `message` is toml's own message, which
    /// keeps the line/column and names the key.
    #[error("{origin}: {message}")]
    Parse {
        /// Where the text came from (file path or a descriptive label).
        origin: String,
        /// The TOML parser's message (includes line and column).
        message: String,
    },
    /// The value parsed but is out of range or inconsistent.
    #[error("{origin}: {field}: {reason}")]
    Invalid {
        /// Where the value came from (file path or a descriptive label).
        origin: String,
        /// The offending field, e.g. `[ring]` or `joints.index.min`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl ConfigError {
    /// Where the offending text or value came from.
    pub fn origin(&self) -> &str {
        match self {
            ConfigError::Parse { origin, .. } | ConfigError::Invalid { origin, .. } => origin,
        }
    }

    /// The same error, attributed to another origin (e.g. the file path).
    #[must_use]
    pub fn with_origin(mut self, new_origin: &str) -> Self {
        match &mut self {
            ConfigError::Parse { origin, .. } | ConfigError::Invalid { origin, .. } => {
                new_origin.clone_into(origin);
            }
        }
        self
    }

    pub(crate) fn invalid(
        origin: &str,
        field: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        ConfigError::Invalid {
            origin: origin.to_owned(),
            field: field.into(),
            reason: reason.into(),
        }
    }

    pub(crate) fn parse(origin: &str, err: &toml::de::Error) -> Self {
        ConfigError::Parse {
            origin: origin.to_owned(),
            message: err.to_string().trim_end().to_owned(),
        }
    }
}
