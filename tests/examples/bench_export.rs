//! Benchmark: `teleop export --format lerobot` throughput (recorded seconds exported per second
//! of wall time) and peak memory, for a 1-minute and a 10-minute recording, side by side in one
//! run with the floor and with the tool a lab would otherwise use, on the same recordings.
//!
//! Method: the program writes synthetic recordings with `teleop-recording` (as the recorder
//! writes them: zstd chunks, the Revo2 profile embedded) at the rates a real simulated session
//! records: a `teleop launch --duration 8` of the default session (2026-11-27) recorded
//! hand/state and hand/tactile at 1005 Hz, glove/force_command at 1106 Hz, glove/state and
//! hand/command at 255 Hz, health at 10 Hz, glove/diagnostics at 2 Hz (3 640 messages/s). The
//! operator does 20 s episodes with 5 s between them (START, then STOP with success). Three
//! methods, each run as a child process on each recording:
//! - `teleop export` (REPEATS runs): 30 fps, with the force command, into a fresh folder;
//! - the floor (REPEATS runs): this program with `--floor FILE`, which reads every message of
//!   the file with `teleop-recording`'s reader (every chunk decompressed, every message
//!   iterated and its payload copied out, as the export's reading does) and nothing else: no
//!   decoding, resampling or writing;
//! - the lab's script (PYTHON_REPEATS runs: each takes minutes), `bench_export_python.py`: the
//!   `mcap` + `mcap-ros2-support` reader and decoder, numpy's zero-order hold at 30 fps, one
//!   parquet file per episode with pyarrow (what it does and does not do: its docstring). Its
//!   interpreter is resolved once (`sys.executable`) so that no launcher shim is timed. Without
//!   python3 or its packages the row is skipped with the reason.
//!
//! For each run: its wall time from spawn to exit (start-up, reading, resampling, writing and
//! the export's final consistency check included), and its peak resident set (`ru_maxrss` of
//! that child from `wait4`). Reported per recording and method: the wall time's p50, p99 and max
//! over the runs (nearest rank: with 5 or 3 runs p99 is the max), each as recorded seconds per
//! wall second (so the max is the slowest run), and the largest peak RSS.
//!
//! Run (release: the floor is this program, so it must be optimised as `teleop` is):
//! `cargo build --release -p teleop && TELEOP_TEST_BIN_DIR=target/release cargo run --release -p teleop-e2e --example bench_export`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use teleop_e2e::{bin, netns::skip, Sandbox};
use teleop_msgs::{
    device_model, episode_event, episode_outcome, fixed_text, Episode, GloveDiagnostics,
    GloveForceCommand, GloveState, HandCommand, HandState, Message, NodeHealth, Tactile,
};
use teleop_recording::{read_messages, Filter, RecordedMessage, Recorder, TopicId, WriterOptions};

/// Runs of `teleop export` and of the floor per recording.
const REPEATS: usize = 5;
/// Runs of the Python script per recording (a 10-minute recording takes it minutes).
const PYTHON_REPEATS: usize = 3;
const T0: u64 = 5_000_000_000_000;
const S: u64 = 1_000_000_000;

/// (rate in Hz, what) of the session's topics.
const RATES: [(f64, usize); 7] = [
    (1005.0, 0), // hand/state
    (1005.0, 1), // hand/tactile
    (1106.0, 2), // glove/force_command
    (255.0, 3),  // glove/state
    (255.0, 4),  // hand/command
    (10.0, 5),   // health
    (2.0, 6),    // glove/diagnostics
];

struct Writer {
    rec: Recorder,
    ids: Vec<TopicId>,
}

impl Writer {
    fn put<M: Message>(&mut self, id: usize, mut sample: M, stamp: u64, seq: u64) {
        let header = sample.header_mut();
        header.stamp_ns = stamp;
        header.seq = seq + 1;
        self.rec
            .write(
                self.ids[id],
                &RecordedMessage::from_sample(&sample, stamp + 200_000),
            )
            .unwrap();
    }
}

/// Writes `minutes` of the session with episodes; returns the recorded seconds.
fn write_recording(path: &Path, minutes: u64) -> f64 {
    let profile = Sandbox::repo().join("config/hands/revo2.toml");
    let metadata = vec![(
        "hand_profile".to_string(),
        BTreeMap::from([
            ("file".to_string(), "config/hands/revo2.toml".to_string()),
            (
                "text".to_string(),
                std::fs::read_to_string(profile).unwrap(),
            ),
        ]),
    )];
    let mut rec = Recorder::create(path, WriterOptions::default(), &metadata).unwrap();
    let ids = vec![
        rec.add_message_type::<HandState>().unwrap(),
        rec.add_message_type::<Tactile>().unwrap(),
        rec.add_message_type::<GloveForceCommand>().unwrap(),
        rec.add_message_type::<GloveState>().unwrap(),
        rec.add_message_type::<HandCommand>().unwrap(),
        rec.add_message_type::<NodeHealth>().unwrap(),
        rec.add_message_type::<GloveDiagnostics>().unwrap(),
        rec.add_message_type::<Episode>().unwrap(),
    ];
    let mut w = Writer { rec, ids };
    let end = T0 + minutes * 60 * S;
    // The next sample of each topic: (stamp, topic, seq), merged in time order.
    let mut next: Vec<(u64, usize, u64)> = RATES.iter().map(|&(_, t)| (T0, t, 0)).collect();
    // Episodes: START at 5 s + 25 s × n, STOP 20 s later.
    let mut marks: Vec<(u64, u8)> = Vec::new();
    let mut at = T0 + 5 * S;
    while at + 20 * S < end {
        marks.push((at, episode_event::START));
        marks.push((at + 20 * S, episode_event::STOP));
        at += 25 * S;
    }
    let mut mark = 0;
    loop {
        let (i, &(stamp, topic, seq)) = next.iter().enumerate().min_by_key(|(_, n)| n.0).unwrap();
        if stamp >= end {
            break;
        }
        while mark < marks.len() && marks[mark].0 <= stamp {
            let (t, event) = marks[mark];
            let e = Episode {
                event,
                outcome: episode_outcome::SUCCESS,
                task: fixed_text("grasp the ball"),
                ..Episode::default()
            };
            w.put(7, e, t, mark as u64);
            mark += 1;
        }
        let x = (seq as f32 * 0.001).sin();
        match topic {
            0 => {
                let mut s = HandState {
                    hand_model: device_model::REVO2,
                    joint_count: 6,
                    ..HandState::default()
                };
                for j in s.joints.iter_mut().take(6) {
                    j.position = x;
                    j.speed = -x;
                    j.effort = f32::NAN;
                }
                w.put(0, s, stamp, seq);
            }
            1 => {
                let mut s = Tactile {
                    hand_model: device_model::REVO2,
                    fingertip_count: 5,
                    ..Tactile::default()
                };
                for f in s.fingertips.iter_mut() {
                    f.normal_n = x.abs();
                    f.tangential_n = x * 0.1;
                }
                w.put(1, s, stamp, seq);
            }
            2 => {
                let s = GloveForceCommand {
                    force: [(x * 300.0) as i16; 5],
                    ..GloveForceCommand::default()
                };
                w.put(2, s, stamp, seq);
            }
            3 => {
                let s = GloveState {
                    position: [x.abs(); 6],
                    ..GloveState::default()
                };
                w.put(3, s, stamp, seq);
            }
            4 => {
                let mut s = HandCommand {
                    hand_model: device_model::REVO2,
                    joint_count: 6,
                    ..HandCommand::default()
                };
                for j in s.joints.iter_mut().take(6) {
                    j.target = x;
                }
                w.put(4, s, stamp, seq);
            }
            5 => w.put(5, NodeHealth::default(), stamp, seq),
            _ => w.put(6, GloveDiagnostics::default(), stamp, seq),
        }
        let rate = RATES[i].0;
        next[i] = (T0 + ((seq + 1) as f64 * 1e9 / rate) as u64, topic, seq + 1);
    }
    w.rec.finish().unwrap();
    (minutes * 60) as f64
}

/// One child's run: wall time from spawn to exit, peak RSS, what it printed.
struct Run {
    wall: f64,
    rss_mib: f64,
    stdout: String,
}

/// Runs `cmd` to its end as a child, measured; panics naming `what` unless it succeeded.
fn measure(cmd: &mut Command, what: &str) -> Run {
    let started = Instant::now();
    // Waited for with wait4 below, which gives this child's own rusage (std's wait does not).
    #[allow(clippy::zombie_processes)]
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {what}: {e}"));
    let mut stdout = String::new();
    // Read to its end (the child's exit) before waiting: a full pipe would hold the child up.
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut stdout)
        .unwrap();
    let mut status = 0;
    // SAFETY: a zeroed rusage is a valid out-parameter; the pid is our own unwaited child.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let pid = child.id() as libc::pid_t;
    // SAFETY: valid pointers to locals for the call's duration.
    let rc = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    let wall = started.elapsed().as_secs_f64();
    assert_eq!(rc, pid, "wait4: {}", std::io::Error::last_os_error());
    assert!(
        libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0,
        "{what} failed (status {status}): {stdout}"
    );
    Run {
        wall,
        // ru_maxrss is in KiB on Linux (getrusage(2)).
        rss_mib: usage.ru_maxrss as f64 / 1024.0,
        stdout,
    }
}

/// One `teleop export` into a fresh `out`.
fn export_once(recording: &Path, out: &Path) -> Run {
    let _ = std::fs::remove_dir_all(out);
    measure(
        Command::new(bin("teleop"))
            .args(["export", recording.to_str().unwrap(), "--format", "lerobot"])
            .args([
                "--fps",
                "30",
                "--with-force-command",
                "--out",
                out.to_str().unwrap(),
            ]),
        "teleop export",
    )
}

/// One floor run: this program with `--floor`.
fn floor_once(recording: &Path) -> Run {
    measure(
        Command::new(std::env::current_exe().unwrap())
            .arg("--floor")
            .arg(recording),
        "the floor (--floor)",
    )
}

/// The floor's child: every message of `path` read and nothing else; prints the messages.
fn floor(path: &Path) {
    let mut messages = 0u64;
    let mut bytes = 0u64;
    for msg in read_messages(path, &Filter::all()).unwrap() {
        messages += 1;
        bytes += msg.unwrap().payload.len() as u64;
    }
    println!("{messages} {bytes}");
}

/// The interpreter that has the script's packages, or why there is none.
fn python() -> Result<PathBuf, String> {
    let out = Command::new("python3")
        .args([
            "-c",
            "import sys, numpy, pyarrow, mcap.reader, mcap_ros2.decoder; print(sys.executable)",
        ])
        .output()
        .map_err(|e| format!("cannot run python3 ({e})"))?;
    if out.status.success() {
        Ok(PathBuf::from(String::from_utf8_lossy(&out.stdout).trim()))
    } else {
        let err = String::from_utf8_lossy(&out.stderr);
        Err(format!(
            "{} (pip install -r .ci/requirements.txt)",
            err.trim().lines().last().unwrap_or("python3 failed")
        ))
    }
}

fn python_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/bench_export_python.py")
}

/// One run of the lab's script into a fresh `out`.
fn python_once(python: &Path, recording: &Path, out: &Path) -> Run {
    let _ = std::fs::remove_dir_all(out);
    measure(
        Command::new(python)
            .arg(python_script())
            .arg(recording)
            .arg(out)
            .arg("30"),
        "bench_export_python.py",
    )
}

/// Untimed: whether the script's frames in `out` are those of `dataset`, column by column;
/// the columns that differ (none: the same), or the row counts when those differ.
fn python_compare(python: &Path, dataset: &Path, out: &Path) -> String {
    let run = measure(
        Command::new(python)
            .arg(python_script())
            .arg("--compare")
            .arg(dataset)
            .arg(out),
        "bench_export_python.py --compare",
    );
    let report: serde_json::Value = serde_json::from_str(&run.stdout)
        .unwrap_or_else(|e| panic!("bench_export_python.py --compare's output: {e}"));
    let differ = report["differ"].as_array().unwrap();
    if report["rows"][0] != report["rows"][1] {
        format!(
            "rows differ: {} (ours) and {} (the script's)",
            report["rows"][0], report["rows"][1]
        )
    } else if differ.is_empty() {
        "equal to ours, every column, bit for bit".to_string()
    } else {
        format!("these columns differ from ours: {differ:?}")
    }
}

fn rank(sorted: &[f64], q: f64) -> f64 {
    let i = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

/// A speed-up as `527x`, or `2.4x` below 10.
fn times(x: f64) -> String {
    if x < 10.0 {
        format!("{x:.1}x")
    } else {
        format!("{x:.0}x")
    }
}

/// One table row: `runs` of a method on a recording of `recorded` seconds.
fn row(recording: &str, method: &str, output: &str, recorded: f64, runs: &[Run]) {
    let mut walls: Vec<f64> = runs.iter().map(|r| r.wall).collect();
    walls.sort_by(f64::total_cmp);
    let peak = runs.iter().map(|r| r.rss_mib).fold(0.0, f64::max);
    println!(
        "| {recording} | {method} | {output} | {} | {} | {} | {peak:.1} MiB |",
        times(recorded / rank(&walls, 0.5)),
        times(recorded / rank(&walls, 0.99)),
        times(recorded / walls[walls.len() - 1]),
    );
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let [flag, file] = &args[..] {
        if flag == "--floor" {
            floor(Path::new(file));
            return;
        }
    }
    assert!(args.is_empty(), "usage: bench_export [--floor FILE]");
    if cfg!(debug_assertions) {
        println!("warning: this program is a debug build, so is the floor's reader: run it with --release");
    }
    println!(
        "method: see the program's doc comment; per recording {REPEATS} runs of `teleop export` ({}), {REPEATS} of the floor, {PYTHON_REPEATS} of the Python script",
        bin("teleop").display()
    );
    let python = python();
    let sandbox = Sandbox::new();
    println!(
        "| recording | method | output | recorded s per s at p50 | at p99 | at max wall time | peak RSS |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut notes = Vec::new();
    for minutes in [1, 10] {
        let path = sandbox
            .dir
            .path()
            .join(format!("session-{minutes}min.mcap"));
        let recorded = write_recording(&path, minutes);
        let info = teleop_recording::info(&path).unwrap();
        let recording = format!(
            "{minutes} min ({} messages, {:.1} MB)",
            info.messages,
            info.size_bytes as f64 / 1e6
        );

        let floor: Vec<Run> = (0..REPEATS).map(|_| floor_once(&path)).collect();
        let read: u64 = floor[0]
            .stdout
            .split_whitespace()
            .next()
            .and_then(|n| n.parse().ok())
            .unwrap();
        assert_eq!(read, info.messages, "the floor read every message");
        let what = format!("{read} messages read");
        row(
            &recording,
            "floor: read every message",
            &what,
            recorded,
            &floor,
        );

        let dataset = sandbox.dir.path().join(format!("dataset-{minutes}"));
        let export: Vec<Run> = (0..REPEATS).map(|_| export_once(&path, &dataset)).collect();
        let frames = teleop_dataset_frames(&dataset);
        let what = format!("{frames} frames");
        row(&recording, "`teleop export`", &what, recorded, &export);

        match &python {
            Ok(python) => {
                let out = sandbox.dir.path().join(format!("python-{minutes}"));
                let runs: Vec<Run> = (0..PYTHON_REPEATS)
                    .map(|_| python_once(python, &path, &out))
                    .collect();
                let report: serde_json::Value = serde_json::from_str(&runs[0].stdout)
                    .unwrap_or_else(|e| panic!("bench_export_python.py's output: {e}"));
                let theirs = report["frames"].as_u64().unwrap();
                let what = format!("{theirs} frames");
                row(
                    &recording,
                    "Python: mcap-ros2 + numpy + pyarrow",
                    &what,
                    recorded,
                    &runs,
                );
                notes.push(format!(
                    "{minutes} min: the Python script's frames: {}",
                    python_compare(python, &dataset, &out)
                ));
            }
            Err(reason) => {
                skip(&format!("the Python script: {reason}"));
                println!("| {recording} | Python: mcap-ros2 + numpy + pyarrow | skipped: {reason} | | | | |");
            }
        }
    }
    for note in notes {
        println!("{note}");
    }
}

/// Frames the last export wrote, from its `info.json`.
fn teleop_dataset_frames(out: &Path) -> u64 {
    let text = std::fs::read_to_string(out.join("meta/info.json")).unwrap();
    let info: serde_json::Value = serde_json::from_str(&text).unwrap();
    info["total_frames"].as_u64().unwrap()
}
