//! The real `teleop-leap` process against the real `teleop-sim-leap` through its pseudo-terminal
//! (the node's real serial-port path): bring-up (every servo in mode 5 with torque on), the
//! cycles answered whole (at least 9 in 10 on a busy machine), a commanded pose reached, a finger stopping at
//! the ball with its current rising, the hold on a stale command, a silent servo named while
//! the others keep working, an overloaded servo stopped and named, bad bytes and CRC errors
//! survived and counted, the adapter unplugged and back without a restart (and, under a moving
//! command, a ramp from where the hand is, not a jump), torque off on every servo after SIGINT
//! (also on one the node took for silent), every torque off when a servo refuses its bring-up;
//! `teleop leap info`, `move`, `home` and `reboot` against the simulator and a missing adapter.
//!
//! Both executables must be built (`cargo build --workspace --bins` besides this crate): they
//! are looked for next to this test's target folder.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use std::time::{Duration, Instant};

use teleop_e2e::hand::{largest_error, one_at_a_time, position_command, positions, HandNode};
use teleop_e2e::rig::Rig as TestRig;
use teleop_e2e::{bin, Sandbox, Stats};
use teleop_leap::bus::{Bus, SerialLine};
use teleop_leap::protocol::xc330;
use teleop_leap::servos::status;
use teleop_leap::timing::Timing;
use teleop_msgs::{device_model, HandCommand, HandState, NodeHealth};

/// The simulator process's handles: its pty link and control socket.
struct Sim {
    link: PathBuf,
    control: PathBuf,
}

impl Sim {
    /// Starts `teleop-sim-leap` with `object` and `extra` options on `rig`.
    fn start(rig: &mut TestRig, object: &str, extra: &[&str]) -> Self {
        let (link, control) = (rig.path("leap"), rig.path("leap.ctl"));
        let (link_arg, control_arg) = (link.display().to_string(), control.display().to_string());
        let args = [
            &[
                "--link",
                &link_arg,
                "--object",
                object,
                "--control",
                &control_arg,
            ][..],
            extra,
        ]
        .concat();
        rig.start_sim("sim-leap", bin("teleop-sim-leap"), &args, "leap: link");
        Self { link, control }
    }

    /// One control command and its one-line answer.
    fn control(&self, command: &str) -> String {
        teleop_e2e::control(&self.control, command)
    }

    /// One control command that must succeed.
    fn ok(&self, command: &str) -> String {
        let reply = self.control(command);
        assert!(reply.starts_with("ok"), "{command}: {reply}");
        reply
    }

    /// The simulator's `stats` (per servo: comma-separated lists).
    fn stats(&self) -> Stats {
        teleop_e2e::sim_stats(&self.control)
    }
}

/// The node against the simulator process.
type Rig = HandNode<Sim>;

fn start(object: &str, extra: &[&str], config: &str) -> Rig {
    let mut rig = TestRig::new();
    let sim = Sim::start(&mut rig, object, extra);
    let config = format!(
        "port = \"{}\"\nhealth_period_ms = 100\nhand_profile = \"{}\"\n{config}",
        sim.link.display(),
        Sandbox::repo().join("config/hands/leap.toml").display()
    );
    HandNode::start_with(rig, "leap", env!("CARGO_BIN_EXE_teleop-leap"), &config, sim)
}

fn command(targets: &[f32; 16]) -> HandCommand {
    position_command(device_model::LEAP, targets)
}

/// The hand up with every servo's state fresh.
fn up_and_fresh(s: &HandState) -> bool {
    s.link_up == 1 && s.joints[..16].iter().all(|j| j.status & status::STALE == 0)
}

/// Stops the node (SIGINT): it exits cleanly, its log says `said`, and the simulator has every
/// servo's torque off.
fn stop_torque_off(rig: &mut Rig, said: &str) {
    let exit = rig.node().stop();
    assert!(exit.success(), "{exit:?}\n{}", rig.log());
    assert!(rig.log().contains(said), "{said:?} in\n{}", rig.log());
    let stats = rig.sim.stats();
    assert!(stats["torque"].split(',').all(|t| t == "0"), "{stats}");
}

/// How long a wait for something that should happen within a few cycles may take before it
/// fails: generous, since a wait ends as soon as its condition holds and the machine may be busy.
const PATIENCE: Duration = Duration::from_secs(10);

/// Waits (up to [`PATIENCE`]) for a health report of the node that satisfies `ok`.
fn wait_health(rig: &Rig, what: &str, ok: impl Fn(&NodeHealth) -> bool) -> NodeHealth {
    let start = Instant::now();
    let mut last = None;
    while start.elapsed() < PATIENCE {
        for h in rig.node_health() {
            if ok(&h) {
                return h;
            }
            last = Some(h);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let details = last.map(|h| {
        h.details()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
    });
    panic!(
        "no health report with {what}: last {details:?}\n{}",
        rig.log()
    );
}

/// Publishes `cmd` every 10 ms until a state satisfies `ok` (returned) or [`PATIENCE`] has
/// passed (the newest state returned: the caller's assertions then say what is wrong).
fn follow_until(
    rig: &mut Rig,
    cmd: &HandCommand,
    mut ok: impl FnMut(&HandState) -> bool,
) -> HandState {
    let start = Instant::now();
    let mut last = None;
    while start.elapsed() < PATIENCE {
        rig.commands.publish(cmd).unwrap();
        std::thread::sleep(Duration::from_millis(10));
        let mut hit = None;
        rig.states.drain(|s| {
            if hit.is_none() && ok(s) {
                hit = Some(*s);
            }
            last = Some(*s);
        });
        if let Some(s) = hit {
            return s;
        }
    }
    last.unwrap_or_else(|| panic!("no hand state\n{}", rig.log()))
}

/// Follows `targets` until the hand is within 0.05 rad of them (or [`PATIENCE`] passes).
fn reach(rig: &mut Rig, targets: &[f32; 16]) -> HandState {
    follow_until(rig, &command(targets), |s| largest_error(s, targets) < 0.05)
}

/// A pose clear of the ball: every finger's closure (its three flexing joints) under 1 rad.
const POSE: [f32; 16] = [
    0.1, 0.3, 0.3, 0.2, 0.0, 0.3, 0.3, 0.2, -0.1, 0.3, 0.3, 0.2, 0.6, 0.3, 0.2, 0.2,
];

/// Everything the issue asks of the node against the simulated hand, in one session.
#[test]
fn the_node_drives_the_simulated_hand_and_rides_out_its_faults() {
    let _one = one_at_a_time();
    let mut rig = start("ball", &[], "");
    let up = rig.wait_state(Duration::from_secs(20), "the hand up", |s| {
        s.link_up == 1
            && s.joints[..16]
                .iter()
                .all(|j| j.status & status::UNKNOWN == 0)
    });
    assert_eq!((up.joint_count, up.hand_model), (16, device_model::LEAP));
    assert_eq!(up.holding, 1, "no command yet: holding where the hand is");
    rig.wait_log(PATIENCE, "LEAP Hand connected");

    // Bring-up: every servo in current-based position control (5) with its torque on.
    let stats = rig.sim.stats();
    assert!(stats["mode"].split(',').all(|m| m == "5"), "{stats}");
    assert!(stats["torque"].split(',').all(|t| t == "1"), "{stats}");

    // Cycles answered whole: a Fast Sync Read served per cycle and every servo read in its
    // state, in at least 9 of 10 (behaviour, not a rate; on a busy machine a reply that comes
    // after its deadline leaves that one cycle's state stale, which the node counts).
    rig.states.drain(|_| {});
    let served = |stats: Stats| -> u64 { stats["fast_sync_read"].parse().unwrap() };
    let before = served(rig.sim.stats());
    let start = Instant::now();
    let (mut n, mut all_fresh, mut seqs) = (0u64, 0u64, (u64::MAX, 0u64));
    while start.elapsed() < Duration::from_secs(1) {
        rig.states.drain(|s| {
            n += 1;
            seqs = (seqs.0.min(s.header.seq), seqs.1.max(s.header.seq));
            if s.joints[..16].iter().all(|j| j.status & status::STALE == 0) {
                all_fresh += 1;
            }
        });
        std::thread::sleep(Duration::from_millis(2));
    }
    let reads = served(rig.sim.stats()) - before;
    let cycles = seqs.1 + 1 - seqs.0;
    eprintln!(
        "{cycles} cycles ({n} states received, {all_fresh} with every servo read), {reads} Fast \
         Sync Reads served"
    );
    assert!(n > 0, "no hand state");
    assert!(all_fresh * 10 >= n * 9, "{all_fresh} of {n} complete");
    assert!(
        reads * 10 >= cycles * 9,
        "{cycles} cycles, {reads} reads served"
    );

    // A commanded pose, reached.
    let s = reach(&mut rig, &POSE);
    let worst = largest_error(&s, &POSE);
    eprintln!("pose error {worst:.4} rad");
    assert!(worst < 0.05, "{:?} vs {POSE:?}", positions::<16>(&s));
    assert_eq!(s.holding, 0);
    let free_current: f32 = (5..8).map(|j| s.joints[j].current_ma.abs()).sum();

    // The middle finger closes on the ball: it stops short of its target, its current rising.
    let mut closed = POSE;
    closed[5..8].fill(1.2);
    // Followed until the simulator has the finger on the ball, then until it rests there,
    // pressing (on a deadline: the assertions below say which part failed).
    let start = Instant::now();
    while rig.sim.stats().values::<f64>("contact").unwrap()[1] <= 0.0 && start.elapsed() < PATIENCE
    {
        follow(&mut rig, &command(&closed), Duration::from_millis(50));
    }
    let s = follow_until(&mut rig, &command(&closed), |s| {
        let current: f32 = (5..8).map(|j| s.joints[j].current_ma.abs()).sum();
        s.joints[6].speed.abs() < 0.2 && current > free_current + 100.0
    });
    let p = positions::<16>(&s);
    let closure: f32 = p[5..8].iter().sum();
    let current: f32 = (5..8).map(|j| s.joints[j].current_ma.abs()).sum();
    eprintln!(
        "middle stopped at {:?} (closure {closure:.3} rad), current {current:.0} mA (free: \
         {free_current:.0} mA)",
        &p[5..8]
    );
    assert!(closure < 3.3, "the ball stops the middle finger: {p:?}");
    assert!(
        s.joints[6].speed.abs() < 0.2,
        "at rest: {}",
        s.joints[6].speed
    );
    assert!(current > free_current + 100.0, "pressing: {current} mA");
    let stats = rig.sim.stats();
    let contact: Vec<f64> = stats.values("contact").unwrap();
    assert!(
        contact[1] > 0.0,
        "the middle finger touches the ball: {stats}"
    );

    // The command goes stale: the hand holds the last target, still pressing.
    let later = rig.holds_still(0.01);
    let still: f32 = (5..8).map(|j| later.joints[j].current_ma.abs()).sum();
    assert!(
        still > current / 2.0,
        "the grip stays: {still} mA (was {current})"
    );

    // A silent servo: named, left out, the others keep working; back when it answers again.
    rig.sim.ok("silent 11");
    rig.wait_log(PATIENCE, "ring_dip (id 11) silent");
    let s = rig.wait_state(PATIENCE, "id 11 marked silent", |s| {
        s.joints[11].status & status::SILENT != 0
    });
    assert_eq!(s.link_up, 1);
    let fresh = rig.wait_state(PATIENCE, "the others read", |s| {
        (0..16)
            .filter(|j| *j != 11)
            .all(|j| s.joints[j].status & status::STALE == 0)
    });
    assert!(fresh.joints[11].status & status::STALE != 0);
    wait_health(&rig, "one silent servo", |h| {
        h.detail("silent_servos") == Some(1.0)
    });
    rig.sim.ok("clear");
    rig.wait_log(PATIENCE, "ring_dip (id 11): answers again");
    rig.wait_state(PATIENCE, "id 11 back", |s| {
        s.joints[11].status & (status::SILENT | status::STALE) == 0
    });

    // An overloaded servo: its torque off, named, the others keep working, no reboot.
    rig.sim.ok("overload 6");
    rig.wait_log(PATIENCE, "middle_pip (id 6): overload");
    rig.wait_log(
        PATIENCE,
        "power-cycle the hand, or stop this node (it holds the port) and run `teleop leap \
         reboot --id 6`",
    );
    let s = rig.wait_state(PATIENCE, "id 6 in alert", |s| {
        s.joints[6].status & status::ALERT != 0
    });
    assert_eq!(
        s.joints[6].status >> status::HARDWARE_ERROR_SHIFT,
        0x20,
        "overload bit"
    );
    assert!((0..16)
        .filter(|j| *j != 6)
        .all(|j| s.joints[j].status & (status::ALERT | status::SILENT) == 0));
    let stats = rig.sim.stats();
    let torque: Vec<&str> = stats["torque"].split(',').collect();
    assert_eq!(torque[6], "0", "{stats}");
    assert_eq!(torque.iter().filter(|t| **t == "1").count(), 15, "{stats}");
    assert_eq!(stats["reboot"], "0", "no automatic reboot: {stats}");
    wait_health(&rig, "one servo in a hardware error", |h| {
        h.detail("hw_error_servos") == Some(1.0)
    });

    // Bad bytes and CRC errors: counted, survived.
    let before = rig.latest_health();
    rig.sim.ok("noise 200");
    rig.sim.ok("crc 0.1");
    let grew =
        |h: &NodeHealth, k: &str| h.detail(k).unwrap_or(0.0) > before.detail(k).unwrap_or(0.0);
    let h = wait_health(&rig, "more CRC errors and garbage", |h| {
        grew(h, "crc_errors") && grew(h, "garbage_bytes") && h.errors > before.errors
    });
    rig.sim.ok("crc 0");
    eprintln!(
        "after noise and CRC errors: {:?}",
        h.details().collect::<Vec<_>>()
    );
    rig.wait_state(PATIENCE, "still up", |s| s.link_up == 1);

    // The adapter unplugged and back: the node reopens it without a restart.
    rig.sim.ok("unplug 500");
    rig.wait_state(PATIENCE, "the link down", |s| s.link_up == 0);
    rig.wait_state(Duration::from_secs(10), "the hand back", up_and_fresh);
    wait_health(&rig, "a reconnect", |h| h.detail("reconnects") >= Some(1.0));

    // Stop: torque off on every servo.
    stop_torque_off(&mut rig, "stopping: torque off on 16 servos");
}

/// What the servos after a silent one in a Fast Sync Read chain do is not documented: the
/// simulator's `truncate` ends the reply at the silent servo. Only the silent one is named and
/// left out; the ones after it are read again from the next cycle.
#[test]
fn a_silent_servo_that_truncates_the_chain_is_the_only_one_left_out() {
    let _one = one_at_a_time();
    let rig = start("none", &["--fast-sync-missing", "truncate"], "");
    rig.wait_state(Duration::from_secs(20), "the hand up", up_and_fresh);
    rig.sim.ok("silent 9");
    rig.wait_log(PATIENCE, "ring_mcp_forward (id 9) silent");
    rig.wait_state(PATIENCE, "id 9 marked silent", |s| {
        s.joints[9].status & status::SILENT != 0
    });
    let s = rig.wait_state(PATIENCE, "all but id 9 read", |s| {
        (0..16)
            .filter(|j| *j != 9)
            .all(|j| s.joints[j].status & (status::STALE | status::SILENT) == 0)
    });
    assert!(s.joints[9].status & status::SILENT != 0);
    std::thread::sleep(Duration::from_millis(300));
    let log = rig.log();
    for other in ["ring_pip (id 10) silent", "thumb_ip (id 15) silent"] {
        assert!(!log.contains(other), "{other}\n{log}");
    }
    wait_health(&rig, "one silent servo", |h| {
        h.detail("silent_servos") == Some(1.0)
    });
}

/// `teleop leap info`, `move`, `home` and `reboot` against the simulator (the node not running), and
/// a missing adapter named.
#[test]
fn teleop_leap_service_commands_against_the_simulator() {
    let _one = one_at_a_time();
    let mut rig = TestRig::new();
    let sim = Sim::start(&mut rig, "none", &[]);
    let port = sim.link.display().to_string();
    // The servos boot when the adapter is first opened: give them their boot time.
    let info = |rig: &TestRig| rig.sandbox.cli(&["leap", "--port", &port, "info"]);
    let start = Instant::now();
    let (ok, text) = loop {
        let (ok, text) = info(&rig);
        assert!(ok, "{text}");
        if text.contains("16 of 16 servos answer") || start.elapsed() > PATIENCE {
            break (ok, text);
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    eprintln!("{text}");
    assert!(ok, "{text}");
    for want in [
        "16 of 16 servos answer",
        "ring_dip",
        "XC330-M288-T",
        " 52 ",
        "position",
        " V",
        " C",
    ] {
        assert!(text.contains(want), "{want:?} in\n{text}");
    }

    // `move`: one joint by name, ramped there, then torque off.
    let (ok, text) = rig.sandbox.cli(&[
        "leap",
        "--port",
        &port,
        "move",
        "index_pip",
        "40",
        "--seconds",
        "2",
    ]);
    assert!(ok, "{text}");
    let stats = sim.stats();
    let index_pip: f64 = stats.values("joint").unwrap()[2];
    assert!(
        (index_pip - 40f64.to_radians()).abs() < 0.05,
        "index_pip at {index_pip} rad after `move index_pip 40`: {stats}\n{text}"
    );
    assert!(stats["torque"].split(',').all(|t| t == "0"), "{stats}");

    // `home`: every joint ramped to the profile's open pose (all 0 rad: flat), then torque off.
    let (ok, text) = rig
        .sandbox
        .cli(&["leap", "--port", &port, "home", "--seconds", "3"]);
    assert!(ok, "{text}");
    let stats = sim.stats();
    let joints: Vec<f64> = stats.values("joint").unwrap();
    assert!(
        joints.iter().all(|q| q.abs() < 0.05),
        "home: {joints:?}\n{text}"
    );
    assert!(stats["torque"].split(',').all(|t| t == "0"), "{stats}");

    // An overloaded servo is cleared by `reboot --id`.
    sim.ok("overload 3");
    let (ok, text) = info(&rig);
    assert!(ok && text.contains("overload"), "{text}");
    let (ok, text) = rig
        .sandbox
        .cli(&["leap", "--port", &port, "reboot", "--id", "3"]);
    assert!(ok && text.contains("index_dip (id 3): rebooted"), "{text}");
    // The servo reboots (its boot time): its Hardware Error Status cleared once it is back.
    let start = Instant::now();
    let mut stats = sim.stats();
    while stats["hardware_error"].split(',').nth(3) != Some("0") && start.elapsed() < PATIENCE {
        std::thread::sleep(Duration::from_millis(50));
        stats = sim.stats();
    }
    assert_eq!(
        stats["hardware_error"].split(',').nth(3),
        Some("0"),
        "{stats}"
    );
    rig.process("sim-leap").stop();

    let missing = rig.path("ttyUSB9");
    let (ok, text) = rig
        .sandbox
        .cli(&["leap", "--port", &missing.display().to_string(), "info"]);
    assert!(!ok);
    assert!(
        text.contains("cannot open") && text.contains("is the adapter plugged in"),
        "{text}"
    );
}

/// Every servo silent (the hand's power lost, the adapter still there): a run of cycles without
/// any state loses the hand (torque off tried, link down, reconnecting with back-off), and it
/// comes back without a restart when the servos answer again.
#[test]
fn a_run_of_cycles_without_any_state_loses_the_hand_until_it_answers_again() {
    let _one = one_at_a_time();
    let rig = start("none", &[], "failed_cycle_limit = 20\n");
    rig.wait_state(Duration::from_secs(20), "the hand up", up_and_fresh);
    for id in 0..16 {
        rig.sim.ok(&format!("silent {id}"));
    }
    rig.wait_log(PATIENCE, "20 cycles in a row without any servo's state");
    rig.wait_state(PATIENCE, "the link down", |s| s.link_up == 0);
    rig.wait_log(PATIENCE, "no servo answers on");
    rig.sim.ok("clear");
    rig.wait_state(Duration::from_secs(10), "the hand back", up_and_fresh);
    wait_health(&rig, "a reconnect", |h| h.detail("reconnects") >= Some(1.0));
}

/// A servo back from silence while commands are followed holds where it is and ramps to its
/// target at `resume_speed`; it does not jump there.
#[test]
fn a_servo_back_from_silence_ramps_to_the_command() {
    let _one = one_at_a_time();
    let mut rig = start("none", &[], "resume_speed = 0.5\n");
    rig.wait_state(Duration::from_secs(20), "the hand up", up_and_fresh);
    reach(&mut rig, &POSE);
    rig.sim.ok("silent 11");
    rig.wait_log(PATIENCE, "ring_dip (id 11) silent");
    // The command moves the silent joint: it does not hear it.
    let mut far = POSE;
    far[11] = 1.2;
    rig.send(&command(&far), Duration::from_millis(300));
    rig.sim.ok("clear");
    // Watched from when it is read again for 1.5 s (the ramp's first 0.75 rad at most).
    let start = Instant::now();
    let mut seen = Vec::new();
    while start.elapsed() < PATIENCE + Duration::from_secs(2) {
        for s in follow(&mut rig, &command(&far), Duration::from_millis(20)) {
            if s.joints[11].status & status::STALE == 0 {
                seen.push((start.elapsed().as_secs_f32(), s.joints[11].position));
            }
        }
        if seen
            .first()
            .is_some_and(|(t0, _)| start.elapsed().as_secs_f32() > t0 + 1.5)
        {
            break;
        }
    }
    assert!(!seen.is_empty(), "ring_dip read again\n{}", rig.log());
    rig.wait_log(PATIENCE, "ring_dip (id 11): answers again");
    eprintln!("ring_dip after it came back: {seen:?}");
    ramps_at_half_a_radian_per_second(&seen);
}

/// `seen` (seconds, rad) rises from its first position at most at 0.5 rad/s (`resume_speed`),
/// with a cycle's slack, and gets on toward the target: a ramp, no jump.
fn ramps_at_half_a_radian_per_second(seen: &[(f32, f32)]) {
    let (t0, q0) = seen[0];
    for (t, q) in seen {
        assert!(
            *q <= q0 + 0.5 * (t - t0) + 0.05,
            "jumped: {q} rad {:.2} s after {q0} rad: {seen:?}",
            t - t0
        );
    }
    let (_, last) = seen[seen.len() - 1];
    assert!(last > q0 + 0.3, "it ramps toward its target: {seen:?}");
}

/// Follows `cmd` for `d`, publishing every 10 ms; the states received meanwhile.
fn follow(rig: &mut Rig, cmd: &HandCommand, d: Duration) -> Vec<HandState> {
    let start = Instant::now();
    let mut out = Vec::new();
    while start.elapsed() < d {
        rig.commands.publish(cmd).unwrap();
        std::thread::sleep(Duration::from_millis(10));
        rig.states.drain(|s| out.push(*s));
    }
    out
}

/// The adapter unplugged while the commands go on and move the hand away: after the reconnect
/// the hand ramps at `resume_speed` from where it is (the state read at bring-up), it does not
/// jump to the command.
#[test]
fn after_an_unplug_under_a_moving_command_the_hand_ramps_from_where_it_is() {
    let _one = one_at_a_time();
    let mut rig = start("none", &[], "resume_speed = 0.5\n");
    rig.wait_state(Duration::from_secs(20), "the hand up", up_and_fresh);
    reach(&mut rig, &POSE);
    // The adapter goes; once the node has seen it go (the commands fresh all along), the
    // command moves index_pip 1.2 rad away.
    rig.sim.ok("unplug 500");
    let start = Instant::now();
    while !follow(&mut rig, &command(&POSE), Duration::from_millis(20))
        .iter()
        .any(|s| s.link_up == 0)
    {
        assert!(start.elapsed() < PATIENCE, "the link down\n{}", rig.log());
    }
    let mut far = POSE;
    far[2] = 1.5;
    let start = Instant::now();
    let mut seen = Vec::new();
    while start.elapsed() < PATIENCE + Duration::from_secs(2) {
        for s in follow(&mut rig, &command(&far), Duration::from_millis(20)) {
            // Back: the first state is the one read at bring-up.
            if s.link_up == 1 && s.joints[2].status & status::UNKNOWN == 0 {
                seen.push((start.elapsed().as_secs_f32(), s.joints[2].position));
            }
        }
        if seen
            .first()
            .is_some_and(|(t0, _)| start.elapsed().as_secs_f32() > t0 + 1.5)
        {
            break;
        }
    }
    assert!(!seen.is_empty(), "the hand came back\n{}", rig.log());
    eprintln!("index_pip after the reconnect: {seen:?}");
    assert!(
        seen[0].1 < 1.2,
        "not at the command before the ramp: {seen:?}"
    );
    ramps_at_half_a_radian_per_second(&seen);
}

/// The stop reaches a servo the node took for silent (it hears again, but the node has not
/// looked for it yet): the broadcast torque off, before each answering servo is confirmed.
#[test]
fn the_stop_turns_off_a_servo_the_node_took_for_silent() {
    let _one = one_at_a_time();
    let mut rig = start("none", &[], "silent_retry_ms = 60000\n");
    rig.wait_state(Duration::from_secs(20), "the hand up", up_and_fresh);
    rig.sim.ok("silent 11 300");
    rig.wait_log(PATIENCE, "ring_dip (id 11) silent");
    // It hears again; the node looks for it only in a minute.
    rig.wait_state(PATIENCE, "id 11 still marked silent", |s| {
        s.joints[11].status & status::SILENT != 0
    });
    let start = Instant::now();
    while rig.sim.stats()["silent"] != "none" && start.elapsed() < PATIENCE {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(rig.sim.stats()["silent"], "none");
    stop_torque_off(
        &mut rig,
        "torque off on 15 servos, 1 silent (the broadcast only)",
    );
}

/// A servo refusing a step of the bring-up (its Current Limit, lowered by another tool, below
/// the node's Goal Current): the node does not run, and no servo is left with its torque on.
#[test]
fn a_servo_refusing_its_bring_up_leaves_every_servo_torque_off() {
    let _one = one_at_a_time();
    let mut rig = TestRig::new();
    let sim = Sim::start(&mut rig, "none", &[]);
    {
        let line = SerialLine::open(&sim.link.display().to_string(), 4_000_000).unwrap();
        let mut bus = Bus::new(line, Timing::new(4_000_000, 250, Duration::from_millis(20)));
        // The servos boot when the adapter is first opened.
        let start = Instant::now();
        while bus.ping(5).is_err() {
            assert!(start.elapsed() < Duration::from_secs(5), "servo 5 boots");
        }
        let r = bus
            .write(5, xc330::CURRENT_LIMIT, &200u16.to_le_bytes())
            .unwrap();
        assert!(r.error.is_ok(), "{}", r.error);
    }
    let config = format!(
        "port = \"{}\"\nhealth_period_ms = 100\nreconnect_backoff_ms = [100, 200]\n\
         hand_profile = \"{}\"\n",
        sim.link.display(),
        Sandbox::repo().join("config/hands/leap.toml").display()
    );
    let rig = HandNode::start_with(rig, "leap", env!("CARGO_BIN_EXE_teleop-leap"), &config, sim);
    rig.wait_log(
        Duration::from_secs(10),
        "middle_mcp_forward (id 5): Goal Current refused",
    );
    // Looked at again, refused again: never a servo with its torque on.
    for _ in 0..10 {
        let stats = rig.sim.stats();
        assert!(
            stats["torque"].split(',').all(|t| t == "0"),
            "{stats}\n{}",
            rig.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    rig.wait_state(PATIENCE, "the link down", |s| s.link_up == 0);
}
