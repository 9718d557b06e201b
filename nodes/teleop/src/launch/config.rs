//! `launch.toml`: the topology. Parsed and checked completely before anything starts; every
//! error names the file, the line and the field.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;
use teleop_runtime::realtime::{Realtime, SchedPolicy, MAX_CPU};
use teleop_runtime::{qualified, Namespace};
use toml::Spanned;

/// When a process that ended is started again.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Restart {
    /// Never.
    Never,
    /// Whenever it ends without `teleop launch` asking it to: a failure status, a signal, and
    /// also a clean exit (status 0, e.g. a SIGTERM from someone else), which left the pipeline
    /// without it all the same.
    OnFailure,
    /// Whenever it ends while the session runs (today the same as `on-failure`: the launcher
    /// asks a process to end only when the session stops).
    Always,
}

/// Session-wide settings (`[session]`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Session {
    /// How long a process may take to stop after SIGINT before it is killed.
    pub stop_timeout_ms: u64,
    /// How long a running process may take to show its iceoryx2 node before a warning.
    pub liveness_grace_ms: u64,
}

impl Default for Session {
    fn default() -> Self {
        Self {
            stop_timeout_ms: 3000,
            liveness_grace_ms: 5000,
        }
    }
}

/// One `[[process]]` entry as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProcess {
    name: Spanned<String>,
    program: Spanned<String>,
    #[serde(default)]
    args: Vec<String>,
    #[serde(default = "default_restart")]
    restart: Restart,
    #[serde(default = "default_max_restarts")]
    max_restarts: u32,
    #[serde(default = "default_restart_delay_ms")]
    restart_delay_ms: Spanned<u64>,
    #[serde(default = "default_restart_backoff_max_ms")]
    restart_backoff_max_ms: Spanned<u64>,
    #[serde(default = "default_restart_window_s")]
    restart_window_s: Spanned<u64>,
    #[serde(default = "default_health_timeout_ms")]
    health_timeout_ms: Spanned<u64>,
    #[serde(default = "default_ready_timeout_ms")]
    ready_timeout_ms: Spanned<u64>,
    #[serde(default = "default_true")]
    required: bool,
    node: Option<String>,
    namespace: Option<Spanned<String>>,
    #[serde(default)]
    env: BTreeMap<String, String>,
    sched_policy: Option<Spanned<String>>,
    sched_priority: Option<Spanned<i64>>,
    cpu_affinity: Option<Spanned<Vec<i64>>>,
    #[serde(default)]
    lock_memory: bool,
    nice: Option<Spanned<i64>>,
}

fn default_restart() -> Restart {
    Restart::OnFailure
}
fn default_max_restarts() -> u32 {
    5
}
fn default_restart_delay_ms() -> Spanned<u64> {
    Spanned::new(0..0, 500)
}
fn default_restart_backoff_max_ms() -> Spanned<u64> {
    Spanned::new(0..0, 10_000)
}
fn default_restart_window_s() -> Spanned<u64> {
    Spanned::new(0..0, 60)
}
fn default_health_timeout_ms() -> Spanned<u64> {
    Spanned::new(0..0, 3000)
}
fn default_ready_timeout_ms() -> Spanned<u64> {
    Spanned::new(0..0, 0)
}

/// Longest accepted time setting (one day): larger values are surely typos, and would overflow
/// the clock arithmetic.
pub const MAX_TIME_MS: u64 = 24 * 3600 * 1000;
fn default_true() -> bool {
    true
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLaunch {
    #[serde(default)]
    session: Session,
    #[serde(default)]
    process: Vec<RawProcess>,
}

/// A process to run, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Process {
    /// Unique name, used to tag its logs.
    pub name: String,
    /// The executable: a path (relative to the launch file), or a bare name looked up next to
    /// `teleop` and then in `PATH`.
    pub program: String,
    /// Arguments (relative paths are relative to the launch file's folder, the working directory).
    pub args: Vec<String>,
    /// Restart policy.
    pub restart: Restart,
    /// Most restarts within `restart_window_s` before giving up.
    pub max_restarts: u32,
    /// Pause before the first restart; it doubles with every further restart in the window.
    pub restart_delay_ms: u64,
    /// The longest pause before a restart.
    pub restart_backoff_max_ms: u64,
    /// Restarts older than this no longer count against `max_restarts`, nor for the backoff.
    pub restart_window_s: u64,
    /// A process whose node published health and then published none for this long is hung:
    /// it is killed and restarted per its policy (0: never).
    pub health_timeout_ms: u64,
    /// Before the next process starts, wait until this one's node reported its health (it is
    /// up: the recorder has subscribed to every topic), at most this long (0: do not wait).
    pub ready_timeout_ms: u64,
    /// When it fails for good, the whole session stops with a failure.
    pub required: bool,
    /// The iceoryx2 node name it creates, with its namespace (`left/glove`; None: it creates
    /// none). Written without the namespace in the file (default: the process name).
    pub node: Option<String>,
    /// The namespace of its topics (passed to it in `TELEOP_NAMESPACE`); None: the topics
    /// without a namespace.
    pub namespace: Option<Namespace>,
    /// Extra environment.
    pub env: BTreeMap<String, String>,
    /// Scheduling of its time-critical threads, memory locking, CPU affinity, nice value
    /// (`sched_policy`, `sched_priority`, `cpu_affinity`, `lock_memory`, `nice`), passed to it
    /// in the environment (see `teleop_runtime::realtime`).
    pub realtime: Realtime,
}

/// A checked launch file.
#[derive(Debug, Clone)]
pub struct Launch {
    /// The file it came from.
    pub path: PathBuf,
    /// Session settings.
    pub session: Session,
    /// Processes in start order (they stop in reverse order).
    pub processes: Vec<Process>,
}

/// Reads and checks a launch file.
pub fn load(path: &Path) -> anyhow::Result<Launch> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("{}: cannot read launch file: {e}", path.display()))?;
    parse(&text, path)
}

/// Parses and checks launch file text (`path` is used for messages and relative paths).
pub fn parse(text: &str, path: &Path) -> anyhow::Result<Launch> {
    let origin = path.display();
    let raw: RawLaunch = toml::from_str(text)
        .map_err(|e| anyhow::anyhow!("{origin}: {}", e.to_string().trim_end()))?;
    let at = |span: core::ops::Range<usize>| line_of(text, span.start);
    if raw.process.is_empty() {
        anyhow::bail!("{origin}: no [[process]] entries: nothing to launch");
    }
    for (field, ms) in [
        ("session.stop_timeout_ms", raw.session.stop_timeout_ms),
        ("session.liveness_grace_ms", raw.session.liveness_grace_ms),
    ] {
        if ms > MAX_TIME_MS {
            anyhow::bail!("{origin}: {field} = {ms}: at most {MAX_TIME_MS} (one day)");
        }
    }
    let mut processes: Vec<Process> = Vec::new();
    for p in raw.process {
        let name = p.name.get_ref().trim().to_string();
        let valid_name = !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
        if !valid_name {
            anyhow::bail!(
                "{origin}:{}: process.name {:?}: use letters, digits, '-' or '_'",
                at(p.name.span()),
                p.name.get_ref()
            );
        }
        if processes.iter().any(|q| q.name == name) {
            anyhow::bail!(
                "{origin}:{}: process.name {name:?} is used twice",
                at(p.name.span())
            );
        }
        if p.program.get_ref().trim().is_empty() {
            anyhow::bail!(
                "{origin}:{}: process.program of {name:?} is empty",
                at(p.program.span())
            );
        }
        // A time setting in `unit_ms` milliseconds per unit, at most a day.
        let time = |v: &Spanned<u64>, field: &str, unit_ms: u64| -> anyhow::Result<u64> {
            let value = *v.get_ref();
            if value.saturating_mul(unit_ms) > MAX_TIME_MS {
                anyhow::bail!(
                    "{origin}:{}: process.{field} of {name:?} = {value}: at most one day",
                    at(v.span())
                );
            }
            Ok(value)
        };
        let namespace = match &p.namespace {
            None => None,
            Some(ns) => Some(Namespace::new(ns.get_ref()).map_err(|e| {
                anyhow::anyhow!(
                    "{origin}:{}: process.namespace of {name:?}: {e}",
                    at(ns.span())
                )
            })?),
        };
        let restart_delay_ms = time(&p.restart_delay_ms, "restart_delay_ms", 1)?;
        let restart_backoff_max_ms = time(&p.restart_backoff_max_ms, "restart_backoff_max_ms", 1)?;
        let restart_window_s = time(&p.restart_window_s, "restart_window_s", 1000)?;
        let health_timeout_ms = time(&p.health_timeout_ms, "health_timeout_ms", 1)?;
        let ready_timeout_ms = time(&p.ready_timeout_ms, "ready_timeout_ms", 1)?;
        if ready_timeout_ms > 0 && p.node.as_deref() == Some("") {
            anyhow::bail!(
                "{origin}:{}: process.ready_timeout_ms of {name:?}: it has no node (`node = \"\"`) \
                 to report its health",
                at(p.ready_timeout_ms.span())
            );
        }
        // What `teleop launch` itself sets is not the launch file's to change: another IPC
        // prefix or root would take the process out of the session (and out of its one-writer
        // checks and its e-stop), another namespace out of its side.
        if let Some(key) = p.env.keys().find(|k| reserved_env(k)) {
            anyhow::bail!(
                "{origin}: process.env of {name:?}: {key} is set by `teleop launch` itself \
                 (use the process's `namespace`, `sched_*` keys or `teleop launch`'s own \
                 environment instead)"
            );
        }
        let realtime = realtime(&p, &|span, field, why| {
            anyhow::anyhow!("{origin}:{}: process.{field} of {name:?}: {why}", at(span))
        })?;
        processes.push(Process {
            node: match p.node {
                Some(n) if n.is_empty() => None,
                Some(n) => Some(qualified(namespace.as_ref(), &n)),
                None => Some(qualified(namespace.as_ref(), &name)),
            },
            namespace,
            name,
            program: p.program.into_inner(),
            args: p.args,
            restart: p.restart,
            max_restarts: p.max_restarts,
            restart_delay_ms,
            restart_backoff_max_ms,
            restart_window_s,
            health_timeout_ms,
            ready_timeout_ms,
            required: p.required,
            env: p.env,
            realtime,
        });
    }
    Ok(Launch {
        path: path.to_path_buf(),
        session: raw.session,
        processes,
    })
}

/// True for an environment variable `teleop launch` sets for every process itself.
fn reserved_env(key: &str) -> bool {
    [
        teleop_runtime::ENV_IPC_ROOT,
        teleop_runtime::ENV_IPC_PREFIX,
        teleop_runtime::ENV_NAMESPACE,
        teleop_runtime::ENV_SUPERVISOR_PID,
        "TELEOP_LAUNCH_FILE",
    ]
    .contains(&key)
        || teleop_runtime::realtime::ENV_ALL.contains(&key)
}

/// The scheduling settings of a process entry, checked; `error(span, field, why)` makes the
/// error that names the line and the field.
fn realtime(
    p: &RawProcess,
    error: &dyn Fn(core::ops::Range<usize>, &str, String) -> anyhow::Error,
) -> anyhow::Result<Realtime> {
    let policy = match &p.sched_policy {
        None => SchedPolicy::Other,
        Some(s) => SchedPolicy::parse(s.get_ref()).ok_or_else(|| {
            error(
                s.span(),
                "sched_policy",
                format!("{:?}: use \"fifo\", \"rr\" or \"other\"", s.get_ref()),
            )
        })?,
    };
    let priority = match &p.sched_priority {
        None if policy == SchedPolicy::Other => 0,
        None => {
            let span = p.sched_policy.as_ref().map(|s| s.span()).unwrap_or(0..0);
            return Err(error(
                span,
                "sched_priority",
                format!(
                    "missing: policy {:?} needs a priority 1..=99",
                    policy.name()
                ),
            ));
        }
        Some(v) => {
            let value = *v.get_ref();
            let range = if policy == SchedPolicy::Other {
                0..=0
            } else {
                1..=99
            };
            if !range.contains(&value) {
                return Err(error(
                    v.span(),
                    "sched_priority",
                    match policy {
                        SchedPolicy::Other => format!(
                            "{value}: needs sched_policy \"fifo\" or \"rr\" (\"other\" has no priority)"
                        ),
                        _ => format!("{value}: use 1..=99"),
                    },
                ));
            }
            value as u8
        }
    };
    let mut cpus = Vec::new();
    if let Some(list) = &p.cpu_affinity {
        if list.get_ref().is_empty() {
            return Err(error(
                list.span(),
                "cpu_affinity",
                "empty: name at least one CPU, or leave it out".into(),
            ));
        }
        for &cpu in list.get_ref() {
            match usize::try_from(cpu) {
                Ok(c) if c <= MAX_CPU => cpus.push(c),
                _ => {
                    return Err(error(
                        list.span(),
                        "cpu_affinity",
                        format!("CPU {cpu}: use 0..={MAX_CPU}"),
                    ))
                }
            }
        }
    }
    let nice = match &p.nice {
        None => None,
        Some(v) => Some(
            i8::try_from(*v.get_ref())
                .ok()
                .filter(|n| (-20..=19).contains(n))
                .ok_or_else(|| error(v.span(), "nice", format!("{}: use -20..=19", v.get_ref())))?,
        ),
    };
    let rt = Realtime {
        policy,
        priority,
        cpus,
        lock_memory: p.lock_memory,
        nice,
    };
    debug_assert_eq!(rt.check(), Ok(()));
    Ok(rt)
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

impl Process {
    /// The pause before a restart when `recent` restarts already happened within the window:
    /// `restart_delay_ms` doubled per earlier restart, at most `restart_backoff_max_ms` (and at
    /// least `restart_delay_ms`).
    pub fn restart_delay(&self, recent: usize) -> Duration {
        let factor = u32::try_from(recent)
            .ok()
            .and_then(|n| 1u64.checked_shl(n))
            .unwrap_or(u64::MAX);
        let ms = self
            .restart_delay_ms
            .saturating_mul(factor)
            .min(self.restart_backoff_max_ms.max(self.restart_delay_ms));
        Duration::from_millis(ms)
    }

    /// The restart window.
    pub fn restart_window(&self) -> Duration {
        Duration::from_secs(self.restart_window_s)
    }
}

impl Launch {
    /// The namespaces of the processes that have an iceoryx2 node, in order of first use, each
    /// once (`None`: the topics without a namespace).
    pub fn namespaces(&self) -> Vec<Option<Namespace>> {
        let mut out: Vec<Option<Namespace>> = Vec::new();
        for p in self.processes.iter().filter(|p| p.node.is_some()) {
            if !out.contains(&p.namespace) {
                out.push(p.namespace.clone());
            }
        }
        out
    }

    /// The folder relative paths are resolved against (and the processes' working directory).
    pub fn base_dir(&self) -> PathBuf {
        match self.path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }

    /// Where `process`'s executable is: a path relative to the launch file, the file of that
    /// name next to the running `teleop`, or the bare name for a `PATH` lookup.
    pub fn resolve_program(&self, process: &Process) -> PathBuf {
        if process.program.contains('/') {
            return self.base_dir().join(&process.program);
        }
        if let Some(dir) = std::env::current_exe()
            .ok()
            .and_then(|e| e.parent().map(PathBuf::from))
        {
            let beside = dir.join(&process.program);
            if beside.is_file() {
                return beside;
            }
        }
        PathBuf::from(&process.program)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(text: &str) -> anyhow::Result<Launch> {
        parse(text, Path::new("dir/launch.toml"))
    }

    #[test]
    fn defaults_and_order() {
        let l = parse_str(
            "[[process]]\nname = \"a\"\nprogram = \"teleop-a\"\n\n[[process]]\nname = \"b\"\nprogram = \"./bin/b\"\nrestart = \"never\"\nrequired = false\nnode = \"\"\n",
        )
        .unwrap();
        assert_eq!(l.processes.len(), 2);
        let a = &l.processes[0];
        assert_eq!(
            (a.restart, a.max_restarts, a.required),
            (Restart::OnFailure, 5, true)
        );
        assert_eq!(a.node.as_deref(), Some("a"));
        let b = &l.processes[1];
        assert_eq!(
            (b.restart, b.required, b.node.clone()),
            (Restart::Never, false, None)
        );
        assert_eq!(l.resolve_program(b), PathBuf::from("dir/./bin/b"));
        assert_eq!(l.session.stop_timeout_ms, 3000);
    }

    #[test]
    fn errors_name_file_line_and_field() {
        let e = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\nrestart = \"sometimes\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("dir/launch.toml: "), "{e}");
        assert!(e.contains("line 4") && e.contains("sometimes"), "{e}");

        let e = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\nargz = []\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown field `argz`") && e.contains("line 4"),
            "{e}"
        );

        let e = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\n\n[[process]]\nname = \"a\"\nprogram = \"y\"\n")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "dir/launch.toml:6: process.name \"a\" is used twice");

        let e = parse_str("[[process]]\nname = \"a b\"\nprogram = \"x\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("dir/launch.toml:2: process.name"), "{e}");

        let e = parse_str("[[process]]\nname = \"a\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field `program`"), "{e}");

        let e = parse_str("[session]\n").unwrap_err().to_string();
        assert!(e.contains("no [[process]]"), "{e}");
    }

    #[test]
    fn every_shipped_launch_file_runs_its_time_critical_processes_at_real_time_priority() {
        let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut files = vec![repo.join("launch.toml")];
        files.extend(
            std::fs::read_dir(repo.join("launch"))
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|e| e == "toml")),
        );
        assert!(files.len() >= 10, "{files:?}");
        let time_critical = [
            "teleop-glove",
            "teleop-revo2",
            "teleop-allegro",
            "teleop-shadow",
            "teleop-retarget",
            "teleop-feedback",
            "teleop-bridge",
        ];
        for file in files {
            let launch = load(&file).unwrap();
            for p in &launch.processes {
                if time_critical.contains(&p.program.as_str()) {
                    assert_eq!(
                        p.realtime.policy,
                        SchedPolicy::Fifo,
                        "{}: process {} runs without a real-time policy",
                        file.display(),
                        p.name
                    );
                }
            }
        }
    }

    #[test]
    fn env_that_teleop_launch_sets_itself_is_refused() {
        for key in ["TELEOP_IPC_PREFIX", "TELEOP_IPC_ROOT", "TELEOP_NAMESPACE"] {
            let e = parse_str(&format!(
                "[[process]]\nname = \"a\"\nprogram = \"x\"\nenv = {{ {key} = \"other_\" }}\n"
            ))
            .unwrap_err()
            .to_string();
            assert!(
                e.starts_with(&format!(
                    "dir/launch.toml: process.env of \"a\": {key} is set by `teleop launch` itself"
                )),
                "{e}"
            );
        }
        let ok = parse_str(
            "[[process]]\nname = \"a\"\nprogram = \"x\"\nenv = { RUST_LOG = \"debug\" }\n",
        )
        .unwrap();
        assert_eq!(ok.processes[0].env["RUST_LOG"], "debug");
    }

    #[test]
    fn restart_backoff_doubles_up_to_its_maximum() {
        let l = parse_str(
            "[[process]]\nname = \"a\"\nprogram = \"x\"\nrestart_delay_ms = 100\nrestart_backoff_max_ms = 1000\nrestart_window_s = 30\nhealth_timeout_ms = 0\n",
        )
        .unwrap();
        let p = &l.processes[0];
        let ms: Vec<u128> = (0..7).map(|n| p.restart_delay(n).as_millis()).collect();
        assert_eq!(ms, [100, 200, 400, 800, 1000, 1000, 1000]);
        assert_eq!(p.restart_delay(usize::MAX).as_millis(), 1000);
        assert_eq!(p.restart_window(), Duration::from_secs(30));
        assert_eq!(p.health_timeout_ms, 0);
        // Defaults: 500 ms doubling to 10 s, a 60 s window, hung after 3 s without health.
        let d = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\n").unwrap();
        let d = &d.processes[0];
        assert_eq!(d.restart_delay(0).as_millis(), 500);
        assert_eq!(d.restart_delay(9).as_millis(), 10_000);
        assert_eq!((d.restart_window_s, d.health_timeout_ms), (60, 3000));
        // Not waited for unless asked; a process without a node cannot be.
        assert_eq!(d.ready_timeout_ms, 0);
        let r = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\nready_timeout_ms = 5000\n")
            .unwrap();
        assert_eq!(r.processes[0].ready_timeout_ms, 5000);
        let e = parse_str(
            "[[process]]\nname = \"a\"\nprogram = \"x\"\nnode = \"\"\nready_timeout_ms = 5000\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("dir/launch.toml:5: process.ready_timeout_ms of \"a\": it has no node"),
            "{e}"
        );
    }

    #[test]
    fn huge_times_are_refused_not_overflowed() {
        for (field, value) in [
            ("restart_delay_ms", "18446744073709551615"),
            ("restart_backoff_max_ms", "86400001"),
            ("restart_window_s", "86401"),
            ("health_timeout_ms", "9999999999999"),
            ("ready_timeout_ms", "86400001"),
        ] {
            let e = parse_str(&format!(
                "[[process]]\nname = \"a\"\nprogram = \"x\"\n{field} = {value}\n"
            ))
            .unwrap_err()
            .to_string();
            assert!(
                e.starts_with(&format!("dir/launch.toml:4: process.{field} of \"a\" = ")),
                "{e}"
            );
        }
        let e = parse_str("[session]\nstop_timeout_ms = 18446744073709551615\n[[process]]\nname = \"a\"\nprogram = \"x\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("session.stop_timeout_ms"), "{e}");
        // Negative numbers are type errors, with their line.
        let e = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\nrestart_delay_ms = -1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 4"), "{e}");
    }

    #[test]
    fn scheduling_settings() {
        let l = parse_str(
            "[[process]]\nname = \"hand\"\nprogram = \"x\"\nsched_policy = \"fifo\"\nsched_priority = 80\ncpu_affinity = [1]\nlock_memory = true\nnice = -5\n\n[[process]]\nname = \"b\"\nprogram = \"y\"\n",
        )
        .unwrap();
        assert_eq!(
            l.processes[0].realtime,
            Realtime {
                policy: SchedPolicy::Fifo,
                priority: 80,
                cpus: vec![1],
                lock_memory: true,
                nice: Some(-5),
            }
        );
        assert!(l.processes[1].realtime.is_default());
        let rr = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\nsched_policy = \"rr\"\nsched_priority = 1\n")
            .unwrap();
        assert_eq!(rr.processes[0].realtime.policy, SchedPolicy::Rr);

        for (lines, expect) in [
            (
                "sched_policy = \"deadline\"\nsched_priority = 10\n",
                "dir/launch.toml:4: process.sched_policy of \"a\": \"deadline\": use",
            ),
            (
                "sched_policy = \"fifo\"\n",
                "dir/launch.toml:4: process.sched_priority of \"a\": missing",
            ),
            (
                "sched_policy = \"fifo\"\nsched_priority = 100\n",
                "dir/launch.toml:5: process.sched_priority of \"a\": 100: use 1..=99",
            ),
            (
                "sched_policy = \"fifo\"\nsched_priority = 0\n",
                "dir/launch.toml:5: process.sched_priority of \"a\": 0: use 1..=99",
            ),
            (
                "sched_priority = 10\n",
                "dir/launch.toml:4: process.sched_priority of \"a\": 10: needs sched_policy",
            ),
            (
                "cpu_affinity = [0, -1]\n",
                "dir/launch.toml:4: process.cpu_affinity of \"a\": CPU -1: use 0..=1023",
            ),
            (
                "cpu_affinity = []\n",
                "dir/launch.toml:4: process.cpu_affinity of \"a\": empty",
            ),
            (
                "nice = 20\n",
                "dir/launch.toml:4: process.nice of \"a\": 20: use -20..=19",
            ),
            (
                "nice = -99999999999\n",
                "dir/launch.toml:4: process.nice of \"a\": -99999999999: use -20..=19",
            ),
        ] {
            let e = parse_str(&format!(
                "[[process]]\nname = \"a\"\nprogram = \"x\"\n{lines}"
            ))
            .unwrap_err()
            .to_string();
            assert!(e.starts_with(expect), "{lines}: {e}");
        }
        let e = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\nlock_memory = 1\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 4"), "{e}");
    }

    #[test]
    fn namespaces() {
        let l = parse_str(
            "[[process]]\nname = \"left-glove\"\nprogram = \"teleop-glove\"\nnamespace = \"left\"\nnode = \"glove\"\n\n[[process]]\nname = \"recorder\"\nprogram = \"teleop-recorder\"\n\n[[process]]\nname = \"feedback\"\nprogram = \"teleop-feedback\"\nnamespace = \"cell2/right\"\n",
        )
        .unwrap();
        let left = &l.processes[0];
        assert_eq!(left.namespace.as_ref().map(Namespace::as_str), Some("left"));
        assert_eq!(left.node.as_deref(), Some("left/glove"));
        assert_eq!(l.processes[1].namespace, None);
        assert_eq!(l.processes[1].node.as_deref(), Some("recorder"));
        assert_eq!(l.processes[2].node.as_deref(), Some("cell2/right/feedback"));

        for (bad, why) in [
            ("\"\"", "empty"),
            ("\"/left\"", "empty path segment"),
            ("\"left/\"", "empty path segment"),
            ("\"Left\"", "'L'"),
            ("\"le ft\"", "' '"),
        ] {
            let e = parse_str(&format!(
                "[[process]]\nname = \"a\"\nprogram = \"x\"\nnamespace = {bad}\n"
            ))
            .unwrap_err()
            .to_string();
            assert!(
                e.starts_with("dir/launch.toml:4: process.namespace of \"a\": ") && e.contains(why),
                "{bad}: {e}"
            );
        }
        let e = parse_str("[[process]]\nname = \"a\"\nprogram = \"x\"\nnamespace = 3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 4") && e.contains("namespace"), "{e}");
    }
}
