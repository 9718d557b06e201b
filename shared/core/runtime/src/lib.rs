//! The node runtime: the one way a pipeline process talks to the others.
//!
//! Owns the plumbing every node shares, so that a node's own code is its loop and its pure step:
//! - [`IpcSettings`]: the iceoryx2 root path and prefix (set by `teleop launch` through the
//!   environment; tests give each test its own so they never see each other's services), and the
//!   process's topic [`Namespace`] (`left/glove/state`; see `teleop-namespace`), so that node code
//!   is the same on every side; [`discover_namespaces`] finds the namespaces in use;
//! - [`NodeRuntime`]: the iceoryx2 node, typed [`Publisher`]s and [`Subscriber`]s for the topics of
//!   `teleop-msgs`, each paired with an event service so that receivers sleep until data arrives;
//! - [`EventLoop`]: a WaitSet over the inputs with per-input deadlines (input watchdogs) and a
//!   periodic tick; returns on SIGINT/SIGTERM so the node can stop cleanly ([`stop_signal`]
//!   does the same for loops that block on something else, such as a serial port);
//! - [`EStopInput`]: the latched e-stop (a latch file per namespace that outlives every process,
//!   the `estop` topic as its doorbell, `estop/ack` as the nodes' answer);
//! - [`Health`]: counters (timeouts, clamps, errors, drops) and the periodic [`NodeHealth`] report;
//! - [`load_toml`]: configuration files whose errors name the file, line and field;
//! - [`now_ns`]: the CLOCK_MONOTONIC stamp used in every header; [`sleep_until`]: absolute
//!   deadlines (`clock_nanosleep`, `TIMER_ABSTIME`); [`init_logging`]: `tracing` through a
//!   bounded queue that drops (and counts) instead of blocking a loop;
//! - [`control`]: a line-based control socket served on threads of its own (the simulators',
//!   whose commands and answers are `teleop-sim-kit`'s, and the bridge's fault injection);
//! - [`node_main`]: the opening of every node's `main` (logging, arguments, configuration file,
//!   exit status) and [`NodeArgs`], the arguments every node with a configuration file takes;
//! - [`schedule`]: when a pipeline engine's inputs go stale (by their samples' stamps) and when
//!   it ticks (absolute deadlines), pure, for the nodes and for reprocessing alike;
//! - [`link`]: the link between stations as a bridge's health reports it, whose measured delay
//!   the freshness of samples that crossed it allows for;
//! - [`args`]: command-line value parsers (`teleop` and the device service commands);
//! - [`realtime`]: the scheduling policy, priority, CPU affinity, memory locking and nice value
//!   `launch.toml` gives a process, for its time-critical threads;
//! - [`serial_latency`]: low-latency mode on a serial port and the warning about a slow USB
//!   adapter's latency timer (the serial device nodes' links).
//!
//! Must not depend on: any device protocol, the retargeting or force-feedback logic, or the CLI.
//!
//! [`NodeHealth`]: teleop_msgs::NodeHealth

pub mod args;
mod clock;
mod config_file;
pub mod control;
mod estop;
mod event_loop;
mod health;
mod ipc;
pub mod link;
mod logging;
pub mod node_main;
mod ports;
pub mod realtime;
pub mod schedule;
pub mod serial_latency;
mod signals;

pub use clock::{now_ns, sleep_until, sleep_until_ns};
pub use config_file::{check_ms, load_toml, parse_toml, ConfigFileError, MAX_CONFIG_MS};
pub use estop::{
    latch_engaged, latch_holder, latch_path, latched_namespaces, release_latch_held_by, set_latch,
    set_latch_by, EStopInput, LATCH_POLL,
};
pub use event_loop::{EventLoop, Flow, Input, StopReason, Wake};
pub use health::Health;
pub use ipc::{
    clean_dead_nodes, discover_namespaces, IpcSettings, NodeRuntime, RuntimeError, SessionLock,
    ENV_IPC_PREFIX, ENV_IPC_ROOT, ENV_NAMESPACE,
};
pub use logging::{dropped_log_lines, init_logging};
pub use node_main::{node_main, NodeArgs, NodeMain};
pub use ports::{sample_time, Publisher, Subscriber};
pub use signals::{
    follow_supervisor, install_stop_handlers, stop_signal, take_over_stop_signals,
    ENV_SUPERVISOR_PID,
};
pub use teleop_namespace::{qualified, split, Namespace, NamespaceError};

/// iceoryx2 service type used everywhere (inter-process, shared memory).
pub type Service = iceoryx2::service::ipc::Service;
