//! Benchmark: latency through the retargeting and force-feedback processes.
//!
//! Method: `teleop launch` runs `teleop-retarget` and `teleop-feedback` as separate processes
//! (release build); this program publishes a glove sample (resp. a hand state + tactile sample)
//! every 2 ms, and sleeps on the output topic's event until the hand command (resp. glove force command) whose
//! `origin_ns` equals the sample's stamp. Latency = receive time - publish stamp, both
//! CLOCK_MONOTONIC: one IPC hop in, the node's wake-up and step, one IPC hop out. The nodes sleep
//! in their WaitSets (event-driven), as in a session. Prints p50/p99/max over N samples after a
//! warm-up.
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example bench_stages`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::time::{Duration, Instant};

use teleop_e2e::{wait_for, Sandbox};
use teleop_msgs::{GloveForceCommand, GloveState, HandCommand, HandState, Tactile};
use teleop_runtime::{now_ns, NodeRuntime, Publisher, Subscriber};

const SAMPLES: usize = 5000;
const WARMUP: usize = 200;
const PERIOD: Duration = Duration::from_millis(2);

fn main() {
    let sandbox = Sandbox::new();
    sandbox.write(
        "launch.toml",
        r#"
[[process]]
name = "feedback"
program = "teleop-feedback"
args = ["--profile", "revo2.toml"]
[[process]]
name = "retarget"
program = "teleop-retarget"
args = ["--profile", "revo2.toml"]
"#,
    );
    sandbox.write(
        "revo2.toml",
        &std::fs::read_to_string(Sandbox::repo().join("config/hands/revo2.toml")).unwrap(),
    );
    let _session = sandbox.launch(&sandbox.dir.path().join("launch.toml"));
    let node = NodeRuntime::new("bench", &sandbox.ipc).unwrap();
    let mut glove: Publisher<GloveState> = node.publisher().unwrap();
    let commands: Subscriber<HandCommand> = node.subscriber().unwrap();
    let mut state: Publisher<HandState> = node.publisher().unwrap();
    let mut tactile: Publisher<Tactile> = node.publisher().unwrap();
    let forces: Subscriber<GloveForceCommand> = node.subscriber().unwrap();

    println!("method: publish every {PERIOD:?}, sleep on the output's event, then take the output with the same origin_ns;");
    println!("        latency = receive - publish stamp (CLOCK_MONOTONIC), {SAMPLES} samples after {WARMUP} warm-up");

    wait_for(Duration::from_secs(20), "retarget", || {
        glove.publish(&live_glove(0)).unwrap();
        std::thread::sleep(Duration::from_millis(10));
        commands.poll_latest()
    });
    let glove_lat = measure(
        |i| glove.publish(&live_glove(i)).unwrap().stamp_ns,
        || {
            let mut got = Vec::new();
            commands.drain(|c| got.push(c.header.origin_ns));
            got
        },
        |t| {
            let _ = commands.listener().timed_wait(|_| {}, t);
        },
    );
    report("glove/state -> teleop-retarget -> hand/command", glove_lat);

    wait_for(Duration::from_secs(20), "feedback", || {
        state.publish(&live_hand()).unwrap();
        tactile.publish(&touch(1.0)).unwrap();
        std::thread::sleep(Duration::from_millis(10));
        forces.poll_latest().filter(|f| f.header.origin_ns != 0)
    });
    let tactile_lat = measure(
        |i| {
            state.publish(&live_hand()).unwrap();
            tactile
                .publish(&touch(1.0 + (i % 10) as f32 * 0.1))
                .unwrap()
                .stamp_ns
        },
        || {
            let mut got = Vec::new();
            forces.drain(|f| got.push(f.header.origin_ns));
            got
        },
        |t| {
            let _ = forces.listener().timed_wait(|_| {}, t);
        },
    );
    report(
        "hand/tactile -> teleop-feedback -> glove/force_command",
        tactile_lat,
    );
}

fn live_glove(i: usize) -> GloveState {
    GloveState {
        raw_position: [(i % 1000) as u16; 6],
        link_up: 1,
        ..Default::default()
    }
}

fn live_hand() -> HandState {
    HandState {
        joint_count: 6,
        link_up: 1,
        ..Default::default()
    }
}

fn touch(n: f32) -> Tactile {
    let mut t = Tactile {
        fingertip_count: 5,
        ..Default::default()
    };
    t.fingertips[1].normal_n = n;
    t
}

/// Sends with `send(i)` (returns the origin stamp) and waits for an output with that origin.
fn measure(
    mut send: impl FnMut(usize) -> u64,
    mut receive: impl FnMut() -> Vec<u64>,
    wait: impl Fn(Duration),
) -> Vec<u64> {
    let mut latencies = Vec::with_capacity(SAMPLES);
    let mut lost = 0;
    for i in 0..SAMPLES + WARMUP {
        let next = Instant::now() + PERIOD;
        let origin = send(i);
        let deadline = Instant::now() + Duration::from_millis(100);
        let received = loop {
            if receive().contains(&origin) {
                break Some(now_ns());
            }
            if Instant::now() > deadline {
                break None;
            }
            wait(Duration::from_millis(1));
        };
        match received {
            Some(t) if i >= WARMUP => latencies.push(t - origin),
            None => lost += 1,
            _ => {}
        }
        while Instant::now() < next {
            std::thread::sleep(Duration::from_micros(100));
        }
    }
    if lost > 0 {
        println!("  ({lost} samples got no output within 100 ms)");
    }
    latencies
}

fn report(what: &str, mut v: Vec<u64>) {
    v.sort_unstable();
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1000.0;
    println!(
        "{what}: n={} p50={:.1} us p99={:.1} us max={:.1} us",
        v.len(),
        at(0.5),
        at(0.99),
        at(1.0)
    );
}
