//! The real `teleop-allegro` process against the real `teleop-sim-allegro` through the simulated
//! slcan adapter on a pseudo-terminal (the node's real `SlcanLink` path), for each protocol
//! generation: bring-up, the 333 Hz state, PD to a commanded pose, a finger closing on the ball
//! stopping at it with its effort rising, the hold on a stale command, a stopped stream (torque
//! stopped, brought up again), an unplugged adapter, unknown and bad frames counted, the other
//! generation named; `teleop allegro info` against the simulator and its error for a missing
//! adapter.
//!
//! Both executables must be built (`cargo build --workspace --bins` besides this crate): they
//! are looked for next to this test's target folder.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use teleop_e2e::hand::{largest_error, one_at_a_time, position_command, positions, HandNode};
use teleop_e2e::rig::Rig as TestRig;
use teleop_e2e::{bin, Sandbox, Stats};
use teleop_msgs::{device_model, HandCommand, HandState};

/// The simulations run one at a time: two 333 Hz hands over pseudo-terminals at once on a small
/// machine would test the machine.
static SERIAL: Mutex<()> = Mutex::new(());

/// The simulator process's handles: its slcan adapter and control socket, and this test's turn.
struct Sim {
    slcan: PathBuf,
    control: PathBuf,
    _serial: MutexGuard<'static, ()>,
}

impl Sim {
    /// Starts `teleop-sim-allegro` as `generation` with `object` on `rig`, with `extra` options
    /// (the hand behaviours no document gives), once no other simulation runs.
    fn start(rig: &mut TestRig, generation: &str, object: &str, extra: &[&str]) -> Self {
        let serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
        let (slcan, control) = (rig.path("allegro-slcan"), rig.path("allegro.ctl"));
        let (slcan_arg, control_arg) = (slcan.display().to_string(), control.display().to_string());
        let args = [
            &["--generation", generation, "--object", object][..],
            extra,
            &["--slcan", &slcan_arg, "--control", &control_arg],
        ]
        .concat();
        rig.start_sim(
            "sim-allegro",
            bin("teleop-sim-allegro"),
            &args,
            "allegro: generation",
        );
        Self {
            slcan,
            control,
            _serial: serial,
        }
    }

    /// One control command and its one-line answer.
    fn control(&self, command: &str) -> String {
        teleop_e2e::control(&self.control, command)
    }

    /// The simulator's `stats` (per joint: comma-separated lists).
    fn stats(&self) -> Stats {
        teleop_e2e::sim_stats(&self.control)
    }
}

/// The node against the simulator process; the simulation's turn ends after both stopped.
type Rig = HandNode<Sim>;

/// How the Allegro's tests start, command and look at the node.
trait AllegroRig {
    /// The simulator as `generation` with `object`, the node set to `protocol`.
    fn new(generation: &str, protocol: &str, object: &str) -> Self;
    /// As [`AllegroRig::new`], the simulator started with `extra` options.
    fn with_sim_options(generation: &str, protocol: &str, object: &str, extra: &[&str]) -> Self;
    /// Publishes `targets` every 10 ms for `d`; returns the last state.
    fn command(&mut self, targets: &[f32; 16], d: Duration) -> HandState;
    /// States received within `d` (draining every 2 ms).
    fn count_states(&self, d: Duration) -> u64;
    /// Stops the node with SIGINT; its exit status.
    fn stop_node(&mut self) -> std::process::ExitStatus;
}

impl AllegroRig for Rig {
    fn new(generation: &str, protocol: &str, object: &str) -> Self {
        Self::with_sim_options(generation, protocol, object, &[])
    }

    fn with_sim_options(generation: &str, protocol: &str, object: &str, extra: &[&str]) -> Self {
        let mut rig = TestRig::new();
        let sim = Sim::start(&mut rig, generation, object, extra);
        let config = format!(
            "link = \"slcan:{}\"\nprotocol = \"{protocol}\"\nhealth_period_ms = 100\n\
             hand_profile = \"{}\"\n",
            sim.slcan.display(),
            Sandbox::repo().join("config/hands/allegro.toml").display()
        );
        let program = env!("CARGO_BIN_EXE_teleop-allegro");
        HandNode::start_with(rig, "allegro", program, &config, sim)
    }

    fn command(&mut self, targets: &[f32; 16], d: Duration) -> HandState {
        self.send(&command(targets), d)
    }

    fn count_states(&self, d: Duration) -> u64 {
        self.states.drain(|_| {});
        let start = Instant::now();
        let mut n = 0u64;
        while start.elapsed() < d {
            n += self.states.drain(|_| {}) as u64;
            std::thread::sleep(Duration::from_millis(2));
        }
        n
    }

    fn stop_node(&mut self) -> std::process::ExitStatus {
        self.node().stop()
    }
}

fn command(targets: &[f32; 16]) -> HandCommand {
    position_command(device_model::ALLEGRO, targets)
}

/// The simulator's PWM per joint.
fn sim_pwm(status: &Stats) -> Vec<i32> {
    status.values("pwm").unwrap()
}

/// A pose clear of the ball: fingers slightly flexed and spread, thumb turned in.
const POSE: [f32; 16] = [
    0.1, 0.3, 0.3, 0.2, 0.0, 0.2, 0.2, 0.2, -0.1, 0.3, 0.3, 0.2, 0.6, 0.2, 0.2, 0.2,
];

/// Everything the issue asks of one generation, in one simulator session.
fn generation(generation: &str) {
    let _one = one_at_a_time();
    let mut rig = Rig::new(generation, generation, "ball");
    let up = rig.wait_state(Duration::from_secs(20), "the hand up", |s| s.link_up == 1);
    assert_eq!(up.joint_count, 16);
    assert_eq!(up.holding, 1, "no command yet: holding where the hand is");

    // The hand's own 333 Hz stream clocks the state.
    let n = rig.count_states(Duration::from_secs(1));
    eprintln!("{generation}: {n} hand states in 1 s");
    assert!((250..=420).contains(&n), "{generation}: {n} states in 1 s");

    // PD to a commanded pose.
    let s = rig.command(&POSE, Duration::from_millis(2500));
    let worst = largest_error(&s, &POSE);
    eprintln!("{generation}: PD settle error {worst:.4} rad");
    assert!(
        worst < 0.05,
        "{generation}: {:?} vs {POSE:?}",
        positions::<16>(&s)
    );
    assert_eq!(s.holding, 0);

    // The middle finger closes on the ball: it stops short of its target, pressing harder.
    let mut closed = POSE;
    closed[5..8].fill(1.5);
    let early = rig.command(&closed, Duration::from_millis(150));
    let s = rig.command(&closed, Duration::from_millis(2000));
    let p = positions::<16>(&s);
    let effort: f32 = (5..8).map(|j| s.joints[j].effort).sum();
    let early_effort: f32 = (5..8).map(|j| early.joints[j].effort).sum();
    eprintln!(
        "{generation}: middle stopped at {:?}, effort {effort:.3} N m (free: {early_effort:.3})",
        &p[5..8]
    );
    assert!(
        p[6] < 1.3 || p[5] < 1.3,
        "{generation}: the ball stops the middle finger: {p:?}"
    );
    assert!(
        s.joints[5].speed.abs() < 0.1,
        "{generation}: at rest: {}",
        s.joints[5].speed
    );
    assert!(effort > 0.3, "{generation}: pressing: {effort} N m");
    let status = rig.sim.stats();
    let contact: Vec<f64> = status.values("contact").unwrap();
    assert!(
        contact[1] > 0.0,
        "{generation}: the middle finger touches the ball: {status}"
    );

    // The command goes stale: the hand holds the last target, still pressing.
    let later = rig.holds_still(0.01);
    let still: f32 = (5..8).map(|j| later.joints[j].effort).sum();
    assert!(
        still > effort / 2.0,
        "{generation}: the grip stays: {still} (was {effort})"
    );

    // A stopped stream: torque off, SYSTEM_OFF, down; back when the stream resumes.
    let errors_before = later.link_errors;
    assert!(rig.sim.control("stop-stream").starts_with("ok"));
    rig.wait_state(Duration::from_secs(3), "the link down", |s| s.link_up == 0);
    rig.wait_log(Duration::from_secs(2), "torque stopped, SYSTEM_OFF sent");
    // The zero-torque frames cross the simulated adapter after the node logs them: on a busy
    // machine the simulator's stats can be read before it has taken them.
    let deadline = Instant::now() + Duration::from_secs(2);
    let mut status = rig.sim.stats();
    while !sim_pwm(&status).iter().all(|p| *p == 0) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
        status = rig.sim.stats();
    }
    assert!(
        sim_pwm(&status).iter().all(|p| *p == 0),
        "{generation}: torque stopped: {status}"
    );
    assert!(rig.sim.control("resume-stream").starts_with("ok"));
    let back = rig.wait_state(Duration::from_secs(10), "the hand back", |s| s.link_up == 1);
    assert!(
        back.link_errors > errors_before,
        "{generation}: missing cycles counted"
    );

    // Unknown ids and bad frames (a position id with one byte), and an unparsable adapter
    // line: counted, survived.
    let bad_id = if generation == "v4" { "080" } else { "3D3" };
    for _ in 0..10 {
        assert!(rig.sim.control("inject 7F0#010203").starts_with("ok"));
        assert!(rig
            .sim
            .control(&format!("inject {bad_id}#01"))
            .starts_with("ok"));
    }
    assert!(rig.sim.control("garbage").starts_with("ok"));
    std::thread::sleep(Duration::from_millis(400));
    let h = rig.latest_health();
    let (unknown, bad) = (h.detail("unknown_frames"), h.detail("bad_frames"));
    eprintln!(
        "{generation}: health errors {}, unknown {unknown:?}, bad {bad:?}",
        h.errors
    );
    assert!(
        unknown >= Some(10.0) && bad >= Some(10.0),
        "{generation}: {:?}",
        h.details().collect::<Vec<_>>()
    );
    rig.wait_state(Duration::from_secs(2), "still up", |s| s.link_up == 1);

    // The adapter unplugged and back: the node reopens it.
    rig.sim.control("unplug 500");
    rig.wait_state(Duration::from_secs(3), "the link down", |s| s.link_up == 0);
    rig.wait_state(Duration::from_secs(10), "the hand back", |s| s.link_up == 1);

    // Stop: zero torque, SYSTEM_OFF, clean exit.
    let status = rig.stop_node();
    assert!(status.success(), "{status:?}\n{}", rig.log());
    assert!(
        rig.log().contains("sent zero torque and SYSTEM_OFF"),
        "{}",
        rig.log()
    );
    let status = rig.sim.stats();
    assert_eq!(status["system"], "off", "{status}");
    assert!(sim_pwm(&status).iter().all(|p| *p == 0), "{status}");
}

#[test]
fn v1_against_the_simulator() {
    generation("v1");
}

#[test]
fn v2_against_the_simulator() {
    generation("v2");
}

#[test]
fn v3_against_the_simulator() {
    generation("v3");
}

#[test]
fn v4_against_the_simulator() {
    generation("v4");
}

/// What real v4 hands do is not published on two points (docs/devices/allegro.md, "Open"): whether
/// they zero torque when torque frames stop, and whether SET_PERIOD alone starts the stream. The
/// node works with a hand that does both: it sends torque every period (holding included), and its
/// bring-up sends SYSTEM_ON either way.
#[test]
fn v4_with_a_torque_watchdog_and_streaming_on_set_period() {
    let _one = one_at_a_time();
    let mut rig = Rig::with_sim_options(
        "v4",
        "v4",
        "ball",
        &["--torque-timeout-ms", "20", "--v4-stream-on-period"],
    );
    rig.wait_state(Duration::from_secs(20), "the hand up", |s| s.link_up == 1);
    let s = rig.command(&POSE, Duration::from_millis(2500));
    let worst = largest_error(&s, &POSE);
    assert!(worst < 0.05, "PD settle error {worst} rad");
    // Stale: the hold keeps sending torque, so the watchdog never trips during it and the pose
    // stays. (Counted from here: a scheduling stall of this loaded test machine longer than the
    // 20 ms watchdog while the hand is followed is not what this checks; it is printed.)
    let before = rig.sim.stats();
    eprintln!(
        "torque timeouts before the hold: {}",
        before["torque_timeouts"]
    );
    rig.wait_state(Duration::from_secs(2), "holding", |s| s.holding == 1);
    std::thread::sleep(Duration::from_millis(500));
    let status = rig.sim.stats();
    assert_eq!(
        status["torque_timeouts"], before["torque_timeouts"],
        "the watchdog tripped while the hand held: {status}"
    );
    let held = rig.states.poll_latest().unwrap();
    let worst = largest_error(&held, &POSE);
    assert!(worst < 0.05, "held pose error {worst} rad");
    // The node stopped: the watchdog zeroes nothing it had not already zeroed.
    let status = rig.stop_node();
    assert!(status.success(), "{status:?}\n{}", rig.log());
    let status = rig.sim.stats();
    assert!(sim_pwm(&status).iter().all(|p| *p == 0), "{status}");
}

#[test]
fn the_other_generation_is_named_and_the_node_waits_for_the_right_one() {
    let _one = one_at_a_time();
    let rig = Rig::new("v4", "v3", "none");
    rig.wait_log(Duration::from_secs(10), "saw v4 IDs; set protocol = v4");
    let mut rig = rig;
    assert!(rig.node().is_running(), "the node keeps trying");
    // The hand becomes the generation set: the node comes up without a restart.
    rig.sim.control("generation v3");
    rig.wait_state(Duration::from_secs(10), "the hand up", |s| s.link_up == 1);
    drop(rig);

    let rig = Rig::new("v2", "v4", "none");
    rig.wait_log(
        Duration::from_secs(10),
        "saw v1-v3 (document protocol) IDs; set protocol = v1, v2 or v3",
    );
}

#[test]
fn teleop_allegro_info_against_the_simulator_and_a_missing_adapter() {
    let mut rig = TestRig::new();
    let sim = Sim::start(&mut rig, "v4", "ball", &[]);
    let link = format!("slcan:{}", sim.slcan.display());
    let teleop = |args: &[&str]| rig.sandbox.run_teleop(args);
    let out = teleop(&["allegro", "--link", &link, "info"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{text}");
    for want in [
        "protocol      v4 (detected)",
        "serial        SAH040",
        "firmware",
        "thumb",
    ] {
        assert!(text.contains(want), "{want:?} in\n{text}");
    }
    assert!(text.contains(" C\n"), "temperatures in\n{text}");

    // `move`: one joint to an angle with the PD loop, then the hand is released.
    let out = teleop(&[
        "allegro",
        "--link",
        &link,
        "move",
        "index_1",
        "30",
        "--seconds",
        "1",
    ]);
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let status = sim.stats();
    let index_1: f64 = status.values("position").unwrap()[1];
    assert!(
        (index_1 - 30f64.to_radians()).abs() < 0.05,
        "index_1 at {index_1} rad after `move index_1 30`: {status}"
    );
    // SYSTEM_OFF is the last frame `move` sends before closing the adapter; the simulated bus
    // delivers it to the hand's firmware a frame time later, which may be after this process
    // asked for the status.
    let mut status = status;
    let deadline = Instant::now() + Duration::from_secs(2);
    while status["system"] != "off" && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
        status = sim.stats();
    }
    assert_eq!(status["system"], "off", "released: {status}");
    rig.process("sim-allegro").stop();

    let missing = rig.path("ttyACM9");
    let teleop = |args: &[&str]| rig.sandbox.run_teleop(args);
    let out = teleop(&[
        "allegro",
        "--link",
        &format!("slcan:{}", missing.display()),
        "info",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains(&format!(
            "slcan:{}: no such device; is the adapter plugged in?",
            missing.display()
        )),
        "{err}"
    );
}

/// A document-protocol hand answers QUERY_STATE_DATA with 0x0E frames from each finger (the
/// device document's table); their payload is not documented, so the simulator lays it out as a
/// position frame or sends none. Either way the node comes up on the 0x0F stream (the answers
/// to its bring-up's QUERY_STATE are not a period), and answers arriving mid-stream are neither
/// finger frames nor unknown ones.
#[test]
fn v3_tells_state_answers_from_the_stream_with_either_payload() {
    let _one = one_at_a_time();
    for (payload, inject) in [("positions", "0000000000000000"), ("empty", "")] {
        let rig = Rig::with_sim_options("v3", "v3", "none", &["--state-answer", payload]);
        rig.wait_state(Duration::from_secs(20), "the hand up", |s| s.link_up == 1);
        let before = rig.latest_health();
        for _ in 0..10 {
            for id in ["393", "394", "395", "396"] {
                let reply = rig.sim.control(&format!("inject {id}#{inject}"));
                assert!(reply.starts_with("ok"), "{reply}");
            }
        }
        std::thread::sleep(Duration::from_millis(400));
        let h = rig.latest_health();
        let frames =
            |h: &teleop_msgs::NodeHealth| (h.detail("unknown_frames"), h.detail("bad_frames"));
        assert_eq!(
            frames(&h),
            frames(&before),
            "{payload}: state answers counted as unknown or bad frames\n{}",
            rig.log()
        );
        let s = rig.wait_state(Duration::from_secs(2), "still up", |s| s.link_up == 1);
        // Positions from the stream only: every joint near where the hand rests, none at the
        // injected counts' -166 deg.
        assert!(
            positions::<16>(&s).iter().all(|q| q.abs() < 2.0),
            "{payload}: {:?}",
            positions::<16>(&s)
        );
    }
}

/// A loaded host (CPU hogs beside the node and the simulator: a load average near 10 on two
/// cores) delays the hand's frames by tens of milliseconds on their way (the simulator's
/// threads are not scheduled, the pty holds them) while the hand streams without a gap. The
/// adapter's `Z1` stamps show the frames were sent on time: the node counts no missed-period
/// run and never brings the hand up again. (Before stamps were used: 1-7 restarts in 12 s.)
#[test]
fn v4_rides_out_a_loaded_host() {
    let _one = one_at_a_time();
    use std::sync::atomic::{AtomicBool, Ordering};
    let rig = Rig::new("v4", "v4", "none");
    rig.wait_state(Duration::from_secs(20), "the hand up", |s| s.link_up == 1);
    let before = rig.latest_health();
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    let hogs: Vec<_> = (0..10)
        .map(|_| {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut x = 0u64;
                while !stop.load(Ordering::Relaxed) {
                    x = std::hint::black_box(x.wrapping_mul(6_364_136_223_846_793_005) + 1);
                }
            })
        })
        .collect();
    let start = Instant::now();
    let mut down = 0u64;
    while start.elapsed() < Duration::from_secs(8) {
        rig.states.drain(|s| {
            if s.link_up == 0 {
                down += 1;
            }
        });
        std::thread::sleep(Duration::from_millis(20));
    }
    stop.store(true, Ordering::Relaxed);
    for h in hogs {
        h.join().unwrap();
    }
    let log = rig.log();
    assert!(
        !log.contains("bringing the hand up again"),
        "the hand was restarted under load\n{log}"
    );
    assert_eq!(down, 0, "hand states with the link down under load");
    std::thread::sleep(Duration::from_millis(300));
    let after = rig.latest_health();
    let late = after.detail("late_periods");
    eprintln!(
        "under load: health errors {} -> {}, late periods {late:?}",
        before.errors, after.errors
    );
    // The load did delay frames (the waits the stamps cleared are counted as late periods).
    assert!(
        late > Some(0.0),
        "no late period seen: {:?}",
        after.details().collect::<Vec<_>>()
    );
    rig.wait_state(Duration::from_secs(2), "still up", |s| s.link_up == 1);
}
