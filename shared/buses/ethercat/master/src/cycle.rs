//! The cycle: bring-up to OP with a [`Driver`], then absolute-deadline scheduling; each cycle
//! packs the host's command (or, when it has none, the driver's hold, once), exchanges process
//! data, checks the AL state of every SubDevice and the working counter computed from the bus,
//! and hands the decoded inputs to the [`Host`]. Lost frames are counted and ridden out; an AL
//! error is acknowledged and OP requested again; a lost link brings the bus up again without a
//! process restart. On stop the device gets its hold outputs for a few cycles, then leaves OP.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use ethercrab::MainDevice;
use futures_lite::future::block_on;
use teleop_runtime::now_ns;

use crate::bus::{expected_wkc, recover_op, scan, Bus, Found, OpGroup, PreOpGroup};
use crate::driver::{Driver, Image, OwnExchange, OwnLayout};

/// Cycles the device gets its hold outputs for before the master leaves OP on stop.
const STOP_HOLD_CYCLES: u32 = 10;

/// How often [`Host::link_down`] is called while the master waits to bring the bus up again.
pub const LINK_DOWN_REPORT: Duration = Duration::from_millis(100);

/// How the master cycles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Settings {
    /// Cycle period.
    pub period: Duration,
    /// Without a valid exchange (an answer with the right working counter, every SubDevice in
    /// OP) for this long, the link counts as lost and the bus is brought up again.
    pub link_timeout: Duration,
}

/// Counters kept across reconnects.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counters {
    /// Cycles with a wrong working counter (or inputs the driver could not decode).
    pub wkc_errors: u32,
    /// Cycles whose frame was lost.
    pub lost_frames: u32,
    /// AL errors acknowledged with OP requested again.
    pub recoveries: u32,
}

/// What the master tells its host about the cycle, to count (it logs them itself).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// The driver could not pack the host's command (e.g. a value outside what the device's
    /// unit mode can express): the device holds. Reported every cycle it happens.
    Refused,
    /// A SubDevice dropped to SAFE-OP; its error was acknowledged and OP requested.
    Recovered,
    /// The device was lost (no valid exchange within the link timeout); bringing it up again.
    Lost,
}

/// One valid exchange, as the host sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Exchange {
    /// CLOCK_MONOTONIC right after the answer came back (the origin of the samples made from it).
    pub origin_ns: u64,
    /// True while the device holds (the host gave no command, or the driver could not take it).
    pub holding: bool,
    /// The counters so far.
    pub counters: Counters,
}

/// Where commands come from and decoded inputs go: the node's ports.
pub trait Host<D: Driver> {
    /// True once the master must stop (leaving OP cleanly).
    fn stop_requested(&self) -> bool;

    /// The command to follow now; `None`: the device holds (the host decides when: a stale
    /// command, the e-stop, a refused command; see `teleop-hand-node`). Called once per cycle.
    fn command(&mut self) -> Option<D::Command>;

    /// The device is in OP, configured by `driver`.
    fn connected(&mut self, driver: &D);

    /// A valid exchange and its decoded inputs (called every good cycle: no allocation, no
    /// blocking).
    fn exchanged(
        &mut self,
        driver: &D,
        inputs: &D::Inputs,
        exchange: &Exchange,
    ) -> anyhow::Result<()>;

    /// Something to count (see [`Event`]).
    fn event(&mut self, event: Event);

    /// The link is down (bring-up failed, or the device was lost); `counters` so far. Called
    /// after each failed bring-up and each loss, and every [`LINK_DOWN_REPORT`] while waiting to
    /// try again, so the host can keep reporting (its health above all) while the device is
    /// away.
    fn link_down(&mut self, counters: &Counters) -> anyhow::Result<()>;
}

/// The first bring-up back-off; it doubles after each failure up to [`MAX_BACKOFF`].
pub const FIRST_BACKOFF: Duration = Duration::from_millis(100);

/// The longest wait between bring-ups, and the wait after a [`WrongDevice`].
pub const MAX_BACKOFF: Duration = Duration::from_secs(2);

/// The bus holds another device than the driver's: its identity check refused what it found
/// (the refusal names both). Not a link that comes back by retrying fast: [`run`] logs it as an
/// error, once per distinct refusal, and looks again every [`MAX_BACKOFF`] (a device swapped
/// for the right one is still found).
#[derive(Debug, thiserror::Error)]
#[error("wrong device: {0:#}")]
pub struct WrongDevice(pub anyhow::Error);

/// Finds the device on the bus (identity check by `identify`, whose refusal becomes a
/// [`WrongDevice`]) and leaves it in PRE-OP.
pub async fn discover(
    md: &MainDevice<'static>,
    identify: impl FnOnce(&[Found]) -> anyhow::Result<()>,
) -> anyhow::Result<PreOpGroup> {
    let (group, found) = scan(md).await?;
    identify(&found).map_err(|e| anyhow::Error::new(WrongDevice(e)))?;
    Ok(group)
}

/// Scans the bus, checks the identity, lets the driver configure the device in PRE-OP, and goes
/// to OP.
pub async fn bring_up<D: Driver>(
    md: &MainDevice<'static>,
    driver: &mut D,
) -> anyhow::Result<OpGroup> {
    let group = discover(md, |found| driver.identify(found)).await?;
    driver.configure(md, &group).await?;
    group
        .into_op(md)
        .await
        .map_err(|e| anyhow::anyhow!("PRE-OP -> OP failed: {e}"))
}

/// Brings the device up and cycles until the host asks to stop; brings it up again (backing off
/// from [`FIRST_BACKOFF`] up to [`MAX_BACKOFF`]) whenever bring-up fails or the device is lost
/// (a failing host, e.g. a publish error inside the cycle, counts as lost too); a
/// [`WrongDevice`] is looked at again every [`MAX_BACKOFF`]. Returns an error only when the
/// host fails to report the link down.
pub fn run<D: Driver, H: Host<D>>(
    bus: &Bus,
    driver: &mut D,
    host: &mut H,
    settings: &Settings,
) -> anyhow::Result<()> {
    let mut counters = Counters::default();
    let mut backoff = FIRST_BACKOFF;
    // The last wrong device logged (each distinct one is logged once).
    let mut wrong_logged: Option<String> = None;
    while !host.stop_requested() {
        let bus = bus.current(); // a fresh bus once ethercrab's own task has ended (ethercrab:)
        match block_on(bring_up(bus.md(), driver)) {
            Ok(group) => {
                tracing::info!(
                    period_us = settings.period.as_micros() as u64,
                    expected_wkc = driver
                        .own_layout()
                        .map_or_else(|| expected_wkc(bus.md(), &group), |l| l.expected_wkc),
                    "{} in OP",
                    driver.name()
                );
                backoff = FIRST_BACKOFF;
                wrong_logged = None;
                host.connected(driver);
                match cycle(&bus, &group, driver, host, settings, &mut counters) {
                    Ok(()) => {
                        leave_op(&bus, group, driver.name());
                        break;
                    }
                    Err(e) => {
                        tracing::warn!(
                            "lost the {}: {e:#}; bringing the bus up again",
                            driver.name()
                        );
                        host.event(Event::Lost);
                        host.link_down(&counters)?;
                    }
                }
            }
            Err(e) if e.is::<WrongDevice>() => {
                let text = format!("{e:#}");
                if wrong_logged.as_ref() != Some(&text) {
                    tracing::error!(
                        "{} bring-up refused: {text}; looking again every {} ms",
                        driver.name(),
                        MAX_BACKOFF.as_millis()
                    );
                    wrong_logged = Some(text);
                }
                host.link_down(&counters)?;
                wait_link_down(MAX_BACKOFF, host, &counters)?;
            }
            Err(e) => {
                tracing::warn!(
                    "{} bring-up failed: {e:#}; retrying in {} ms",
                    driver.name(),
                    backoff.as_millis()
                );
                host.link_down(&counters)?;
                wait_link_down(backoff, host, &counters)?;
                backoff = (backoff * 2).min(MAX_BACKOFF);
            }
        }
    }
    tracing::info!("stopped");
    Ok(())
}

/// Waits `d` (less when the host asks to stop), telling the host the link is down every
/// [`LINK_DOWN_REPORT`].
fn wait_link_down<D: Driver>(
    d: Duration,
    host: &mut impl Host<D>,
    counters: &Counters,
) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut reported = start;
    while start.elapsed() < d && !host.stop_requested() {
        std::thread::sleep(Duration::from_millis(10));
        if reported.elapsed() >= LINK_DOWN_REPORT {
            reported = Instant::now();
            host.link_down(counters)?;
        }
    }
    Ok(())
}

/// Copies `outputs` into ethercrab's process image, SubDevice by SubDevice.
fn write_outputs(md: &MainDevice<'static>, group: &OpGroup, outputs: &Image) {
    for (i, sd) in group.iter(md).enumerate() {
        let mut io = sd.io_raw_mut();
        let part = outputs.subdevice(i);
        if let Some(dst) = io.outputs().get_mut(..part.len()) {
            dst.copy_from_slice(part);
        }
    }
}

/// Copies ethercrab's process image into `inputs`, SubDevice by SubDevice.
fn read_inputs(md: &MainDevice<'static>, group: &OpGroup, inputs: &mut Image) {
    for (i, sd) in group.iter(md).enumerate() {
        let io = sd.io_raw();
        let part = inputs.subdevice_mut(i);
        if let Some(src) = io.inputs().get(..part.len()) {
            part.copy_from_slice(src);
        }
    }
}

/// How the process data moves: ethercrab's group image, or one LRW the master builds from the
/// driver's [`OwnLayout`] (the group's own exchange then only reads the AL states).
enum Exchanger {
    Group,
    Own(OwnExchange),
}

impl Exchanger {
    fn new(layout: Option<OwnLayout>) -> Self {
        match layout {
            Some(layout) => Self::Own(OwnExchange::new(layout)),
            None => Self::Group,
        }
    }

    fn images(&self, md: &MainDevice<'static>, group: &OpGroup) -> (Image, Image) {
        match self {
            Self::Group => (
                Image::with_lengths(group.iter(md).map(|sd| sd.io_raw().outputs().len())),
                Image::with_lengths(group.iter(md).map(|sd| sd.io_raw().inputs().len())),
            ),
            Self::Own(own) => own.images(),
        }
    }

    fn expected_wkc(&self, md: &MainDevice<'static>, group: &OpGroup) -> u16 {
        match self {
            Self::Group => expected_wkc(md, group),
            Self::Own(own) => own.layout().expected_wkc,
        }
    }

    /// Puts the outputs where the next exchange sends them.
    fn write(&mut self, md: &MainDevice<'static>, group: &OpGroup, outputs: &Image) {
        match self {
            Self::Group => write_outputs(md, group, outputs),
            Self::Own(own) => own.write(outputs),
        }
    }

    /// One exchange: the AL states and the working counter (of the process data), the inputs
    /// copied into `inputs` when it came back.
    fn exchange(
        &mut self,
        md: &MainDevice<'static>,
        group: &OpGroup,
        inputs: &mut Image,
    ) -> Result<
        (ethercrab::TxRxResponse<{ crate::bus::MAX_SUBDEVICES }>, u16),
        ethercrab::error::Error,
    > {
        match self {
            Self::Group => {
                let response = block_on(group.tx_rx(md))?;
                let wkc = response.working_counter;
                read_inputs(md, group, inputs);
                Ok((response, wkc))
            }
            Self::Own(own) => {
                let wkc = block_on(own.exchange(md, inputs))?;
                let response = block_on(group.tx_rx(md))?;
                Ok((response, wkc))
            }
        }
    }
}

/// Cycles until stop (`Ok`) or until the device is lost (`Err`).
fn cycle<D: Driver, H: Host<D>>(
    bus: &Bus,
    group: &OpGroup,
    driver: &mut D,
    host: &mut H,
    settings: &Settings,
    counters: &mut Counters,
) -> anyhow::Result<()> {
    let md = bus.md();
    let period = settings.period;
    let mut exchanger = Exchanger::new(driver.own_layout());
    let expected = exchanger.expected_wkc(md, group);
    let subdevices = group.len();
    let (mut outputs, mut inputs) = exchanger.images(md, group);
    let polled: Mutex<Option<D::Polled>> = Mutex::new(None);
    let poll_period = driver.poll_period();
    let stop_poll = AtomicBool::new(false);

    std::thread::scope(|scope| -> anyhow::Result<()> {
        if let Some(poll_period) = poll_period {
            let (polled, stop_poll) = (&polled, &stop_poll);
            std::thread::Builder::new()
                .name("ecat-side-poll".into())
                .spawn_scoped(scope, move || {
                    side_channel::<D>(md, group, poll_period, polled, stop_poll)
                })?;
        }
        // This thread cycles at the real-time priority launch.toml names (its side thread,
        // started above, stays normal).
        teleop_runtime::realtime::enter_realtime();
        let result = (|| -> anyhow::Result<()> {
            let mut deadline = Instant::now();
            let mut last_inputs: Option<D::Inputs> = None;
            let mut refused = false;
            let mut holding = false;
            let mut lost_in_a_row = 0u32;
            let mut wrong_in_a_row = 0u32;
            let mut last_good = Instant::now();
            while !host.stop_requested() {
                // Absolute deadlines: a late cycle does not shift the ones after it.
                deadline += period;
                let now = Instant::now();
                if deadline > now {
                    teleop_runtime::sleep_until(deadline);
                } else if now - deadline > period * 10 {
                    deadline = now; // far behind (e.g. after a stall): re-anchor instead of bursting
                }
                // What to send: the host's command, or the driver's hold when it has none (the
                // host's policy: stale, e-stop, refused) or the driver cannot take it.
                let command = host.command();
                let fresh = command.is_some();
                let packed = command.is_some_and(|c| driver.pack(&c, &mut outputs));
                let write = if packed {
                    refused = false;
                    holding = false;
                    true
                } else {
                    if fresh {
                        if !refused {
                            tracing::warn!(
                                "the {} cannot take the hand command: the device holds",
                                driver.name()
                            );
                            refused = true;
                        }
                        host.event(Event::Refused);
                    } else {
                        refused = false;
                    }
                    if holding && !driver.hold_every_cycle() {
                        false // keep sending the hold already in the outputs
                    } else if last_inputs.is_some() || driver.hold_every_cycle() {
                        driver.hold(last_inputs.as_ref(), &mut outputs);
                        holding = true;
                        true
                    } else {
                        false
                    }
                };
                if write {
                    exchanger.write(md, group, &outputs);
                }
                let response = exchanger.exchange(md, group, &mut inputs);
                let origin_ns = now_ns();
                let (response, working_counter) = match response {
                    Ok(r) => {
                        lost_in_a_row = 0;
                        r
                    }
                    Err(e) => {
                        counters.lost_frames += 1;
                        lost_in_a_row += 1;
                        tracing::debug!("cycle lost: {e}");
                        if last_good.elapsed() > settings.link_timeout {
                            anyhow::bail!(
                                "no answer for {} ms ({lost_in_a_row} cycles; {e})",
                                last_good.elapsed().as_millis()
                            );
                        }
                        continue;
                    }
                };
                // The AL states come in the same frame; check them first: a SubDevice that lost
                // OP (watchdog, power cycle, emulator restart) also answers with a wrong working
                // counter, which must not hide it.
                if response.subdevice_states.len() != subdevices {
                    anyhow::bail!(
                        "the {} left OP: {} of {subdevices} SubDevices answered the state check",
                        driver.name(),
                        response.subdevice_states.len()
                    );
                }
                let mut recovered = false;
                for (index, state) in response.subdevice_states.iter().enumerate() {
                    match state {
                        ethercrab::SubDeviceState::Op => {}
                        ethercrab::SubDeviceState::SafeOp => {
                            let code = block_on(recover_op(md, group, index))?;
                            counters.recoveries += 1;
                            tracing::warn!(
                                subdevice = index,
                                al_status_code = format!("{code:#06x}"),
                                "{} dropped to SAFE-OP: acknowledged, OP requested",
                                driver.name()
                            );
                            host.event(Event::Recovered);
                            recovered = true;
                        }
                        other => {
                            anyhow::bail!(
                                "the {} left OP (SubDevice {index}: {other:?})",
                                driver.name()
                            )
                        }
                    }
                }
                if recovered {
                    holding = false; // re-send the hold/command after recovery
                    continue;
                }
                if working_counter != expected {
                    counters.wkc_errors += 1;
                    wrong_in_a_row += 1;
                    if counters.wkc_errors % 100 == 1 {
                        tracing::warn!(
                            wkc = working_counter,
                            expected,
                            total = counters.wkc_errors,
                            "wrong working counter: inputs of this cycle ignored"
                        );
                    }
                    if last_good.elapsed() > settings.link_timeout {
                        anyhow::bail!(
                            "{wrong_in_a_row} cycles in a row with a wrong working counter"
                        );
                    }
                    continue;
                }
                wrong_in_a_row = 0;
                last_good = Instant::now();
                let side =
                    poll_period.and_then(|_| *polled.lock().unwrap_or_else(|e| e.into_inner()));
                let Some(decoded) = driver.unpack(&inputs, side.as_ref()) else {
                    counters.wkc_errors += 1;
                    continue;
                };
                let exchange = Exchange {
                    origin_ns,
                    holding: !packed,
                    counters: *counters,
                };
                host.exchanged(driver, &decoded, &exchange)?;
                last_inputs = Some(decoded);
            }
            // Stopping: the driver's hold for a few cycles before leaving OP.
            if let Some(last) = &last_inputs {
                driver.hold(Some(last), &mut outputs);
                exchanger.write(md, group, &outputs);
                for _ in 0..STOP_HOLD_CYCLES {
                    let _ = exchanger.exchange(md, group, &mut inputs);
                    std::thread::sleep(period);
                }
                tracing::info!("sent hold before leaving OP");
            }
            Ok(())
        })();
        stop_poll.store(true, Ordering::SeqCst);
        teleop_runtime::realtime::leave_realtime();
        result
    })
}

/// Runs the driver's side channel every `period` until `stop`. A failure is logged once per run
/// of failures; a panic inside ethercrab (a CoE emergency answering an SDO) is caught.
fn side_channel<D: Driver>(
    md: &MainDevice<'static>,
    group: &OpGroup,
    period: Duration,
    out: &Mutex<Option<D::Polled>>,
    stop: &AtomicBool,
) {
    let mut failures = 0u32;
    while !stop.load(Ordering::SeqCst) {
        let started = Instant::now();
        let read = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| D::poll(md, group)));
        match read {
            Ok(Ok(value)) => {
                failures = 0;
                *out.lock().unwrap_or_else(|e| e.into_inner()) = Some(value);
            }
            Ok(Err(e)) => {
                failures += 1;
                if failures == 1 {
                    tracing::warn!("side-channel poll failed: {e:#}");
                }
            }
            Err(_) => tracing::error!(
                "side-channel poll panicked inside ethercrab (CoE emergency?); polling goes on"
            ),
        }
        std::thread::sleep(period.saturating_sub(started.elapsed()));
    }
}

/// Takes the device from OP down to INIT (logs the outcome; `name` is the device's).
pub fn leave_op(bus: &Bus, group: OpGroup, name: &str) {
    match block_on(async {
        let g = group.into_safe_op(bus.md()).await?;
        let g = g.into_pre_op(bus.md()).await?;
        g.into_init(bus.md()).await
    }) {
        Ok(_) => tracing::info!("{name} back in INIT"),
        Err(e) => tracing::warn!("leaving OP failed: {e}"),
    }
}
