//! Real-time scheduling from `launch.toml`: a launched node's time-critical threads (the glove
//! exchange loop, the EtherCAT cycle and frame pump) really run with the policy and priority
//! the file names, its other threads do not; a process without the right says so once, names
//! the fix, and runs on at normal priority.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use teleop_e2e::{bin, retarget_launch, wait_for, Sandbox};

/// (thread name, policy, real-time priority) of every thread of `pid`, from
/// /proc/<pid>/task/<tid>/stat (fields 2, 41 and 40).
fn threads(pid: u32) -> Vec<(String, i32, i32)> {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return Vec::new();
    };
    tasks
        .flatten()
        .filter_map(|task| {
            let stat = std::fs::read_to_string(task.path().join("stat")).ok()?;
            let name = stat[stat.find('(')? + 1..stat.rfind(')')?].to_string();
            let fields: Vec<&str> = stat[stat.rfind(')')? + 2..].split(' ').collect();
            // `fields[0]` is field 3 (state).
            Some((
                name,
                fields[41 - 3].parse().ok()?,
                fields[40 - 3].parse().ok()?,
            ))
        })
        .collect()
}

/// The launch file text without its shipped scheduling settings, so a test sets its own.
fn without_realtime(text: String) -> String {
    text.lines()
        .filter(|l| !l.starts_with("sched_policy") && !l.starts_with("sched_priority"))
        .map(|l| format!("{l}\n"))
        .collect()
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() == 0 }
}

#[test]
fn launched_nodes_run_their_time_critical_threads_at_the_configured_priority() {
    let sandbox = Sandbox::new();
    let launch = sandbox.default_session(|text| {
        without_realtime(text)
            .replace(
            "args = [\"--config\", \"config/glove.toml\"]\n",
            "args = [\"--config\", \"config/glove.toml\"]\nsched_policy = \"fifo\"\nsched_priority = 31\ncpu_affinity = [0]\n",
        )
        .replace(
            "args = [\"--config\", \"config/revo2/retarget.toml\"]\n",
            "args = [\"--config\", \"config/revo2/retarget.toml\"]\nnice = 5\n",
        )
        .replace(
            "args = [\"--config\", \"config/revo2.toml\"]\n",
            "args = [\"--config\", \"config/revo2.toml\"]\nsched_policy = \"rr\"\nsched_priority = 42\nlock_memory = true\n",
        )
        .replace(
            "args = [\"--config\", \"config/revo2/feedback.toml\"]\n",
            "args = [\"--config\", \"config/revo2/feedback.toml\"]\nsched_policy = \"fifo\"\nsched_priority = 20\n",
        )
    });
    let mut session = sandbox.launch(&launch);
    let glove = wait_for(Duration::from_secs(30), "glove node", || {
        sandbox.pid_of("glove")
    });
    let revo2 = wait_for(Duration::from_secs(30), "revo2 node", || {
        sandbox.pid_of("revo2")
    });
    if !is_root() {
        // Without the right: one warning each, with the fix, and the nodes run on.
        wait_for(Duration::from_secs(30), "the warning", || {
            (session
                .log()
                .matches("cannot use real-time scheduling")
                .count()
                >= 2)
                .then_some(())
        });
        let log = session.log();
        assert!(log.contains("setcap cap_sys_nice+ep"), "{log}");
        session.stop();
        return;
    }
    // The glove exchange loop runs on the node's main thread.
    let main_glove = wait_for(
        Duration::from_secs(30),
        "glove loop at SCHED_FIFO 31",
        || {
            threads(glove).into_iter().find(|(name, policy, prio)| {
                name.starts_with("teleop-glove") && *policy == libc::SCHED_FIFO && *prio == 31
            })
        },
    );
    assert_eq!(main_glove.1, libc::SCHED_FIFO);
    // Pinned to CPU 0.
    let status = std::fs::read_to_string(format!("/proc/{glove}/status")).unwrap();
    assert!(
        status
            .lines()
            .any(|l| l.starts_with("Cpus_allowed_list:") && l.ends_with("\t0")),
        "{status}"
    );
    // The EtherCAT cycle (main thread) and frame pump at SCHED_RR 42, once in OP.
    wait_for(
        Duration::from_secs(30),
        "revo2 cycle and pump at SCHED_RR 42",
        || {
            let t = threads(revo2);
            let rt = |n: &str| {
                t.iter().any(|(name, policy, prio)| {
                    name.starts_with(n) && *policy == libc::SCHED_RR && *prio == 42
                })
            };
            (rt("teleop-revo2") && rt("ecat-pump")).then_some(())
        },
    );
    // Its other threads stay normal.
    let others: Vec<_> = threads(revo2)
        .into_iter()
        .filter(|(name, ..)| name == "log-writer")
        .collect();
    assert!(!others.is_empty(), "{:?}", threads(revo2));
    assert!(
        others
            .iter()
            .all(|(_, policy, _)| *policy == libc::SCHED_OTHER),
        "{others:?}"
    );
    // Memory locked: VmLck in /proc/<pid>/status.
    let status = std::fs::read_to_string(format!("/proc/{revo2}/status")).unwrap();
    let locked_kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmLck:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap();
    assert!(locked_kb > 0, "{status}");
    // A node built on the event loop: the loop's thread (its main thread).
    let feedback = wait_for(Duration::from_secs(30), "feedback node", || {
        sandbox.pid_of("feedback")
    });
    wait_for(
        Duration::from_secs(30),
        "feedback loop at SCHED_FIFO 20",
        || {
            threads(feedback)
                .iter()
                .any(|(name, policy, prio)| {
                    name.starts_with("teleop-feedback")
                        && *policy == libc::SCHED_FIFO
                        && *prio == 20
                })
                .then_some(())
        },
    );
    // A node without settings stays normal.
    let retarget = wait_for(Duration::from_secs(30), "retarget node", || {
        sandbox.pid_of("retarget")
    });
    assert!(threads(retarget)
        .iter()
        .all(|(_, policy, _)| *policy == libc::SCHED_OTHER));
    // Its nice value (field 19 of the main thread's stat).
    let stat = std::fs::read_to_string(format!("/proc/{retarget}/stat")).unwrap();
    let nice: i32 = stat[stat.rfind(')').unwrap() + 2..]
        .split(' ')
        .nth(19 - 3)
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(nice, 5, "{stat}");
    assert!(!session.log().contains("cannot use real-time scheduling"));
    session.stop();
}

#[test]
fn without_the_right_a_node_warns_once_and_runs_on_at_normal_priority() {
    if !is_root() {
        // Not root: the test above already runs the refusal path.
        return;
    }
    let sandbox = Sandbox::new();
    // The glove and Revo2 nodes run as root but without CAP_SYS_NICE and with RLIMIT_RTPRIO 0:
    // they may not use a real-time policy. The Revo2 node's cycle and frame pump threads both
    // ask: still one warning per process.
    let unprivileged = |text: String, node: &str| {
        let exe = bin(&format!("teleop-{node}")).display().to_string();
        text.replace(
            &format!("program = \"teleop-{node}\"\nargs = [\"--config\", \"config/{node}.toml\"]\n"),
            &format!(
                "program = \"prlimit\"\nargs = [\"--rtprio=0\", \"setpriv\", \"--inh-caps=-sys_nice\", \"--bounding-set=-sys_nice\", {exe:?}, \"--config\", \"config/{node}.toml\"]\nsched_policy = \"fifo\"\nsched_priority = 31\n"
            ),
        )
    };
    let launch = sandbox.default_session(|text| {
        unprivileged(unprivileged(without_realtime(text), "glove"), "revo2")
    });
    assert_eq!(
        std::fs::read_to_string(&launch)
            .unwrap()
            .matches("prlimit")
            .count(),
        2
    );
    let mut session = sandbox.launch(&launch);
    let glove = wait_for(Duration::from_secs(30), "glove node", || {
        sandbox.pid_of("glove")
    });
    let revo2 = wait_for(Duration::from_secs(30), "revo2 node", || {
        sandbox.pid_of("revo2")
    });
    let warnings = |log: &str, process: &str| {
        log.lines()
            .filter(|l| {
                l.trim_start().starts_with(&format!("{process} |"))
                    && l.contains("cannot use real-time scheduling")
            })
            .count()
    };
    // The Revo2 node's pump asks at start, its cycle once in OP (when commands flow).
    wait_for(
        Duration::from_secs(30),
        "the warnings, and the hand following commands",
        || {
            let log = session.log();
            (warnings(&log, "glove") == 1
                && warnings(&log, "revo2") == 1
                && log.contains("hand commands fresh"))
            .then_some(())
        },
    );
    std::thread::sleep(Duration::from_secs(1));
    let log = session.log();
    assert_eq!(
        (warnings(&log, "glove"), warnings(&log, "revo2")),
        (1, 1),
        "{log}"
    );
    assert!(
        log.contains("setcap cap_sys_nice+ep") && log.contains("rtprio 31"),
        "{log}"
    );
    // They run on, at the normal policy.
    assert_eq!(
        sandbox.pid_of("glove"),
        Some(glove),
        "the glove node ran on"
    );
    assert_eq!(
        sandbox.pid_of("revo2"),
        Some(revo2),
        "the revo2 node ran on"
    );
    for pid in [glove, revo2] {
        assert!(threads(pid)
            .iter()
            .all(|(_, policy, _)| *policy == libc::SCHED_OTHER));
    }
    session.stop();
}

#[test]
fn scheduling_settings_in_the_launchers_environment_do_not_reach_its_processes() {
    if !is_root() {
        eprintln!("skipped: not root (a real-time policy would be refused anyway)");
        return;
    }
    let sandbox = Sandbox::new();
    let launch = sandbox.write("launch.toml", &retarget_launch());
    // `teleop launch` itself started with settings meant for no process of this file.
    let mut launcher = sandbox
        .teleop()
        .arg("launch")
        .arg(&launch)
        .env(teleop_runtime::realtime::ENV_SCHED_POLICY, "fifo")
        .env(teleop_runtime::realtime::ENV_SCHED_PRIORITY, "33")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let retarget = wait_for(Duration::from_secs(30), "retarget node", || {
        sandbox.pid_of("retarget")
    });
    std::thread::sleep(Duration::from_millis(500));
    let threads = threads(retarget);
    let _ = launcher.kill();
    let _ = launcher.wait();
    assert!(!threads.is_empty());
    assert!(
        threads.iter().all(|(_, policy, _)| *policy == 0),
        "a thread runs real-time: {threads:?}"
    );
}
