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

/// Records a stop signal another handler caught (iceoryx2's), as if this crate's had.
pub(crate) fn record(signal: i32) {
    SIGNAL.store(signal, Ordering::SeqCst);
}

/// Moves a SIGINT/SIGTERM that iceoryx2's handler recorded into this crate's record; true when
/// there was one (or this crate's handler had one).
pub(crate) fn carry_over() -> bool {
    use iceoryx2_bb_posix::signal::{NonFatalFetchableSignal, SignalHandler};
    if stop_signal().is_some() {
        return true;
    }
    let signal = match SignalHandler::last_signal() {
        Some(NonFatalFetchableSignal::Interrupt) => libc::SIGINT,
        Some(NonFatalFetchableSignal::Terminate) => libc::SIGTERM,
        _ => return false,
    };
    record(signal);
    true
}

/// Makes this crate's handler the one for SIGINT and SIGTERM for good. iceoryx2 installs its
/// own once, when its signal handler is first used, and keeps a single "last signal" that its
/// checks swap out and that every shared-memory creation clears (`call_and_fetch` around the
/// memset): a Ctrl-C that came while a node was creating its ports was wiped there, and the
/// node's loop never stopped (seen in CI). So iceoryx2's handler is made to exist first (what it
/// recorded carried over), then replaced by this crate's, whose record nothing consumes.
/// [`crate::NodeRuntime::new`] and the event loop call it.
pub fn take_over_stop_signals() {
    carry_over();
    install_stop_handlers();
}

/// The stop signal received so far (`libc::SIGINT` or `libc::SIGTERM`), if any.
pub fn stop_signal() -> Option<i32> {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}
