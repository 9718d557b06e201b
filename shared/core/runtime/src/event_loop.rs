//! The node's wait loop: sleep in an iceoryx2 WaitSet until an input arrives, an input's
//! watchdog deadline passes, or the periodic tick is due. No busy polling.

use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::{CallbackProgression, WaitSetBuilder};
use iceoryx2::waitset::WaitSetRunResult;

use crate::ipc::RuntimeError;
use crate::Service;

/// One input of an [`EventLoop`]: the listener of a [`Subscriber`](crate::Subscriber) and an
/// optional watchdog deadline.
pub struct Input<'a> {
    listener: &'a Listener<Service>,
    deadline: Option<Duration>,
}

impl<'a> Input<'a> {
    /// An input that wakes the loop whenever it receives.
    pub fn new(listener: &'a Listener<Service>) -> Self {
        Self {
            listener,
            deadline: None,
        }
    }

    /// An input with a watchdog: the loop also wakes with [`Wake::Timeout`] whenever nothing
    /// arrived for `deadline`.
    pub fn with_deadline(listener: &'a Listener<Service>, deadline: Duration) -> Self {
        Self {
            listener,
            deadline: Some(deadline),
        }
    }
}

/// Why the loop woke the node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// Input `i` (index into the inputs given to [`EventLoop::run`]) has new data.
    Input(usize),
    /// Input `i` received nothing within its deadline.
    Timeout(usize),
    /// The periodic tick.
    Tick,
}

/// Why [`EventLoop::run`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// SIGINT.
    Interrupt,
    /// SIGTERM.
    Terminate,
    /// The node's callback asked to stop.
    Requested,
}

/// A stop signal recorded by this crate's handler or by iceoryx2's (moved into this crate's).
fn stop_requested() -> bool {
    crate::signals::carry_over()
}

/// Whether the loop goes on after a wake-up.
pub type Flow = core::ops::ControlFlow<()>;

/// The wait loop of a node.
pub struct EventLoop {
    tick: Duration,
}

impl EventLoop {
    /// A loop that also wakes every `tick` (health reports, stale checks, periodic output).
    pub fn new(tick: Duration) -> Self {
        Self { tick }
    }

    /// Sleeps until something happens and calls `on_wake` for it, until SIGINT/SIGTERM or until
    /// `on_wake` returns `Break`. The loop is the node's time-critical thread: while it runs, the
    /// calling thread has the scheduling policy and priority `launch.toml` names for the process
    /// (see [`crate::realtime`]; none: unchanged).
    pub fn run(
        &self,
        inputs: &[Input<'_>],
        on_wake: impl FnMut(Wake) -> Flow,
    ) -> Result<StopReason, RuntimeError> {
        crate::realtime::enter_realtime();
        let result = self.wait(inputs, on_wake);
        crate::realtime::leave_realtime();
        result
    }

    /// [`run`](Self::run) for a node whose handling of a wake-up can fail: the first error
    /// stops the loop and comes back as the inner `Err` (the node then exits non-zero, and its
    /// supervisor restarts it); `Ok` says why the loop stopped otherwise.
    pub fn try_run<E>(
        &self,
        inputs: &[Input<'_>],
        mut on_wake: impl FnMut(Wake) -> Result<(), E>,
    ) -> Result<Result<StopReason, E>, RuntimeError> {
        let mut failure = None;
        let stop = self.run(inputs, |wake| match on_wake(wake) {
            Ok(()) => Flow::Continue(()),
            Err(e) => {
                failure = Some(e);
                Flow::Break(())
            }
        })?;
        Ok(failure.map_or(Ok(stop), Err))
    }

    fn wait(
        &self,
        inputs: &[Input<'_>],
        mut on_wake: impl FnMut(Wake) -> Flow,
    ) -> Result<StopReason, RuntimeError> {
        let waitset = WaitSetBuilder::new()
            .create::<Service>()
            .map_err(|e| RuntimeError::ipc("creating waitset", "event loop", e))?;
        let mut guards = Vec::with_capacity(inputs.len());
        for input in inputs {
            let guard = match input.deadline {
                Some(deadline) => waitset.attach_deadline(input.listener, deadline),
                None => waitset.attach_notification(input.listener),
            }
            .map_err(|e| RuntimeError::ipc("attaching input", "event loop", e))?;
            guards.push(guard);
        }
        let tick = waitset
            .attach_interval(self.tick)
            .map_err(|e| RuntimeError::ipc("attaching tick", "event loop", e))?;
        // SIGINT/SIGTERM: recorded by this crate's handler, where nothing consumes them (see
        // `take_over_stop_signals`), and checked on every wake (the tick bounds the delay) and
        // after every interrupted wait.
        crate::signals::take_over_stop_signals();

        let result = loop {
            let result = waitset
                .wait_and_process(|id| {
                    if stop_requested() {
                        return CallbackProgression::Stop;
                    }
                    let wake = if id.has_event_from(&tick) {
                        Some(Wake::Tick)
                    } else {
                        guards.iter().enumerate().find_map(|(i, g)| {
                            if id.has_missed_deadline(g) {
                                Some(Wake::Timeout(i))
                            } else if id.has_event_from(g) {
                                Some(Wake::Input(i))
                            } else {
                                None
                            }
                        })
                    };
                    match wake.map(&mut on_wake) {
                        Some(Flow::Break(())) => CallbackProgression::Stop,
                        _ => CallbackProgression::Continue,
                    }
                })
                .map_err(|e| RuntimeError::ipc("waiting", "event loop", e))?;
            // iceoryx2 reports any interrupted wait as `Interrupt`; Linux interrupts epoll_wait
            // also when a stopped process is continued (SIGSTOP, SIGCONT: a debugger, a
            // terminal's Ctrl-Z and `fg`). Only SIGINT/SIGTERM stop the loop.
            if result != WaitSetRunResult::Interrupt || stop_requested() {
                break result;
            }
        };
        Ok(match (crate::signals::stop_signal(), result) {
            (Some(libc::SIGTERM), _) => StopReason::Terminate,
            (Some(_), _) => StopReason::Interrupt,
            (None, result) => match result {
                WaitSetRunResult::Interrupt => StopReason::Interrupt,
                WaitSetRunResult::TerminationRequest => StopReason::Terminate,
                WaitSetRunResult::StopRequest | WaitSetRunResult::AllEventsHandled => {
                    StopReason::Requested
                }
            },
        })
    }
}
