//! Benchmark: the pipeline across two stations (operator and robot) joined by their bridges over
//! zenoh (QUIC, mutual TLS), on a veth pair between two network namespaces, beside the local
//! iceoryx2 hop, with 0, 5 and 20 ms of one-way delay injected in each direction.
//!
//! Method: `teleop_e2e::stations` starts `launch/revo2-operator.toml` and `launch/revo2-robot.toml` (release
//! builds, the simulated Revo2 closing on the ball, both bridges with `clock = "shared"`: the
//! namespaces share CLOCK_MONOTONIC, so one-way times are measured directly). This process
//! subscribes at both stations, polling every 200 us (the same for the local and the remote
//! hop, so their difference is the bridges' share); per sample, receive time (CLOCK_MONOTONIC)
//! minus a header stamp:
//!
//! - `hand/command` hop: at the robot (through both bridges) vs at the operator (the local
//!   iceoryx2 hop), each `now - stamp_ns` (the retargeting's publish time);
//! - `hand/state` hop: at the operator (through the bridges) vs at the robot (local);
//! - glove -> hand: `hand/command` at the robot, `now - origin_ns` (the glove node's receipt of
//!   the glove sample the command comes from);
//! - hand -> glove force: `glove/force_command` at the operator, `now - origin_ns` (the Revo2
//!   node's receipt of the hand sample the force comes from);
//! - bridge CPU: utime + stime from /proc over the window, % of one core;
//! - what the operator feels: the glove force's p50/max; the safety counters over the window
//!   (the Revo2 node's command timeouts, the feedback's stale inputs, the bridges' stale arrivals).
//!
//! Delay is injected by each bridge's fault injector on what it receives (a delay line: this
//! kernel has no netem), so 5 ms means 5 ms each way. 10 s per condition after 1 s settling.
//!
//! Root only. Run: `cargo build --release --workspace --bins --examples && cargo run --release -p teleop-e2e --example bench_remote`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::time::{Duration, Instant};

use teleop_e2e::bench::{loadavg, percentiles};
use teleop_e2e::stations::Station;
use teleop_msgs::{GloveForceCommand, HandCommand, HandState};
use teleop_runtime::{now_ns, Subscriber};

const WINDOW: Duration = Duration::from_secs(10);

fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the command's closing parenthesis: state is field 3; utime 14, stime 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let get = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<u64>().ok())
            .unwrap_or(0)
    };
    get(11) + get(12)
}

struct Probe {
    at_robot: Subscriber<HandCommand>,
    at_operator: Subscriber<HandCommand>,
    state_remote: Subscriber<HandState>,
    state_local: Subscriber<HandState>,
    force: Subscriber<GloveForceCommand>,
}

fn counters(operator: &Station, robot: &Station) -> (u64, u64, u64) {
    let (mut hand, mut feedback, mut stale) = (0, 0, 0);
    robot.health_of("revo2", |h| hand = hand.max(h.timeouts));
    operator.health_of("feedback", |h| feedback = feedback.max(h.timeouts));
    let stats = |s: &Station| {
        let answer = s.control("stats");
        answer
            .split_whitespace()
            .skip_while(|w| *w != "stale")
            .nth(1)
            .and_then(|v| v.parse::<u64>().ok())
            .unwrap_or(0)
    };
    stale += stats(operator) + stats(robot);
    (hand, feedback, stale)
}

fn condition(delay_ms: u32, operator: &Station, robot: &Station, probe: &Probe) {
    for s in [operator, robot] {
        assert!(s.control(&format!("delay {delay_ms}")).starts_with("ok"));
    }
    std::thread::sleep(Duration::from_secs(1));
    let before = counters(operator, robot);
    let pids = (operator.bridge_pid().unwrap(), robot.bridge_pid().unwrap());
    let cpu0 = (cpu_ticks(pids.0), cpu_ticks(pids.1));
    let (
        mut cmd_remote,
        mut cmd_local,
        mut st_remote,
        mut st_local,
        mut glove_hand,
        mut hand_glove,
        mut force,
    ) = (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    probe.at_robot.drain(|_| {});
    probe.at_operator.drain(|_| {});
    probe.state_remote.drain(|_| {});
    probe.state_local.drain(|_| {});
    probe.force.drain(|_| {});
    let start = Instant::now();
    while start.elapsed() < WINDOW {
        probe.at_robot.drain(|c| {
            let now = now_ns();
            cmd_remote.push(now.saturating_sub(c.header.stamp_ns));
            glove_hand.push(now.saturating_sub(c.header.origin_ns));
        });
        probe
            .at_operator
            .drain(|c| cmd_local.push(now_ns().saturating_sub(c.header.stamp_ns)));
        probe
            .state_remote
            .drain(|s| st_remote.push(now_ns().saturating_sub(s.header.stamp_ns)));
        probe
            .state_local
            .drain(|s| st_local.push(now_ns().saturating_sub(s.header.stamp_ns)));
        probe.force.drain(|f| {
            hand_glove.push(now_ns().saturating_sub(f.header.origin_ns));
            force.push(u64::from(
                f.force
                    .iter()
                    .copied()
                    .max()
                    .unwrap_or(0)
                    .max(0)
                    .unsigned_abs(),
            ));
        });
        std::thread::sleep(Duration::from_micros(200));
    }
    let wall = start.elapsed().as_secs_f64();
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    let cpu = |t0: u64, pid: u32| (cpu_ticks(pid) - t0) as f64 / hz / wall * 100.0;
    let after = counters(operator, robot);
    println!(
        "\n{delay_ms} ms injected each way ({} s):",
        WINDOW.as_secs()
    );
    println!("        times in us: p50 / p99 / max");
    let n = |v: &Vec<u64>| v.len();
    println!(
        "  hand/command, local iceoryx2 hop ({:>5})   {}",
        n(&cmd_local),
        percentiles(cmd_local)
    );
    println!(
        "  hand/command, across the bridges ({:>5})    {}",
        n(&cmd_remote),
        percentiles(cmd_remote)
    );
    println!(
        "  hand/state, local iceoryx2 hop ({:>5})     {}",
        n(&st_local),
        percentiles(st_local)
    );
    println!(
        "  hand/state, across the bridges ({:>5})      {}",
        n(&st_remote),
        percentiles(st_remote)
    );
    println!(
        "  glove sample -> hand/command at the robot   {}",
        percentiles(glove_hand)
    );
    println!(
        "  hand sample -> glove/force_command at the operator {}",
        percentiles(hand_glove)
    );
    let mut f = force.clone();
    f.sort_unstable();
    println!(
        "  glove force felt: p50 {} max {} (of 1000); bridge CPU: operator {:.1} %, robot {:.1} % of one core",
        f.get(f.len() / 2).copied().unwrap_or(0),
        f.last().copied().unwrap_or(0),
        cpu(cpu0.0, pids.0),
        cpu(cpu0.1, pids.1)
    );
    println!(
        "  safety over the window: hand command timeouts +{}, feedback stale +{}, stale arrivals at the bridges +{}",
        after.0.saturating_sub(before.0),
        after.1.saturating_sub(before.1),
        after.2.saturating_sub(before.2)
    );
}

fn main() {
    if let Some(reason) = teleop_e2e::netns::skip_reason() {
        println!("cannot run: {reason}");
        return;
    }
    println!(
        "two stations over a veth pair, zenoh over QUIC with mutual TLS; load average before: {}",
        loadavg()
    );
    let (_op_ns, _robot_ns, operator, robot) = teleop_e2e::stations::start("tlbn", |_, t| {
        t.replace("clock = \"estimate\"", "clock = \"shared\"")
    });
    let probe = Probe {
        at_robot: robot.node.subscriber().unwrap(),
        at_operator: operator.node.subscriber().unwrap(),
        state_remote: operator.node.subscriber().unwrap(),
        state_local: robot.node.subscriber().unwrap(),
        force: operator.node.subscriber().unwrap(),
    };
    let start = Instant::now();
    let mut crossing = 0;
    while crossing < 100 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the loop did not close\n{}\n{}",
            operator.logs(),
            robot.logs()
        );
        probe.at_robot.drain(|_| crossing += 1);
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_secs(2));
    for delay in [0, 5, 20] {
        condition(delay, &operator, &robot, &probe);
    }
    println!("\nload average after: {}", loadavg());
    let (mut operator, mut robot) = (operator, robot);
    operator.session.stop();
    robot.session.stop();
}
