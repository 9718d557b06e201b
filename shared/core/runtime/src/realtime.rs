//! Real-time scheduling of a process's time-critical threads.
//!
//! `teleop launch` passes a process's `launch.toml` scheduling settings in the environment
//! ([`ENV_SCHED_POLICY`], [`ENV_SCHED_PRIORITY`], [`ENV_CPU_AFFINITY`], [`ENV_LOCK_MEMORY`],
//! [`ENV_NICE`]). [`setup_process`] (called by [`crate::NodeRuntime::new`]) applies the
//! process-wide part: memory locking, the nice value and the CPU affinity of the calling thread
//! (threads created later inherit them). [`enter_realtime`] gives the calling thread the named
//! policy and priority: nodes call it at the top of their time-critical threads (the EtherCAT
//! cycle and frame pump, the glove exchange loop), and only there, so that logging, health and
//! side threads never compete with them.
//!
//! When the process lacks the right (not root, no `CAP_SYS_NICE`, `RLIMIT_RTPRIO` 0) it says
//! so once, names the fix, and runs on at normal priority.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Once, OnceLock};

/// Scheduling policy: `fifo`, `rr` or `other`.
pub const ENV_SCHED_POLICY: &str = "TELEOP_SCHED_POLICY";
/// Real-time priority, 1..=99 (`fifo` and `rr` only).
pub const ENV_SCHED_PRIORITY: &str = "TELEOP_SCHED_PRIORITY";
/// CPUs the process may run on, comma-separated (`2,3`).
pub const ENV_CPU_AFFINITY: &str = "TELEOP_CPU_AFFINITY";
/// `1`: lock all current and future memory (`mlockall`), so a page fault never stalls a cycle.
pub const ENV_LOCK_MEMORY: &str = "TELEOP_LOCK_MEMORY";
/// Nice value, -20..=19 (threads that stay under `other`).
pub const ENV_NICE: &str = "TELEOP_NICE";
/// Every variable of the scheduling settings.
pub const ENV_ALL: [&str; 5] = [
    ENV_SCHED_POLICY,
    ENV_SCHED_PRIORITY,
    ENV_CPU_AFFINITY,
    ENV_LOCK_MEMORY,
    ENV_NICE,
];

/// A thread scheduling policy.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum SchedPolicy {
    /// `SCHED_OTHER`: the normal time-sharing policy.
    #[default]
    Other,
    /// `SCHED_FIFO`: runs until it blocks or a higher priority is runnable.
    Fifo,
    /// `SCHED_RR`: `SCHED_FIFO` with a time slice among equal priorities.
    Rr,
}

impl SchedPolicy {
    /// The name used in `launch.toml` and the environment.
    pub fn name(self) -> &'static str {
        match self {
            Self::Other => "other",
            Self::Fifo => "fifo",
            Self::Rr => "rr",
        }
    }

    /// Parses `fifo`, `rr` or `other`.
    pub fn parse(s: &str) -> Option<Self> {
        [Self::Other, Self::Fifo, Self::Rr]
            .into_iter()
            .find(|p| p.name() == s)
    }

    fn libc(self) -> libc::c_int {
        match self {
            Self::Other => libc::SCHED_OTHER,
            Self::Fifo => libc::SCHED_FIFO,
            Self::Rr => libc::SCHED_RR,
        }
    }
}

/// Highest CPU number accepted in an affinity list (`CPU_SETSIZE` - 1).
pub const MAX_CPU: usize = 1023;

/// A process's scheduling settings.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Realtime {
    /// Policy of the time-critical threads.
    pub policy: SchedPolicy,
    /// Their priority (1..=99 for `fifo`/`rr`, 0 for `other`).
    pub priority: u8,
    /// CPUs the process may use (empty: any).
    pub cpus: Vec<usize>,
    /// Lock all memory (`mlockall(MCL_CURRENT | MCL_FUTURE)`).
    pub lock_memory: bool,
    /// Nice value of the process (None: unchanged).
    pub nice: Option<i8>,
}

impl Realtime {
    /// Checks the combination; the error says which setting is wrong and why.
    pub fn check(&self) -> Result<(), String> {
        match self.policy {
            SchedPolicy::Other if self.priority != 0 => {
                return Err(format!(
                    "priority {} needs policy \"fifo\" or \"rr\" (\"other\" has none)",
                    self.priority
                ))
            }
            SchedPolicy::Fifo | SchedPolicy::Rr if !(1..=99).contains(&self.priority) => {
                return Err(format!(
                    "priority {} for policy {:?}: use 1..=99",
                    self.priority,
                    self.policy.name()
                ))
            }
            _ => {}
        }
        if let Some(cpu) = self.cpus.iter().find(|&&c| c > MAX_CPU) {
            return Err(format!("CPU {cpu}: at most {MAX_CPU}"));
        }
        if let Some(nice) = self.nice.filter(|n| !(-20..=19).contains(n)) {
            return Err(format!("nice {nice}: use -20..=19"));
        }
        Ok(())
    }

    /// Whether anything differs from the normal scheduling of a process.
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// The environment that passes these settings to a process (only what is set).
    pub fn to_env(&self) -> Vec<(&'static str, String)> {
        let mut env = Vec::new();
        if self.policy != SchedPolicy::Other {
            env.push((ENV_SCHED_POLICY, self.policy.name().to_string()));
            env.push((ENV_SCHED_PRIORITY, self.priority.to_string()));
        }
        if !self.cpus.is_empty() {
            let cpus: Vec<String> = self.cpus.iter().map(usize::to_string).collect();
            env.push((ENV_CPU_AFFINITY, cpus.join(",")));
        }
        if self.lock_memory {
            env.push((ENV_LOCK_MEMORY, "1".to_string()));
        }
        if let Some(nice) = self.nice {
            env.push((ENV_NICE, nice.to_string()));
        }
        env
    }

    /// Reads the settings from variables given by `var` (the inverse of [`Self::to_env`]).
    pub fn from_vars(var: impl Fn(&str) -> Option<String>) -> Result<Self, String> {
        let number = |name: &str, text: &str| -> Result<i64, String> {
            text.trim()
                .parse::<i64>()
                .map_err(|_| format!("{name}={text:?}: not a number"))
        };
        let mut rt = Self::default();
        if let Some(p) = var(ENV_SCHED_POLICY) {
            rt.policy = SchedPolicy::parse(p.trim())
                .ok_or_else(|| format!("{ENV_SCHED_POLICY}={p:?}: use fifo, rr or other"))?;
        }
        if let Some(p) = var(ENV_SCHED_PRIORITY) {
            rt.priority = u8::try_from(number(ENV_SCHED_PRIORITY, &p)?)
                .map_err(|_| format!("{ENV_SCHED_PRIORITY}={p:?}: use 1..=99"))?;
        }
        if let Some(list) = var(ENV_CPU_AFFINITY) {
            for cpu in list.split(',').filter(|c| !c.trim().is_empty()) {
                rt.cpus.push(
                    usize::try_from(number(ENV_CPU_AFFINITY, cpu)?)
                        .map_err(|_| format!("{ENV_CPU_AFFINITY}={list:?}: not a CPU number"))?,
                );
            }
        }
        if let Some(v) = var(ENV_LOCK_MEMORY) {
            rt.lock_memory = match v.trim() {
                "1" | "true" => true,
                "0" | "false" | "" => false,
                _ => return Err(format!("{ENV_LOCK_MEMORY}={v:?}: use 1 or 0")),
            };
        }
        if let Some(n) = var(ENV_NICE) {
            rt.nice = Some(
                i8::try_from(number(ENV_NICE, &n)?)
                    .map_err(|_| format!("{ENV_NICE}={n:?}: use -20..=19"))?,
            );
        }
        rt.check()?;
        Ok(rt)
    }
}

/// This process's settings, read from the environment once. Bad settings are reported once and
/// replaced by the normal scheduling (a node never fails to start over them).
pub fn settings() -> &'static Realtime {
    static SETTINGS: OnceLock<Realtime> = OnceLock::new();
    SETTINGS.get_or_init(|| {
        Realtime::from_vars(|name| std::env::var(name).ok()).unwrap_or_else(|e| {
            tracing::warn!("scheduling settings ignored: {e}; running at normal priority");
            Realtime::default()
        })
    })
}

/// What [`enter_realtime`] did for the calling thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// No real-time policy was asked for: the thread stays as it was.
    Normal,
    /// The thread now runs with the asked policy and priority.
    Realtime,
    /// The process may not use it (warned once): the thread runs on at normal priority.
    Refused,
}

/// Applies the process-wide settings of [`settings`] once: memory locking, the nice value and
/// the CPU affinity of the calling thread (threads created later inherit the last two). Each
/// refusal is reported once, with its fix; the process runs on.
pub fn setup_process() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let rt = settings();
        if rt.lock_memory {
            // SAFETY: mlockall has no memory preconditions.
            if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
                tracing::warn!(
                    "cannot lock memory: {}; running on unlocked (a page fault can stall a \
                     cycle). Fix: `setcap cap_ipc_lock+ep` on the executable, or `memlock \
                     unlimited` for the user in /etc/security/limits.conf",
                    std::io::Error::last_os_error()
                );
            }
        }
        if let Some(nice) = rt.nice {
            // SAFETY: setpriority has no memory preconditions; 0 is the calling thread.
            if unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, libc::c_int::from(nice)) } != 0 {
                tracing::warn!(
                    "cannot set nice {nice}: {}; running on at the inherited nice value. \
                     Fix: `setcap cap_sys_nice+ep` on the executable, or a `nice` limit for \
                     the user in /etc/security/limits.conf",
                    std::io::Error::last_os_error()
                );
            }
        }
        set_affinity(&rt.cpus);
    });
}

/// Gives the calling thread the policy and priority of [`settings`] (and its CPU affinity).
/// Call it at the top of a time-critical thread. Without the right, warns once per process
/// with the fix and leaves the thread at normal priority.
pub fn enter_realtime() -> Outcome {
    enter_realtime_with(settings())
}

/// [`enter_realtime`] with explicit settings (benchmarks compare policies in one process).
pub fn enter_realtime_with(rt: &Realtime) -> Outcome {
    setup_process();
    set_affinity(&rt.cpus);
    if rt.policy == SchedPolicy::Other {
        return Outcome::Normal;
    }
    let param = libc::sched_param {
        sched_priority: libc::c_int::from(rt.priority),
    };
    // SAFETY: `param` is a valid sched_param; pthread_self() is the calling thread.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), rt.policy.libc(), &param) };
    if rc == 0 {
        tracing::debug!(
            thread = std::thread::current().name().unwrap_or("?"),
            policy = rt.policy.name(),
            priority = rt.priority,
            "real-time scheduling"
        );
        return Outcome::Realtime;
    }
    static WARNED: AtomicBool = AtomicBool::new(false);
    if !WARNED.swap(true, Ordering::SeqCst) {
        let exe = std::env::current_exe()
            .map(|e| e.display().to_string())
            .unwrap_or_else(|_| "<executable>".into());
        tracing::warn!(
            "cannot use real-time scheduling ({} priority {}) for thread {:?}: {}; running on at \
             normal priority. Fix: `sudo setcap cap_sys_nice+ep {exe}` (together with any \
             capability it already has, e.g. `cap_net_raw,cap_sys_nice+ep`), or allow the user \
             real-time priorities in /etc/security/limits.conf (`<user> - rtprio {}`)",
            rt.policy.name(),
            rt.priority,
            std::thread::current().name().unwrap_or("?"),
            std::io::Error::from_raw_os_error(rc),
            rt.priority
        );
    }
    Outcome::Refused
}

/// Returns the calling thread to the normal policy (`SCHED_OTHER`), so that the threads it
/// starts afterwards (which inherit its policy) do not compete with the time-critical ones.
pub fn leave_realtime() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: `param` is a valid sched_param; pthread_self() is the calling thread. Lowering
    // the policy is always permitted.
    unsafe {
        libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_OTHER, &param);
    }
}

/// Pins the calling thread to `cpus` (nothing if empty); a failure is reported once.
fn set_affinity(cpus: &[usize]) {
    if cpus.is_empty() {
        return;
    }
    // SAFETY: cpu_set_t is plain data; CPU_ZERO/CPU_SET write inside it (cpus are checked to
    // be below CPU_SETSIZE by `Realtime::check`); sched_setaffinity reads it.
    let rc = unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_ZERO(&mut set);
        for &cpu in cpus.iter().filter(|&&c| c <= MAX_CPU) {
            libc::CPU_SET(cpu, &mut set);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
    };
    static WARNED: AtomicBool = AtomicBool::new(false);
    if rc != 0 && !WARNED.swap(true, Ordering::SeqCst) {
        tracing::warn!(
            ?cpus,
            "cannot set the CPU affinity: {}; running on any CPU. Fix: name CPUs this machine \
             has (and that its cpuset allows)",
            std::io::Error::last_os_error()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let pairs: Vec<(String, String)> = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |name| {
            pairs
                .iter()
                .find(|(k, _)| k == name)
                .map(|(_, v)| v.clone())
        }
    }

    #[test]
    fn environment_round_trip() {
        let rt = Realtime {
            policy: SchedPolicy::Fifo,
            priority: 80,
            cpus: vec![1, 3],
            lock_memory: true,
            nice: Some(-5),
        };
        let env = rt.to_env();
        let pairs: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
        assert_eq!(Realtime::from_vars(vars(&pairs)), Ok(rt));
        assert!(Realtime::default().to_env().is_empty());
        assert_eq!(Realtime::from_vars(vars(&[])), Ok(Realtime::default()));
    }

    #[test]
    fn bad_settings_are_named() {
        for (pairs, expect) in [
            (
                vec![(ENV_SCHED_POLICY, "deadline")],
                "use fifo, rr or other",
            ),
            (
                vec![(ENV_SCHED_POLICY, "fifo"), (ENV_SCHED_PRIORITY, "0")],
                "use 1..=99",
            ),
            (
                vec![(ENV_SCHED_POLICY, "rr"), (ENV_SCHED_PRIORITY, "100")],
                "use 1..=99",
            ),
            (vec![(ENV_SCHED_PRIORITY, "10")], "needs policy"),
            (vec![(ENV_SCHED_PRIORITY, "-1")], "use 1..=99"),
            (vec![(ENV_CPU_AFFINITY, "0,x")], "not a number"),
            (vec![(ENV_CPU_AFFINITY, "4096")], "at most 1023"),
            (vec![(ENV_NICE, "20")], "use -20..=19"),
            (vec![(ENV_NICE, "1000")], "use -20..=19"),
            (vec![(ENV_LOCK_MEMORY, "yes")], "use 1 or 0"),
        ] {
            let e = Realtime::from_vars(vars(&pairs)).unwrap_err();
            assert!(e.contains(expect), "{pairs:?}: {e}");
        }
    }

    /// (policy, rt_priority) of a thread of this process, from /proc (fields 41 and 40).
    fn thread_sched(tid: libc::pid_t) -> (i32, i32) {
        let stat = std::fs::read_to_string(format!("/proc/self/task/{tid}/stat")).unwrap();
        let after_comm = &stat[stat.rfind(')').unwrap() + 2..];
        let fields: Vec<&str> = after_comm.split(' ').collect();
        // Field 3 (state) is after_comm's first; rt_priority is field 40, policy 41.
        (
            fields[41 - 3].parse().unwrap(),
            fields[40 - 3].parse().unwrap(),
        )
    }

    fn is_root() -> bool {
        // SAFETY: geteuid has no preconditions.
        unsafe { libc::geteuid() == 0 }
    }

    #[test]
    fn a_thread_gets_the_policy_and_priority_asked_for() {
        let rt = Realtime {
            policy: SchedPolicy::Fifo,
            priority: 42,
            ..Default::default()
        };
        let rt2 = rt.clone();
        let (outcome, sched) = std::thread::spawn(move || {
            let outcome = enter_realtime_with(&rt);
            // SAFETY: gettid has no preconditions.
            let tid = unsafe { libc::gettid() };
            (outcome, thread_sched(tid))
        })
        .join()
        .unwrap();
        if is_root() {
            assert_eq!(outcome, Outcome::Realtime);
            assert_eq!(sched, (libc::SCHED_FIFO, 42));
        } else {
            assert_eq!(outcome, Outcome::Refused);
            assert_eq!(sched, (libc::SCHED_OTHER, 0));
        }
        // Leaving returns to the normal policy.
        let left = std::thread::spawn(move || {
            enter_realtime_with(&rt2);
            leave_realtime();
            // SAFETY: gettid has no preconditions.
            thread_sched(unsafe { libc::gettid() })
        })
        .join()
        .unwrap();
        assert_eq!(left, (libc::SCHED_OTHER, 0));
        // The caller's own thread is untouched.
        // SAFETY: gettid has no preconditions.
        let me = thread_sched(unsafe { libc::gettid() });
        assert_eq!(me.0, libc::SCHED_OTHER);
    }
}
