//! The Revo2 node, started as a process, drives the emulated Revo2 through ethercrab's real
//! MainDevice state machine over the local-socket transport. The emulator runs in this test
//! process so the test can inject faults and look at the device.
#![allow(clippy::unwrap_used)]

use std::process::{Child, Command};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use sim_revo2::hand::VirtualObject;
use sim_revo2::{revo2_subdevice_with_loop, Revo2};
use teleop_ecat_link::serve_socket;
use teleop_ecat_link::StreamServer;
use teleop_ecat_sim::{AlState, SubDevice};
mod common;

use common::{position_command, positions};
use teleop_msgs::{HandCommand, HandState, Tactile};
use teleop_runtime::{IpcSettings, NodeRuntime, Publisher, Subscriber};

type Sim = Arc<Mutex<SubDevice<Revo2>>>;

fn lock(sim: &Sim) -> std::sync::MutexGuard<'_, SubDevice<Revo2>> {
    sim.lock().unwrap_or_else(|e| e.into_inner())
}

/// Serves the emulated Revo2 on a socket until `stop`.
fn serve(server: StreamServer, sim: Sim, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let stopping = || stop.load(Ordering::SeqCst);
        serve_socket(&server, &sim, Instant::now(), &stopping, &mut |_, _| {}).unwrap();
    })
}

struct Rig {
    commands: Publisher<HandCommand>,
    states: Subscriber<HandState>,
    tactile: Subscriber<Tactile>,
    _runtime: NodeRuntime,
    node: Option<Child>,
    sim: Sim,
    stop: Arc<AtomicBool>,
    server: Option<std::thread::JoinHandle<()>>,
    ipc: IpcSettings,
    dir: tempfile::TempDir,
}

impl Rig {
    fn new(extra_config: &str) -> Self {
        teleop_runtime::init_logging();
        let dir = tempfile::tempdir().unwrap();
        let ipc = IpcSettings::isolated(&dir.path().join("iox"));
        let socket = dir.path().join("revo2.sock");
        // A firmware that reads AL control once per 1 ms loop, as the simulator process runs.
        let sim: Sim = Arc::new(Mutex::new(revo2_subdevice_with_loop(
            Some(VirtualObject::ball()),
            7,
            Duration::from_millis(1),
        )));
        let stop = Arc::new(AtomicBool::new(false));
        let server = serve(
            StreamServer::bind(&socket).unwrap(),
            sim.clone(),
            stop.clone(),
        );
        let config = dir.path().join("revo2.toml");
        std::fs::write(
            &config,
            format!(
                "transport = \"sim:{}\"\nlink_timeout_ms = 100\n{extra_config}",
                socket.display()
            ),
        )
        .unwrap();
        let log = std::fs::File::create(dir.path().join("node.log")).unwrap();
        let node = Command::new(env!("CARGO_BIN_EXE_teleop-revo2"))
            .arg("--config")
            .arg(&config)
            .envs(ipc.to_env())
            .env("TELEOP_LOG", "info")
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .unwrap();
        let runtime = NodeRuntime::new("revo2-test", &ipc).unwrap();
        let rig = Self {
            commands: runtime.publisher().unwrap(),
            states: runtime.subscriber().unwrap(),
            tactile: runtime.subscriber().unwrap(),
            _runtime: runtime,
            node: Some(node),
            sim,
            stop,
            server: Some(server),
            ipc,
            dir,
        };
        rig.wait_state(Duration::from_secs(30), "the hand in OP", |s| {
            s.link_up == 1
        });
        rig
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("node.log")).unwrap_or_default()
    }

    fn wait_state(
        &self,
        timeout: Duration,
        what: &str,
        ok: impl FnMut(&HandState) -> bool,
    ) -> HandState {
        common::wait_state(&self.states, timeout, what, ok, || self.log())
    }

    /// Publishes position targets every 10 ms for `d`, returning the last hand state.
    fn command(&mut self, targets: [f32; 6], d: Duration) -> HandState {
        let start = Instant::now();
        while start.elapsed() < d {
            self.commands.publish(&position_command(targets)).unwrap();
            std::thread::sleep(Duration::from_millis(10));
        }
        self.states.poll_latest().unwrap()
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        if let Some(mut node) = self.node.take() {
            // SAFETY: kill(2) of our own child.
            unsafe {
                libc::kill(node.id() as libc::pid_t, libc::SIGINT);
            }
            let _ = node.wait();
        }
        self.stop.store(true, Ordering::SeqCst);
        if let Some(s) = self.server.take() {
            let _ = s.join();
        }
        if std::thread::panicking() {
            eprintln!("---- node log ----\n{}", self.log());
        }
        self.ipc.remove_shared_memory();
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
    rig.wait_state(Duration::from_secs(2), "holding", |s| s.holding == 1);
    std::thread::sleep(Duration::from_millis(300));
    let held = rig.states.poll_latest().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let later = rig.states.poll_latest().unwrap();
    assert_eq!(later.holding, 1);
    for (a, b) in positions(&held).iter().zip(positions(&later)) {
        assert!(
            (a - b).abs() < 0.005,
            "held: {:?} -> {:?}",
            positions(&held),
            positions(&later)
        );
    }
    let grip = rig.tactile.poll_latest().unwrap().fingertips[1].normal_n;
    assert!(
        grip > t.fingertips[1].normal_n / 2.0,
        "the grip stays: {grip} N (was {} N)",
        t.fingertips[1].normal_n
    );
    assert!(rig.log().contains("hand command stale: the device holds"));
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
    let pid_alive = rig.node.as_mut().unwrap().try_wait().unwrap().is_none();
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
    assert!(
        rig.node.as_mut().unwrap().try_wait().unwrap().is_none(),
        "same process"
    );
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
