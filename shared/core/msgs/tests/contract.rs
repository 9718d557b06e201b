//! Checks the message contract: every schema describes the struct's real layout as ROS 2 CDR,
//! payload bytes round-trip, and the topic registry is consistent.
#![allow(clippy::unwrap_used)]

use std::collections::HashMap;

use iceoryx2::prelude::ZeroCopySend;
use proptest::prelude::*;
use teleop_msgs::*;

/// Parses a ROS 2 `.msg` schema (top-level fields, then `MSG:` sections) and lays it out as CDR
/// would after the 4-byte encapsulation header: every primitive aligned to its own size, fixed
/// arrays without a length prefix, nested structs without tail padding. Returns each primitive
/// leaf as (path, offset, size) and the total size. Independent of the Rust structs on purpose.
fn cdr_layout(schema: &str) -> (Vec<(String, usize, usize)>, usize) {
    let separator = format!("{}\n", "=".repeat(80));
    let mut sections = schema.split(separator.as_str());
    let top = sections.next().unwrap();
    let mut nested: HashMap<String, Vec<(String, String)>> = HashMap::new();
    for section in sections {
        let (first, body) = section.split_once('\n').unwrap();
        let name = first.strip_prefix("MSG: ").expect("MSG: line").to_string();
        nested.insert(name, parse_fields(body));
    }
    let mut leaves = Vec::new();
    let mut offset = 0;
    for (ty, name) in parse_fields(top) {
        lay_out(&ty, &name, &nested, &mut offset, &mut leaves);
    }
    (leaves, offset)
}

fn parse_fields(body: &str) -> Vec<(String, String)> {
    body.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let mut parts = l.split_whitespace();
            let ty = parts.next().unwrap().to_string();
            let name = parts.next().unwrap().to_string();
            assert!(parts.next().is_none(), "extra tokens in {l:?}");
            let re_ok = name.chars().next().unwrap().is_ascii_lowercase()
                && name
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
                && !name.contains("__")
                && !name.ends_with('_');
            assert!(re_ok, "field name {name:?} is not a valid ROS 2 field name");
            (ty, name)
        })
        .collect()
}

fn primitive_size(ty: &str) -> Option<usize> {
    Some(match ty {
        "uint8" | "int8" | "byte" | "char" | "bool" => 1,
        "uint16" | "int16" => 2,
        "uint32" | "int32" | "float32" => 4,
        "uint64" | "int64" | "float64" => 8,
        _ => return None,
    })
}

fn lay_out(
    ty: &str,
    path: &str,
    nested: &HashMap<String, Vec<(String, String)>>,
    offset: &mut usize,
    leaves: &mut Vec<(String, usize, usize)>,
) {
    if let Some((elem, count)) = ty.strip_suffix(']').and_then(|t| t.split_once('[')) {
        let count: usize = count.parse().expect("fixed-size arrays only");
        for i in 0..count {
            lay_out(elem, &format!("{path}[{i}]"), nested, offset, leaves);
        }
    } else if let Some(size) = primitive_size(ty) {
        *offset = offset.div_ceil(size) * size;
        leaves.push((path.to_string(), *offset, size));
        *offset += size;
    } else {
        let fields = nested
            .get(ty)
            .unwrap_or_else(|| panic!("no MSG: section for {ty}"));
        for (fty, fname) in fields {
            lay_out(fty, &format!("{path}.{fname}"), nested, offset, leaves);
        }
    }
}

/// The repr(C) side: flatten the field tables of the struct and its nested types.
fn repr_c_layout(fields: &[Field], base: usize, path: &str, out: &mut Vec<(String, usize, usize)>) {
    let nested: HashMap<&str, &[Field]> = [
        (SampleHeader::ROS_NAME, SampleHeader::FIELDS),
        (JointCommand::ROS_NAME, JointCommand::FIELDS),
        (JointState::ROS_NAME, JointState::FIELDS),
        (Fingertip::ROS_NAME, Fingertip::FIELDS),
        (HealthDetail::ROS_NAME, HealthDetail::FIELDS),
    ]
    .into_iter()
    .collect();
    for f in fields {
        let name = if path.is_empty() {
            f.name.to_string()
        } else {
            format!("{path}.{}", f.name)
        };
        let (elem, count) = match f.ros_type.strip_suffix(']').and_then(|t| t.split_once('[')) {
            Some((e, c)) => (e, Some(c.parse::<usize>().unwrap())),
            None => (f.ros_type, None),
        };
        let n = count.unwrap_or(1);
        let stride = f.size / n;
        for i in 0..n {
            let p = if count.is_some() {
                format!("{name}[{i}]")
            } else {
                name.clone()
            };
            let at = base + f.offset + i * stride;
            match primitive_size(elem) {
                Some(size) => {
                    assert_eq!(size, stride, "{p}: Rust size differs from the ROS type");
                    out.push((p, at, size));
                }
                None => repr_c_layout(nested[elem], at, &p, out),
            }
        }
    }
}

struct CheckLayout;
impl TopicVisitor for CheckLayout {
    type Output = ();
    fn visit<M: Message>(self) {
        let schema = M::schema();
        let (cdr, cdr_size) = cdr_layout(&schema);
        let mut rust = Vec::new();
        repr_c_layout(M::FIELDS, 0, "", &mut rust);
        assert_eq!(
            cdr,
            rust,
            "{}: CDR layout differs from repr(C)",
            M::SCHEMA_NAME
        );
        assert_eq!(cdr_size, size_of::<M>(), "{}: CDR size", M::SCHEMA_NAME);
        assert_eq!(align_of::<M>(), 8);
        // iceoryx2 matches services by this name: the schema name and the contract version.
        let type_name = unsafe { <M as ZeroCopySend>::type_name() };
        assert_eq!(type_name, M::TYPE_NAME);
        assert_eq!(type_name, format!("{}@v{CONTRACT_VERSION}", M::SCHEMA_NAME));
    }
}

#[test]
fn every_schema_matches_the_struct_layout_as_cdr() {
    for topic in topics() {
        visit_topic(topic.name, CheckLayout).unwrap();
    }
}

#[test]
fn contract_version_3_layout_of_the_hand_types() {
    assert_eq!(CONTRACT_VERSION, 3);
    assert_eq!(HandState::TYPE_NAME, "teleop_msgs/msg/HandState@v3");
    assert_eq!(size_of::<HandState>(), 536);
    assert_eq!(size_of::<Tactile>(), 176);
    assert_eq!(size_of::<JointState>(), 20);
    assert_eq!(size_of::<Fingertip>(), 28);
    let offset = |fields: &[Field], name: &str| {
        fields
            .iter()
            .find(|f| f.name == name)
            .map(|f| (f.offset, f.ros_type))
            .unwrap()
    };
    assert_eq!(offset(HandState::FIELDS, "link_kind"), (37, "uint8"));
    assert_eq!(offset(HandState::FIELDS, "bus_state"), (38, "uint8"));
    assert_eq!(offset(HandState::FIELDS, "link_error_code"), (44, "uint32"));
    assert_eq!(offset(HandState::FIELDS, "link_errors"), (48, "uint32"));
    assert_eq!(offset(HandState::FIELDS, "lost_frames"), (52, "uint32"));
    assert_eq!(offset(JointState::FIELDS, "effort"), (8, "float32"));
    assert_eq!(offset(Fingertip::FIELDS, "pressure"), (16, "int32"));
    assert_eq!(offset(Fingertip::FIELDS, "temperature"), (20, "int32"));
    assert_eq!(offset(Fingertip::FIELDS, "sensor_kind"), (27, "uint8"));
    for schema in [HandState::schema(), Tactile::schema()] {
        for gone in ["al_state", "al_status_code", "wkc_errors"] {
            assert!(!schema.contains(gone), "{gone} in {schema}");
        }
    }
}

/// Offset and ROS type of the field `name` of a field table.
fn field(fields: &[Field], name: &str) -> (usize, &'static str) {
    fields
        .iter()
        .find(|f| f.name == name)
        .map(|f| (f.offset, f.ros_type))
        .unwrap_or_else(|| panic!("no field {name}"))
}

#[test]
fn contract_version_3_device_info_and_health_layout() {
    assert_eq!(size_of::<DeviceInfo>(), 336);
    assert_eq!(field(DeviceInfo::FIELDS, "device_model"), (32, "uint8"));
    assert_eq!(field(DeviceInfo::FIELDS, "link_kind"), (33, "uint8"));
    assert_eq!(field(DeviceInfo::FIELDS, "bus_address"), (40, "uint32"));
    assert_eq!(field(DeviceInfo::FIELDS, "identity_serial"), (44, "uint32"));
    assert_eq!(field(DeviceInfo::FIELDS, "model_name"), (48, "uint8[32]"));
    assert_eq!(field(DeviceInfo::FIELDS, "link"), (272, "uint8[64]"));
    assert_eq!(size_of::<NodeHealth>(), 384);
    assert_eq!(size_of::<HealthDetail>(), 32);
    assert_eq!(field(NodeHealth::FIELDS, "detail_count"), (69, "uint8"));
    assert_eq!(
        field(NodeHealth::FIELDS, "details"),
        (128, "teleop_msgs/HealthDetail[8]")
    );
    // Slot names of version 2 are gone.
    for gone in ["firmware_a", "serial_b", "uint32 id\n", "uint8 kind"] {
        assert!(!DeviceInfo::schema().contains(gone), "{gone}");
    }
    assert!(!NodeHealth::schema().contains("uint8[7] detail"));
    // A default (zeroed) payload: every field zero, whatever the array lengths.
    assert!(DeviceInfo::default().as_bytes().iter().all(|&b| b == 0));
}

#[test]
fn one_numbering_of_devices_with_names() {
    let models = [
        (device_model::REVO2, "revo2"),
        (device_model::ALLEGRO, "allegro"),
        (device_model::SHADOW, "shadow"),
        (device_model::GLOVE, "glove"),
        (device_model::LEAP, "leap"),
    ];
    for (id, name) in models {
        assert_eq!(device_model::name(id), name);
        assert_eq!(device_model::from_name(name), Some(id));
    }
    let mut ids: Vec<u8> = models.iter().map(|(id, _)| *id).collect();
    ids.push(device_model::UNKNOWN);
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(
        ids.len(),
        models.len() + 1,
        "every model has its own number"
    );
    assert_eq!(device_model::name(device_model::UNKNOWN), "unknown");
    assert_eq!(device_model::name(200), "unknown");
    assert_eq!(device_model::from_name("unknown"), None);
    assert_eq!(device_model::from_name("Revo2"), None);
}

#[test]
fn health_details_are_set_by_name_and_read_back() {
    let mut h = NodeHealth::default();
    assert_eq!(h.details().count(), 0);
    assert!(h.set_detail("reconnects", 1.0));
    assert!(h.set_detail("rtt_ms", 0.25));
    assert!(h.set_detail("reconnects", 3.0));
    assert_eq!(
        h.details().collect::<Vec<_>>(),
        vec![
            ("reconnects".to_string(), 3.0),
            ("rtt_ms".to_string(), 0.25)
        ]
    );
    assert_eq!(h.detail("rtt_ms"), Some(0.25));
    assert_eq!(h.detail("missing"), None);
    for i in 2..MAX_HEALTH_DETAILS {
        assert!(h.set_detail(&format!("d{i}"), i as f64));
    }
    // Full: a new name is refused and nothing is overwritten; known names still update.
    assert!(!h.set_detail("one_too_many", 9.0));
    assert_eq!(h.details().count(), MAX_HEALTH_DETAILS);
    assert!(h.set_detail("d7", 70.0));
    assert_eq!(h.detail("d7"), Some(70.0));
    // A count past the array reads as the array, never out of bounds.
    h.detail_count = u8::MAX;
    assert_eq!(h.details().count(), MAX_HEALTH_DETAILS);
}

#[test]
fn schema_text_follows_ros2msg_conventions() {
    let schema = HandCommand::schema();
    assert!(schema.starts_with("teleop_msgs/SampleHeader header\n"));
    assert!(schema.contains(&format!(
        "{}\nMSG: teleop_msgs/JointCommand\n",
        "=".repeat(80)
    )));
    assert!(schema.contains("teleop_msgs/JointCommand[24] joints\n"));
    for topic in topics() {
        let type_name = topic.schema_name.rsplit('/').next().unwrap();
        assert!(type_name.chars().next().unwrap().is_ascii_uppercase());
        assert!(type_name.chars().all(|c| c.is_ascii_alphanumeric()));
    }
}

#[test]
fn topic_registry_is_consistent() {
    let names: Vec<_> = topics().iter().map(|t| t.name).collect();
    let mut unique = names.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), names.len(), "duplicate topic");
    for t in topics() {
        struct Size;
        impl TopicVisitor for Size {
            type Output = (usize, &'static str);
            fn visit<M: Message>(self) -> (usize, &'static str) {
                (size_of::<M>(), M::SCHEMA_NAME)
            }
        }
        assert_eq!(visit_topic(t.name, Size), Some((t.size, t.schema_name)));
    }
    assert!(visit_topic("no/such/topic", CheckLayout).is_none());
}

#[test]
fn decode_refuses_wrong_sizes() {
    let bytes = vec![0u8; size_of::<GloveState>() + 1];
    assert_eq!(
        GloveState::from_bytes(&bytes),
        Err(DecodeError::WrongSize {
            expected: 88,
            got: 89
        })
    );
    assert!(GloveState::from_bytes(&[]).is_err());
}

#[test]
fn health_name_round_trips_and_truncates() {
    let mut h = NodeHealth::default();
    h.set_name("retarget");
    assert_eq!(h.name(), "retarget");
    h.set_name(&"é".repeat(20)); // 40 bytes, cut at a char boundary
    assert_eq!(h.name(), "é".repeat(16));
}

#[test]
fn source_ids_differ_between_nodes() {
    assert_ne!(source_id("retarget"), source_id("feedback"));
    assert_eq!(source_id(""), 0x811c_9dc5);
}

proptest! {
    #[test]
    fn any_bytes_of_the_right_size_round_trip(bytes in proptest::collection::vec(any::<u8>(), 536)) {
        let state = HandState::from_bytes(&bytes).unwrap();
        prop_assert_eq!(state.as_bytes(), &bytes[..]);
        let cmd = HandCommand::from_bytes(&bytes[..328]).unwrap();
        prop_assert_eq!(cmd.as_bytes(), &bytes[..328]);
        let tactile = Tactile::from_bytes(&bytes[1..177]).unwrap();
        prop_assert_eq!(tactile.as_bytes(), &bytes[1..177]);
    }

    #[test]
    fn decoding_any_length_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        for t in topics() {
            struct Decode<'a>(&'a [u8]);
            impl TopicVisitor for Decode<'_> {
                type Output = bool;
                fn visit<M: Message>(self) -> bool {
                    M::from_bytes(self.0).is_ok()
                }
            }
            let ok = visit_topic(t.name, Decode(&bytes)).unwrap();
            prop_assert_eq!(ok, bytes.len() == t.size);
        }
    }

    #[test]
    fn field_values_survive_the_byte_view(seq in any::<u64>(), raw in any::<[u16; 6]>(), force in any::<[i16; 5]>()) {
        let mut s = GloveState::default();
        s.header.seq = seq;
        s.raw_position = raw;
        s.force = force;
        let back = GloveState::from_bytes(s.as_bytes()).unwrap();
        prop_assert_eq!(back.header.seq, seq);
        prop_assert_eq!(back.raw_position, raw);
        prop_assert_eq!(back.force, force);
    }
}
