//! The polled bus loop: the LEAP Hand as a transport under the hand-node core's session loop
//! (`teleop_hand_node::session`, which owns reconnect, back-off, the link-down reports and
//! calling the stop once per session).
//!
//! Connecting opens the serial port, finds the servos and brings them up ([`crate::bringup`]);
//! a servo that refuses a step leaves every servo's torque off and the connect fails. The host
//! is then told where the hand is (the state read at bring-up), before its first command, so
//! that the ramp to the commands starts there. A turn sleeps to the next absolute deadline at
//! `rate_hz`, writes the goals of every servo brought up and not silent in one Sync Write (the
//! admitted command within the profile's limits, or the goals held: for a fresh session where
//! the hand is), and reads current, velocity and position of every servo not silent in one
//! Fast Sync Read. Faults, each counted and named once:
//!
//! - a reply with a bad CRC, or bytes that are no packet: counted; the blocks of the reply
//!   whose CRC checks are taken, the others' state is the last one read;
//! - no reply, or a reply without some servos' blocks (cut short at a silent one): the first
//!   servo missing [`SILENT_AFTER`] cycles in a row is pinged (asked again after a lost reply)
//!   and, silent, named and left out
//!   of the reads and goals (its state marked stale); each is looked for again every
//!   `silent_retry_ms` and brought back when it answers (its goal set where it is; brought up
//!   again if it lost its torque), ramping to the commands at `resume_speed`;
//! - a block with the Alert bit: that servo's Hardware Error Status is read and named in words;
//!   the servo has turned its torque off and only a reboot clears it (the node holds the port:
//!   power-cycle the hand, or stop the node and run `teleop leap reboot`); the others go on,
//!   and nothing reboots it automatically. When its alert goes away (it was rebooted) it is
//!   brought up again;
//! - `failed_cycle_limit` cycles in a row without any servo's state, or a failing line: the hand
//!   is lost (the session loop reconnects with back-off).
//!
//! Every session ends with torque off: one broadcast Write that every servo hearing it carries
//! out (one the node took for silent too), then each answering servo confirmed. The loop talks
//! to the rest of the process through a [`Host`] (the node's ports, or the CLI's `home` and
//! `move`). Per cycle it allocates nothing and logs nothing while the servos behave.

use std::time::Instant;

use teleop_hand_node::session::{self, Backoff, ConnectError, Ending, Fault, Transport};
use teleop_hand_node::Resume;
use teleop_hand_profile::HandProfile;
use teleop_leap_protocol::xc330;

use crate::bringup::{self, Identity, Names, StepError};
use crate::bus::{Bus, BusCounters, BusError, FastRead, Line, SerialLine};
use crate::config::{Settings, SERVOS};
use crate::servos::{self, bit, joints, Mask, Servos};
use crate::timing::{Timing, P99};

/// What the hand should do this cycle (rad, joint order): hold the goals last written (where
/// the hand was at bring-up when none was), or follow the host's, admitted and ramped by it
/// (the node: `teleop-hand-node`'s `HandPorts`; a service command: its `RampedMove`).
pub type Target = teleop_hand_node::Target<SERVOS>;

/// Counters since the loop started (across reconnects).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counters {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles with a bad exchange (no reply, a corrupt one, a servo's block missing).
    pub bad_cycles: u64,
    /// Cycles without any servo's state.
    pub failed_cycles: u64,
    /// Deadlines missed by more than a period (the loop then starts again from now).
    pub overruns: u64,
    /// Times a servo went silent.
    pub silent_events: u64,
    /// Hardware errors reported (a servo's Alert, once per occurrence).
    pub hardware_errors: u64,
    /// Times the hand was brought up again after a loss.
    pub reconnects: u64,
    /// The line's counters (replies with bad CRCs, garbage, timeouts...).
    pub bus: BusCounters,
    /// The 99th percentile of the exchange time (goal write to state read) over the last
    /// [`P99_WINDOW`] cycles, microseconds.
    pub exchange_us_p99: u32,
}

/// Cycles over which the exchange time's 99th percentile is taken.
pub const P99_WINDOW: u32 = 500;

/// Cycles in a row a servo's block must be missing before it is pinged and, silent, left out.
pub const SILENT_AFTER: u8 = 3;

/// One cycle, as the host sees it.
#[derive(Debug, Clone, Copy)]
pub struct Cycle<'a> {
    /// The servos' latest state (fresh this cycle or not).
    pub servos: &'a Servos,
    /// The goals written, counts.
    pub goals: &'a [i32; SERVOS],
    /// True when the hand holds (no command followed this cycle).
    pub holding: bool,
    /// Counters so far.
    pub counters: &'a Counters,
    /// When the state was read (CLOCK_MONOTONIC ns).
    pub received_ns: u64,
}

/// The hand just came up.
#[derive(Debug, Clone, Copy)]
pub struct Connected<'a> {
    /// The serial port.
    pub port: &'a str,
    /// What the servos told.
    pub identity: &'a Identity,
    /// The servo IDs, in joint order.
    pub ids: &'a [u8; SERVOS],
    /// Where the hand is: the servos as read at bring-up (the goals they hold).
    pub bring_up: &'a Cycle<'a>,
}

/// The hand is not running.
#[derive(Debug, Clone, Copy)]
pub struct Down<'a> {
    /// Why (already logged by the loop).
    pub why: &'a str,
    /// Counters so far.
    pub counters: &'a Counters,
}

/// The rest of the process, as the loop sees it.
pub trait Host {
    /// True when the loop should stop (SIGINT/SIGTERM, a CLI's time is up).
    fn stop_requested(&self) -> bool;
    /// What to do this cycle (called once per cycle).
    fn target(&mut self) -> Target;
    /// The hand came up (after every bring-up, before the first [`Host::target`]).
    fn connected(&mut self, hand: &Connected<'_>) -> anyhow::Result<()>;
    /// One cycle was run.
    fn cycle(&mut self, cycle: &Cycle<'_>) -> anyhow::Result<()>;
    /// The hand is down (called after each failure and every
    /// `teleop_hand_node::session::LINK_DOWN_REPORT` while waiting). An error ends the loop.
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()>;
}

/// Opens the line (again).
pub type Open<'a, L> = dyn FnMut() -> Result<L, String> + 'a;

/// Runs until the host asks to stop, on the serial port of `settings`.
pub fn run(settings: &Settings, profile: &HandProfile, host: &mut impl Host) -> anyhow::Result<()> {
    let (port, baud) = (settings.port.clone(), settings.baud);
    let mut open =
        move || SerialLine::open(&port, baud).map_err(|e| format!("{port}: cannot open: {e}"));
    run_on(settings, profile, host, &mut open)
}

/// Runs until the host asks to stop, on the lines `open` gives.
pub fn run_on<L: Line>(
    settings: &Settings,
    profile: &HandProfile,
    host: &mut impl Host,
    open: &mut Open<'_, L>,
) -> anyhow::Result<()> {
    let names: Vec<String> = profile.joints.iter().map(|j| j.name.clone()).collect();
    let mut poll = Poll {
        settings,
        profile,
        names,
        host,
        open,
        counters: Counters::default(),
        was_up: false,
    };
    let backoff = Backoff {
        first: settings.backoff[0],
        most: settings.backoff[1],
    };
    session::run(&mut poll, backoff)
}

/// The polled bus as the session loop's transport.
struct Poll<'a, 'o, H: Host, L> {
    settings: &'a Settings,
    profile: &'a HandProfile,
    names: Vec<String>,
    host: &'a mut H,
    open: &'a mut Open<'o, L>,
    counters: Counters,
    was_up: bool,
}

/// A hand that is up: its bus and the state of its loop.
pub struct Up<L> {
    bus: Bus<L>,
    servos: Servos,
    identity: Identity,
    goals: [i32; SERVOS],
    /// Joints whose servo was brought up (its goal set where it was): the only ones written.
    driven: Mask,
    announced: bool,
    next: Instant,
    failed_run: u32,
    next_look: Instant,
    /// The silent joint looked for last (round robin).
    looked: usize,
    read: FastRead,
    /// The exchange times' 99th percentile.
    p99: P99,
    /// Servos brought up again while the hand runs: the ramp from where each held to the
    /// commands (the core's `Resume`, one joint each), until it has caught up.
    rejoin: [Option<Resume>; SERVOS],
    /// Cycles in a row each servo's block was missing from a reply that came.
    misses: [u8; SERVOS],
}

impl<H: Host, L: Line> Poll<'_, '_, H, L> {
    fn names(&self) -> Names<'_> {
        Names {
            joints: &self.names,
            ids: &self.settings.ids,
        }
    }

    /// Reads and reports the Hardware Error Status of joint `j` (its alert is on).
    fn report_alert(&mut self, up: &mut Up<L>, j: usize) {
        let id = self.settings.ids[j];
        let name = self.names().of(j);
        let status = match up.bus.read(id, xc330::HARDWARE_ERROR_STATUS, 1) {
            Ok(r) if r.error.number().is_none() => r.data().first().copied(),
            _ => None,
        };
        self.counters.hardware_errors += 1;
        up.servos.set_hardware_error(j, status.unwrap_or(0));
        let what = status.map_or_else(
            || "a hardware error (its status did not read)".to_string(),
            bringup::hardware_error_text,
        );
        tracing::error!(
            "{name}: {what}: the servo has turned its torque off and only a reboot clears it: \
             power-cycle the hand, or stop this node (it holds the port) and run `teleop leap \
             reboot --id {id}`; the other servos go on"
        );
    }

    /// Joint `j`'s servo answers again (or was rebooted): brings it back alone
    /// ([`bringup::bring_up_again`]).
    fn revive(&mut self, up: &mut Up<L>, j: usize, why: &str) {
        let name = self.names().of(j);
        match bringup::bring_up_again(&mut up.bus, self.settings, j) {
            Ok(state) => {
                up.servos.revive(j);
                up.servos.take(j, state);
                up.goals[j] = state.position;
                up.driven |= bit(j);
                // It holds where it is: the commands reach it by a ramp from there.
                let mut ramp = Resume::new(self.settings.resume_speed);
                ramp.held_at(&[servos::position_rad(
                    &self.profile.joints[j],
                    state.position,
                )]);
                up.rejoin[j] = Some(ramp);
                tracing::info!("{name}: {why}: back in the loop, torque on");
            }
            Err((what, StepError::Alert)) => {
                tracing::warn!("{name}: {why}, but {what}: still in a hardware error");
                self.report_alert(up, j);
            }
            Err((what, e)) => {
                tracing::warn!("{}", bringup::describe(&name, what, &e));
            }
        }
    }

    /// Servos asked sent no block: once the first of them has been missing [`SILENT_AFTER`]
    /// cycles in a row (one late reply on a loaded host, or one burst of noise, is no silent
    /// servo), it is pinged (asked again after a lost reply) and, silent, named and left out.
    /// Only the first: a chain cut short at a silent servo loses the blocks after it too, and
    /// those are asked again next cycle (a ping costs a reply's timeout, and sixteen would
    /// stall the loop).
    fn find_silent(&mut self, up: &mut Up<L>, missing: Mask) -> Result<(), BusError> {
        for (j, m) in up.misses.iter_mut().enumerate() {
            *m = if missing & bit(j) != 0 {
                m.saturating_add(1)
            } else {
                0
            };
        }
        let Some(j) = joints(missing).next() else {
            return Ok(());
        };
        if up.misses[j] < SILENT_AFTER {
            return Ok(());
        }
        up.misses[j] = 0;
        match bringup::ping(&mut up.bus, self.settings.ids[j]) {
            Ok(_) => Ok(()),
            Err(e @ BusError::Io(_)) => Err(e),
            Err(_) => {
                self.silent(up, j);
                Ok(())
            }
        }
    }

    /// Joint `j`'s servo is silent: named, left out of the reads.
    fn silent(&mut self, up: &mut Up<L>, j: usize) {
        up.servos.mark_silent(j);
        self.counters.silent_events += 1;
        tracing::warn!(
            "{} silent: left out of the cycle (its state is stale), looked for every {} ms",
            self.names().of(j),
            self.settings.silent_retry.as_millis()
        );
    }

    /// Looks for one silent servo when it is time.
    fn look_for_silent(&mut self, up: &mut Up<L>, now: Instant) -> Result<(), BusError> {
        let silent = up.servos.silent();
        if silent == 0 || now < up.next_look {
            return Ok(());
        }
        let n = silent.count_ones();
        up.next_look = now + self.settings.silent_retry / n;
        let j = (1..=SERVOS)
            .map(|k| (up.looked + k) % SERVOS)
            .find(|j| silent & bit(*j) != 0)
            .unwrap_or(0);
        up.looked = j;
        match up.bus.ping(self.settings.ids[j]) {
            Ok((model, _)) if model == self.settings.model => {
                self.revive(up, j, "answers again");
                Ok(())
            }
            Ok((model, _)) => {
                tracing::error!(
                    "{} answers as a {} (model {model}): not brought up",
                    self.names().of(j),
                    bringup::model_text(model)
                );
                Ok(())
            }
            Err(e @ BusError::Io(_)) => Err(e),
            Err(_) => Ok(()),
        }
    }
}

/// Torque off on every servo: one broadcast Write of Torque Enable = 0 (carried out by every
/// servo that hears it, also one the node took for silent; none answers), then each servo not
/// in `silent` confirmed by its own status (asked twice). How many confirmed, and the joints
/// that did not.
fn torque_off<L: Line>(bus: &mut Bus<L>, ids: &[u8; SERVOS], silent: Mask) -> (u32, Mask) {
    // A failing line fails the confirmations too: they say so.
    let _ = bus.broadcast_write(xc330::TORQUE_ENABLE, &[0]);
    let mut off = 0;
    let mut unconfirmed = 0;
    for (j, &id) in ids.iter().enumerate() {
        if silent & bit(j) != 0 {
            continue;
        }
        let mut done = false;
        for _ in 0..2 {
            match bus.write(id, xc330::TORQUE_ENABLE, &[0]) {
                Ok(r) if r.error.number().is_none() => {
                    done = true;
                    break;
                }
                Err(BusError::Io(_)) => break,
                _ => {}
            }
        }
        if done {
            off += 1;
        } else {
            unconfirmed |= bit(j);
        }
    }
    (off, unconfirmed)
}

/// The line failed: the hand is lost.
fn lost<E>(port: &str, e: BusError) -> Fault<E> {
    Fault::Lost(format!("{port}: {e}"))
}

impl<H: Host, L: Line> Transport for Poll<'_, '_, H, L> {
    type Session = Up<L>;
    type Error = anyhow::Error;

    fn name(&self) -> &str {
        "LEAP Hand"
    }

    fn stop_requested(&self) -> bool {
        self.host.stop_requested()
    }

    fn connect(&mut self) -> Result<Up<L>, ConnectError> {
        let settings = self.settings;
        let line = (self.open)().map_err(ConnectError::Lost)?;
        // Until the servos' Return Delay Time is written, allow the largest (254 x 2 us).
        let slow = Timing::new(settings.baud, u8::MAX - 1, settings.reply_slack);
        let mut bus = Bus::new(line, slow);
        bus.set_counters(self.counters.bus);
        let identity = bringup::find(&mut bus, settings, &self.names())?;
        for j in joints(identity.silent) {
            tracing::warn!(
                "{} silent at bring-up: the hand comes up without it",
                self.names().of(j)
            );
        }
        let mut states = [None; SERVOS];
        let mut failed = [const { None }; SERVOS];
        let all: Mask = Mask::MAX >> (Mask::BITS as usize - SERVOS);
        bringup::bring_up(
            &mut bus,
            settings,
            all & !identity.silent,
            &mut states,
            &mut failed,
        );
        bus.set_timing(Timing::new(
            settings.baud,
            settings.return_delay,
            settings.reply_slack,
        ));
        let mut servos = Servos::new(settings.ids, identity.silent);
        let mut goals = [0i32; SERVOS];
        let mut driven: Mask = 0;
        for (j, state) in states.iter().enumerate() {
            if let Some(state) = state {
                servos.take(j, *state);
                goals[j] = state.position;
                if failed[j].is_none() {
                    driven |= bit(j);
                }
            }
        }
        let mut alerts = Vec::new();
        for (j, f) in failed.iter().enumerate() {
            let Some((what, e)) = f else { continue };
            match e {
                StepError::Io(b) => {
                    return Err(ConnectError::Lost(format!("{}: {b}", settings.port)))
                }
                StepError::Refused(_) => {
                    // None runs with a setting refused: torque off on every one that may
                    // have turned it on (a refusal of the torque-on itself).
                    let (off, _) = torque_off(&mut bus, &settings.ids, identity.silent);
                    return Err(ConnectError::Setting(format!(
                        "{}; torque off on {off} servos",
                        bringup::describe(&self.names().of(j), what, e)
                    )));
                }
                StepError::Alert => alerts.push(j),
                StepError::NoReply(_) => {
                    tracing::warn!("{}", bringup::describe(&self.names().of(j), what, e));
                    servos.mark_silent(j);
                    self.counters.silent_events += 1;
                }
            }
        }
        if self.was_up {
            self.counters.reconnects += 1;
        }
        self.was_up = true;
        let now = Instant::now();
        let mut up = Up {
            bus,
            servos,
            identity,
            goals,
            driven,
            announced: false,
            next: now,
            failed_run: 0,
            next_look: now + settings.silent_retry,
            looked: SERVOS - 1,
            read: FastRead::EMPTY,
            p99: P99::new(P99_WINDOW),
            rejoin: [None; SERVOS],
            misses: [0; SERVOS],
        };
        for j in alerts {
            self.report_alert(&mut up, j);
        }
        Ok(up)
    }

    fn serve(&mut self, up: &mut Up<L>) -> Result<(), Fault<anyhow::Error>> {
        let settings = self.settings;
        if !up.announced {
            up.announced = true;
            tracing::info!(
                port = %settings.port,
                baud = settings.baud,
                rate_hz = 1.0 / settings.period.as_secs_f64(),
                "hand up: polling its servos"
            );
            self.host
                .connected(&Connected {
                    port: &settings.port,
                    identity: &up.identity,
                    ids: &settings.ids,
                    bring_up: &Cycle {
                        servos: &up.servos,
                        goals: &up.goals,
                        holding: true,
                        counters: &self.counters,
                        received_ns: teleop_runtime::now_ns(),
                    },
                })
                .map_err(Fault::Failed)?;
            up.next = Instant::now();
        }
        // The next absolute deadline; a stall of more than a period starts again from now.
        up.next += settings.period;
        let now = Instant::now();
        if now > up.next + settings.period {
            self.counters.overruns += 1;
            up.next = now;
        }
        teleop_runtime::sleep_until(up.next);
        let start = Instant::now();

        let holding = match self.host.target() {
            Target::Follow(t) => {
                let dt = settings.period.as_secs_f64();
                for (j, joint) in self.profile.joints.iter().enumerate().take(SERVOS) {
                    let mut rad = [t[j]];
                    if let Some(ramp) = &mut up.rejoin[j] {
                        if !ramp.follow(&mut rad, dt) {
                            up.rejoin[j] = None;
                        }
                    }
                    if let Some(c) = servos::goal_counts(joint, rad[0]) {
                        up.goals[j] = c;
                    }
                }
                false
            }
            Target::Hold => true,
        };
        let mut bytes = [[0u8; 4]; SERVOS];
        for (b, g) in bytes.iter_mut().zip(&up.goals) {
            *b = g.to_le_bytes();
        }
        // Only to the servos brought up (a goal where the hand is not known is no goal), and
        // not to the silent: one that hears again must not jump to a goal it missed the ramp
        // to (it is brought back, holding where it is, when it answers).
        let written = up.driven & !up.servos.silent();
        let items = settings
            .ids
            .iter()
            .zip(&bytes)
            .enumerate()
            .filter(|(j, _)| written & bit(*j) != 0)
            .map(|(_, (id, b))| (*id, &b[..]));
        up.bus
            .sync_write(xc330::GOAL_POSITION, 4, items)
            .map_err(|e| lost(&settings.port, e))?;

        up.servos.begin_cycle();
        let mut ask = [0u8; SERVOS];
        let n = up.servos.read_ids(&mut ask);
        let mut bad = false;
        if n > 0 {
            let read =
                up.bus
                    .fast_sync_read(xc330::STATE_ADDR, xc330::STATE_LEN, &ask[..n], &mut up.read);
            if let Err(e @ BusError::Io(_)) = read {
                return Err(lost(&settings.port, e));
            }
            // The blocks that came whole (all of them, or those at the start of a reply cut
            // short or damaged).
            let applied = up.servos.apply(&ask[..n], &up.read);
            bad = read.is_err() || applied.missing != 0;
            if !matches!(read, Err(BusError::Corrupt(_))) {
                // Which is silent: a chain may end its reply at a silent servo, leaving out
                // the ones after it (not documented: docs/devices/leap.md, "Unknown"). Noise
                // (a reply that does not check) names nobody and counts no miss.
                self.find_silent(up, applied.missing)
                    .map_err(|e| lost(&settings.port, e))?;
            }
            for j in joints(applied.new_alerts) {
                self.report_alert(up, j);
            }
            for j in joints(applied.cleared_alerts) {
                self.revive(up, j, "its hardware error cleared (rebooted)");
            }
        }
        self.look_for_silent(up, Instant::now())
            .map_err(|e| lost(&settings.port, e))?;
        let received_ns = teleop_runtime::now_ns();
        if let Some(us) = up.p99.add(start.elapsed()) {
            self.counters.exchange_us_p99 = us;
        }

        let c = &mut self.counters;
        c.cycles += 1;
        c.bad_cycles += u64::from(bad);
        if up.servos.fresh() == 0 {
            c.failed_cycles += 1;
            up.failed_run += 1;
            if up.failed_run >= settings.failed_cycle_limit {
                return Err(Fault::Lost(format!(
                    "{} cycles in a row without any servo's state",
                    up.failed_run
                )));
            }
        } else {
            up.failed_run = 0;
        }
        c.bus = *up.bus.counters();
        self.host
            .cycle(&Cycle {
                servos: &up.servos,
                goals: &up.goals,
                holding,
                counters: &self.counters,
                received_ns,
            })
            .map_err(Fault::Failed)
    }

    fn stop(&mut self, mut up: Up<L>, ending: Ending<'_>) {
        let (off, unconfirmed) = torque_off(&mut up.bus, &self.settings.ids, up.servos.silent());
        let refused: Vec<String> = joints(unconfirmed).map(|j| self.names().of(j)).collect();
        self.counters.bus = *up.bus.counters();
        let port = &self.settings.port;
        let silent = up.servos.silent().count_ones();
        let summary = format!(
            "torque off on {off} servos{}{}",
            if silent > 0 {
                format!(", {silent} silent (the broadcast only)")
            } else {
                String::new()
            },
            if refused.is_empty() {
                String::new()
            } else {
                format!("; not confirmed: {}", refused.join(", "))
            }
        );
        match ending {
            Ending::Stop => tracing::info!(port, "stopping: {summary}"),
            Ending::Lost(why) => tracing::warn!(port, "{why}: {summary}"),
            Ending::Failed => tracing::warn!(port, "the node failed: {summary}"),
        }
    }

    fn link_down(&mut self, down: &session::Down<'_>) -> anyhow::Result<()> {
        self.host.link_down(&Down {
            why: down.why,
            counters: &self.counters,
        })
    }
}
