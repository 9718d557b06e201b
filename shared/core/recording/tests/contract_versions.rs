//! Recordings of contract version 1 are read converted to the current contract; unknown
//! versions are refused by name; the current version round-trips and is recorded as metadata.
#![allow(clippy::unwrap_used)]

mod common;

use std::{
    collections::{BTreeMap, HashMap, HashSet},
    io::BufWriter,
    path::{Path, PathBuf},
};

use common::{fill, leaves, sample, value, Leaf, Value};
use teleop_msgs::{
    bus_state, fingertip_sensor, link_kind, HandState, Message, Tactile, CDR_LE_HEADER,
    CONTRACT_VERSION,
};
use teleop_recording::{
    legacy::{HAND_STATE_V1_SCHEMA, TACTILE_V1_SCHEMA},
    *,
};

const SAMPLE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../recordings/grasp.sample.mcap"
);

/// Leaf values of a payload by path (`joints[3].speed`).
fn values(schema: &str, bytes: &[u8]) -> HashMap<String, Value> {
    leaves(schema)
        .iter()
        .map(|leaf| (leaf.path.clone(), value(bytes, leaf)))
        .collect()
}

/// The version 1 path a version 2 leaf comes from, or the value version 2 gives it when it is
/// new. `v2_path` of `HandState` or `Tactile`.
enum Origin {
    From(String),
    New(Value),
}

fn origin(v2_path: &str, v1: &HashMap<String, Value>) -> Origin {
    let renamed = [
        ("bus_state", "al_state"),
        ("link_error_code", "al_status_code"),
        ("link_errors", "wkc_errors"),
    ];
    if let Some((_, old)) = renamed.iter().find(|(new, _)| *new == v2_path) {
        return Origin::From(old.to_string());
    }
    if v2_path == "link_kind" {
        return Origin::New(Value::Int(link_kind::ETHERCAT.into()));
    }
    if v2_path.starts_with("reserved[") && !v1.contains_key(v2_path) {
        return Origin::New(Value::Int(0));
    }
    if v2_path.ends_with(".effort") {
        return Origin::New(Value::Float(f64::NAN));
    }
    if v2_path.ends_with(".pressure") || v2_path.ends_with(".temperature") {
        return Origin::New(Value::Int(0));
    }
    if let Some(tip) = v2_path
        .strip_prefix("fingertips[")
        .and_then(|p| p.strip_suffix("].sensor_kind"))
    {
        let used = match v1["fingertip_count"] {
            Value::Int(n) => n,
            Value::Float(_) => unreachable!(),
        };
        let kind = if tip.parse::<i128>().unwrap() < used {
            fingertip_sensor::REVO2_FORCE
        } else {
            fingertip_sensor::NONE
        };
        return Origin::New(Value::Int(kind.into()));
    }
    Origin::From(v2_path.to_string())
}

fn same(a: Value, b: Value) -> bool {
    match (a, b) {
        (Value::Float(x), Value::Float(y)) => {
            x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan())
        }
        (a, b) => a == b,
    }
}

/// Checks every leaf of the converted payload against the version 1 payload it came from.
fn check_converted(v1_schema: &str, v1_bytes: &[u8], v2_schema: &str, v2_bytes: &[u8]) {
    let v1 = values(v1_schema, v1_bytes);
    let v2 = values(v2_schema, v2_bytes);
    let mut carried = HashSet::new();
    for (path, got) in &v2 {
        let want = match origin(path, &v1) {
            Origin::From(old) => {
                let want = *v1
                    .get(&old)
                    .unwrap_or_else(|| panic!("{path}: no version 1 field {old}"));
                carried.insert(old);
                want
            }
            Origin::New(value) => value,
        };
        assert!(same(*got, want), "{path}: got {got:?}, want {want:?}");
    }
    // Every version 1 field arrives somewhere but the fingertips' reserved bytes (zero in
    // version 1, their place taken by the sensor kind).
    for path in v1.keys() {
        let dropped = path.starts_with("fingertips[") && path.ends_with("].reserved");
        assert_eq!(carried.contains(path), !dropped, "{path}");
    }
}

/// The raw messages of a file, by (topic, log time, sequence): schema text and payload.
fn raw_messages(path: &Path) -> HashMap<(String, u64, u32), (String, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let mut out = HashMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(&m.data[..4], &CDR_LE_HEADER);
        let key = (m.channel.topic.clone(), m.log_time, m.sequence);
        let text = String::from_utf8(schema.data.to_vec()).unwrap();
        assert!(out.insert(key, (text, m.data[4..].to_vec())).is_none());
    }
    out
}

fn v1_schema_of(topic: &str) -> Option<&'static str> {
    match topic {
        "hand/state" => Some(HAND_STATE_V1_SCHEMA),
        "hand/tactile" => Some(TACTILE_V1_SCHEMA),
        _ => None,
    }
}

fn check_against_raw(path: &Path, messages: &[OwnedMessage]) -> HashMap<String, usize> {
    let raw = raw_messages(path);
    let mut converted: HashMap<String, usize> = HashMap::new();
    for m in messages {
        let (schema, bytes) = &raw[&(m.topic.clone(), m.log_time_ns, m.sequence)];
        match v1_schema_of(&m.topic) {
            Some(v1_schema) => {
                assert_eq!(schema, v1_schema, "{}", m.topic);
                let v2_schema = if m.topic == HandState::TOPIC {
                    HandState::schema()
                } else {
                    Tactile::schema()
                };
                check_converted(v1_schema, bytes, &v2_schema, &m.payload);
                *converted.entry(m.topic.clone()).or_default() += 1;
            }
            // Unchanged types: the recorded bytes.
            None => assert_eq!(&m.payload, bytes, "{}", m.topic),
        }
    }
    converted
}

/// The topics `info` says are converted, each from version 1.
fn converted_topics(info: &RecordingInfo) -> Vec<&str> {
    info.topics
        .iter()
        .filter(|t| t.converted_from.is_some())
        .inspect(|t| assert_eq!(t.converted_from, Some(1), "{}", t.topic))
        .map(|t| t.topic.as_str())
        .collect()
}

#[test]
fn the_version_1_sample_recording_reads_converted() {
    let path = Path::new(SAMPLE);
    let info = info(path).unwrap();
    assert!(info.complete);
    assert_eq!(converted_topics(&info), ["hand/state", "hand/tactile"]);
    assert!(
        !info.metadata.iter().any(|(n, _)| n == CONTRACT_METADATA),
        "written before contract version 2"
    );
    let messages: Vec<OwnedMessage> = read_messages(path, &Filter::all())
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(messages.len() as u64, info.messages);
    let converted = check_against_raw(path, &messages);
    let count = |topic: &str| {
        info.topics
            .iter()
            .find(|t| t.topic == topic)
            .unwrap()
            .messages
    };
    assert_eq!(converted["hand/state"] as u64, count("hand/state"));
    assert_eq!(converted["hand/tactile"] as u64, count("hand/tactile"));

    // What the session did is still there: the hand in OP, the fingertips touching the ball.
    let states: Vec<HandState> = messages.iter().filter_map(|m| m.decode()).collect();
    assert_eq!(states.len() as u64, count("hand/state"));
    assert!(states.iter().any(|s| s.link_up == 1
        && s.bus_state == bus_state::AL_OP
        && s.link_kind == link_kind::ETHERCAT
        && s.joint_count == 6
        && s.active_joints().iter().any(|j| j.position > 0.1)));
    let tactile: Vec<Tactile> = messages.iter().filter_map(|m| m.decode()).collect();
    assert!(tactile.iter().any(|t| t
        .active_fingertips()
        .iter()
        .any(|f| f.normal_n > 1.0 && f.sensor_kind == fingertip_sensor::REVO2_FORCE)));
}

#[test]
fn a_killed_version_1_recording_reads_converted_too() {
    // Cut before the summary: the streaming reader (file order, no indexes) converts as well.
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(SAMPLE).unwrap();
    let cut = write(dir.path(), "cut.mcap", &bytes[..bytes.len() / 2]);
    let cut_info = info(&cut).unwrap();
    assert!(!cut_info.complete);
    assert_eq!(converted_topics(&cut_info), ["hand/state", "hand/tactile"]);
    let messages: Vec<OwnedMessage> = read_messages(&cut, &Filter::topics(["hand/state"]))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert!(messages.len() > 100, "{}", messages.len());
    let raw = raw_messages(Path::new(SAMPLE));
    for m in &messages {
        let (_, v1) = &raw[&(m.topic.clone(), m.log_time_ns, m.sequence)];
        check_converted(HAND_STATE_V1_SCHEMA, v1, &HandState::schema(), &m.payload);
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// A file with one channel and one message, written with the MCAP library directly.
fn raw_file(
    dir: &Path,
    topic: &str,
    schema_name: &str,
    schema_text: &str,
    payload: &[u8],
) -> PathBuf {
    let path = dir.join(format!("{}.mcap", topic.replace('/', "_")));
    let file = std::fs::File::create(&path).unwrap();
    let mut w = mcap::WriteOptions::new()
        .create(BufWriter::new(file))
        .unwrap();
    let schema = w
        .add_schema(schema_name, "ros2msg", schema_text.as_bytes())
        .unwrap();
    let channel = w
        .add_channel(schema, topic, "cdr", &BTreeMap::new())
        .unwrap();
    w.write_to_known_channel(
        &mcap::records::MessageHeader {
            channel_id: channel,
            sequence: 7,
            log_time: 10,
            publish_time: 9,
        },
        &[&CDR_LE_HEADER[..], payload].concat(),
    )
    .unwrap();
    w.finish().unwrap();
    path
}

/// A version 1 payload of `size` bytes with a distinctive value in every field.
fn v1_payload(schema: &str, size: usize, seed: u64) -> Vec<u8> {
    let leaves: Vec<Leaf> = leaves(schema);
    let mut bytes = vec![0u8; size];
    fill(&mut bytes, &leaves, seed);
    bytes
}

#[test]
fn every_version_1_field_is_carried_over() {
    let dir = tempfile::tempdir().unwrap();
    for (topic, v1_schema, v1_size, v2_schema) in [
        ("hand/state", HAND_STATE_V1_SCHEMA, 432, HandState::schema()),
        ("hand/tactile", TACTILE_V1_SCHEMA, 136, Tactile::schema()),
    ] {
        let mut payload = v1_payload(v1_schema, v1_size, 3);
        let schema_name = if topic == "hand/state" {
            HandState::SCHEMA_NAME
        } else {
            Tactile::SCHEMA_NAME
        };
        if topic == "hand/tactile" {
            // Three fingertips used, two not: their sensor kind differs.
            let count = leaves(v1_schema)
                .into_iter()
                .find(|l| l.path == "fingertip_count")
                .unwrap();
            payload[count.offset] = 3;
        }
        let path = raw_file(dir.path(), topic, schema_name, v1_schema, &payload);
        let messages: Vec<OwnedMessage> = read_messages(&path, &Filter::all())
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(messages.len(), 1);
        assert_eq!(messages[0].schema_name, schema_name);
        check_converted(v1_schema, &payload, &v2_schema, &messages[0].payload);

        // A version 1 message of the wrong size is a bad message naming the version.
        let short = raw_file(dir.path(), topic, schema_name, v1_schema, &payload[1..]);
        let err = read_messages(&short, &Filter::all())
            .unwrap()
            .find_map(Result::err)
            .unwrap();
        assert!(matches!(err, RecordingError::BadMessage { .. }), "{err}");
        assert!(err.to_string().contains("contract version 1"), "{err}");
    }
}

#[test]
fn an_unknown_version_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let unknown = HAND_STATE_V1_SCHEMA.replace("uint32 wkc_errors", "uint64 wkc_errors");
    let path = raw_file(
        dir.path(),
        "hand/state",
        HandState::SCHEMA_NAME,
        &unknown,
        &[0u8; 436],
    );
    let err = read_messages(&path, &Filter::all()).unwrap_err();
    match &err {
        RecordingError::WrongSchemaVersion {
            topic,
            schema,
            found,
            ..
        } => {
            assert_eq!(topic, "hand/state");
            assert_eq!(schema, HandState::SCHEMA_NAME);
            assert_eq!(*found, unknown);
        }
        other => panic!("{other}"),
    }
    let text = err.to_string();
    for part in [
        &path.display().to_string(),
        "hand/state",
        HandState::SCHEMA_NAME,
        "unknown version",
    ] {
        assert!(text.contains(part), "{part} missing: {text}");
    }
    // A version 1 schema text on another topic is not version 1 of that topic.
    let path = raw_file(
        dir.path(),
        "hand/tactile",
        Tactile::SCHEMA_NAME,
        HAND_STATE_V1_SCHEMA,
        &[0u8; 432],
    );
    let err = read_messages(&path, &Filter::all()).unwrap_err();
    assert!(
        matches!(err, RecordingError::WrongSchemaVersion { .. }),
        "{err}"
    );
}

#[test]
fn the_current_version_round_trips_and_is_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("v2.mcap");
    // A `contract` record given by the caller (copied from a version 1 file's reprocessing,
    // say) is replaced by the recorder's own.
    let stale = BTreeMap::from([("version".to_string(), "1".to_string())]);
    let mut rec = Recorder::create(
        &path,
        WriterOptions::default(),
        &[(CONTRACT_METADATA.to_string(), stale.clone())],
    )
    .unwrap();
    let err = rec.add_metadata(CONTRACT_METADATA, stale).unwrap_err();
    assert!(matches!(err, RecordingError::InvalidUse { .. }), "{err}");
    // Earlier versions are read, never written.
    let err = rec
        .add_topic("hand/state", HandState::SCHEMA_NAME, HAND_STATE_V1_SCHEMA)
        .unwrap_err();
    assert!(
        matches!(err, RecordingError::WrongSchemaVersion { .. }),
        "{err}"
    );
    let hand = rec.add_message_type::<HandState>().unwrap();
    let tactile = rec.add_message_type::<Tactile>().unwrap();
    let mut state: HandState = sample(5, 1, 100);
    state.joints[0].effort = f32::NAN;
    state.joints[1].effort = 0.75;
    state.link_kind = link_kind::CAN;
    state.bus_state = bus_state::CAN_ERROR_PASSIVE;
    let mut tips: Tactile = sample(6, 1, 100);
    tips.fingertips[2].sensor_kind = fingertip_sensor::PST_PRESSURE;
    tips.fingertips[2].pressure = -1234;
    tips.fingertips[2].temperature = 3000;
    rec.write(hand, &RecordedMessage::from_sample(&state, 200))
        .unwrap();
    rec.write(tactile, &RecordedMessage::from_sample(&tips, 201))
        .unwrap();
    rec.finish().unwrap();

    let info = info(&path).unwrap();
    assert!(converted_topics(&info).is_empty());
    let contract: Vec<_> = info
        .metadata
        .iter()
        .filter(|(n, _)| n == CONTRACT_METADATA)
        .collect();
    assert_eq!(contract.len(), 1, "{:?}", info.metadata);
    assert_eq!(
        contract[0].1.get("version"),
        Some(&CONTRACT_VERSION.to_string())
    );
    let messages: Vec<OwnedMessage> = read_messages(&path, &Filter::all())
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(messages.len(), 2);
    assert_eq!(messages[0].payload, state.as_bytes());
    assert_eq!(messages[1].payload, tips.as_bytes());
    let back: HandState = messages[0].decode().unwrap();
    assert!(back.joints[0].effort.is_nan());
    assert_eq!(back.joints[1].effort, 0.75);
    assert_eq!(back.bus_state, bus_state::CAN_ERROR_PASSIVE);
    let back: Tactile = messages[1].decode().unwrap();
    assert_eq!(back.fingertips[2].pressure, -1234);
}
