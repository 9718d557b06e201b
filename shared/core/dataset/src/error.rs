//! The errors of reading and writing datasets: each names the file or folder.

use std::path::{Path, PathBuf};

/// Something went wrong with a dataset; every variant names the path.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
    /// A parquet file could not be written or read.
    #[error("{path}: parquet: {detail}")]
    Parquet {
        /// The file.
        path: PathBuf,
        /// What the parquet crate said.
        detail: String,
    },
    /// The dataset (or an argument about it) is not what it must be.
    #[error("{path}: {detail}")]
    Invalid {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// The existing dataset holds other features than the export writes.
    #[error("{path}: not the same dataset: {detail}")]
    Mismatch {
        /// The dataset's `info.json`.
        path: PathBuf,
        /// The first difference.
        detail: String,
    },
}

impl DatasetError {
    pub(crate) fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }

    pub(crate) fn parquet(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::Parquet {
            path: path.to_path_buf(),
            detail: e.to_string(),
        }
    }

    pub(crate) fn invalid(path: &Path, detail: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.to_path_buf(),
            detail: detail.into(),
        }
    }

    pub(crate) fn mismatch(path: &Path, detail: impl Into<String>) -> Self {
        Self::Mismatch {
            path: path.to_path_buf(),
            detail: detail.into(),
        }
    }
}
