//! A process built with another message contract version is refused by name when it opens a
//! topic, instead of misreading the samples.
#![allow(clippy::unwrap_used)]

use iceoryx2::node::NodeBuilder;
use iceoryx2::prelude::{ServiceName, ZeroCopySend};
use teleop_msgs::{EStop, HandState, Message, SERVICE_PREFIX};
use teleop_runtime::*;

/// `HandState` as a process of contract version 1 declared it (same name, no version, 432
/// bytes).
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("teleop_msgs/msg/HandState")]
struct HandStateV1 {
    bytes: [u64; 54],
}

/// `EStop` with the current layout but another contract version in its name.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("teleop_msgs/msg/EStop@v4")]
struct EStopV4 {
    bytes: [u64; 5],
}

/// Opens `topic`'s service as an older or newer process would, then returns what this build's
/// runtime says when it opens the same topic.
fn refusal<Theirs: ZeroCopySend + core::fmt::Debug + 'static, Ours: Message>(
    settings: &IpcSettings,
) -> RuntimeError {
    let config = settings.config().unwrap();
    let other = NodeBuilder::new()
        .config(&config)
        .create::<Service>()
        .unwrap();
    let name = ServiceName::new(&format!("{SERVICE_PREFIX}{}", Ours::TOPIC)).unwrap();
    let _service = other
        .service_builder(&name)
        .publish_subscribe::<Theirs>()
        .create()
        .unwrap();
    let ours = NodeRuntime::new("contract-test", settings).unwrap();
    let publisher = ours.publisher::<Ours>().err().unwrap();
    let subscriber = ours.subscriber::<Ours>().err().unwrap();
    assert_eq!(publisher.to_string(), subscriber.to_string());
    publisher
}

#[test]
fn another_contract_version_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let settings = IpcSettings::isolated(dir.path());

    let err = refusal::<HandStateV1, HandState>(&settings);
    assert!(
        matches!(err, RuntimeError::ContractMismatch { .. }),
        "{err}"
    );
    let text = err.to_string();
    for part in [
        "contract version mismatch on service teleop/hand/state",
        "`teleop_msgs/msg/HandState@v3 (536 bytes)`",
        "`teleop_msgs/msg/HandState (432 bytes)`",
    ] {
        assert!(text.contains(part), "{part:?} missing from: {text}");
    }

    // Same size, another version: refused all the same.
    let err = refusal::<EStopV4, EStop>(&settings);
    let text = err.to_string();
    assert!(
        text.contains("contract version mismatch on service teleop/estop")
            && text.contains("`teleop_msgs/msg/EStop@v4 (40 bytes)`"),
        "{text}"
    );
    settings.remove_shared_memory();
}
