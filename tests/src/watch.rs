//! The one watcher: subscribes to a session's topics (in a sandbox's IPC settings) and waits
//! for a condition with a timeout. What it saw (how many samples of each topic, how old the
//! newest, the newest hand state's link and hold) goes into the failure message, with the logs
//! of whatever ran the session.

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use teleop_msgs::{
    GloveDiagnostics, GloveForceCommand, GloveState, HandCommand, HandState, Message, NodeHealth,
    Tactile,
};
use teleop_runtime::{NodeRuntime, Subscriber};

use crate::rig::Logs;
use crate::Sandbox;

/// How recent a topic's newest sample must be for [`fresh`].
pub const FRESH: Duration = Duration::from_millis(150);

/// True when `s`'s newest sample was made within [`FRESH`].
pub fn fresh<M: Message>(s: &Subscriber<M>) -> bool {
    s.is_fresh(Instant::now(), FRESH)
}

/// A subscriber of every topic a session's tests look at.
pub struct Watcher {
    /// `glove/state`.
    pub glove: Subscriber<GloveState>,
    /// `glove/diagnostics`.
    pub diag: Subscriber<GloveDiagnostics>,
    /// `hand/command`.
    pub cmd: Subscriber<HandCommand>,
    /// `hand/state`.
    pub state: Subscriber<HandState>,
    /// `hand/tactile`.
    pub tactile: Subscriber<Tactile>,
    /// `glove/force_command`.
    pub force: Subscriber<GloveForceCommand>,
    /// `health`.
    pub health: Subscriber<NodeHealth>,
    /// The watcher's own node; tests may open more ports on it (a publisher of commands).
    pub node: NodeRuntime,
}

impl Watcher {
    /// Subscribes, as the iceoryx2 node `name`, in `sandbox`'s IPC settings.
    pub fn new(sandbox: &Sandbox, name: &str) -> Self {
        let node = NodeRuntime::new(name, &sandbox.ipc).expect("the watcher's node");
        Self {
            glove: node.subscriber().expect("glove/state"),
            diag: node.subscriber().expect("glove/diagnostics"),
            cmd: node.subscriber().expect("hand/command"),
            state: node.subscriber().expect("hand/state"),
            tactile: node.subscriber().expect("hand/tactile"),
            force: node.subscriber().expect("glove/force_command"),
            health: node.subscriber().expect("health"),
            node,
        }
    }

    /// Receives every queued sample of every topic (each topic's newest is kept).
    pub fn drain_all(&self) {
        self.glove.drain(|_| {});
        self.diag.drain(|_| {});
        self.cmd.drain(|_| {});
        self.state.drain(|_| {});
        self.tactile.drain(|_| {});
        self.force.drain(|_| {});
        self.health.drain(|_| {});
    }

    /// Receives every queued sample and checks `ok` on what the watcher then holds, every 5 ms,
    /// until it holds; panics after `timeout` naming `what`, with what it saw and `logs`.
    pub fn until(
        &self,
        logs: &dyn Logs,
        timeout: Duration,
        what: &str,
        mut ok: impl FnMut(&Self) -> bool,
    ) {
        let start = Instant::now();
        loop {
            self.drain_all();
            if ok(self) {
                return;
            }
            self.check_deadline(start, timeout, what, logs);
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Receives hand states every 2 ms until one satisfies `ok` and returns it; panics after
    /// `timeout` naming `what`, with what it saw and `logs`.
    pub fn wait_state(
        &self,
        logs: &dyn Logs,
        timeout: Duration,
        what: &str,
        ok: impl FnMut(&HandState) -> bool,
    ) -> HandState {
        self.wait_sample(&self.state, logs, timeout, what, ok)
    }

    /// Receives samples of `topic` every 2 ms until one satisfies `ok` and returns it; panics
    /// after `timeout` naming `what`, with what the watcher saw and `logs`.
    pub fn wait_sample<M: Message>(
        &self,
        topic: &Subscriber<M>,
        logs: &dyn Logs,
        timeout: Duration,
        what: &str,
        ok: impl FnMut(&M) -> bool,
    ) -> M {
        let seen_and_logs = || format!("{}\n{}", self.seen(), logs.logs());
        wait_sample(topic, &seen_and_logs, timeout, what, ok)
    }

    /// The health reports of the node `name` received since the last call (other nodes'
    /// reports are passed over).
    pub fn node_health(&self, name: &str) -> Vec<NodeHealth> {
        let mut out = Vec::new();
        self.health.drain(|h| {
            if h.name() == name {
                out.push(*h);
            }
        });
        out
    }

    /// What the watcher saw: per topic the samples received and lost and the newest one's age;
    /// the newest hand state's link and hold.
    pub fn seen(&self) -> String {
        let now = Instant::now();
        let mut out = String::from("the watcher saw:");
        topic_line(&mut out, &self.glove, now);
        topic_line(&mut out, &self.diag, now);
        topic_line(&mut out, &self.cmd, now);
        topic_line(&mut out, &self.state, now);
        topic_line(&mut out, &self.tactile, now);
        topic_line(&mut out, &self.force, now);
        topic_line(&mut out, &self.health, now);
        if let Some(s) = self.state.latest() {
            let _ = write!(
                out,
                "\n  newest hand state: link_up {} holding {} joints {}",
                s.link_up, s.holding, s.joint_count
            );
        }
        out
    }

    fn check_deadline(&self, start: Instant, timeout: Duration, what: &str, logs: &dyn Logs) {
        check_time(start, timeout, what, &|| {
            format!("{}\n{}", self.seen(), logs.logs())
        });
    }
}

/// Receives samples of `topic` every 2 ms until one satisfies `ok` and returns it; panics after
/// `timeout` naming `what`, with `logs`.
pub fn wait_sample<M: Message>(
    topic: &Subscriber<M>,
    logs: &dyn Logs,
    timeout: Duration,
    what: &str,
    mut ok: impl FnMut(&M) -> bool,
) -> M {
    let start = Instant::now();
    loop {
        let mut found = None;
        topic.drain(|s| {
            if found.is_none() && ok(s) {
                found = Some(*s);
            }
        });
        if let Some(s) = found {
            return s;
        }
        check_time(start, timeout, what, logs);
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Panics naming `what`, with `logs`, once `timeout` has passed since `start`.
fn check_time(start: Instant, timeout: Duration, what: &str, logs: &dyn Logs) {
    assert!(
        start.elapsed() < timeout,
        "timed out after {timeout:?} waiting for {what}\n{}",
        logs.logs()
    );
}

/// One topic's line in [`Watcher::seen`].
fn topic_line<M: Message>(out: &mut String, s: &Subscriber<M>, now: Instant) {
    let _ = write!(
        out,
        "\n  {:<20} {:>6} samples, {} lost",
        M::TOPIC,
        s.received(),
        s.dropped()
    );
    if let Some(age) = s.age(now) {
        let _ = write!(out, ", newest received {age:.0?} ago");
    }
}
