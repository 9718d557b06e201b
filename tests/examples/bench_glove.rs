//! Benchmark: glove exchanges per second against the line limit, and the latency from the
//! simulated device's sample to the published `glove/state`.
//!
//! Method: the simulated glove runs in this process on a pseudo-terminal, pacing every byte at
//! 10 bit times of the baud rate and answering after 200 us of processing; the real
//! `teleop-glove` process (release build, diagnostics off so every exchange is a force
//! exchange) talks to it with `serialport`. For each glove state received here, the matching
//! device answer is the last one whose last byte left the device before the node received it
//! (exchanges are strictly sequential). Latency splits: device sample -> last byte sent
//! (processing + wire time), -> node received it, -> node published, and the total. Line limit =
//! baud / 10 / 34 bytes per exchange.
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example bench_glove`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use teleop_e2e::bench::percentiles;
use teleop_e2e::{bin, Sandbox};
use teleop_glove_protocol::BaudRate;
use teleop_msgs::GloveState;
use teleop_runtime::{NodeRuntime, Subscriber};
use teleop_sim_glove::hand::{Hand, HandModel, Script};
use teleop_sim_glove::{Faults, SimGlove, SimOptions};

const SECONDS: f64 = 5.0;

fn main() {
    println!("method: sim glove in-process on a pty (10 bit times per byte, 200 us processing), real teleop-glove process;");
    println!("        {SECONDS} s per baud rate after 0.5 s warm-up; latencies from CLOCK_MONOTONIC stamps, us p50/p99/max");
    for baud in [BaudRate::B115200, BaudRate::B57600, BaudRate::B19200] {
        run(baud);
    }
}

fn run(baud: BaudRate) {
    let sandbox = Sandbox::new();
    let link = sandbox.dir.path().join("glove");
    let sim = SimGlove::start(
        SimOptions {
            link: link.clone(),
            id: 1,
            baud,
            response_delay: Duration::from_micros(200),
            faults: Faults::default(),
            seed: 1,
        },
        Hand::new(Script::OpenClose { period_s: 2.0 }, HandModel::default()),
    )
    .unwrap();
    let config = sandbox.write(
        "glove.toml",
        &format!(
            "port = {:?}\nbaud = {}\ndiagnostics_hz = 0.0\nanswer_timeout_ms = 100\n",
            link.display().to_string(),
            baud.bits_per_second()
        ),
    );
    let mut node = Command::new(bin("teleop-glove"))
        .arg("--config")
        .arg(&config)
        .envs(sandbox.ipc.to_env())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let runtime = NodeRuntime::new("bench-glove", &sandbox.ipc).unwrap();
    let states: Subscriber<GloveState> = runtime.subscriber().unwrap();
    while states.poll_latest().is_none_or(|s| s.link_up == 0) {
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(500));
    sim.record_answers(true);
    states.drain(|_| {});
    let mut received = Vec::new();
    let start = Instant::now();
    while start.elapsed().as_secs_f64() < SECONDS {
        let _ = states
            .listener()
            .timed_wait(|_| {}, Duration::from_millis(10));
        states.drain(|s| received.push((*s, teleop_runtime::now_ns())));
    }
    let elapsed = start.elapsed().as_secs_f64();
    sim.record_answers(false);
    let answers = sim.take_answer_timings();
    // SAFETY: kill(2) of our own child.
    unsafe {
        libc::kill(node.id() as libc::pid_t, libc::SIGINT);
    }
    node.wait().unwrap();

    let (mut device, mut line_to_node, mut in_node, mut total, mut to_subscriber) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (s, got) in &received {
        let rx = s.header.origin_ns;
        let i = answers.partition_point(|a| a.sent_ns <= rx);
        if i == 0 {
            continue;
        }
        let a = answers[i - 1];
        device.push(a.sent_ns - a.sampled_ns);
        line_to_node.push(rx - a.sent_ns);
        in_node.push(s.header.stamp_ns - rx);
        total.push(s.header.stamp_ns - a.sampled_ns);
        to_subscriber.push(got.saturating_sub(s.header.stamp_ns));
    }
    let rate = received.len() as f64 / elapsed;
    let limit = f64::from(baud.bits_per_second()) / 10.0 / 34.0;
    println!(
        "\n{} baud: {:.1} exchanges/s = {:.1} % of the line limit {:.1}/s ({} answers, {} states)",
        baud.bits_per_second(),
        rate,
        100.0 * rate / limit,
        limit,
        answers.len(),
        received.len()
    );
    for (name, v) in [
        ("device sample -> answer's last byte sent", device),
        ("last byte sent -> node has the answer", line_to_node),
        ("node has it -> glove/state published", in_node),
        ("device sample -> glove/state published", total),
        ("published -> this subscriber woke", to_subscriber),
    ] {
        println!("  {name:<42} {}", percentiles(v));
    }
}
