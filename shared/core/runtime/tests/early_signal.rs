//! A SIGINT that arrives while a node is still starting (creating its ports, before its event
//! loop waits) stops the loop at its next wake-up, even when one of iceoryx2's own signal checks
//! ran in between (they consume iceoryx2's record of the signal). (Its own test binary: the
//! signal is process-wide.)
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use iceoryx2_bb_posix::signal::SignalHandler;
use teleop_runtime::{EventLoop, Flow, IpcSettings, NodeRuntime, StopReason};

#[test]
fn a_signal_while_starting_stops_the_loop_at_its_next_wake() {
    let dir = tempfile::tempdir().unwrap();
    let runtime = NodeRuntime::new("early-signal", &IpcSettings::isolated(dir.path())).unwrap();
    let _publisher: teleop_runtime::Publisher<teleop_msgs::EStop> = runtime.publisher().unwrap();
    // SAFETY: raise has no preconditions; a handler records SIGINT.
    unsafe {
        libc::raise(libc::SIGINT);
    }
    // One of iceoryx2's checks, as its calls around shared memory make them.
    let _ = SignalHandler::termination_requested();
    let _other: teleop_runtime::Publisher<teleop_msgs::NodeHealth> = runtime.publisher().unwrap();
    let mut wakes = 0;
    // A loop that has not stopped after 50 ticks (1 s) stops itself: `Requested`.
    let reason = EventLoop::new(Duration::from_millis(20))
        .run(&[], |_| {
            wakes += 1;
            if wakes >= 50 {
                Flow::Break(())
            } else {
                Flow::Continue(())
            }
        })
        .unwrap();
    assert_eq!(reason, StopReason::Interrupt, "after {wakes} wakes");
    assert_eq!(wakes, 0, "stopped before handing a wake to the node");
}
