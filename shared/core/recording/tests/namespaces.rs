//! Channels of namespaced topics (`left/glove/state`): checked against the contract like the
//! plain topic, read back under their own names, and decoded per namespace by `read_samples`.
#![allow(clippy::unwrap_used)]

use teleop_msgs::{GloveState, HandCommand, Message};
use teleop_recording::*;

#[test]
fn namespaced_channels_are_contract_channels() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("two-sides.mcap");
    let mut rec = Recorder::create(&path, WriterOptions::default(), &[]).unwrap();
    let schema = GloveState::schema();
    let plain = rec.add_message_type::<GloveState>().unwrap();
    let left = rec
        .add_topic("left/glove/state", GloveState::SCHEMA_NAME, &schema)
        .unwrap();
    let right = rec
        .add_topic("right/glove/state", GloveState::SCHEMA_NAME, &schema)
        .unwrap();
    assert!(plain != left && left != right);

    // A namespaced contract channel must carry the contract's schema and payload size.
    let e = rec
        .add_topic("left/hand/command", GloveState::SCHEMA_NAME, &schema)
        .unwrap_err();
    assert!(
        matches!(e, RecordingError::UnknownSchema { ref topic, .. } if topic == "left/hand/command"),
        "{e}"
    );
    let e = rec
        .write(
            left,
            &RecordedMessage {
                topic: "left/glove/state",
                log_time_ns: 1,
                publish_time_ns: 1,
                sequence: 1,
                payload: &[0u8; 3],
            },
        )
        .unwrap_err();
    assert!(e.to_string().contains("left/glove/state"), "{e}");

    for (i, (id, channel)) in [
        (plain, "glove/state"),
        (left, "left/glove/state"),
        (right, "right/glove/state"),
    ]
    .into_iter()
    .enumerate()
    {
        let mut sample = GloveState::default();
        sample.header.seq = 1;
        sample.raw_position[0] = i as u16;
        let msg = RecordedMessage {
            topic: channel,
            ..RecordedMessage::from_sample(&sample, 10 + i as u64)
        };
        rec.write(id, &msg).unwrap();
    }
    rec.finish().unwrap();

    let info = info(&path).unwrap();
    let mut names: Vec<&str> = info.topics.iter().map(|t| t.topic.as_str()).collect();
    names.sort_unstable();
    assert_eq!(
        names,
        ["glove/state", "left/glove/state", "right/glove/state"]
    );
    let left_msgs: Vec<OwnedMessage> = read_messages(&path, &Filter::topics(["left/glove/state"]))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(left_msgs.len(), 1);
    let payload = GloveState::from_bytes(&left_msgs[0].payload).unwrap();
    assert_eq!(payload.raw_position[0], 1);
    // `decode` keeps to the plain topic: a namespaced sample is not mistaken for it.
    assert!(left_msgs[0].decode::<GloveState>().is_none());
    assert!(left_msgs[0].decode::<HandCommand>().is_none());

    // `read_samples` decodes one side's samples, named by its namespace.
    let ns = |n: &str| teleop_namespace::Namespace::new(n).unwrap();
    for (namespace, raw) in [(None, 0), (Some(ns("left")), 1), (Some(ns("right")), 2)] {
        let read = read_samples::<GloveState>(&path, namespace.as_ref()).unwrap();
        assert_eq!(read.undecodable, 0);
        let raws: Vec<u16> = read.samples.iter().map(|s| s.raw_position[0]).collect();
        assert_eq!(raws, [raw], "{namespace:?}");
    }
    let none = read_samples::<GloveState>(&path, Some(&ns("other"))).unwrap();
    assert!(none.samples.is_empty());
}
