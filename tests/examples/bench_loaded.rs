//! The default session on a busy host: glove exchanges per second and `hand/command` latency with
//! and without a `cargo build` of this workspace running beside it.
//!
//! Method: `teleop launch` runs the repository's `launch.toml` (its own sandbox, the binaries of
//! this build or of `TELEOP_TEST_BIN_DIR`) for SECONDS, once on a quiet host and once while
//! `cargo build --release --workspace --bins` compiles this workspace from scratch into a
//! throw-away target folder (started 5 s before the session, killed after it). The session's
//! own summary gives the numbers: `glove/state` rate (one sample per glove exchange) and
//! `hand/command` latency since the host received the glove sample (stamp - origin,
//! p50/p99/max over every sample of the session). `--no-realtime` strips the launch file's
//! `sched_*` settings (the session as shipped before it had them).
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example
//! bench_loaded -- 20 [--no-realtime]`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use teleop_e2e::Sandbox;

/// One row of the session summary's topic table: (rate Hz, p50, p99, max ms).
fn row(summary: &str, topic: &str) -> Option<(f64, String, String, String)> {
    let line = summary
        .lines()
        .find(|l| l.split_whitespace().next() == Some(topic))?;
    let f: Vec<&str> = line.split_whitespace().collect();
    Some((
        f.get(1)?.parse().ok()?,
        f.get(2)?.to_string(),
        f.get(3)?.to_string(),
        f.get(4)?.to_string(),
    ))
}

/// A cold release build of this workspace into `target`, its output discarded.
fn background_build(target: &std::path::Path) -> Child {
    Command::new("cargo")
        .args(["build", "--release", "--workspace", "--bins"])
        .current_dir(Sandbox::repo())
        .env("CARGO_TARGET_DIR", target)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .process_group(0)
        .spawn()
        .expect("cargo build")
}

fn stop_build(mut build: Child) {
    // The whole process group: cargo and every rustc it started.
    // SAFETY: kill(2) on the group of a child this program started.
    unsafe {
        libc::kill(-(build.id() as libc::pid_t), libc::SIGKILL);
    }
    let _ = build.wait();
}

fn session(seconds: u64, realtime: bool) -> String {
    let sandbox = Sandbox::new();
    let launch = sandbox.default_session(|t| {
        if realtime {
            t
        } else {
            t.lines()
                .filter(|l| !l.starts_with("sched_"))
                .map(|l| format!("{l}\n"))
                .collect()
        }
    });
    let out = sandbox
        .teleop()
        .arg("launch")
        .arg(&launch)
        .args(["--duration", &seconds.to_string()])
        .env("TELEOP_LOG", "warn")
        .output()
        .unwrap();
    let log =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    log.split("session summary")
        .nth(1)
        .unwrap_or("")
        .to_string()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seconds: u64 = args.iter().find_map(|a| a.parse().ok()).unwrap_or(20);
    let realtime = !args.iter().any(|a| a == "--no-realtime");
    println!(
        "default session, {seconds} s per condition, binaries {}, launch.toml {}",
        std::env::var("TELEOP_TEST_BIN_DIR").unwrap_or_else(|_| "of this build".into()),
        if realtime {
            "as shipped (sched_policy fifo)"
        } else {
            "without its sched_* settings"
        }
    );
    println!(
        "{:<10} {:>14} {:>22}  {:>10} {:>10}",
        "HOST", "GLOVE_EXCH/S", "HAND_CMD p50/p99/max", "RESTARTS", "LOADAVG"
    );
    for loaded in [false, true] {
        let target = tempfile::tempdir().unwrap();
        let build = loaded.then(|| background_build(target.path()));
        if loaded {
            std::thread::sleep(Duration::from_secs(5));
        }
        let summary = session(seconds, realtime);
        let load = teleop_e2e::bench::loadavg();
        if let Some(build) = build {
            stop_build(build);
        }
        let glove = row(&summary, "glove/state");
        let cmd = row(&summary, "hand/command");
        let restarts = summary
            .lines()
            .find_map(|l| l.strip_prefix("restarts: "))
            .unwrap_or("?")
            .to_string();
        println!(
            "{:<10} {:>14} {:>22}  {:>10} {:>10}",
            if loaded { "build" } else { "quiet" },
            glove.as_ref().map_or("-".into(), |g| format!("{:.0}", g.0)),
            cmd.as_ref()
                .map_or("-".into(), |c| format!("{}/{}/{} ms", c.1, c.2, c.3)),
            restarts,
            load
        );
        if glove.is_none() {
            println!("(no summary; session output follows)\n{summary}");
        }
    }
}
