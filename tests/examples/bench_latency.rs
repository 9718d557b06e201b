//! Benchmark: the session's latency budget, split per stage, beside its physical floor.
//!
//! Method: both device simulators run inside this program (so it sees device-side times) at the
//! paths the nodes expect; `teleop launch` runs the glove, retargeting, Revo2 and force-feedback
//! nodes as processes (release build, the repository's configurations). For 20 s after a warm-up:
//! - Path A, glove sample -> the EtherCAT cycle that carries its hand command: the simulated
//!   glove records when it sampled each answer; `glove/state` (origin = the node's receive time)
//!   is matched to the last answer sent before it; `hand/command` to the glove state by
//!   `origin_ns`; the cycle by the first frame at the emulated Revo2, after the command's stamp,
//!   whose position targets equal the command's. Only commands whose targets (per mille) no
//!   other command of the run has are measured, so that a frame carrying an earlier, identical
//!   command is never taken for a later one's. Stages: device sample -> `glove/state`
//!   published -> `hand/command` published -> frame at the device. Floor: one EtherCAT cycle.
//! - Path B, Revo2 tactile sample -> the glove force frame's last byte on the serial line: the
//!   emulated Revo2 records when it answered each frame (its inputs are sampled then);
//!   `hand/tactile` is matched to the last frame before its origin; `glove/force_command` by
//!   `origin_ns`; the force frame by the first request at the simulated glove, after the
//!   command's stamp, carrying the same forces (last byte, at 115200 baud). Stages: device
//!   sample -> `hand/tactile` published -> `glove/force_command` published -> last byte at the
//!   glove. Floor: one serial exchange (34 bytes at 115200 baud = 2.95 ms).
//!
//! - EtherCAT period deviation: |interval - 1 ms| between consecutive process-data frames at
//!   the emulated Revo2 (stamped when it answered each one; mailbox frames left out).
//!
//! - Wake-up floor: a thread at SCHED_FIFO 90 sleeps to 1 ms absolute deadlines
//!   (`clock_nanosleep`) through each case and records how late it wakes (what `cyclictest`
//!   measures): no scheduling policy gets a loop closer to its deadline than this machine does.
//!
//! Four cases side by side in one run: the nodes at the normal policy and at a real-time policy
//! (`launch.toml`: `sched_policy = "fifo"`, the Revo2 node at priority 70, the glove 60,
//! retargeting and force feedback 50), each idle and under CPU stress (two `yes > /dev/null`
//! processes, one per core). The simulators stand in for devices, which do not share the
//! host's CPU: in every case their threads run at SCHED_FIFO 80 (when the program may; it says
//! when not), so the cases differ only in the nodes' policy.
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example bench_latency`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::collections::HashMap;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use teleop_e2e::Sandbox;
use teleop_ecat_link::serve_socket;
use teleop_ecat_link::StreamServer;
use teleop_ecat_sim::SubDevice;
use teleop_glove_protocol::BaudRate;
use teleop_msgs::{GloveForceCommand, GloveState, HandCommand, Tactile};
use teleop_runtime::realtime::{
    enter_realtime_with, leave_realtime, Outcome, Realtime, SchedPolicy,
};
use teleop_runtime::{now_ns, NodeRuntime, Subscriber};
use teleop_sim_glove::hand::{Hand as GloveHand, HandModel, Script};
use teleop_sim_glove::{Faults, SimGlove, SimOptions};
use teleop_sim_revo2::hand::{Drive, VirtualObject};
use teleop_sim_revo2::{revo2_subdevice, Revo2};

const SECONDS: u64 = 20;

/// What the emulated Revo2 saw per frame: when, and the position targets it then had.
#[derive(Default)]
struct Frames {
    at: Vec<(u64, [f32; 6])>,
    /// When each process-data frame (one per cycle) was answered; the others are mailbox and
    /// state frames.
    cycles: Vec<u64>,
    output_cycles: u64,
}

fn serve_revo2(
    server: StreamServer,
    sim: Arc<Mutex<SubDevice<Revo2>>>,
    frames: Arc<Mutex<Frames>>,
    stop: Arc<AtomicBool>,
) {
    let stopping = || stop.load(Ordering::SeqCst);
    let mut record = |_received: Instant, dev: &SubDevice<Revo2>| {
        let targets = dev.app().hand().drives().map(|d| match d {
            Drive::Position { target, .. } | Drive::Hold(target) => target,
            _ => f32::NAN,
        });
        // The frame has been answered: its inputs were sampled now.
        let now = now_ns();
        let mut frames = frames.lock().unwrap();
        frames.at.push((now, targets));
        let cycles = dev.app().output_cycles;
        if cycles != frames.output_cycles {
            frames.output_cycles = cycles;
            frames.cycles.push(now);
        }
    };
    serve_socket(&server, &sim, Instant::now(), &stopping, &mut record).unwrap();
}

/// p50, p99 and max in ms (None: no samples).
fn quantiles(v: &[u64]) -> Option<[f64; 3]> {
    let mut v = v.to_vec();
    if v.is_empty() {
        return None;
    }
    v.sort_unstable();
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1e6;
    Some([at(0.5), at(0.99), at(1.0)])
}

fn percentiles(v: Vec<u64>) -> String {
    match quantiles(&v) {
        None => "-".into(),
        Some([p50, p99, max]) => format!(
            "p50 {p50:>7.3}  p99 {p99:>7.3}  max {max:>7.3}  (n={})",
            v.len()
        ),
    }
}

/// One case's headline figures.
struct Summary {
    label: String,
    exchanges: f64,
    period: Option<[f64; 3]>,
    floor: Option<[f64; 3]>,
    a: Option<[f64; 3]>,
    b: Option<[f64; 3]>,
}

/// The launch file's real-time settings for a node process (by its config file).
const NODE_PRIORITIES: [(&str, u8); 4] = [
    ("config/revo2.toml", 70),
    ("config/glove.toml", 60),
    ("config/revo2/retarget.toml", 50),
    ("config/revo2/feedback.toml", 50),
];
/// The simulators' priority (they stand in for devices).
const SIM_PRIORITY: u8 = 80;

/// Sleeps to 1 ms absolute deadlines at SCHED_FIFO 90 until `stop`; returns how late each
/// wake-up was (ns).
fn wake_probe(stop: Arc<AtomicBool>) -> std::thread::JoinHandle<Vec<u64>> {
    std::thread::spawn(move || {
        enter_realtime_with(&Realtime {
            policy: SchedPolicy::Fifo,
            priority: 90,
            ..Default::default()
        });
        let mut late = Vec::with_capacity(SECONDS as usize * 1000 + 1000);
        let mut deadline = now_ns();
        while !stop.load(Ordering::SeqCst) {
            deadline += 1_000_000;
            teleop_runtime::sleep_until_ns(deadline);
            late.push(now_ns().saturating_sub(deadline));
        }
        late
    })
}

fn run(label: &str, realtime: bool) -> Summary {
    let sandbox = Sandbox::new();
    let launch = sandbox.default_session(|t| {
        let t = if realtime {
            NODE_PRIORITIES.iter().fold(t, |t, (config, priority)| {
                let args = format!("args = [\"--config\", \"{config}\"]\n");
                t.replace(
                    &args,
                    &format!("{args}sched_policy = \"fifo\"\nsched_priority = {priority}\n"),
                )
            })
        } else {
            t
        };
        // The simulators run in this program; the recorder is not part of the budget.
        let mut out = String::new();
        for block in t.split("[[process]]") {
            if block.contains("teleop-sim-") || block.contains("teleop-recorder") {
                continue;
            }
            if !out.is_empty() {
                out.push_str("[[process]]");
            }
            out.push_str(block);
        }
        out
    });
    // The simulators' threads inherit this thread's policy while it starts them.
    let sims = enter_realtime_with(&Realtime {
        policy: SchedPolicy::Fifo,
        priority: SIM_PRIORITY,
        ..Default::default()
    });
    if sims != Outcome::Realtime {
        println!("note: the simulators run at the normal policy (no right to SCHED_FIFO)");
    }
    let link = sandbox.dir.path().join("glove");
    let glove = SimGlove::start(
        SimOptions {
            link,
            id: 1,
            baud: BaudRate::B115200,
            response_delay: Duration::from_micros(200),
            faults: Faults::default(),
            seed: 1,
        },
        GloveHand::new(Script::Grasp { period_s: 6.0 }, HandModel::default()),
    )
    .unwrap();
    let revo2 = Arc::new(Mutex::new(revo2_subdevice(Some(VirtualObject::ball()), 42)));
    let frames = Arc::new(Mutex::new(Frames::default()));
    let stop = Arc::new(AtomicBool::new(false));
    let server = StreamServer::bind(&sandbox.dir.path().join("revo2.sock")).unwrap();
    let serve = {
        let (revo2, frames, stop) = (revo2.clone(), frames.clone(), stop.clone());
        std::thread::spawn(move || serve_revo2(server, revo2, frames, stop))
    };
    leave_realtime();
    let mut session = sandbox.launch(&launch);
    let node = NodeRuntime::new("bench-latency", &sandbox.ipc).unwrap();
    let states: Subscriber<GloveState> = node.subscriber().unwrap();
    let cmds: Subscriber<HandCommand> = node.subscriber().unwrap();
    let tactile: Subscriber<Tactile> = node.subscriber().unwrap();
    let forces: Subscriber<GloveForceCommand> = node.subscriber().unwrap();
    let warm = Instant::now();
    while warm.elapsed() < Duration::from_secs(30)
        && !(states.poll_latest().is_some()
            && forces.poll_latest().is_some()
            && tactile.poll_latest().is_some())
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_secs(1));
    states.drain(|_| {});
    cmds.drain(|_| {});
    tactile.drain(|_| {});
    forces.drain(|_| {});
    glove.record_answers(true);
    let _ = glove.take_answer_timings();
    {
        let mut frames = frames.lock().unwrap();
        frames.at.clear();
        frames.cycles.clear();
    }
    let (mut s_v, mut c_v, mut t_v, mut f_v) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let probe_stop = Arc::new(AtomicBool::new(false));
    let probe = wake_probe(probe_stop.clone());
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(SECONDS) {
        std::thread::sleep(Duration::from_millis(2));
        states.drain(|m| s_v.push(*m));
        cmds.drain(|m| c_v.push(*m));
        tactile.drain(|m| t_v.push(*m));
        forces.drain(|m| f_v.push(*m));
    }
    glove.record_answers(false);
    probe_stop.store(true, Ordering::SeqCst);
    let floor = probe.join().unwrap();
    session.stop();
    stop.store(true, Ordering::SeqCst);
    let _ = serve.join();
    let answers = glove.take_answer_timings();
    let requests = glove.take_force_timings();
    let (frames, cycles) = {
        let mut frames = frames.lock().unwrap();
        (
            std::mem::take(&mut frames.at),
            std::mem::take(&mut frames.cycles),
        )
    };

    // Path A. A frame is attributed to a command by its position targets, so only commands whose
    // targets (per mille, as the device has them) no other command of the run has are measured:
    // a frame carrying an earlier, identical command would otherwise be taken for this one's
    // (the retargeted grasp repeats its targets, and a held hand keeps them).
    let per_mille = |c: &HandCommand| -> Vec<i32> {
        c.active_joints()
            .iter()
            .map(|j| (j.target * 1000.0).round() as i32)
            .collect()
    };
    let mut uses: HashMap<Vec<i32>, u32> = HashMap::new();
    for c in &c_v {
        *uses.entry(per_mille(c)).or_default() += 1;
    }
    let cmd_by_origin: HashMap<u64, &HandCommand> = c_v
        .iter()
        .filter(|c| c.flags & teleop_msgs::command_flags::HELD == 0 && uses[&per_mille(c)] == 1)
        .map(|c| (c.header.origin_ns, c))
        .collect();
    let distinct = cmd_by_origin.len();
    let (mut a1, mut a2, mut a3, mut a_total) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for s in &s_v {
        let i = answers.partition_point(|a| a.sent_ns <= s.header.origin_ns);
        let Some(answer) = i.checked_sub(1).map(|i| answers[i]) else {
            continue;
        };
        let Some(cmd) = cmd_by_origin.get(&s.header.origin_ns) else {
            continue;
        };
        let want = per_mille(cmd);
        let from = frames.partition_point(|f| f.0 < cmd.header.stamp_ns);
        let carried = frames[from..].iter().find(|f| {
            f.1.iter()
                .zip(&want)
                .all(|(a, &b)| (a - b as f32).abs() < 0.6)
        });
        let Some(frame) = carried else { continue };
        a1.push(s.header.stamp_ns.saturating_sub(answer.sampled_ns));
        a2.push(cmd.header.stamp_ns.saturating_sub(s.header.stamp_ns));
        a3.push(frame.0.saturating_sub(cmd.header.stamp_ns));
        a_total.push(frame.0.saturating_sub(answer.sampled_ns));
    }
    // Path B: the glove node sends the newest force command when an exchange starts, so a
    // request carries the newest command published before its first byte (its last byte
    // arrives 16 byte times = 1.39 ms later); commands replaced before that are never sent.
    let wire = 1_389_000u64;
    let tactile_by_origin: HashMap<u64, &Tactile> =
        t_v.iter().map(|t| (t.header.origin_ns, t)).collect();
    let (mut b1, mut b2, mut b3, mut b_total) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for r in &requests {
        let i = f_v.partition_point(|f| f.header.stamp_ns + wire <= r.received_ns);
        let Some(f) = i.checked_sub(1).map(|i| &f_v[i]) else {
            continue;
        };
        if f.force != r.forces {
            continue;
        }
        let Some(t) = tactile_by_origin.get(&f.header.origin_ns) else {
            continue;
        };
        let j = frames.partition_point(|fr| fr.0 <= t.header.origin_ns);
        let Some(sample) = j.checked_sub(1).map(|j| frames[j].0) else {
            continue;
        };
        b1.push(t.header.stamp_ns.saturating_sub(sample));
        b2.push(f.header.stamp_ns.saturating_sub(t.header.stamp_ns));
        b3.push(r.received_ns.saturating_sub(f.header.stamp_ns));
        b_total.push(r.received_ns.saturating_sub(sample));
    }
    let period: Vec<u64> = cycles
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]).abs_diff(1_000_000))
        .collect();
    let summary = Summary {
        label: label.to_string(),
        exchanges: answers.len() as f64 / SECONDS as f64,
        period: quantiles(&period),
        floor: quantiles(&floor),
        a: quantiles(&a_total),
        b: quantiles(&b_total),
    };
    let exchanges = summary.exchanges;
    println!(
        "\n{label}: ms ({exchanges:.0} glove exchanges/s, {:.0} EtherCAT frames/s)",
        frames.len() as f64 / SECONDS as f64
    );
    println!(
        "E  EtherCAT period deviation |interval - 1 ms|     {}",
        percentiles(period)
    );
    println!(
        "W  wake-up lateness, SCHED_FIFO 90, 1 ms sleeps   {}",
        percentiles(floor)
    );
    println!(
        "A  glove sample -> EtherCAT cycle carrying its hand command (floor: one cycle, 1.000 ms)"
    );
    println!(
        "   measured over the {distinct} of {} hand commands whose targets no other command had",
        c_v.len()
    );
    println!(
        "   glove sample -> glove/state published       {}",
        percentiles(a1)
    );
    println!(
        "   glove/state -> hand/command published        {}",
        percentiles(a2)
    );
    println!(
        "   hand/command -> frame at the Revo2           {}",
        percentiles(a3)
    );
    println!(
        "   total                                        {}",
        percentiles(a_total)
    );
    println!(
        "B  Revo2 tactile sample -> glove force frame's last byte (floor: one exchange, 2.951 ms)"
    );
    println!(
        "   tactile sample -> hand/tactile published     {}",
        percentiles(b1)
    );
    println!(
        "   hand/tactile -> glove/force_command          {}",
        percentiles(b2)
    );
    println!(
        "   glove/force_command -> last byte at glove    {}",
        percentiles(b3)
    );
    println!(
        "   total                                        {}",
        percentiles(b_total)
    );
    summary
}

fn main() {
    println!("method: see the program's doc comment (20 s per case, release build, 2-core VM)");
    let mut summaries = vec![
        run("normal policy, idle", false),
        run("real-time policy, idle", true),
    ];
    let hogs: Vec<Child> = (0..2)
        .map(|_| Command::new("yes").stdout(Stdio::null()).spawn().unwrap())
        .collect();
    summaries.push(run("normal policy, two CPU hogs", false));
    summaries.push(run("real-time policy, two CPU hogs", true));
    for mut h in hogs {
        let _ = h.kill();
        let _ = h.wait();
    }
    let ms = |q: Option<[f64; 3]>| match q {
        Some([p50, p99, max]) => format!("{p50:>6.3} {p99:>7.3} {max:>7.3}"),
        None => format!("{:>22}", "-"),
    };
    println!("\nside by side (ms: p50 p99 max)");
    println!(
        "{:<32} {:>10}  {:<22}  {:<22}  {:<22}  {:<22}",
        "case",
        "glove ex/s",
        "EtherCAT period dev",
        "wake-up floor",
        "path A total",
        "path B total"
    );
    for s in &summaries {
        println!(
            "{:<32} {:>10.0}  {}  {}  {}  {}",
            s.label,
            s.exchanges,
            ms(s.period),
            ms(s.floor),
            ms(s.a),
            ms(s.b)
        );
    }
}
