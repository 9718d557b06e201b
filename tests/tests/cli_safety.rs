//! The command line against hostile or careless use, through the executables: no argument makes
//! `teleop` panic, `teleop echo ... | head` ends quietly with success, `teleop replay` refuses
//! unknown topics, publishes only sensor topics by default and never into a topic a running
//! process publishes unless told to, and two recorders started at once write two files.
#![allow(clippy::unwrap_used)]

use std::io::BufRead;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use teleop_e2e::{bin, glove, wait_for, Sandbox};
use teleop_msgs::{EStop, GloveState, HandCommand, Message};
use teleop_recording::{RecordedMessage, Recorder};
use teleop_runtime::NodeRuntime;

/// Writes `n` samples of each of `glove/state`, `hand/command` and `estop` (engaged), one of
/// each every 10 ms.
fn write_mixed_recording(path: &Path, n: u64) {
    let mut rec = Recorder::create(path, Default::default(), &[]).unwrap();
    let glove_id = rec.add_message_type::<GloveState>().unwrap();
    let cmd_id = rec.add_message_type::<HandCommand>().unwrap();
    let estop_id = rec.add_message_type::<EStop>().unwrap();
    for i in 0..n {
        let stamp = 1_000_000_000 + i * 10_000_000;
        let mut s = glove(i);
        s.header.seq = i + 1;
        s.header.stamp_ns = stamp;
        rec.write(glove_id, &RecordedMessage::from_sample(&s, stamp))
            .unwrap();
        let mut c = HandCommand::default();
        c.header.seq = i + 1;
        c.header.stamp_ns = stamp;
        rec.write(cmd_id, &RecordedMessage::from_sample(&c, stamp))
            .unwrap();
        let mut e = EStop {
            engaged: 1,
            ..Default::default()
        };
        e.header.seq = i + 1;
        e.header.stamp_ns = stamp;
        rec.write(estop_id, &RecordedMessage::from_sample(&e, stamp))
            .unwrap();
    }
    rec.finish().unwrap();
}

fn stderr_of(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn no_argument_makes_teleop_panic() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("r.mcap");
    write_mixed_recording(&rec, 3);
    let rec = rec.to_str().unwrap();
    let cases: &[(&[&str], &str)] = &[
        (&["stats", "--seconds", "nan"], "--seconds"),
        (&["stats", "--seconds", "-1"], "--seconds"),
        (&["stats", "--seconds", "1e300"], "--seconds"),
        (&["replay", rec, "--start", "-1"], "--start"),
        (&["replay", rec, "--start", "1e30"], "--start"),
        (&["replay", rec, "--end", "inf"], "--end"),
        (&["replay", rec, "--speed", "nan"], "--speed"),
        (&["replay", rec, "--speed", "0"], "--speed"),
        (&["replay", rec, "--speed", "1e-300"], "--speed"),
        (&["launch", "--duration", "nan"], "--duration"),
        (&["launch", "--duration", "1e20"], "--duration"),
        (&["record", "--duration", "-5"], "--duration"),
        (&["calibrate", "--yes", "--settle", "inf"], "--settle"),
        (&["calibrate", "--yes", "--capture", "nan"], "--capture"),
        (
            &["glove", "--timeout-ms", "18446744073709551615", "info"],
            "--timeout-ms",
        ),
    ];
    for (args, named) in cases {
        let out = sandbox.run_teleop(args);
        let err = stderr_of(&out);
        assert_eq!(out.status.code(), Some(2), "teleop {args:?}: {err}");
        assert!(
            err.contains(named),
            "teleop {args:?} must name {named}: {err}"
        );
        assert!(!err.contains("panicked"), "teleop {args:?}: {err}");
    }
}

#[test]
fn echo_into_a_closed_pipe_ends_quietly_with_success() {
    let sandbox = Sandbox::new();
    let node = NodeRuntime::new("echo-pipe-test", &sandbox.ipc).unwrap();
    let mut publisher = node.publisher::<GloveState>().unwrap();
    // `teleop echo glove/state | head -n 1`: the reader takes one line and closes the pipe.
    let mut echo = sandbox
        .teleop()
        .args(["echo", GloveState::TOPIC])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = echo.stdout.take().unwrap();
    let head = std::thread::spawn(move || {
        let mut line = String::new();
        std::io::BufReader::new(stdout)
            .read_line(&mut line)
            .unwrap();
        line
    });
    let start = Instant::now();
    let mut i = 0;
    let status = loop {
        if let Some(status) = echo.try_wait().unwrap() {
            break status;
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "teleop echo kept running after its reader went away"
        );
        i += 1;
        publisher.publish(&glove(i)).unwrap();
        std::thread::sleep(Duration::from_millis(5));
    };
    let line = head.join().unwrap();
    // The first line of echo's first YAML document.
    assert_eq!(line, "---\n", "{line}");
    let mut err = String::new();
    std::io::Read::read_to_string(&mut echo.stderr.take().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{status}: {err}");
    assert!(err.is_empty(), "nothing on stderr: {err}");
}

#[test]
fn listings_into_a_closed_pipe_end_quietly_with_success() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("r.mcap");
    write_mixed_recording(&rec, 3);
    let launch = sandbox.default_session(|t| t);
    let cases: [&[&str]; 4] = [
        &["recordings", "info", rec.to_str().unwrap()],
        &["topics"],
        &["nodes"],
        &["launch", "--check", launch.to_str().unwrap()],
    ];
    for args in cases {
        // The reader is gone before the command writes anything.
        let mut child = sandbox
            .teleop()
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let err = stderr_of(&out);
        assert!(out.status.success(), "teleop {args:?}: {err}");
        assert!(!err.contains("panicked"), "teleop {args:?}: {err}");
    }
}

#[test]
fn replay_refuses_unknown_topics_naming_the_known_ones() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("r.mcap");
    write_mixed_recording(&rec, 3);
    let rec = rec.to_str().unwrap();
    let out = sandbox.run_teleop(&["replay", rec, "--topics", "glove/stat"]);
    let err = stderr_of(&out);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("\"glove/stat\"") && err.contains("glove/state, glove/diagnostics"),
        "names the unknown topic and lists the known ones: {err}"
    );
    // A topic of the contract that the recording does not have.
    let out = sandbox.run_teleop(&["replay", rec, "--topics", "hand/tactile"]);
    let err = stderr_of(&out);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("hand/tactile") && err.contains("not in the recording"),
        "{err}"
    );
    assert!(
        err.contains("hand/command"),
        "lists the recorded channels: {err}"
    );
}

#[test]
fn replay_of_an_empty_window_fails_instead_of_looping_for_ever() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("r.mcap");
    write_mixed_recording(&rec, 3);
    let mut replay = sandbox
        .teleop()
        .args(["replay", rec.to_str().unwrap(), "--loop", "--start", "100"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_for(Duration::from_secs(20), "replay to give up", || {
        replay.try_wait().unwrap()
    });
    let mut err = String::new();
    std::io::Read::read_to_string(&mut replay.stderr.take().unwrap(), &mut err).unwrap();
    assert!(!status.success(), "{err}");
    assert!(err.contains("between --start and --end"), "{err}");
}

#[test]
fn replay_publishes_only_sensor_topics_unless_named() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("r.mcap");
    write_mixed_recording(&rec, 30);
    let node = NodeRuntime::new("replay-default-test", &sandbox.ipc).unwrap();
    let states = node.subscriber::<GloveState>().unwrap();
    let commands = node.subscriber::<HandCommand>().unwrap();
    let estops = node.subscriber::<EStop>().unwrap();
    // Samples of (glove/state, hand/command, estop) received during one replay.
    let replay = |extra: &[&str]| {
        let (mut n_states, mut n_commands, mut n_estops) = (0, 0, 0);
        let mut child = sandbox
            .teleop()
            .args(["replay", rec.to_str().unwrap()])
            .args(extra)
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let start = Instant::now();
        let status = loop {
            states.drain(|_| n_states += 1);
            commands.drain(|_| n_commands += 1);
            estops.drain(|_| n_estops += 1);
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            assert!(start.elapsed() < Duration::from_secs(20));
            std::thread::sleep(Duration::from_millis(2));
        };
        states.drain(|_| n_states += 1);
        commands.drain(|_| n_commands += 1);
        estops.drain(|_| n_estops += 1);
        assert!(status.success());
        (n_states, n_commands, n_estops)
    };
    let (n_states, n_commands, n_estops) = replay(&[]);
    assert!(n_states > 0, "glove/state is a sensor topic: replayed");
    assert_eq!(
        (n_commands, n_estops),
        (0, 0),
        "no hand command and no e-stop by default"
    );
    // Named, a command topic is replayed.
    let (n_states, n_commands, n_estops) = replay(&["--topics", HandCommand::TOPIC]);
    assert_eq!((n_states, n_estops), (0, 0));
    assert!(n_commands > 0);
}

#[test]
fn replay_refuses_a_topic_with_a_live_publisher_unless_allowed() {
    let sandbox = Sandbox::new();
    let rec = sandbox.dir.path().join("r.mcap");
    write_mixed_recording(&rec, 30);
    let rec = rec.to_str().unwrap();
    let node = NodeRuntime::new("live-glove", &sandbox.ipc).unwrap();
    let mut live = node.publisher::<GloveState>().unwrap();
    live.publish(&glove(1)).unwrap();
    let out = sandbox.run_teleop(&["replay", rec]);
    let err = stderr_of(&out);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("glove/state") && err.contains("--allow-live"),
        "names the live topic and the way out: {err}"
    );
    let sub = node.subscriber::<GloveState>().unwrap();
    sub.drain(|_| {});
    let mut replay = sandbox
        .teleop()
        .args(["replay", rec, "--allow-live"])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut replayed = 0;
    let start = Instant::now();
    while replay.try_wait().unwrap().is_none() {
        assert!(start.elapsed() < Duration::from_secs(20));
        sub.drain(|_| replayed += 1);
        std::thread::sleep(Duration::from_millis(2));
    }
    sub.drain(|_| replayed += 1);
    assert!(replay.wait().unwrap().success());
    assert!(replayed > 0, "published with --allow-live");
}

/// Whether process `pid` has a handler for SIGINT (from `SigCgt` in /proc/<pid>/status).
fn catches_sigint(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|status| {
            let mask = status.lines().find_map(|l| l.strip_prefix("SigCgt:"))?;
            u64::from_str_radix(mask.trim(), 16).ok()
        })
        .is_some_and(|mask| mask & (1 << (libc::SIGINT - 1)) != 0)
}

#[test]
fn two_recorders_started_at_once_write_two_files() {
    let sandbox = Sandbox::new();
    let dir = sandbox.dir.path().join("recordings");
    let start = |name: &str| {
        Command::new(bin("teleop-recorder"))
            .args(["--dir", dir.to_str().unwrap(), "--name", name])
            .envs(sandbox.ipc.to_env())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let mut recorders = [start("recorder-a"), start("recorder-b")];
    let files = || -> Vec<_> {
        std::fs::read_dir(&dir)
            .map(|d| d.flatten().map(|e| e.path()).collect())
            .unwrap_or_default()
    };
    // Started: both files exist (or a recorder gave up) and both stop cleanly on SIGINT.
    wait_for(Duration::from_secs(20), "two recordings started", || {
        let running = recorders
            .iter_mut()
            .all(|r| r.try_wait().unwrap().is_none());
        let ready = files().len() == 2 && recorders.iter().all(|r| catches_sigint(r.id()));
        (ready || !running).then_some(())
    });
    for r in &recorders {
        // SAFETY: kill(2) of our own child.
        unsafe {
            libc::kill(r.id() as libc::pid_t, libc::SIGINT);
        }
    }
    for r in recorders {
        let out = r.wait_with_output().unwrap();
        assert!(out.status.success(), "{}", stderr_of(&out));
    }
    let files = files();
    assert_eq!(files.len(), 2, "{files:?}");
    for f in &files {
        assert!(
            teleop_recording::info(f).unwrap().complete,
            "{}",
            f.display()
        );
    }
}
