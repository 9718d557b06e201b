//! Python's `mcap` + `mcap-ros2-support` decode every field of every contract type from a
//! recording exactly as written.
//!
//! Needs `pip install mcap==1.6.0 mcap-ros2-support==0.6.0`; without them the test prints why
//! and passes, unless `TELEOP_REQUIRE_CHECKS=1` (set by `.ci/run` as root) makes a missing package a failure.
#![allow(clippy::unwrap_used)]

mod common;

use std::{collections::BTreeMap, path::Path, process::Command};

use common::{for_each_type, leaves, sample, value, ForEachType, Value};
use serde_json::Value as Json;
use teleop_msgs::Message;
use teleop_recording::*;

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/decode_check.py");

fn python_ready() -> Result<(), String> {
    let out = Command::new("python3")
        .args(["-c", "import mcap, mcap_ros2.decoder"])
        .output()
        .map_err(|e| format!("python3 not found: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).trim().to_string())
    }
}

/// Written samples: topic, log time, schema, payload bytes.
struct Written {
    topic: String,
    log_time: u64,
    schema: String,
    bytes: Vec<u8>,
}

struct WriteAll<'a> {
    rec: &'a mut Recorder,
    written: Vec<Written>,
}

impl ForEachType for WriteAll<'_> {
    fn run<M: Message>(&mut self) {
        let id = self.rec.add_message_type::<M>().unwrap();
        for k in 0..2u64 {
            let t = 1_000_000_000 + self.written.len() as u64 * 1_000_000;
            let s: M = sample(self.written.len() as u64 * 3 + k, 1_000 + k, t - 77);
            self.rec
                .write(id, &RecordedMessage::from_sample(&s, t))
                .unwrap();
            self.written.push(Written {
                topic: M::TOPIC.to_string(),
                log_time: t,
                schema: M::schema(),
                bytes: s.as_bytes().to_vec(),
            });
        }
    }
}

fn flatten(prefix: &str, json: &Json, out: &mut BTreeMap<String, Json>) {
    match json {
        Json::Object(map) => {
            for (k, v) in map {
                let p = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&p, v, out);
            }
        }
        Json::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                flatten(&format!("{prefix}[{i}]"), v, out);
            }
        }
        other => {
            out.insert(prefix.to_string(), other.clone());
        }
    }
}

fn same(json: &Json, want: Value) -> bool {
    match want {
        Value::Int(i) => {
            json.as_u64().map(i128::from) == Some(i) || json.as_i64().map(i128::from) == Some(i)
        }
        Value::Float(f) => json.as_f64() == Some(f),
    }
}

fn check_file(path: &Path, written: &[Written]) {
    let out = Command::new("python3")
        .arg(SCRIPT)
        .arg(path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "decode_check.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<Json> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), written.len());
    let mut checked = 0;
    let mut checked_paths = std::collections::BTreeSet::new();
    for (line, w) in lines.iter().zip(written) {
        assert_eq!(line["topic"], w.topic.as_str());
        assert_eq!(line["log_time"], w.log_time);
        assert_eq!(line["publish_time"], w.log_time - 77);
        let mut decoded = BTreeMap::new();
        flatten("", &line["message"], &mut decoded);
        let expected = leaves(&w.schema);
        assert_eq!(
            decoded.len(),
            expected.len(),
            "{}: Python decoded {:?}",
            w.topic,
            decoded.keys().collect::<Vec<_>>()
        );
        for leaf in &expected {
            let want = value(&w.bytes, leaf);
            let got = decoded
                .get(&leaf.path)
                .unwrap_or_else(|| panic!("{}: Python has no field {}", w.topic, leaf.path));
            assert!(
                same(got, want),
                "{}: field {} is {got} in Python, {want:?} in Rust",
                w.topic,
                leaf.path
            );
            checked += 1;
            checked_paths.insert(format!("{} {}", w.topic, leaf.path));
        }
    }
    // The fields of contract version 2 are among them.
    for field in [
        "hand/state joints[23].effort",
        "hand/state link_kind",
        "hand/state bus_state",
        "hand/state link_error_code",
        "hand/state link_errors",
        "hand/state reserved[4]",
        "hand/tactile fingertips[4].pressure",
        "hand/tactile fingertips[4].temperature",
        "hand/tactile fingertips[4].sensor_kind",
    ] {
        assert!(checked_paths.contains(field), "{field} not checked");
    }
    println!(
        "{}: Python decoded {} messages, {checked} fields, all equal",
        path.display(),
        lines.len()
    );
}

#[test]
fn python_mcap_ros2_decodes_every_field() {
    if let Err(reason) = python_ready() {
        if std::env::var_os("TELEOP_REQUIRE_CHECKS").is_some() {
            panic!("Python mcap packages required but missing: {reason}");
        }
        println!(
            "SKIPPED: Python mcap/mcap-ros2-support not available ({reason}); \
             pip install mcap==1.6.0 mcap-ros2-support==0.6.0"
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("python.mcap");
    let mut rec = Recorder::create(&path, WriterOptions::default(), &[]).unwrap();
    let mut w = WriteAll {
        rec: &mut rec,
        written: Vec::new(),
    };
    for_each_type(&mut w);
    let written = w.written;
    rec.finish().unwrap();
    check_file(&path, &written);

    // A repaired file of a killed recorder decodes the same (here everything was flushed).
    let mut rec =
        Recorder::create(&dir.path().join("k.mcap"), WriterOptions::default(), &[]).unwrap();
    let mut w = WriteAll {
        rec: &mut rec,
        written: Vec::new(),
    };
    for_each_type(&mut w);
    rec.flush().unwrap();
    let killed = rec.path().to_path_buf();
    std::mem::forget(rec);
    let repaired = dir.path().join("repaired.mcap");
    repair(&killed, &repaired).unwrap();
    check_file(&repaired, &written);
}
