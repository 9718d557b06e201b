//! Recordings of contract versions 1 and 2 are read converted to the current contract (the
//! version 1 sample, and two version 2 sessions recorded by the version 2 build: Allegro and
//! Shadow); unknown versions are refused by name; the current version round-trips and is
//! recorded as metadata.
#![allow(clippy::unwrap_used)]

mod common;

use std::{
    collections::{BTreeMap, HashMap, HashSet},
    path::{Path, PathBuf},
};

use common::{fill, leaves, raw_file, sample, value, write_bytes, Leaf, Value};
use teleop_msgs::{
    bus_state, device_model, fingertip_sensor, link_kind, text_of, DeviceInfo, HandState, Message,
    NodeHealth, Tactile, CDR_LE_HEADER, CONTRACT_VERSION,
};
use teleop_recording::{
    legacy::{
        DEVICE_INFO_V2_SCHEMA, HAND_STATE_V1_SCHEMA, NODE_HEALTH_V2_SCHEMA, TACTILE_V1_SCHEMA,
        V2_DETAIL_NAMES,
    },
    *,
};

const SAMPLE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../recordings/grasp.sample.mcap"
);
/// The default session with the Allegro Hand, 2 s, recorded by the contract version 2 build.
const ALLEGRO_V2: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../recordings/allegro-v2.sample.mcap"
);
/// The default session with the Shadow Hand, 2 s, recorded by the contract version 2 build.
const SHADOW_V2: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../recordings/shadow-v2.sample.mcap"
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

/// The bytes of the field `name` (all its primitive leaves, in order) of a payload.
fn field_bytes(schema: &str, bytes: &[u8], name: &str) -> Vec<u8> {
    let leaves = leaves(schema);
    let of_field: Vec<&Leaf> = leaves
        .iter()
        .filter(|l| {
            l.path == name
                || l.path.starts_with(&format!("{name}["))
                || l.path.starts_with(&format!("{name}."))
        })
        .collect();
    assert!(!of_field.is_empty(), "no field {name}");
    let start = of_field[0].offset;
    let end = of_field.last().unwrap().offset + leaf_size(of_field.last().unwrap());
    bytes[start..end].to_vec()
}

fn leaf_size(leaf: &Leaf) -> usize {
    match leaf.ty.as_str() {
        "uint8" | "int8" => 1,
        "uint16" | "int16" => 2,
        "uint32" | "int32" | "float32" => 4,
        _ => 8,
    }
}

/// `bytes` in a field of `size` bytes (zero padded).
fn padded(bytes: &[u8], size: usize) -> Vec<u8> {
    let mut out = bytes.to_vec();
    out.resize(size, 0);
    out
}

/// What version 3 makes of a version 2 `DeviceInfo`, written from the slot meanings of
/// version 2 per device kind (1 glove, 2 Revo2, 3 Allegro, 4 Shadow), independent of the
/// converter: the expected version 3 payload.
fn device_info_expected(v2: &[u8]) -> DeviceInfo {
    let f = |name: &str| field_bytes(DEVICE_INFO_V2_SCHEMA, v2, name);
    let id = u32::from_le_bytes(f("id").try_into().unwrap());
    let text = |name: &str| -> [u8; 32] { padded(&f(name), 32).try_into().unwrap() };
    let strip = |name: &str, prefix: &str| -> [u8; 32] {
        let t = text(name);
        let rest = t.strip_prefix(prefix.as_bytes()).unwrap_or(&t);
        padded(rest, 32).try_into().unwrap()
    };
    let mut want = DeviceInfo::from_bytes(&[0; size_of::<DeviceInfo>()]).unwrap();
    want.header = teleop_msgs::SampleHeader {
        seq: u64::from_le_bytes(f("header.seq").try_into().unwrap()),
        stamp_ns: u64::from_le_bytes(f("header.stamp_ns").try_into().unwrap()),
        origin_ns: u64::from_le_bytes(f("header.origin_ns").try_into().unwrap()),
        source_id: u32::from_le_bytes(f("header.source_id").try_into().unwrap()),
        reserved: u32::from_le_bytes(f("header.reserved").try_into().unwrap()),
    };
    want.model_name = text("model");
    match f("kind")[0] {
        1 => {
            want.device_model = device_model::GLOVE;
            want.link_kind = link_kind::SERIAL;
            want.bus_address = id;
        }
        3 => {
            want.device_model = device_model::ALLEGRO;
            want.link_kind = link_kind::CAN;
            want.bus_address = id;
            want.firmware_version = text("firmware_a");
            want.protocol = strip("firmware_b", "protocol ");
            want.serial_number = text("serial_a");
            want.link = padded(&text("serial_b"), 64).try_into().unwrap();
        }
        4 => {
            want.device_model = device_model::SHADOW;
            want.link_kind = link_kind::ETHERCAT;
            want.identity_serial = id;
            want.hardware_revision = strip("firmware_a", "palm revision ");
            want.serial_number = text("serial_a");
        }
        kind => {
            if kind == 2 {
                want.device_model = device_model::REVO2;
                want.link_kind = link_kind::ETHERCAT;
                want.identity_serial = id;
            } else {
                want.bus_address = id;
            }
            want.firmware_version = text("firmware_a");
            want.second_board_firmware = text("firmware_b");
            want.serial_number = text("serial_a");
            want.second_board_serial = text("serial_b");
        }
    }
    want
}

/// Checks a converted `NodeHealth` against the version 2 payload it came from: every counter
/// carried, the detail bytes named as the node that wrote them filled them.
fn check_health(v2: &[u8], v3: &NodeHealth) {
    let f = |name: &str| field_bytes(NODE_HEALTH_V2_SCHEMA, v2, name);
    let carried = [
        "header",
        "node_name",
        "loop_rate_hz",
        "input_count",
        "input_age_ms",
        "timeouts",
        "clamps",
        "errors",
        "dropped",
    ];
    for name in carried {
        let now = if name == "header" {
            v3.as_bytes()[..32].to_vec()
        } else {
            field_bytes(&NodeHealth::schema(), v3.as_bytes(), name)
        };
        assert_eq!(now, f(name), "{name}");
    }
    let detail = f("detail");
    let name = text_of(&f("node_name"));
    let node = name.rsplit('/').next().unwrap();
    let byte = |i: usize| f64::from(detail[i]);
    let u16_ms = |i: usize| f64::from(u16::from_le_bytes([detail[i], detail[i + 1]])) / 100.0;
    let want: Vec<(String, f64)> = match node {
        "feedback" => ["little", "ring", "middle", "index", "thumb"]
            .iter()
            .enumerate()
            .map(|(i, finger)| (format!("source_{finger}"), byte(i)))
            .collect(),
        "bridge" => vec![
            ("link_state".into(), byte(0)),
            ("rtt_ms".into(), u16_ms(1)),
            ("latency_p99_ms".into(), u16_ms(3)),
        ],
        // The Allegro's seven byte counters, in version 2's order (named once, in `legacy`).
        "allegro" => V2_DETAIL_NAMES
            .iter()
            .find(|(n, _)| *n == "allegro")
            .unwrap()
            .1
            .iter()
            .enumerate()
            .map(|(i, n)| (n.to_string(), byte(i)))
            .collect(),
        _ => (0..7)
            .filter(|&i| detail[i] != 0)
            .map(|i| (format!("detail_{i}"), byte(i)))
            .collect(),
    };
    assert_eq!(v3.details().collect::<Vec<_>>(), want, "{name}");
}

/// Compares every message read from `path` with the raw one recorded: converted ones field
/// by field, the others byte for byte. Returns how many of each topic were converted.
fn check_against_raw(path: &Path, messages: &[OwnedMessage]) -> HashMap<String, usize> {
    let raw = raw_messages(path);
    let mut converted: HashMap<String, usize> = HashMap::new();
    for m in messages {
        let (schema, bytes) = &raw[&(m.topic.clone(), m.log_time_ns, m.sequence)];
        let legacy = match m.topic.as_str() {
            "hand/state" | "hand/tactile" if schema == v1_schema_of(&m.topic).unwrap() => {
                let v1_schema = v1_schema_of(&m.topic).unwrap();
                let now_schema = if m.topic == HandState::TOPIC {
                    HandState::schema()
                } else {
                    Tactile::schema()
                };
                check_converted(v1_schema, bytes, &now_schema, &m.payload);
                true
            }
            "device/info" if schema == DEVICE_INFO_V2_SCHEMA => {
                let got: DeviceInfo = m.decode().unwrap();
                assert_eq!(got, device_info_expected(bytes));
                true
            }
            "health" if schema == NODE_HEALTH_V2_SCHEMA => {
                check_health(bytes, &m.decode().unwrap());
                true
            }
            _ => false,
        };
        if legacy {
            *converted.entry(m.topic.clone()).or_default() += 1;
        } else {
            // Unchanged types: the recorded bytes.
            assert_eq!(&m.payload, bytes, "{}", m.topic);
        }
    }
    converted
}

/// The topics `info` says are converted, with the version each is converted from.
fn converted_topics(info: &RecordingInfo) -> Vec<(&str, u32)> {
    info.topics
        .iter()
        .filter_map(|t| Some((t.topic.as_str(), t.converted_from?)))
        .collect()
}

/// Every message of a file, read.
fn all_messages(path: &Path) -> Vec<OwnedMessage> {
    read_messages(path, &Filter::all())
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap()
}

#[test]
fn the_version_1_sample_recording_reads_converted() {
    let path = Path::new(SAMPLE);
    let info = info(path).unwrap();
    assert!(info.complete);
    // Version 1's `DeviceInfo` and `NodeHealth` have version 2's layout.
    assert_eq!(
        converted_topics(&info),
        [
            ("device/info", 2),
            ("hand/state", 1),
            ("hand/tactile", 1),
            ("health", 2)
        ]
    );
    assert!(
        !info.metadata.iter().any(|(n, _)| n == CONTRACT_METADATA),
        "written before contract version 2"
    );
    let messages = all_messages(path);
    assert_eq!(messages.len() as u64, info.messages);
    let converted = check_against_raw(path, &messages);
    let count = |topic: &str| {
        info.topics
            .iter()
            .find(|t| t.topic == topic)
            .unwrap()
            .messages
    };
    for topic in ["hand/state", "hand/tactile", "health", "device/info"] {
        assert_eq!(converted[topic] as u64, count(topic), "{topic}");
    }

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
    // The Revo2's two boards and the glove, by name.
    let devices: Vec<DeviceInfo> = messages.iter().filter_map(|m| m.decode()).collect();
    let revo2 = devices
        .iter()
        .find(|d| d.device_model == device_model::REVO2)
        .unwrap();
    assert_eq!(
        revo2.named_fields(),
        [
            ("device_model", "revo2".to_string()),
            ("link_kind", "ethercat".to_string()),
            ("identity_serial", "42".to_string()),
            ("model_name", "BrainCo-Revo2Slave".to_string()),
            ("serial_number", "RV2C24110000042".to_string()),
            ("firmware_version", "1.4.2".to_string()),
            ("second_board_serial", "RV2W24110000042".to_string()),
            ("second_board_firmware", "0.9.7".to_string()),
        ]
    );
    let glove = devices
        .iter()
        .find(|d| d.device_model == device_model::GLOVE)
        .unwrap();
    assert_eq!(
        (
            glove.link_kind,
            glove.bus_address,
            text_of(&glove.model_name)
        ),
        (link_kind::SERIAL, 1, "EH55BF1".to_string())
    );
    // The force feedback's contact sources, named: the fingertips touched the ball (tactile).
    let health: Vec<NodeHealth> = messages.iter().filter_map(|m| m.decode()).collect();
    assert!(health.iter().any(|h| h.name() == "feedback"
        && h.detail("source_index") == Some(f64::from(teleop_msgs::contact_source::TACTILE))));
}

/// Reads a version 2 sample: `hand/state` and the other unchanged types as recorded,
/// `device/info` and `health` converted from version 2. Returns the messages.
fn read_v2_sample(path: &Path) -> Vec<OwnedMessage> {
    let info = info(path).unwrap();
    assert!(info.complete);
    assert_eq!(
        converted_topics(&info),
        [("device/info", 2), ("health", 2)],
        "{}",
        path.display()
    );
    let contract: Vec<_> = info
        .metadata
        .iter()
        .filter(|(n, _)| n == CONTRACT_METADATA)
        .map(|(_, fields)| fields.get("version").map(String::as_str))
        .collect();
    assert_eq!(contract, [Some("2")]);
    let messages = all_messages(path);
    assert_eq!(messages.len() as u64, info.messages);
    let converted = check_against_raw(path, &messages);
    for topic in ["health", "device/info"] {
        let recorded = info.topics.iter().find(|t| t.topic == topic).unwrap();
        assert_eq!(converted[topic] as u64, recorded.messages, "{topic}");
    }
    messages
}

/// Reads a version 2 sample of one hand (as [`read_v2_sample`]): its converted `DeviceInfo`
/// has `fields` by name, and its `hand/state` (version 2's, unchanged) shows the hand with the
/// link up on `link` with `joint_count` joints. Returns the messages.
fn read_v2_hand_sample(
    path: &str,
    model: u8,
    fields: &[(&str, &str)],
    link: u8,
    joint_count: u8,
) -> Vec<OwnedMessage> {
    let messages = read_v2_sample(Path::new(path));
    let devices: Vec<DeviceInfo> = messages.iter().filter_map(|m| m.decode()).collect();
    let device = devices.iter().find(|d| d.device_model == model).unwrap();
    let want: Vec<(&str, String)> = fields.iter().map(|&(n, v)| (n, v.to_string())).collect();
    assert_eq!(device.named_fields(), want, "{path}");
    let states: Vec<HandState> = messages.iter().filter_map(|m| m.decode()).collect();
    assert!(
        states.iter().any(|s| s.link_up == 1
            && s.link_kind == link
            && s.hand_model == model
            && s.joint_count == joint_count),
        "{path}"
    );
    messages
}

#[test]
fn the_version_2_allegro_sample_reads_converted() {
    // Version 2 kept the link in `serial_b` (32 bytes: the path is cut there).
    let messages = read_v2_hand_sample(
        ALLEGRO_V2,
        device_model::ALLEGRO,
        &[
            ("device_model", "allegro"),
            ("link_kind", "can"),
            ("bus_address", "0"),
            ("model_name", "Wonik Allegro Hand v4"),
            ("serial_number", "SAH04000AR0042"),
            ("firmware_version", "hw 0x0401 fw 0x0102"),
            ("protocol", "v4"),
            ("link", "slcan:/tmp/v2fix/run/teleop-alle"),
        ],
        link_kind::CAN,
        16,
    );
    let health: Vec<NodeHealth> = messages.iter().filter_map(|m| m.decode()).collect();
    let node = health.iter().rev().find(|h| h.name() == "allegro").unwrap();
    assert_eq!(node.detail("protocol_generation"), Some(4.0));
    assert_eq!(
        node.detail("bus_state"),
        Some(f64::from(bus_state::CAN_ERROR_ACTIVE))
    );
    assert!(node.detail("max_temperature_c") > Some(0.0));
}

#[test]
fn the_version_2_shadow_sample_reads_converted() {
    read_v2_hand_sample(
        SHADOW_V2,
        device_model::SHADOW,
        &[
            ("device_model", "shadow"),
            ("link_kind", "ethercat"),
            ("identity_serial", "1178"),
            ("model_name", "Shadow Hand E (SR06 palm, 0220)"),
            ("serial_number", "1178"),
            ("hardware_revision", "0"),
        ],
        link_kind::ETHERCAT,
        24,
    );
}

/// The byte offset of the primitive field `path` (`kind`, `serial_a[0]`) in a payload of
/// `schema`.
fn offset_of(schema: &str, path: &str) -> usize {
    leaves(schema)
        .into_iter()
        .find(|l| l.path == path)
        .unwrap_or_else(|| panic!("no field {path}"))
        .offset
}

/// The one message of a file holding a version 2 `DeviceInfo` `payload`, read converted.
fn read_v2_device_info(dir: &Path, payload: &[u8]) -> DeviceInfo {
    let path = cdr_file(
        dir,
        "device/info",
        DeviceInfo::SCHEMA_NAME,
        DEVICE_INFO_V2_SCHEMA,
        payload,
    );
    let messages = all_messages(&path);
    assert_eq!(messages.len(), 1);
    messages[0].decode().unwrap()
}

#[test]
fn every_version_2_slot_lands_in_its_named_field() {
    let dir = tempfile::tempdir().unwrap();
    let size = 200;
    let kind_at = offset_of(DEVICE_INFO_V2_SCHEMA, "kind");
    // Each device kind of version 2 and one it did not number; text slots full of distinctive
    // bytes (no zero: all 32 bytes are text).
    for kind in [1u8, 2, 3, 4, 9] {
        let mut payload = v1_payload(DEVICE_INFO_V2_SCHEMA, size, u64::from(kind));
        payload[kind_at] = kind;
        let got = read_v2_device_info(dir.path(), &payload);
        assert_eq!(got, device_info_expected(&payload), "kind {kind}");
        let expected_model = [
            device_model::GLOVE,
            device_model::REVO2,
            device_model::ALLEGRO,
            device_model::SHADOW,
        ]
        .get(usize::from(kind) - 1)
        .copied()
        .unwrap_or(device_model::UNKNOWN);
        assert_eq!(got.device_model, expected_model, "kind {kind}");
    }
    // Prefixes version 2 wrote are dropped: "protocol v4" is v4, "palm revision 7" is 7.
    for (kind, slot, text, field) in [
        (3u8, "firmware_b", "protocol v4", "protocol"),
        (4, "firmware_a", "palm revision 7", "hardware_revision"),
    ] {
        let mut payload = vec![0u8; size];
        payload[kind_at] = kind;
        let at = offset_of(DEVICE_INFO_V2_SCHEMA, &format!("{slot}[0]"));
        payload[at..at + text.len()].copy_from_slice(text.as_bytes());
        let got = read_v2_device_info(dir.path(), &payload);
        let value = got
            .named_fields()
            .into_iter()
            .find(|(name, _)| *name == field)
            .map(|(_, v)| v);
        assert_eq!(value.as_deref(), text.rsplit(' ').next(), "{field}");
    }
}

#[test]
fn every_version_2_health_detail_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let at = |path: &str| offset_of(NODE_HEALTH_V2_SCHEMA, path);
    for node in ["feedback", "left/bridge", "right/allegro", "retarget"] {
        let mut payload = v1_payload(NODE_HEALTH_V2_SCHEMA, 128, 5);
        let name_at = at("node_name[0]");
        payload[name_at..name_at + 32].fill(0);
        payload[name_at..name_at + node.len()].copy_from_slice(node.as_bytes());
        // One zero detail byte: a node without names of its own keeps only the others.
        payload[at("detail[2]")] = 0;
        let path = cdr_file(
            dir.path(),
            "health",
            NodeHealth::SCHEMA_NAME,
            NODE_HEALTH_V2_SCHEMA,
            &payload,
        );
        let got: NodeHealth = all_messages(&path)[0].decode().unwrap();
        check_health(&payload, &got);
        let named = got.details().count();
        let want = match node {
            "feedback" => 5,
            "left/bridge" => 3,
            "right/allegro" => 7,
            _ => 6,
        };
        assert_eq!(named, want, "{node}");
    }
    // A version 2 message of the wrong size is a bad message naming the version.
    let path = cdr_file(
        dir.path(),
        "health",
        NodeHealth::SCHEMA_NAME,
        NODE_HEALTH_V2_SCHEMA,
        &[0u8; 127],
    );
    let err = read_messages(&path, &Filter::all())
        .unwrap()
        .find_map(Result::err)
        .unwrap();
    assert!(err.to_string().contains("contract version 2"), "{err}");
}

#[test]
fn a_killed_version_1_recording_reads_converted_too() {
    // Cut before the summary: the streaming reader (file order, no indexes) converts as well.
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(SAMPLE).unwrap();
    let cut = write_bytes(dir.path(), "cut.mcap", &bytes[..bytes.len() / 2]);
    let cut_info = info(&cut).unwrap();
    assert!(!cut_info.complete);
    let topics: Vec<&str> = converted_topics(&cut_info)
        .into_iter()
        .map(|(topic, _)| topic)
        .collect();
    assert_eq!(
        topics,
        ["device/info", "hand/state", "hand/tactile", "health"]
    );
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

/// A file of one CDR channel and one message: `payload` after the CDR header.
fn cdr_file(
    dir: &Path,
    topic: &str,
    schema_name: &str,
    schema_text: &str,
    payload: &[u8],
) -> PathBuf {
    let data = [&CDR_LE_HEADER[..], payload].concat();
    raw_file(dir, topic, schema_name, schema_text, "cdr", &data)
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
            payload[offset_of(v1_schema, "fingertip_count")] = 3;
        }
        let path = cdr_file(dir.path(), topic, schema_name, v1_schema, &payload);
        let messages: Vec<OwnedMessage> = read_messages(&path, &Filter::all())
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(messages.len(), 1);
        assert_eq!(messages[0].schema_name, schema_name);
        check_converted(v1_schema, &payload, &v2_schema, &messages[0].payload);

        // A version 1 message of the wrong size is a bad message naming the version.
        let short = cdr_file(dir.path(), topic, schema_name, v1_schema, &payload[1..]);
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
    let path = cdr_file(
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
    let path = cdr_file(
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
    let path = dir.path().join("current.mcap");
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
