//! The message contract of the teleoperation pipeline.
//!
//! Owns every payload that crosses a process boundary: fixed-size `#[repr(C)]` structs with
//! `ZeroCopySend`, an explicit iceoryx2 type name, no heap, no pointers and no padding (checked
//! at compile time). Every payload starts with the same [`SampleHeader`] (sequence number, stamp,
//! origin stamp, source id) so that end-to-end latency can be attributed per stage.
//!
//! Each payload also carries its ROS 2 `.msg` schema ([`Message::schema`]): the raw struct bytes
//! behind the 4-byte CDR little-endian encapsulation header are valid ROS 2 CDR for that schema, so
//! a recorder can write them to MCAP unchanged and any ROS 2 tool decodes them. The `cdr_layout`
//! test checks every schema against the struct's real field offsets.
//!
//! [`topics`] lists every topic with its payload type; [`visit_topic`] lets generic tools
//! (echo, stats, recorder) work on any topic without per-topic code.
//!
//! The contract is versioned ([`CONTRACT_VERSION`]): the version is part of every payload's
//! iceoryx2 type name, so processes built from different contracts refuse each other by name,
//! and recordings of earlier versions are converted on read by `teleop-recording`.
//!
//! Must not depend on: anything but `iceoryx2` (for `ZeroCopySend`). No I/O here.

mod contract;
mod message;

/// The contract version as a literal, for `concat!` (see [`CONTRACT_VERSION`]).
#[doc(hidden)]
#[macro_export]
macro_rules! contract_version {
    () => {
        3
    };
}

/// The version of the message contract: raised whenever any payload's layout or meaning
/// changes. It is part of every payload's iceoryx2 type name ([`Message::TYPE_NAME`]), so a
/// process built with another contract is refused when it opens a service instead of misreading
/// its samples, and recordings store it (see `teleop-recording`).
///
/// History: 1, the first contract (EtherCAT-shaped `HandState`, Revo2-only `Fingertip`);
/// 2, link-neutral `HandState` (link kind, bus state, link error code, link errors), joint
/// effort, fingertip sensor kind with pressure and temperature; 3, one numbering of hands and
/// devices (`device_model`: `DeviceInfo`'s device kind is gone), `DeviceInfo` fields named by
/// meaning, `NodeHealth` details named (`HealthDetail`) instead of seven anonymous bytes.
pub const CONTRACT_VERSION: u32 = contract_version!();

pub use contract::*;
pub use message::{DecodeError, Field, Message, Nested, TopicInfo, TopicVisitor};

/// The CDR encapsulation header (little-endian, no options) that turns a payload's bytes into a
/// ROS 2 CDR message.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Prefix of every iceoryx2 service name used by the pipeline: topic `glove/state` is the service
/// `teleop/glove/state`.
pub const SERVICE_PREFIX: &str = "teleop/";

/// The command topics that take exactly one writer per namespace: a second publisher is refused
/// (`teleop_runtime`), so two operators, two sessions or a stray tool cannot drive one hand or
/// one glove in turn. (`teleop replay --allow-live` is the one named, counted exception.)
pub const SINGLE_WRITER_TOPICS: [&str; 2] = ["hand/command", "glove/force_command"];

/// FNV-1a hash of a node name: the `source_id` a node writes into every header it stamps.
pub const fn source_id(name: &str) -> u32 {
    let bytes = name.as_bytes();
    let mut hash: u32 = 0x811c_9dc5;
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u32;
        hash = hash.wrapping_mul(0x0100_0193);
        i += 1;
    }
    hash
}
