//! The torque loop, clocked by the hand's own stream, with its reconnect: open the link, bring
//! the hand up, then per complete set of finger frames one PD step and four torque frames,
//! until stop (zero torque, SYSTEM_OFF) or a fault (a run of missing cycles or bus errors:
//! zero torque, SYSTEM_OFF, and the link opened and the hand brought up again).
//!
//! The loop talks to the rest of the process through a [`Host`] (the node's ports, or the CLI's
//! `home` and `move`), so tests drive it without IPC. Per cycle it allocates nothing and logs
//! nothing; faults and reconnects are logged (rarely, and never one line per frame).

use std::time::{Duration, Instant};

use teleop_allegro_protocol::{v4, Generation, Protocol, FINGERS, JOINTS};
use teleop_can_link::{BusState, CanLink, LinkError};

use crate::bringup::{self, Hand, Identity};
use crate::config::Settings;
use crate::control::{Controller, Limits, VelocityFilter};
use crate::gather::{Gather, Pushed};
use crate::pace::{Pace, Timeout};
use crate::wire::{Incoming, Wire};

/// What the hand should do this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// Hold the last target followed (where the hand was at its first cycle since bring-up if
    /// there was none).
    Hold,
    /// Go to these joint angles (rad, joint order) this cycle, as they are: the host has
    /// admitted them and ramps them after a hold (the node: `teleop-hand-node`'s `HandPorts`;
    /// a service command: its `Resume`).
    Follow([f64; JOINTS]),
}

/// Counters since the loop started (across reconnects).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counters {
    /// Complete cycles (torque frames sent).
    pub cycles: u64,
    /// Cycles with a finger frame missing (a finger came again before the set was complete,
    /// or no frame within `frame_timeout_ms`).
    pub missing_cycles: u64,
    /// Finger frames missing from those cycles.
    pub lost_frames: u64,
    /// Frames with an id neither protocol knows (or the other generation's).
    pub unknown_frames: u64,
    /// Frames with a known id and a payload that does not decode.
    pub bad_frames: u64,
    /// Link errors (send or receive failed).
    pub bus_errors: u64,
    /// Joint torques limited (summed over cycles).
    pub limited: u64,
    /// Times the hand was brought up again after a fault.
    pub reconnects: u64,
    /// Waits without a finger frame that the next frame's stamp showed were the host's: the
    /// frames came late (a loaded host), none was missing.
    pub late_periods: u64,
}

impl Counters {
    /// Cycles with a bad exchange: missing finger frames or a bus error (`HandState::link_errors`).
    pub fn link_errors(&self) -> u64 {
        self.missing_cycles + self.bus_errors
    }
}

/// One complete cycle, as the host sees it.
#[derive(Debug, Clone, Copy)]
pub struct Cycle {
    /// Joint positions, rad.
    pub q: [f64; JOINTS],
    /// Filtered joint velocities, rad/s.
    pub qdot: [f64; JOINTS],
    /// Commanded torques, N m.
    pub torque: [f64; JOINTS],
    /// The target followed, rad.
    pub target: [f64; JOINTS],
    /// True when the hand holds (no fresh command).
    pub holding: bool,
    /// v4 joint temperatures, deg C (None: not reported).
    pub temperatures: [Option<u8>; JOINTS],
    /// v4: the newest info answer.
    pub info: Option<v4::Info>,
    /// The controller state the link reports.
    pub bus_state: BusState,
    /// Counters so far.
    pub counters: Counters,
    /// When the frame completing the set arrived (CLOCK_MONOTONIC ns).
    pub received_ns: u64,
}

/// The hand just came up.
#[derive(Debug, Clone, Copy)]
pub struct Connected<'a> {
    /// The link (`slcan:/dev/ttyACM0`).
    pub link: &'a str,
    /// The generation spoken.
    pub generation: Generation,
    /// What the hand told.
    pub identity: &'a Identity,
    /// PWM counts per N m in use.
    pub pwm_per_nm: f64,
}

/// The hand is not running.
#[derive(Debug, Clone, Copy)]
pub struct Down<'a> {
    /// Why (already logged by the loop).
    pub why: &'a str,
    /// Counters so far.
    pub counters: &'a Counters,
    /// True when the hand answers in the other protocol generation (a setting to change).
    pub wrong_setting: bool,
}

/// The rest of the process, as the loop sees it.
pub trait Host {
    /// True when the loop should stop (SIGINT/SIGTERM, a CLI's time is up).
    fn stop_requested(&self) -> bool;
    /// What to do this cycle (called once per complete cycle).
    fn target(&mut self) -> Target;
    /// The hand came up (after every bring-up).
    fn connected(&mut self, hand: &Connected<'_>) -> anyhow::Result<()>;
    /// One cycle was run.
    fn cycle(&mut self, cycle: &Cycle) -> anyhow::Result<()>;
    /// The hand is down (no link, no answer, or a fault): called after each failed attempt and
    /// each fault.
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()>;
}

/// Opens the link (again).
pub type Open<'a> = dyn FnMut() -> Result<Box<dyn CanLink>, LinkError> + 'a;

/// Logs an error when it differs from the previous one or 10 s after it was last logged.
struct Reporter {
    last: String,
    at: Option<Instant>,
}

impl Reporter {
    fn report(&mut self, text: &str, setting: bool) {
        let again = self.last == text
            && self
                .at
                .is_some_and(|t| t.elapsed() < Duration::from_secs(10));
        if again {
            return;
        }
        if setting {
            tracing::error!("{text}; retrying");
        } else {
            tracing::warn!("{text}; retrying");
        }
        self.last = text.to_string();
        self.at = Some(Instant::now());
    }

    fn clear(&mut self) {
        self.last.clear();
        self.at = None;
    }
}

/// Sleeps `d` in short slices, returning early when the host asks to stop.
fn pause(host: &impl Host, d: Duration) {
    let end = Instant::now() + d;
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if host.stop_requested() {
            return;
        }
        std::thread::sleep(left.min(Duration::from_millis(20)));
    }
}

/// How a serving run ended.
enum Ended {
    Stop,
    Fault(String),
}

/// Runs until the host asks to stop: opens the link with `open`, brings the hand up, serves
/// cycles, and after any failure tries again (backing off) without ever giving up.
pub fn run(settings: &Settings, host: &mut impl Host, open: &mut Open<'_>) -> anyhow::Result<()> {
    let mut counters = Counters::default();
    let mut backoff = settings.backoff[0];
    let mut reporter = Reporter {
        last: String::new(),
        at: None,
    };
    let mut was_up = false;
    while !host.stop_requested() {
        let mut link = match open() {
            Ok(link) => link,
            Err(e) => {
                let why = e.to_string();
                reporter.report(&why, false);
                host.link_down(&Down {
                    why: &why,
                    counters: &counters,
                    wrong_setting: false,
                })?;
                pause(host, backoff);
                backoff = (backoff * 2).min(settings.backoff[1]);
                continue;
            }
        };
        let hand = match bringup::resolve(&mut *link, settings) {
            Ok(hand) => hand,
            Err(e) => {
                let why = e.to_string();
                reporter.report(&why, e.is_setting());
                host.link_down(&Down {
                    why: &why,
                    counters: &counters,
                    wrong_setting: e.is_setting(),
                })?;
                drop(link);
                pause(host, backoff);
                backoff = (backoff * 2).min(settings.backoff[1]);
                continue;
            }
        };
        reporter.clear();
        backoff = settings.backoff[0];
        if was_up {
            counters.reconnects += 1;
        }
        was_up = true;
        let ended = serve(&mut *link, &hand, settings, host, &mut counters);
        let wire = Wire::new(hand.generation, settings.device_id, settings.calibration);
        let stopped = bringup::shut_down(&mut *link, &wire);
        match ended? {
            Ended::Stop => {
                match stopped {
                    Ok(()) => tracing::info!(
                        link = link.describe(),
                        "stopping: sent zero torque and SYSTEM_OFF"
                    ),
                    Err(e) => tracing::warn!("stopping: zero torque and SYSTEM_OFF failed: {e}"),
                }
                return Ok(());
            }
            Ended::Fault(why) => {
                let why = format!(
                    "{}: {why}: torque stopped, SYSTEM_OFF sent{}; bringing the hand up again",
                    link.describe(),
                    stopped.map_or_else(|e| format!(" (failed: {e})"), |()| String::new())
                );
                tracing::warn!("{why}");
                host.link_down(&Down {
                    why: &why,
                    counters: &counters,
                    wrong_setting: false,
                })?;
                drop(link);
                pause(host, settings.backoff[0]);
            }
        }
    }
    Ok(())
}

/// The PWM per N m of a hand: configured, else what a v4 hand's info says, else the
/// generation's.
pub fn pwm_per_nm(settings: &Settings, hand: &Hand) -> f64 {
    settings
        .pwm_per_nm
        .or_else(|| {
            (hand.generation.protocol() == Protocol::V4)
                .then(|| hand.identity.info.map(|i| i.pwm_per_nm()))
                .flatten()
        })
        .unwrap_or_else(|| hand.generation.default_pwm_per_nm())
}

/// Serves cycles until stop or a fault.
fn serve(
    link: &mut dyn CanLink,
    hand: &Hand,
    settings: &Settings,
    host: &mut impl Host,
    counters: &mut Counters,
) -> anyhow::Result<Ended> {
    let wire = Wire::new(hand.generation, settings.device_id, settings.calibration);
    let k = pwm_per_nm(settings, hand);
    let limits = Limits {
        pwm_per_nm: k,
        pwm: settings.pwm_limit,
        max_torque_nm: settings.max_torque_nm,
    };
    let mut controller = Controller::new(
        settings.kp,
        settings.kd,
        limits,
        VelocityFilter::new(settings.velocity_filter, settings.velocity_cutoff_hz),
    );
    let name = link.describe().to_string();
    tracing::info!(
        link = %name,
        generation = %hand.generation,
        pwm_per_nm = k,
        "hand up: running on its stream"
    );
    host.connected(&Connected {
        link: &name,
        generation: hand.generation,
        identity: &hand.identity,
        pwm_per_nm: k,
    })?;
    let mut identity = hand.identity.clone();
    let mut gather = Gather::new();
    // The target held: the last one followed, or where the hand was at its first cycle.
    let mut held: Option<[f64; JOINTS]> = None;
    let mut run = 0u32;
    let mut missed_since_complete = 0u32;
    let period = settings.period.as_secs_f64();
    let timeout = settings.frame_timeout;
    let mut deadline = Instant::now() + timeout;
    // A wait without finger frames on a link that stamps them is only suspected missing until
    // the next frame's stamp tells (see `pace`).
    let mut pace = Pace::new(timeout, settings.late_frame_limit);
    let mut next_info = settings.info_period.map(|p| Instant::now() + p);
    let info_query = wire.info_query();
    loop {
        if host.stop_requested() {
            return Ok(Ended::Stop);
        }
        if run >= settings.missing_frame_limit {
            return Ok(Ended::Fault(format!(
                "{run} cycles in a row with a missing finger frame or a bus error"
            )));
        }
        let wait = deadline.saturating_duration_since(Instant::now());
        let received = link.recv(wait);
        let mut finger_frame = false;
        match received {
            Ok(Some(frame)) => match wire.decode(&frame) {
                Incoming::Position { finger, q } => {
                    finger_frame = true;
                    deadline = Instant::now() + timeout;
                    // The suspected waits before it that its stamp shows were missed periods;
                    // the others were late.
                    let suspected = pace.suspected();
                    let missed = pace.frame(link.rx_stamp_ms());
                    counters.late_periods += u64::from(suspected.saturating_sub(missed));
                    if missed > 0 {
                        // As if each had timed out: the set under way ends with the first.
                        let n = gather.timeout();
                        counters.missing_cycles += u64::from(missed);
                        counters.lost_frames +=
                            u64::from(n) + u64::from(missed - 1) * FINGERS as u64;
                        missed_since_complete += missed;
                        run += missed;
                    }
                    match gather.push(finger, q) {
                        Pushed::Pending => {}
                        Pushed::Missed(n) => {
                            counters.missing_cycles += 1;
                            counters.lost_frames += u64::from(n);
                            missed_since_complete += 1;
                            run += 1;
                        }
                        Pushed::Complete => {
                            let received_ns = teleop_runtime::now_ns();
                            let q = *gather.positions();
                            let dt = period * f64::from(1 + missed_since_complete);
                            missed_since_complete = 0;
                            let (target, holding) = match host.target() {
                                Target::Follow(t) => {
                                    held = Some(t);
                                    (t, false)
                                }
                                Target::Hold => (*held.get_or_insert(q), true),
                            };
                            let out = controller.step(&q, dt, &target);
                            counters.limited += u64::from(out.limited);
                            let mut sent = true;
                            for f in &wire.torque_frames(&out.torque, k, &settings.pwm_limit) {
                                if let Err(e) = link.send(f) {
                                    counters.bus_errors += 1;
                                    sent = false;
                                    if !e.is_recoverable()
                                        || matches!(e, LinkError::Disconnected { .. })
                                    {
                                        return Ok(Ended::Fault(e.to_string()));
                                    }
                                    break;
                                }
                            }
                            run = if sent { 0 } else { run + 1 };
                            if let (Some(at), Some(query)) = (next_info, info_query) {
                                if Instant::now() >= at {
                                    next_info = settings.info_period.map(|p| at + p);
                                    if link.send(&query).is_err() {
                                        counters.bus_errors += 1;
                                    }
                                }
                            }
                            counters.cycles += 1;
                            host.cycle(&Cycle {
                                q,
                                qdot: out.qdot,
                                torque: out.torque,
                                target,
                                holding,
                                temperatures: identity.temperatures,
                                info: identity.info,
                                bus_state: link.bus_state(),
                                counters: *counters,
                                received_ns,
                            })?;
                        }
                    }
                }
                Incoming::Foreign(_) | Incoming::Unknown => counters.unknown_frames += 1,
                Incoming::Bad => counters.bad_frames += 1,
                Incoming::Other => {}
                other => {
                    identity.take(&other);
                }
            },
            Ok(None) => {}
            Err(e) => {
                // Counted in the run by the timeout below.
                counters.bus_errors += 1;
                if !e.is_recoverable() || matches!(e, LinkError::Disconnected { .. }) {
                    return Ok(Ended::Fault(e.to_string()));
                }
                // A bus-off or I/O error repeats at once: count one per timeout, not a burst.
                std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
            }
        }
        if !finger_frame && Instant::now() >= deadline {
            if pace.timeout(timeout) == Timeout::Missed {
                let n = gather.timeout();
                counters.missing_cycles += 1;
                counters.lost_frames += u64::from(n);
                missed_since_complete += 1;
                run += 1;
            }
            deadline = Instant::now() + timeout;
        }
    }
}
