//! The runtime's ports and event loop over real iceoryx2 shared memory, each test in its own
//! iceoryx2 root and prefix.
#![allow(clippy::unwrap_used)]

use std::ops::ControlFlow;
use std::time::{Duration, Instant};

use teleop_msgs::{GloveState, HandCommand, Message};
use teleop_runtime::*;

/// A temp dir and isolated settings; the shared memory of the prefix goes with it.
struct Isolated {
    _dir: tempfile::TempDir,
    settings: IpcSettings,
}

impl Drop for Isolated {
    fn drop(&mut self) {
        self.settings.remove_shared_memory();
    }
}

impl core::ops::Deref for Isolated {
    type Target = IpcSettings;
    fn deref(&self) -> &IpcSettings {
        &self.settings
    }
}

fn settings() -> Isolated {
    let dir = tempfile::tempdir().unwrap();
    let settings = IpcSettings::isolated(dir.path());
    Isolated {
        _dir: dir,
        settings,
    }
}

#[test]
fn publish_stamps_and_subscriber_receives_in_order() {
    let ipc = settings();
    let a = NodeRuntime::new("pub-node", &ipc).unwrap();
    let b = NodeRuntime::new("sub-node", &ipc).unwrap();
    let mut publisher = a.publisher::<GloveState>().unwrap();
    let subscriber = b.subscriber::<GloveState>().unwrap();
    let before = now_ns();
    for i in 0..5u16 {
        let mut s = GloveState::default();
        s.raw_position[0] = i;
        let header = publisher.publish(&s).unwrap();
        assert_eq!(header.seq, u64::from(i) + 1);
        assert_eq!(
            header.origin_ns, header.stamp_ns,
            "a fresh sample is its own origin"
        );
        assert_eq!(header.source_id, teleop_msgs::source_id("pub-node"));
    }
    let mut seen = Vec::new();
    assert_eq!(
        subscriber.drain(|s| seen.push((s.header.seq, s.raw_position[0]))),
        5
    );
    assert_eq!(
        seen,
        (1..=5).map(|i| (i, (i - 1) as u16)).collect::<Vec<_>>()
    );
    let latest = subscriber.latest().unwrap();
    assert!(latest.header.stamp_ns >= before);
    assert_eq!(subscriber.dropped(), 0);
    assert!(subscriber.is_fresh(Instant::now(), Duration::from_secs(1)));
}

#[test]
fn freshness_counts_from_the_stamp_not_the_receipt() {
    let ipc = settings();
    let a = NodeRuntime::new("pub-node", &ipc).unwrap();
    let b = NodeRuntime::new("sub-node", &ipc).unwrap();
    let mut p = a.publisher::<HandCommand>().unwrap();
    let s = b.subscriber::<HandCommand>().unwrap();
    // Made 300 ms before it is received (as a sample from a topic's history after a restart).
    let mut old = HandCommand::default();
    old.header.stamp_ns = now_ns() - 300_000_000;
    p.send_as_is(&old).unwrap();
    assert!(s.poll_latest().is_some());
    assert!(!s.is_fresh(Instant::now(), Duration::from_millis(100)));
    assert!(s.is_fresh(Instant::now(), Duration::from_secs(10)));
    // Stamped now: fresh. A stamp from the future counts from the receipt.
    p.publish(&HandCommand::default()).unwrap();
    assert!(s.poll_latest().is_some());
    assert!(s.is_fresh(Instant::now(), Duration::from_millis(100)));
    let mut future = HandCommand::default();
    future.header.stamp_ns = now_ns() + 3_600_000_000_000;
    p.send_as_is(&future).unwrap();
    assert!(s.poll_latest().is_some());
    std::thread::sleep(Duration::from_millis(150));
    assert!(!s.is_fresh(Instant::now(), Duration::from_millis(100)));
}

#[test]
fn origin_is_kept_when_set() {
    let ipc = settings();
    let n = NodeRuntime::new("origin", &ipc).unwrap();
    let mut p = n.publisher::<HandCommand>().unwrap();
    let s = n.subscriber::<HandCommand>().unwrap();
    let mut cmd = HandCommand::default();
    cmd.header.origin_ns = 42;
    p.publish(&cmd).unwrap();
    assert_eq!(s.poll_latest().unwrap().header.origin_ns, 42);
}

#[test]
fn settings_isolate_pipelines() {
    let one = settings();
    let two = settings();
    let a = NodeRuntime::new("a", &one).unwrap();
    let b = NodeRuntime::new("b", &two).unwrap();
    let mut p = a.publisher::<GloveState>().unwrap();
    let s = b.subscriber::<GloveState>().unwrap();
    p.publish(&GloveState::default()).unwrap();
    assert_eq!(s.drain(|_| {}), 0);
}

#[test]
fn namespaces_separate_topics_and_are_discovered() {
    let ipc = settings();
    let in_ns = |ns: &str| IpcSettings {
        namespace: Some(ns.into()),
        ..ipc.settings.clone()
    };
    let left = NodeRuntime::new("glove", &in_ns("left")).unwrap();
    let right = NodeRuntime::new("glove", &in_ns("right")).unwrap();
    let root = NodeRuntime::new("glove", &ipc).unwrap();
    assert_eq!(left.name(), "left/glove");
    assert_eq!(left.namespace().map(Namespace::as_str), Some("left"));
    assert_eq!(root.name(), "glove");
    assert_ne!(left.source_id(), right.source_id());

    let mut p_left = left.publisher::<GloveState>().unwrap();
    let s_right = right.subscriber::<GloveState>().unwrap();
    let s_root = root.subscriber::<GloveState>().unwrap();
    // A tool serving several namespaces reaches `left` from a node outside it.
    let s_left = root.subscriber_in::<GloveState>(left.namespace()).unwrap();
    p_left.publish(&GloveState::default()).unwrap();
    assert_eq!(s_left.drain(|_| {}), 1);
    assert_eq!(s_right.drain(|_| {}), 0);
    assert_eq!(s_root.drain(|_| {}), 0);

    let found = discover_namespaces(&ipc).unwrap();
    let names: Vec<&str> = found.iter().map(Namespace::as_str).collect();
    assert_eq!(names, ["left", "right"]);
}

#[test]
fn invalid_namespace_is_refused_by_name() {
    let ipc = settings();
    let bad = IpcSettings {
        namespace: Some("left/".into()),
        ..ipc.settings.clone()
    };
    let err = NodeRuntime::new("x", &bad).err().unwrap().to_string();
    assert!(
        err.contains("namespace") && err.contains("\"left/\""),
        "{err}"
    );
}

#[test]
fn gaps_in_sequence_numbers_count_as_drops() {
    let ipc = settings();
    let n = NodeRuntime::new("gaps", &ipc).unwrap();
    let mut p = n.publisher::<GloveState>().unwrap();
    let s = n.subscriber::<GloveState>().unwrap();
    let mut msg = GloveState::default();
    for seq in [1u64, 2, 5, 6, 10] {
        msg.header.seq = seq;
        p.send_as_is(&msg).unwrap();
    }
    s.drain(|_| {});
    assert_eq!(s.dropped(), 2 + 3);
}

#[test]
fn event_loop_wakes_on_input_and_reports_missed_deadlines() {
    let ipc = settings();
    let n = NodeRuntime::new("loop", &ipc).unwrap();
    let s = n.subscriber::<GloveState>().unwrap();
    let publisher_thread = {
        let ipc = ipc.clone();
        std::thread::spawn(move || {
            let n = NodeRuntime::new("loop-pub", &ipc).unwrap();
            let mut p = n.publisher::<GloveState>().unwrap();
            for _ in 0..3 {
                std::thread::sleep(Duration::from_millis(20));
                p.publish(&GloveState::default()).unwrap();
            }
            // then go quiet: the subscriber's deadline must fire
            std::thread::sleep(Duration::from_millis(400));
        })
    };
    let mut received = 0;
    let mut timeouts_after_data = 0;
    let stop = EventLoop::new(Duration::from_millis(50))
        .run(
            &[Input::with_deadline(
                s.listener(),
                Duration::from_millis(100),
            )],
            |wake| {
                match wake {
                    Wake::Input(0) => received += s.drain(|_| {}),
                    Wake::Timeout(0) if received == 3 => timeouts_after_data += 1,
                    _ => {}
                }
                if timeouts_after_data > 0 {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            },
        )
        .unwrap();
    publisher_thread.join().unwrap();
    assert_eq!(stop, StopReason::Requested);
    assert_eq!(received, 3);
    assert_eq!(timeouts_after_data, 1);
}

#[test]
fn health_reports_counters_and_input_ages() {
    let ipc = settings();
    let n = NodeRuntime::new("healthy", &ipc).unwrap();
    let reader = n.subscriber::<teleop_msgs::NodeHealth>().unwrap();
    let mut health = Health::new(&n).unwrap();
    health.count_timeout();
    health.count_clamps(3);
    health.count_error();
    health.count_loop();
    health
        .publish(&[Some(Duration::from_millis(5)), None])
        .unwrap();
    let h = reader.poll_latest().unwrap();
    assert_eq!(h.name(), "healthy");
    assert_eq!((h.timeouts, h.clamps, h.errors), (1, 3, 1));
    assert_eq!(h.input_count, 2);
    assert!((h.input_age_ms[0] - 5.0).abs() < 1e-3);
    assert_eq!(h.input_age_ms[1], -1.0);
    assert!(h.loop_rate_hz > 0.0);
    assert_eq!(GloveState::TOPIC, "glove/state");
}

#[test]
fn bad_settings_are_refused_with_the_setting_named() {
    let bad = IpcSettings {
        root: None,
        prefix: Some("bad/prefix".into()),
        ..IpcSettings::default()
    };
    let err = NodeRuntime::new("x", &bad).err().unwrap().to_string();
    assert!(
        err.contains("prefix") && err.contains("bad/prefix"),
        "{err}"
    );
}
