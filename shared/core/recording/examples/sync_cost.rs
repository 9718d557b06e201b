//! What `sync_data` per closed chunk costs the recorder: the same stream written twice, with
//! `WriterOptions::sync` on and off, timing each chunk close (`Recorder::flush`: compress,
//! write, and with sync `fdatasync`).
//!
//! Method: the default session's heaviest topics at their rates (hand/state, hand/command and
//! glove/state at 1 kHz, hand/tactile at 100 Hz, health at 10 Hz), samples made on the fly, a
//! chunk closed every 100 ms of log time and paced in real time (as the recorder closes one
//! every 100 ms), for `SECONDS` (default 10) per mode, into a folder on the file system to
//! measure (default: the system's temporary folder). Prints p50/p99/max per chunk close.
//!
//! `cargo run --release -p teleop-recording --example sync_cost [-- FOLDER [SECONDS]]`
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_msgs::{GloveState, HandCommand, HandState, NodeHealth, Tactile};
use teleop_recording::{RecordedMessage, Recorder, WriterOptions};

fn main() {
    let mut args = std::env::args().skip(1);
    let folder = args.next().map(std::path::PathBuf::from);
    let seconds: u64 = args.next().map_or(10, |s| s.parse().unwrap());
    let dir = match &folder {
        Some(f) => tempfile::tempdir_in(f).unwrap(),
        None => tempfile::tempdir().unwrap(),
    };
    println!(
        "sync_cost: {seconds} s per mode into {}, a chunk every 100 ms (times in us)",
        dir.path().display()
    );
    for sync in [false, true] {
        let path = dir.path().join(format!("sync-{sync}.mcap"));
        let (closes, bytes) = run(&path, sync, seconds);
        println!(
            "sync {:<5}  chunk close {}  ({} chunks, {:.1} MB)",
            sync,
            percentiles(closes.clone()),
            closes.len(),
            bytes as f64 / 1e6
        );
    }
}

/// Writes `seconds` of the stream; returns the duration of every chunk close (ns) and the
/// file size.
fn run(path: &std::path::Path, sync: bool, seconds: u64) -> (Vec<u64>, u64) {
    let options = WriterOptions {
        // Chunks are closed below, by the pacing loop.
        chunk_flush: Duration::from_secs(3600),
        sync,
        ..WriterOptions::default()
    };
    let mut rec = Recorder::create(path, options, &[]).unwrap();
    let state = rec.add_message_type::<HandState>().unwrap();
    let command = rec.add_message_type::<HandCommand>().unwrap();
    let glove = rec.add_message_type::<GloveState>().unwrap();
    let tactile = rec.add_message_type::<Tactile>().unwrap();
    let health = rec.add_message_type::<NodeHealth>().unwrap();
    let mut closes = Vec::new();
    let start = Instant::now();
    let mut seq = 0u64;
    for chunk in 0..seconds * 10 {
        for ms in 0..100u64 {
            seq += 1;
            let t = 1_000_000_000 + (chunk * 100 + ms) * 1_000_000;
            let mut s = HandState::default();
            s.header.seq = seq;
            s.header.stamp_ns = t;
            s.joints[0].position = (seq % 1000) as f32 * 1e-3;
            rec.write(state, &RecordedMessage::from_sample(&s, t))
                .unwrap();
            let mut c = HandCommand::default();
            c.header.seq = seq;
            c.header.stamp_ns = t;
            c.joints[0].target = (seq % 997) as f32 * 1e-3;
            rec.write(command, &RecordedMessage::from_sample(&c, t))
                .unwrap();
            let mut g = GloveState::default();
            g.header.seq = seq;
            g.header.stamp_ns = t;
            g.raw_position = [(seq % 1000) as u16; 6];
            rec.write(glove, &RecordedMessage::from_sample(&g, t))
                .unwrap();
            if ms % 10 == 0 {
                let mut x = Tactile::default();
                x.header.seq = seq / 10;
                x.header.stamp_ns = t;
                rec.write(tactile, &RecordedMessage::from_sample(&x, t))
                    .unwrap();
            }
            if ms == 0 {
                let mut h = NodeHealth::default();
                h.header.seq = seq / 100;
                h.header.stamp_ns = t;
                rec.write(health, &RecordedMessage::from_sample(&h, t))
                    .unwrap();
            }
        }
        let at = Instant::now();
        rec.flush().unwrap();
        closes.push(at.elapsed().as_nanos() as u64);
        // Real-time pacing: the next chunk closes 100 ms after this one was due.
        let due = start + Duration::from_millis((chunk + 1) * 100);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    let summary = rec.finish().unwrap();
    let bytes = std::fs::metadata(&summary.files[0]).unwrap().len();
    (closes, bytes)
}

fn percentiles(mut v: Vec<u64>) -> String {
    v.sort_unstable();
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1000.0;
    format!(
        "p50 {:>8.1}  p99 {:>8.1}  max {:>8.1}",
        at(0.5),
        at(0.99),
        at(1.0)
    )
}
