//! The viewer: the live pipeline or a recording, streamed to a rerun viewer (a running one, one
//! it starts, or an `.rrd` file).
//!
//! Three layers, so that the content is tested without rerun and rerun stays in this crate:
//! - content ([`kinematics`], [`sample`], [`content`]): pure. The hand models of
//!   `teleop-kinematics` (the operator's hand posed from the glove, the same model fingertip
//!   retargeting solves for; the robot hand from its profile and its joint state) and the conversion of each sample into entity paths and plain values
//!   ([`content::Frame`]), with decimation.
//! - rerun ([`logger`], [`layout`]): logs frames as rerun archetypes on two timelines
//!   (`recording_time`, `sample_time`) and sends the default layout (blueprint) for the robot
//!   hand.
//! - sources ([`live`], [`recording`]): iceoryx2 subscribers feeding a logging thread through a
//!   bounded queue that drops (and counts) rather than blocks; or a recording read in log-time
//!   order, with a progress bar.
//!
//! Owns: everything rerun. Must not be a dependency of any other crate (the `teleop view`
//! command runs the `teleop-viewer` executable), and must not publish anything: viewing never
//! affects the pipeline.

pub mod content;
pub mod layout;
pub mod live;
pub mod logger;
pub mod recording;
pub mod sample;

/// The rerun SDK this crate was built with (viewers of the same version read its data).
pub use rerun;
/// The hand models (`teleop-kinematics`), under the name this crate's modules use.
pub use teleop_kinematics as kinematics;
