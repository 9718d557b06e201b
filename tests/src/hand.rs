//! A hand node under test: its executable started on a [`Rig`] with a configuration, and the
//! test's ports to it (commands out; state, tactile and health in). Each hand's node tests add
//! their device (a simulator process, or an emulated bus in the test process) and their
//! commands; starting, waiting, health, logs and stopping are here once.

use std::ffi::OsStr;
use std::time::{Duration, Instant};

use teleop_msgs::{HandCommand, HandState, NodeHealth, Tactile};
use teleop_runtime::{NodeRuntime, Publisher, Subscriber};

use crate::rig::{wait_text, Logs, Process, Rig};
use crate::watch::wait_sample;

/// A hand node's process, the test's ports to it, and the device it drives when that lives in
/// the test's process (`sim`, e.g. a [`Served`](crate::ecat::Served) bus; `()` for a simulator
/// process on the rig). Fields drop in order: the ports before their node, the rig (processes
/// stopped, logs printed on failure, the sandbox removed), the device last.
pub struct HandNode<S = ()> {
    /// `hand/command`, which the node follows.
    pub commands: Publisher<HandCommand>,
    /// `hand/state` from the node.
    pub states: Subscriber<HandState>,
    /// `hand/tactile` from the node.
    pub tactile: Subscriber<Tactile>,
    /// `health` (every node's; [`HandNode::node_health`] keeps the node's own).
    pub health: Subscriber<NodeHealth>,
    /// The test's iceoryx2 node (more ports may be opened on it).
    pub runtime: NodeRuntime,
    /// The node's name (its process and its health reports).
    name: String,
    /// The node and whatever else the test started (a simulator).
    pub rig: Rig,
    /// The device in the test's process.
    pub sim: S,
}

impl HandNode {
    /// Starts `program --config` (with `config` written into the sandbox) as `name` on `rig`
    /// and opens the test's ports as the iceoryx2 node `<name>-test`.
    pub fn start(rig: Rig, name: &str, program: impl AsRef<OsStr>, config: &str) -> Self {
        Self::start_with(rig, name, program, config, ())
    }
}

impl<S> HandNode<S> {
    /// As [`HandNode::start`], the node driving `sim`, a device in the test's process.
    pub fn start_with(
        mut rig: Rig,
        name: &str,
        program: impl AsRef<OsStr>,
        config: &str,
        sim: S,
    ) -> Self {
        rig.start_node(name, program, config);
        let runtime =
            NodeRuntime::new(&format!("{name}-test"), &rig.sandbox.ipc).expect("test node");
        Self {
            commands: runtime.publisher().expect("hand/command"),
            states: runtime.subscriber().expect("hand/state"),
            tactile: runtime.subscriber().expect("hand/tactile"),
            health: runtime.subscriber().expect("health"),
            runtime,
            name: name.to_string(),
            rig,
            sim,
        }
    }

    /// Every process's log so far.
    pub fn log(&self) -> String {
        self.rig.logs()
    }

    /// The node's process.
    pub fn node(&mut self) -> &mut Process {
        let name = self.name.clone();
        self.rig.process(&name)
    }

    /// Waits (up to `timeout`) until the logs of the rig's processes contain `text`.
    pub fn wait_log(&self, timeout: Duration, text: &str) {
        wait_text(&self.rig, &self.name, timeout, text);
    }

    /// Receives hand states every 2 ms until one satisfies `ok` and returns it; panics after
    /// `timeout` naming `what`, with the logs.
    pub fn wait_state(
        &self,
        timeout: Duration,
        what: &str,
        ok: impl FnMut(&HandState) -> bool,
    ) -> HandState {
        wait_sample(&self.states, &self.rig, timeout, what, ok)
    }

    /// The command having stopped: waits (up to 2 s) until the node holds, lets the hand settle
    /// for 300 ms, and checks that over the next 500 ms it still holds and no joint moves more
    /// than `tolerance` (in the command's units). Returns the last state.
    pub fn holds_still(&self, tolerance: f32) -> HandState {
        self.wait_state(Duration::from_secs(2), "holding", |s| s.holding == 1);
        std::thread::sleep(Duration::from_millis(300));
        let positions =
            |s: &HandState| -> Vec<f32> { s.active_joints().iter().map(|j| j.position).collect() };
        let held = self.states.poll_latest().expect("a hand state");
        std::thread::sleep(Duration::from_millis(500));
        let later = self.states.poll_latest().expect("a hand state");
        assert_eq!(later.holding, 1, "{}: the hand holds", self.name);
        for (a, b) in positions(&held).iter().zip(positions(&later)) {
            assert!(
                (a - b).abs() < tolerance,
                "{}: held: {:?} -> {:?}",
                self.name,
                positions(&held),
                positions(&later)
            );
        }
        later
    }

    /// Publishes `cmd` every 10 ms for `d`; returns the newest hand state.
    pub fn send(&mut self, cmd: &HandCommand, d: Duration) -> HandState {
        let start = Instant::now();
        while start.elapsed() < d {
            self.commands.publish(cmd).expect("publish hand/command");
            std::thread::sleep(Duration::from_millis(10));
        }
        self.states
            .poll_latest()
            .unwrap_or_else(|| panic!("no hand state from {}\n{}", self.name, self.log()))
    }

    /// The node's health reports received since the last call (other nodes' are passed over).
    pub fn node_health(&self) -> Vec<NodeHealth> {
        let mut out = Vec::new();
        self.health.drain(|h| {
            if h.name() == self.name {
                out.push(*h);
            }
        });
        out
    }
}
