//! SIGINT/SIGTERM for loops that do not sleep in an iceoryx2 WaitSet (serial I/O loops, the
//! launcher, simulators), and the parent-death signal of processes `teleop launch` started.

use std::sync::atomic::{AtomicI32, Ordering};

static SIGNAL: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_signal(signal: libc::c_int) {
    SIGNAL.store(signal, Ordering::SeqCst);
}

/// Installs handlers that record SIGINT and SIGTERM instead of terminating the process; poll
/// [`stop_signal`] in the loop.
pub fn install_stop_handlers() {
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only stores into an atomic, which is async-signal-safe.
        unsafe {
            libc::signal(
                signal,
                on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t,
            );
        }
    }
}

/// Environment variable in which `teleop launch` gives its children its own pid.
pub const ENV_SUPERVISOR_PID: &str = "TELEOP_SUPERVISOR_PID";

/// In a process started by `teleop launch` ([`ENV_SUPERVISOR_PID`] set): asks the kernel again
/// for SIGTERM when its parent dies, and stops at once (SIGTERM to itself) if the launcher
/// already died.
///
/// The launcher sets the parent-death signal before exec, but the kernel clears it when it
/// executes a binary with file capabilities (the `setcap cap_net_raw` that raw-socket EtherCAT
/// needs) or set-user-ID: without this, a node driving hardware would outlive its supervisor.
/// [`crate::NodeRuntime::new`] calls it, so every node does.
pub fn follow_supervisor() {
    let Some(supervisor) = std::env::var(ENV_SUPERVISOR_PID)
        .ok()
        .and_then(|v| v.parse::<libc::pid_t>().ok())
    else {
        return;
    };
    // SAFETY: prctl(PR_SET_PDEATHSIG) and kill(pid, 0) have no memory preconditions.
    let supervisor_gone = unsafe {
        libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
        libc::kill(supervisor, 0) != 0
            && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH)
    };
    if supervisor_gone {
        // The launcher died before the signal was armed again.
        // SAFETY: raise has no preconditions.
        unsafe {
            libc::raise(libc::SIGTERM);
        }
    }
}

/// The stop signal received so far (`libc::SIGINT` or `libc::SIGTERM`), if any.
pub fn stop_signal() -> Option<i32> {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}
