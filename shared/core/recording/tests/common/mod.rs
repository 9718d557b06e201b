//! Test helpers: distinctive samples of every contract type, built generically from the ROS 2
//! schema text, and the primitive leaves of a payload.
#![allow(dead_code, clippy::unwrap_used)]

use std::{
    collections::{BTreeMap, HashMap},
    io::BufWriter,
    path::{Path, PathBuf},
};

use teleop_msgs::{Message, TopicVisitor};

/// One primitive field of a payload, laid out as CDR (= `repr(C)`, checked by teleop-msgs).
#[derive(Debug, Clone)]
pub struct Leaf {
    /// `header.seq`, `raw_position[3]`, `joints[2].target`.
    pub path: String,
    pub offset: usize,
    /// ROS 2 primitive type.
    pub ty: String,
}

/// A primitive value read from a payload.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    Int(i128),
    Float(f64),
}

fn size_of_primitive(ty: &str) -> Option<usize> {
    Some(match ty {
        "uint8" | "int8" | "byte" | "char" | "bool" => 1,
        "uint16" | "int16" => 2,
        "uint32" | "int32" | "float32" => 4,
        "uint64" | "int64" | "float64" => 8,
        _ => return None,
    })
}

fn fields(body: &str) -> Vec<(String, String)> {
    body.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let mut parts = l.split_whitespace();
            (
                parts.next().unwrap().to_string(),
                parts.next().unwrap().to_string(),
            )
        })
        .collect()
}

/// The primitive leaves of a schema, in order.
pub fn leaves(schema: &str) -> Vec<Leaf> {
    let separator = format!("{}\n", "=".repeat(80));
    let mut sections = schema.split(separator.as_str());
    let top = sections.next().unwrap();
    let mut nested = HashMap::new();
    for section in sections {
        let (first, body) = section.split_once('\n').unwrap();
        nested.insert(
            first.strip_prefix("MSG: ").unwrap().to_string(),
            fields(body),
        );
    }
    let mut out = Vec::new();
    let mut offset = 0;
    for (ty, name) in fields(top) {
        lay_out(&ty, &name, &nested, &mut offset, &mut out);
    }
    out
}

fn lay_out(
    ty: &str,
    path: &str,
    nested: &HashMap<String, Vec<(String, String)>>,
    offset: &mut usize,
    out: &mut Vec<Leaf>,
) {
    if let Some((elem, count)) = ty.strip_suffix(']').and_then(|t| t.split_once('[')) {
        for i in 0..count.parse::<usize>().unwrap() {
            lay_out(elem, &format!("{path}[{i}]"), nested, offset, out);
        }
    } else if let Some(size) = size_of_primitive(ty) {
        *offset = offset.div_ceil(size) * size;
        out.push(Leaf {
            path: path.to_string(),
            offset: *offset,
            ty: ty.to_string(),
        });
        *offset += size;
    } else {
        for (fty, fname) in nested.get(ty).unwrap_or_else(|| panic!("no MSG: {ty}")) {
            lay_out(fty, &format!("{path}.{fname}"), nested, offset, out);
        }
    }
}

/// Reads a leaf's value from payload bytes.
pub fn value(bytes: &[u8], leaf: &Leaf) -> Value {
    let b = &bytes[leaf.offset..];
    match leaf.ty.as_str() {
        "uint8" | "byte" | "char" | "bool" => Value::Int(b[0].into()),
        "int8" => Value::Int((b[0] as i8).into()),
        "uint16" => Value::Int(u16::from_le_bytes([b[0], b[1]]).into()),
        "int16" => Value::Int(i16::from_le_bytes([b[0], b[1]]).into()),
        "uint32" => Value::Int(u32::from_le_bytes(b[..4].try_into().unwrap()).into()),
        "int32" => Value::Int(i32::from_le_bytes(b[..4].try_into().unwrap()).into()),
        "uint64" => Value::Int(u64::from_le_bytes(b[..8].try_into().unwrap()).into()),
        "int64" => Value::Int(i64::from_le_bytes(b[..8].try_into().unwrap()).into()),
        "float32" => Value::Float(f32::from_le_bytes(b[..4].try_into().unwrap()).into()),
        "float64" => Value::Float(f64::from_le_bytes(b[..8].try_into().unwrap())),
        other => panic!("unknown primitive {other}"),
    }
}

/// Writes a distinctive, finite value into every leaf: no two leaves (and no two seeds) share
/// a value where the type has room, floats are exact in binary, signed fields get negatives.
pub fn fill(bytes: &mut [u8], leaves: &[Leaf], seed: u64) {
    for (i, leaf) in leaves.iter().enumerate() {
        let n = (i as u64 + 1) * 7 + seed * 1009;
        let b = &mut bytes[leaf.offset..];
        match leaf.ty.as_str() {
            "uint8" | "byte" | "char" | "bool" => b[0] = (n % 251) as u8,
            "int8" => b[0] = (-((n % 127) as i8)) as u8,
            "uint16" => b[..2].copy_from_slice(&((n % 65_521) as u16).to_le_bytes()),
            "int16" => b[..2].copy_from_slice(&(-((n % 32_749) as i16)).to_le_bytes()),
            "uint32" => b[..4].copy_from_slice(&(n as u32 ^ 0x8000_0000).to_le_bytes()),
            "int32" => b[..4].copy_from_slice(&(-(n as i32)).to_le_bytes()),
            "uint64" => b[..8].copy_from_slice(&(n | 0x0100_0000_0000_0000).to_le_bytes()),
            "int64" => b[..8].copy_from_slice(&(-(n as i64)).to_le_bytes()),
            "float32" => b[..4].copy_from_slice(&(n as f32 * 0.25 - 1000.5).to_le_bytes()),
            "float64" => b[..8].copy_from_slice(&(n as f64 * 0.125 - 1e6).to_le_bytes()),
            other => panic!("unknown primitive {other}"),
        }
    }
}

/// A distinctive sample of `M`, with its header stamped `seq`, `stamp_ns`.
pub fn sample<M: Message>(seed: u64, seq: u64, stamp_ns: u64) -> M {
    let mut bytes = M::default().as_bytes().to_vec();
    fill(&mut bytes, &leaves(&M::schema()), seed);
    let mut m = M::from_bytes(&bytes).unwrap();
    m.header_mut().seq = seq;
    m.header_mut().stamp_ns = stamp_ns;
    m
}

/// Asserts two payloads of `M` are equal field by field (top-level fields by name).
pub fn assert_same<M: Message>(got: &M, want: &M) {
    let (g, w) = (got.as_bytes(), want.as_bytes());
    for f in M::FIELDS {
        assert_eq!(
            &g[f.offset..f.offset + f.size],
            &w[f.offset..f.offset + f.size],
            "{}: field {} differs",
            M::TOPIC,
            f.name
        );
    }
    assert_eq!(format!("{got:?}"), format!("{want:?}"));
}

/// Runs `f` for every contract type.
pub trait ForEachType {
    fn run<M: Message>(&mut self);
}

struct Adapter<'a, F>(&'a mut F);

impl<F: ForEachType> TopicVisitor for Adapter<'_, F> {
    type Output = ();
    fn visit<M: Message>(self) {
        self.0.run::<M>();
    }
}

pub fn for_each_type<F: ForEachType>(f: &mut F) {
    for topic in teleop_msgs::topics() {
        teleop_msgs::visit_topic(topic.name, Adapter(f)).unwrap();
    }
}

/// Calls `M`'s handler for the contract type of `topic`.
pub fn with_type<F: ForEachType>(topic: &str, f: &mut F) {
    teleop_msgs::visit_topic(topic, Adapter(f)).unwrap_or_else(|| panic!("unknown topic {topic}"));
}

/// Writes `bytes` to `dir/name`.
pub fn write_bytes(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// A file of one channel and one message (named after its topic), written with the MCAP library
/// directly, bypassing the recorder's checks.
pub fn raw_file(
    dir: &Path,
    topic: &str,
    schema_name: &str,
    schema_text: &str,
    message_encoding: &str,
    data: &[u8],
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
        .add_channel(schema, topic, message_encoding, &BTreeMap::new())
        .unwrap();
    w.write_to_known_channel(
        &mcap::records::MessageHeader {
            channel_id: channel,
            sequence: 1,
            log_time: 10,
            publish_time: 9,
        },
        data,
    )
    .unwrap();
    w.finish().unwrap();
    path
}
