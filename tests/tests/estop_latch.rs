//! The latched e-stop and freshness from the sample's stamp, through the real processes: an
//! e-stop survives a `kill -9` of the force-feedback node and reaches a node that was down when
//! it was sent; `teleop estop` lists the nodes that acknowledged it (and fails when none did);
//! only `--release` releases. A glove sample older than the timeout, kept in the topic's history,
//! does not drive the hand after the retargeting node restarts.
#![allow(clippy::unwrap_used)]

use std::process::{Output, Stdio};
use std::time::{Duration, Instant};

use teleop_e2e::{node_process, wait_for, with_profile, Sandbox, Session, FEEDBACK_TOML};
use teleop_msgs::{device_model, force_flags, units, GloveForceCommand, GloveState, HandCommand};
use teleop_msgs::{HandState, NodeHealth, Tactile};
use teleop_runtime::{now_ns, EStopInput, NodeRuntime, Publisher, Subscriber};

/// One node `name` ([`node_process`]), restarted 1.5 s after it dies (long enough to send an
/// e-stop while it is down).
fn launch_one(name: &str) -> String {
    let policy = "restart = \"always\"\nrestart_delay_ms = 1500\nrestart_backoff_max_ms = 1500\n";
    format!(
        "[session]\nstop_timeout_ms = 2000\n{}",
        node_process(name, policy)
    )
}

/// The node `name` (`teleop-<name>`, configured by `config` and the Revo2 profile) alone in the
/// sandbox (`launch_one`): writes its files, returns the launch file.
fn alone(sandbox: &Sandbox, name: &str, config: &str) -> std::path::PathBuf {
    sandbox.write(&format!("{name}.toml"), &with_profile(config));
    sandbox.write("launch.toml", &launch_one(name))
}

/// The feedback node alone in the sandbox ([`feedback_launch`]), running, and the test playing
/// its hand ([`hand_in`]) until the glove's force comes back from the contact.
fn feedback_pushing(sandbox: &Sandbox) -> (Session, NodeRuntime, Hand) {
    let session = sandbox.launch(&feedback_launch(sandbox));
    let (node, mut hand) = hand_in(sandbox, None, "e2e-hand");
    hand.until(Duration::from_secs(20), "glove force from contact", pushing);
    (session, node, hand)
}

/// The feedback node alone in the sandbox ([`alone`]).
fn feedback_launch(sandbox: &Sandbox) -> std::path::PathBuf {
    alone(sandbox, "feedback", FEEDBACK_TOML)
}

/// The test plays the hand: state and tactile with the thumb pressing (10 N: the glove's thumb
/// saturates at 800).
struct Hand {
    state: Publisher<HandState>,
    tactile: Publisher<Tactile>,
    forces: Subscriber<GloveForceCommand>,
}

impl Hand {
    /// For `duration`, every 2 ms: publish the hand; returns the force commands that came back.
    fn pump(&mut self, duration: Duration) -> Vec<GloveForceCommand> {
        let mut forces = Vec::new();
        let start = Instant::now();
        while start.elapsed() < duration {
            self.state
                .publish(&HandState {
                    hand_model: device_model::REVO2,
                    joint_count: 6,
                    link_up: 1,
                    units: units::NORMALISED,
                    ..Default::default()
                })
                .unwrap();
            let mut t = Tactile {
                hand_model: device_model::REVO2,
                fingertip_count: 5,
                ..Default::default()
            };
            t.fingertips[0].normal_n = 10.0;
            self.tactile.publish(&t).unwrap();
            self.forces.drain(|f| forces.push(*f));
            std::thread::sleep(Duration::from_millis(2));
        }
        forces
    }

    /// Pumps for `duration`: force commands come back from `whose` node, every one stopped
    /// (else the test fails saying `failure`).
    fn stays_stopped(&mut self, duration: Duration, whose: &str, failure: &str) {
        let forces = self.pump(duration);
        assert!(!forces.is_empty(), "force commands from {whose}");
        assert!(
            forces.iter().all(stopped),
            "{failure}: {:?}",
            forces.iter().find(|f| !stopped(f))
        );
    }

    /// After the feedback node restarted: drops the killed node's last force commands, then the
    /// restarted node's stay stopped for 700 ms (else the test fails saying `failure`).
    fn restarted_stays_stopped(&mut self, failure: &str) {
        self.forces.drain(|_| {});
        self.stays_stopped(Duration::from_millis(700), "the restarted node", failure);
    }

    /// Pumps until the newest force command satisfies `ok` (panics after `timeout`).
    fn until(&mut self, timeout: Duration, what: &str, ok: impl Fn(&GloveForceCommand) -> bool) {
        wait_for(timeout, what, || {
            self.pump(Duration::from_millis(20))
                .last()
                .is_some_and(&ok)
                .then_some(())
        });
    }
}

fn stopped(f: &GloveForceCommand) -> bool {
    f.force == [0; 5] && f.flags & force_flags::ESTOP != 0
}

fn pushing(f: &GloveForceCommand) -> bool {
    f.force[4] == 800 && f.flags & force_flags::ESTOP == 0
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Runs `teleop estop` with `args`: asserts that it succeeds (or, `succeeds` false, fails) and
/// says each of `says`; returns what it printed.
fn estop(sandbox: &Sandbox, args: &[&str], succeeds: bool, says: &[&str]) -> String {
    let out = sandbox.run_teleop(&[&["estop"], args].concat());
    let said = text(&out);
    assert_eq!(out.status.success(), succeeds, "{said}");
    for words in says {
        assert!(said.contains(words), "{words:?} not said: {said}");
    }
    said
}

/// Starts `teleop estop` with `args` in the background, its output captured.
fn spawn_estop(sandbox: &Sandbox, args: &[&str]) -> std::process::Child {
    sandbox
        .teleop()
        .arg("estop")
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// `teleop estop --release` succeeds saying each of `says`, and `hand`'s forces return.
fn release(sandbox: &Sandbox, hand: &mut Hand, says: &[&str]) {
    estop(sandbox, &["--release"], true, says);
    hand.until(Duration::from_secs(3), "forces after release", pushing);
}

/// Kills `pid` with SIGKILL (no chance to clean up).
fn kill_9(pid: u32) {
    // SAFETY: kill(2) on a pid the test read from the pipeline's node list.
    unsafe {
        libc::kill(pid as libc::pid_t, libc::SIGKILL);
    }
}

/// Waits for the supervisor to have restarted `name`: alive with a pid other than `old`.
fn restarted(sandbox: &Sandbox, name: &str, old: u32) -> u32 {
    wait_for(Duration::from_secs(20), "the restarted node", || {
        sandbox.pid_of(name).filter(|&p| p != old)
    })
}

#[test]
fn estop_latches_through_restarts_is_acknowledged_and_releases_only_on_release() {
    let sandbox = Sandbox::new();
    let (_session, _node, mut hand) = feedback_pushing(&sandbox);

    // Engaged: the CLI names the node that acknowledged; forces zero.
    estop(
        &sandbox,
        &[],
        true,
        &["ENGAGED", "acknowledged by feedback"],
    );
    hand.until(Duration::from_secs(2), "e-stop", stopped);

    // kill -9 the feedback node: the restarted one is still engaged.
    let first = sandbox.pid_of("feedback").unwrap();
    kill_9(first);
    let second = restarted(&sandbox, "feedback", first);
    hand.restarted_stays_stopped("restarted node released the e-stop");

    // Released: forces return.
    release(&sandbox, &mut hand, &["acknowledged by feedback"]);

    // Engaged while the node is down: nobody acknowledges (exit 1, said so), and the node comes
    // back engaged.
    kill_9(second);
    wait_for(Duration::from_secs(5), "the node to be gone", || {
        (sandbox.pid_of("feedback") != Some(second)).then_some(())
    });
    estop(&sandbox, &[], false, &["no node acknowledged"]);
    let third = restarted(&sandbox, "feedback", second);
    assert_ne!(third, first);
    hand.restarted_stays_stopped("the e-stop sent while the node was down was lost");

    // Only --release releases.
    release(&sandbox, &mut hand, &[]);
}

/// A node that reads its doorbell late (starved of the CPU) still takes a release that it reads
/// within the release's wait; one that reads it after the command ended stays engaged (the safe
/// side), and `teleop estop --release` names it and fails instead of reporting the e-stop
/// released because another node answered.
#[test]
fn a_release_waits_for_a_slow_node_and_fails_when_it_does_not_reach_it() {
    let sandbox = Sandbox::new();
    let (_session, _node, mut hand) = feedback_pushing(&sandbox);
    // A second node that obeys the e-stop, run by the test: it reads its doorbell only when the
    // test lets it.
    let slow_node = NodeRuntime::new("e2e-slow", &sandbox.ipc).unwrap();
    let slow = EStopInput::new(&slow_node).unwrap();
    let latch = teleop_runtime::latch_path(&sandbox.ipc, None);
    let said = estop(
        &sandbox,
        &[],
        true,
        &[
            "ENGAGED",
            "acknowledged by feedback; did not answer within 1000 ms: e2e-slow",
        ],
    );
    // It stops all the same, on the latch.
    std::thread::sleep(teleop_runtime::LATCH_POLL);
    slow.update().unwrap();
    assert!(slow.engaged(), "{said}");
    hand.until(Duration::from_secs(2), "e-stop", stopped);

    let spawn_release = || spawn_estop(&sandbox, &["--release"]);
    let latch_removed = || {
        wait_for(
            Duration::from_secs(10),
            "the release to remove the latch",
            || (!latch.exists()).then_some(()),
        )
    };
    // Read 2 s after the release rang (it used to wait 1 s): the release waits for it.
    let release = spawn_release();
    latch_removed();
    std::thread::sleep(Duration::from_secs(2));
    slow.update().unwrap();
    assert!(!slow.engaged(), "the slow node took the release");
    let out = release.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        text(&out).contains("acknowledged by e2e-slow, feedback"),
        "{}",
        text(&out)
    );
    hand.until(Duration::from_secs(3), "forces after release", pushing);

    // Read after the release's whole wait: not released, and said so.
    estop(&sandbox, &[], true, &["ENGAGED"]);
    std::thread::sleep(teleop_runtime::LATCH_POLL);
    slow.update().unwrap();
    assert!(slow.engaged());
    hand.until(Duration::from_secs(2), "e-stop", stopped);
    estop(
        &sandbox,
        &["--release"],
        false,
        &[
            "NOT released by every node",
            "acknowledged by feedback; did not answer within 5000 ms: e2e-slow",
            "did not reach 1 node(s)",
            "run `teleop estop --release` again",
        ],
    );
    slow.update().unwrap();
    assert!(
        slow.engaged(),
        "a node that missed the release's doorbell released on its own"
    );
    // Another release reaches it.
    let release = spawn_release();
    wait_for(Duration::from_secs(4), "the slow node released", || {
        slow.update().unwrap();
        (!slow.engaged()).then_some(())
    });
    let out = release.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", text(&out));
}

/// A release of one namespace reaches its node, but the plain latch (an e-stop of every side)
/// still holds it: the node answers still engaged, and `teleop estop --release --namespace`
/// says so and how to release it, instead of telling the operator to run the same release
/// again.
#[test]
fn a_namespaced_release_names_a_node_the_plain_latch_still_holds() {
    let sandbox = Sandbox::new();
    let mut ipc = sandbox.ipc.clone();
    ipc.namespace = Some("left".to_string());
    let left_node = NodeRuntime::new("e2e-left", &ipc).unwrap();
    let left = EStopInput::new(&left_node).unwrap();
    // Nobody answers the engage here (the node reads only when the test lets it): exit 1,
    // engaged all the same.
    estop(
        &sandbox,
        &[],
        false,
        &[
            "ENGAGED (latched)",
            "did not answer within 1000 ms: left/e2e-left",
            "though 1 obey it",
        ],
    );
    wait_for(Duration::from_secs(5), "the left node engaged", || {
        left.update().unwrap();
        left.engaged().then_some(())
    });
    let release = spawn_estop(&sandbox, &["--release", "--namespace", "left"]);
    // The node reads every doorbell while the release waits.
    let mut release = Some(release);
    let mut out = None;
    wait_for(Duration::from_secs(15), "the release to end", || {
        left.update().unwrap();
        let child = release.as_mut()?;
        if child.try_wait().unwrap().is_some() {
            out = Some(release.take()?.wait_with_output().unwrap());
            return Some(());
        }
        std::thread::sleep(Duration::from_millis(5));
        None
    });
    let out = out.unwrap();
    let said = text(&out);
    assert!(!out.status.success(), "{said}");
    for words in [
        "NOT released by every node",
        "answered still engaged: left/e2e-left",
        "release without `--namespace`",
    ] {
        assert!(said.contains(words), "{words:?} not said: {said}");
    }
    assert!(left.engaged(), "the plain latch holds it");
    // Without the namespace the release removes the plain latch too.
    let release = spawn_estop(&sandbox, &["--release"]);
    wait_for(Duration::from_secs(5), "the left node released", || {
        left.update().unwrap();
        (!left.engaged()).then_some(())
    });
    let out = release.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", text(&out));
}

const RETARGET_TOML: &str = r#"
glove_timeout_ms = 100
"#;

#[test]
fn a_glove_sample_older_than_the_timeout_does_not_drive_the_hand_after_a_restart() {
    let sandbox = Sandbox::new();
    let launch = alone(&sandbox, "retarget", RETARGET_TOML);
    let _session = sandbox.launch(&launch);
    let node = NodeRuntime::new("e2e-glove", &sandbox.ipc).unwrap();
    let mut glove: Publisher<GloveState> = node.publisher().unwrap();
    let commands: Subscriber<HandCommand> = node.subscriber().unwrap();
    let health: Subscriber<NodeHealth> = node.subscriber().unwrap();
    let sample = |raw: [u16; 6], link_up: u8| GloveState {
        raw_position: raw,
        position: raw.map(|r| f32::from(r) / 1000.0),
        link_up,
        glove_id: 1,
        ..Default::default()
    };
    // The operator's hand, open: the retargeting node follows it.
    wait_for(Duration::from_secs(20), "a hand command", || {
        glove.publish(&sample([1000; 6], 1)).unwrap();
        std::thread::sleep(Duration::from_millis(10));
        commands.poll_latest()
    });
    // The last glove sample (kept in the topic's history) grows old; the node restarts.
    std::thread::sleep(Duration::from_millis(300));
    let old = sandbox.pid_of("retarget").unwrap();
    kill_9(old);
    let killed_at = now_ns();
    restarted(&sandbox, "retarget", old);
    // Its first health report: its glove subscriber exists (made before its health port), so
    // the next glove sample brings it the historical one first.
    wait_for(
        Duration::from_secs(10),
        "the restarted node's health",
        || {
            let mut seen = None;
            health.drain(|h| {
                if h.name() == "retarget" && h.header.stamp_ns > killed_at {
                    seen = Some(());
                }
            });
            seen
        },
    );
    commands.drain(|_| {});
    // Wake the restarted node with a glove whose link is down (no pose of its own): the only
    // pose it could follow is the historical one.
    let start = Instant::now();
    let mut followed = Vec::new();
    while start.elapsed() < Duration::from_millis(600) {
        glove.publish(&sample([0; 6], 0)).unwrap();
        commands.drain(|c| followed.push(*c));
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(
        followed.is_empty(),
        "the restarted node followed a glove sample made before its timeout: {:?}",
        followed.first()
    );
}

#[test]
fn in_the_simulated_session_the_hand_holds_and_the_glove_goes_limp_until_release() {
    let sandbox = Sandbox::new();
    let launch = sandbox.default_session(|t| t);
    let session = sandbox.launch(&launch);
    let node = NodeRuntime::new("e2e-watch", &sandbox.ipc).unwrap();
    let state: Subscriber<HandState> = node.subscriber().unwrap();
    let commands: Subscriber<HandCommand> = node.subscriber().unwrap();
    let forces: Subscriber<GloveForceCommand> = node.subscriber().unwrap();
    let fresh = Duration::from_millis(150);
    let until = |what: &str, ok: &dyn Fn() -> bool| {
        let start = Instant::now();
        while !ok() {
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "timed out waiting for {what}\n{}",
                session.log()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    let following = || {
        commands.drain(|_| {});
        state.drain(|_| {});
        commands.is_fresh(Instant::now(), fresh)
            && state
                .latest()
                .is_some_and(|s| s.link_up == 1 && s.holding == 0)
    };
    until("the hand following the glove", &following);

    estop(
        &sandbox,
        &[],
        true,
        &["acknowledged by feedback, glove, revo2"],
    );
    // The glove still drives fresh commands, but the hand holds and the glove force is zero.
    until("the hand holding under the e-stop", &|| {
        commands.drain(|_| {});
        state.drain(|_| {});
        forces.drain(|_| {});
        commands.is_fresh(Instant::now(), fresh)
            && state
                .latest()
                .is_some_and(|s| s.link_up == 1 && s.holding == 1)
            && forces.latest().is_some_and(|f| stopped(&f))
    });
    estop(&sandbox, &["--release"], true, &[]);
    until("the hand following again", &following);
    forces.drain(|_| {});
    assert_eq!(
        forces.latest().unwrap().flags & force_flags::ESTOP,
        0,
        "glove force released"
    );
}

#[test]
fn a_replayed_glove_drives_the_hand_its_stamps_moved_to_the_replay() {
    let sandbox = Sandbox::new();
    let launch = alone(&sandbox, "retarget", RETARGET_TOML);
    let _session = sandbox.launch(&launch);
    let node = NodeRuntime::new("e2e-glove", &sandbox.ipc).unwrap();
    let commands: Subscriber<HandCommand> = node.subscriber().unwrap();
    let mut glove: Publisher<GloveState> = node.publisher().unwrap();
    let sample = GloveState {
        raw_position: [1000; 6],
        position: [1.0; 6],
        link_up: 1,
        glove_id: 1,
        ..Default::default()
    };
    wait_for(Duration::from_secs(20), "a hand command", || {
        glove.publish(&sample).unwrap();
        std::thread::sleep(Duration::from_millis(10));
        commands.poll_latest()
    });
    // Record the glove for a second, on this machine's clock.
    let rec = sandbox.dir.path().join("glove.mcap");
    let mut recorder = sandbox
        .teleop()
        .args([
            "record",
            "--topics",
            "glove/state",
            "--duration",
            "1",
            "--out",
        ])
        .arg(&rec)
        .spawn()
        .unwrap();
    let status = wait_for(Duration::from_secs(20), "the recording", || {
        glove.publish(&sample).unwrap();
        std::thread::sleep(Duration::from_millis(5));
        recorder.try_wait().unwrap()
    });
    assert!(status.success());
    drop(glove);
    // The recorded samples are now older than the glove timeout; replayed, they are made again.
    std::thread::sleep(Duration::from_millis(500));
    commands.drain(|_| {});
    let out = sandbox.run_teleop(&["replay", rec.to_str().unwrap(), "--topics", "glove/state"]);
    assert!(out.status.success(), "{}", text(&out));
    let mut followed = Vec::new();
    commands.drain(|c| followed.push(*c));
    let live: Vec<_> = followed
        .iter()
        .filter(|c| c.flags & teleop_msgs::command_flags::HELD == 0)
        .collect();
    assert!(
        live.len() > 50,
        "{} of {} commands followed the replay",
        live.len(),
        followed.len()
    );
    // The recorded latency is kept: the glove samples' origin moved with their stamp.
    assert!(live.iter().all(|c| c.header.stamp_ns >= c.header.origin_ns
        && c.header.stamp_ns - c.header.origin_ns < 1_000_000_000));
}

#[test]
fn release_without_namespace_releases_a_side_latched_while_its_nodes_are_down() {
    let sandbox = Sandbox::new();
    let latch = teleop_runtime::latch_path(
        &sandbox.ipc,
        Some(&teleop_runtime::Namespace::new("left").unwrap()),
    );
    // Nothing runs: engaged all the same, said so, exit 1.
    estop(
        &sandbox,
        &["--namespace", "left"],
        false,
        &["no node acknowledged"],
    );
    assert!(latch.exists(), "{}", latch.display());
    // No namespace is in use, but the left side is latched: released with the others.
    let out = sandbox.run_teleop(&["estop", "--release"]);
    assert!(text(&out).contains("namespace left"), "{}", text(&out));
    assert!(!latch.exists(), "{}", text(&out));
}

/// A hand in namespace `ns` (or none) of the sandbox's pipeline.
fn hand_in(sandbox: &Sandbox, ns: Option<&str>, name: &str) -> (NodeRuntime, Hand) {
    let mut ipc = sandbox.ipc.clone();
    ipc.namespace = ns.map(str::to_string);
    let node = NodeRuntime::new(name, &ipc).unwrap();
    let hand = Hand {
        state: node.publisher().unwrap(),
        tactile: node.publisher().unwrap(),
        forces: node.subscriber().unwrap(),
    };
    (node, hand)
}

/// Whether this test may mount file systems and change file attributes (root), else the
/// reason; under `TELEOP_REQUIRE_CHECKS` (CI, as root) a test that cannot fails instead.
fn root_or_skip() -> bool {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } == 0 {
        return true;
    }
    teleop_e2e::netns::skip("not running as root (mounts a small tmpfs / sets chattr +i)");
    false
}

/// Runs `program args`, panicking with its output when it fails.
fn run(program: &str, args: &[&str]) {
    let out = std::process::Command::new(program)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{program}: {e}"));
    assert!(out.status.success(), "{program} {args:?}: {}", text(&out));
}

/// A mounted tmpfs of `size` (unmounted on drop).
struct Tmpfs(std::path::PathBuf);

impl Tmpfs {
    fn mount(at: std::path::PathBuf, size: &str) -> Self {
        std::fs::create_dir_all(&at).unwrap();
        run(
            "mount",
            &[
                "-t",
                "tmpfs",
                "-o",
                &format!("size={size},mode=0755"),
                "tmpfs",
                at.to_str().unwrap(),
            ],
        );
        Self(at)
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg("-l")
            .arg(&self.0)
            .status();
    }
}

#[test]
fn estop_with_a_full_ipc_root_still_stops_the_running_nodes() {
    if !root_or_skip() {
        return;
    }
    let mut sandbox = Sandbox::new();
    let mount = Tmpfs::mount(sandbox.dir.path().join("ipcfs"), "16m");
    sandbox.ipc = teleop_runtime::IpcSettings::isolated(&mount.0);
    let (session, _node, mut hand) = feedback_pushing(&sandbox);

    // The disk of the IPC root fills up: `teleop estop` cannot make its iceoryx2 node.
    let fill = mount.0.join("fill");
    let _ = std::fs::write(&fill, vec![0u8; 32 << 20]);
    estop(
        &sandbox,
        &[],
        false,
        &["cannot ring any doorbell", "ENGAGED"],
    );
    // The latch alone stops the running node.
    hand.until(
        Duration::from_secs(2),
        "e-stop through the latch alone",
        stopped,
    );
    std::fs::remove_file(&fill).unwrap();
    release(&sandbox, &mut hand, &[]);
    drop(session);
}

#[test]
fn estop_with_an_unwritable_latch_still_rings_every_doorbell() {
    if !root_or_skip() {
        return;
    }
    let sandbox = Sandbox::new();
    let (_session, _node, mut hand) = feedback_pushing(&sandbox);

    // No file can be made in the IPC root any more (iceoryx2's own files live in folders below
    // it, so its ports still work): the latch cannot be written.
    let root = sandbox.ipc.root.clone().unwrap();
    run("chattr", &["+i", &root]);
    struct Mutable(String);
    impl Drop for Mutable {
        fn drop(&mut self) {
            let _ = std::process::Command::new("chattr")
                .args(["-i", &self.0])
                .status();
        }
    }
    let mutable = Mutable(root);
    estop(&sandbox, &[], false, &["cannot write the e-stop latch"]);
    hand.until(
        Duration::from_secs(2),
        "e-stop through the doorbell alone",
        stopped,
    );
    drop(mutable);
    release(&sandbox, &mut hand, &[]);
}

#[test]
fn an_estop_engaged_while_nothing_runs_stops_both_sides_of_a_session_started_later() {
    let sandbox = Sandbox::new();
    sandbox.write("feedback.toml", &with_profile(FEEDBACK_TOML));
    // Nothing runs: engaged all the same (exit 1: nobody acknowledged).
    let said = estop(&sandbox, &[], false, &[]);
    let side = |ns: &str| {
        format!(
            "\n[[process]]\nname = \"feedback-{ns}\"\nnode = \"feedback\"\nprogram = \"teleop-feedback\"\nnamespace = \"{ns}\"\nargs = [\"--config\", \"feedback.toml\"]\n"
        )
    };
    let launch = sandbox.write(
        "launch.toml",
        &format!(
            "[session]\nstop_timeout_ms = 2000\n{}{}",
            side("left"),
            side("right")
        ),
    );
    let _session = sandbox.launch(&launch);
    let (_l, mut left) = hand_in(&sandbox, Some("left"), "e2e-left");
    let (_r, mut right) = hand_in(&sandbox, Some("right"), "e2e-right");
    left.until(Duration::from_secs(20), "the left side's forces", |_| true);
    right.until(Duration::from_secs(20), "the right side's forces", |_| true);
    for (name, hand) in [("left", &mut left), ("right", &mut right)] {
        hand.stays_stopped(
            Duration::from_millis(500),
            &format!("the {name} side"),
            &format!("{name} side pushes under the e-stop engaged before it started"),
        );
    }
    assert!(said.contains("in any namespace, will obey it"), "{said}");
    estop(&sandbox, &["--release"], true, &[]);
    left.until(Duration::from_secs(3), "left forces after release", pushing);
    right.until(
        Duration::from_secs(3),
        "right forces after release",
        pushing,
    );
}

#[test]
fn the_glove_node_obeys_the_estop_itself() {
    let sandbox = Sandbox::new();
    let link = sandbox.dir.path().join("glove");
    let glove_toml = std::fs::read_to_string(Sandbox::repo().join("config/glove.toml"))
        .unwrap()
        .replace("/tmp/teleop-glove", link.to_str().unwrap());
    sandbox.write("glove.toml", &glove_toml);
    let launch = sandbox.write(
        "launch.toml",
        &format!(
            "[session]\nstop_timeout_ms = 2000\n\n[[process]]\nname = \"sim-glove\"\nprogram = \"teleop-sim-glove\"\nargs = [\"--link\", {link:?}, \"--control\", \"glove.ctl\"]\nnode = \"\"\n\n[[process]]\nname = \"glove\"\nprogram = \"teleop-glove\"\nargs = [\"--config\", \"glove.toml\"]\n",
            link = link.display().to_string()
        ),
    );
    let session = sandbox.launch(&launch);
    wait_for(
        Duration::from_secs(20),
        "the simulator's control socket",
        || sandbox.dir.path().join("glove.ctl").exists().then_some(()),
    );
    let node = NodeRuntime::new("e2e-forces", &sandbox.ipc).unwrap();
    // The only writer of glove/force_command here (force feedback is not running): a tool that
    // ignores the e-stop.
    let mut forces: Publisher<GloveForceCommand> = node.publisher().unwrap();
    let force_set = |sandbox: &Sandbox| {
        let reply = sandbox.control("glove.ctl", "state");
        reply
            .split("force_set=[")
            .nth(1)
            .and_then(|r| r.split(']').next())
            .map(str::to_string)
    };
    let push = |forces: &mut Publisher<GloveForceCommand>| {
        forces
            .publish(&GloveForceCommand {
                force: [600; 5],
                ..Default::default()
            })
            .unwrap();
        std::thread::sleep(Duration::from_millis(5));
    };
    let push_until = |forces: &mut Publisher<GloveForceCommand>, want: &str, what: &str| {
        wait_for(Duration::from_secs(20), what, || {
            push(forces);
            (force_set(&sandbox).as_deref() == Some(want)).then_some(())
        })
    };
    push_until(&mut forces, "600, 600, 600, 600, 600", "the glove pushing");
    let out = sandbox.run_teleop(&["estop"]);
    assert!(out.status.success(), "{}\n{}", text(&out), session.log());
    assert!(
        text(&out).contains("acknowledged by glove"),
        "{}",
        text(&out)
    );
    push_until(
        &mut forces,
        "0, 0, 0, 0, 0",
        "the glove limp under the e-stop",
    );
    // It stays limp while the tool goes on pushing.
    for _ in 0..100 {
        push(&mut forces);
    }
    assert_eq!(force_set(&sandbox).as_deref(), Some("0, 0, 0, 0, 0"));
    estop(&sandbox, &["--release"], true, &[]);
    push_until(
        &mut forces,
        "600, 600, 600, 600, 600",
        "the glove pushing after release",
    );
}

#[test]
fn a_second_session_on_one_prefix_is_refused_with_the_first_ones_pid() {
    let sandbox = Sandbox::new();
    let launch = feedback_launch(&sandbox);
    let first = sandbox.launch(&launch);
    wait_for(Duration::from_secs(20), "the first session", || {
        sandbox.pid_of("feedback")
    });
    let out = sandbox
        .teleop()
        .arg("launch")
        .arg(&launch)
        .arg("--duration")
        .arg("3")
        .output()
        .unwrap();
    assert!(!out.status.success(), "{}", text(&out));
    assert!(
        text(&out).contains("another session runs on IPC prefix") && text(&out).contains("(pid "),
        "{}",
        text(&out)
    );
    drop(first);
}

#[test]
fn an_exit_the_launcher_did_not_ask_for_is_restarted_and_a_required_one_left_stopped_fails() {
    let sandbox = Sandbox::new();
    sandbox.write("feedback.toml", &with_profile(FEEDBACK_TOML));
    let one = |restart: &str| {
        format!(
            "[session]\nstop_timeout_ms = 2000\n\n[[process]]\nname = \"feedback\"\nprogram = \"teleop-feedback\"\nargs = [\"--config\", \"feedback.toml\"]\nrestart = \"{restart}\"\nrestart_delay_ms = 200\nrequired = true\n"
        )
    };
    let term = |pid: u32| {
        // SAFETY: kill(2) on a pid read from the pipeline's node list.
        unsafe {
            libc::kill(pid as libc::pid_t, libc::SIGTERM);
        }
    };
    // on-failure: a clean exit on someone else's SIGTERM is restarted.
    let launch = sandbox.write("on-failure.toml", &one("on-failure"));
    let mut session = sandbox.launch(&launch);
    let first = wait_for(Duration::from_secs(20), "feedback", || {
        sandbox.pid_of("feedback")
    });
    term(first);
    restarted(&sandbox, "feedback", first);
    assert!(session
        .log()
        .contains("exited without being asked to: exit status 0"));
    assert!(session.stop().success());

    // never + required: the session ends failed and says what is missing.
    let launch = sandbox.write("never.toml", &one("never"));
    let mut session = sandbox.launch(&launch);
    let pid = wait_for(Duration::from_secs(20), "feedback", || {
        sandbox.pid_of("feedback")
    });
    term(pid);
    let status = session
        .wait_exit(Duration::from_secs(20))
        .expect("the session ends");
    assert!(!status.success(), "{}", session.log());
    assert!(
        session
            .log()
            .contains("MISSING required process feedback: exited by itself (exit status 0)"),
        "{}",
        session.log()
    );
}

#[test]
fn zero_timeouts_are_refused_when_a_node_loads_its_configuration() {
    let sandbox = Sandbox::new();
    for (program, file, contents, field) in [
        (
            "teleop-feedback",
            "feedback.toml",
            with_profile(&FEEDBACK_TOML.replace("tick_ms = 10", "tick_ms = 0")),
            "tick_ms = 0",
        ),
        (
            "teleop-glove",
            "glove.toml",
            "force_timeout_ms = 0\n".to_string(),
            "force_timeout_ms = 0",
        ),
    ] {
        let path = sandbox.write(file, &contents);
        let mut child = std::process::Command::new(teleop_e2e::bin(program))
            .arg("--config")
            .arg(&path)
            .envs(sandbox.ipc.to_env())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while child.try_wait().unwrap().is_none() && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(20));
        }
        let refused = child.try_wait().unwrap();
        let _ = child.kill();
        let out = child.wait_with_output().unwrap();
        assert!(
            refused.is_some_and(|s| !s.success()),
            "{program} ran with {field}: {}",
            text(&out)
        );
        assert!(text(&out).contains(field), "{program}: {}", text(&out));
    }
}
