//! Writing, reading, crash recovery, rotation and `info` on real files.
#![allow(clippy::unwrap_used)]

mod common;

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
    time::Duration,
};

use common::{assert_same, for_each_type, sample, with_type, ForEachType};
use teleop_msgs::{GloveState, HandState, Message, NodeHealth, CDR_LE_HEADER};
use teleop_recording::*;

const MS: u64 = 1_000_000;
const T0: u64 = 5_000_000_000;

fn metadata() -> Vec<(String, BTreeMap<String, String>)> {
    let map = |pairs: &[(&str, &str)]| {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect::<BTreeMap<_, _>>()
    };
    vec![
        (
            "launch".to_string(),
            map(&[
                ("file", "launch.toml"),
                ("text", "[[process]]\nname = \"glove\"\n"),
            ]),
        ),
        (
            "devices".to_string(),
            map(&[("glove", "sim"), ("hand", "sim")]),
        ),
        ("software".to_string(), map(&[("version", "0.1.0")])),
    ]
}

fn has_metadata(info: &RecordingInfo) {
    for (name, fields) in metadata() {
        assert!(
            info.metadata
                .iter()
                .any(|(n, f)| *n == name && *f == fields),
            "{}: metadata {name} missing: {:?}",
            info.path.display(),
            info.metadata
        );
    }
}

fn all(path: &Path, filter: &Filter) -> Vec<OwnedMessage> {
    read_messages(path, filter)
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap()
}

/// Writes `count` GloveState samples at 1 kHz from T0; returns the samples.
fn write_glove(rec: &mut Recorder, count: u64) -> Vec<GloveState> {
    let id = rec.add_message_type::<GloveState>().unwrap();
    (0..count)
        .map(|i| {
            let t = T0 + i * MS;
            let s: GloveState = sample(i, i + 1, t - 300_000);
            rec.write(id, &RecordedMessage::from_sample(&s, t)).unwrap();
            s
        })
        .collect()
}

/// Simulates SIGKILL: the recorder vanishes without finishing; the file holds what it had
/// handed to the operating system. Returns a copy of that file.
/// Writes tick `i` of a 1 kHz stream of `M` on `stream` and, every 100th tick, a `NodeHealth`
/// on `health` (a node's 10 Hz health); returns the tick's time, `T0 + i` ms.
fn write_tick<M: Message>(rec: &mut Recorder, stream: TopicId, health: TopicId, i: u64) -> u64 {
    let t = T0 + i * MS;
    let s: M = sample(i, i + 1, t);
    rec.write(stream, &RecordedMessage::from_sample(&s, t))
        .unwrap();
    if i.is_multiple_of(100) {
        let h: NodeHealth = sample(i, i / 100 + 1, t);
        rec.write(health, &RecordedMessage::from_sample(&h, t))
            .unwrap();
    }
    t
}

fn kill(rec: Recorder, dir: &Path) -> PathBuf {
    let path = rec.path().to_path_buf();
    std::mem::forget(rec);
    let copy = dir.join("killed.mcap");
    std::fs::copy(&path, &copy).unwrap();
    copy
}

struct WriteAll<'a> {
    rec: &'a mut Recorder,
    /// (topic, log time, payload bytes)
    written: Vec<(String, u64, Vec<u8>)>,
    t: u64,
}

impl ForEachType for WriteAll<'_> {
    fn run<M: Message>(&mut self) {
        let id = self.rec.add_message_type::<M>().unwrap();
        for k in 0..3u64 {
            self.t += MS;
            let s: M = sample(k * 31 + self.written.len() as u64, 100 + k, self.t - 1234);
            self.rec
                .write(id, &RecordedMessage::from_sample(&s, self.t))
                .unwrap();
            self.written
                .push((M::TOPIC.to_string(), self.t, s.as_bytes().to_vec()));
        }
    }
}

struct Compare<'a> {
    got: &'a [u8],
    want: &'a [u8],
}

impl ForEachType for Compare<'_> {
    fn run<M: Message>(&mut self) {
        let got = M::from_bytes(self.got).unwrap();
        let want = M::from_bytes(self.want).unwrap();
        assert_same(&got, &want);
    }
}

#[test]
fn every_contract_type_round_trips_field_by_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sub/folder/all.mcap");
    let mut rec = Recorder::create(&path, WriterOptions::default(), &metadata()).unwrap();
    let mut w = WriteAll {
        rec: &mut rec,
        written: Vec::new(),
        t: T0,
    };
    for_each_type(&mut w);
    let written = w.written;
    assert_eq!(written.len(), teleop_msgs::topics().len() * 3);
    let summary = rec.finish().unwrap();
    assert_eq!(summary.files, vec![path.clone()]);
    assert_eq!(summary.messages, written.len() as u64);

    let read = all(&path, &Filter::all());
    assert_eq!(read.len(), written.len());
    for (msg, (topic, t, bytes)) in read.iter().zip(&written) {
        assert_eq!(&msg.topic, topic);
        assert_eq!(msg.log_time_ns, *t);
        assert_eq!(msg.publish_time_ns, t - 1234);
        assert_eq!(msg.message_encoding, "cdr");
        assert_eq!(&msg.payload, bytes);
        with_type(
            topic,
            &mut Compare {
                got: &msg.payload,
                want: bytes,
            },
        );
    }
    // Sequence numbers and typed decoding.
    let glove: Vec<GloveState> = read.iter().filter_map(|m| m.decode()).collect();
    assert_eq!(glove.len(), 3);
    assert_eq!(glove[1].header.seq, 101);
    assert_eq!(read[1].sequence, 101);

    // The raw message bytes in the file are the CDR header followed by the payload, on
    // channels `cdr` with `ros2msg` schemas named as in the contract.
    let bytes = std::fs::read(&path).unwrap();
    let mut raw = 0;
    for (m, (topic, _, payload)) in mcap::MessageStream::new(&bytes).unwrap().zip(&written) {
        let m = m.unwrap();
        assert_eq!(&m.channel.topic, topic);
        assert_eq!(m.channel.message_encoding, "cdr");
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "ros2msg");
        let info = teleop_msgs::topics()
            .iter()
            .find(|t| t.name == topic)
            .unwrap();
        assert_eq!(schema.name, info.schema_name);
        assert_eq!(&m.data[..4], &CDR_LE_HEADER);
        assert_eq!(&m.data[4..], &payload[..]);
        raw += 1;
    }
    assert_eq!(raw, written.len());
}

#[test]
fn killed_recorder_loses_at_most_the_last_chunk_flush() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.mcap");
    let mut rec = Recorder::create(&path, WriterOptions::default(), &metadata()).unwrap();
    // 1 s at 1 kHz.
    let samples = write_glove(&mut rec, 1000);
    let last = T0 + 999 * MS;
    let killed = kill(rec, dir.path());

    let before = info(&killed).unwrap();
    assert!(!before.complete);
    has_metadata(&before);
    assert!(read_messages(&killed, &Filter::all()).unwrap().count() > 0);

    let repaired = dir.path().join("repaired/rec.mcap");
    let report = repair(&killed, &repaired).unwrap();
    assert!(!report.input_complete);
    assert!(report.stopped.is_some(), "{report:?}");
    // Chunks closed at 100, 200, ... 900 ms: the 99 messages after 900 ms were in the open one.
    assert_eq!(report.messages, 901);
    let recovered_until = report.last_log_time_ns.unwrap();
    assert!(
        recovered_until + 100 * MS > last,
        "lost more than 100 ms: last written {last}, last recovered {recovered_until}"
    );

    let after = info(&repaired).unwrap();
    assert!(after.complete);
    has_metadata(&after);
    assert_eq!(after.messages, report.messages);
    let msgs = all(&repaired, &Filter::all());
    assert_eq!(msgs.len() as u64, report.messages);
    for (i, (m, s)) in msgs.iter().zip(&samples).enumerate() {
        assert_eq!(m.log_time_ns, T0 + i as u64 * MS);
        assert_same(&m.decode::<GloveState>().unwrap(), s);
    }
    // Every message older than 100 ms before the last one written is there.
    let must = samples
        .iter()
        .enumerate()
        .filter(|(i, _)| T0 + *i as u64 * MS + 100 * MS <= last)
        .count();
    assert!(msgs.len() >= must, "{} < {must}", msgs.len());
    // The killed file read directly gives the same messages.
    assert_eq!(all(&killed, &Filter::all()), msgs);
}

#[test]
fn flush_if_due_closes_the_chunk_in_idle_periods() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("idle.mcap");
    let mut rec = Recorder::create(&path, WriterOptions::default(), &[]).unwrap();
    write_glove(&mut rec, 10);
    // Not yet due: 9 ms since the first message.
    rec.flush_if_due(T0 + 50 * MS).unwrap();
    rec.flush_if_due(T0 + 150 * MS).unwrap();
    let killed = kill(rec, dir.path());
    let i = info(&killed).unwrap();
    assert!(!i.complete);
    assert_eq!(i.messages, 10);
}

#[test]
fn rotation_by_size_gives_readable_files_with_schemas_channels_and_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.mcap");
    let options = WriterOptions {
        rotate_bytes: Some(100_000),
        compression: false,
        ..WriterOptions::default()
    };
    let mut rec = Recorder::create(&path, options, &metadata()).unwrap();
    let hand = rec.add_message_type::<HandState>().unwrap();
    let health = rec.add_message_type::<NodeHealth>().unwrap();
    let n = 1500u64;
    for i in 0..n {
        write_tick::<HandState>(&mut rec, hand, health, i);
    }
    rec.note_drops("hand/state", 2);
    let summary = rec.finish().unwrap();
    assert!(summary.files.len() >= 3, "{:?}", summary.files);
    assert_eq!(summary.files[0], path);
    assert_eq!(summary.files[1], dir.path().join("big_1.mcap"));
    assert_eq!(summary.messages, n + n / 100);

    let mut seqs = Vec::new();
    for file in &summary.files {
        let i = info(file).unwrap();
        assert!(i.complete);
        has_metadata(&i);
        let topics: Vec<&str> = i.topics.iter().map(|t| t.topic.as_str()).collect();
        assert_eq!(topics, ["hand/state", "health"], "{}", file.display());
        assert_eq!(i.topics[0].schema_name, HandState::SCHEMA_NAME);
        // Finished parts are near the limit (they close after a chunk passes it).
        if file != summary.files.last().unwrap() {
            assert!(
                i.size_bytes >= 100_000,
                "{} {}",
                file.display(),
                i.size_bytes
            );
            assert!(
                i.size_bytes < 400_000,
                "{} {}",
                file.display(),
                i.size_bytes
            );
        }
        for m in all(file, &Filter::topics(["hand/state"])) {
            seqs.push(m.decode::<HandState>().unwrap().header.seq);
        }
    }
    assert_eq!(seqs, (1..=n).collect::<Vec<_>>());
    // Drops go into the file that was open when they were noted, and into the total.
    let last = info(summary.files.last().unwrap()).unwrap();
    assert_eq!(last.topics[0].drops, Some(2));
    assert_eq!(info(&path).unwrap().topics[0].drops, Some(0));
    assert_eq!(summary.topics[0].drops, 2);
}

#[test]
fn rotation_by_duration_splits_on_log_time() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("long.mcap");
    let options = WriterOptions {
        rotate_after: Some(Duration::from_secs(1)),
        ..WriterOptions::default()
    };
    let mut rec = Recorder::create(&path, options, &metadata()).unwrap();
    let id = rec.add_message_type::<GloveState>().unwrap();
    // 3.5 s at 100 Hz.
    for i in 0..350u64 {
        let t = T0 + i * 10 * MS;
        let s: GloveState = sample(i, i + 1, t);
        rec.write(id, &RecordedMessage::from_sample(&s, t)).unwrap();
    }
    let summary = rec.finish().unwrap();
    assert_eq!(summary.files.len(), 4, "{:?}", summary.files);
    let mut total = 0;
    for (k, file) in summary.files.iter().enumerate() {
        let i = info(file).unwrap();
        assert!(i.complete);
        has_metadata(&i);
        assert_eq!(i.topics.len(), 1);
        assert!(i.duration < Duration::from_secs(1));
        assert_eq!(i.start_ns, T0 + k as u64 * 1_000 * MS);
        total += i.messages;
    }
    assert_eq!(total, 350);
}

#[test]
fn info_on_finished_and_killed_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("info.mcap");
    let mut rec = Recorder::create(&path, WriterOptions::default(), &metadata()).unwrap();
    let glove = rec.add_message_type::<GloveState>().unwrap();
    let health = rec.add_message_type::<NodeHealth>().unwrap();
    // A topic outside the contract is recorded too.
    let other = rec
        .add_topic("lab/marker", "lab_msgs/msg/Marker", "uint32 id\n")
        .unwrap();
    // 2 s: glove at 1 kHz, health at 10 Hz, one marker.
    for i in 0..2000u64 {
        let t = write_tick::<GloveState>(&mut rec, glove, health, i);
        if i == 1000 {
            let marker = RecordedMessage {
                topic: "lab/marker",
                log_time_ns: t,
                publish_time_ns: t,
                sequence: 1,
                payload: &7u32.to_le_bytes(),
            };
            rec.write(other, &marker).unwrap();
        }
    }
    rec.note_drops("glove/state", 3);
    rec.note_drops("glove/state", 2);

    // Killed first (a copy of the file as it is now), then finished.
    let killed = {
        let copy = dir.path().join("killed.mcap");
        std::fs::copy(rec.path(), &copy).unwrap();
        copy
    };
    let summary = rec.finish().unwrap();
    assert_eq!(summary.topics[0].messages, 2000);
    assert_eq!(summary.topics[0].drops, 5);

    let i = info(&path).unwrap();
    assert!(i.complete);
    assert_eq!(i.messages, 2021);
    assert_eq!(i.start_ns, T0);
    assert_eq!(i.end_ns, T0 + 1999 * MS);
    assert_eq!(i.duration, Duration::from_nanos(1999 * MS));
    has_metadata(&i);
    assert!(i.metadata.iter().any(|(n, _)| n == "drops"));
    let names: Vec<&str> = i.topics.iter().map(|t| t.topic.as_str()).collect();
    assert_eq!(names, ["glove/state", "health", "lab/marker"]);
    let g = &i.topics[0];
    assert_eq!(g.messages, 2000);
    assert_eq!(g.schema_name, GloveState::SCHEMA_NAME);
    assert_eq!(g.first_log_ns, Some(T0));
    assert_eq!(g.last_log_ns, Some(T0 + 1999 * MS));
    assert!((g.rate_hz - 1000.0).abs() < 1e-6, "{}", g.rate_hz);
    assert_eq!(g.drops, Some(5));
    let h = &i.topics[1];
    assert_eq!(h.messages, 20);
    assert!((h.rate_hz - 10.0).abs() < 1e-6, "{}", h.rate_hz);
    assert_eq!(h.drops, Some(0));
    assert_eq!(i.topics[2].messages, 1);
    assert_eq!(i.topics[2].rate_hz, 0.0);

    let k = info(&killed).unwrap();
    assert!(!k.complete);
    has_metadata(&k);
    assert!(!k.metadata.iter().any(|(n, _)| n == "drops"));
    assert_eq!(k.topics[0].drops, None);
    assert_eq!(k.start_ns, T0);
    // The open chunk (under 100 ms of data) is missing, the rest is there.
    let kg = &k.topics[0];
    assert!(kg.messages > 1900 && kg.messages < 2000, "{}", kg.messages);
    assert!((kg.rate_hz - 1000.0).abs() < 1e-6, "{}", kg.rate_hz);
    assert_eq!(kg.last_log_ns, Some(T0 + (kg.messages - 1) * MS));

    // Filters: topics and a window relative to the first message, on both kinds of file.
    for file in [&path, &killed] {
        let window = Filter {
            topics: Some(vec!["glove/state".into(), "lab/marker".into()]),
            start: Some(Duration::from_millis(500)),
            end: Some(Duration::from_millis(1500)),
        };
        let msgs = all(file, &window);
        assert_eq!(msgs.len(), 1001, "{}", file.display());
        assert_eq!(msgs[0].log_time_ns, T0 + 500 * MS);
        assert!(msgs.iter().all(|m| m.log_time_ns < T0 + 1500 * MS));
        let marker: Vec<_> = msgs.iter().filter(|m| m.topic == "lab/marker").collect();
        assert_eq!(marker.len(), 1);
        assert_eq!(marker[0].payload, 7u32.to_le_bytes());
        assert_eq!(marker[0].schema_name, "lab_msgs/msg/Marker");
        assert!(all(file, &Filter::topics(["no/such/topic"])).is_empty());
        // The killed file lacks the last health sample (at 1.9 s, in the open chunk).
        let health = all(file, &Filter::topics(["health"]));
        assert_eq!(health.len(), if file == &path { 20 } else { 19 });
        // Log-time order.
        let all_msgs = all(file, &Filter::all());
        assert!(all_msgs
            .windows(2)
            .all(|w| w[0].log_time_ns <= w[1].log_time_ns));
    }
}

#[test]
fn an_empty_recording_is_valid() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.mcap");
    let mut rec = Recorder::create(&path, WriterOptions::default(), &metadata()).unwrap();
    rec.add_message_type::<GloveState>().unwrap();
    let summary = rec.finish().unwrap();
    assert_eq!(summary.messages, 0);
    let i = info(&path).unwrap();
    assert!(i.complete);
    assert_eq!(i.messages, 0);
    assert_eq!(i.topics.len(), 1);
    assert_eq!(i.duration, Duration::ZERO);
    assert!(all(&path, &Filter::all()).is_empty());
}

#[test]
fn create_does_not_overwrite_and_topics_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("once.mcap");
    let mut rec = Recorder::create(&path, WriterOptions::default(), &[]).unwrap();
    let err = Recorder::create(&path, WriterOptions::default(), &[]).unwrap_err();
    assert!(matches!(err, RecordingError::Io { .. }), "{err}");
    assert!(err.to_string().contains("once.mcap"), "{err}");

    let a = rec.add_message_type::<GloveState>().unwrap();
    assert_eq!(rec.add_message_type::<GloveState>().unwrap(), a);
    let err = rec
        .add_topic("glove/state", GloveState::SCHEMA_NAME, "uint8 x\n")
        .unwrap_err();
    assert!(matches!(err, RecordingError::InvalidUse { .. }), "{err}");
    let err = rec
        .add_topic("hand/state", HandState::SCHEMA_NAME, "uint8 x\n")
        .unwrap_err();
    assert!(
        matches!(err, RecordingError::WrongSchemaVersion { .. }),
        "{err}"
    );
    let err = rec
        .add_topic("hand/state", "other/msg/Hand", &HandState::schema())
        .unwrap_err();
    assert!(matches!(err, RecordingError::UnknownSchema { .. }), "{err}");

    // Messages must match their topic id and the contract's size.
    let s: GloveState = sample(1, 1, 1);
    let mut msg = RecordedMessage::from_sample(&s, 10);
    msg.topic = "hand/state";
    let err = rec.write(a, &msg).unwrap_err();
    assert!(matches!(err, RecordingError::InvalidUse { .. }), "{err}");
    let mut msg = RecordedMessage::from_sample(&s, 10);
    msg.payload = &msg.payload[1..];
    let err = rec.write(a, &msg).unwrap_err();
    assert!(matches!(err, RecordingError::BadMessage { .. }), "{err}");
    rec.finish().unwrap();
}

#[test]
fn dropping_a_recorder_finishes_its_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dropped.mcap");
    {
        let mut rec = Recorder::create(&path, WriterOptions::default(), &metadata()).unwrap();
        write_glove(&mut rec, 10);
        rec.note_drops("glove/state", 4);
    }
    let i = info(&path).unwrap();
    assert!(i.complete);
    assert_eq!(i.messages, 10);
    assert_eq!(i.topics[0].drops, Some(4));
}

#[test]
fn recorder_and_reader_can_move_between_threads() {
    fn send<T: Send>() {}
    send::<Recorder>();
    send::<Messages>();
    send::<RecordingError>();
}

/// Item 16 of issue 20: a part file that exists already is never truncated (the next free
/// number is used), and a rotation that cannot create its file goes on in the current one.
#[test]
fn rotation_keeps_existing_files_and_survives_a_failed_part() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rot.mcap");
    let precious = dir.path().join("rot_1.mcap");
    std::fs::write(&precious, "someone else's file").unwrap();
    let options = WriterOptions {
        rotate_after: Some(Duration::from_secs(1)),
        ..WriterOptions::default()
    };
    let mut rec = Recorder::create(&path, options.clone(), &metadata()).unwrap();
    let written = write_glove(&mut rec, 2500);
    let summary = rec.finish().unwrap();
    assert_eq!(
        std::fs::read_to_string(&precious).unwrap(),
        "someone else's file"
    );
    assert!(!summary.files.contains(&precious), "{:?}", summary.files);
    let got: usize = summary
        .files
        .iter()
        .map(|f| all(f, &Filter::all()).len())
        .sum();
    assert_eq!(got, written.len());

    // A part name longer than the file system allows: every rotation fails, nothing is lost.
    let long = dir.path().join(format!("{}.mcap", "x".repeat(250)));
    let mut rec = Recorder::create(&long, options, &metadata()).unwrap();
    let written = write_glove(&mut rec, 2500);
    let summary = rec.finish().unwrap();
    assert_eq!(summary.files, std::slice::from_ref(&long));
    assert_eq!(all(&long, &Filter::all()).len(), written.len());
    assert!(info(&long).unwrap().complete);
}

/// Item 16 of issue 20: limits of zero would start a file per message.
#[test]
fn rotation_limits_of_zero_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    for options in [
        WriterOptions {
            rotate_bytes: Some(0),
            ..WriterOptions::default()
        },
        WriterOptions {
            rotate_after: Some(Duration::ZERO),
            ..WriterOptions::default()
        },
    ] {
        let path = dir.path().join("zero.mcap");
        let err = Recorder::create(&path, options, &[]).unwrap_err();
        assert!(err.to_string().contains("rotat"), "{err}");
        assert!(!path.exists(), "no file for refused options");
    }
}
