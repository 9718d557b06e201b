//! The simulated Shadow Hand session (`launch/shadow.toml`) end to end: the scripted operator's
//! grasp closes the emulated Hand E (two EtherCAT SubDevices behind `teleop-shadow`) on the
//! ball under its middle finger, the middle fingertip's PST reads pressure, the glove's middle
//! finger feels force from it, the recording holds it all, and `teleop reprocess` reproduces the
//! recorded hand commands.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_e2e::{Sandbox, Session};
use teleop_msgs::Message;
use teleop_msgs::{
    contact_source, device_model, link_kind, GloveDiagnostics, GloveForceCommand, GloveState,
    HandCommand, HandState, Tactile,
};
use teleop_runtime::{NodeRuntime, Subscriber};

/// The middle fingertip in the profile's fingertip order (ff, mf, rf, lf, th).
const MF_TIP: usize = 1;
/// The glove's middle finger (little, ring, middle, index, thumb).
const GLOVE_MIDDLE: usize = 2;

struct Watch {
    glove: Subscriber<GloveState>,
    diag: Subscriber<GloveDiagnostics>,
    cmd: Subscriber<HandCommand>,
    state: Subscriber<HandState>,
    tactile: Subscriber<Tactile>,
    force: Subscriber<GloveForceCommand>,
    _node: NodeRuntime,
}

impl Watch {
    fn new(sandbox: &Sandbox) -> Self {
        let node = NodeRuntime::new("shadow-session-test", &sandbox.ipc).unwrap();
        Self {
            glove: node.subscriber().unwrap(),
            diag: node.subscriber().unwrap(),
            cmd: node.subscriber().unwrap(),
            state: node.subscriber().unwrap(),
            tactile: node.subscriber().unwrap(),
            force: node.subscriber().unwrap(),
            _node: node,
        }
    }

    fn fresh<M: teleop_msgs::Message>(s: &Subscriber<M>) -> bool {
        s.is_fresh(Instant::now(), Duration::from_millis(150))
    }

    fn all_fresh(&self) -> bool {
        self.glove.drain(|_| {});
        self.cmd.drain(|_| {});
        self.state.drain(|_| {});
        self.tactile.drain(|_| {});
        self.force.drain(|_| {});
        Self::fresh(&self.glove)
            && Self::fresh(&self.cmd)
            && Self::fresh(&self.state)
            && Self::fresh(&self.tactile)
            && Self::fresh(&self.force)
    }
}

fn wait_running(session: &Session, watch: &Watch) {
    let start = Instant::now();
    while !watch.all_fresh() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "the Shadow session did not start\n{}",
            session.log()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_shadow_session_closes_the_loop_and_reprocesses() {
    let sandbox = Sandbox::new();
    let launch = sandbox.session("launch/shadow.toml");
    let mut session = sandbox.launch(&launch);
    let watch = Watch::new(&sandbox);
    wait_running(&session, &watch);

    let state = watch.state.latest().unwrap();
    assert_eq!(state.hand_model, device_model::SHADOW);
    assert_eq!(state.joint_count, 24);
    assert_eq!(state.link_kind, link_kind::ETHERCAT);
    assert_eq!(state.link_up, 1);

    // The scripted grasp (about 6 s): every finger closes, the ball stops the middle finger and
    // presses its fingertip; the glove's middle finger feels the PST pressure.
    let (mut pressure, mut felt) = ([0i32; 5], 0i16);
    let mut force = [0i16; 5];
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(8) {
        watch.tactile.drain(|t| {
            for (p, tip) in pressure.iter_mut().zip(t.active_fingertips()) {
                *p = (*p).max(tip.pressure);
            }
        });
        watch.force.drain(|f| {
            for (k, &v) in f.force.iter().enumerate() {
                if f.source[k] == contact_source::TACTILE {
                    force[k] = force[k].max(v);
                }
            }
        });
        watch
            .diag
            .drain(|d| felt = d.force.iter().fold(felt, |m, &v| m.max(v)));
        watch.cmd.drain(|_| {});
        watch.state.drain(|_| {});
        std::thread::sleep(Duration::from_millis(5));
    }
    let joints = sandbox.control("teleop-sim-shadow.ctl", "joints");
    eprintln!(
        "PST pressure (ff, mf, rf, lf, th) {pressure:?}; glove force from tactile (little, ring, \
         middle, index, thumb) {force:?}; felt {felt}; joints: {joints}"
    );
    assert!(
        pressure[MF_TIP] > 100,
        "the ball presses the middle fingertip: {pressure:?}; {joints}\n{}",
        session.log()
    );
    assert!(
        force[GLOVE_MIDDLE] > 100,
        "glove middle force from PST: {force:?}"
    );
    assert!(
        2 * force[1].max(force[3]) < force[GLOVE_MIDDLE],
        "the ring and index fingers close on nothing: {force:?}"
    );
    assert!(felt > 50, "the simulated operator feels it: {felt}");

    let status = session.stop();
    assert!(status.success());
    let log = session.log();
    let recording = log
        .lines()
        .find_map(|l| l.strip_prefix("recording: "))
        .expect("the summary says where the recording is");
    let recording = launch.parent().unwrap().join(recording);
    let info = teleop_recording::info(&recording).unwrap();
    assert!(
        info.complete && info.messages > 2_000,
        "{} messages",
        info.messages
    );

    // Replayed: the recorded PST samples come back on hand/tactile, the grasp among them.
    let tactile: Subscriber<Tactile> = watch._node.subscriber().unwrap();
    let mut replay = sandbox
        .teleop()
        .args(["replay", recording.to_str().unwrap(), "--speed", "8"])
        .args(["--topics", Tactile::TOPIC])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let (mut replayed, mut pressed) = (0, 0);
    let start = Instant::now();
    let status = loop {
        tactile.drain(|t| {
            replayed += 1;
            pressed += usize::from(t.fingertips[MF_TIP].pressure > 100);
        });
        if let Some(status) = replay.try_wait().unwrap() {
            break status;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "the replay did not end"
        );
        std::thread::sleep(Duration::from_millis(2));
    };
    tactile.drain(|t| {
        replayed += 1;
        pressed += usize::from(t.fingertips[MF_TIP].pressure > 100);
    });
    assert!(status.success());
    assert!(
        replayed > 1_000 && pressed > 100,
        "replayed {replayed} tactile samples, {pressed} with the middle fingertip pressed"
    );

    let config = sandbox.dir.path().join("config/shadow");
    let out = sandbox.dir.path().join("reprocessed.mcap");
    let r = sandbox.run_teleop(&[
        "reprocess",
        recording.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--retarget-config",
        config.join("retarget.toml").to_str().unwrap(),
        "--feedback-config",
        config.join("feedback.toml").to_str().unwrap(),
    ]);
    let report = String::from_utf8_lossy(&r.stdout);
    assert!(
        r.status.success(),
        "{report}{}",
        String::from_utf8_lossy(&r.stderr)
    );
    let line = report
        .lines()
        .find(|l| l.starts_with("hand/command"))
        .unwrap_or_else(|| panic!("{report}"));
    let differ: u64 = line.split_whitespace().nth(3).unwrap().parse().unwrap();
    assert_eq!(
        differ, 0,
        "reprocess reproduces the hand commands:\n{report}"
    );
}
