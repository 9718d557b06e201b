//! The Revo2 node over a real link: a veth pair `ecm0`/`ecs0` inside a network namespace of its
//! own per test, the emulator `teleop-sim-revo2 --interface ecs0` on a raw socket on one end and
//! the node (a process, as in production) on the other, with
//! - `transport = "ethercrab:ecm0"`: ethercrab's own raw-socket task, unmodified;
//! - `transport = "interface:ecm0"`: the node's frame pump on a raw socket;
//! - and an independent master, SOEM (through pysoem, `tests/soem_op.py`), bringing the emulator
//!   to OP over the same kind of link.
//!
//! Privileged: each test is skipped, with the reason printed, unless it runs as root with `ip`
//! (iproute2) and `unshare(CLONE_NEWNET)` works; the SOEM test also needs `python3` with pysoem
//! (`pip install -r .ci/requirements.txt`). The emulator's binary must have been built (`cargo
//! build --workspace --bins`). The test process subscribes to the node's topics directly: the
//! iceoryx2 shared memory is not network-namespaced.
#![allow(clippy::unwrap_used)]

mod common;

use teleop_e2e::netns::{die_with_parent, python_module_missing, skip, stop, Netns};
use teleop_e2e::skip_unless_privileged;

use common::{position_command, positions};
use std::path::Path;
use std::process::{Child, Command};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use teleop_msgs::{HandCommand, HandState};
use teleop_runtime::{IpcSettings, NodeRuntime, Publisher, Subscriber};

/// Prefix of the namespaces these tests create: `<prefix><pid>-<n>`.
const NETNS_PREFIX: &str = "teleop-revo2-veth-";

/// One test at a time: each runs a node at 1 kHz and an emulator, and the machine has 2 cores.
fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

/// The emulator serving on `ecs0` in `ns`, no object in its hand, its output in `dir/sim.log`.
fn start_sim(ns: &Netns, dir: &Path) -> Child {
    ns.start_emulator(
        "teleop-sim-revo2",
        &["--object", "none"],
        dir,
        "revo2: interface ecs0",
    )
}

/// The node on `ecm0` with `transport`, the emulator on `ecs0`, and the test's ports.
struct Rig {
    commands: Publisher<HandCommand>,
    states: Subscriber<HandState>,
    _runtime: NodeRuntime,
    node: Option<Child>,
    sim: Option<Child>,
    ipc: IpcSettings,
    dir: tempfile::TempDir,
    ns: Netns,
}

impl Rig {
    fn new(transport: &str) -> Self {
        teleop_runtime::init_logging();
        let ns = Netns::new(NETNS_PREFIX);
        let dir = tempfile::tempdir().unwrap();
        let ipc = IpcSettings::isolated(&dir.path().join("iox"));
        let sim = start_sim(&ns, dir.path());
        let config = dir.path().join("revo2.toml");
        std::fs::write(
            &config,
            format!("transport = \"{transport}\"\nlink_timeout_ms = 100\n"),
        )
        .unwrap();
        let log = std::fs::File::create(dir.path().join("node.log")).unwrap();
        let mut cmd = ns.command(env!("CARGO_BIN_EXE_teleop-revo2"));
        cmd.arg("--config")
            .arg(&config)
            .envs(ipc.to_env())
            .env("TELEOP_LOG", "info")
            .stdout(log.try_clone().unwrap())
            .stderr(log);
        let node = die_with_parent(&mut cmd).spawn().unwrap();
        let runtime = NodeRuntime::new("revo2-veth-test", &ipc).unwrap();
        let rig = Self {
            commands: runtime.publisher().unwrap(),
            states: runtime.subscriber().unwrap(),
            _runtime: runtime,
            node: Some(node),
            sim: Some(sim),
            ipc,
            dir,
            ns,
        };
        rig.wait_state(Duration::from_secs(30), "the hand in OP", |s| {
            s.link_up == 1 && s.bus_state == teleop_msgs::bus_state::AL_OP
        });
        rig
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("node.log")).unwrap_or_default()
    }

    fn sim_log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("sim.log")).unwrap_or_default()
    }

    fn wait_state(
        &self,
        timeout: Duration,
        what: &str,
        ok: impl FnMut(&HandState) -> bool,
    ) -> HandState {
        let logs = || {
            format!(
                "---- node log ----\n{}\n---- emulator log ----\n{}",
                self.log(),
                self.sim_log()
            )
        };
        teleop_e2e::watch::wait_sample(&self.states, &logs, timeout, what, ok)
    }

    /// Publishes position targets every 10 ms until the hand state (link up) reports every
    /// joint within `tolerance` of its target; returns that state.
    fn follow(&mut self, targets: [f32; 6], tolerance: f32, timeout: Duration) -> HandState {
        let start = Instant::now();
        let mut last = None;
        loop {
            self.commands.publish(&position_command(targets)).unwrap();
            std::thread::sleep(Duration::from_millis(10));
            let mut reached = None;
            self.states.drain(|s| {
                if s.link_up == 1 {
                    last = Some(positions(s));
                    let close = positions(s)
                        .iter()
                        .zip(targets)
                        .all(|(p, t)| (p - t).abs() <= tolerance);
                    if close {
                        reached = Some(*s);
                    }
                }
            });
            if let Some(s) = reached {
                return s;
            }
            assert!(
                start.elapsed() < timeout,
                "the hand did not follow {targets:?} (last positions {last:?})\n---- node log ----\n{}",
                self.log()
            );
        }
    }

    fn node_pid(&self) -> u32 {
        self.node.as_ref().unwrap().id()
    }

    fn sim_running(&mut self) -> bool {
        self.sim.as_mut().unwrap().try_wait().unwrap().is_none()
    }

    fn node_running(&mut self) -> bool {
        self.node.as_mut().unwrap().try_wait().unwrap().is_none()
    }

    /// A command on the emulator's control socket; returns its answer.
    fn sim_control(&self, line: &str) -> String {
        teleop_e2e::control(&self.dir.path().join("sim.ctl"), line)
    }

    /// `ip link set ecm0 down`, wait for the node to report the link down, then `up`.
    ///
    /// The emulator is told to go quiet (drop frames) for 1.5 s first: `teleop-sim-revo2
    /// --interface` exits for good when a reply cannot be sent, and a reply racing the
    /// interface going down fails with ENOBUFS on the veth pair. The node still meets the
    /// interface reset itself: ethercrab's task's next send fails with ENETDOWN, and so do the
    /// pump's socket calls.
    fn reset_master_interface(&mut self) {
        let answer = self.sim_control("unplug 1500");
        assert!(answer.starts_with("ok"), "{answer}");
        self.ns.ip(&["link", "set", "ecm0", "down"]);
        self.wait_state(Duration::from_secs(10), "the link reported down", |s| {
            s.link_up == 0
        });
        std::thread::sleep(Duration::from_millis(500));
        self.ns.ip(&["link", "set", "ecm0", "up"]);
    }

    /// [`Self::reset_master_interface`], then wait for the node to report the link up again
    /// and check it recovered in the same process with the emulator still serving; returns
    /// the node's log.
    fn reset_master_interface_and_recover(&mut self) -> String {
        let pid = self.node_pid();
        self.reset_master_interface();
        self.wait_state(Duration::from_secs(20), "the link up again", |s| {
            s.link_up == 1
        });
        assert!(self.node_running(), "same process");
        assert_eq!(self.node_pid(), pid);
        assert!(self.sim_running(), "the emulator is still serving");
        self.log()
    }

    /// Follows a pose, resets the master's interface
    /// ([`Self::reset_master_interface_and_recover`]) and follows another; the node's log after
    /// the reset says each of `says` and none of `never`.
    fn follow_across_an_interface_reset(&mut self, says: &[&str], never: &[&str]) {
        self.follow(
            [0.2, 0.3, 0.1, 0.4, 0.5, 0.6],
            0.02,
            Duration::from_secs(10),
        );
        let log = self.reset_master_interface_and_recover();
        for words in says {
            assert!(log.contains(words), "{words:?} not logged:\n{log}");
        }
        for words in never {
            assert!(!log.contains(words), "{words:?} logged:\n{log}");
        }
        self.follow(
            [0.6, 0.5, 0.7, 0.2, 0.3, 0.1],
            0.02,
            Duration::from_secs(10),
        );
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        if let Some(mut node) = self.node.take() {
            stop(&mut node);
        }
        if let Some(mut sim) = self.sim.take() {
            stop(&mut sim);
        }
        if std::thread::panicking() {
            eprintln!(
                "---- node log ----\n{}\n---- emulator log ----\n{}",
                self.log(),
                self.sim_log()
            );
        }
        self.ipc.remove_shared_memory();
    }
}

#[test]
fn ethercrab_task_reaches_op_follows_commands_and_recovers_with_a_fresh_bus() {
    skip_unless_privileged!();
    let _serial = serial();
    let mut rig = Rig::new("ethercrab:ecm0");
    let log = rig.log();
    assert!(
        log.contains("ethercrab's raw-socket task running") && !log.contains("EtherCAT link open"),
        "ethercrab's own task carries the frames, not the pump:\n{log}"
    );
    assert!(log.contains("Revo2 found") && log.contains("control_fw=1.4.2"));
    // Admin-down makes the task's next send fail (ENETDOWN): ethercrab's task ends for good and
    // takes its PDU handles with it. The node reports the link down, and once the interface is
    // up again opens a fresh bus (new storage, MainDevice and task) in the same process.
    rig.follow_across_an_interface_reset(&["ethercrab's task ended", "opened a fresh bus"], &[]);
}

#[test]
fn pump_on_interface_reaches_op_follows_commands_and_survives_an_interface_reset() {
    skip_unless_privileged!();
    let _serial = serial();
    let mut rig = Rig::new("interface:ecm0");
    let log = rig.log();
    assert!(
        log.contains("EtherCAT link open") && !log.contains("ethercrab's raw-socket task"),
        "{log}"
    );
    // The pump reopens its raw socket and the same bus is brought up again.
    rig.follow_across_an_interface_reset(&["EtherCAT link lost"], &["opened a fresh bus"]);
}

/// Why the SOEM test cannot run, if it cannot.
#[test]
fn soem_brings_the_emulated_revo2_to_op_over_the_veth_pair() {
    skip_unless_privileged!();
    if let Some(reason) = python_module_missing("pysoem") {
        skip(&reason);
        return;
    }
    let _serial = serial();
    let ns = Netns::new(NETNS_PREFIX);
    let dir = tempfile::tempdir().unwrap();
    let mut sim = start_sim(&ns, dir.path());
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/soem_op.py");
    let (out, report) = ns.run_soem(script, 300, &mut sim, dir.path());
    assert!(
        out.contains("vendor 0x00bc0000 product 0x00009252") && out.contains("in OP"),
        "{report}"
    );
}

#[test]
fn ethercrab_transport_without_cap_net_raw_says_how_to_grant_it() {
    skip_unless_privileged!();
    if Command::new("setpriv").arg("--version").output().is_err() {
        skip("no setpriv (util-linux) to drop CAP_NET_RAW");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let ipc = IpcSettings::isolated(&dir.path().join("iox"));
    // Root without CAP_NET_RAW in its bounding set: the raw socket is refused (EPERM).
    let out = Command::new("setpriv")
        .args(["--bounding-set", "-net_raw", "--"])
        .arg(env!("CARGO_BIN_EXE_teleop-revo2"))
        .args(["--transport", "ethercrab:lo"])
        .envs(ipc.to_env())
        .env("TELEOP_LOG", "info")
        .output()
        .unwrap();
    ipc.remove_shared_memory();
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!out.status.success(), "{log}");
    assert!(
        log.contains("setcap cap_net_raw,cap_net_admin=eip")
            && log.contains("ethercrab's raw EtherCAT socket on lo"),
        "{log}"
    );
}
