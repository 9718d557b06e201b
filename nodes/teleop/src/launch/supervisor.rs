//! The process supervisor behind `teleop launch`: starts every process of the launch file (and
//! stops the ones already started when one cannot be started), tags and forwards their output,
//! restarts them per policy (a budget of restarts per window, with exponential backoff), kills
//! and restarts a process whose node stopped reporting its health (hung), watches their iceoryx2
//! nodes, and stops them in reverse start order.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::prelude::CallbackProgression;
use teleop_runtime::{clean_dead_nodes, IpcSettings, Service};

use super::config::{Launch, Process, Restart};

/// How the session ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// Stopped by SIGINT/SIGTERM or at the end of `--duration`; nothing required failed.
    Stopped(&'static str),
    /// A required process failed and was not (or no longer) restarted.
    Failed(String),
}

struct Slot<'a> {
    process: &'a Process,
    child: Option<Child>,
    started: Instant,
    /// Restarts since the session started (for the summary).
    restarts: u32,
    /// When the restarts within the process's window happened.
    recent_restarts: Vec<Instant>,
    restart_at: Option<Instant>,
    node_seen: bool,
    warned_no_node: bool,
    /// How the process last ended by itself (for the summary of a process left stopped).
    last_exit: Option<String>,
}

/// Runs the session until a signal, the end of `duration`, or a failed required process.
pub fn run(
    launch: &Launch,
    ipc: &IpcSettings,
    duration: Option<Duration>,
) -> anyhow::Result<Outcome> {
    teleop_runtime::install_stop_handlers();
    // One session per IPC prefix: a second would run every topic with two writers.
    let _session = ipc.lock_session()?;
    let config = ipc.config()?;
    clean_dead_nodes(&config);
    let mut watch = super::summary::SessionWatch::new(ipc, &launch.namespaces())?;
    let recordings: Arc<Mutex<Vec<String>>> = Arc::default();
    let started = Instant::now();
    let mut slots: Vec<Slot> = Vec::with_capacity(launch.processes.len());
    let stop_timeout = Duration::from_millis(launch.session.stop_timeout_ms);
    for process in &launch.processes {
        let child = match spawn(launch, process, ipc, &recordings) {
            Ok(child) => child,
            Err(e) => {
                // Never leave the processes started so far running unsupervised.
                tracing::error!("{e:#}: stopping the processes already started");
                stop_all(&mut slots, stop_timeout);
                clean_dead_nodes(&config);
                return Err(e);
            }
        };
        slots.push(Slot {
            process,
            child: Some(child),
            started: Instant::now(),
            restarts: 0,
            recent_restarts: Vec::new(),
            restart_at: None,
            node_seen: false,
            warned_no_node: false,
            last_exit: None,
        });
        if let Some(slot) = slots.last_mut() {
            wait_ready(&mut watch, slot);
        }
    }
    tracing::info!(
        file = %launch.path.display(),
        processes = slots.len(),
        "session running; Ctrl-C stops it"
    );

    let grace = Duration::from_millis(launch.session.liveness_grace_ms);
    let mut last_liveness = Instant::now();
    let outcome = loop {
        std::thread::sleep(Duration::from_millis(50));
        watch.poll();
        match teleop_runtime::stop_signal() {
            None => {}
            Some(libc::SIGTERM) => break Outcome::Stopped("SIGTERM"),
            Some(_) => break Outcome::Stopped("Ctrl-C"),
        }
        if duration.is_some_and(|d| started.elapsed() >= d) {
            break Outcome::Stopped("--duration elapsed");
        }
        kill_hung(&watch, &mut slots);
        if let Some(failure) = reap(&mut slots) {
            break Outcome::Failed(failure);
        }
        let mut restart_failure = None;
        for slot in slots.iter_mut() {
            if slot.restart_at.is_some_and(|t| Instant::now() >= t) {
                slot.restart_at = None;
                clean_dead_nodes(&config);
                match spawn(launch, slot.process, ipc, &recordings) {
                    Ok(child) => {
                        slot.child = Some(child);
                        slot.started = Instant::now();
                        slot.node_seen = false;
                        slot.warned_no_node = false;
                    }
                    Err(e) if slot.process.required => {
                        restart_failure = Some(format!("{e:#}"));
                    }
                    Err(e) => {
                        tracing::error!(process = %slot.process.name, "restart failed: {e:#}")
                    }
                }
            }
        }
        if let Some(failure) = restart_failure {
            break Outcome::Failed(failure);
        }
        if last_liveness.elapsed() >= Duration::from_secs(1) {
            last_liveness = Instant::now();
            check_liveness(&config, &mut slots, grace);
        }
    };
    match &outcome {
        Outcome::Stopped(why) => tracing::info!("stopping ({why})"),
        Outcome::Failed(why) => tracing::error!("stopping: {why}"),
    }
    // Processes that ended by themselves and were not restarted: the session ran without them.
    let missing: Vec<String> = slots
        .iter()
        .filter(|s| s.child.is_none() && s.restart_at.is_none())
        .map(|s| {
            format!(
                "MISSING {} process {}: {}, not restarted",
                if s.process.required {
                    "required"
                } else {
                    "optional"
                },
                s.process.name,
                s.last_exit.as_deref().unwrap_or("ended")
            )
        })
        .collect();
    stop_all(&mut slots, stop_timeout);
    clean_dead_nodes(&config);
    watch.poll();
    let restarts: Vec<(String, u32)> = slots
        .iter()
        .map(|s| (s.process.name.clone(), s.restarts))
        .collect();
    let recorded = recordings.lock().map(|r| r.clone()).unwrap_or_default();
    print!("{}", watch.report(started.elapsed(), &restarts, &recorded));
    for line in &missing {
        println!("{line}");
    }
    // Recording that stopped before the session did fails the session.
    match (outcome, super::summary::recording_stopped(&recorded)) {
        (Outcome::Stopped(_), Some(why)) => {
            Ok(Outcome::Failed(format!("RECORDING STOPPED: {why}")))
        }
        (outcome, _) => Ok(outcome),
    }
}

/// Stops every running process, in reverse start order.
fn stop_all(slots: &mut [Slot], timeout: Duration) {
    for slot in slots.iter_mut().rev() {
        if let Some(child) = slot.child.take() {
            stop(&slot.process.name, child, timeout);
        }
    }
}

/// Waits until the process just started reported its node's health, at most its
/// `ready_timeout_ms` (a process without it, or without a node, is not waited for); gives up
/// early on a stop signal or when the process exits, and warns when it went on without it.
fn wait_ready(watch: &mut super::summary::SessionWatch, slot: &mut Slot) {
    let p = slot.process;
    let Some(node) = p.node.as_deref().filter(|_| p.ready_timeout_ms > 0) else {
        return;
    };
    let deadline = slot.started + Duration::from_millis(p.ready_timeout_ms);
    loop {
        watch.poll();
        if watch.last_health(node).is_some_and(|t| t >= slot.started) {
            tracing::info!(process = %p.name, "ready: starting the next process");
            return;
        }
        let exited = slot
            .child
            .as_mut()
            .is_none_or(|c| c.try_wait().ok().flatten().is_some());
        if exited || teleop_runtime::stop_signal().is_some() {
            return;
        }
        if Instant::now() >= deadline {
            tracing::warn!(
                process = %p.name,
                "no health report within ready_timeout_ms = {}: starting the next process \
                 without it",
                p.ready_timeout_ms
            );
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Kills (SIGKILL) every process whose node reported its health since it started and then went
/// silent for longer than its `health_timeout_ms`: alive but hung. `reap` then restarts it per
/// its policy, as any process killed by a signal.
fn kill_hung(watch: &super::summary::SessionWatch, slots: &mut [Slot]) {
    for slot in slots.iter_mut() {
        let p = slot.process;
        let (Some(child), Some(node)) = (&slot.child, &p.node) else {
            continue;
        };
        if p.health_timeout_ms == 0 {
            continue;
        }
        let Some(last) = watch.last_health(node).filter(|&t| t >= slot.started) else {
            continue;
        };
        let silent = last.elapsed();
        if silent > Duration::from_millis(p.health_timeout_ms) {
            let pid = child.id();
            tracing::error!(
                process = %p.name,
                pid,
                node = %node,
                "hung: no health report for {} ms (health_timeout_ms = {}): killing it",
                silent.as_millis(),
                p.health_timeout_ms
            );
            // SAFETY: plain kill(2) on our own child's pid, which has not been reaped yet.
            unsafe {
                libc::kill(pid as libc::pid_t, libc::SIGKILL);
            }
            // Do not judge it again until it has been reaped and restarted.
            slot.started = Instant::now() + Duration::from_secs(3600);
        }
    }
}

/// Notices processes that ended; schedules restarts; returns why the session must stop if a
/// required process failed for good.
///
/// Every exit seen here is one `teleop launch` did not ask for (it stops processes itself only
/// in [`stop_all`]): even a clean exit (status 0, e.g. after a SIGTERM from someone else) left
/// the pipeline without that process, so `on-failure` restarts it like any failure, and a
/// required process that is not restarted ends the session as failed.
fn reap(slots: &mut [Slot]) -> Option<String> {
    for slot in slots.iter_mut() {
        let Some(child) = slot.child.as_mut() else {
            continue;
        };
        let status = match child.try_wait() {
            Ok(Some(status)) => status,
            Ok(None) => continue,
            Err(e) => {
                tracing::error!(process = %slot.process.name, "cannot query process: {e}");
                continue;
            }
        };
        let pid = child.id();
        slot.child = None;
        let p = slot.process;
        let what = describe(status);
        tracing::error!(
            process = %p.name,
            pid,
            "exited without being asked to: {what}"
        );
        slot.last_exit = Some(format!("exited by itself ({what})"));
        let wants_restart = match p.restart {
            Restart::Never => false,
            Restart::OnFailure | Restart::Always => true,
        };
        let now = Instant::now();
        let window = p.restart_window();
        slot.recent_restarts
            .retain(|&t| now.saturating_duration_since(t) < window);
        let recent = slot.recent_restarts.len();
        if wants_restart && recent < p.max_restarts as usize {
            let delay = p.restart_delay(recent);
            slot.restarts += 1;
            slot.recent_restarts.push(now);
            slot.restart_at = Some(now + delay);
            tracing::warn!(
                process = %p.name,
                "restarting in {} ms (restart {}/{} within {} s)",
                delay.as_millis(),
                recent + 1,
                p.max_restarts,
                p.restart_window_s
            );
        } else if p.required {
            let why = if wants_restart {
                format!(
                    "required process {} exited ({what}) after {recent} restarts within {} s",
                    p.name, p.restart_window_s
                )
            } else {
                format!(
                    "required process {} exited ({what}) and is not restarted",
                    p.name
                )
            };
            return Some(why);
        } else {
            tracing::warn!(
                process = %p.name,
                "not restarted: the session goes on without it (required = false)"
            );
        }
    }
    None
}

fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exit status {code}"),
        (None, Some(signal)) => format!("killed by signal {signal}"),
        _ => status.to_string(),
    }
}

fn spawn(
    launch: &Launch,
    process: &Process,
    ipc: &IpcSettings,
    recordings: &Arc<Mutex<Vec<String>>>,
) -> anyhow::Result<Child> {
    let program = launch.resolve_program(process);
    let mut command = Command::new(&program);
    // No scheduling settings that `teleop launch` itself was given: only the process's own.
    for name in teleop_runtime::realtime::ENV_ALL {
        command.env_remove(name);
    }
    command
        .args(&process.args)
        .current_dir(launch.base_dir())
        .envs(ipc.to_env())
        // Every process runs in its own namespace, or in none even if `teleop launch` was
        // given one in its environment.
        .env_remove(teleop_runtime::ENV_NAMESPACE)
        .envs(
            process
                .namespace
                .iter()
                .map(|ns| (teleop_runtime::ENV_NAMESPACE, ns.as_str())),
        )
        // The recorder stores the launch file as metadata.
        .env(
            "TELEOP_LAUNCH_FILE",
            std::fs::canonicalize(&launch.path).unwrap_or_else(|_| launch.path.clone()),
        )
        .envs(&process.env)
        // Its scheduling settings, applied by the process itself (so that only its
        // time-critical threads get the real-time priority, and a refusal is its own warning).
        .envs(process.realtime.to_env())
        // The child arms its parent-death signal again after exec (see
        // `teleop_runtime::follow_supervisor`): the kernel drops ours for binaries with file
        // capabilities.
        .env(
            teleop_runtime::ENV_SUPERVISOR_PID,
            std::process::id().to_string(),
        )
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        // Own process group: a terminal's Ctrl-C reaches only `teleop launch`, which then stops
        // the processes in order.
        .process_group(0);
    // SAFETY: prctl is async-signal-safe; it makes the child get SIGTERM if `teleop launch`
    // dies, so no process keeps driving hardware unsupervised.
    unsafe {
        command.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            Ok(())
        });
    }
    let mut child = command.spawn().map_err(|e| {
        anyhow::anyhow!(
            "{}: process {:?}: cannot start {}: {e}",
            launch.path.display(),
            process.name,
            program.display()
        )
    })?;
    tracing::info!(process = %process.name, pid = child.id(), program = %program.display(), "started");
    if let Some(out) = child.stdout.take() {
        forward(&process.name, out, recordings.clone())?;
    }
    if let Some(err) = child.stderr.take() {
        forward(&process.name, err, recordings.clone())?;
    }
    Ok(child)
}

/// Copies a child's output line by line to our stderr, tagged with the process name, and notes
/// what a recorder says for the session summary (the files it records, `recording stopped`).
fn forward(
    name: &str,
    stream: impl Read + Send + 'static,
    recordings: Arc<Mutex<Vec<String>>>,
) -> anyhow::Result<()> {
    let tag = name.to_string();
    std::thread::Builder::new()
        .name(format!("log-{name}"))
        .spawn(move || {
            for line in BufReader::new(stream).lines() {
                let Ok(line) = line else { break };
                if let Some(note) = super::summary::recorder_note(&line) {
                    if let Ok(mut r) = recordings.lock() {
                        r.push(note);
                    }
                }
                let mut err = std::io::stderr().lock();
                let _ = writeln!(err, "{tag:>12} | {line}");
            }
        })?;
    Ok(())
}

/// SIGINT, then SIGKILL if it has not stopped within `timeout`.
fn stop(name: &str, mut child: Child, timeout: Duration) {
    let pid = child.id() as libc::pid_t;
    // SAFETY: plain kill(2) on our own child's pid, which has not been reaped yet.
    unsafe {
        libc::kill(pid, libc::SIGINT);
    }
    let deadline = Instant::now() + timeout;
    loop {
        match child.try_wait() {
            Ok(Some(status)) => {
                tracing::info!(process = %name, "stopped: {}", describe(status));
                return;
            }
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            _ => break,
        }
    }
    tracing::warn!(process = %name, "did not stop within {} ms: killing it", timeout.as_millis());
    let _ = child.kill();
    let _ = child.wait();
}

/// Marks processes whose iceoryx2 node is alive, warns about ones that never showed it, and
/// cleans up nodes of processes that died.
fn check_liveness(config: &iceoryx2::config::Config, slots: &mut [Slot], grace: Duration) {
    let mut alive: Vec<(String, u32)> = Vec::new();
    let mut dead = false;
    let listed = Node::<Service>::list(config, |state| {
        match &state {
            NodeState::Alive(view) => {
                if let Some(details) = view.details() {
                    alive.push((
                        details.name().as_str().to_string(),
                        details.process_id().value() as u32,
                    ));
                }
            }
            NodeState::Dead(_) => dead = true,
            _ => {}
        }
        CallbackProgression::Continue
    });
    if let Err(e) = listed {
        tracing::warn!("cannot list iceoryx2 nodes: {e:?}");
        return;
    }
    if dead {
        clean_dead_nodes(config);
    }
    for slot in slots.iter_mut() {
        let (Some(child), Some(node)) = (&slot.child, &slot.process.node) else {
            continue;
        };
        let pid = child.id();
        if alive.iter().any(|(n, p)| n == node && *p == pid) {
            if !slot.node_seen {
                tracing::debug!(process = %slot.process.name, node = %node, "iceoryx2 node alive");
            }
            slot.node_seen = true;
        } else if slot.node_seen {
            tracing::warn!(process = %slot.process.name, node = %node, "iceoryx2 node disappeared while the process runs");
            slot.node_seen = false;
        } else if !slot.warned_no_node && slot.started.elapsed() > grace {
            tracing::warn!(
                process = %slot.process.name,
                node = %node,
                "running for {} s but its iceoryx2 node has not appeared (wrong IPC settings or hung?)",
                slot.started.elapsed().as_secs()
            );
            slot.warned_no_node = true;
        }
    }
}
