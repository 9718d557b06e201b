//! The backbone end to end: `teleop launch` starts the retargeting and force-feedback processes
//! from a launch file; this test process plays the glove and the hand over the real topics and
//! checks what comes back.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_e2e::{node_process, wait_for, with_profile, Sandbox, FEEDBACK_TOML};
use teleop_msgs::{
    command_flags, contact_source, device_model, force_flags, units, GloveForceCommand, GloveState,
    HandCommand, HandState, Tactile,
};
use teleop_runtime::{NodeRuntime, Publisher, Subscriber};

// Mode `joint`: these tests check the glove map's values end to end (the fingertip modes have
// their own tests in teleop-retarget and the hand sessions).
const RETARGET_TOML: &str = r#"
glove_timeout_ms = 100
[retarget]
mode = "joint"
max_speed = 5.0
[retarget.joints.index]
max = 0.6
"#;

fn launch_toml(restart: &str) -> String {
    let policy = format!("restart = \"{restart}\"\nrestart_delay_ms = 100\n");
    format!(
        "[session]\nstop_timeout_ms = 2000\n{}{}",
        node_process("feedback", &policy),
        node_process("retarget", &policy)
    )
}

/// The test's side of the pipeline: it plays the glove and the hand.
struct Rig {
    glove: Publisher<GloveState>,
    tactile: Publisher<Tactile>,
    state: Publisher<HandState>,
    commands: Subscriber<HandCommand>,
    forces: Subscriber<GloveForceCommand>,
}

impl Rig {
    fn new(node: &NodeRuntime) -> Self {
        Self {
            glove: node.publisher().unwrap(),
            tactile: node.publisher().unwrap(),
            state: node.publisher().unwrap(),
            commands: node.subscriber().unwrap(),
            forces: node.subscriber().unwrap(),
        }
    }

    /// For `duration`, every 2 ms: publish the glove (if given) and the hand's state and tactile
    /// (if given); collect every hand command and force command that comes back.
    fn pump(
        &mut self,
        duration: Duration,
        glove: Option<[u16; 6]>,
        tactile: Option<[f32; 5]>,
    ) -> (Vec<HandCommand>, Vec<GloveForceCommand>) {
        let (mut cmds, mut forces) = (Vec::new(), Vec::new());
        let start = Instant::now();
        while start.elapsed() < duration {
            if let Some(raw) = glove {
                let mut s = GloveState {
                    raw_position: raw,
                    link_up: 1,
                    glove_id: 1,
                    ..Default::default()
                };
                s.position = raw.map(|r| f32::from(r) / 1000.0);
                self.glove.publish(&s).unwrap();
            }
            if let Some(normals) = tactile {
                let mut state = HandState {
                    hand_model: device_model::REVO2,
                    joint_count: 6,
                    link_up: 1,
                    link_kind: teleop_msgs::link_kind::ETHERCAT,
                    bus_state: teleop_msgs::bus_state::AL_OP,
                    units: units::NORMALISED,
                    ..Default::default()
                };
                state.joints[0].position = 0.2;
                self.state.publish(&state).unwrap();
                let mut t = Tactile {
                    hand_model: device_model::REVO2,
                    fingertip_count: 5,
                    ..Default::default()
                };
                for (tip, n) in t.fingertips.iter_mut().zip(normals) {
                    tip.normal_n = n;
                }
                self.tactile.publish(&t).unwrap();
            }
            self.commands.drain(|c| cmds.push(*c));
            self.forces.drain(|f| forces.push(*f));
            std::thread::sleep(Duration::from_millis(2));
        }
        (cmds, forces)
    }
}

fn targets(cmd: &HandCommand) -> Vec<f32> {
    cmd.active_joints().iter().map(|j| j.target).collect()
}

fn assert_close(actual: &[f32], expected: &[f32], tol: f32) {
    assert_eq!(actual.len(), expected.len());
    for (i, (a, e)) in actual.iter().zip(expected).enumerate() {
        assert!(
            (a - e).abs() <= tol,
            "joint {i}: {a} vs {e} (all: {actual:?})"
        );
    }
}

#[test]
fn launch_runs_retargeting_and_force_feedback_end_to_end() {
    let sandbox = Sandbox::new();
    sandbox.write("retarget.toml", &with_profile(RETARGET_TOML));
    sandbox.write("feedback.toml", &with_profile(FEEDBACK_TOML));
    let launch = sandbox.write("launch.toml", &launch_toml("on-failure"));
    let mut session = sandbox.launch(&launch);
    let node = NodeRuntime::new("e2e-rig", &sandbox.ipc).unwrap();
    let mut rig = Rig::new(&node);

    // Glove order: little, ring, middle, index, thumb, thumb rotation (0 = bent / innermost).
    let raw = [1000, 750, 500, 250, 0, 200];
    wait_for(Duration::from_secs(20), "the first hand command", || {
        let (cmds, _) = rig.pump(Duration::from_millis(20), Some(raw), None);
        cmds.last().copied()
    });
    let (cmds, _) = rig.pump(Duration::from_millis(1000), Some(raw), None);
    let last = *cmds.last().expect("hand commands while the glove is live");
    assert!(
        cmds.len() > 100,
        "one command per glove sample, got {}",
        cmds.len()
    );
    assert_eq!(last.hand_model, device_model::REVO2);
    assert_eq!(last.units, units::NORMALISED);
    // Revo2 order: thumb flex, thumb abduct, index, middle, ring, pinky; index clamped to 0.6.
    assert_close(&targets(&last), &[1.0, 0.8, 0.6, 0.5, 0.25, 0.0], 0.02);
    assert_ne!(last.flags & command_flags::CLAMPED, 0, "index was clamped");
    assert_eq!(last.flags & command_flags::HELD, 0);
    assert!(last.header.origin_ns > 0 && last.header.stamp_ns >= last.header.origin_ns);

    // The glove goes quiet: the hand holds the last targets, flagged, and never drifts.
    let (held, _) = rig.pump(Duration::from_millis(400), None, None);
    let held: Vec<_> = held
        .iter()
        .filter(|c| c.flags & command_flags::HELD != 0)
        .collect();
    assert!(!held.is_empty(), "held commands after the glove timeout");
    for c in &held {
        assert_eq!(targets(c), targets(&last), "held command drifted");
    }

    // Contact: index fingertip 2.3 N -> (2.3 - 0.3) * 250 = 500 on the glove's index; the
    // thumb's 10 N saturates at max_force 800.
    let tactile = [10.0, 2.3, 0.0, 0.0, 0.0];
    let (_, forces) = rig.pump(Duration::from_millis(800), Some(raw), Some(tactile));
    let f = forces.last().expect("force commands while tactile is live");
    // Glove order: little, ring, middle, index, thumb.
    assert_eq!(f.force[..3], [0, 0, 0]);
    assert!(
        (i32::from(f.force[3]) - 500).abs() <= 5,
        "index force {:?}",
        f.force
    );
    assert_eq!(f.force[4], 800, "thumb saturates at max_force");
    assert_ne!(f.flags & force_flags::CLAMPED, 0);
    assert_eq!(f.source[3], contact_source::TACTILE);
    assert_eq!(f.source[0], contact_source::NONE);

    // E-stop through the CLI: every force zero at once, while contact persists.
    let out = sandbox.run_teleop(&["estop"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, forces) = rig.pump(Duration::from_millis(300), Some(raw), Some(tactile));
    let f = forces.last().unwrap();
    assert_eq!(f.force, [0; 5]);
    assert_ne!(f.flags & force_flags::ESTOP, 0);
    assert_eq!(f.source, [contact_source::ESTOP; 5]);
    let out = sandbox.run_teleop(&["estop", "--release"]);
    assert!(out.status.success());
    let (_, forces) = rig.pump(Duration::from_millis(500), Some(raw), Some(tactile));
    assert_eq!(
        forces.last().unwrap().force[4],
        800,
        "forces return after release"
    );

    // Tactile and hand state go stale: the force ramps down (not a jump) to zero.
    let (_, forces) = rig.pump(Duration::from_millis(800), Some(raw), None);
    let thumb: Vec<i16> = forces.iter().map(|f| f.force[4]).collect();
    assert_eq!(*thumb.last().unwrap(), 0, "force reaches zero");
    assert!(
        thumb.iter().any(|&v| v > 0 && v < 800),
        "ramped through intermediate values: {thumb:?}"
    );
    assert_ne!(forces.last().unwrap().flags & force_flags::STALE, 0);

    // The inspection commands see the running pipeline.
    let nodes = String::from_utf8(sandbox.run_teleop(&["nodes"]).stdout).unwrap();
    for name in ["retarget", "feedback"] {
        assert!(
            nodes
                .lines()
                .any(|l| l.starts_with(name) && l.contains("alive")),
            "{name} not alive in:\n{nodes}"
        );
    }
    let topics = String::from_utf8(sandbox.run_teleop(&["topics"]).stdout).unwrap();
    assert!(topics.contains("hand/command") && topics.contains("teleop_msgs/msg/HandCommand"));
    // A Revo2 command, its joints named by the Revo2 profile.
    let echo = sandbox.run_teleop(&["echo", "hand/command", "-n", "1"]);
    let echo = String::from_utf8_lossy(&echo.stdout);
    assert!(
        echo.contains("thumb_abduct:") && echo.contains("pinky:"),
        "{echo}"
    );

    let status = session.stop();
    assert!(status.success(), "clean stop on Ctrl-C: {status:?}");
    let log = session.log();
    assert!(
        log.contains("retarget |") && log.contains("feedback |"),
        "tagged logs"
    );
    let stop_retarget = log.find("stopped: exit status 0 process=retarget").unwrap();
    let stop_feedback = log.find("stopped: exit status 0 process=feedback").unwrap();
    assert!(
        stop_retarget < stop_feedback,
        "stopped in reverse start order"
    );
}

#[test]
fn a_killed_process_is_restarted_and_the_pipeline_resumes() {
    let sandbox = Sandbox::new();
    sandbox.write("retarget.toml", &with_profile(RETARGET_TOML));
    sandbox.write("feedback.toml", &with_profile(FEEDBACK_TOML));
    let launch = sandbox.write("launch.toml", &launch_toml("on-failure"));
    let _session = sandbox.launch(&launch);
    let node = NodeRuntime::new("e2e-rig", &sandbox.ipc).unwrap();
    let mut rig = Rig::new(&node);
    let raw = [500; 6];
    wait_for(Duration::from_secs(20), "the first hand command", || {
        rig.pump(Duration::from_millis(20), Some(raw), None)
            .0
            .last()
            .copied()
    });
    let pid_of = |name: &str| -> Option<u32> {
        let out = String::from_utf8(sandbox.run_teleop(&["nodes"]).stdout).unwrap();
        out.lines()
            .find(|l| l.starts_with(name) && l.contains("alive"))
            .and_then(|l| l.split_whitespace().nth(2)?.parse().ok())
    };
    let old = wait_for(Duration::from_secs(5), "retarget's pid", || {
        pid_of("retarget")
    });
    // SAFETY: plain kill(2) of the retargeting process.
    unsafe {
        libc::kill(old as libc::pid_t, libc::SIGKILL);
    }
    let new = wait_for(Duration::from_secs(10), "a restarted retarget", || {
        pid_of("retarget").filter(|&p| p != old)
    });
    assert_ne!(new, old);
    wait_for(
        Duration::from_secs(10),
        "hand commands from the new process",
        || {
            let (cmds, _) = rig.pump(Duration::from_millis(20), Some(raw), None);
            cmds.iter()
                .find(|c| c.header.source_id == teleop_msgs::source_id("retarget"))
                .copied()
        },
    );
}

#[test]
fn a_required_process_that_fails_stops_the_session_with_failure() {
    let sandbox = Sandbox::new();
    let launch = sandbox.write(
        "launch.toml",
        r#"
[[process]]
name = "broken"
program = "teleop-retarget"
args = ["--config", "missing.toml"]
restart = "on-failure"
max_restarts = 1
restart_delay_ms = 50
"#,
    );
    let mut session = sandbox.launch(&launch);
    let status = session
        .wait_exit(Duration::from_secs(20))
        .expect("launcher exits by itself");
    assert!(!status.success());
    let log = session.log();
    assert!(
        log.contains("missing.toml: cannot read"),
        "the node names the file:\n{log}"
    );
    assert!(log.contains("restart 1/1"), "{log}");
    assert!(
        log.contains("required process broken exited (exit status 1)"),
        "{log}"
    );
}

#[test]
fn a_malformed_launch_file_is_refused_before_anything_starts() {
    let sandbox = Sandbox::new();
    let launch = sandbox.write(
        "launch.toml",
        "[[process]]\nname = \"retarget\"\nprogram = \"teleop-retarget\"\nrestart = \"sometimes\"\n",
    );
    let out = sandbox.run_teleop(&["launch", launch.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("launch.toml") && err.contains("line 4") && err.contains("restart"),
        "{err}"
    );
    assert!(!err.contains("started"), "nothing may start: {err}");
}

#[test]
fn calibrate_records_a_profile_from_the_live_glove_and_stats_sees_the_traffic() {
    use std::io::{BufRead, BufReader, Write};
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;
    use teleop_sim_glove::hand::PinchFinger;

    let sandbox = Sandbox::new();
    sandbox.write("retarget.toml", &with_profile(RETARGET_TOML));
    let launch = sandbox.write(
        "launch.toml",
        "[[process]]\nname = \"retarget\"\nprogram = \"teleop-retarget\"\nargs = [\"--config\", \"retarget.toml\"]\n",
    );
    let _session = sandbox.launch(&launch);

    // The operator's poses as the glove reports them (glove order, thumb rotation last): the
    // glove's ranges, then the pinches, thumb to index, middle and ring as the simulated
    // glove holds them and to the little finger (which the simulator does not pinch) where the
    // default hand model's pads meet under this profile's ranges.
    let sim_pinch = |finger: PinchFinger| finger.positions().map(|p| p.round() as u16);
    let poses: [[u16; 6]; 8] = [
        [950, 940, 960, 930, 900, 800], // open hand
        [60, 70, 50, 80, 150, 800],     // fist
        [950, 940, 960, 930, 900, 120], // thumb in
        [950, 940, 960, 930, 900, 880], // thumb out
        sim_pinch(PinchFinger::Index),
        sim_pinch(PinchFinger::Middle),
        sim_pinch(PinchFinger::Ring),
        [270, 950, 950, 950, 280, 140], // pinch thumb to little
    ];
    let pose = Arc::new(AtomicUsize::new(0));
    let stop = Arc::new(AtomicUsize::new(0));
    let glove_thread = {
        let (pose, stop, ipc) = (pose.clone(), stop.clone(), sandbox.ipc.clone());
        std::thread::spawn(move || {
            let node = NodeRuntime::new("e2e-glove", &ipc).unwrap();
            let mut glove: Publisher<GloveState> = node.publisher().unwrap();
            while stop.load(Ordering::SeqCst) == 0 {
                let raw = poses[pose.load(Ordering::SeqCst)];
                glove
                    .publish(&GloveState {
                        raw_position: raw,
                        link_up: 1,
                        ..Default::default()
                    })
                    .unwrap();
                std::thread::sleep(Duration::from_millis(2));
            }
        })
    };

    let stats = sandbox.run_teleop(&["stats", "--seconds", "1"]);
    let stats = String::from_utf8(stats.stdout).unwrap();
    let rate = |topic: &str| -> f64 {
        let line = stats.lines().find(|l| l.starts_with(topic)).unwrap();
        line.split_whitespace().nth(1).unwrap().parse().unwrap()
    };
    assert!(rate("glove/state") > 100.0, "{stats}");
    assert!(
        rate("hand/command") > 100.0,
        "retarget answers every glove sample:\n{stats}"
    );

    let mut calibrate = sandbox
        .teleop()
        .args(["calibrate", "--out", "operator.toml", "--capture", "0.3"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = calibrate.stdin.take().unwrap();
    let stdout = BufReader::new(calibrate.stdout.take().unwrap());
    let mut transcript = String::new();
    for line in stdout.lines() {
        let line = line.unwrap();
        transcript.push_str(&line);
        transcript.push('\n');
        // "Pose k/8 (name): prompt" then "  Press Enter ..." on the next line once the
        // operator should be in pose k.
        if let Some(k) = line.strip_prefix("Pose ").and_then(|r| r.split('/').next()) {
            pose.store(k.parse::<usize>().unwrap() - 1, Ordering::SeqCst);
            std::thread::sleep(Duration::from_millis(100));
            stdin.write_all(b"\n").unwrap();
        }
    }
    let status = calibrate.wait().unwrap();
    stop.store(1, Ordering::SeqCst);
    glove_thread.join().unwrap();
    assert!(status.success(), "{transcript}");
    let profile = std::fs::read_to_string(sandbox.dir.path().join("operator.toml")).unwrap();
    let table = toml_lite(&profile);
    assert_eq!(table["little"]["open"], "950");
    assert_eq!(table["little"]["closed"], "60");
    assert_eq!(table["thumb"]["closed"], "150");
    assert_eq!(table["thumb_rotation"]["inner"], "120");
    assert_eq!(table["thumb_rotation"]["outer"], "880");
    // The pinch step fitted the operator's thumb: every pinch closes in the model.
    assert!(
        transcript.contains("Pose 8/8 (pinch thumb to little)"),
        "{transcript}"
    );
    let gaps: Vec<f32> = transcript
        .lines()
        .filter_map(|l| l.split_once(" mm before, ")?.1.strip_suffix(" mm after"))
        .map(|after| after.parse().unwrap())
        .collect();
    assert_eq!(gaps.len(), 4, "{transcript}");
    assert!(gaps.iter().all(|g| g.abs() < 1.0), "{transcript}");
    for key in [
        "thumb_base_mm",
        "thumb_direction_deg",
        "opposition_deg",
        "thumb_flexion_scale",
        "thumb_length_scale",
    ] {
        assert!(table["operator"].contains_key(key), "{profile}");
    }
    // The retargeting node accepts the profile.
    let mut node = std::process::Command::new(teleop_e2e::bin("teleop-retarget"))
        .args(["--calibration", "operator.toml", "--name", "retarget-check"])
        .arg("--profile")
        .arg(Sandbox::repo().join("config/hands/revo2.toml"))
        .envs(sandbox.ipc.to_env())
        .current_dir(sandbox.dir.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let first = BufReader::new(node.stderr.take().unwrap())
        .lines()
        .next()
        .unwrap()
        .unwrap();
    // SAFETY: kill(2) of our own child.
    unsafe {
        libc::kill(node.id() as libc::pid_t, libc::SIGINT);
    }
    node.wait().unwrap();
    assert!(first.contains("calibration profile loaded"), "{first}");
}

/// Reads `[section]` + `key = value` lines (all a calibration profile has), each value as its
/// text.
fn toml_lite(
    text: &str,
) -> std::collections::BTreeMap<String, std::collections::BTreeMap<String, String>> {
    let mut out = std::collections::BTreeMap::new();
    let mut section = String::new();
    for line in text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
    {
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            section = name.to_string();
        } else if let Some((k, v)) = line.split_once('=') {
            out.entry(section.clone())
                .or_insert_with(std::collections::BTreeMap::new)
                .insert(k.trim().to_string(), v.trim().to_string());
        }
    }
    out
}
