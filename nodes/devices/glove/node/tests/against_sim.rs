//! The glove node, started as a process, against the simulated glove on a real pseudo-terminal.
//! The simulator runs in this test process so the test can see what reached the device and
//! inject faults; the node is the real `teleop-glove` executable with `serialport`.
#![allow(clippy::unwrap_used)]

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use teleop_e2e::rig::{Logs, Process, Rig as TestRig};
use teleop_e2e::watch::wait_sample;
use teleop_glove_protocol::BaudRate;
use teleop_msgs::{GloveDiagnostics, GloveForceCommand, GloveState, NodeHealth};
use teleop_runtime::{NodeRuntime, Publisher, Subscriber};
use teleop_sim_glove::hand::{Hand, HandModel, Script};
use teleop_sim_glove::{Faults, SimGlove, SimOptions};

/// Fields drop in order: the ports before their node, the node (its log printed on failure)
/// and the sandbox next, the simulator last.
struct Rig {
    states: Subscriber<GloveState>,
    diagnostics: Subscriber<GloveDiagnostics>,
    health: Subscriber<NodeHealth>,
    forces: Publisher<GloveForceCommand>,
    _runtime: NodeRuntime,
    rig: TestRig,
    sim: SimGlove,
}

impl Rig {
    fn new() -> Self {
        Self::with_answer_timeout(30)
    }

    fn with_answer_timeout(answer_timeout_ms: u64) -> Self {
        let mut rig = TestRig::new();
        let link = rig.path("glove");
        let sim = SimGlove::start(
            SimOptions {
                link: link.clone(),
                id: 1,
                baud: BaudRate::B115200,
                response_delay: Duration::from_micros(200),
                faults: Faults::default(),
                seed: 7,
            },
            Hand::new(Script::Hold([600.0; 6]), HandModel::default()),
        )
        .unwrap();
        let config = format!(
            "port = {:?}\nanswer_timeout_ms = {answer_timeout_ms}\ndiagnostics_hz = 4.0\nforce_timeout_ms = 100\nreopen_backoff_ms = [50, 400]\nhealth_period_ms = 200\n",
            link.display().to_string()
        );
        rig.start_node("glove", env!("CARGO_BIN_EXE_teleop-glove"), &config);
        let runtime = NodeRuntime::new("glove-test", &rig.sandbox.ipc).unwrap();
        let rig = Self {
            states: runtime.subscriber().unwrap(),
            diagnostics: runtime.subscriber().unwrap(),
            health: runtime.subscriber().unwrap(),
            forces: runtime.publisher().unwrap(),
            _runtime: runtime,
            rig,
            sim,
        };
        rig.wait_until(Duration::from_secs(20), "the first glove state", |s| {
            s.link_up == 1
        });
        rig
    }

    fn log(&self) -> String {
        self.rig.logs()
    }

    /// Glove states received during `d`.
    fn collect(&self, d: Duration) -> Vec<GloveState> {
        let mut out = Vec::new();
        let start = Instant::now();
        while start.elapsed() < d {
            self.states.drain(|s| out.push(*s));
            std::thread::sleep(Duration::from_millis(2));
        }
        out
    }

    fn wait_until(
        &self,
        timeout: Duration,
        what: &str,
        ok: impl FnMut(&GloveState) -> bool,
    ) -> GloveState {
        wait_sample(&self.states, &self.rig, timeout, what, ok)
    }

    fn node(&mut self) -> &mut Process {
        self.rig.process("glove")
    }

    fn node_alive(&mut self) -> bool {
        self.node().is_running()
    }
}

#[test]
fn glove_node_streams_states_near_line_rate_and_applies_force_commands() {
    let mut rig = Rig::new();
    let states = rig.collect(Duration::from_secs(2));
    let rate = states.len() as f64 / 2.0;
    // 34 bytes per exchange at 115200 baud is 339/s at most; diagnostics take a few slots.
    assert!(rate > 150.0 && rate < 345.0, "{rate} glove states/s");
    let last = states.last().unwrap();
    assert_eq!(last.raw_position, [600; 6]);
    assert!((last.position[0] - 0.6).abs() < 1e-6);
    assert!(last.header.origin_ns > 0 && last.header.stamp_ns >= last.header.origin_ns);

    // Force commands published on the topic reach the device.
    let wanted = [100, -200, 300, 400, 1000];
    let start = Instant::now();
    loop {
        rig.forces
            .publish(&GloveForceCommand {
                force: wanted,
                ..Default::default()
            })
            .unwrap();
        if rig.sim.device().unwrap().force_set == wanted {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "force never reached the device"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    // ... push the simulated fingers open, which the glove reports back, and the diagnostics
    // (at their low rate) show the measured forces, while the command stays fresh.
    let start = Instant::now();
    let (mut pushed, mut diag) = (None, None);
    while pushed.is_none() || diag.is_none() {
        rig.forces
            .publish(&GloveForceCommand {
                force: wanted,
                ..Default::default()
            })
            .unwrap();
        rig.states.drain(|s| {
            if s.raw_position[3] > 630 {
                pushed = Some(*s);
            }
        });
        if let Some(d) = rig.diagnostics.poll_latest().filter(|d| d.force[3] > 300) {
            diag = Some(d);
        }
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "pushed {pushed:?}, diagnostics {diag:?}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let (pushed, diag) = (pushed.unwrap(), diag.unwrap());
    assert!(
        pushed.raw_position[1] < 600,
        "ring finger pulled towards a fist by -200"
    );
    assert!(
        diag.temperature_c.iter().all(|&t| (25..=80).contains(&t)),
        "{diag:?}"
    );
    assert!(diag.current_ma[3] > diag.current_ma[0]);

    // The command goes stale: the glove gets zero force.
    let start = Instant::now();
    while rig.sim.device().unwrap().force_set != [0; 5] {
        assert!(
            start.elapsed() < Duration::from_secs(2),
            "stale force never zeroed"
        );
        std::thread::sleep(Duration::from_millis(5));
    }

    // Stop: the last thing the glove gets is zero force.
    rig.forces
        .publish(&GloveForceCommand {
            force: wanted,
            ..Default::default()
        })
        .unwrap();
    std::thread::sleep(Duration::from_millis(30));
    for _ in 0..5 {
        rig.forces
            .publish(&GloveForceCommand {
                force: wanted,
                ..Default::default()
            })
            .unwrap();
        std::thread::sleep(Duration::from_millis(10));
    }
    rig.node().stop();
    assert_eq!(
        rig.sim.device().unwrap().force_set,
        [0; 5],
        "zero force on stop"
    );
    assert!(rig.log().contains("sent zero force"), "{}", rig.log());
}

#[test]
fn every_injected_fault_is_survived_counted_and_logged() {
    let mut rig = Rig::new();
    let pid = rig.node().pid();
    for (name, mut faults) in [
        (
            "garbage",
            Faults {
                garbage: 0.3,
                ..Default::default()
            },
        ),
        (
            "drop",
            Faults {
                drop: 0.3,
                ..Default::default()
            },
        ),
        (
            "corrupt",
            Faults {
                corrupt: 0.3,
                ..Default::default()
            },
        ),
        (
            "other-id",
            Faults {
                other_id: 0.3,
                ..Default::default()
            },
        ),
    ] {
        let before = rig
            .collect(Duration::from_millis(50))
            .last()
            .map_or(0, |s| s.errors);
        rig.sim.set_faults(faults);
        let during = rig.collect(Duration::from_millis(800));
        faults = Faults::default();
        rig.sim.set_faults(faults);
        // About 3 ms per exchange, but a dropped answer costs two answer timeouts (60 ms: the
        // link waits one more for a late answer): at drop=0.3 about 16 states in 800 ms.
        assert!(
            during.len() > 8,
            "{name}: states keep flowing ({})",
            during.len()
        );
        assert!(
            during.iter().all(|s| s.link_up == 1),
            "{name}: the link stays up"
        );
        let after = rig.collect(Duration::from_millis(300));
        let errors = after.last().unwrap().errors;
        assert!(errors > before, "{name}: counted ({before} -> {errors})");
        assert!(rig.node_alive(), "{name}: no restart");
        assert_eq!(rig.node().pid(), pid);
    }
    let stats = rig.sim.stats();
    assert!(
        stats.garbage > 0 && stats.dropped > 0 && stats.corrupted > 0 && stats.other_id > 0,
        "{stats:?}"
    );
    let log = rig.log();
    assert!(log.contains("line errors since the last report"), "{log}");
    for field in ["timeouts=", "bad_frames=", "garbage=", "other_id="] {
        assert!(log.contains(field), "{field} in {log}");
    }
    let health = rig.health.poll_latest().unwrap();
    assert!(health.errors > 0, "{health:?}");
}

#[test]
fn a_late_answer_is_discarded_counted_and_logged_without_a_restart() {
    let mut rig = Rig::with_answer_timeout(100);
    let pid = rig.node().pid();
    // Past the node's answer timeout, within the one more timeout the link waits for late
    // answers (the link's own test checks the data after it).
    rig.sim.answer_late(Duration::from_millis(150));
    let start = Instant::now();
    while rig.sim.stats().late == 0 {
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "never answered late"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let states = rig.collect(Duration::from_millis(500));
    assert!(states.len() > 50 && states.iter().all(|s| s.link_up == 1));
    assert!(rig.node_alive());
    assert_eq!(rig.node().pid(), pid);
    let start = Instant::now();
    while !rig.log().contains("late=1") {
        assert!(start.elapsed() < Duration::from_secs(2), "{}", rig.log());
        std::thread::sleep(Duration::from_millis(20));
    }
    let log = rig.log();
    assert!(
        log.contains("timeouts=1") && !log.contains("link down"),
        "{log}"
    );
}

#[test]
fn unplug_and_replug_recover_without_a_restart() {
    let mut rig = Rig::new();
    let pid = rig.node().pid();
    rig.sim.unplug(Duration::from_millis(700));
    rig.wait_until(Duration::from_secs(5), "link down", |s| s.link_up == 0);
    rig.wait_until(Duration::from_secs(10), "link up again", |s| s.link_up == 1);
    let states = rig.collect(Duration::from_millis(500));
    assert!(states.len() > 50 && states.iter().all(|s| s.link_up == 1));
    assert!(rig.node_alive());
    assert_eq!(rig.node().pid(), pid);
    assert_eq!(rig.sim.stats().unplugs, 1);
    let log = rig.log();
    assert!(
        log.contains("link down") && log.contains("port open"),
        "{log}"
    );
}

#[test]
fn a_bad_config_is_refused_with_the_field_named() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("glove.toml");
    std::fs::write(&config, "baud = 9600\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_teleop-glove"))
        .arg("--config")
        .arg(&config)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("glove.toml") && err.contains("baud = 9600"),
        "{err}"
    );
}

#[test]
fn sustained_overload_shows_up_as_actuator_errors() {
    let mut rig = Rig::new();
    let start = Instant::now();
    let diag = loop {
        rig.forces
            .publish(&GloveForceCommand {
                force: [0, 0, 0, 1000, 0],
                ..Default::default()
            })
            .unwrap();
        if let Some(d) = rig
            .diagnostics
            .poll_latest()
            .filter(|d| d.error_bits[3] != 0)
        {
            break d;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "no error bits");
        std::thread::sleep(Duration::from_millis(10));
    };
    // Locked rotor + over-current on the index finger only.
    assert_eq!(diag.error_bits, [0, 0, 0, 0b101, 0]);
    let start = Instant::now();
    while !rig.log().contains("actuator error") {
        assert!(start.elapsed() < Duration::from_secs(2), "{}", rig.log());
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(rig.log().contains("locked"), "{}", rig.log());
}
