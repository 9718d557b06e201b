//! Benchmark: recorder throughput and CPU at the full simulated-session rate, and at replay
//! speed (`teleop replay --max-speed` into a second recorder).
//!
//! Method: (1) `teleop launch` runs the default simulated session (release build) with the
//! recorder writing into a temporary folder, for 10 s; the recorder's CPU time is read from
//! /proc/<pid>/stat (utime + stime) between 2 s and 10 s. (2) That recording is replayed at
//! maximum speed while a fresh `teleop-recorder` records the replayed topics; reported: replay
//! messages/s, recorder CPU, messages recorded and drops (a recorder that cannot keep up loses
//! samples, which its drop count shows).
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

    // Replay at maximum speed into a second recorder.
    let out = sandbox.dir.path().join("replayed.mcap");
    let mut recorder = Command::new(bin("teleop-recorder"))
        .args(["--out", out.to_str().unwrap()])
        .envs(sandbox.ipc.to_env())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let c0 = cpu_ticks(recorder.id()).unwrap();
    let t = Instant::now();
    let replay = sandbox.run_teleop(&["replay", rec.to_str().unwrap(), "--max-speed"]);
    let replay_time = t.elapsed();
    assert!(replay.status.success());
    std::thread::sleep(Duration::from_millis(300));
    let c1 = cpu_ticks(recorder.id()).unwrap();
    // SAFETY: kill(2) of our own child.
    unsafe {
        libc::kill(recorder.id() as libc::pid_t, libc::SIGINT);
    }
    recorder.wait().unwrap();
    let replayed = teleop_recording::info(&out).unwrap();
    let drops: u64 = replayed.topics.iter().filter_map(|t| t.drops).sum();
    println!(
        "replay --max-speed: {} messages in {:.2} s = {:.0} msg/s ({:.0}x real time); recorder CPU {:.1} % of the replay time, recorded {} ({:.1} %), sequence-gap drops {}",
        info.messages,
        replay_time.as_secs_f64(),
        info.messages as f64 / replay_time.as_secs_f64(),
        secs / replay_time.as_secs_f64(),
        (c1 - c0) as f64 / ticks_per_second() / replay_time.as_secs_f64() * 100.0,
        replayed.messages,
        100.0 * replayed.messages as f64 / info.messages as f64,
        drops
    );
}
