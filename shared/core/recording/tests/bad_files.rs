//! Damaged and foreign files: every reader gives a typed error naming the file, never a panic.
#![allow(clippy::unwrap_used)]

mod common;

use std::{collections::BTreeMap, path::Path, sync::OnceLock};

use common::{raw_file, write_bytes};
use proptest::prelude::*;
use teleop_msgs::{GloveState, Message, NodeHealth, CDR_LE_HEADER};
use teleop_recording::*;

fn glove_data() -> Vec<u8> {
    let s: GloveState = common::sample(1, 1, 1);
    [&CDR_LE_HEADER[..], s.as_bytes()].concat()
}

/// Calls every reader on `path` and returns their errors.
fn errors(path: &Path, dir: &Path) -> Vec<RecordingError> {
    let out = dir.join("repaired.mcap");
    vec![
        info(path).unwrap_err(),
        read_messages(path, &Filter::all()).unwrap_err(),
        repair(path, &out).unwrap_err(),
    ]
}

fn names_path(err: &RecordingError, path: &Path) {
    assert_eq!(err.path(), path);
    assert!(
        err.to_string().contains(&path.display().to_string()),
        "{err}"
    );
}

#[test]
fn not_mcap_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let random: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let text = b"[[process]]\nname = \"glove\"\nthis is a launch file, not a recording\n";
    for (name, bytes) in [("random.bin", &random[..]), ("launch.toml", &text[..])] {
        let path = write_bytes(dir.path(), name, bytes);
        for err in errors(&path, dir.path()) {
            assert!(matches!(err, RecordingError::NotMcap { .. }), "{err}");
            names_path(&err, &path);
        }
    }
    // Nothing was written for a file that could not be read.
    assert!(!dir.path().join("repaired.mcap").exists());
    // A file that does not exist.
    let missing = dir.path().join("missing.mcap");
    let err = info(&missing).unwrap_err();
    assert!(matches!(err, RecordingError::Io { .. }), "{err}");
    names_path(&err, &missing);
}

#[test]
fn empty_and_header_truncated_files_are_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.mcap");
    let mut rec = Recorder::create(&good, WriterOptions::default(), &[]).unwrap();
    rec.add_message_type::<GloveState>().unwrap();
    rec.finish().unwrap();
    let bytes = std::fs::read(&good).unwrap();
    for cut in [0, 3, 8, 12, 17, 30] {
        let path = write_bytes(dir.path(), &format!("cut{cut}.mcap"), &bytes[..cut]);
        for err in errors(&path, dir.path()) {
            assert!(
                matches!(err, RecordingError::Truncated { .. }),
                "cut at {cut}: {err}"
            );
            names_path(&err, &path);
            if cut == 0 {
                assert!(err.to_string().contains("empty"), "{err}");
            }
        }
    }
}

#[test]
fn wrong_schema_version_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let old = GloveState::schema().replace("uint32 errors", "uint32 error_count");
    let path = raw_file(
        dir.path(),
        "glove/state",
        GloveState::SCHEMA_NAME,
        &old,
        "cdr",
        &glove_data(),
    );
    let err = read_messages(&path, &Filter::all()).unwrap_err();
    match &err {
        RecordingError::WrongSchemaVersion {
            topic,
            schema,
            expected,
            found,
            ..
        } => {
            assert_eq!(topic, "glove/state");
            assert_eq!(schema, GloveState::SCHEMA_NAME);
            assert_eq!(*expected, GloveState::schema());
            assert_eq!(*found, old);
        }
        other => panic!("{other}"),
    }
    names_path(&err, &path);
    assert!(err.to_string().contains("error_count"), "{err}");
    // Other topics can still be read; info describes the file.
    assert_eq!(
        read_messages(&path, &Filter::topics(["health"]))
            .unwrap()
            .count(),
        0
    );
    assert_eq!(info(&path).unwrap().messages, 1);
    // Comments and blank lines are not a different version.
    let commented = format!("# GloveState\n\n{}", GloveState::schema());
    let path = raw_file(
        dir.path(),
        "glove/state",
        GloveState::SCHEMA_NAME,
        &commented,
        "cdr",
        &glove_data(),
    );
    assert_eq!(
        read_messages(&path, &Filter::all())
            .unwrap()
            .collect::<Result<Vec<_>, _>>()
            .unwrap()
            .len(),
        1
    );
}

#[test]
fn unknown_schema_for_a_known_topic_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    for (schema, encoding) in [
        ("glove_msgs/msg/Glove", "cdr"),
        (NodeHealth::SCHEMA_NAME, "cdr"),
        (GloveState::SCHEMA_NAME, "json"),
    ] {
        let path = raw_file(
            dir.path(),
            "glove/state",
            schema,
            &GloveState::schema(),
            encoding,
            &glove_data(),
        );
        let err = read_messages(&path, &Filter::all()).unwrap_err();
        assert!(
            matches!(&err, RecordingError::UnknownSchema { topic, .. } if topic == "glove/state"),
            "{err}"
        );
        names_path(&err, &path);
        assert!(err.to_string().contains(GloveState::SCHEMA_NAME), "{err}");
    }
}

#[test]
fn bad_messages_on_contract_topics_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let good = glove_data();
    let big_endian = [&[0u8, 0, 0, 0][..], &good[4..]].concat();
    for data in [
        &good[..good.len() - 1],
        &good[4..],
        &big_endian[..],
        &[][..],
    ] {
        let path = raw_file(
            dir.path(),
            "glove/state",
            GloveState::SCHEMA_NAME,
            &GloveState::schema(),
            "cdr",
            data,
        );
        let mut msgs = read_messages(&path, &Filter::all()).unwrap();
        let err = msgs.next().unwrap().unwrap_err();
        assert!(matches!(err, RecordingError::BadMessage { .. }), "{err}");
        names_path(&err, &path);
        assert!(msgs.next().is_none());
    }
    // Foreign topics pass through; a CDR message must still have room for its header.
    let path = raw_file(
        dir.path(),
        "lab/x",
        "lab/msg/X",
        "uint8 a\n",
        "cdr",
        &[0, 1],
    );
    let err = read_messages(&path, &Filter::all())
        .unwrap()
        .next()
        .unwrap()
        .unwrap_err();
    assert!(matches!(err, RecordingError::BadMessage { .. }), "{err}");
    let path = raw_file(dir.path(), "lab/x", "lab/msg/X", "uint8 a\n", "json", b"{}");
    let msgs: Vec<_> = read_messages(&path, &Filter::all())
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(msgs[0].payload, b"{}");
}

#[test]
fn repair_refuses_to_overwrite_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("self.mcap");
    Recorder::create(&path, WriterOptions::default(), &[])
        .unwrap()
        .finish()
        .unwrap();
    let err = repair(&path, &path).unwrap_err();
    assert!(matches!(err, RecordingError::InvalidUse { .. }), "{err}");
    assert!(info(&path).unwrap().complete);
}

/// A small finished recording, for mutation.
fn valid_file() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("valid.mcap");
        let options = WriterOptions {
            chunk_flush: std::time::Duration::from_millis(10),
            ..WriterOptions::default()
        };
        let meta = vec![(
            "software".to_string(),
            BTreeMap::from([("version".to_string(), "1".to_string())]),
        )];
        let mut rec = Recorder::create(&path, options, &meta).unwrap();
        let glove = rec.add_message_type::<GloveState>().unwrap();
        let health = rec.add_message_type::<NodeHealth>().unwrap();
        for i in 0..40u64 {
            let t = 1_000_000 + i * 1_000_000;
            let s: GloveState = common::sample(i, i + 1, t);
            rec.write(glove, &RecordedMessage::from_sample(&s, t))
                .unwrap();
            if i % 10 == 0 {
                let h: NodeHealth = common::sample(i, i + 1, t);
                rec.write(health, &RecordedMessage::from_sample(&h, t))
                    .unwrap();
            }
        }
        rec.note_drops("glove/state", 1);
        rec.finish().unwrap();
        std::fs::read(&path).unwrap()
    })
}

/// Runs every reader on `bytes`; they may fail but must not panic.
fn exercise(bytes: &[u8]) {
    let dir = tempfile::tempdir().unwrap();
    let path = write_bytes(dir.path(), "in.mcap", bytes);
    let _ = info(&path);
    if let Ok(msgs) = read_messages(&path, &Filter::all()) {
        for _ in msgs {}
    }
    let window = Filter {
        topics: Some(vec!["glove/state".to_string()]),
        start: Some(std::time::Duration::from_millis(5)),
        end: Some(std::time::Duration::from_millis(30)),
    };
    if let Ok(msgs) = read_messages(&path, &window) {
        for _ in msgs {}
    }
    let out = dir.path().join("out.mcap");
    if repair(&path, &out).is_ok() {
        // What repair writes is always readable.
        let i = info(&out).unwrap();
        assert!(i.complete);
        let _ = read_messages(&out, &Filter::all()).map(|m| m.count());
    }
}

proptest! {
    // PROPTEST_CASES raises the count for a longer hunt.
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|c| c.parse().ok()).unwrap_or(128),
        ..ProptestConfig::default()
    })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2048)) {
        exercise(&bytes);
    }

    #[test]
    fn arbitrary_bytes_after_the_magic_never_panic(
        bytes in proptest::collection::vec(any::<u8>(), 0..2048),
    ) {
        exercise(&[mcap::MAGIC, &bytes[..]].concat());
    }

    #[test]
    fn damaged_recordings_never_panic(
        cut in prop_oneof![Just(1.0f64), 0.0f64..=1.0],
        flips in proptest::collection::vec((0.0f64..1.0, any::<u8>()), 0..8),
    ) {
        let mut bytes = valid_file().to_vec();
        for (at, value) in flips {
            let i = ((bytes.len() as f64 * at) as usize).min(bytes.len() - 1);
            bytes[i] = value;
        }
        bytes.truncate((bytes.len() as f64 * cut) as usize);
        exercise(&bytes);
    }
}

#[test]
fn every_cut_of_a_recording_is_handled() {
    let bytes = valid_file();
    let dir = tempfile::tempdir().unwrap();
    let header_end = 17 + u64::from_le_bytes(bytes[9..17].try_into().unwrap()) as usize;
    let mut last_recovered = 0;
    for cut in (0..=bytes.len()).step_by(7).chain([bytes.len()]) {
        let path = write_bytes(dir.path(), "cut.mcap", &bytes[..cut]);
        let overwrite = RepairOptions { overwrite: true };
        match repair_with(&path, &dir.path().join("out.mcap"), overwrite) {
            Ok(report) => {
                // A longer prefix never recovers fewer messages.
                assert!(report.messages >= last_recovered, "cut {cut}");
                last_recovered = report.messages;
            }
            Err(err) => {
                // Only a file cut before the end of its header is beyond repair.
                assert!(cut < header_end, "cut {cut}: {err}");
                assert!(matches!(err, RecordingError::Truncated { .. }), "{err}");
                names_path(&err, &path);
            }
        }
        exercise(&bytes[..cut]);
    }
    assert_eq!(last_recovered, 44);
}
