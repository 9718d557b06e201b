//! A hand node under test: its executable started on a [`Rig`] with a configuration, and the
//! test's ports to it (commands out; state, tactile and health in). Each hand's node tests add
//! their device (a simulator process, or an emulated bus in the test process) and their
//! commands; starting, waiting, health, logs and stopping are here once, with the commands and
//! readings every hand's tests make (a position command in rad, the joints' positions) and
//! their turn ([`one_at_a_time`]). [`HandNode::simulated`] is any shipped hand's node against its
//! simulator process, for tests that need a running hand of each kind.

use std::ffi::OsStr;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use teleop_msgs::{control_mode, units, HandCommand, HandState, NodeHealth, Tactile};
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

    /// The node's newest health report, waiting up to 3 s for one (a panic with the logs
    /// after).
    pub fn latest_health(&self) -> NodeHealth {
        let start = Instant::now();
        loop {
            if let Some(h) = self.node_health().pop() {
                return h;
            }
            assert!(
                start.elapsed() < Duration::from_secs(3),
                "no health from {}\n{}",
                self.name,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
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

impl HandNode {
    /// The shipped hand `hand` (`revo2`, `shadow`, `allegro`, `leap`; the Allegro in protocol
    /// `v4`) as a node against its simulator process on a fresh rig, health every 100 ms;
    /// waits (up to 20 s) until `hand/state` says the link is up.
    pub fn simulated(hand: &str) -> Self {
        let mut rig = Rig::new();
        let config = match hand {
            "revo2" | "shadow" => {
                let transport = rig.start_socket_sim(hand);
                format!("transport = \"{transport}\"\nhealth_period_ms = 100\n")
            }
            "allegro" => {
                let slcan = rig.path("allegro-slcan").display().to_string();
                let control = rig.path("allegro.ctl").display().to_string();
                rig.start_sim(
                    "sim-allegro",
                    crate::bin("teleop-sim-allegro"),
                    &[
                        "--slcan",
                        &slcan,
                        "--generation",
                        "v4",
                        "--control",
                        &control,
                    ],
                    "allegro: generation",
                );
                format!("link = \"slcan:{slcan}\"\nprotocol = \"v4\"\nhealth_period_ms = 100\n")
            }
            "leap" => {
                let link = rig.path("leap-link").display().to_string();
                let control = rig.path("leap.ctl").display().to_string();
                rig.start_sim(
                    "sim-leap",
                    crate::bin("teleop-sim-leap"),
                    &["--link", &link, "--control", &control],
                    "leap: link",
                );
                format!("port = \"{link}\"\nhealth_period_ms = 100\n")
            }
            other => panic!("no simulated hand {other}"),
        };
        let node = Self::start(rig, hand, crate::bin(&format!("teleop-{hand}")), &config);
        node.wait_state(Duration::from_secs(20), "the link up", |s| s.link_up == 1);
        node
    }
}

/// One hand session at a time in a test binary: a simulated hand and its node at hundreds of
/// cycles per second over pseudo-terminals; two at once on a two-core machine measure each
/// other. Hold the guard for the session.
pub fn one_at_a_time() -> MutexGuard<'static, ()> {
    static ONE: Mutex<()> = Mutex::new(());
    ONE.lock().unwrap_or_else(|e| e.into_inner())
}

/// A position command for the hand `hand_model` (a `teleop_msgs::device_model`) in physical
/// units (rad): one joint per target, in the hand's order.
pub fn position_command(hand_model: u8, targets: &[f32]) -> HandCommand {
    let mut c = HandCommand {
        hand_model,
        joint_count: u8::try_from(targets.len()).unwrap_or(u8::MAX),
        control_mode: control_mode::POSITION,
        units: units::PHYSICAL,
        ..Default::default()
    };
    for (j, t) in c.joints.iter_mut().zip(targets) {
        j.target = *t;
    }
    c
}

/// The largest distance of a hand state's joint positions from `targets` (the first
/// `targets.len()` joints), in the command's units.
pub fn largest_error(s: &HandState, targets: &[f32]) -> f32 {
    s.joints
        .iter()
        .zip(targets)
        .map(|(j, t)| (j.position - t).abs())
        .fold(0.0f32, f32::max)
}

/// The first `N` joints' positions of a hand state.
pub fn positions<const N: usize>(s: &HandState) -> [f32; N] {
    let mut p = [0.0; N];
    for (v, j) in p.iter_mut().zip(&s.joints) {
        *v = j.position;
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_position_command_carries_its_targets_and_positions_read_the_joints() {
        let c = position_command(teleop_msgs::device_model::LEAP, &[0.5, -0.25, 1.0]);
        assert_eq!(c.hand_model, teleop_msgs::device_model::LEAP);
        assert_eq!(c.joint_count, 3);
        assert_eq!(
            (c.control_mode, c.units),
            (control_mode::POSITION, units::PHYSICAL)
        );
        let targets: Vec<f32> = c.joints[..4].iter().map(|j| j.target).collect();
        assert_eq!(targets, [0.5, -0.25, 1.0, 0.0]);
        let mut s = HandState::default();
        for (j, p) in s.joints.iter_mut().zip([0.1, 0.2, 0.3]) {
            j.position = p;
        }
        assert_eq!(positions::<2>(&s), [0.1, 0.2]);
        assert!((largest_error(&s, &[0.1, 0.0, 0.35]) - 0.2).abs() < 1e-6);
        assert_eq!(largest_error(&s, &[0.1]), 0.0, "only the joints given");
    }
}
