//! The default simulated session's fault suite (the session itself, as every hand's, is tested
//! in `hand_session`): each process killed in turn, the glove unplugged, the EtherCAT link cut,
//! corrupted serial frames and lost EtherCAT frames. Every case ends in the documented safe
//! state (hand holds, glove force zero) and recovers.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use teleop_e2e::watch::{fresh, Watcher};
use teleop_e2e::{Sandbox, Session};
use teleop_msgs::command_flags;

/// The hand holds: the Revo2 node holds on a stale command, or the retargeting node sends the
/// last command again flagged as held (its glove input is stale or the glove's link is down).
fn hand_holds(w: &Watcher) -> bool {
    w.state
        .latest()
        .is_some_and(|s| s.holding == 1 && s.link_up == 1)
        || (fresh(&w.cmd)
            && w.cmd
                .latest()
                .is_some_and(|c| c.flags & command_flags::HELD != 0))
}

fn start(sandbox: &Sandbox) -> (Session, Watcher) {
    let launch = sandbox.default_session(|t| t);
    let session = sandbox.launch(&launch);
    let watch = Watcher::new(sandbox, "session-test");
    watch.until(
        &session,
        Duration::from_secs(30),
        "the whole pipeline running",
        |w| {
            fresh(&w.glove)
                && fresh(&w.cmd)
                && fresh(&w.state)
                && fresh(&w.tactile)
                && fresh(&w.force)
        },
    );
    (session, watch)
}

/// Log times of every sample per (topic, source), to look for gaps.
fn topic_gaps(path: &std::path::Path) -> BTreeMap<String, (u64, Duration)> {
    let mut last: BTreeMap<(String, u32), (u64, u64)> = BTreeMap::new();
    let mut worst: BTreeMap<String, (u64, Duration)> = BTreeMap::new();
    for m in teleop_recording::read_messages(path, &teleop_recording::Filter::all()).unwrap() {
        let m = m.unwrap();
        let header = teleop_msgs::SampleHeader {
            seq: u64::from_le_bytes(m.payload[0..8].try_into().unwrap()),
            source_id: u32::from_le_bytes(m.payload[24..28].try_into().unwrap()),
            ..Default::default()
        };
        let e = worst.entry(m.topic.clone()).or_insert((0, Duration::ZERO));
        if let Some((seq, at)) = last.insert(
            (m.topic.clone(), header.source_id),
            (header.seq, m.log_time_ns),
        ) {
            if header.seq > seq + 1 {
                e.0 += header.seq - seq - 1;
            }
            e.1 =
                e.1.max(Duration::from_nanos(m.log_time_ns.saturating_sub(at)));
        }
    }
    worst
}

#[test]
fn killing_each_process_in_turn_ends_safe_and_recovers() {
    let sandbox = Sandbox::new();
    let (mut session, watch) = start(&sandbox);
    let glove_link = sandbox.dir.path().join("glove").display().to_string();
    for victim in [
        "retarget",
        "feedback",
        "revo2",
        "glove",
        "sim-revo2",
        "sim-glove",
    ] {
        let pid_now = || match victim {
            "sim-glove" => Sandbox::pid_with_arg(&format!("--link {glove_link}")),
            "sim-revo2" => {
                Sandbox::pid_with_arg(&sandbox.dir.path().join("revo2.sock").display().to_string())
            }
            node => sandbox.pid_of(node),
        };
        let pid = pid_now().unwrap_or_else(|| panic!("pid of {victim}"));
        // SAFETY: kill(2) of a process of this test's own session.
        unsafe {
            libc::kill(pid as libc::pid_t, libc::SIGKILL);
        }
        let killed = Instant::now();
        // The documented safe state for each stage.
        match victim {
            "retarget" | "glove" | "sim-glove" => watch.until(
                &session,
                Duration::from_secs(3),
                "the hand holding",
                hand_holds,
            ),
            "feedback" | "revo2" | "sim-revo2" => {
                let cmd_zero = |w: &Watcher| {
                    victim != "feedback" && w.force.latest().is_some_and(|f| f.force == [0; 5])
                };
                let device_zero = || {
                    sandbox
                        .control("glove.ctl", "state")
                        .contains("force_set=[0, 0, 0, 0, 0]")
                };
                watch.until(&session, Duration::from_secs(3), "glove force zero", |w| {
                    cmd_zero(w) || device_zero()
                });
            }
            _ => {}
        }
        assert!(killed.elapsed() < Duration::from_secs(3));
        // Restarted by the launcher (its log says so) ...
        let restarted = |session: &Session| {
            session
                .log()
                .lines()
                .any(|l| l.contains("restarting in") && l.ends_with(&format!("process={victim}")))
        };
        watch.until(
            &session,
            Duration::from_secs(5),
            &format!("{victim} restarted"),
            |_| restarted(&session),
        );
        // ... a new process runs (after the restart delay, so no sample of the killed one is
        // still fresh) ...
        watch.until(
            &session,
            Duration::from_secs(10),
            &format!("a new {victim}"),
            |_| pid_now().is_some_and(|p| p != pid),
        );
        // ... and everything flows again.
        watch.until(
            &session,
            Duration::from_secs(25),
            &format!("recovery after killing {victim}"),
            |w| {
                fresh(&w.glove)
                    && fresh(&w.cmd)
                    && fresh(&w.force)
                    && w.state.latest().is_some_and(|s| s.link_up == 1)
                    && fresh(&w.state)
                    && w.cmd
                        .latest()
                        .is_some_and(|c| c.flags & command_flags::HELD == 0)
            },
        );
    }
    session.stop();
    let log = session.log();
    let recording = log
        .lines()
        .find_map(|l| l.strip_prefix("recording: "))
        .unwrap();
    let recording = sandbox.dir.path().join(recording);
    // The recorder was never killed: topics of processes that stayed alive have no sequence gap.
    let gaps = topic_gaps(&recording);
    for (topic, (lost, _)) in &gaps {
        assert_eq!(*lost, 0, "{topic} lost samples in the recording: {gaps:?}");
    }
}

#[test]
fn device_faults_are_ridden_out() {
    let sandbox = Sandbox::new();
    let (session, watch) = start(&sandbox);

    // Glove unplugged: the glove reports its link down, the hand holds; replugged: it follows.
    assert!(sandbox
        .control("glove.ctl", "unplug 1000")
        .starts_with("ok"));
    watch.until(
        &session,
        Duration::from_secs(3),
        "glove link down and hand holding",
        |w| w.glove.latest().is_some_and(|g| g.link_up == 0) && hand_holds(w),
    );
    watch.until(&session, Duration::from_secs(10), "glove back", |w| {
        w.glove.latest().is_some_and(|g| g.link_up == 1) && !hand_holds(w)
    });

    // EtherCAT link cut: the hand state reports the link down, glove force goes to zero; then back.
    assert!(sandbox
        .control("revo2.ctl", "unplug 1000")
        .starts_with("ok"));
    watch.until(
        &session,
        Duration::from_secs(3),
        "EtherCAT link down and zero glove force",
        |w| {
            w.state.latest().is_some_and(|s| s.link_up == 0)
                && w.force.latest().is_some_and(|f| f.force == [0; 5])
        },
    );
    watch.until(&session, Duration::from_secs(15), "EtherCAT back", |w| {
        w.state.latest().is_some_and(|s| s.link_up == 1) && fresh(&w.state)
    });

    // Corrupted serial frames and lost EtherCAT frames: counted, no interruption.
    let errors_before = watch.glove.latest().unwrap().errors;
    let lost_before = watch.state.latest().unwrap().lost_frames;
    assert!(sandbox
        .control("glove.ctl", "corrupt 0.2")
        .starts_with("ok"));
    assert!(sandbox.control("revo2.ctl", "drop 0.1").starts_with("ok"));
    std::thread::sleep(Duration::from_millis(1500));
    watch.until(
        &session,
        Duration::from_secs(2),
        "faults counted while running",
        |w| {
            w.glove
                .latest()
                .is_some_and(|g| g.errors > errors_before && g.link_up == 1)
                && w.state
                    .latest()
                    .is_some_and(|s| s.lost_frames > lost_before && s.link_up == 1)
                && fresh(&w.glove)
                && fresh(&w.state)
        },
    );
    assert!(sandbox.control("glove.ctl", "clear").starts_with("ok"));
    assert!(sandbox.control("revo2.ctl", "drop 0").starts_with("ok"));
}

/// The short soak CI runs (the long one is `cargo run --release -p teleop-e2e --example soak`):
/// 20 s of the default session without a drop, a restart or a lost link.
#[test]
fn short_soak_without_drops_or_restarts() {
    let sandbox = Sandbox::new();
    let (mut session, watch) = start(&sandbox);
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(20) {
        watch.until(
            &session,
            Duration::from_secs(2),
            "the pipeline flowing",
            |w| {
                fresh(&w.glove)
                    && fresh(&w.state)
                    && fresh(&w.force)
                    && w.state.latest().is_some_and(|s| s.link_up == 1)
            },
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(session.stop().success());
    let log = session.log();
    let summary = log.split("session summary").nth(1).expect("summary");
    assert!(summary.contains("restarts: none"), "{summary}");
    let mut rows = 0;
    for line in summary
        .lines()
        .skip(2)
        .take_while(|l| !l.starts_with("NODE"))
    {
        let drops = line.split_whitespace().last().unwrap();
        assert_eq!(drops, "0", "drops on {line}");
        rows += 1;
    }
    assert!(rows >= 9, "{summary}");
    let recording = sandbox.dir.path().join(
        log.lines()
            .find_map(|l| l.strip_prefix("recording: "))
            .unwrap(),
    );
    let info = teleop_recording::info(&recording).unwrap();
    assert!(
        info.topics.iter().all(|t| t.drops == Some(0)),
        "{:?}",
        info.topics
    );
}

/// The latest index fingertip force on the hand, newtons.
fn index_force(w: &Watcher) -> f32 {
    w.tactile.latest().map_or(0.0, |t| t.fingertips[1].normal_n)
}

/// Lowest index force over `outage`, sampled while it lasts; `holding` is set when the Revo2
/// node reported holding meanwhile.
fn lowest_index_force(session: &Session, w: &Watcher, outage: Duration, holding: &mut bool) -> f32 {
    let start = Instant::now();
    let mut lowest = f32::MAX;
    w.until(
        session,
        outage + Duration::from_secs(1),
        "the outage",
        |w| {
            lowest = lowest.min(index_force(w));
            *holding |= w.state.latest().is_some_and(|s| s.holding == 1);
            start.elapsed() >= outage
        },
    );
    lowest
}

#[test]
fn a_grasp_survives_a_lost_glove_and_a_lost_operator() {
    let sandbox = Sandbox::new();
    // The operator closes on the ball and keeps squeezing it.
    let squeeze = sandbox.write(
        "squeeze.csv",
        "0,950,950,950,950,900,700\n2,510,510,510,510,533,300\n1000,510,510,510,510,533,300\n",
    );
    // The retargeting node, killed below, comes back only after 2 s.
    let launch = sandbox.default_session(|t| {
        t.replace(
            "\"--script\", \"grasp\"",
            &format!("\"--script\", \"{}\"", squeeze.display()),
        )
        .replace(
            "args = [\"--config\", \"config/revo2/retarget.toml\"]\nrestart = \"on-failure\"\nmax_restarts = 5\nrestart_delay_ms = 500",
            "args = [\"--config\", \"config/revo2/retarget.toml\"]\nrestart = \"on-failure\"\nmax_restarts = 5\nrestart_delay_ms = 2000",
        )
    });
    assert!(std::fs::read_to_string(&launch)
        .unwrap()
        .contains("restart_delay_ms = 2000"));
    let session = sandbox.launch(&launch);
    let watch = Watcher::new(&sandbox, "session-test");
    watch.until(&session, Duration::from_secs(30), "the ball gripped", |w| {
        fresh(&w.cmd) && fresh(&w.state) && index_force(w) > 1.0
    });
    // A settled grip: the samples of one more second drained, the latest kept.
    std::thread::sleep(Duration::from_secs(1));
    watch.until(&session, Duration::from_secs(1), "a settled grip", |_| true);
    let gripped = index_force(&watch);
    assert!(gripped > 1.0, "index force on the ball: {gripped} N");

    // The glove is lost for 2 s: the retargeting node re-sends its last command as held, and
    // the Revo2 node holds its last target whenever that goes stale.
    assert!(sandbox
        .control("glove.ctl", "unplug 2000")
        .starts_with("ok"));
    let mut holding = false;
    let lowest = lowest_index_force(&session, &watch, Duration::from_secs(2), &mut holding);
    assert!(
        lowest > gripped / 2.0,
        "glove lost: the index force fell to {lowest} N (gripped at {gripped} N)\n{}",
        session.log()
    );
    watch.until(&session, Duration::from_secs(10), "glove back", |w| {
        w.glove.latest().is_some_and(|g| g.link_up == 1) && fresh(&w.cmd)
    });

    // The operator's commands stop for 2 s (the retargeting node dies and is restarted 2 s
    // later): the Revo2 node's command goes stale and the hand holds the last target, still
    // squeezing.
    let retarget = sandbox.pid_of("retarget").expect("pid of retarget");
    // SAFETY: kill(2) of a process of this test's own session.
    unsafe {
        libc::kill(retarget as libc::pid_t, libc::SIGKILL);
    }
    let mut holding = false;
    let lowest = lowest_index_force(&session, &watch, Duration::from_secs(2), &mut holding);
    assert!(holding, "the Revo2 node held on the stale command");
    assert!(
        lowest > gripped / 2.0,
        "commands lost: the index force fell to {lowest} N (gripped at {gripped} N)\n{}",
        session.log()
    );
    watch.until(&session, Duration::from_secs(10), "commands back", |w| {
        fresh(&w.cmd) && w.state.latest().is_some_and(|s| s.holding == 0)
    });
}
