//! Soak: the default simulated session for a long time (default 600 s), checking that no process
//! grows in memory, nothing is dropped, and latency stays stable.
//!
//! Method: `teleop launch` runs the repository's `launch.toml` (release build) inside a sandbox.
//! Every 10 s the resident set size (VmRSS from /proc/<pid>/status) of every process and the
//! latency of `hand/command` and `glove/force_command` since the host received their device
//! sample (stamp - origin, from `teleop stats` over 2 s) are sampled. At the end the session summary gives drops,
//! restarts and faults. Memory growth = RSS at the end - RSS after a 60 s warm-up.
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example soak -- 600`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::time::{Duration, Instant};

use teleop_e2e::Sandbox;

fn rss_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

fn main() {
    let seconds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(600);
    let sandbox = Sandbox::new();
    let launch = sandbox.default_session(|t| t);
    let mut session = sandbox.launch(&launch);
    std::thread::sleep(Duration::from_secs(5));
    let link = sandbox.dir.path().join("glove").display().to_string();
    let sock = sandbox.dir.path().join("revo2.sock").display().to_string();
    let procs: Vec<(&str, u32)> = ["recorder", "glove", "revo2", "feedback", "retarget"]
        .iter()
        .map(|n| {
            (
                *n,
                sandbox.pid_of(n).unwrap_or_else(|| panic!("{n} running")),
            )
        })
        .chain([
            (
                "sim-glove",
                Sandbox::pid_with_arg(&format!("--link {link}")).unwrap(),
            ),
            ("sim-revo2", Sandbox::pid_with_arg(&sock).unwrap()),
        ])
        .collect();
    println!("soak for {seconds} s; sampling every 10 s: RSS per process (KiB), latency p99 (ms) of hand/command and glove/force_command");
    let start = Instant::now();
    let mut rss: Vec<Vec<u64>> = vec![Vec::new(); procs.len()];
    let mut baseline: Option<Vec<u64>> = None;
    let mut lat: Vec<(f64, f64)> = Vec::new();
    while start.elapsed() < Duration::from_secs(seconds) {
        std::thread::sleep(Duration::from_secs(8));
        let stats =
            String::from_utf8(sandbox.run_teleop(&["stats", "--seconds", "2"]).stdout).unwrap();
        let p99 = |topic: &str| -> f64 {
            stats
                .lines()
                .find(|l| l.starts_with(topic))
                .and_then(|l| l.split_whitespace().nth(5)?.parse().ok())
                .unwrap_or(f64::NAN)
        };
        lat.push((p99("hand/command"), p99("glove/force_command")));
        let now: Vec<u64> = procs
            .iter()
            .map(|(_, pid)| rss_kib(*pid).unwrap_or(0))
            .collect();
        if baseline.is_none() && start.elapsed() >= Duration::from_secs(60.min(seconds / 2)) {
            baseline = Some(now.clone());
        }
        for (r, v) in rss.iter_mut().zip(&now) {
            r.push(*v);
        }
        println!(
            "t={:>5.0}s rss {:?} p99 cmd {:.3} force {:.3}",
            start.elapsed().as_secs_f64(),
            now,
            lat.last().unwrap().0,
            lat.last().unwrap().1
        );
    }
    session.stop();
    let log = session.log();
    let summary = log
        .split("session summary")
        .nth(1)
        .unwrap_or("(no summary)");
    println!("\nsession summary{summary}");
    let baseline = baseline.unwrap_or_else(|| rss.iter().map(|r| r[0]).collect());
    println!(
        "{:<10} {:>12} {:>12} {:>10}",
        "PROCESS", "RSS_WARM", "RSS_END", "GROWTH"
    );
    for (i, (name, _)) in procs.iter().enumerate() {
        let end = *rss[i].last().unwrap();
        println!(
            "{name:<10} {:>12} {:>12} {:>+10}",
            baseline[i],
            end,
            end as i64 - baseline[i] as i64
        );
    }
    let finite = |v: Vec<f64>| -> Vec<f64> { v.into_iter().filter(|x| x.is_finite()).collect() };
    for (name, v) in [
        ("hand/command", finite(lat.iter().map(|l| l.0).collect())),
        (
            "glove/force_command",
            finite(lat.iter().map(|l| l.1).collect()),
        ),
    ] {
        let (lo, hi) = v
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
        println!(
            "{name}: latency p99 per 2 s window ranged {lo:.3} .. {hi:.3} ms over {} windows",
            v.len()
        );
    }
}
