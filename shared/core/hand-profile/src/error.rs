//! Errors of loading a profile: each names the file, and for a bad value the line and field.

/// A profile that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProfileError {
    /// The file could not be read.
    #[error("{origin}: cannot read the hand profile: {reason}")]
    Read {
        /// The file.
        origin: String,
        /// Why.
        reason: String,
    },
    /// Not TOML, or not the shape of a profile (toml's message names the line, column and key).
    #[error("{origin}: {message}")]
    Parse {
        /// The file.
        origin: String,
        /// toml's message.
        message: String,
    },
    /// A value that parsed but does not make sense.
    #[error("{origin}:{line}: {field}: {reason}")]
    Invalid {
        /// The file.
        origin: String,
        /// 1-based line of the offending value.
        line: usize,
        /// The field, e.g. `joint[3].limits` or `feedback[0].joints`.
        field: String,
        /// What is wrong.
        reason: String,
    },
}
