//! The Shadow node, started as a process, drives the emulated Hand E (bridge and palm as two
//! `teleop-ecat-sim` SubDevices) through ethercrab's real MainDevice state machine and the
//! node's own sync manager and FMMU programming, over the local-socket transport. The emulator
//! runs in this test process so the test can inject faults and look at the hand.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::{Duration, Instant};

use common::{serve, Sim};
use teleop_e2e::hand::HandNode;
use teleop_e2e::rig::Rig as TestRig;
use teleop_msgs::{control_mode, device_model, units, HandCommand, HandState};
use teleop_shadow::joints::JOINTS;
use teleop_shadow_protocol::mapping::Mapping;
use teleop_sim_shadow::ethercat::ShadowBus;
use teleop_sim_shadow::hand::{Hand, VirtualObject};
use teleop_sim_shadow::palm::{Palm, CUT_OUT_C};

fn lock(sim: &Sim) -> std::sync::MutexGuard<'_, ShadowBus> {
    sim.lock()
}

fn joint(name: &str) -> usize {
    JOINTS.iter().position(|j| *j == name).unwrap()
}

/// The Shadow node against the emulated Hand E (a ball under its middle finger) served from
/// this process.
type Rig = HandNode<Sim>;

/// How the Shadow Hand's tests start and command the node.
trait ShadowRig {
    /// The node up in OP.
    fn new() -> Self;
    /// Publishes joint targets (rad, by name; the others 0) every 10 ms for `d`; returns the
    /// last hand state.
    fn command(&mut self, targets: &[(&str, f32)], d: Duration) -> HandState;
}

impl ShadowRig for Rig {
    fn new() -> Self {
        let rig = TestRig::new();
        let socket = rig.path("shadow.sock");
        let hand = Hand::new(Mapping::EV3, Some(VirtualObject::ball()));
        let sim = serve(&socket, Palm::with_hand(hand));
        let config = format!("transport = \"sim:{}\"\n", socket.display());
        let program = env!("CARGO_BIN_EXE_teleop-shadow");
        let rig = HandNode::start_with(rig, "shadow", program, &config, sim);
        rig.wait_state(Duration::from_secs(30), "the hand in OP", |s| {
            s.link_up == 1
        });
        rig
    }

    fn command(&mut self, targets: &[(&str, f32)], d: Duration) -> HandState {
        let mut c = HandCommand {
            hand_model: device_model::SHADOW,
            joint_count: 24,
            control_mode: control_mode::POSITION,
            units: units::PHYSICAL,
            ..Default::default()
        };
        for (name, t) in targets {
            c.joints[joint(name)].target = *t;
        }
        self.send(&c, d)
    }
}

fn position(s: &HandState, name: &str) -> f32 {
    s.joints[joint(name)].position
}

#[test]
fn bring_up_position_control_pst_contact_hold_and_link_loss() {
    let mut rig = Rig::new();
    {
        let sim = lock(&rig.sim);
        assert_eq!(sim.bridge.al_state().0, teleop_ecat_sim::AlState::Op);
        assert_eq!(sim.palm.al_state().0, teleop_ecat_sim::AlState::Op);
    }
    let log = rig.log();
    assert!(log.contains("Shadow palm found"), "{log}");

    // A pose: the index knuckle, the thumb's rotation and the wrist.
    let pose = [("FFJ3", 0.8), ("THJ5", 0.4), ("WRJ2", -0.2), ("RFJ4", -0.2)];
    let s = rig.command(&pose, Duration::from_millis(1500));
    for (name, target) in pose {
        let p = position(&s, name);
        assert!((p - target).abs() < 0.05, "{name}: {p} for {target}");
    }
    let sim_ffj3 = lock(&rig.sim).palm().hand.angles[joint("FFJ3")];
    assert!(
        (sim_ffj3 - 0.8).abs() < 0.05,
        "the emulated joint: {sim_ffj3}"
    );
    assert_eq!(s.holding, 0);
    assert_eq!(s.hand_model, device_model::SHADOW);

    // The middle finger closes on the ball: it stops, and its fingertip's PST reads pressure.
    let grasp = [("MFJ3", 1.4), ("MFJ2", 0.6), ("MFJ1", 0.6), ("FFJ3", 1.2)];
    let s = rig.command(&grasp, Duration::from_millis(1500));
    let mf = position(&s, "MFJ3") + (position(&s, "MFJ1") + position(&s, "MFJ2")) / 2.0;
    assert!(
        (0.95..1.1).contains(&mf),
        "stopped by the ball: closure {mf}"
    );
    assert!(position(&s, "FFJ3") > 1.1, "the index closes freely");
    let t = rig.tactile.poll_latest().unwrap();
    let (mf_p, ff_p) = (t.fingertips[1].pressure, t.fingertips[0].pressure);
    assert!(mf_p > 100 && ff_p < 20, "PST pressure MF {mf_p}, FF {ff_p}");
    assert!(
        s.joints[joint("MFJ3")].effort > 0.05,
        "{:?}",
        s.joints[joint("MFJ3")]
    );

    // The command goes stale: the hand holds, the grasp keeps pressing.
    let held = rig.wait_state(Duration::from_secs(2), "holding", |s| s.holding == 1);
    std::thread::sleep(Duration::from_millis(400));
    let later = rig.states.poll_latest().unwrap();
    assert_eq!(later.holding, 1);
    for name in ["FFJ3", "THJ5", "MFJ3"] {
        let (a, b) = (position(&held, name), position(&later, name));
        assert!(
            (a - b).abs() < 0.01,
            "{name} drifted while holding: {a} -> {b}"
        );
    }
    assert!(rig.tactile.poll_latest().unwrap().fingertips[1].pressure > 100);

    // The link goes down for 300 ms: reported, then the same process brings the hand up again.
    let pid = rig.node().pid();
    lock(&rig.sim).bridge.faults().link_down = true;
    rig.wait_state(Duration::from_secs(3), "link down", |s| s.link_up == 0);
    std::thread::sleep(Duration::from_millis(300));
    lock(&rig.sim).bridge.faults().link_down = false;
    rig.wait_state(Duration::from_secs(10), "link up again", |s| s.link_up == 1);
    assert_eq!(rig.node().pid(), pid);
    let s = rig.command(&[("FFJ3", 0.3)], Duration::from_millis(1500));
    assert!(
        (position(&s, "FFJ3") - 0.3).abs() < 0.05,
        "control after the link came back"
    );
}

#[test]
fn a_silent_motor_is_reported_and_an_overheated_one_stopped_while_the_rest_work() {
    let mut rig = Rig::new();
    let ffj4 = usize::from(Mapping::EV3.motor_of_joint("FFJ4").unwrap());
    let thj5 = usize::from(Mapping::EV3.motor_of_joint("THJ5").unwrap());
    rig.command(&[("FFJ3", 0.2)], Duration::from_millis(600));
    lock(&rig.sim).palm_mut().boards[ffj4].silent = true;
    lock(&rig.sim).palm_mut().motors[thj5].temperature = CUT_OUT_C + 5.0;
    let s = rig.command(&[("FFJ3", 0.9), ("THJ5", 0.5)], Duration::from_millis(1500));
    assert!(
        (position(&s, "FFJ3") - 0.9).abs() < 0.05,
        "the others keep working"
    );
    assert!(position(&s, "THJ5").abs() < 0.1, "THJ5's motor is stopped");
    let torque = lock(&rig.sim).palm().motors[thj5].torque;
    assert!(
        torque.abs() < 50.0,
        "no torque on the stopped motor: {torque}"
    );
    let log = rig.log();
    assert!(
        log.contains(&format!("motor {ffj4} (FFJ4) stopped answering")),
        "{log}"
    );
    assert!(
        log.contains(&format!("motor {thj5} (THJ5) stopped by over temperature")),
        "{log}"
    );
    assert_ne!(
        s.joints[joint("THJ5")].status & 0x8000,
        0,
        "the flag in hand/state"
    );
}

/// Issue 20, item 8: while the link is down the node keeps publishing its health, so the
/// launch supervisor does not take it for hung (it published none and was killed).
#[test]
fn health_keeps_coming_while_the_link_is_down() {
    let mut rig = Rig::new();
    rig.command(&[("FFJ3", 0.2)], Duration::from_millis(300));
    lock(&rig.sim).bridge.faults().link_down = true;
    rig.wait_state(Duration::from_secs(3), "link down", |s| s.link_up == 0);
    let _ = rig.node_health();
    let start = Instant::now();
    let mut reports = 0;
    while start.elapsed() < Duration::from_secs(4) {
        reports += rig.node_health().len();
        std::thread::sleep(Duration::from_millis(20));
    }
    let down = rig.states.poll_latest().unwrap();
    lock(&rig.sim).bridge.faults().link_down = false;
    assert_eq!(down.link_up, 0, "the link stayed down throughout");
    // Every 500 ms (health_period_ms): about 8 in 4 s.
    assert!(
        reports >= 4,
        "health reports while the link was down: {reports}\n{}",
        rig.log()
    );
    rig.wait_state(Duration::from_secs(10), "link up again", |s| s.link_up == 1);
}

/// Issue 20, item 4: a NaN or infinite target is no valid command on every hand: the Shadow
/// holds where it was, says so, and counts the refusal as an error (it held, but counted it as
/// a stale command, which it was not).
#[test]
fn a_non_finite_target_holds_and_is_counted() {
    let mut rig = Rig::new();
    let s = rig.command(&[("FFJ3", 0.8)], Duration::from_millis(1500));
    let before = position(&s, "FFJ3");
    assert!((before - 0.8).abs() < 0.05, "{before}");
    let _ = rig.node_health();
    for bad in [f32::NAN, f32::INFINITY] {
        let s = rig.command(&[("FFJ3", 0.2), ("THJ5", bad)], Duration::from_millis(700));
        assert_eq!(s.holding, 1, "{bad}: the state says the hand holds");
        let p = position(&s, "FFJ3");
        assert!(
            (p - before).abs() < 0.02,
            "{bad}: FFJ3 moved {before} -> {p}"
        );
    }
    let health = rig.node_health();
    let last = health.last().unwrap();
    assert!(last.errors > 0, "refusals counted as errors: {last:?}");
    assert_eq!(last.timeouts, 0, "not counted as stale commands: {last:?}");
    assert!(rig.log().contains("refused"), "{}", rig.log());
    // When the refused commands stop coming, that is a stale command.
    std::thread::sleep(Duration::from_millis(700));
    let last = *rig.node_health().last().unwrap();
    assert_eq!(last.timeouts, 1, "{last:?}");
}
