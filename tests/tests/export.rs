//! `teleop export --format lerobot`: a recording with five episodes (a success, a failure, one
//! discarded, one whose hand/state stalled, one never stopped) becomes a dataset of the first
//! two, which an independent reader (pyarrow, `tests/python/check_lerobot.py`) reads whole and
//! finds consistent; a frame's values are the recorded samples at its instant (zero-order
//! hold); appending works and appending other features is refused; a bimanual recording
//! exports both sides; an export that dies at any of the writer's crash points leaves a
//! dataset that reads right; gaps, values that are not finite and missing topics are refused
//! by name.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use teleop_e2e::{dataset::check_lerobot, Sandbox};
use teleop_msgs::{
    device_model, episode_event, episode_outcome, fixed_text, units, Episode, GloveForceCommand,
    GloveState, HandCommand, HandState, Message, Tactile,
};
use teleop_recording::{RecordedMessage, Recorder, TopicId, WriterOptions};

const T0: u64 = 1_000_000_000_000;
const MS: u64 = 1_000_000;
const S: u64 = 1_000_000_000;
const JOINTS: usize = 6;

/// A periodic topic of the synthetic session: sample `seq` is stamped `T0 + phase + seq ×
/// period` and logged `delay` later.
#[derive(Clone, Copy)]
struct Stream {
    period: u64,
    phase: u64,
    delay: u64,
}

const GLOVE: Stream = Stream {
    period: 10 * MS,
    phase: MS,
    delay: 3 * MS,
};
const STATE: Stream = Stream {
    period: 2 * MS,
    phase: MS / 2,
    delay: MS / 5,
};
const TACTILE: Stream = Stream {
    period: 20 * MS,
    phase: 7 * MS,
    delay: MS,
};
const COMMAND: Stream = Stream {
    period: 10 * MS,
    phase: 4 * MS,
    delay: MS,
};
const FORCE: Stream = Stream {
    period: 10 * MS,
    phase: 6 * MS,
    delay: MS / 2,
};
/// hand/state is silent over this span (relative to T0): the stalled episode's.
const STALL: (u64, u64) = (11 * S, 11 * S + 600 * MS);
const END: u64 = 14 * S;

impl Stream {
    fn stamp(self, seq: u64) -> u64 {
        T0 + self.phase + seq * self.period
    }
    /// The newest sample at or before `at`.
    fn newest(self, at: u64) -> u64 {
        (at - T0 - self.phase) / self.period
    }
}

fn glove_position(seq: u64, c: usize) -> f32 {
    ((seq * 7 + c as u64 * 13) % 1000) as f32 / 1000.0
}
fn joint_position(seq: u64, j: usize) -> f32 {
    seq as f32 * 0.001 + j as f32
}
fn joint_speed(seq: u64, j: usize) -> f32 {
    -(seq as f32) * 0.01 - j as f32
}
fn tip_normal(seq: u64, i: usize) -> f32 {
    seq as f32 * 0.1 + i as f32
}
fn tip_tangential(i: usize) -> f32 {
    i as f32 * 2.0 + 0.5
}
fn target(seq: u64, j: usize) -> f32 {
    seq as f32 * 0.002 + j as f32 * 0.1
}
fn force(seq: u64, i: usize) -> i16 {
    ((seq % 500) + i as u64 * 10) as i16
}

/// The episode marks: (relative time, event, outcome, task).
fn marks() -> Vec<(u64, u8, u8, &'static str)> {
    use episode_event::{DISCARD, START, STOP};
    use episode_outcome::{FAILURE, SUCCESS, UNLABELLED};
    vec![
        (S, START, UNLABELLED, "pick up the cube"),
        (3 * S, STOP, SUCCESS, ""),
        (4 * S, START, UNLABELLED, "pick up the cube"),
        (6 * S, STOP, FAILURE, ""),
        (7 * S, START, UNLABELLED, "pour the water"),
        (8 * S + 500 * MS, DISCARD, UNLABELLED, ""),
        (10 * S + 500 * MS, START, UNLABELLED, "stack the blocks"),
        (12 * S, STOP, SUCCESS, ""),
        (13 * S, START, UNLABELLED, "wave"),
    ]
}

/// A side of the session: its namespace (`None`: the topics without one) and what it adds to
/// every value (so that the two sides of a bimanual recording differ).
type Side = (Option<&'static str>, f32);

/// What a synthetic session's hands do beyond the default.
#[derive(Clone, Copy)]
struct Variant {
    /// hand/state's effort of sample `seq`, joint `j` (the Revo2's is NaN: it measures none).
    effort: fn(u64, usize) -> f32,
    /// Whether hand/tactile is recorded.
    tactile: bool,
    /// Whether the hand profile is embedded (else the export finds it from the hand model).
    profile: bool,
}

const REVO2: Variant = Variant {
    effort: |_, _| f32::NAN,
    tactile: true,
    profile: true,
};

/// Writes the session: every side's topics and the marks, in log-time order, with the Revo2
/// profile embedded as the recorder embeds it.
fn write_recording(path: &Path, sides: &[Side]) {
    write_variant(path, sides, REVO2);
}

/// [`write_recording`] with the hands doing what `variant` says.
fn write_variant(path: &Path, sides: &[Side], variant: Variant) {
    let profile = Sandbox::repo().join("config/hands/revo2.toml");
    let mut metadata = vec![(
        "hand_profile".to_string(),
        BTreeMap::from([
            ("file".to_string(), profile.display().to_string()),
            (
                "text".to_string(),
                std::fs::read_to_string(&profile).unwrap(),
            ),
        ]),
    )];
    if !variant.profile {
        metadata.clear();
    }
    let mut rec = Recorder::create(path, WriterOptions::default(), &metadata).unwrap();
    let name =
        |ns: Option<&str>, topic: &str| ns.map_or(topic.to_string(), |ns| format!("{ns}/{topic}"));
    // Per side, per topic: (channel, id).
    let mut ids: Vec<Vec<(String, TopicId)>> = Vec::new();
    for (ns, _) in sides {
        let mut add = |topic: &str, schema: &str, text: String| {
            let channel = name(*ns, topic);
            let id = rec.add_topic(&channel, schema, &text).unwrap();
            (channel, id)
        };
        // Per topic in the order of `due`'s topic numbers (hand/tactile's channel is there even
        // when it gets no message, as when a recorder subscribed to a topic nobody published).
        ids.push(vec![
            add(
                GloveState::TOPIC,
                GloveState::SCHEMA_NAME,
                GloveState::schema(),
            ),
            add(
                HandState::TOPIC,
                HandState::SCHEMA_NAME,
                HandState::schema(),
            ),
            add(Tactile::TOPIC, Tactile::SCHEMA_NAME, Tactile::schema()),
            add(
                HandCommand::TOPIC,
                HandCommand::SCHEMA_NAME,
                HandCommand::schema(),
            ),
            add(
                GloveForceCommand::TOPIC,
                GloveForceCommand::SCHEMA_NAME,
                GloveForceCommand::schema(),
            ),
        ]);
    }
    let episode_id = rec.add_message_type::<Episode>().unwrap();
    // (log time, side, topic, seq) of every sample, then written in log order; topic 5 is a mark.
    let mut due: Vec<(u64, usize, usize, u64)> = Vec::new();
    for side in 0..sides.len() {
        for (topic, stream) in [GLOVE, STATE, TACTILE, COMMAND, FORCE]
            .into_iter()
            .enumerate()
        {
            if topic == 2 && !variant.tactile {
                continue;
            }
            let mut seq = 0;
            while stream.stamp(seq) < T0 + END {
                let rel = stream.stamp(seq) - T0;
                let stalled = topic == 1 && (STALL.0..STALL.1).contains(&rel);
                if !stalled {
                    due.push((stream.stamp(seq) + stream.delay, side, topic, seq));
                }
                seq += 1;
            }
        }
    }
    for (i, (at, ..)) in marks().into_iter().enumerate() {
        due.push((T0 + at + MS / 2, 0, 5, i as u64));
    }
    due.sort();
    for (log, side, topic, seq) in due {
        let off = sides[side].1;
        let mut write = |bytes: RecordedMessage| {
            let (channel, id) = &ids[side][topic];
            rec.write(
                *id,
                &RecordedMessage {
                    topic: channel,
                    ..bytes
                },
            )
            .unwrap();
        };
        match topic {
            0 => {
                let mut s = GloveState::default();
                s.header.stamp_ns = GLOVE.stamp(seq);
                s.position = std::array::from_fn(|c| glove_position(seq, c) + off);
                write(RecordedMessage::from_sample(&s, log));
            }
            1 => {
                let mut s = HandState {
                    hand_model: device_model::REVO2,
                    joint_count: JOINTS as u8,
                    units: units::NORMALISED,
                    ..HandState::default()
                };
                s.header.stamp_ns = STATE.stamp(seq);
                for (j, joint) in s.joints.iter_mut().enumerate().take(JOINTS) {
                    joint.position = joint_position(seq, j) + off;
                    joint.speed = joint_speed(seq, j) + off;
                    joint.effort = (variant.effort)(seq, j);
                }
                write(RecordedMessage::from_sample(&s, log));
            }
            2 => {
                let mut s = Tactile {
                    hand_model: device_model::REVO2,
                    fingertip_count: 5,
                    ..Tactile::default()
                };
                s.header.stamp_ns = TACTILE.stamp(seq);
                for (i, tip) in s.fingertips.iter_mut().enumerate() {
                    tip.normal_n = tip_normal(seq, i) + off;
                    tip.tangential_n = tip_tangential(i) + off;
                }
                write(RecordedMessage::from_sample(&s, log));
            }
            3 => {
                let mut s = HandCommand {
                    hand_model: device_model::REVO2,
                    joint_count: JOINTS as u8,
                    ..HandCommand::default()
                };
                s.header.stamp_ns = COMMAND.stamp(seq);
                for (j, joint) in s.joints.iter_mut().enumerate().take(JOINTS) {
                    joint.target = target(seq, j) + off;
                }
                write(RecordedMessage::from_sample(&s, log));
            }
            4 => {
                let mut s = GloveForceCommand::default();
                s.header.stamp_ns = FORCE.stamp(seq);
                s.force = std::array::from_fn(|i| force(seq, i) + off as i16);
                write(RecordedMessage::from_sample(&s, log));
            }
            _ => {
                let (at, event, outcome, task) = marks()[seq as usize];
                let mut s = Episode {
                    event,
                    outcome,
                    task: fixed_text(task),
                    ..Episode::default()
                };
                s.header.stamp_ns = T0 + at;
                rec.write(episode_id, &RecordedMessage::from_sample(&s, log))
                    .unwrap();
            }
        }
    }
    rec.finish().unwrap();
}

/// The frame at `at` as the recording's samples give it (newest at or before, every topic):
/// observation.state, action, glove.force_command.
fn expected_frame(at: u64, off: f32) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let (g, s, t, c, f) = (
        GLOVE.newest(at),
        STATE.newest(at),
        TACTILE.newest(at),
        COMMAND.newest(at),
        FORCE.newest(at),
    );
    let mut state: Vec<f32> = (0..6).map(|ch| glove_position(g, ch) + off).collect();
    state.extend((0..JOINTS).map(|j| joint_position(s, j) + off));
    state.extend((0..JOINTS).map(|j| joint_speed(s, j) + off));
    for i in 0..5 {
        state.extend([tip_normal(t, i) + off, tip_tangential(i) + off]);
    }
    let action = (0..JOINTS).map(|j| target(c, j) + off).collect();
    let forces = (0..5)
        .map(|i| f32::from(force(f, i) + off as i16))
        .collect();
    (state, action, forces)
}

fn floats(v: &serde_json::Value) -> Vec<f32> {
    v.as_array()
        .unwrap_or_else(|| panic!("not a list: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap() as f32)
        .collect()
}

fn export(sandbox: &Sandbox, rec: &Path, out: &Path, extra: &[&str]) -> (bool, String, String) {
    let mut args = vec![
        "export",
        rec.to_str().unwrap(),
        "--format",
        "lerobot",
        "--fps",
        "30",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let r = sandbox.run_teleop(&args);
    (
        r.status.success(),
        String::from_utf8_lossy(&r.stdout).into_owned(),
        String::from_utf8_lossy(&r.stderr).into_owned(),
    )
}

#[test]
fn episodes_export_to_a_lerobot_dataset_that_pyarrow_reads_back() {
    let sandbox = Sandbox::new();
    let rec: PathBuf = sandbox.dir.path().join("session.mcap");
    write_recording(&rec, &[(None, 0.0)]);
    let out = sandbox.dir.path().join("dataset");

    let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &["--with-force-command"]);
    assert!(ok, "{stdout}\n{stderr}");
    for line in [
        "episode 1 (\"pick up the cube\", success): episode 0 of the dataset, 61 frames",
        "episode 2 (\"pick up the cube\", failure): episode 1 of the dataset, 61 frames",
        "episode 3 (\"pour the water\") discarded: not exported",
        "episode 4 (\"stack the blocks\", success): refused: hand/state at",
        "episode 5 (\"wave\") was never stopped: not exported",
        "2 episodes exported, 1 refused; the dataset now holds 2 episodes, 122 frames, 1 tasks",
    ] {
        assert!(stdout.contains(line), "missing `{line}` in:\n{stdout}");
    }

    // Frame 10 of episode 0 (1 s + 10/30 s) and frame 5 of episode 1 (4 s + 5/30 s).
    for (index, at) in [
        (10u64, T0 + S + 333_333_333),
        (61 + 5, T0 + 4 * S + 166_666_667),
    ] {
        // Without pyarrow only this check skips: the appends below need none.
        let Some(report) = check_lerobot(&out, Some(index)) else {
            continue;
        };
        assert_eq!(report["total_episodes"], 2);
        assert_eq!(report["total_frames"], 122);
        let frame = &report["frame"];
        let (state, action, forces) = expected_frame(at, 0.0);
        assert_eq!(floats(&frame["observation.state"]), state, "frame {index}");
        assert_eq!(floats(&frame["action"]), action, "frame {index}");
        assert_eq!(
            floats(&frame["glove.force_command"]),
            forces,
            "frame {index}"
        );
    }
    let info = info_json(&out);
    let names = info["features"]["observation.state"]["names"]
        .as_array()
        .unwrap();
    assert_eq!(names[0], "glove.little.pos");
    assert_eq!(names[6], "thumb_flex.pos");
    assert_eq!(names[12], "thumb_flex.vel");
    assert_eq!(names[18], "thumb.tip.normal_n");
    assert_eq!(
        names.len(),
        6 + 2 * JOINTS + 10,
        "no effort columns for the Revo2"
    );
    assert_eq!(info["features"]["action"]["names"][5], "pinky.target");
    assert_eq!(info["robot_type"], "revo2");

    // Appending: only the success this time.
    let (ok, stdout, stderr) = export(
        &sandbox,
        &rec,
        &out,
        &["--with-force-command", "--only-success"],
    );
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("episode 2 (\"pick up the cube\") failure: not exported (--only-success)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("the dataset now holds 3 episodes, 183 frames"),
        "{stdout}"
    );
    if let Some(report) = check_lerobot(&out, Some(122 + 10)) {
        let (state, ..) = expected_frame(T0 + S + 333_333_333, 0.0);
        assert_eq!(floats(&report["frame"]["observation.state"]), state);
        assert_eq!(report["frame"]["episode_index"], 2);
        assert_eq!(report["total_tasks"], 1);
    }

    // Other features: refused by name, the dataset left as it was.
    let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &[]);
    assert!(!ok, "{stdout}");
    assert!(stderr.contains("glove.force_command"), "{stderr}");
    if let Some(report) = check_lerobot(&out, None) {
        assert_eq!(report["total_episodes"], 3);
    }
}

#[test]
fn bad_arguments_are_refused_by_name() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("session.mcap");
    write_recording(&rec, &[(None, 0.0)]);
    let out = sandbox.dir.path().join("dataset");
    let (ok, _, stderr) = export(&sandbox, &rec, &out, &["--min-rate-ratio", "1.5"]);
    assert!(!ok && stderr.contains("--min-rate-ratio 1.5"), "{stderr}");
    let missing = sandbox.dir.path().join("nope.mcap");
    let (ok, _, stderr) = export(&sandbox, &missing, &out, &[]);
    assert!(!ok && stderr.contains("nope.mcap"), "{stderr}");
    let (ok, _, stderr) = export(&sandbox, &rec, &out, &["--namespace", "left"]);
    assert!(!ok && stderr.contains("left/"), "{stderr}");
    // One file given twice (here by another path to it) would export its episodes twice.
    let again = sandbox.dir.path().join(".").join("session.mcap");
    let (ok, _, stderr) = export(&sandbox, &rec, &out, &[again.to_str().unwrap()]);
    assert!(!ok && stderr.contains("is given twice"), "{stderr}");
    assert!(!out.exists(), "no dataset from refused exports");
}

#[test]
fn a_bimanual_recording_exports_both_sides_named_by_side() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("bimanual.mcap");
    write_recording(&rec, &[(Some("left"), 0.0), (Some("right"), 100.0)]);
    let out = sandbox.dir.path().join("dataset");
    let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &["--with-force-command"]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("2 episodes exported, 1 refused"),
        "{stdout}"
    );
    assert!(stdout.contains("refused: left/hand/state at"), "{stdout}");
    let info = info_json(&out);
    assert_eq!(info["robot_type"], "revo2_bimanual");
    let names = info["features"]["observation.state"]["names"]
        .as_array()
        .unwrap();
    let per_side = 6 + 2 * JOINTS + 10;
    assert_eq!(names.len(), 2 * per_side);
    assert_eq!(names[6], "left/thumb_flex.pos");
    assert_eq!(names[per_side + 6], "right/thumb_flex.pos");
    assert_eq!(
        info["features"]["action"]["names"][JOINTS],
        "right/thumb_flex.target"
    );
    assert_eq!(
        info["features"]["glove.force_command"]["names"][5],
        "right/glove.little.force"
    );

    // Without an embedded profile the hand model comes from the first side's command
    // (left/hand/command: there is no unqualified one).
    let bare = sandbox.dir.path().join("bimanual-bare.mcap");
    write_variant(
        &bare,
        &[(Some("left"), 0.0), (Some("right"), 100.0)],
        Variant {
            profile: false,
            ..REVO2
        },
    );
    let bare_out = sandbox.dir.path().join("bare");
    let (ok, stdout, stderr) = export(&sandbox, &bare, &bare_out, &["--with-force-command"]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("2 episodes exported, 1 refused"),
        "{stdout}"
    );
    let bare_info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(bare_out.join("meta/info.json")).unwrap())
            .unwrap();
    assert_eq!(bare_info["features"], info["features"]);

    let Some(report) = check_lerobot(&out, Some(10)) else {
        return;
    };
    let at = T0 + S + 333_333_333;
    let (left, left_action, left_forces) = expected_frame(at, 0.0);
    let (right, right_action, right_forces) = expected_frame(at, 100.0);
    let frame = &report["frame"];
    assert_eq!(floats(&frame["observation.state"]), [left, right].concat());
    assert_eq!(
        floats(&frame["action"]),
        [left_action, right_action].concat()
    );
    assert_eq!(
        floats(&frame["glove.force_command"]),
        [left_forces, right_forces].concat()
    );
}

/// An export that dies at each of the writer's crash points (`TELEOP_EXPORT_CRASH_AT`: after
/// the first episode's frames, just before the swap, just after it) leaves a dataset that
/// reads right, the old version before the swap and the new one after it; the next export
/// removes what it left and appends.
#[test]
fn an_export_that_dies_at_each_crash_point_leaves_a_dataset_that_reads_right() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("session.mcap");
    write_recording(&rec, &[(None, 0.0)]);
    let out = sandbox.dir.path().join("dataset");
    let staging = sandbox.dir.path().join(".dataset.teleop-export-staging");
    let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &[]);
    assert!(ok, "{stdout}\n{stderr}");
    let total_episodes = || -> u64 {
        let info = info_json(&out);
        info["total_episodes"].as_u64().unwrap()
    };
    let mut episodes = 2;
    for (point, published) in [
        ("mid-data", false),
        ("before-swap", false),
        ("after-swap", true),
    ] {
        let r = sandbox
            .teleop()
            .args(["export", rec.to_str().unwrap(), "--format", "lerobot"])
            .args(["--fps", "30", "--out", out.to_str().unwrap()])
            .env("TELEOP_EXPORT_CRASH_AT", point)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert!(
            !r.status.success() && stderr.contains(&format!("TELEOP_EXPORT_CRASH_AT={point}")),
            "{point}: the export did not die there: {stderr}"
        );
        // What it left beside the dataset: its staging folder, or after the swap the old
        // version there.
        assert!(staging.exists(), "{point}: nothing left to clean up");
        if published {
            episodes += 2;
        }
        assert_eq!(total_episodes(), episodes, "{point}");
        if let Some(report) = check_lerobot(&out, None) {
            assert_eq!(
                report["total_episodes"].as_u64().unwrap(),
                episodes,
                "{point}"
            );
        }
        // The next export removes what was left and appends.
        let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &[]);
        assert!(ok, "after {point}: {stdout}\n{stderr}");
        episodes += 2;
        assert!(
            stdout.contains(&format!("the dataset now holds {episodes} episodes")),
            "after {point}: {stdout}"
        );
        assert!(
            !staging.exists(),
            "after {point}: the staging folder is gone"
        );
        if let Some(report) = check_lerobot(&out, None) {
            assert_eq!(report["total_episodes"].as_u64().unwrap(), episodes);
        }
    }
}

/// A stall the rate rule lets through is refused by the gap rule (naming the topic and the
/// gap) unless the gap is allowed; a later effort that is not finite refuses its episode by
/// name; a hand profile's fingertips without tactile samples refuse the export once.
#[test]
fn gaps_non_finite_values_and_missing_topics_are_refused_by_name() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("session.mcap");
    write_recording(&rec, &[(None, 0.0)]);
    let out = sandbox.dir.path().join("dataset");
    let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &["--min-rate-ratio", "0"]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains(
            "episode 4 (\"stack the blocks\", success): refused: hand/state silent for 602 ms, more than --max-gap-ms 100"
        ),
        "{stdout}"
    );
    let out = sandbox.dir.path().join("held");
    let extra = ["--min-rate-ratio", "0", "--max-gap-ms", "700"];
    let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &extra);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("3 episodes exported, 0 refused"),
        "{stdout}"
    );

    // Efforts measured, then NaN in one sample within episode 2 (4 s .. 6 s).
    let rec = sandbox.dir.path().join("efforts.mcap");
    write_variant(
        &rec,
        &[(None, 0.0)],
        Variant {
            // The sample frame 30 of episode 2 (due at 5 s) holds is NaN for joint 2.
            effort: |seq, j| {
                if seq == STATE.newest(T0 + 5 * S) && j == 2 {
                    f32::NAN
                } else {
                    seq as f32 * 0.01 + j as f32
                }
            },
            ..REVO2
        },
    );
    let out = sandbox.dir.path().join("efforts");
    let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &[]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains(
            "episode 2 (\"pick up the cube\", failure): refused: feature `observation.state`, `"
        ) && stdout.contains(".effort`: a value that is not finite at frame"),
        "{stdout}"
    );
    assert!(
        stdout.contains("1 episodes exported, 2 refused"),
        "{stdout}"
    );
    let info = info_json(&out);
    let names = info["features"]["observation.state"]["names"]
        .as_array()
        .unwrap();
    assert_eq!(
        names.len(),
        6 + 3 * JOINTS + 10,
        "effort columns: {names:?}"
    );
    if let Some(report) = check_lerobot(&out, Some(0)) {
        assert_eq!(report["total_episodes"], 1);
    }

    // The Revo2 profile has fingertip sensors; the recording has no tactile sample.
    let rec = sandbox.dir.path().join("no-tactile.mcap");
    write_variant(
        &rec,
        &[(None, 0.0)],
        Variant {
            tactile: false,
            ..REVO2
        },
    );
    let out = sandbox.dir.path().join("no-tactile");
    let (ok, stdout, stderr) = export(&sandbox, &rec, &out, &[]);
    assert!(!ok, "{stdout}");
    assert!(
        stderr.contains("no hand/tactile message")
            && stderr.contains("`observation.state`")
            && stderr.contains("thumb.tip.normal_n"),
        "{stderr}"
    );
    assert!(
        !stdout.contains("refused"),
        "refused once, not per episode: {stdout}"
    );
    assert!(!out.exists());
}

/// The dataset's `meta/info.json` at `out`, parsed.
fn info_json(out: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("meta/info.json")).unwrap()).unwrap()
}
