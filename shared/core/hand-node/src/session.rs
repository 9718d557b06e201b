//! The one session loop every hand's device runs under: connect, serve turns until stop or a
//! loss, the device's hold on stop, reconnect with back-off, and the link-down reports while
//! the hand is away. A device plugs in as a [`Transport`].
//!
//! # The three clockings
//!
//! [`Transport::serve`] is one turn of the device's clock, and the transport waits for that
//! clock inside it:
//!
//! - host-clocked cycles (the EtherCAT master): sleep to the next absolute deadline, exchange
//!   one frame of process data;
//! - a device-clocked stream (the Allegro's 333 Hz CAN stream): wait for the next frame (or its
//!   timeout), and on a complete set one control step;
//! - a host-polled request/response bus (Dynamixel servos): sleep to the next poll deadline,
//!   write the goals, read the state back.
//!
//! The loop checks for stop between turns, so a turn must return within a cycle or a frame
//! timeout. It allocates nothing and logs nothing while the turns go well.
//!
//! # What the loop guarantees
//!
//! - [`Transport::stop`] (the device's hold or torque off) is called exactly once for every
//!   session [`Transport::connect`] opened, on every way out: a stop request, a loss, a failure;
//! - a [`ConnectError::Lost`] link is tried again after a back-off that doubles from
//!   [`Backoff::first`] up to [`Backoff::most`]; a [`ConnectError::WrongDevice`] or a
//!   [`ConnectError::Setting`] is logged at error level and looked at again only every
//!   [`Backoff::most`] (a device swapped for the right one, or a fixed setting, is still found);
//!   after a loss in service the device is connected again after [`Backoff::first`];
//! - a failure is logged when it differs from the last one logged, or that one is older than
//!   [`REPEAT_LOG`];
//! - while the hand is away, [`Transport::link_down`] is called after each failure and every
//!   [`LINK_DOWN_REPORT`] while waiting, so the node's health keeps coming.

use std::time::{Duration, Instant};

/// How often [`Transport::link_down`] is called while the loop waits to connect again.
pub const LINK_DOWN_REPORT: Duration = Duration::from_millis(100);

/// The same failure is logged again at most this often.
pub const REPEAT_LOG: Duration = Duration::from_secs(10);

/// The longest the loop sleeps at once while waiting (then it checks for stop again).
const WAIT_SLICE: Duration = Duration::from_millis(20);

/// How long the loop waits before connecting again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    /// The first wait after a lost link (and the wait after a loss in service).
    pub first: Duration,
    /// The longest wait; also the wait after a wrong device or a wrong setting.
    pub most: Duration,
}

/// Why a device could not be connected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConnectError {
    /// No link, or no answer: it may come back, so it is tried again soon (with back-off).
    #[error("{0}")]
    Lost(String),
    /// Another device answers than the transport's (the text names both): looked at again
    /// slowly.
    #[error("wrong device: {0}")]
    WrongDevice(String),
    /// The device answers, but a setting does not fit it (e.g. its protocol generation; the text
    /// names the setting to change): looked at again slowly.
    #[error("{0}")]
    Setting(String),
}

impl ConnectError {
    /// Which kind of being down this is.
    pub fn cause(&self) -> Cause {
        match self {
            Self::Lost(_) => Cause::Lost,
            Self::WrongDevice(_) => Cause::WrongDevice,
            Self::Setting(_) => Cause::Setting,
        }
    }
}

/// Why the hand is down, as [`Transport::link_down`] is told.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cause {
    /// The link or the device is lost (or not there yet).
    Lost,
    /// Another device answers.
    WrongDevice,
    /// A setting does not fit the device.
    Setting,
}

/// The hand is down.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Down<'a> {
    /// Why, in words (logged by the loop already).
    pub why: &'a str,
    /// Why, by kind.
    pub cause: Cause,
}

/// How a turn failed.
#[derive(Debug, Clone)]
pub enum Fault<E> {
    /// The device is lost (a run of missing answers, a link error): the session ends and the
    /// loop connects again.
    Lost(String),
    /// The transport's host failed (e.g. publishing): the session ends and so does the loop,
    /// with this error.
    Failed(E),
}

/// How a session ends, as [`Transport::stop`] is told.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending<'a> {
    /// Stop was requested.
    Stop,
    /// The device was lost (why).
    Lost(&'a str),
    /// The host failed; the loop ends with its error.
    Failed,
}

/// A device, as the session loop drives it (see the module documentation).
pub trait Transport {
    /// A connected device: its link and the state of its cycle.
    type Session;
    /// What the transport's host fails with.
    type Error;

    /// The device's name, for the log.
    fn name(&self) -> &str;

    /// True once the loop must stop (SIGINT/SIGTERM, a CLI command's time is up).
    fn stop_requested(&self) -> bool;

    /// Opens the link and brings the device up (checking that it is the transport's device);
    /// tells the host it connected.
    fn connect(&mut self) -> Result<Self::Session, ConnectError>;

    /// One turn of the device's clock: waits for it, exchanges, hands the state to the host.
    /// No allocation and no logging while it goes well.
    fn serve(&mut self, session: &mut Self::Session) -> Result<(), Fault<Self::Error>>;

    /// The session ends (see `ending`): the device's hold on stop (hold outputs, zero torque,
    /// torque off) and the link closed. Called exactly once per session.
    fn stop(&mut self, session: Self::Session, ending: Ending<'_>);

    /// The hand is down: the host reports it (its health above all). An error ends the loop.
    fn link_down(&mut self, down: &Down<'_>) -> Result<(), Self::Error>;
}

/// Logs a failure when it differs from the last logged, or that one is older than
/// [`REPEAT_LOG`].
struct Reporter {
    last: String,
    at: Option<Instant>,
}

impl Reporter {
    fn report(&mut self, name: &str, error: &ConnectError, retry: Duration) {
        let text = error.to_string();
        let again = self.last == text && self.at.is_some_and(|t| t.elapsed() < REPEAT_LOG);
        if again {
            return;
        }
        let ms = retry.as_millis();
        match error.cause() {
            Cause::Lost => tracing::warn!("{name}: {text}; retrying in {ms} ms"),
            Cause::WrongDevice | Cause::Setting => {
                tracing::error!("{name}: {text}; looking again every {ms} ms")
            }
        }
        self.last = text;
        self.at = Some(Instant::now());
    }

    fn clear(&mut self) {
        self.last.clear();
        self.at = None;
    }
}

/// Runs `transport` until it asks to stop (see the module documentation). Returns an error
/// only when its host fails (in a turn, or reporting the link down).
pub fn run<T: Transport>(transport: &mut T, backoff: Backoff) -> Result<(), T::Error> {
    let mut wait = backoff.first;
    let mut reporter = Reporter {
        last: String::new(),
        at: None,
    };
    while !transport.stop_requested() {
        let mut session = match transport.connect() {
            Ok(session) => session,
            Err(e) => {
                let pause = match e.cause() {
                    Cause::Lost => {
                        let pause = wait;
                        wait = (wait * 2).min(backoff.most);
                        pause
                    }
                    Cause::WrongDevice | Cause::Setting => backoff.most,
                };
                reporter.report(transport.name(), &e, pause);
                let why = e.to_string();
                down_for(
                    transport,
                    &Down {
                        why: &why,
                        cause: e.cause(),
                    },
                    pause,
                )?;
                continue;
            }
        };
        wait = backoff.first;
        reporter.clear();
        let fault = loop {
            if transport.stop_requested() {
                break None;
            }
            if let Err(fault) = transport.serve(&mut session) {
                break Some(fault);
            }
        };
        match fault {
            None => {
                transport.stop(session, Ending::Stop);
                return Ok(());
            }
            Some(Fault::Failed(e)) => {
                transport.stop(session, Ending::Failed);
                return Err(e);
            }
            Some(Fault::Lost(why)) => {
                transport.stop(session, Ending::Lost(&why));
                tracing::warn!("{}: lost: {why}; connecting again", transport.name());
                let down = Down {
                    why: &why,
                    cause: Cause::Lost,
                };
                down_for(transport, &down, backoff.first)?;
            }
        }
    }
    Ok(())
}

/// Reports `down` now and every [`LINK_DOWN_REPORT`] for `pause` (less when stop is requested).
fn down_for<T: Transport>(
    transport: &mut T,
    down: &Down<'_>,
    pause: Duration,
) -> Result<(), T::Error> {
    transport.link_down(down)?;
    let start = Instant::now();
    let end = start + pause;
    let mut next_report = start + LINK_DOWN_REPORT;
    loop {
        if transport.stop_requested() {
            return Ok(());
        }
        let now = Instant::now();
        let Some(left) = end.checked_duration_since(now).filter(|d| !d.is_zero()) else {
            return Ok(());
        };
        if now >= next_report {
            next_report += LINK_DOWN_REPORT;
            transport.link_down(down)?;
        }
        let to_report = next_report.saturating_duration_since(now);
        std::thread::sleep(left.min(to_report).min(WAIT_SLICE));
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use std::cell::Cell;
    use std::collections::VecDeque;

    use super::*;

    /// What a fake connect or turn does.
    #[derive(Debug, Clone)]
    enum Step {
        Connect(Result<(), ConnectError>),
        /// Serve this many good turns, then end the session this way (`None`: stop).
        Serve(u32, Option<Fault<&'static str>>),
    }

    /// A transport that follows a script and records what the loop did, and when.
    struct Fake {
        script: VecDeque<Step>,
        /// Turns left in the session under way, and how it ends.
        turns: Option<(u32, Option<Fault<&'static str>>)>,
        /// Stop once the script is done.
        stop: Cell<bool>,
        connects: Vec<Instant>,
        sessions: u32,
        stops: Vec<String>,
        downs: Vec<(Instant, String, Cause)>,
    }

    impl Fake {
        fn new(script: impl IntoIterator<Item = Step>) -> Self {
            Self {
                script: script.into_iter().collect(),
                turns: None,
                stop: Cell::new(false),
                connects: Vec::new(),
                sessions: 0,
                stops: Vec::new(),
                downs: Vec::new(),
            }
        }

        /// Gaps between connect attempts.
        fn gaps(&self) -> Vec<Duration> {
            self.connects.windows(2).map(|w| w[1] - w[0]).collect()
        }
    }

    impl Transport for Fake {
        type Session = u32;
        type Error = &'static str;

        fn name(&self) -> &str {
            "fake"
        }

        fn stop_requested(&self) -> bool {
            self.stop.get()
        }

        fn connect(&mut self) -> Result<u32, ConnectError> {
            self.connects.push(Instant::now());
            match self.script.pop_front() {
                Some(Step::Connect(Ok(()))) => {
                    self.sessions += 1;
                    match self.script.pop_front() {
                        Some(Step::Serve(n, end)) => self.turns = Some((n, end)),
                        other => panic!("a session without its turns: {other:?}"),
                    }
                    Ok(self.sessions)
                }
                Some(Step::Connect(Err(e))) => {
                    if self.script.is_empty() {
                        self.stop.set(true);
                    }
                    Err(e)
                }
                other => panic!("unexpected connect: {other:?}"),
            }
        }

        fn serve(&mut self, _: &mut u32) -> Result<(), Fault<&'static str>> {
            let (left, end) = self.turns.as_mut().unwrap();
            if *left > 0 {
                *left -= 1;
                return Ok(());
            }
            match end.take() {
                Some(fault) => Err(fault),
                None => {
                    self.stop.set(true);
                    Ok(())
                }
            }
        }

        fn stop(&mut self, session: u32, ending: Ending<'_>) {
            self.stops.push(format!("{session}: {ending:?}"));
            if self.script.is_empty() {
                self.stop.set(true);
            }
        }

        fn link_down(&mut self, down: &Down<'_>) -> Result<(), &'static str> {
            self.downs
                .push((Instant::now(), down.why.to_string(), down.cause));
            Ok(())
        }
    }

    fn lost(why: &str) -> Step {
        Step::Connect(Err(ConnectError::Lost(why.into())))
    }

    const BACKOFF: Backoff = Backoff {
        first: Duration::from_millis(10),
        most: Duration::from_millis(80),
    };

    /// A lost link is tried again after a back-off that doubles up to the most, and starts from
    /// the first again once the device came up; a loss in service connects again after the first.
    #[test]
    fn a_lost_link_is_retried_with_back_off() {
        let mut fake = Fake::new([
            lost("no link"),
            lost("no link"),
            lost("no link"),
            lost("no link"),
            lost("no link"),
            Step::Connect(Ok(())),
            Step::Serve(3, Some(Fault::Lost("no answer".into()))),
            lost("no link"),
            Step::Connect(Ok(())),
            Step::Serve(2, None),
        ]);
        run(&mut fake, BACKOFF).unwrap();
        let gaps = fake.gaps();
        let ms = |m| Duration::from_millis(m);
        // At least the back-off (a loaded host only waits longer).
        for (gap, least) in gaps.iter().zip([10, 20, 40, 80, 80, 10, 10]) {
            assert!(*gap >= ms(least), "{gaps:?}");
        }
        assert_eq!(gaps.len(), 7);
        assert_eq!(fake.stops, ["1: Lost(\"no answer\")", "2: Stop"]);
        assert!(fake
            .downs
            .iter()
            .any(|(_, why, cause)| why == "no answer" && *cause == Cause::Lost));
    }

    /// A wrong device (or setting) is looked at again only every `most`, never at the lost
    /// link's fast back-off, and reported down by its kind.
    #[test]
    fn a_wrong_device_is_not_retried_fast() {
        let wrong = |why: &str| Step::Connect(Err(ConnectError::WrongDevice(why.into())));
        let mut fake = Fake::new([
            wrong("found a gripper, expected a hand"),
            wrong("found a gripper, expected a hand"),
            Step::Connect(Err(ConnectError::Setting("set protocol = v4".into()))),
            wrong("found a gripper, expected a hand"),
        ]);
        run(&mut fake, BACKOFF).unwrap();
        let gaps = fake.gaps();
        assert_eq!(gaps.len(), 3);
        assert!(gaps.iter().all(|g| *g >= BACKOFF.most), "{gaps:?}");
        let causes: Vec<Cause> = fake.downs.iter().map(|d| d.2).collect();
        assert!(causes.contains(&Cause::WrongDevice) && causes.contains(&Cause::Setting));
        assert!(!causes.contains(&Cause::Lost), "{causes:?}");
        assert!(fake.downs[0].1.starts_with("wrong device: found a gripper"));
        assert!(fake.stops.is_empty());
    }

    /// The hold hook runs exactly once per session, on each way out: a loss, a stop, and a
    /// failing host (whose error the loop returns).
    #[test]
    fn stop_holds_once_per_session_on_every_way_out() {
        let mut fake = Fake::new([
            Step::Connect(Ok(())),
            Step::Serve(5, Some(Fault::Lost("no answer".into()))),
            Step::Connect(Ok(())),
            Step::Serve(5, None),
        ]);
        run(&mut fake, BACKOFF).unwrap();
        assert_eq!(fake.stops, ["1: Lost(\"no answer\")", "2: Stop"]);

        let mut fake = Fake::new([
            Step::Connect(Ok(())),
            Step::Serve(1, Some(Fault::Failed("publish failed"))),
        ]);
        assert_eq!(run(&mut fake, BACKOFF), Err("publish failed"));
        assert_eq!(fake.stops, ["1: Failed"]);
        assert_eq!(fake.sessions, 1);
    }

    /// While the hand is away the host hears of it periodically, not only at each attempt, so
    /// its health keeps coming.
    #[test]
    fn link_down_is_reported_while_waiting() {
        let slow = Backoff {
            first: Duration::from_millis(500),
            most: Duration::from_millis(500),
        };
        let mut fake = Fake::new([lost("no link"), lost("no link")]);
        run(&mut fake, slow).unwrap();
        let first_wait: Vec<_> = fake
            .downs
            .iter()
            .filter(|d| d.0 < fake.connects[1])
            .collect();
        // One at the failure, then one every LINK_DOWN_REPORT of the 500 ms wait.
        assert!(first_wait.len() >= 3, "{}", first_wait.len());
        assert!(first_wait.iter().all(|d| d.1 == "no link"));
    }
}
