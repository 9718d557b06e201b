//! Network namespaces with a veth pair for the tests that run EtherCAT over a real link (the
//! emulator on a raw socket at one end, a master at the other) or two stations as two machines,
//! and how such a privileged test skips, or fails under `TELEOP_REQUIRE_CHECKS`, where it cannot
//! run.

use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Child, Command, Output};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

/// Why these tests cannot run here, if they cannot.
pub fn skip_reason() -> Option<String> {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return Some("not running as root (needs CAP_NET_ADMIN to make network namespaces and veth pairs, CAP_NET_RAW for raw sockets)".into());
    }
    match Command::new("ip").arg("-V").output() {
        Ok(o) if o.status.success() => {}
        _ => return Some("`ip` (iproute2) is not available".into()),
    }
    // unshare(CLONE_NEWNET) in a thread of its own: namespaces are per thread, and this one ends.
    let unshared = std::thread::spawn(|| {
        // SAFETY: moves only this short-lived thread into a new network namespace.
        if unsafe { libc::unshare(libc::CLONE_NEWNET) } == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error())
        }
    })
    .join();
    match unshared {
        Ok(Ok(())) => None,
        Ok(Err(e)) => Some(format!("unshare(CLONE_NEWNET) fails here: {e}")),
        Err(_) => Some("the thread trying unshare(CLONE_NEWNET) panicked".into()),
    }
}

/// Prints why a test cannot run and lets it return; under `TELEOP_REQUIRE_CHECKS` (set by
/// `.ci/run` as root, where these independent checks must run) fails instead.
pub fn skip(reason: &str) {
    assert!(
        std::env::var_os("TELEOP_REQUIRE_CHECKS").is_none(),
        "required: {reason}"
    );
    eprintln!("skipped: {reason}");
}

/// Returns from the calling test (after [`skip`]) unless it can make network namespaces.
#[macro_export]
macro_rules! skip_unless_privileged {
    () => {
        if let Some(reason) = $crate::netns::skip_reason() {
            $crate::netns::skip(&reason);
            return;
        }
    };
}

/// Runs `cmd` to its end; panics naming it, its status and its output unless it succeeded.
pub fn run(cmd: &mut Command) -> Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed ({}): {}{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Kills the child with SIGKILL if this test process dies first (it is a `ip netns exec`
/// child that would otherwise keep running in the namespace).
pub fn die_with_parent(cmd: &mut Command) -> &mut Command {
    // SAFETY: prctl is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        })
    }
}

/// A network namespace with a veth pair `ecm0` (master side) / `ecs0` (SubDevice side), both
/// up; deleted on drop.
pub struct Netns {
    name: String,
}

impl Netns {
    /// A namespace named `<prefix><pid>-<n>` (namespaces of `prefix` left by a killed run are
    /// deleted first) with only its loopback, up.
    pub fn empty(prefix: &str) -> Self {
        remove_stale_namespaces(prefix);
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let name = format!(
            "{prefix}{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        );
        run(Command::new("ip").args(["netns", "add", &name]));
        let ns = Self { name };
        ns.ip(&["link", "set", "lo", "up"]);
        ns
    }

    /// Two namespaces, as two machines, joined by a veth pair: `st0` in the first with
    /// `addresses.0`, `st1` in the second with `addresses.1` (CIDR, e.g. `192.0.2.1/24`), both
    /// up, no other route.
    pub fn pair(prefix: &str, addresses: (&str, &str)) -> (Self, Self) {
        let a = Self::empty(prefix);
        let b = Self::empty(prefix);
        a.ip(&[
            "link", "add", "st0", "type", "veth", "peer", "name", "st1", "netns", &b.name,
        ]);
        a.ip(&["addr", "add", addresses.0, "dev", "st0"]);
        b.ip(&["addr", "add", addresses.1, "dev", "st1"]);
        a.ip(&["link", "set", "st0", "up"]);
        b.ip(&["link", "set", "st1", "up"]);
        (a, b)
    }

    /// A namespace named `<prefix><pid>-<n>` (namespaces of `prefix` left by a killed run are
    /// deleted first) with a veth pair `ecm0`/`ecs0` inside it.
    pub fn new(prefix: &str) -> Self {
        let ns = Self::empty(prefix);
        ns.ip(&[
            "link", "add", "ecm0", "type", "veth", "peer", "name", "ecs0",
        ]);
        for dev in ["ecm0", "ecs0"] {
            ns.ip(&["link", "set", dev, "up"]);
        }
        ns
    }

    /// `ip -n NS ARGS`.
    pub fn ip(&self, args: &[&str]) {
        run(Command::new("ip").args(["-n", &self.name]).args(args));
    }

    /// `program` to be run inside the namespace.
    pub fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut cmd = Command::new("ip");
        cmd.args(["netns", "exec", &self.name]).arg(program);
        cmd
    }

    /// The emulator `program` (a workspace binary) serving on `ecs0` in the namespace
    /// (`--interface ecs0`, `args`, `--control dir/sim.ctl`), its output in `dir/sim.log`;
    /// returns once the log says `ready` (fails, with the log, if it exits or takes 10 s).
    pub fn start_emulator(&self, program: &str, args: &[&str], dir: &Path, ready: &str) -> Child {
        let log = std::fs::File::create(dir.join("sim.log")).expect("sim.log");
        let mut cmd = self.command(crate::bin(program));
        cmd.args(["--interface", "ecs0"])
            .args(args)
            .arg("--control")
            .arg(dir.join("sim.ctl"))
            .env("TELEOP_LOG", "info")
            .stdout(log.try_clone().expect("sim.log"))
            .stderr(log);
        let mut sim = die_with_parent(&mut cmd)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {program}: {e}"));
        let start = Instant::now();
        loop {
            let text = std::fs::read_to_string(dir.join("sim.log")).unwrap_or_default();
            if text.contains(ready) {
                return sim;
            }
            if let Ok(Some(status)) = sim.try_wait() {
                panic!("the emulator exited ({status}):\n{text}");
            }
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "the emulator did not start:\n{text}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Runs the SOEM check `script` (python3 with pysoem) on `ecm0` for `cycles` cycles, for
    /// at most 60 s, then stops the emulator `sim` (its log in `dir/sim.log`). Asserts that the
    /// script succeeded and ended with `OK`; returns its output and a report for further
    /// checks (status, output, the emulator's log).
    pub fn run_soem(
        &self,
        script: &str,
        cycles: u32,
        sim: &mut Child,
        dir: &Path,
    ) -> (String, String) {
        let mut cmd = self.command("python3");
        cmd.args([script, "ecm0", &cycles.to_string()]);
        let (status, out, err) = run_for(die_with_parent(&mut cmd), Duration::from_secs(60));
        stop(sim);
        let sim_log = std::fs::read_to_string(dir.join("sim.log")).unwrap_or_default();
        let report =
            format!("soem_op.py: {status:?}\n{out}{err}\n---- emulator log ----\n{sim_log}");
        assert!(status.is_some_and(|s| s.success()), "{report}");
        assert_eq!(out.lines().last(), Some("OK"), "{report}");
        (out, report)
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = Command::new("ip")
            .args(["netns", "del", &self.name])
            .status();
    }
}

/// Deletes namespaces left by an earlier run of these tests that was killed before its drops ran.
fn remove_stale_namespaces(prefix: &str) {
    let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
        return;
    };
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let name = line.split_whitespace().next().unwrap_or("");
        let Some(rest) = name.strip_prefix(prefix) else {
            continue;
        };
        let pid = rest.split('-').next().unwrap_or("");
        if !pid.is_empty() && !Path::new("/proc").join(pid).exists() {
            let _ = Command::new("ip").args(["netns", "del", name]).status();
        }
    }
}

/// SIGINT to `child`, SIGKILL if it has not ended within 5 s.
pub fn stop(child: &mut Child) {
    // SAFETY: kill(2) of our own child.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGINT);
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    while Instant::now() < deadline {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// Why an independent check in Python cannot run here, if it cannot: python3 missing, or
/// `module` (from `.ci/requirements.txt`) not importable by it.
pub fn python_module_missing(module: &str) -> Option<String> {
    match Command::new("python3")
        .args(["-c", &format!("import {module}")])
        .output()
    {
        Ok(o) if o.status.success() => None,
        Ok(o) => Some(format!(
            "{module} is not importable by python3 ({}); pip install -r .ci/requirements.txt",
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("")
        )),
        Err(e) => Some(format!("no python3: {e}")),
    }
}

/// Runs `cmd` (its output piped) for at most `timeout` (then kills it: status `None`); its exit
/// status, standard output and standard error.
pub fn run_for(
    cmd: &mut Command,
    timeout: Duration,
) -> (Option<std::process::ExitStatus>, String, String) {
    use std::io::Read;
    let mut child = cmd
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    let deadline = Instant::now() + timeout;
    let status = loop {
        if let Ok(Some(status)) = child.try_wait() {
            break Some(status);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let (mut out, mut err) = (String::new(), String::new());
    if let Some(mut o) = child.stdout.take() {
        let _ = o.read_to_string(&mut out);
    }
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    (status, out, err)
}
