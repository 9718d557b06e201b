//! The bimanual session (`launch/bimanual.toml`): two simulated gloves, two emulated Revo2s and
//! a retargeting and a force-feedback node per side, each side in its own namespace (`left`,
//! `right`), and one recorder for both. For 20 s: both sides close their loops on their own
//! topics, `teleop stats` sees both, one `teleop estop` stops both, and the recording holds
//! both namespaces' channels.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_e2e::{Sandbox, Session};
use teleop_msgs::{
    contact_source, force_flags, source_id, GloveForceCommand, GloveState, HandCommand, HandState,
    NodeHealth, Tactile,
};
use teleop_runtime::{Namespace, NodeRuntime, Subscriber};

const SIDES: [&str; 2] = ["left", "right"];

/// The topics that flow on each side of a running session.
const FLOWING: [&str; 5] = [
    "glove/state",
    "hand/command",
    "hand/state",
    "hand/tactile",
    "glove/force_command",
];

/// How long the session runs.
const SESSION: Duration = Duration::from_secs(20);

/// One side's topics, seen from outside its namespace.
struct Side {
    name: &'static str,
    glove: Subscriber<GloveState>,
    cmd: Subscriber<HandCommand>,
    state: Subscriber<HandState>,
    tactile: Subscriber<Tactile>,
    force: Subscriber<GloveForceCommand>,
    health: Subscriber<NodeHealth>,
}

impl Side {
    fn new(node: &NodeRuntime, name: &'static str) -> Self {
        let ns = Namespace::new(name).unwrap();
        let ns = Some(&ns);
        Self {
            name,
            glove: node.subscriber_in(ns).unwrap(),
            cmd: node.subscriber_in(ns).unwrap(),
            state: node.subscriber_in(ns).unwrap(),
            tactile: node.subscriber_in(ns).unwrap(),
            force: node.subscriber_in(ns).unwrap(),
            health: node.subscriber_in(ns).unwrap(),
        }
    }

    fn running(&self) -> bool {
        let fresh = Duration::from_millis(150);
        let now = Instant::now();
        self.glove.drain(|_| {});
        self.cmd.drain(|_| {});
        self.state.drain(|_| {});
        self.tactile.drain(|_| {});
        self.force.drain(|_| {});
        self.glove.is_fresh(now, fresh)
            && self.cmd.is_fresh(now, fresh)
            && self.state.is_fresh(now, fresh)
            && self.tactile.is_fresh(now, fresh)
            && self.force.is_fresh(now, fresh)
    }
}

/// What one side showed while the operator grasped the ball.
#[derive(Default, Debug)]
struct Closed {
    commands: u64,
    /// Hand commands not made by this side's retargeting node.
    foreign_commands: u64,
    states: u64,
    /// Largest index fingertip normal force (N).
    index_normal: f32,
    /// Largest glove index force commanded from tactile contact.
    index_force: i16,
    health_names: Vec<String>,
}

impl Closed {
    fn done(&self) -> bool {
        self.commands > 0 && self.states > 0 && self.index_normal > 1.0 && self.index_force > 0
    }

    fn take(&mut self, side: &Side) {
        let retarget = source_id(&format!("{}/retarget", side.name));
        side.cmd.drain(|c| {
            self.commands += 1;
            if c.header.source_id != retarget {
                self.foreign_commands += 1;
            }
        });
        side.state.drain(|_| self.states += 1);
        // Revo2 fingertip order: thumb, index, ...
        side.tactile
            .drain(|t| self.index_normal = self.index_normal.max(t.fingertips[1].normal_n));
        // Glove order: little, ring, middle, index, thumb.
        side.force.drain(|f| {
            if f.source[3] == contact_source::TACTILE {
                self.index_force = self.index_force.max(f.force[3]);
            }
        });
        let names = &mut self.health_names;
        side.health.drain(|h| {
            let name = h.name();
            if !names.contains(&name) {
                names.push(name);
            }
        });
    }
}

fn until(session: &Session, timeout: Duration, what: &str, mut ok: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ok() {
        assert!(
            start.elapsed() < timeout,
            "timed out waiting for {what}\n{}",
            session.log()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// `teleop stats` rows: (qualified topic, samples).
fn stats_rows(text: &str) -> Vec<(String, u64)> {
    text.lines()
        .filter_map(|l| {
            let mut cols = l.split_whitespace();
            let topic = cols.next()?.to_string();
            let samples = cols.nth(1)?.parse().ok()?;
            Some((topic, samples))
        })
        .collect()
}

#[test]
fn both_sides_close_their_loops_and_are_recorded() {
    let sandbox = Sandbox::new();
    let launch = sandbox.bimanual_session();
    let mut session = sandbox.launch(&launch);
    let started = Instant::now();
    let node = NodeRuntime::new("bimanual-test", &sandbox.ipc).unwrap();
    let sides = SIDES.map(|s| Side::new(&node, s));
    until(
        &session,
        Duration::from_secs(60),
        "both sides running",
        || sides.iter().all(Side::running),
    );

    // Both scripted operators grasp their ball: on each side its own retargeting node commands
    // its hand, the hand's fingertips touch the ball, and that side's feedback pushes back.
    let mut closed = [Closed::default(), Closed::default()];
    until(
        &session,
        Duration::from_secs(15),
        "both loops closed",
        || {
            for (c, side) in closed.iter_mut().zip(&sides) {
                c.take(side);
            }
            closed.iter().all(Closed::done)
        },
    );
    // Each side's nodes report their health in that side's namespace, under their own names.
    for (c, side) in closed.iter_mut().zip(&sides) {
        let names =
            ["glove", "revo2", "retarget", "feedback"].map(|n| format!("{}/{n}", side.name));
        until(
            &session,
            Duration::from_secs(5),
            "every node's health",
            || {
                c.take(side);
                names.iter().all(|n| c.health_names.contains(n))
            },
        );
        assert_eq!(c.foreign_commands, 0, "{}: {c:?}", side.name);
    }

    // `teleop stats` without a namespace shows every side.
    let out = sandbox.run_teleop(&["stats", "--seconds", "1"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows = stats_rows(&String::from_utf8(out.stdout).unwrap());
    for side in SIDES {
        for topic in FLOWING {
            let name = format!("{side}/{topic}");
            let samples = rows.iter().find(|(t, _)| *t == name).map(|r| r.1);
            assert!(
                samples.is_some_and(|n| n > 0),
                "{name}: {samples:?} in {rows:?}"
            );
        }
    }
    // `teleop nodes --namespace left` lists the left side only.
    let out =
        String::from_utf8(sandbox.run_teleop(&["nodes", "--namespace", "left"]).stdout).unwrap();
    assert!(
        out.contains("left/glove") && out.contains("left/feedback"),
        "{out}"
    );
    assert!(!out.contains("right/"), "{out}");

    // One e-stop without a namespace stops both sides; released, forces come back.
    let out = sandbox.run_teleop(&["estop"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stopped = |side: &Side| {
        let mut all = true;
        let mut seen = false;
        side.force.drain(|f| {
            seen = true;
            all &= f.flags & force_flags::ESTOP != 0 && f.force == [0; 5];
        });
        seen && all
    };
    for side in &sides {
        until(
            &session,
            Duration::from_secs(2),
            "e-stop on every side",
            || stopped(side),
        );
    }
    let out = sandbox.run_teleop(&["estop", "--release"]);
    assert!(out.status.success());
    for side in &sides {
        until(
            &session,
            Duration::from_secs(5),
            "forces after release",
            || {
                let mut back = false;
                side.force
                    .drain(|f| back |= f.flags & force_flags::ESTOP == 0 && f.force[3] > 0);
                back
            },
        );
    }

    if let Some(rest) = SESSION.checked_sub(started.elapsed()) {
        std::thread::sleep(rest);
    }
    let status = session.stop();
    assert!(status.success(), "{}", session.log());
    let log = session.log();
    assert!(
        log.contains("left/hand/command") && log.contains("right/hand/command"),
        "the session summary shows both sides\n{log}"
    );
    let recording = log
        .lines()
        .find_map(|l| l.strip_prefix("recording: "))
        .expect("the summary says where the recording is");
    let path = sandbox.dir.path().join("launch").join(recording);
    let info = teleop_recording::info(&path).unwrap();
    assert!(info.complete);
    for side in SIDES {
        for topic in FLOWING.iter().chain(&["health"]) {
            let name = format!("{side}/{topic}");
            let t = info.topics.iter().find(|t| t.topic == name);
            assert!(
                t.is_some_and(|t| t.messages > 0),
                "{name} in the recording: {:?}",
                info.topics
                    .iter()
                    .map(|t| (&t.topic, t.messages))
                    .collect::<Vec<_>>()
            );
        }
        let device = format!("{side}/device.glove");
        assert!(
            info.metadata.iter().any(|(name, _)| *name == device),
            "{device}: {:?}",
            info.metadata
                .iter()
                .map(|(name, _)| name)
                .collect::<Vec<_>>()
        );
    }
    assert!(
        !info.topics.iter().any(|t| t.topic == "hand/command"),
        "nothing was recorded outside the namespaces"
    );
    // Read back, the channels decode as their contract types.
    let left_cmds = teleop_recording::read_messages(
        &path,
        &teleop_recording::Filter::topics(["left/hand/command"]),
    )
    .unwrap()
    .map(|m| m.unwrap())
    .filter(|m| m.payload.len() == std::mem::size_of::<HandCommand>())
    .count();
    assert!(left_cmds > 0);
    let out = sandbox.run_teleop(&["recordings", "info", path.to_str().unwrap()]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("left/hand/tactile") && text.contains("right/hand/tactile"),
        "{text}"
    );
}
