//! Benchmark: the Revo2 node's cycle as the device sees it (period jitter at 1 kHz) and the
//! latency from a `hand/command` publication to the first cycle that carries it, idle and under
//! CPU stress.
//!
//! Method: the emulated Revo2 (`teleop_sim_revo2`) is served on a Unix socket by a thread of this
//! process, exactly as `nodes/devices/revo2/node/tests/against_sim.rs` does; the real `teleop-revo2` process
//! (release build, default config: 1 kHz, tactile in the process data) brings it to OP through
//! ethercrab. The serve thread stamps every frame with CLOCK_MONOTONIC (`now_ns`) as soon as it
//! has been read from the socket, runs it through the emulator and keeps the process-data frames
//! (those that made the emulator apply outputs) with the position target of joint 0 the
//! emulator's hand was driven to by that frame. Measurement starts 1 s after the first
//! `hand/state` with `link_up == 1` and lasts 20 s.
//!
//! 1. Period = time between consecutive process-data frames at the emulator; deviation =
//!    |period - 1000 us|.
//! 2. Meanwhile this process publishes a `HandCommand` (REVO2, 6 joints, POSITION, NORMALISED)
//!    every 5 ms, each at a pseudo-random point of the millisecond after its slot (so that the
//!    publications do not lock to one phase of the node's cycle), whose joint 0 target is
//!    k/1000, k stepping by 2 through 100..898 (exact after the node's per-mille rounding, never
//!    repeated within 2 s). Latency = arrival time of the first process-data frame carrying k -
//!    the `stamp_ns` that `Publisher::publish` returned.
//! 3. Both again with two `yes > /dev/null` child processes (one per core) spinning for the whole
//!    run.
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example bench_revo2`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use teleop_e2e::bench::{loadavg, percentiles};
use teleop_e2e::{bin, revo2_position_command, Sandbox};
use teleop_ecat_link::{FrameLink, StreamServer, MAX_FRAME};
use teleop_ecat_sim::SubDevice;
use teleop_msgs::{HandCommand, HandState};
use teleop_runtime::{now_ns, NodeRuntime, Publisher, Subscriber};
use teleop_sim_revo2::hand::Drive;
use teleop_sim_revo2::{revo2_subdevice, Revo2};

const SECONDS: u64 = 20;
const WARM_UP: Duration = Duration::from_secs(1);
const COMMAND_PERIOD: Duration = Duration::from_millis(5);
const NOMINAL_NS: u64 = 1_000_000;
/// Process-data frames recorded at most (20 s at 1 kHz with room to spare).
const CAPACITY: usize = 200_000;

type Sim = Arc<Mutex<SubDevice<Revo2>>>;

fn lock(sim: &Sim) -> std::sync::MutexGuard<'_, SubDevice<Revo2>> {
    sim.lock().unwrap_or_else(|e| e.into_inner())
}

/// One process-data frame: arrival time and joint 0's position target (per mille; -1 when the
/// joint is not position-driven).
#[derive(Clone, Copy)]
struct Frame {
    t_ns: u64,
    target: i32,
}

#[derive(Default)]
struct Recorded {
    frames: Vec<Frame>,
    /// Frames that were not process data (mailbox, AL state) while recording.
    other_frames: u64,
}

fn main() {
    println!("method: emulated Revo2 served on a Unix socket by a thread of this process, real teleop-revo2");
    println!("        process (1 kHz, default config); frames stamped with CLOCK_MONOTONIC when read from the");
    println!("        socket; {SECONDS} s after OP + 1 s warm-up; a HandCommand every 5 ms (+ random 0..1 ms phase)");
    println!("        with a new joint 0 target;");
    println!("        times in us: p50 / p99 / max");
    run(false);
    run(true);
}

fn run(stress: bool) {
    let sandbox = Sandbox::new();
    let socket = sandbox.dir.path().join("revo2.sock");
    let sim: Sim = Arc::new(Mutex::new(revo2_subdevice(None, 7)));
    let stop = Arc::new(AtomicBool::new(false));
    let recording = Arc::new(AtomicBool::new(false));
    let server = serve(
        StreamServer::bind(&socket).unwrap(),
        sim.clone(),
        stop.clone(),
        recording.clone(),
    );
    let config = sandbox.write(
        "revo2.toml",
        &format!("transport = \"sim:{}\"\n", socket.display()),
    );
    let log = std::fs::File::create(sandbox.dir.path().join("node.log")).unwrap();
    let mut node = Command::new(bin("teleop-revo2"))
        .arg("--config")
        .arg(&config)
        .envs(sandbox.ipc.to_env())
        .env("TELEOP_LOG", "info")
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .spawn()
        .unwrap();
    let runtime = NodeRuntime::new("bench-revo2", &sandbox.ipc).unwrap();
    let mut commands: Publisher<HandCommand> = runtime.publisher().unwrap();
    let states: Subscriber<HandState> = runtime.subscriber().unwrap();
    let start = Instant::now();
    while states.poll_latest().is_none_or(|s| s.link_up == 0) {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the node did not reach OP:\n{}",
            std::fs::read_to_string(sandbox.dir.path().join("node.log")).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let before = states.poll_latest().unwrap();
    let load_before = loadavg();

    let mut load: Vec<Child> = Vec::new();
    if stress {
        for _ in 0..2 {
            load.push(
                Command::new("yes")
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap(),
            );
        }
    }

    // Commands flow from the start of the warm-up so that the node follows them when recording
    // begins.
    // Each command goes out at a pseudo-random point of the millisecond after its 5 ms slot: a
    // fixed 5 ms period would lock the publications to one phase of the node's 1 ms cycle (both
    // run on the same clock) and measure that phase instead of the distribution.
    let mut published: Vec<(u64, i32)> = Vec::with_capacity(10_000);
    let mut i = 0usize;
    let mut rng = 0x9E37_79B9_7F4A_7C15u64;
    let mut slot = Instant::now();
    let warm_end = slot + WARM_UP;
    let end = warm_end + Duration::from_secs(SECONDS);
    let mut armed = false;
    while slot < end {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        let next = slot + Duration::from_micros(rng % 1000);
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
        if !armed && Instant::now() >= warm_end {
            recording.store(true, Ordering::SeqCst);
            armed = true;
        }
        let k = 100 + (2 * i % 800) as i32;
        i += 1;
        let mut targets = [0.0; 6];
        targets[0] = k as f32 / 1000.0;
        let header = commands
            .publish(&revo2_position_command(targets, 0.0))
            .unwrap();
        if armed {
            published.push((header.stamp_ns, k));
        }
        slot += COMMAND_PERIOD;
    }
    // Let the last commands reach the device before recording stops.
    std::thread::sleep(Duration::from_millis(50));
    recording.store(false, Ordering::SeqCst);
    let after = states.poll_latest().unwrap();
    let load_after = loadavg();

    for mut child in load {
        // SAFETY: kill(2) of our own child.
        unsafe {
            libc::kill(child.id() as libc::pid_t, libc::SIGKILL);
        }
        let _ = child.wait();
    }
    // SAFETY: kill(2) of our own child.
    unsafe {
        libc::kill(node.id() as libc::pid_t, libc::SIGINT);
    }
    node.wait().unwrap();
    stop.store(true, Ordering::SeqCst);
    let recorded = server.join().unwrap();
    let node_log = std::fs::read_to_string(sandbox.dir.path().join("node.log")).unwrap_or_default();

    report(stress, &recorded, &published, &before, &after, &node_log);
    println!("  load average (1 min) before / after: {load_before} / {load_after}");
}

/// Serves the emulated Revo2 on a socket until `stop`; returns the frames recorded while
/// `recording`.
fn serve(
    server: StreamServer,
    sim: Sim,
    stop: Arc<AtomicBool>,
    recording: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Recorded> {
    std::thread::spawn(move || {
        let start = Instant::now();
        let mut buf = vec![0u8; MAX_FRAME];
        let mut out = vec![0u8; MAX_FRAME];
        let mut rec = Recorded {
            frames: Vec::with_capacity(CAPACITY),
            other_frames: 0,
        };
        while !stop.load(Ordering::SeqCst) {
            let Some(mut conn) = server.accept().unwrap() else {
                lock(&sim).tick(start.elapsed());
                std::thread::sleep(Duration::from_millis(1));
                continue;
            };
            while !stop.load(Ordering::SeqCst) {
                match conn.recv(&mut buf, Duration::from_millis(1)) {
                    Ok(Some(n)) => {
                        let t_ns = now_ns();
                        let mut sim = lock(&sim);
                        let cycles = sim.app().output_cycles;
                        let reply = sim.process_frame_into(&buf[..n], &mut out, start.elapsed());
                        if recording.load(Ordering::Relaxed) {
                            if sim.app().output_cycles != cycles {
                                let target = match sim.app().hand().drives()[0] {
                                    Drive::Position { target, .. } => target.round() as i32,
                                    _ => -1,
                                };
                                if rec.frames.len() < CAPACITY {
                                    rec.frames.push(Frame { t_ns, target });
                                }
                            } else {
                                rec.other_frames += 1;
                            }
                        }
                        drop(sim);
                        if let Some(len) = reply {
                            if conn.send(&out[..len]).is_err() {
                                break;
                            }
                        }
                    }
                    Ok(None) => lock(&sim).tick(start.elapsed()),
                    Err(_) => break,
                }
            }
        }
        rec
    })
}

fn report(
    stress: bool,
    rec: &Recorded,
    published: &[(u64, i32)],
    before: &HandState,
    after: &HandState,
    node_log: &str,
) {
    let frames = &rec.frames;
    let periods: Vec<u64> = frames.windows(2).map(|w| w[1].t_ns - w[0].t_ns).collect();
    let deviation: Vec<u64> = periods.iter().map(|p| p.abs_diff(NOMINAL_NS)).collect();
    let span_s = frames
        .last()
        .zip(frames.first())
        .map_or(0.0, |(l, f)| (l.t_ns - f.t_ns) as f64 / 1e9);
    let late = |limit_us: u64| periods.iter().filter(|&&p| p > limit_us * 1000).count();

    // Latency: the first process-data frame at or after the publication that carries its target.
    // A command never carried was either superseded or lost. The node reads the latest command
    // at the start of a cycle, before its frame arrives here, and starts a cycle only after the
    // previous one's reply: the second frame after a publication was read after it. If the next
    // command was published before that frame arrived, it may have replaced this one (the node
    // sends the latest, by design); otherwise the command was lost.
    let mut latency = Vec::with_capacity(published.len());
    let (mut superseded, mut lost) = (0, 0);
    for (n, &(stamp, k)) in published.iter().enumerate() {
        let from = frames.partition_point(|f| f.t_ns < stamp);
        match frames[from..]
            .iter()
            .take_while(|f| f.t_ns < stamp + 1_000_000_000)
            .find(|f| f.target == k)
        {
            Some(f) => latency.push(f.t_ns - stamp),
            None => {
                let next_frame = frames.get(from + 1).map_or(u64::MAX, |f| f.t_ns);
                if published.get(n + 1).is_some_and(|p| p.0 < next_frame) {
                    superseded += 1;
                } else {
                    lost += 1;
                }
            }
        }
    }
    let mean_us = if latency.is_empty() {
        0.0
    } else {
        latency.iter().sum::<u64>() as f64 / latency.len() as f64 / 1000.0
    };
    let min_us = latency.iter().min().copied().unwrap_or(0) as f64 / 1000.0;

    println!(
        "\n{}",
        if stress {
            "under CPU stress: two `yes > /dev/null` child processes (one per core)"
        } else {
            "idle machine (apart from whatever else runs on it)"
        }
    );
    println!(
        "  {} process-data frames in {span_s:.2} s = {:.1} Hz; {} other frames",
        frames.len(),
        (frames.len().saturating_sub(1)) as f64 / span_s.max(1e-9),
        rec.other_frames
    );
    println!(
        "  cycle period at the device       {}",
        percentiles(periods.clone())
    );
    println!(
        "  |period - 1000 us|               {}",
        percentiles(deviation)
    );
    println!(
        "  periods > 1.5 ms: {}, > 2 ms: {}, > 5 ms: {} (of {})",
        late(1500),
        late(2000),
        late(5000),
        periods.len()
    );
    println!(
        "  command published -> first frame carrying it {}  (mean {mean_us:.1}, min {min_us:.1}; {} commands, never carried: {superseded} superseded by a newer one, {lost} otherwise)",
        percentiles(latency),
        published.len()
    );
    println!(
        "  node counters during the run: lost frames {}, link errors (wrong working counter) {}; link_up {}; recoveries logged: {}",
        after.lost_frames - before.lost_frames,
        after.link_errors - before.link_errors,
        after.link_up,
        node_log.matches("dropped to SAFE-OP").count()
    );
}
