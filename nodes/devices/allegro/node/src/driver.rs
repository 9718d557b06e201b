//! The torque loop, clocked by the hand's own stream: the Allegro as a transport under the
//! hand-node core's session loop (`teleop_hand_node::session`, which owns reconnect, back-off,
//! the link-down reports and calling the stop once per session). Connecting opens the link and
//! brings the hand up (a hand of the other generation is a setting error, looked at again
//! slowly); a turn is one frame or its timeout, and per complete set of finger frames one PD
//! step and four torque frames; a run of missing cycles or bus errors loses the hand; every
//! session ends with zero torque and SYSTEM_OFF.
//!
//! The loop talks to the rest of the process through a [`Host`] (the node's ports, or the CLI's
//! `home` and `move`), so tests drive it without IPC. Per cycle it allocates nothing and logs
//! nothing; faults and reconnects are logged (rarely, and never one line per frame).

use std::time::Instant;

use teleop_allegro_protocol::{v4, Generation, Protocol, FINGERS, JOINTS};
use teleop_can_link::{BusState, CanFrame, CanLink, LinkError};
use teleop_hand_node::session::{self, Backoff, Cause, ConnectError, Ending, Fault, Transport};

use crate::bringup::{self, Hand, Identity};
use crate::config::Settings;
use crate::control::{Controller, Limits, VelocityFilter};
use crate::gather::{Gather, Pushed};
use crate::pace::{Pace, Timeout};
use crate::wire::{Incoming, Wire};

/// What the hand should do this cycle (rad, joint order): hold the last target followed (where
/// the hand was at its first cycle since bring-up if there was none), or follow the host's,
/// admitted and ramped by it (the node: `teleop-hand-node`'s `HandPorts`; a service command:
/// its `RampedMove`).
pub type Target = teleop_hand_node::Target<JOINTS>;

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
    /// each fault, and every `teleop_hand_node::session::LINK_DOWN_REPORT` while the session
    /// loop waits to bring the hand up again. An error ends the loop.
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()>;
}

/// Opens the link (again).
pub type Open<'a> = dyn FnMut() -> Result<Box<dyn CanLink>, LinkError> + 'a;

/// Runs until the host asks to stop, under the hand-node core's session loop: opens the link
/// with `open`, brings the hand up, serves its stream, and after any failure tries again
/// (backing off by `settings.backoff`; a hand of the other generation is looked at again only
/// every `backoff[1]`) without ever giving up. Every session ends with zero torque and
/// SYSTEM_OFF.
pub fn run(settings: &Settings, host: &mut impl Host, open: &mut Open<'_>) -> anyhow::Result<()> {
    let mut stream = Stream {
        settings,
        host,
        open,
        counters: Counters::default(),
        was_up: false,
    };
    let backoff = Backoff {
        first: settings.backoff[0],
        most: settings.backoff[1],
    };
    session::run(&mut stream, backoff)
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

/// The hand on its CAN stream, as the session loop's transport: a turn is one frame (or its
/// timeout), and on a complete set of finger frames one PD step and four torque frames.
struct Stream<'a, 'o, H: Host> {
    settings: &'a Settings,
    host: &'a mut H,
    open: &'a mut Open<'o>,
    /// Counters since the loop started (across reconnects).
    counters: Counters,
    /// True once the hand was up (a later bring-up is a reconnect).
    was_up: bool,
}

/// A hand that is up: its link and the state of its loop.
struct Up {
    link: Box<dyn CanLink>,
    hand: Hand,
    wire: Wire,
    /// PWM counts per N m in use.
    k: f64,
    controller: Controller,
    /// False until the host was told the hand came up (on the first turn).
    announced: bool,
    /// The identity, updated by the hand's answers.
    identity: Identity,
    gather: Gather,
    /// The target held: the last one followed, or where the hand was at its first cycle.
    held: Option<[f64; JOINTS]>,
    /// Cycles in a row with a missing finger frame or a bus error.
    run: u32,
    missed_since_complete: u32,
    deadline: Instant,
    /// A wait without finger frames on a link that stamps them is only suspected missing until
    /// the next frame's stamp tells (see `pace`).
    pace: Pace,
    next_info: Option<Instant>,
    info_query: Option<CanFrame>,
}

impl<H: Host> Transport for Stream<'_, '_, H> {
    type Session = Up;
    type Error = anyhow::Error;

    fn name(&self) -> &str {
        "Allegro Hand"
    }

    fn stop_requested(&self) -> bool {
        self.host.stop_requested()
    }

    fn connect(&mut self) -> Result<Up, ConnectError> {
        let mut link = (self.open)().map_err(|e| ConnectError::Lost(e.to_string()))?;
        let hand = bringup::resolve(&mut *link, self.settings).map_err(|e| {
            if e.is_setting() {
                ConnectError::Setting(e.to_string())
            } else {
                ConnectError::Lost(e.to_string())
            }
        })?;
        if self.was_up {
            self.counters.reconnects += 1;
        }
        self.was_up = true;
        let settings = self.settings;
        let wire = Wire::new(hand.generation, settings.device_id, settings.calibration);
        let k = pwm_per_nm(settings, &hand);
        let limits = Limits {
            pwm_per_nm: k,
            pwm: settings.pwm_limit,
            max_torque_nm: settings.max_torque_nm,
        };
        let controller = Controller::new(
            settings.kp,
            settings.kd,
            limits,
            VelocityFilter::new(settings.velocity_filter, settings.velocity_cutoff_hz),
        );
        let timeout = settings.frame_timeout;
        Ok(Up {
            link,
            identity: hand.identity.clone(),
            hand,
            info_query: wire.info_query(),
            wire,
            k,
            controller,
            announced: false,
            gather: Gather::new(),
            held: None,
            run: 0,
            missed_since_complete: 0,
            deadline: Instant::now() + timeout,
            pace: Pace::new(timeout, settings.late_frame_limit),
            next_info: settings.info_period.map(|p| Instant::now() + p),
        })
    }

    fn serve(&mut self, up: &mut Up) -> Result<(), Fault<anyhow::Error>> {
        if !up.announced {
            up.announced = true;
            let name = up.link.describe().to_string();
            tracing::info!(
                link = %name,
                generation = %up.hand.generation,
                pwm_per_nm = up.k,
                "hand up: running on its stream"
            );
            self.host
                .connected(&Connected {
                    link: &name,
                    generation: up.hand.generation,
                    identity: &up.hand.identity,
                    pwm_per_nm: up.k,
                })
                .map_err(Fault::Failed)?;
        }
        turn(self.settings, self.host, &mut self.counters, up)
    }

    fn stop(&mut self, mut up: Up, ending: Ending<'_>) {
        let stopped = bringup::shut_down(&mut *up.link, &up.wire);
        let link = up.link.describe();
        match (ending, stopped) {
            (Ending::Stop, Ok(())) => {
                tracing::info!(link, "stopping: sent zero torque and SYSTEM_OFF")
            }
            (Ending::Lost(why), Ok(())) => {
                tracing::warn!(link, "{why}: torque stopped, SYSTEM_OFF sent")
            }
            (Ending::Failed, Ok(())) => {
                tracing::warn!(link, "the node failed: torque stopped, SYSTEM_OFF sent")
            }
            (_, Err(e)) => tracing::warn!(link, "stopping: zero torque and SYSTEM_OFF failed: {e}"),
        }
    }

    fn link_down(&mut self, down: &session::Down<'_>) -> anyhow::Result<()> {
        self.host.link_down(&Down {
            why: down.why,
            counters: &self.counters,
            wrong_setting: down.cause == Cause::Setting,
        })
    }
}

/// One turn: the next frame (or its timeout), and on a complete set one PD step and the torque
/// frames; a fault ends the session.
fn turn(
    settings: &Settings,
    host: &mut impl Host,
    counters: &mut Counters,
    up: &mut Up,
) -> Result<(), Fault<anyhow::Error>> {
    let Up {
        link,
        wire,
        k,
        controller,
        identity,
        gather,
        held,
        run,
        missed_since_complete,
        deadline,
        pace,
        next_info,
        info_query,
        ..
    } = up;
    let (k, period, timeout) = (*k, settings.period.as_secs_f64(), settings.frame_timeout);
    if *run >= settings.missing_frame_limit {
        return Err(Fault::Lost(format!(
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
                *deadline = Instant::now() + timeout;
                // The suspected waits before it that its stamp shows were missed periods;
                // the others were late.
                let suspected = pace.suspected();
                let missed = pace.frame(link.rx_stamp_ms());
                counters.late_periods += u64::from(suspected.saturating_sub(missed));
                if missed > 0 {
                    // As if each had timed out: the set under way ends with the first.
                    let n = gather.timeout();
                    counters.missing_cycles += u64::from(missed);
                    counters.lost_frames += u64::from(n) + u64::from(missed - 1) * FINGERS as u64;
                    *missed_since_complete += missed;
                    *run += missed;
                }
                match gather.push(finger, q) {
                    Pushed::Pending => {}
                    Pushed::Missed(n) => {
                        counters.missing_cycles += 1;
                        counters.lost_frames += u64::from(n);
                        *missed_since_complete += 1;
                        *run += 1;
                    }
                    Pushed::Complete => {
                        let received_ns = teleop_runtime::now_ns();
                        let q = *gather.positions();
                        let dt = period * f64::from(1 + *missed_since_complete);
                        *missed_since_complete = 0;
                        let (target, holding) = match host.target() {
                            Target::Follow(t) => {
                                *held = Some(t);
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
                                    return Err(Fault::Lost(e.to_string()));
                                }
                                break;
                            }
                        }
                        *run = if sent { 0 } else { *run + 1 };
                        if let (Some(at), Some(query)) = (*next_info, info_query.as_ref()) {
                            if Instant::now() >= at {
                                *next_info = settings.info_period.map(|p| at + p);
                                if link.send(query).is_err() {
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
                        })
                        .map_err(Fault::Failed)?;
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
                return Err(Fault::Lost(e.to_string()));
            }
            // A bus-off or I/O error repeats at once: count one per timeout, not a burst.
            std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
        }
    }
    if !finger_frame && Instant::now() >= *deadline {
        if pace.timeout(timeout) == Timeout::Missed {
            let n = gather.timeout();
            counters.missing_cycles += 1;
            counters.lost_frames += u64::from(n);
            *missed_since_complete += 1;
            *run += 1;
        }
        *deadline = Instant::now() + timeout;
    }
    Ok(())
}
