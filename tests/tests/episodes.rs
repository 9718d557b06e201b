//! Episodes in a real session: `teleop episode` marks reach the session's recorder, which
//! records them, closes each episode with its health record, and loses none it closed when it
//! is killed (`teleop recordings repair` keeps them); its restarted successor continues the
//! episode left open.

use std::path::{Path, PathBuf};
use std::time::Duration;

use teleop_e2e::dataset::{check_lerobot, load_with_lerobot};
use teleop_e2e::{wait_for, Sandbox};
use teleop_msgs::{episode_outcome, GloveState, HandCommand, HandState, Message, GLOVE_CHANNELS};
use teleop_runtime::NodeRuntime;

/// Runs `teleop episode ARGS` and returns its output, failing the test when it fails.
fn episode(sandbox: &Sandbox, args: &[&str]) -> String {
    let mut all = vec!["episode"];
    all.extend_from_slice(args);
    let (ok, out) = sandbox.cli(&all);
    assert!(ok, "teleop {all:?} failed:\n{out}");
    out
}

/// The recording files in the session's `recordings` folder, oldest first.
fn recordings(sandbox: &Sandbox) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(sandbox.dir.path().join("recordings"))
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    files.retain(|p| p.extension().is_some_and(|e| e == "mcap"));
    files.sort();
    files
}

/// The newest sample of `M` in `file` stamped at or before `at` (what the export's zero-order
/// hold takes for a frame at `at`).
fn newest_before<M: Message>(file: &Path, at: u64) -> M {
    let read = teleop_recording::read_samples::<M>(file, None).expect("the recording reads");
    assert_eq!(read.undecodable, 0, "{}", M::TOPIC);
    read.samples
        .into_iter()
        .filter(|s| s.header().stamp_ns <= at)
        .max_by_key(|s| s.header().stamp_ns)
        .unwrap_or_else(|| panic!("no {} before the episode", M::TOPIC))
}

#[test]
fn three_episodes_through_the_cli_survive_a_killed_recorder() {
    let sandbox = Sandbox::new();
    let launch = sandbox.default_session(|text| text);
    let mut session = sandbox.launch(&launch);
    let recorder = wait_for(Duration::from_secs(30), "the recorder", || {
        sandbox.pid_of("recorder")
    });
    // The operator's glove is moving: the session is up.
    let node = NodeRuntime::new("episode-test", &sandbox.ipc).unwrap();
    let glove = node.subscriber::<GloveState>().unwrap();
    wait_for(Duration::from_secs(30), "glove samples", || {
        glove.poll_latest()
    });

    let said = episode(&sandbox, &["start", "--task", "pick up the ball"]);
    assert!(said.contains("episode 1 open"), "{said}");
    std::thread::sleep(Duration::from_millis(1500));
    let said = episode(&sandbox, &["stop", "--success"]);
    assert!(said.contains("episode 1 closed"), "{said}");
    episode(&sandbox, &["start", "--task", "pick up the ball"]);
    std::thread::sleep(Duration::from_millis(1500));
    episode(&sandbox, &["stop", "--failure"]);
    episode(&sandbox, &["start", "--task", "drop the ball"]);
    std::thread::sleep(Duration::from_millis(500));

    // Killed without warning with episode 3 open: every closed episode is in its file, and
    // the restarted recorder continues the open one.
    // SAFETY: kill(2) on the recorder's pid.
    unsafe {
        libc::kill(recorder as libc::pid_t, libc::SIGKILL);
    }
    wait_for(Duration::from_secs(20), "the recorder's restart", || {
        sandbox.pid_of("recorder").filter(|&p| p != recorder)
    });
    let said = wait_for(Duration::from_secs(20), "the restarted recorder", || {
        let (ok, out) = sandbox.cli(&["episode", "discard"]);
        (ok || !out.contains("no recorder")).then_some(out)
    });
    assert!(said.contains("episode 3 closed"), "{said}");
    assert!(said.contains("2 kept"), "{said}");
    // A STOP with nothing open changes nothing, and the command says so.
    let (ok, out) = sandbox.cli(&["episode", "stop", "--success"]);
    assert!(!ok, "{out}");
    assert!(
        out.contains("ignored the mark: no episode is open"),
        "{out}"
    );
    session.stop();
    let files = recordings(&sandbox);
    assert_eq!(
        files.len(),
        2,
        "the killed recorder's file and its successor's: {files:?}"
    );
    let killed = &files[0];
    assert!(!teleop_recording::info(killed).unwrap().complete);
    let repaired = sandbox.dir.path().join("repaired.mcap");
    let (ok, out) = sandbox.cli(&[
        "recordings",
        "repair",
        killed.to_str().unwrap(),
        "--out",
        repaired.to_str().unwrap(),
    ]);
    assert!(ok, "{out}");

    // The killed recorder's file alone leaves episode 3 open; with its successor's, discarded.
    let alone = teleop_recording::read_episodes(&[&repaired]).unwrap();
    assert_eq!(alone.kept().count(), 2);
    assert_eq!(alone.open().map(|o| o.index), Some(3));
    let episodes = teleop_recording::read_episodes(&[&repaired, &files[1]]).unwrap();
    let closed: Vec<_> = episodes
        .closed()
        .iter()
        .map(|e| (e.index, e.task.as_str(), e.label()))
        .collect();
    assert_eq!(
        closed,
        [
            (1, "pick up the ball", "success"),
            (2, "pick up the ball", "failure"),
            (3, "drop the ball", "discarded"),
        ]
    );
    assert!(episodes.open().is_none());
    let first = &episodes.closed()[0];
    assert_eq!(first.outcome, episode_outcome::SUCCESS);
    // The test waited 1.5 s between its START and its STOP.
    assert!(first.duration_s() >= 1.4, "{}", first.duration_s());

    // Each closed episode's record, with its health, readable by any MCAP tool.
    let info = teleop_recording::info(&repaired).unwrap();
    let record = |name: &str| {
        info.metadata
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|(_, f)| f.clone())
            .unwrap_or_else(|| panic!("no {name} record: {:?}", info.metadata))
    };
    let one = record("episode.1");
    assert_eq!(one["outcome"], "success");
    assert_eq!(one["task"], "pick up the ball");
    let rate: f64 = one["rate_hz.glove/state"].parse().unwrap();
    assert!(
        rate > 10.0,
        "glove/state at {rate} Hz in episode 1: {one:?}"
    );
    assert!(one.contains_key("rate_hz.hand/state"), "{one:?}");
    assert_eq!(one["estops"], "0");
    assert_eq!(one["estop_at_start"], "false");
    assert_eq!(record("episode.2")["outcome"], "failure");
    assert!(
        !info.metadata.iter().any(|(n, _)| n == "episode.3"),
        "episode 3 closed in the successor's file"
    );
    let next = teleop_recording::info(&files[1]).unwrap();
    let three = next
        .metadata
        .iter()
        .find(|(n, _)| n == "episode.3")
        .map(|(_, f)| f.clone())
        .expect("episode 3's record in the successor's file");
    assert_eq!(three["outcome"], "discarded");
    assert_eq!(three["task"], "drop the ball");
    // Records of episodes are written once, not repeated in later files.
    assert!(!next.metadata.iter().any(|(n, _)| n == "episode.1"));

    // The session's two files become a LeRobot dataset of the two kept episodes.
    let dataset = sandbox.dir.path().join("dataset");
    let (ok, out) = sandbox.cli(&[
        "export",
        repaired.to_str().unwrap(),
        files[1].to_str().unwrap(),
        "--format",
        "lerobot",
        "--fps",
        "30",
        "--out",
        dataset.to_str().unwrap(),
        // The rate and gap rules are tested on recordings of known timing (tests/tests/export.rs);
        // a debug session on a loaded test machine may run slower than its own average.
        "--min-rate-ratio",
        "0",
        "--max-gap-ms",
        "5000",
    ]);
    assert!(ok, "{out}");
    // One recording to the export (one recorder session): episode 3, started in the first file
    // and discarded in the second, is discarded, not "never stopped".
    assert!(
        out.contains("episode 3 (\"drop the ball\") discarded: not exported"),
        "{out}"
    );
    let Some(report) = check_lerobot(&dataset, Some(0)) else {
        return;
    };
    assert_eq!(report["total_episodes"], 2, "{report}");
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dataset.join("meta/info.json")).unwrap())
            .unwrap();
    let names = |feature: &str| -> Vec<String> {
        info["features"][feature]["names"]
            .as_array()
            .unwrap_or_else(|| panic!("{feature} has no names: {info}"))
            .iter()
            .map(|n| n.as_str().unwrap().to_string())
            .collect()
    };
    let value = |feature: &str, name: &str| -> f32 {
        let i = names(feature)
            .iter()
            .position(|n| n == name)
            .unwrap_or_else(|| panic!("no {name} in {feature}: {:?}", names(feature)));
        report["frame"][feature][i].as_f64().unwrap() as f32
    };
    // Frame 0 is episode 1's start (every topic had spoken long before it): each value is the
    // newest recorded sample at or before that instant.
    let at = first.start_ns;
    let glove: GloveState = newest_before(&repaired, at);
    for (c, channel) in GLOVE_CHANNELS.iter().enumerate() {
        assert_eq!(
            value("observation.state", &format!("glove.{channel}.pos")),
            glove.position[c],
            "glove {channel}"
        );
    }
    let state: HandState = newest_before(&repaired, at);
    let command: HandCommand = newest_before(&repaired, at);
    // The Revo2's joints, in its profile's order (the session's hand).
    let profile = teleop_hand_profile::HandProfile::builtin("revo2").expect("the Revo2 profile");
    for (j, joint) in profile.joints.iter().map(|j| &j.name).enumerate() {
        assert_eq!(
            value("observation.state", &format!("{joint}.pos")),
            state.joints[j].position,
            "{joint}"
        );
        assert_eq!(
            value("action", &format!("{joint}.target")),
            command.joints[j].target,
            "{joint}"
        );
    }

    // lerobot's own reader, where it is installed (it pulls in torch: optional).
    if let Some(loaded) = load_with_lerobot(&dataset) {
        assert_eq!(loaded["num_episodes"], 2, "{loaded}");
        assert_eq!(loaded["num_frames"], report["total_frames"], "{loaded}");
        assert_eq!(
            loaded["first_frames"][0]["task"], "pick up the ball",
            "{loaded}"
        );
    }
}

#[test]
fn an_episode_mark_without_a_recorder_is_an_error() {
    let sandbox = Sandbox::new();
    let (ok, out) = sandbox.cli(&["episode", "start", "--task", "pour"]);
    assert!(!ok);
    assert!(out.contains("no recorder is running"), "{out}");
    let (ok, out) = sandbox.cli(&["episode", "start", "--task", " "]);
    assert!(!ok);
    assert!(out.contains("the task is empty"), "{out}");
}
