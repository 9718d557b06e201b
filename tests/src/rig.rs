//! The one test rig: processes started in a [`Sandbox`] (its own folder, iceoryx2 prefix and
//! root, sockets inside the folder), each with its output in a log file of its own, stopped with
//! SIGINT when the rig is dropped (in reverse order), their logs printed when a test fails.
//!
//! A rig runs a hand's (or the glove's) node against its simulator, a simulator alone for the
//! service commands of `teleop` (with [`Sandbox::cli`]), or any other set of executables; a
//! whole session is [`Sandbox::launch`]. [`Rig::logs`] is what a failure message shows.

use std::ffi::OsStr;
use std::fs::File;
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use crate::Sandbox;

/// Something whose output a failure message shows: a rig's processes, a session's launcher,
/// or a closure that gathers it.
pub trait Logs {
    /// The output so far, lossy UTF-8.
    fn logs(&self) -> String;
}

impl<F: Fn() -> String> Logs for F {
    fn logs(&self) -> String {
        self()
    }
}

/// One started executable, its stdout and stderr in a log file.
pub struct Process {
    name: String,
    child: Option<Child>,
    log: PathBuf,
}

impl Process {
    /// Starts `command` (stdin closed, `TELEOP_LOG=info` unless set) with its output in `log`.
    pub fn start(name: &str, mut command: Command, log: PathBuf) -> Self {
        let out = File::create(&log).unwrap_or_else(|e| panic!("{}: {e}", log.display()));
        if !command.get_envs().any(|(k, _)| k == "TELEOP_LOG") {
            command.env("TELEOP_LOG", "info");
        }
        let child = command
            .stdin(Stdio::null())
            .stdout(out.try_clone().expect("log file"))
            .stderr(out)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        Self {
            name: name.to_string(),
            child: Some(child),
            log,
        }
    }

    /// The name the rig knows it by.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Its output so far.
    pub fn log(&self) -> String {
        String::from_utf8_lossy(&std::fs::read(&self.log).unwrap_or_default()).into_owned()
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().map_or(0, Child::id)
    }

    /// True while it runs (it has not exited, and was not stopped).
    pub fn is_running(&mut self) -> bool {
        self.child
            .as_mut()
            .is_some_and(|c| c.try_wait().ok().flatten().is_none())
    }

    /// Sends SIGINT (as Ctrl-C would) and waits for the exit status.
    pub fn stop(&mut self) -> ExitStatus {
        let mut child = self
            .child
            .take()
            .unwrap_or_else(|| panic!("{} was stopped already", self.name));
        // SAFETY: kill(2) on our own, not yet reaped child.
        unsafe {
            libc::kill(child.id() as libc::pid_t, libc::SIGINT);
        }
        child
            .wait()
            .unwrap_or_else(|e| panic!("wait for {}: {e}", self.name))
    }

    /// Waits (up to `timeout`) until its log contains `text`; panics naming it, with the log.
    pub fn wait_log(&self, timeout: Duration, text: &str) {
        wait_text(&|| self.log(), &self.name, timeout, text);
    }
}

/// Waits (up to `timeout`) until `logs` (those of `whose`) contain `text`; panics saying so,
/// with the logs.
pub fn wait_text(logs: &dyn Logs, whose: &str, timeout: Duration, text: &str) {
    let start = Instant::now();
    while !logs.logs().contains(text) {
        assert!(
            start.elapsed() < timeout,
            "timed out after {timeout:?} waiting for {text:?} in the log of {whose}\n{}",
            logs.logs()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        if self.child.is_some() {
            self.stop();
        }
    }
}

/// A sandbox and the processes started in it.
pub struct Rig {
    /// Stopped in reverse order of starting, before the sandbox goes.
    processes: Vec<Process>,
    /// The folder and IPC settings of this rig alone.
    pub sandbox: Sandbox,
}

impl Rig {
    /// An empty rig in a fresh sandbox.
    pub fn new() -> Self {
        teleop_runtime::init_logging();
        Self {
            processes: Vec::new(),
            sandbox: Sandbox::new(),
        }
    }

    /// Starts `program args...` in the sandbox with its IPC settings, its output in
    /// `<name>.log` there.
    pub fn start(&mut self, name: &str, program: impl AsRef<OsStr>, args: &[&str]) -> &mut Process {
        let mut command = Command::new(program);
        command
            .args(args)
            .envs(self.sandbox.ipc.to_env())
            .current_dir(self.sandbox.dir.path());
        let log = self.sandbox.dir.path().join(format!("{name}.log"));
        self.processes.push(Process::start(name, command, log));
        self.processes.last_mut().expect("just started")
    }

    /// Writes `config` to `<name>.toml` in the sandbox and starts `program --config` it, as a
    /// node is started.
    pub fn start_node(
        &mut self,
        name: &str,
        program: impl AsRef<OsStr>,
        config: &str,
    ) -> &mut Process {
        let path = self.sandbox.write(&format!("{name}.toml"), config);
        let path = path.to_str().expect("a UTF-8 sandbox path").to_string();
        self.start(name, program, &["--config", &path])
    }

    /// Starts a simulator `program args...` and waits (up to 20 s) until its log says `ready`.
    pub fn start_sim(
        &mut self,
        name: &str,
        program: impl AsRef<OsStr>,
        args: &[&str],
        ready: &str,
    ) -> &mut Process {
        let process = self.start(name, program, args);
        process.wait_log(Duration::from_secs(20), ready);
        process
    }

    /// Starts an EtherCAT hand's simulator on a local socket, `teleop-sim-<device> --socket
    /// <sandbox>/<device>.sock` (its control socket is `<device>.ctl` beside it), as
    /// `sim-<device>`, and waits until it says it serves; returns the `sim:` transport that
    /// reaches it.
    pub fn start_socket_sim(&mut self, device: &str) -> String {
        let socket = self.path(&format!("{device}.sock")).display().to_string();
        self.start_sim(
            &format!("sim-{device}"),
            crate::bin(&format!("teleop-sim-{device}")),
            &["--socket", &socket],
            &format!("{device}: socket"),
        );
        format!("sim:{socket}")
    }

    /// The process started as `name`.
    pub fn process(&mut self, name: &str) -> &mut Process {
        self.processes
            .iter_mut()
            .find(|p| p.name == name)
            .unwrap_or_else(|| panic!("no process {name} in this rig"))
    }

    /// A path inside the sandbox (for a device, socket or file).
    pub fn path(&self, name: &str) -> PathBuf {
        self.sandbox.dir.path().join(name)
    }
}

impl Default for Rig {
    fn default() -> Self {
        Self::new()
    }
}

impl Logs for Rig {
    fn logs(&self) -> String {
        self.processes
            .iter()
            .map(|p| format!("---- {} log ----\n{}\n", p.name, p.log()))
            .collect()
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        while let Some(mut process) = self.processes.pop() {
            if process.child.is_some() {
                process.stop();
            }
            if std::thread::panicking() {
                eprintln!("---- {} log ----\n{}", process.name, process.log());
            }
        }
    }
}

/// The exit status and combined output of `command`, run to completion with stdin closed.
pub fn run(command: &mut Command) -> (bool, String) {
    let out = command
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("cannot run {command:?}: {e}"));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}
