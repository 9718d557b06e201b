//! A SIGINT that arrives while a node is still starting (before its event loop waits) stops the
//! loop at its next wake-up: the signal is recorded where nothing consumes it. (Its own test
//! binary: the signal is process-wide.)
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_runtime::{EventLoop, Flow, StopReason};

#[test]
fn a_signal_before_the_loop_stops_it_at_the_next_tick() {
    teleop_runtime::install_stop_handlers();
    // SAFETY: raise has no preconditions; the handler above records SIGINT.
    unsafe {
        libc::raise(libc::SIGINT);
    }
    // iceoryx2's own handler keeps one "last signal" that a check consumes: take it, as a
    // check elsewhere during start-up would.
    let _ = iceoryx2_bb_posix::signal::SignalHandler::termination_requested();
    let started = Instant::now();
    let mut wakes = 0;
    let reason = EventLoop::new(Duration::from_millis(20))
        .run(&[], |_| {
            wakes += 1;
            Flow::Continue(())
        })
        .unwrap();
    assert_eq!(reason, StopReason::Interrupt);
    assert_eq!(wakes, 0, "stopped before handing a wake to the node");
    assert!(started.elapsed() < Duration::from_secs(5));
}
