//! The one error type of the crate: every variant names the file it is about.

use std::path::{Path, PathBuf};

/// Why a recording could not be written, read or repaired.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The file does not start with the MCAP magic (random bytes, a text file, another format).
    #[error("{}: not an MCAP file", .path.display())]
    NotMcap {
        /// The file.
        path: PathBuf,
    },
    /// The file ends before its header is complete (an empty file, or one cut inside the magic
    /// or the header record): nothing in it can be recovered.
    #[error("{}: truncated MCAP file: {detail}", .path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Where it ends.
        detail: String,
    },
    /// A topic of the message contract is recorded with another schema name or encoding than the
    /// contract's (`ros2msg` schema, `cdr` messages).
    #[error(
        "{}: topic `{topic}` is recorded with schema `{schema}` ({encoding}), the contract expects \
         `{expected}` (ros2msg/cdr)",
        .path.display()
    )]
    UnknownSchema {
        /// The file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// The recorded schema name (empty when the channel has no schema).
        schema: String,
        /// The recorded schema encoding and message encoding, as `schema/message`.
        encoding: String,
        /// The contract's schema name for the topic.
        expected: String,
    },
    /// A topic of the message contract is recorded with the contract's schema name but another
    /// schema text, neither the current contract version's nor one this build converts: the
    /// file was written by another version of the contract.
    #[error(
        "{}: topic `{topic}` is recorded with an unknown version of `{schema}` (this build reads \
         contract version {} and converts version 1): {}",
        .path.display(),
        teleop_msgs::CONTRACT_VERSION,
        first_difference(.expected, .found)
    )]
    WrongSchemaVersion {
        /// The file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// The schema name.
        schema: String,
        /// The contract's schema text.
        expected: String,
        /// The recorded schema text.
        found: String,
    },
    /// One message cannot be a payload of its topic: no CDR header, a big-endian or unknown CDR
    /// header on a contract topic, or the wrong size for the contract's type.
    #[error("{}: bad message on `{topic}`: {detail}", .path.display())]
    BadMessage {
        /// The file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// What is wrong with it.
        detail: String,
    },
    /// Reading or writing the file failed.
    #[error("{}: {source}", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The MCAP structure is damaged (bad record, bad index, bad compression) or the MCAP
    /// library refused an operation.
    #[error("{}: {detail}", .path.display())]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What the MCAP library reported.
        detail: String,
    },
    /// An earlier error stopped the recorder (a full disk, a failed write): everything after
    /// it is refused with that first error, which is the cause.
    #[error("{}: recording stopped by an earlier error: {first}", .path.display())]
    Stopped {
        /// The file being written when it stopped.
        path: PathBuf,
        /// The first error, as text.
        first: String,
    },
    /// The API was used in a way that cannot work: a topic registered twice with different
    /// schemas, a topic id from another recorder, repairing a file onto itself.
    #[error("{}: {detail}", .path.display())]
    InvalidUse {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        detail: String,
    },
}

impl RecordingError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            Self::NotMcap { path }
            | Self::Truncated { path, .. }
            | Self::UnknownSchema { path, .. }
            | Self::WrongSchemaVersion { path, .. }
            | Self::BadMessage { path, .. }
            | Self::Io { path, .. }
            | Self::Mcap { path, .. }
            | Self::Stopped { path, .. }
            | Self::InvalidUse { path, .. } => path,
        }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn mcap(path: &Path, error: mcap::McapError) -> Self {
        match error {
            mcap::McapError::Io(source) => Self::io(path, source),
            other => Self::Mcap {
                path: path.to_path_buf(),
                detail: other.to_string(),
            },
        }
    }

    pub(crate) fn invalid_use(path: &Path, detail: impl Into<String>) -> Self {
        Self::InvalidUse {
            path: path.to_path_buf(),
            detail: detail.into(),
        }
    }
}

/// The first line where two schema texts differ, for error messages (the texts themselves are
/// in the error's fields).
fn first_difference(expected: &str, found: &str) -> String {
    let mut expected_lines = expected.lines();
    let mut found_lines = found.lines();
    let mut line = 1;
    loop {
        match (expected_lines.next(), found_lines.next()) {
            (None, None) => return "the texts differ only in whitespace".to_string(),
            (e, f) if e == f => line += 1,
            (e, f) => {
                return format!(
                    "line {line} is `{}`, the contract has `{}`",
                    f.unwrap_or("<end>"),
                    e.unwrap_or("<end>")
                )
            }
        }
    }
}
