//! Benchmark: recorder throughput and CPU at the full simulated-session rate, and at replay
//! speed (`teleop replay --max-speed` into a second recorder).
//!
//! Method: (1) `teleop launch` runs the default simulated session (release build) with the
//! recorder writing into a temporary folder, for 10 s; the recorder's CPU time is read from
//! /proc/<pid>/stat (utime + stime) between 2 s and 10 s. (2) That recording is replayed at
//! maximum speed (every channel, `--topics`) while a fresh `teleop-recorder` records the
//! replayed topics; reported: the messages the replay says it sent, over its wall time from
//! process start to exit (start-up included); the replay's CPU time (user + system, from
//! getrusage(RUSAGE_CHILDREN) across its wait); the recorder's CPU (/proc/<pid>/schedstat, ns)
//! over the same wall time and in the 300 ms after; messages recorded and drops (a recorder
//! that cannot keep up loses samples, which its drop count shows).
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example bench_recording`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use teleop_e2e::{bin, Sandbox};

fn cpu_ticks(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = after.split_whitespace().collect();
    Some(fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?)
}

/// CPU time of a process in nanoseconds (the first field of /proc/<pid>/schedstat), for
/// windows too short for clock ticks.
fn cpu_ns(pid: u32) -> Option<u64> {
    std::fs::read_to_string(format!("/proc/{pid}/schedstat"))
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

fn ticks_per_second() -> f64 {
    // SAFETY: sysconf has no preconditions.
    (unsafe { libc::sysconf(libc::_SC_CLK_TCK) }) as f64
}

fn pid_of(sandbox: &Sandbox, node: &str) -> Option<u32> {
    let out = String::from_utf8(sandbox.run_teleop(&["nodes"]).stdout).ok()?;
    out.lines()
        .find(|l| l.starts_with(node) && l.contains("alive"))
        .and_then(|l| l.split_whitespace().nth(2)?.parse().ok())
}

fn main() {
    println!("method: see the program's doc comment; CPU = (utime + stime) / wall time of one process, 100 % = one core");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let sandbox = Sandbox::new();
    let launch = std::fs::read_to_string(root.join("launch.toml"))
        .unwrap()
        .replace("config/", &format!("{}/config/", root.display()))
        .replace(
            "\"--dir\", \"recordings\"",
            &format!(
                "\"--out\", \"{}/session.mcap\"",
                sandbox.dir.path().display()
            ),
        )
        .replace(
            "/tmp/teleop-glove",
            &format!("{}/glove", sandbox.dir.path().display()),
        )
        .replace(
            "/tmp/teleop-revo2.sock",
            &format!("{}/revo2.sock", sandbox.dir.path().display()),
        );
    let glove_cfg = std::fs::read_to_string(root.join("config/glove.toml"))
        .unwrap()
        .replace(
            "/tmp/teleop-glove",
            &format!("{}/glove", sandbox.dir.path().display()),
        );
    let revo2_cfg = std::fs::read_to_string(root.join("config/revo2.toml"))
        .unwrap()
        .replace(
            "/tmp/teleop-revo2.sock",
            &format!("{}/revo2.sock", sandbox.dir.path().display()),
        );
    sandbox.write("glove.toml", &glove_cfg);
    sandbox.write("revo2.toml", &revo2_cfg);
    let launch = launch
        .replace(
            &format!("{}/config/glove.toml", root.display()),
            "glove.toml",
        )
        .replace(
            &format!("{}/config/revo2.toml", root.display()),
            "revo2.toml",
        );
    let file = sandbox.write("launch.toml", &launch);
    let mut session = sandbox.launch(&file);
    std::thread::sleep(Duration::from_secs(2));
    let pid = pid_of(&sandbox, "recorder").expect("recorder running");
    let (c0, t0) = (cpu_ticks(pid).unwrap(), Instant::now());
    std::thread::sleep(Duration::from_secs(8));
    let (c1, t1) = (cpu_ticks(pid).unwrap(), Instant::now());
    session.stop();
    let cpu = (c1 - c0) as f64 / ticks_per_second() / (t1 - t0).as_secs_f64() * 100.0;
    let rec = sandbox.dir.path().join("session.mcap");
    let info = teleop_recording::info(&rec).unwrap();
    let secs = info.duration.as_secs_f64();
    let bytes = std::fs::metadata(&rec).unwrap().len();
    let drops: u64 = info.topics.iter().filter_map(|t| t.drops).sum();
    println!(
        "\nfull session: {} messages in {:.1} s = {:.0} msg/s, {:.2} MB/s on disk (zstd), recorder CPU {:.1} %, drops {}",
        info.messages,
        secs,
        info.messages as f64 / secs,
        bytes as f64 / secs / 1e6,
        cpu,
        drops
    );

    // Replay at maximum speed into a second recorder: every channel (`--topics`), not only the
    // sensor topics `teleop replay` publishes by default.
    let out = sandbox.dir.path().join("replayed.mcap");
    let mut recorder = Command::new(bin("teleop-recorder"))
        .args(["--out", out.to_str().unwrap()])
        .envs(sandbox.ipc.to_env())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let channels: Vec<String> = info.topics.iter().map(|t| t.topic.clone()).collect();
    let mut args = vec!["replay", rec.to_str().unwrap(), "--max-speed", "--topics"];
    args.extend(channels.iter().map(String::as_str));
    let children_cpu = || {
        // SAFETY: rusage is plain data that getrusage(2) fills.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: RUSAGE_CHILDREN of this process, into a valid rusage.
        assert_eq!(
            unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) },
            0
        );
        let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
        s(usage.ru_utime) + s(usage.ru_stime)
    };
    // The replay's CPU time (user + system): what the children waited for use, across its wait
    // (the recorder is waited for later).
    let before = children_cpu();
    let c0 = cpu_ns(recorder.id()).unwrap();
    let t = Instant::now();
    let mut replay = sandbox
        .teleop()
        .args(&args)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut replay_err = replay.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        std::io::Read::read_to_string(&mut replay_err, &mut text).unwrap();
        text
    });
    let status = replay.wait().unwrap();
    let replay_time = t.elapsed();
    // The recorder's CPU over exactly the replay's wall time.
    let c1 = cpu_ns(recorder.id()).unwrap();
    let replay_cpu = children_cpu() - before;
    assert!(status.success());
    let progress = reader.join().unwrap();
    // The replay's last progress line ends with "<sent> messages".
    let sent: u64 = progress
        .rsplit('\r')
        .find_map(|line| {
            line.trim()
                .strip_suffix(" messages")?
                .rsplit(' ')
                .next()?
                .parse()
                .ok()
        })
        .expect("the replay reports the messages it sent");
    // ... and until it has written what was queued.
    std::thread::sleep(Duration::from_millis(300));
    let c2 = cpu_ns(recorder.id()).unwrap();
    // SAFETY: kill(2) of our own child.
    unsafe {
        libc::kill(recorder.id() as libc::pid_t, libc::SIGINT);
    }
    recorder.wait().unwrap();
    let replayed = teleop_recording::info(&out).unwrap();
    let drops: u64 = replayed.topics.iter().filter_map(|t| t.drops).sum();
    let wall = replay_time.as_secs_f64();
    println!(
        "replay --max-speed: {sent} messages sent in {wall:.2} s wall (process start to exit, \
         start-up and reading the file's index included) = {:.0} msg/s ({:.0}x the recording's \
         {secs:.1} s); replay CPU {:.3} s = {:.0} % of its wall time; recorder CPU over the same \
         wall time {:.3} s = {:.0} %, and {:.3} s more in the next 300 ms; recorded {} ({:.1} % \
         of sent), sequence-gap drops {}",
        sent as f64 / wall,
        secs / wall,
        replay_cpu,
        replay_cpu / wall * 100.0,
        (c1 - c0) as f64 / 1e9,
        (c1 - c0) as f64 / 1e9 / wall * 100.0,
        (c2 - c1) as f64 / 1e9,
        replayed.messages,
        100.0 * replayed.messages as f64 / sent as f64,
        drops
    );
}
