//! Benchmark: `teleop export --format lerobot` throughput (recorded seconds exported per second
//! of wall time) and peak memory, for a 1-minute and a 10-minute recording side by side.
//!
//! Method: the program writes synthetic recordings with `teleop-recording` (as the recorder
//! writes them: zstd chunks, the Revo2 profile embedded) at the rates a real simulated session
//! records: a `teleop launch --duration 8` of the default session (2026-11-27) recorded
//! hand/state and hand/tactile at 1005 Hz, glove/force_command at 1106 Hz, glove/state and
//! hand/command at 255 Hz, health at 10 Hz, glove/diagnostics at 2 Hz (3 640 messages/s). The
//! operator does 20 s episodes with 5 s between them (START, then STOP with success). Each
//! recording is exported REPEATS times by the `teleop` executable as a child process (30 fps,
//! with the force command, into a fresh folder each time); for each run: its wall time from
//! spawn to exit (start-up, reading, resampling, writing and the final consistency check
//! included), and its peak resident set (`ru_maxrss` of that child from `wait4`). Reported per
//! recording: the wall time's p50, p99 and max over the runs (nearest rank: with 5 runs p99 is
//! the max), each as recorded seconds per wall second (so the max is the slowest run), and the
//! largest peak RSS.
//!
//! Run (the numbers in BENCHMARKS.md come from a release `teleop`; the program that writes the
//! recordings and times the runs may be a debug build):
//! `cargo build --release -p teleop && TELEOP_TEST_BIN_DIR=target/release cargo run -p teleop-e2e --example bench_export`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

use teleop_e2e::{bin, Sandbox};
use teleop_msgs::{
    device_model, episode_event, episode_outcome, fixed_text, Episode, GloveDiagnostics,
    GloveForceCommand, GloveState, HandCommand, HandState, Message, NodeHealth, Tactile,
};
use teleop_recording::{RecordedMessage, Recorder, TopicId, WriterOptions};

const REPEATS: usize = 5;
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

/// One export as a child process: (wall seconds, peak RSS in MiB).
fn export_once(recording: &Path, out: &Path) -> (f64, f64) {
    let _ = std::fs::remove_dir_all(out);
    let started = Instant::now();
    // Waited for with wait4 below, which gives this child's own rusage (std's wait does not).
    #[allow(clippy::zombie_processes)]
    let child = Command::new(bin("teleop"))
        .args(["export", recording.to_str().unwrap(), "--format", "lerobot"])
        .args([
            "--fps",
            "30",
            "--with-force-command",
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
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
        "teleop export failed (status {status})"
    );
    // ru_maxrss is in KiB on Linux (getrusage(2)).
    (wall, usage.ru_maxrss as f64 / 1024.0)
}

fn rank(sorted: &[f64], q: f64) -> f64 {
    let i = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

fn main() {
    println!("method: see the program's doc comment; {REPEATS} exports per recording, each a child `teleop export` ({})", bin("teleop").display());
    let sandbox = Sandbox::new();
    println!(
        "| recording | messages | file | exported frames | recorded s per s at p50 | at p99 | at max wall time | peak RSS |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for minutes in [1, 10] {
        let path = sandbox
            .dir
            .path()
            .join(format!("session-{minutes}min.mcap"));
        let recorded = write_recording(&path, minutes);
        let info = teleop_recording::info(&path).unwrap();
        let out = sandbox.dir.path().join(format!("dataset-{minutes}"));
        let mut walls = Vec::new();
        let mut peak: f64 = 0.0;
        for _ in 0..REPEATS {
            let (wall, rss) = export_once(&path, &out);
            walls.push(wall);
            peak = peak.max(rss);
        }
        walls.sort_by(f64::total_cmp);
        let summary = teleop_dataset_frames(&out);
        println!(
            "| {minutes} min | {} | {:.1} MB | {summary} | {:.0}x | {:.0}x | {:.0}x | {peak:.1} MiB |",
            info.messages,
            info.size_bytes as f64 / 1e6,
            recorded / rank(&walls, 0.5),
            recorded / rank(&walls, 0.99),
            recorded / walls[walls.len() - 1],
        );
    }
}

/// Frames the last export wrote, from its `info.json`.
fn teleop_dataset_frames(out: &Path) -> u64 {
    let text = std::fs::read_to_string(out.join("meta/info.json")).unwrap();
    let info: serde_json::Value = serde_json::from_str(&text).unwrap();
    info["total_frames"].as_u64().unwrap()
}
