//! `teleop launch` as a supervisor: a hung process (alive, its health gone silent) is killed and
//! restarted; restarts have a budget per window and back off exponentially; a process that cannot
//! be started mid-way through start-up stops the ones started before it.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use teleop_e2e::{retarget_launch, revo2_profile, wait_for, with_profile, Sandbox};

fn alive(pid: u32) -> bool {
    // A zombie still has a /proc entry; its state is `Z`.
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| {
        s.rsplit(')')
            .next()
            .is_some_and(|r| !r.trim_start().starts_with('Z'))
    })
}

#[test]
fn a_hung_process_is_killed_and_restarted() {
    let sandbox = Sandbox::new();
    sandbox.write("retarget.toml", &with_profile("health_period_ms = 100\n"));
    let launch = sandbox.write(
        "launch.toml",
        r#"
[[process]]
name = "retarget"
program = "teleop-retarget"
args = ["--config", "retarget.toml", "--name", "retarget"]
restart_delay_ms = 100
health_timeout_ms = 1000
"#,
    );
    let mut session = sandbox.launch(&launch);
    let first = wait_for(Duration::from_secs(20), "retarget node", || {
        sandbox.pid_of("retarget")
    });
    // Its health reports arrive; give the launcher a moment to see one, then freeze it.
    std::thread::sleep(Duration::from_millis(800));
    // SAFETY: kill(2) with SIGSTOP on a process of this test's session.
    unsafe {
        libc::kill(first as libc::pid_t, libc::SIGSTOP);
    }
    let second = wait_for(Duration::from_secs(15), "restarted retarget", || {
        sandbox.pid_of("retarget").filter(|&p| p != first)
    });
    assert!(!alive(first), "the hung process was killed");
    assert!(alive(second));
    let log = session.log();
    assert!(log.contains("hung: no health report"), "{log}");
    assert!(log.contains("restarting in 100 ms"), "{log}");
    session.stop();
}

#[test]
fn restarts_back_off_and_the_budget_ends_the_session() {
    let sandbox = Sandbox::new();
    let launch = sandbox.write(
        "launch.toml",
        r#"
[[process]]
name = "crasher"
program = "sh"
args = ["-c", "exit 3"]
node = ""
restart_delay_ms = 50
restart_backoff_max_ms = 300
max_restarts = 4
"#,
    );
    let mut session = sandbox.launch(&launch);
    let status = session.wait_exit(Duration::from_secs(20)).unwrap();
    assert!(!status.success());
    let log = session.log();
    for (ms, n) in [(50, 1), (100, 2), (200, 3), (300, 4)] {
        let line = format!("restarting in {ms} ms (restart {n}/4 within 60 s)");
        assert!(log.contains(&line), "{line}\n{log}");
    }
    assert!(
        log.contains(
            "required process crasher exited (exit status 3) after 4 restarts within 60 s"
        ),
        "{log}"
    );
}

#[test]
fn restarts_older_than_the_window_no_longer_count() {
    let sandbox = Sandbox::new();
    // Fails every 1.2 s: with a 1 s window it never has a recent restart, so a budget of one
    // restart lasts for ever.
    let launch = sandbox.write(
        "launch.toml",
        r#"
[[process]]
name = "flaky"
program = "sh"
args = ["-c", "sleep 1.2; exit 1"]
node = ""
restart_delay_ms = 50
max_restarts = 1
restart_window_s = 1
"#,
    );
    let mut session = sandbox.launch(&launch);
    wait_for(Duration::from_secs(20), "a third restart", || {
        let log = session.log();
        (log.matches("restarting in 50 ms (restart 1/1 within 1 s)")
            .count()
            >= 3)
            .then_some(())
    });
    assert!(
        session.wait_exit(Duration::from_millis(100)).is_none(),
        "still running"
    );
    session.stop();
}

#[test]
fn a_process_that_cannot_start_stops_the_ones_started_before_it() {
    let sandbox = Sandbox::new();
    // A file that exists but cannot be executed: only the spawn itself fails.
    sandbox.write("not-executable", "#!/bin/sh\nexit 0\n");
    let launch = sandbox.write(
        "launch.toml",
        r#"
[[process]]
name = "sleeper"
program = "sh"
args = ["-c", "sleep 300 # started-before-the-broken-one"]
node = ""

[[process]]
name = "broken"
program = "./not-executable"
node = ""
"#,
    );
    let mut session = sandbox.launch(&launch);
    let status = session.wait_exit(Duration::from_secs(20)).unwrap();
    assert!(!status.success());
    let log = session.log();
    assert!(
        log.contains("cannot start") && log.contains("not-executable"),
        "{log}"
    );
    assert!(
        log.contains("stopping the processes already started"),
        "{log}"
    );
    // The sleeper did not outlive the launcher.
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(
        Sandbox::pid_with_arg("started-before-the-broken-one"),
        None,
        "{log}"
    );
}

#[test]
fn a_node_whose_parent_death_signal_was_cleared_still_dies_with_the_launcher() {
    // The kernel clears the parent-death signal when it executes a binary with file
    // capabilities (`setcap cap_net_raw+ep`, as raw-socket EtherCAT needs); `setpriv
    // --pdeathsig clear` does the same, deterministically and without privileges.
    if std::process::Command::new("setpriv")
        .args(["--pdeathsig", "clear", "true"])
        .status()
        .map_or(true, |s| !s.success())
    {
        eprintln!("skipped: no setpriv with --pdeathsig (util-linux 2.33 or newer)");
        return;
    }
    let sandbox = Sandbox::new();
    let retarget = teleop_e2e::bin("teleop-retarget");
    let launch = sandbox.write(
        "launch.toml",
        &format!(
            r#"
[[process]]
name = "retarget"
program = "setpriv"
args = ["--pdeathsig", "clear", "--", {:?}, "--profile", {:?}, "--name", "orphan-check"]
node = "orphan-check"
"#,
            retarget.display().to_string(),
            revo2_profile()
        ),
    );
    let mut session = sandbox.launch(&launch);
    let node = wait_for(Duration::from_secs(20), "retarget node", || {
        sandbox.pid_of("orphan-check")
    });
    // The launcher dies without a chance to stop anything.
    session.kill();
    wait_for(Duration::from_secs(5), "the orphaned node to stop", || {
        (!alive(node)).then_some(())
    });
}

#[test]
fn a_node_stopped_and_continued_goes_on() {
    // SIGSTOP then SIGCONT (a debugger, Ctrl-Z and `fg`) interrupts the node's wait; it is not
    // a request to stop.
    let sandbox = Sandbox::new();
    let launch = sandbox.write("launch.toml", &retarget_launch());
    let mut session = sandbox.launch(&launch);
    let pid = wait_for(Duration::from_secs(20), "retarget node", || {
        sandbox.pid_of("retarget")
    });
    // Let it settle into its event loop's wait first.
    std::thread::sleep(Duration::from_millis(1000));
    for signal in [libc::SIGSTOP, libc::SIGCONT] {
        // SAFETY: kill(2) on a process of this test's session.
        unsafe {
            libc::kill(pid as libc::pid_t, signal);
        }
        std::thread::sleep(Duration::from_millis(300));
    }
    std::thread::sleep(Duration::from_millis(700));
    assert!(alive(pid), "{}", session.log());
    assert_eq!(sandbox.pid_of("retarget"), Some(pid), "{}", session.log());
    assert!(!session.log().contains("exited"), "{}", session.log());
    session.stop();
}
