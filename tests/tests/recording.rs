//! Recording and replay end to end: the recorder process killed with SIGKILL and repaired, the
//! timing of `teleop replay`, and `teleop reprocess` determinism, all through the executables.
#![allow(clippy::unwrap_used)]

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use teleop_e2e::{bin, glove, wait_for, Sandbox};
use teleop_msgs::GloveState;
use teleop_runtime::NodeRuntime;

#[test]
fn a_recorder_killed_with_sigkill_loses_at_most_the_last_100_ms() {
    let sandbox = Sandbox::new();
    let out = sandbox.dir.path().join("killed.mcap");
    let mut recorder = Command::new(bin("teleop-recorder"))
        .args(["--out", out.to_str().unwrap(), "--topics", "glove/state"])
        .envs(sandbox.ipc.to_env())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let node = NodeRuntime::new("rec-test", &sandbox.ipc).unwrap();
    let mut publisher = node.publisher::<GloveState>().unwrap();
    // Wait until the recorder listens.
    wait_for(Duration::from_secs(20), "the recorder's subscriber", || {
        node.topic_ports::<GloveState>()
            .filter(|(_, subs)| *subs > 0)
    });
    let mut sent = Vec::new();
    let start = Instant::now();
    let mut i = 0;
    while start.elapsed() < Duration::from_millis(1500) {
        i += 1;
        let h = publisher.publish(&glove(i)).unwrap();
        sent.push((h.seq, Instant::now()));
        std::thread::sleep(Duration::from_millis(1));
    }
    let killed_at = Instant::now();
    recorder.kill().unwrap(); // SIGKILL
    recorder.wait().unwrap();

    let info = sandbox.run_teleop(&["recordings", "info", out.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(text.contains("not finished"), "{text}");
    let repaired = sandbox.dir.path().join("repaired.mcap");
    let r = sandbox.run_teleop(&[
        "recordings",
        "repair",
        out.to_str().unwrap(),
        "--out",
        repaired.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let got: std::collections::HashSet<u64> =
        teleop_recording::read_messages(&repaired, &teleop_recording::Filter::all())
            .unwrap()
            .map(|m| m.unwrap().decode::<GloveState>().unwrap().header.seq)
            .collect();
    // Everything published more than 100 ms (chunk close) + 50 ms (delivery and scheduling)
    // before the kill is in the repaired file.
    let must_have: Vec<u64> = sent
        .iter()
        .filter(|(_, at)| killed_at.duration_since(*at) > Duration::from_millis(150))
        .map(|(s, _)| *s)
        .collect();
    let missing: Vec<&u64> = must_have.iter().filter(|s| !got.contains(s)).collect();
    assert!(
        missing.is_empty(),
        "lost {} of {} older samples: {:?}",
        missing.len(),
        must_have.len(),
        &missing[..missing.len().min(10)]
    );
    assert!(
        got.len() as f64 > sent.len() as f64 * 0.85,
        "{} of {}",
        got.len(),
        sent.len()
    );
    let full = sandbox.run_teleop(&["recordings", "info", repaired.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&full.stdout).contains("complete"));
}

/// Writes a recording of glove samples at the given log-time offsets (ms).
fn write_recording(path: &std::path::Path, offsets_ms: &[u64]) {
    let mut rec = teleop_recording::Recorder::create(path, Default::default(), &[]).unwrap();
    let id = rec.add_message_type::<GloveState>().unwrap();
    for (i, ms) in offsets_ms.iter().enumerate() {
        let mut s = glove(i as u64);
        s.header.seq = i as u64 + 1;
        s.header.stamp_ns = 1_000_000_000 + ms * 1_000_000;
        let log = s.header.stamp_ns;
        rec.write(id, &teleop_recording::RecordedMessage::from_sample(&s, log))
            .unwrap();
    }
    rec.finish().unwrap();
}

#[test]
fn replay_reproduces_the_recorded_timing_and_max_speed_is_far_faster() {
    let sandbox = Sandbox::new();
    let path = sandbox.dir.path().join("timing.mcap");
    // Irregular intervals: 5, 20, 5, 20, ... ms over 2.5 s.
    let mut offsets = vec![0u64];
    for i in 0..200 {
        let last = *offsets.last().unwrap();
        offsets.push(last + if i % 2 == 0 { 5 } else { 20 });
    }
    write_recording(&path, &offsets);
    let node = NodeRuntime::new("replay-test", &sandbox.ipc).unwrap();
    let sub = node.subscriber::<GloveState>().unwrap();

    let mut replay = sandbox
        .teleop()
        .args(["replay", path.to_str().unwrap()])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut arrivals = Vec::new();
    let start = Instant::now();
    while arrivals.len() < offsets.len() && start.elapsed() < Duration::from_secs(20) {
        let _ = sub.listener().timed_wait(|_| {}, Duration::from_millis(5));
        sub.drain(|s| arrivals.push((s.header.seq, Instant::now())));
    }
    assert!(replay.wait().unwrap().success());
    assert_eq!(arrivals.len(), offsets.len(), "every sample replayed");
    // Stated tolerance: each inter-sample interval within 3 ms of the recorded one for at least
    // 95 % of samples, and the whole replay within 5 % of the recorded duration.
    let mut close = 0;
    for w in 1..arrivals.len() {
        let got = arrivals[w]
            .1
            .duration_since(arrivals[w - 1].1)
            .as_secs_f64()
            * 1000.0;
        let want = (offsets[w] - offsets[w - 1]) as f64;
        if (got - want).abs() <= 3.0 {
            close += 1;
        }
    }
    assert!(
        close as f64 >= 0.95 * (arrivals.len() - 1) as f64,
        "{close} of {} intervals within 3 ms",
        arrivals.len() - 1
    );
    let total = arrivals
        .last()
        .unwrap()
        .1
        .duration_since(arrivals[0].1)
        .as_secs_f64();
    let recorded = *offsets.last().unwrap() as f64 / 1000.0;
    assert!(
        (total - recorded).abs() <= 0.05 * recorded,
        "{total} s vs {recorded} s"
    );

    let t = Instant::now();
    let fast = sandbox.run_teleop(&["replay", path.to_str().unwrap(), "--max-speed"]);
    assert!(fast.status.success());
    assert!(
        t.elapsed().as_secs_f64() < recorded / 5.0,
        "max speed took {:?}",
        t.elapsed()
    );
}

#[test]
fn info_says_which_topics_of_a_contract_version_1_recording_are_converted() {
    let sandbox = Sandbox::new();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let sample = root.join("recordings/grasp.sample.mcap");
    let r = sandbox.run_teleop(&["recordings", "info", sample.to_str().unwrap()]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let text = String::from_utf8(r.stdout).unwrap();
    let converted: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("converted"))
        .collect();
    assert_eq!(
        converted,
        [
            "converted  hand/state: recorded with contract version 1, read as version 2",
            "converted  hand/tactile: recorded with contract version 1, read as version 2",
        ],
        "{text}"
    );
}

#[test]
fn reprocess_is_deterministic_and_detects_a_changed_gain() {
    let sandbox = Sandbox::new();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let sample = root.join("recordings/grasp.sample.mcap");
    assert!(sample.is_file(), "{} is missing", sample.display());
    let retarget = root.join("config/retarget.toml");
    let feedback = root.join("config/feedback.toml");
    let run = |out: &str, feedback: &std::path::Path, retarget: &std::path::Path| {
        let out = sandbox.dir.path().join(out);
        let r = sandbox.run_teleop(&[
            "reprocess",
            sample.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--retarget-config",
            retarget.to_str().unwrap(),
            "--feedback-config",
            feedback.to_str().unwrap(),
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        (
            std::fs::read(out).unwrap(),
            String::from_utf8(r.stdout).unwrap(),
        )
    };
    let differ = |report: &str, topic: &str| -> u64 {
        let line = report.lines().find(|l| l.starts_with(topic)).unwrap();
        line.split_whitespace().nth(3).unwrap().parse().unwrap()
    };
    let (a, report) = run("a.mcap", &feedback, &retarget);
    let (b, _) = run("b.mcap", &feedback, &retarget);
    assert!(
        a == b,
        "two runs with the same input and config give identical bytes"
    );
    assert_eq!(
        differ(&report, "hand/command"),
        0,
        "retargeting reproduces the recording:\n{report}"
    );

    let mut text = std::fs::read_to_string(&retarget).unwrap();
    text = text.replace("max_speed = 3.0", "max_speed = 1.0");
    let changed = sandbox.write("retarget-changed.toml", &text);
    let (_, changed_report) = run("c.mcap", &feedback, &changed);
    assert!(
        differ(&changed_report, "hand/command") > 100,
        "a changed speed gain is detected:\n{changed_report}"
    );

    let text = std::fs::read_to_string(&feedback)
        .unwrap()
        .replace("gain_per_n = 250.0", "gain_per_n = 100.0");
    let changed = sandbox.write("feedback-changed.toml", &text);
    let (_, changed_report) = run("d.mcap", &changed, &retarget);
    assert!(
        differ(&changed_report, "glove/force_command")
            > 2 * differ(&report, "glove/force_command") + 50,
        "a changed force gain is detected:\nbaseline\n{report}\nchanged\n{changed_report}"
    );
}

#[test]
fn bad_files_are_clear_errors() {
    let sandbox = Sandbox::new();
    let text = sandbox.write("notes.mcap", "this is not a recording\n");
    let out = sandbox.run_teleop(&["recordings", "info", text.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("notes.mcap") && err.to_lowercase().contains("mcap"),
        "{err}"
    );
    let out = sandbox.run_teleop(&["replay", text.to_str().unwrap()]);
    assert!(!out.status.success());
    let missing = sandbox.run_teleop(&["reprocess", "/nonexistent.mcap", "--out", "x.mcap"]);
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("/nonexistent.mcap"));
}
