//! Two stations as two machines for the tests and benchmarks of the link between them: the
//! operator station (`launch/revo2-operator.toml`) and the robot station (`launch/revo2-robot.toml`), each in
//! its own network namespace and sandbox (own iceoryx2 root and prefix), joined by a veth pair
//! with addresses from 192.0.2.0/24 (RFC 5737) and by their bridges, with certificates from one
//! session CA made by `teleop certs` and a fault-injection control socket on each bridge.

use std::time::Duration;

use teleop_msgs::NodeHealth;
use teleop_runtime::{NodeRuntime, Subscriber};

use crate::netns::Netns;
use crate::{Sandbox, Session};

/// The operator station's address on the veth.
pub const OPERATOR_IP: &str = "192.0.2.1";
/// The robot station's address on the veth.
pub const ROBOT_IP: &str = "192.0.2.2";

/// One running station: its sandbox, its launcher and a node for the test's ports.
pub struct Station {
    /// Its folder and iceoryx2 settings.
    pub sandbox: Sandbox,
    /// Its `teleop launch`.
    pub session: Session,
    /// The test's iceoryx2 node at this station.
    pub node: NodeRuntime,
    /// The station's `health` topic.
    pub health: Subscriber<NodeHealth>,
}

impl Station {
    /// Calls `f` with each queued health report of `node`.
    pub fn health_of(&self, node: &str, mut f: impl FnMut(&NodeHealth)) {
        self.health.drain(|h| {
            if h.name() == node {
                f(h);
            }
        });
    }

    /// The bridge's pid, while it runs.
    pub fn bridge_pid(&self) -> Option<u32> {
        self.sandbox.pid_of("bridge")
    }

    /// One command to the bridge's control socket; its answer.
    pub fn control(&self, command: &str) -> String {
        self.sandbox.control("bridge.ctl", command)
    }

    /// The launcher's output so far.
    pub fn logs(&self) -> String {
        self.session.log()
    }
}

/// Both namespaces and the Revo2's stations (`launch/revo2-operator.toml`, `launch/revo2-robot.toml`),
/// started (robot first); `patch` changes a bridge configuration's text (`true` for the
/// operator's).
pub fn start(
    prefix: &str,
    patch: impl Fn(bool, String) -> String,
) -> (Netns, Netns, Station, Station) {
    start_hand(prefix, "revo2", patch)
}

/// As [`start`], with the stations of `hand` (`launch/<hand>-operator.toml` and
/// `launch/<hand>-robot.toml`).
pub fn start_hand(
    prefix: &str,
    hand: &str,
    patch: impl Fn(bool, String) -> String,
) -> (Netns, Netns, Station, Station) {
    let (op_ns, robot_ns) = Netns::pair(
        prefix,
        (&format!("{OPERATOR_IP}/24"), &format!("{ROBOT_IP}/24")),
    );
    let launch = |side: &str| format!("launch/{hand}-{side}.toml");
    let op = prepare(&launch("operator"), "config/bridge/operator.toml", |t| {
        patch(true, t)
    });
    let robot = prepare(&launch("robot"), "config/bridge/robot.toml", |t| {
        // The shipped file listens on the robot's address, ROBOT_IP.
        assert!(t.contains(&format!("quic/{ROBOT_IP}:7447")), "{t}");
        patch(false, t)
    });
    certificates(&op.0, &robot.0);
    let robot = robot.start(&robot_ns);
    let operator = op.start(&op_ns);
    (op_ns, robot_ns, operator, robot)
}

/// A station written into its sandbox, not started yet.
struct Prepared(Sandbox, std::path::PathBuf);

impl Prepared {
    fn start(self, ns: &Netns) -> Station {
        let Prepared(sandbox, file) = self;
        let node = NodeRuntime::new("remote-test", &sandbox.ipc).expect("test node");
        let health = node.subscriber().expect("health subscriber");
        let session = sandbox.launch_in(ns, &file);
        Station {
            sandbox,
            session,
            node,
            health,
        }
    }
}

fn prepare(launch: &str, bridge: &str, patch: impl Fn(String) -> String) -> Prepared {
    let sandbox = Sandbox::new();
    let file = sandbox.session(launch);
    let text = std::fs::read_to_string(sandbox.dir.path().join(bridge)).expect("bridge config");
    sandbox.write(bridge, &patch(text));
    let ctl = sandbox.dir.path().join("bridge.ctl");
    let launch_text = std::fs::read_to_string(&file)
        .expect("launch file")
        .replace(
            &format!("\"../{bridge}\"]"),
            &format!("\"../{bridge}\", \"--control\", \"{}\"]", ctl.display()),
        );
    assert!(launch_text.contains("--control"), "{launch_text}");
    std::fs::write(&file, launch_text).expect("launch file");
    Prepared(sandbox, file)
}

/// `teleop certs --out certs --station SPEC...` in `sandbox`: a new CA there and a certificate
/// per station spec (`NAME=ADDRESS`); panics with its error output unless it succeeded.
pub fn make_certs(sandbox: &Sandbox, stations: &[String]) {
    let mut args = vec!["certs", "--out", "certs"];
    for station in stations {
        args.extend(["--station", station.as_str()]);
    }
    let out = sandbox.run_teleop(&args);
    assert!(
        out.status.success(),
        "teleop certs: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The session's certificates, made at the operator's and copied to the robot's `certs/`.
fn certificates(operator: &Sandbox, robot: &Sandbox) {
    make_certs(
        operator,
        &[
            format!("operator={OPERATOR_IP}"),
            format!("robot={ROBOT_IP}"),
        ],
    );
    let from = operator.dir.path().join("certs");
    let to = robot.dir.path().join("certs");
    std::fs::create_dir_all(&to).expect("certs folder");
    for f in ["ca.pem", "robot.pem", "robot.key"] {
        std::fs::copy(from.join(f), to.join(f)).expect("copy certificate");
    }
}

/// Receives for `window`; what `f` returned for each sample.
pub fn collect<M: teleop_msgs::Message, T>(
    sub: &Subscriber<M>,
    window: Duration,
    mut f: impl FnMut(&M) -> Option<T>,
) -> Vec<T> {
    let mut out = Vec::new();
    let end = std::time::Instant::now() + window;
    while std::time::Instant::now() < end {
        sub.drain(|m| out.extend(f(m)));
        std::thread::sleep(Duration::from_millis(2));
    }
    out
}
