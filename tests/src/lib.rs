//! Harness for end-to-end tests: runs the real executables (`teleop launch` and the nodes it
//! starts) as separate processes, each session in its own temporary folder and iceoryx2
//! root/prefix so that tests can run in parallel without seeing each other.
//!
//! One rig and one watcher serve every test: [`rig`] starts processes (a simulator, a node, the
//! CLI) in a [`Sandbox`] and keeps their logs, [`watch`] waits on a session's topics and says
//! what it saw, [`hand`] is a hand node under test on a rig, [`ecat`] an emulated EtherCAT bus
//! served from the test's own process, [`dataset`] the independent check of an exported LeRobot
//! dataset.
//!
//! The executables must be built first (`cargo build --workspace --bins`, which the README's
//! test command does); [`bin`] says so when one is missing.
//!
//! Must not depend on: node internals. Tests talk to the pipeline only through its topics and
//! its command line, as a user would; the one exception, [`haptics`], runs the stages' library
//! code in one process on a simulated clock (a closed loop across a delay, deterministic).

pub mod dataset;
pub mod ecat;
pub mod hand;
pub mod haptics;
pub mod netns;
pub mod rig;
pub mod stations;
pub mod watch;

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

pub use teleop_runtime::IpcSettings;
/// A simulator's `stats` answer read back ([`sim_stats`]).
pub use teleop_sim_kit::Stats;

/// Path of a workspace executable in the same target folder as the running test, or in
/// `TELEOP_TEST_BIN_DIR` when that is set (to run a test against the binaries of another
/// build, e.g. an older commit's, and see it fail there).
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/<test> -> target/<profile>/<name>
    let dir = match std::env::var_os("TELEOP_TEST_BIN_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => exe
            .parent()
            .and_then(Path::parent)
            .expect("test executable lives in target/<profile>/deps")
            .to_path_buf(),
    };
    let path = dir.join(name);
    assert!(
        path.is_file(),
        "{} is not built: run `cargo build --workspace --bins` first (the README's test command does)",
        path.display()
    );
    path
}

/// A temporary folder with its own iceoryx2 settings.
pub struct Sandbox {
    /// The folder (removed on drop).
    pub dir: tempfile::TempDir,
    /// IPC settings no other test uses.
    pub ipc: IpcSettings,
}

impl Sandbox {
    /// A fresh sandbox.
    pub fn new() -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let ipc = IpcSettings::isolated(&dir.path().join("iceoryx2"));
        Self { dir, ipc }
    }

    /// Writes `text` to `name` inside the sandbox and returns its path.
    pub fn write(&self, name: &str, text: &str) -> PathBuf {
        let path = self.dir.path().join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).expect("create dir");
        }
        std::fs::write(&path, text).expect("write file");
        path
    }

    /// The repository's top folder.
    pub fn repo() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
    }

    /// Writes the default simulated session (the repository's `launch.toml` and `config/`) into
    /// the sandbox with its device paths, socket and recording folder moved inside the sandbox,
    /// so that sessions of parallel tests never meet. `patch` may change the launch file text.
    /// Returns the launch file's path.
    pub fn default_session(&self, patch: impl Fn(String) -> String) -> PathBuf {
        let repo = Self::repo();
        let dir = self.dir.path();
        let relocate = |text: String| {
            text.replace(
                "/tmp/teleop-glove",
                &dir.join("glove").display().to_string(),
            )
            .replace(
                "/tmp/teleop-revo2.sock",
                &dir.join("revo2.sock").display().to_string(),
            )
        };
        for name in [
            "glove.toml",
            "revo2.toml",
            "revo2/retarget.toml",
            "revo2/feedback.toml",
            "hands/revo2.toml",
            "hands/allegro.toml",
            "hands/shadow.toml",
        ] {
            let text =
                std::fs::read_to_string(repo.join("config").join(name)).expect("config file");
            self.write(&format!("config/{name}"), &relocate(text));
        }
        let launch = std::fs::read_to_string(repo.join("launch.toml")).expect("launch.toml");
        self.write("launch.toml", &patch(relocate(launch)))
    }

    /// Writes the bimanual session (`launch/bimanual.toml`) into the sandbox, as
    /// [`Sandbox::session`] does. Returns the launch file's path.
    pub fn bimanual_session(&self) -> PathBuf {
        self.session("launch/bimanual.toml")
    }

    /// Writes the session of the repository's launch file `launch` (a path relative to the
    /// repository, e.g. `launch/allegro.toml`) and every file of `config/`, at the same places,
    /// into the sandbox with every `/tmp/teleop-...` device path, socket and control socket moved
    /// inside the sandbox (`/tmp/teleop-glove` becomes `<sandbox>/teleop-glove`); its recordings
    /// go to `recordings/` in the sandbox. Returns the launch file's path.
    pub fn session(&self, launch: &str) -> PathBuf {
        let repo = Self::repo();
        let inside = format!("{}/teleop-", self.dir.path().display());
        let relocate = |text: String| text.replace("/tmp/teleop-", &inside);
        let mut folders = vec![PathBuf::from("config")];
        while let Some(folder) = folders.pop() {
            for entry in std::fs::read_dir(repo.join(&folder)).expect("config folder") {
                let path = entry.expect("config entry").path();
                let name = folder.join(path.file_name().expect("file name"));
                if path.is_dir() {
                    folders.push(name);
                } else if path.extension().is_some_and(|e| e == "toml") {
                    let text = std::fs::read_to_string(&path).expect("config file");
                    self.write(&name.display().to_string(), &relocate(text));
                }
            }
        }
        let text =
            std::fs::read_to_string(repo.join(launch)).unwrap_or_else(|e| panic!("{launch}: {e}"));
        self.write(launch, &relocate(text))
    }

    /// Sends one command to a simulator's control socket (a path inside the sandbox) and
    /// returns its one-line answer.
    pub fn control(&self, socket: &str, command: &str) -> String {
        control(&self.dir.path().join(socket), command)
    }

    /// Sends one command to a simulator's control socket and returns its answer, asserting it
    /// starts with `ok`.
    pub fn control_ok(&self, socket: &str, command: &str) -> String {
        let reply = self.control(socket, command);
        assert!(reply.starts_with("ok"), "{socket}: {command}: {reply}");
        reply
    }

    /// Pid of the live iceoryx2 node `name` (from `teleop nodes`).
    pub fn pid_of(&self, name: &str) -> Option<u32> {
        let out = String::from_utf8(self.run_teleop(&["nodes"]).stdout).ok()?;
        out.lines()
            .find(|l| l.split_whitespace().next() == Some(name) && l.contains("alive"))
            .and_then(|l| l.split_whitespace().nth(2)?.parse().ok())
    }

    /// Pid of a running process whose command line contains `needle` (for processes without an
    /// iceoryx2 node, such as the device simulators).
    pub fn pid_with_arg(needle: &str) -> Option<u32> {
        std::fs::read_dir("/proc").ok()?.flatten().find_map(|e| {
            let pid: u32 = e.file_name().to_str()?.parse().ok()?;
            let cmd = std::fs::read(e.path().join("cmdline")).ok()?;
            let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
            cmd.contains(needle).then_some(pid)
        })
    }

    /// A `teleop` command with this sandbox's IPC settings.
    pub fn teleop(&self) -> Command {
        let mut cmd = Command::new(bin("teleop"));
        cmd.envs(self.ipc.to_env()).current_dir(self.dir.path());
        cmd
    }

    /// Runs `teleop args...` to completion: whether it succeeded, and its stdout then stderr.
    pub fn cli(&self, args: &[&str]) -> (bool, String) {
        rig::run(self.teleop().args(args))
    }

    /// Runs `teleop args...` to completion.
    pub fn run_teleop(&self, args: &[&str]) -> Output {
        self.teleop()
            .args(args)
            .stdin(Stdio::null())
            .output()
            .expect("run teleop")
    }

    /// Starts `teleop launch FILE` in the background; its output goes to `launch.log` in the
    /// sandbox (printed when the session is dropped during a failing test).
    pub fn launch(&self, file: &Path) -> Session {
        self.launch_with(file, self.teleop())
    }

    /// Starts `teleop launch FILE` inside the network namespace `ns` (a station on its own
    /// "machine"), as [`launch`](Self::launch) does.
    pub fn launch_in(&self, ns: &netns::Netns, file: &Path) -> Session {
        let mut cmd = ns.command(bin("teleop"));
        cmd.envs(self.ipc.to_env()).current_dir(self.dir.path());
        netns::die_with_parent(&mut cmd);
        self.launch_with(file, cmd)
    }

    fn launch_with(&self, file: &Path, mut teleop: Command) -> Session {
        let log_path = self.dir.path().join("launch.log");
        let log = File::create(&log_path).expect("log file");
        let child = teleop
            .arg("launch")
            .arg(file)
            .env("TELEOP_LOG", "info")
            .stdin(Stdio::null())
            .stdout(log.try_clone().expect("log"))
            .stderr(log)
            .spawn()
            .expect("start teleop launch");
        Session {
            child: Some(child),
            log_path,
        }
    }
}

impl Default for Sandbox {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for Sandbox {
    fn drop(&mut self) {
        self.ipc.remove_shared_memory();
    }
}

/// A running `teleop launch`.
pub struct Session {
    child: Option<Child>,
    log_path: PathBuf,
}

impl Session {
    /// The session's combined output so far.
    pub fn log(&self) -> String {
        // Lossy: a process may print bytes that are not UTF-8.
        String::from_utf8_lossy(&std::fs::read(&self.log_path).unwrap_or_default()).into_owned()
    }

    /// Kills the launcher with SIGKILL (no chance to stop its processes) and reaps it.
    pub fn kill(&mut self) {
        let mut child = self.child.take().expect("session still running");
        let _ = child.kill();
        let _ = child.wait();
    }

    /// Sends SIGINT (as Ctrl-C would) and waits for the exit status.
    pub fn stop(&mut self) -> std::process::ExitStatus {
        let mut child = self.child.take().expect("session still running");
        // SAFETY: kill(2) on our own, not yet reaped child.
        unsafe {
            libc::kill(child.id() as libc::pid_t, libc::SIGINT);
        }
        child.wait().expect("wait for teleop launch")
    }

    /// Waits (up to `timeout`) for the launcher to exit on its own.
    pub fn wait_exit(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        let child = self.child.as_mut()?;
        let start = Instant::now();
        while start.elapsed() < timeout {
            if let Ok(Some(status)) = child.try_wait() {
                self.child = None;
                return Some(status);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        None
    }
}

impl rig::Logs for Session {
    fn logs(&self) -> String {
        format!("---- teleop launch output ----\n{}", self.log())
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        if self.child.is_some() {
            self.stop();
        }
        if std::thread::panicking() {
            eprintln!("---- teleop launch output ----\n{}", self.log());
        }
    }
}

/// Sends one command to the simulator's control socket at `path` and returns its one-line
/// answer.
pub fn control(path: &Path, command: &str) -> String {
    use std::io::{BufRead, BufReader, Write};
    let mut stream = std::os::unix::net::UnixStream::connect(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    writeln!(stream, "{command}").expect("send command");
    stream
        .shutdown(std::net::Shutdown::Write)
        .expect("shutdown");
    let mut reply = String::new();
    BufReader::new(stream).read_line(&mut reply).expect("reply");
    reply
}

/// The `stats` of the simulator whose control socket is at `path`, read back (`stats["key"]`).
pub fn sim_stats(path: &Path) -> Stats {
    let reply = control(path, "stats");
    Stats::parse(reply.trim_end()).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The repository's Revo2 hand profile (the tests' hand where the hand does not matter).
pub fn revo2_profile() -> String {
    Sandbox::repo()
        .join("config/hands/revo2.toml")
        .display()
        .to_string()
}

/// A scripted device's clock: whether its period ending at `next` is over (then `next` moves one
/// `period` on); else sleeps until it is and says no, so that the caller serves its bus first.
pub fn period_due(next: &mut Instant, period: Duration) -> bool {
    let now = Instant::now();
    if now < *next {
        std::thread::sleep(*next - now);
        return false;
    }
    *next += period;
    true
}

/// A normalised position command for the Revo2's six joints, each with `speed_limit` (per
/// second; 0 sets none).
pub fn revo2_position_command(targets: [f32; 6], speed_limit: f32) -> teleop_msgs::HandCommand {
    use teleop_msgs::{control_mode, device_model, units, HandCommand};
    let mut c = HandCommand {
        hand_model: device_model::REVO2,
        joint_count: 6,
        control_mode: control_mode::POSITION,
        units: units::NORMALISED,
        ..Default::default()
    };
    for (j, t) in c.joints.iter_mut().zip(targets) {
        j.target = t;
        j.speed_limit = speed_limit;
    }
    c
}

/// A node configuration for a test's sandbox: `text` naming the repository's Revo2 profile.
pub fn with_profile(text: &str) -> String {
    format!("hand_profile = {:?}\n{text}", revo2_profile())
}

/// A launch file's `[[process]]` `name`: the node `teleop-<name>` with `--config <name>.toml`,
/// then `settings` (TOML lines of its restart policy).
pub fn node_process(name: &str, settings: &str) -> String {
    format!(
        "\n[[process]]\nname = \"{name}\"\nprogram = \"teleop-{name}\"\nargs = [\"--config\", \"{name}.toml\"]\n{settings}"
    )
}

/// A launch file of one process, `retarget`: `teleop-retarget` on the Revo2 profile.
pub fn retarget_launch() -> String {
    format!(
        "[[process]]\nname = \"retarget\"\nprogram = \"teleop-retarget\"\nargs = [\"--profile\", {:?}]\n",
        revo2_profile()
    )
}

/// A force-feedback configuration the tests that run `teleop-feedback` share.
pub const FEEDBACK_TOML: &str = r#"
tactile_timeout_ms = 100
hand_timeout_ms = 100
tick_ms = 10
[feedback]
contact_threshold_n = 0.3
gain_per_n = 250.0
max_force = 800
stale_ramp_s = 0.2
"#;

/// A live glove sample whose six positions are `i` modulo 1000.
pub fn glove(i: u64) -> teleop_msgs::GloveState {
    teleop_msgs::GloveState {
        raw_position: [(i % 1000) as u16; 6],
        link_up: 1,
        ..Default::default()
    }
}

/// Polls `f` every 5 ms until it returns `Some`, or panics with `what` after `timeout`.
pub fn wait_for<T>(timeout: Duration, what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let start = Instant::now();
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(
            start.elapsed() < timeout,
            "timed out after {timeout:?} waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// What the benchmark programs (`tests/examples/bench_*.rs`) share.
pub mod bench {
    use std::time::{Duration, Instant};

    use teleop_msgs::{GloveForceCommand, GloveState, HandState};
    use teleop_runtime::{now_ns, NodeRuntime, Publisher, Subscriber};

    /// Starts `program --config CONFIG [extra...]` from this workspace with the sandbox's IPC
    /// settings, in the sandbox, its output discarded (a benchmark prints only its results).
    pub fn spawn_quiet(
        sandbox: &crate::Sandbox,
        program: &str,
        config: &str,
        extra: &[&str],
    ) -> std::process::Child {
        use std::process::{Command, Stdio};
        Command::new(crate::bin(program))
            .args(["--config", config])
            .args(extra)
            .envs(sandbox.ipc.to_env())
            .current_dir(sandbox.dir.path())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {program}: {e}"))
    }

    /// SIGINT to every child, then waits for each (they stop cleanly together).
    pub fn interrupt_all(children: &mut [std::process::Child]) {
        for child in children.iter() {
            // SAFETY: kill(2) on our own, not yet reaped child.
            unsafe {
                libc::kill(child.id() as libc::pid_t, libc::SIGINT);
            }
        }
        for child in children.iter_mut() {
            let _ = child.wait();
        }
    }

    /// What [`drive_glove`] measured.
    pub struct GloveDrive {
        /// Each step of the middle channel: its publish stamp and whether it closed the finger.
        pub steps: Vec<(u64, bool)>,
        /// `hand/state` stamp - origin (the hand node alone), ns.
        pub state_latency: Vec<u64>,
        /// `glove/force_command` receive time - origin (hand sample -> glove force), ns.
        pub force_latency: Vec<u64>,
    }

    /// Publishes `glove/state` at 300 Hz for `warm_up` + `seconds`, stepping channel `middle`
    /// between 900 and 300 every 200-300 ms (random) once warm, and collects the hand-state and
    /// glove-force latencies meanwhile; `measuring` is told on every sample whether the warm-up
    /// is over.
    pub fn drive_glove(
        warm_up: Duration,
        seconds: u64,
        middle: usize,
        glove: &mut Publisher<GloveState>,
        states: &Subscriber<HandState>,
        forces: &Subscriber<GloveForceCommand>,
        mut measuring: impl FnMut(bool),
    ) -> GloveDrive {
        let mut out = GloveDrive {
            steps: Vec::new(),
            state_latency: Vec::new(),
            force_latency: Vec::new(),
        };
        let mut raw = [900u16; 6];
        let mut rng = 0x2545_F491_4F6C_DD1Du64;
        let mut next_step = Instant::now() + warm_up;
        let start = Instant::now();
        let mut period = Instant::now();
        while start.elapsed() < warm_up + Duration::from_secs(seconds) {
            let warm = start.elapsed() >= warm_up;
            measuring(warm);
            let mut stepped = None;
            if warm && Instant::now() >= next_step {
                let closing = raw[middle] == 900;
                raw[middle] = if closing { 300 } else { 900 };
                stepped = Some(closing);
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                next_step = Instant::now() + Duration::from_millis(200 + rng % 100);
            }
            let header = glove
                .publish(&GloveState {
                    raw_position: raw,
                    link_up: 1,
                    ..Default::default()
                })
                .expect("publish glove/state");
            if let Some(closing) = stepped {
                out.steps.push((header.stamp_ns, closing));
            }
            states.drain(|s| {
                if warm && s.link_up == 1 && s.header.origin_ns != 0 {
                    out.state_latency
                        .push(s.header.stamp_ns.saturating_sub(s.header.origin_ns));
                }
            });
            forces.drain(|f| {
                if warm && f.header.origin_ns != 0 {
                    out.force_latency
                        .push(now_ns().saturating_sub(f.header.origin_ns));
                }
            });
            period += Duration::from_micros(3333);
            if let Some(wait) = period.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
        measuring(false);
        out
    }

    /// Runs a hand's pipeline in `sandbox`: the node `teleop-<hand>` (`config/<hand>.toml` and
    /// `node_args`), retargeting without filter or speed limit (`config/<hand>/retarget.toml`
    /// changed so) and force feedback; drives it with [`drive_glove`] (the arguments as there)
    /// from the IPC node `bench-<hand>`, then interrupts the processes. Returns the drive.
    pub fn drive_hand_pipeline(
        sandbox: &crate::Sandbox,
        hand: &str,
        node_args: &[&str],
        warm_up: Duration,
        seconds: u64,
        middle: usize,
        measuring: impl FnMut(bool),
    ) -> GloveDrive {
        let retarget = std::fs::read_to_string(
            sandbox
                .dir
                .path()
                .join(format!("config/{hand}/retarget.toml")),
        )
        .expect("the hand's retarget.toml")
        .replace("max_speed = 2.0", "max_speed = 100.0")
        .replace("min_cutoff_hz = 1.5", "min_cutoff_hz = 1000.0")
        .replace("beta = 0.5", "beta = 0.0");
        let retarget_bench = format!("config/{hand}/retarget-bench.toml");
        sandbox.write(&retarget_bench, &retarget);
        let node = NodeRuntime::new(&format!("bench-{hand}"), &sandbox.ipc).expect("IPC node");
        let mut glove: Publisher<GloveState> = node.publisher().expect("glove/state");
        let states: Subscriber<HandState> = node.subscriber().expect("hand/state");
        let forces: Subscriber<GloveForceCommand> = node.subscriber().expect("glove/force_command");
        let mut children = [
            spawn_quiet(
                sandbox,
                &format!("teleop-{hand}"),
                &format!("config/{hand}.toml"),
                node_args,
            ),
            spawn_quiet(sandbox, "teleop-retarget", &retarget_bench, &[]),
            spawn_quiet(
                sandbox,
                "teleop-feedback",
                &format!("config/{hand}/feedback.toml"),
                &[],
            ),
        ];
        let drive = drive_glove(
            warm_up, seconds, middle, &mut glove, &states, &forces, measuring,
        );
        interrupt_all(&mut children);
        drive
    }

    /// For each glove step `(stamp_ns, closing)` of [`drive_glove`]: the time from the step to
    /// the first of the device's samples `seen` (`(t_ns, value)`, in time order) whose value
    /// moved more than `threshold` from the one before the step (up when closing, down when
    /// opening). Steps with no sample before them or no such move are left out.
    pub fn step_reactions(seen: &[(u64, i32)], steps: &[(u64, bool)], threshold: i32) -> Vec<u64> {
        let mut out = Vec::new();
        for &(t, closing) in steps {
            let i = seen.partition_point(|&(at, _)| at < t);
            let Some(before) = i.checked_sub(1).map(|k| seen[k].1) else {
                continue;
            };
            let moved = seen[i..].iter().find(|&&(_, v)| {
                if closing {
                    v - before > threshold
                } else {
                    v - before < -threshold
                }
            });
            if let Some(&(at, _)) = moved {
                out.push(at - t);
            }
        }
        out
    }

    /// `periods > A ms / > B ms / > C ms: a / b / c of n` for the limits `limits_ms`.
    pub fn late_periods(periods: &[u64], limits_ms: [f64; 3]) -> String {
        let late = |ms: f64| periods.iter().filter(|&&p| p as f64 > ms * 1e6).count();
        let [a, b, c] = limits_ms;
        format!(
            "periods > {a} ms / > {b} ms / > {c} ms: {} / {} / {} of {}",
            late(a),
            late(b),
            late(c),
            periods.len()
        )
    }

    /// `p50 .. p99 .. max ..` of samples in nanoseconds, printed in microseconds (`-` for none).
    pub fn percentiles(mut v: Vec<u64>) -> String {
        if v.is_empty() {
            return "-".into();
        }
        v.sort_unstable();
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1000.0;
        format!(
            "p50 {:>8.1}  p99 {:>8.1}  max {:>8.1}",
            at(0.5),
            at(0.99),
            at(1.0)
        )
    }

    /// The 1-minute load average: the machine is shared, and other work skews the numbers.
    pub fn loadavg() -> String {
        std::fs::read_to_string("/proc/loadavg")
            .ok()
            .and_then(|s| s.split_whitespace().next().map(str::to_string))
            .unwrap_or_else(|| "?".into())
    }
}
