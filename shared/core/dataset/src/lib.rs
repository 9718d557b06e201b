//! LeRobot v3.0 datasets from teleoperation recordings: the parts that know no recording and no
//! IPC.
//!
//! - [`resample`]: samples of several topics, each at its own rate, to frames at one fixed
//!   rate (zero-order hold, no look-ahead) over the episodes' time windows.
//! - [`stats`]: per-episode and aggregated feature statistics, computed as lerobot computes
//!   them (min, max, mean, std, count, quantiles q01..q99).
//! - [`DatasetWriter`]: the dataset's files (parquet frames with one row group per episode,
//!   `meta/info.json`, `meta/tasks.parquet`, `meta/episodes/...`, `meta/stats.json`), new or
//!   appended to, swapped in atomically so that a crashed export never leaves a dataset that
//!   reads wrong; [`check`] reads one back and checks that its parts agree.
//!
//! `docs/lerobot.md` lists the facts of the format this follows and where they come from.
//!
//! Owns: the dataset format, its statistics, the resampling rule. Must not depend on: iceoryx2,
//! the message contract, recordings (the `teleop export` command feeds it samples).

mod check;
mod error;
pub mod resample;
pub mod stats;
mod writer;

pub use check::{check, DatasetSummary};
pub use error::DatasetError;
pub use writer::{
    Committed, DatasetSpec, DatasetWriter, EpisodeBuffer, FeatureSpec, WrittenEpisode,
    CODEBASE_VERSION, DEFAULT_FEATURES,
};
