//! The recording file format of the teleoperation pipeline: the layer the recorder node, the
//! replay and the reprocess commands are built on.
//!
//! A recording is an MCAP file (profile `ros2`, zstd chunks) whose channels carry ROS 2 CDR
//! messages: schema encoding `ros2msg` with the contract's schema name and text, message
//! encoding `cdr`, and each message is the 4-byte CDR little-endian header followed by the raw
//! `repr(C)` payload bytes (see `teleop_msgs`). Any ROS 2 MCAP tool decodes the files: the
//! Python `mcap` + `mcap-ros2-support` packages, Foxglove, rerun.
//!
//! - [`Recorder`] writes: it registers topics, closes a chunk every `chunk_flush` of log time so
//!   that a killed recorder loses at most that much, rotates files by size or duration
//!   (`<stem>_<n>.mcap`, each repeating schemas, channels and metadata), and records per-topic
//!   drops as the `drops` metadata record.
//! - [`info`] describes a file from its summary (finished) or by streaming (killed, `complete
//!   = false`).
//! - [`read_messages`] yields payloads in log-time order (finished) or file order (killed),
//!   checked against the message contract.
//! - [`read_samples`] decodes the messages of one contract type in one namespace.
//! - [`Episodes`] turns the operator's episode marks into spans ([`read_episodes`]: a
//!   recording's).
//! - [`repair`] copies what a killed recorder left (or what reads of a damaged file) into a
//!   finished file, skipping and reporting what does not read.
//!
//! Contract versions: every file starts with a [`CONTRACT_METADATA`] record naming the message
//! contract version it was written with, and each topic's schema text fixes its layout. Readers
//! accept the current schema texts and those of earlier versions that [`legacy`] converts
//! (contract version 1's `HandState` and `Tactile`, e.g. `recordings/grasp.sample.mcap`; the
//! `DeviceInfo` and `NodeHealth` of versions 1 and 2, e.g. `recordings/allegro-v2.sample.mcap`):
//! such messages are read as the current payloads. Any other schema text of a contract topic is
//! refused as [`RecordingError::WrongSchemaVersion`], naming the file, topic and schema.
//!
//! ```
//! use std::collections::BTreeMap;
//! use teleop_msgs::GloveState;
//! use teleop_recording::{info, read_messages, Filter, RecordedMessage, Recorder, WriterOptions};
//!
//! # fn main() -> Result<(), teleop_recording::RecordingError> {
//! # let dir = tempfile::tempdir().map_err(|e| teleop_recording::RecordingError::Io {
//! #     path: "tmp".into(), source: e })?;
//! let path = dir.path().join("session.mcap");
//! let software = BTreeMap::from([("version".to_string(), "0.1.0".to_string())]);
//! let mut recorder = Recorder::create(&path, WriterOptions::default(), &[("software".into(), software)])?;
//! let glove = recorder.add_message_type::<GloveState>()?;
//! let mut sample = GloveState::default();
//! sample.header.seq = 1;
//! sample.header.stamp_ns = 1_000;
//! recorder.write(glove, &RecordedMessage::from_sample(&sample, 2_000))?;
//! recorder.note_drops("glove/state", 0);
//! let summary = recorder.finish()?;
//! assert_eq!(summary.messages, 1);
//!
//! assert!(info(&path)?.complete);
//! for msg in read_messages(&path, &Filter::topics(["glove/state"]))? {
//!     let state: GloveState = msg?.decode().expect("a glove/state payload");
//!     assert_eq!(state.header.seq, 1);
//! }
//! # Ok(())
//! # }
//! ```
//!
//! Every reader is total: any byte string gives a value or a typed [`RecordingError`] that
//! names the file, never a panic.
//!
//! Owns: the file format, its checks and its recovery. Must not depend on: iceoryx2 (beyond the
//! message contract), threads, clocks (the caller provides every time).

mod episodes;
mod error;
mod file;
pub mod legacy;
mod read;
mod repair;
mod write;

pub use episodes::{read_episodes, Change, EpisodeSpan, Episodes, OpenEpisode};
pub use error::RecordingError;
pub use read::{
    head_metadata, info, read_messages, read_samples, Filter, Messages, OwnedMessage,
    RecordingInfo, Samples, TopicInfo,
};
pub use repair::{repair, repair_with, RepairOptions, RepairReport, Skipped};
pub use write::{
    part_path, RecordedMessage, Recorder, RecordingSummary, TopicCount, TopicId, WriterOptions,
    CONTRACT_METADATA, DROPS_METADATA,
};
