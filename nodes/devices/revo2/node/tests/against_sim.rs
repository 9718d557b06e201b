//! The Revo2 node, started as a process, drives the emulated Revo2 through ethercrab's real
//! MainDevice state machine over the local-socket transport. The emulator runs in this test
//! process so the test can inject faults and look at the device.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_e2e::ecat::Served;
use teleop_e2e::hand::HandNode;
use teleop_e2e::rig::Rig as TestRig;
use teleop_ecat_sim::{AlState, SubDevice};
use teleop_sim_revo2::hand::VirtualObject;
use teleop_sim_revo2::{revo2_subdevice_with_loop, Revo2};
mod common;

use common::{position_command, positions};
use teleop_msgs::{control_mode, EStop, HandState};
use teleop_runtime::{NodeRuntime, Publisher};

type Sim = Served<SubDevice<Revo2>>;

fn lock(sim: &Sim) -> std::sync::MutexGuard<'_, SubDevice<Revo2>> {
    sim.lock()
}

/// The Revo2 node against the emulated Revo2 (a ball under its fingers) served from this
/// process.
type Rig = HandNode<Sim>;

/// How the Revo2's tests start and command the node.
trait Revo2Rig {
    /// The node with `extra_config` after its transport and link timeout, up in OP.
    fn new(extra_config: &str) -> Self;
    /// Publishes position targets every 10 ms for `d`, returning the last hand state.
    fn command(&mut self, targets: [f32; 6], d: Duration) -> HandState;
}

impl Revo2Rig for Rig {
    fn new(extra_config: &str) -> Self {
        let rig = TestRig::new();
        let socket = rig.path("revo2.sock");
        // A firmware that reads AL control once per 1 ms loop, as the simulator process runs.
        let sim = Served::start(
            &socket,
            revo2_subdevice_with_loop(Some(VirtualObject::ball()), 7, Duration::from_millis(1)),
        );
        let config = format!(
            "transport = \"sim:{}\"\nlink_timeout_ms = 100\n{extra_config}",
            socket.display()
        );
        let program = env!("CARGO_BIN_EXE_teleop-revo2");
        let rig = HandNode::start_with(rig, "revo2", program, &config, sim);
        rig.wait_state(Duration::from_secs(30), "the hand in OP", |s| {
            s.link_up == 1
        });
        rig
    }

    fn command(&mut self, targets: [f32; 6], d: Duration) -> HandState {
        self.send(&position_command(targets), d)
    }
}

#[test]
fn commanded_targets_move_the_hand_and_closing_on_the_object_gives_tactile_force() {
    let mut rig = Rig::new("");
    assert_eq!(lock(&rig.sim).al_state(), (AlState::Op, false, 0));
    let log = rig.log();
    assert!(
        log.contains("Revo2 found") && log.contains("control_fw=1.4.2"),
        "{log}"
    );

    let s = rig.command([0.2, 0.3, 0.0, 0.0, 0.0, 0.0], Duration::from_millis(800));
    let p = positions(&s);
    assert!(
        (p[0] - 0.2).abs() < 0.02 && (p[1] - 0.3).abs() < 0.02,
        "{p:?}"
    );
    assert_eq!(s.holding, 0);

    // Close on the ball: the fingers stop at it and the fingertips feel it.
    let s = rig.command([1.0; 6], Duration::from_millis(1500));
    let p = positions(&s);
    assert!(
        p[2] > 0.33 && p[2] < 0.6,
        "index stopped at the object: {p:?}"
    );
    assert!(p[1] > 0.95, "thumb abduction is free: {p:?}");
    assert!(s.joints[2].current_ma > s.joints[1].current_ma + 100.0);
    let t = rig.tactile.poll_latest().unwrap();
    assert!(
        t.fingertips[1].normal_n > 1.0,
        "index fingertip force: {:?}",
        t.fingertips[1]
    );
    assert!(t.fingertips[1].proximity > 0);

    // The command goes stale: the hand holds the last target, flagged, and does not drift; the
    // fingers in contact keep squeezing the ball.
    rig.holds_still(0.005);
    let grip = rig.tactile.poll_latest().unwrap().fingertips[1].normal_n;
    assert!(
        grip > t.fingertips[1].normal_n / 2.0,
        "the grip stays: {grip} N (was {} N)",
        t.fingertips[1].normal_n
    );
    assert!(rig
        .log()
        .contains("no fresh hand command: the hand holds its last target"));
}

#[test]
fn watchdog_drop_is_acknowledged_and_frame_loss_ridden_out() {
    let mut rig = Rig::new("");
    rig.command([0.3; 6], Duration::from_millis(300));
    lock(&rig.sim).trip_watchdog();
    rig.wait_state(Duration::from_secs(3), "recovery", |_| {
        rig.log().contains("dropped to SAFE-OP")
    });
    rig.command([0.5; 6], Duration::from_millis(500));
    assert_eq!(lock(&rig.sim).al_state().0, AlState::Op, "{}", rig.log());
    // One acknowledge, seen by the firmware before the OP request, recovers it: an OP request
    // written right after the acknowledge overwrites it unread, and the error stays.
    assert_eq!(
        rig.log().matches("dropped to SAFE-OP").count(),
        1,
        "{}",
        rig.log()
    );

    lock(&rig.sim).faults().wrong_wkc_probability = 0.2;
    let s = rig.command([0.45; 6], Duration::from_millis(500));
    lock(&rig.sim).faults().wrong_wkc_probability = 0.0;
    assert!(s.link_errors > 0, "wrong working counters counted: {s:?}");
    assert_eq!(s.link_up, 1);
    assert!(rig.log().contains("wrong working counter"), "{}", rig.log());

    lock(&rig.sim).faults().drop_probability = 0.2;
    let s = rig.command([0.4; 6], Duration::from_millis(800));
    lock(&rig.sim).faults().drop_probability = 0.0;
    assert!(s.lost_frames > 0, "lost frames counted: {s:?}");
    assert_eq!(s.link_up, 1);
    let pid_alive = rig.node().is_running();
    assert!(pid_alive);
}

#[test]
fn link_loss_is_survived_without_a_restart() {
    let mut rig = Rig::new("");
    rig.command([0.3; 6], Duration::from_millis(300));
    lock(&rig.sim).faults().link_down = true;
    rig.wait_state(Duration::from_secs(5), "link down", |s| s.link_up == 0);
    lock(&rig.sim).faults().link_down = false;
    rig.wait_state(Duration::from_secs(15), "link up again", |s| s.link_up == 1);
    let s = rig.command([0.6; 6], Duration::from_millis(800));
    assert!((positions(&s)[1] - 0.6).abs() < 0.05, "{:?}", positions(&s));
    assert!(rig.node().is_running(), "same process");
}

#[test]
fn tactile_polled_by_sdo_when_not_in_the_process_data() {
    let mut rig = Rig::new("tactile = \"sdo\"\ntactile_poll_hz = 50.0\n");
    assert_eq!(
        lock(&rig.sim).app().tx_assignment(),
        &[0x1A00],
        "only joint data in the process data"
    );
    rig.command([1.0; 6], Duration::from_millis(1500));
    let start = Instant::now();
    let t = loop {
        if let Some(t) = rig
            .tactile
            .poll_latest()
            .filter(|t| t.fingertips[1].normal_n > 1.0)
        {
            break t;
        }
        assert!(
            start.elapsed() < Duration::from_secs(3),
            "no polled tactile force\n{}",
            rig.log()
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    assert_eq!(t.fingertip_count, 5);
    assert!(
        lock(&rig.sim).stats().mailbox_requests > 50,
        "polled over the mailbox"
    );
}

/// Issue 20, item 4: a NaN or infinite target is no valid command. The hand holds where it was
/// (it used to open fully: NaN read as 0), the state says it holds, and the refusal is counted.
#[test]
fn non_finite_targets_hold_and_are_counted() {
    let mut rig = Rig::new("");
    let s = rig.command([0.9; 6], Duration::from_millis(1200));
    let before = positions(&s);
    assert!(
        (before[1] - 0.9).abs() < 0.03,
        "thumb abduction closed: {before:?}"
    );
    let errors_before = rig.node_health().last().map_or(0, |h| h.errors);
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut cmd = position_command([0.9; 6]);
        cmd.joints[1].target = bad; // one bad joint spoils the command
        cmd.joints[0].target = bad;
        let s = rig.send(&cmd, Duration::from_millis(400));
        let p = positions(&s);
        for (j, (a, b)) in before.iter().zip(&p).enumerate() {
            assert!(
                (a - b).abs() < 0.03,
                "{bad}: joint {j} moved: {before:?} -> {p:?}"
            );
        }
        assert_eq!(s.holding, 1, "{bad}: the state says the hand holds");
    }
    std::thread::sleep(Duration::from_millis(600));
    let errors = rig.node_health().last().map_or(0, |h| h.errors);
    assert!(
        errors > errors_before,
        "refused commands counted: errors {errors_before} -> {errors}"
    );
    assert!(rig.log().contains("refused"), "{}", rig.log());
    // A valid command is followed again.
    let s = rig.command([0.5; 6], Duration::from_millis(1200));
    assert!((positions(&s)[1] - 0.5).abs() < 0.03, "{:?}", positions(&s));
    assert_eq!(s.holding, 0);
}

/// Velocity and duty commands respect the hand profile's joint limits (`config/hands/revo2.toml`,
/// the only source of limits: 0..1 of travel): motion toward a limit the joint is at is stopped
/// and counted as a clamp, motion away from it is followed.
#[test]
fn velocity_and_duty_commands_stop_at_the_joint_limits() {
    let mut rig = Rig::new("");
    let mut cmd = position_command([0.0; 6]);
    cmd.control_mode = control_mode::VELOCITY;
    for j in &mut cmd.joints {
        j.target = 0.0;
    }
    cmd.joints[1].target = 1.0; // travel per second, closing
    let s = rig.send(&cmd, Duration::from_millis(1500));
    let p = positions(&s)[1];
    assert!(
        p >= 0.95,
        "velocity: thumb abduction at its upper limit: {p}"
    );
    let _ = rig.node_health();
    rig.send(&cmd, Duration::from_millis(600));
    let clamps = |rig: &Rig| {
        std::thread::sleep(Duration::from_millis(600));
        rig.node_health().last().map_or(0, |h| h.clamps)
    };
    let at_limit = clamps(&rig);
    assert!(at_limit > 0, "closing at the upper limit counted as clamps");
    let mut duty = cmd;
    duty.control_mode = control_mode::DUTY;
    duty.joints[1].target = -0.5; // opening, toward the lower limit
    let s = rig.send(&duty, Duration::from_millis(1500));
    let p = positions(&s)[1];
    assert!(p <= 0.05, "duty: thumb abduction at its lower limit: {p}");
    duty.joints[1].target = 0.5; // away from the lower limit: followed
    let s = rig.send(&duty, Duration::from_millis(150));
    assert!(positions(&s)[1] > p + 0.05, "{:?}", positions(&s));
    assert!(
        clamps(&rig) > at_limit,
        "opening at the lower limit counted"
    );
}

/// Issue 20, item 8: while the link is down the node keeps publishing its health, so the
/// launch supervisor does not take it for hung (it published none and was killed).
#[test]
fn health_keeps_coming_while_the_link_is_down() {
    let mut rig = Rig::new("");
    rig.command([0.3; 6], Duration::from_millis(300));
    lock(&rig.sim).faults().link_down = true;
    rig.wait_state(Duration::from_secs(5), "link down", |s| s.link_up == 0);
    let _ = rig.node_health();
    let start = Instant::now();
    let mut reports = 0;
    let mut at = Vec::new();
    while start.elapsed() < Duration::from_secs(4) {
        let n = rig.node_health().len();
        if n > 0 {
            at.push(start.elapsed());
        }
        reports += n;
        std::thread::sleep(Duration::from_millis(20));
    }
    let down = rig.states.poll_latest().unwrap();
    lock(&rig.sim).faults().link_down = false;
    assert_eq!(down.link_up, 0, "the link stayed down throughout");
    // Every 500 ms (health_period_ms): about 8 in 4 s.
    assert!(
        reports >= 4,
        "health reports while the link was down: {reports} at {at:?}\n{}",
        rig.log()
    );
    rig.wait_state(Duration::from_secs(15), "link up again", |s| s.link_up == 1);
}

/// The fastest motion over any 200 ms of `track` (node stamps, positions), travel/s: long
/// enough that a late frame, after which the device catches up with its target, does not read
/// as a jump; short enough to tell 1 from 2 travel/s over a 0.8 travel move.
fn fastest(track: &[(u64, f32)]) -> f32 {
    let mut fastest = 0.0f32;
    for (i, &(t0, p0)) in track.iter().enumerate() {
        if let Some(&(t1, p1)) = track[i..].iter().find(|(t, _)| t - t0 >= 200_000_000) {
            fastest = fastest.max((p1 - p0).abs() / ((t1 - t0) as f32 * 1e-9));
        }
    }
    fastest
}

/// Issue 20, item 12: when the e-stop is released, the hand does not jump to the operator's
/// pose (which moved while it held): it ramps there at the resume speed (1 travel/s), then
/// tracks.
#[test]
fn after_an_estop_release_the_hand_ramps_to_the_operators_pose() {
    let mut rig = Rig::new("");
    let runtime = NodeRuntime::new("revo2-estop-test", &rig.rig.sandbox.ipc).unwrap();
    let mut doorbell: Publisher<EStop> = runtime.publisher().unwrap();
    let latch = teleop_runtime::latch_path(&rig.rig.sandbox.ipc, None);
    let mut ring = |engaged: bool| {
        teleop_runtime::set_latch(&latch, engaged).unwrap();
        doorbell
            .publish(&EStop {
                engaged: u8::from(engaged),
                ..Default::default()
            })
            .unwrap();
    };
    let a = [0.1; 6];
    let b = [0.1, 0.9, 0.1, 0.1, 0.1, 0.1];
    rig.command(a, Duration::from_millis(1000));
    ring(true);
    let start = Instant::now();
    while rig.command(a, Duration::from_millis(50)).holding == 0 {
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "the e-stop does not hold the hand\n{}",
            rig.log()
        );
    }
    // The operator moves on while the hand holds at A.
    let s = rig.command(b, Duration::from_millis(600));
    assert_eq!(s.holding, 1, "held while the e-stop is engaged");
    assert!((positions(&s)[1] - 0.1).abs() < 0.03, "{:?}", positions(&s));
    ring(false);
    let _ = rig.states.drain(|_| {});
    let mut track: Vec<(u64, f32)> = Vec::new();
    let start = Instant::now();
    while start.elapsed() < Duration::from_millis(2000) {
        rig.commands.publish(&position_command(b)).unwrap();
        rig.states
            .drain(|s| track.push((s.header.origin_ns, s.joints[1].position)));
        std::thread::sleep(Duration::from_millis(5));
    }
    let last = track.last().unwrap().1;
    assert!(
        (last - 0.9).abs() < 0.03,
        "reached B: {last}\n{}",
        rig.log()
    );
    let fastest = fastest(&track);
    assert!(
        fastest < 1.3,
        "the hand moved at {fastest} travel/s toward B after the release: a jump, not a ramp"
    );
    assert!(
        fastest > 0.7,
        "it moves at about the resume speed: {fastest}"
    );
}

/// Issue 20, item 12: when the command comes back after a stale period, the hand does not jump
/// to the operator's pose at full speed: the target ramps from the held position at the
/// configured resume speed (the default: 1 travel per second; the device and these commands
/// could do 2), then tracks.
#[test]
fn after_a_stale_period_the_hand_ramps_to_the_new_pose() {
    let mut rig = Rig::new("");
    rig.command([0.1; 6], Duration::from_millis(1000));
    rig.wait_state(Duration::from_secs(2), "holding", |s| s.holding == 1);
    std::thread::sleep(Duration::from_millis(200));
    // Far pose B for the free thumb abduction, at the commands' full speed (2 travel/s).
    let b = [0.1, 0.9, 0.1, 0.1, 0.1, 0.1];
    let _ = rig.states.drain(|_| {});
    let mut track: Vec<(u64, f32)> = Vec::new();
    let start = Instant::now();
    while start.elapsed() < Duration::from_millis(2000) {
        rig.commands.publish(&position_command(b)).unwrap();
        rig.states.drain(|s| {
            if s.link_up == 1 {
                track.push((s.header.origin_ns, s.joints[1].position));
            }
        });
        std::thread::sleep(Duration::from_millis(5));
    }
    let last = track.last().unwrap().1;
    assert!((last - 0.9).abs() < 0.03, "reached B: {last}");
    // The fastest motion over any 200 ms: bounded by the resume speed (with room for the
    // device's own lag), not the full speed.
    let fastest = fastest(&track);
    assert!(
        fastest < 1.3,
        "the hand moved at {fastest} travel/s toward B: a jump, not a ramp"
    );
    assert!(
        fastest > 0.7,
        "it moves at about the resume speed: {fastest}"
    );
}
