//! The cycle: bring-up to OP with a [`Driver`], then absolute-deadline scheduling; each cycle
//! packs the host's command (or, when it has none, the driver's hold, once), exchanges process
//! data, checks the AL state of every SubDevice and the working counter computed from the bus,
//! and hands the decoded inputs to the [`Host`]. Lost frames are counted and ridden out; an AL
//! error is acknowledged and OP requested again. [`run`] is the master as a transport under the
//! hand-node core's session loop (`teleop_hand_node::session`: the only place of reconnect,
//! back-off and the link-down reports): connecting is bring-up (a [`WrongDevice`] is its own
//! error), a turn is one cycle, and on stop the device gets its hold outputs for a few cycles,
//! then leaves OP. No message types or ports are used here.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ethercrab::MainDevice;
use futures_lite::future::block_on;
use teleop_hand_node::session::{self, Backoff, ConnectError, Down, Ending, Fault, Transport};
use teleop_runtime::now_ns;

use crate::bus::{expected_wkc, recover_op, scan, Bus, CurrentBus, Found, OpGroup, PreOpGroup};
use crate::driver::{Driver, Image, OwnExchange, OwnLayout};

/// Cycles the device gets its hold outputs for before the master leaves OP on stop.
const STOP_HOLD_CYCLES: u32 = 10;

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
    /// after each failed bring-up and each loss, and every
    /// `teleop_hand_node::session::LINK_DOWN_REPORT` while waiting to try again, so the host can
    /// keep reporting (its health above all) while the device is away.
    fn link_down(&mut self, counters: &Counters) -> anyhow::Result<()>;
}

/// The first bring-up back-off; it doubles after each failure up to [`MAX_BACKOFF`].
pub const FIRST_BACKOFF: Duration = Duration::from_millis(100);

/// The longest wait between bring-ups, and the wait after a [`WrongDevice`].
pub const MAX_BACKOFF: Duration = Duration::from_secs(2);

/// The bus holds another device than the driver's: its identity check refused what it found
/// (the refusal names both). Not a link that comes back by retrying fast: [`run`] (the session
/// loop) logs it as an error, again only when it changes or every 10 s, and looks again every
/// [`MAX_BACKOFF`] (a device swapped for the right one is still found).
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

/// Brings the device up and cycles until the host asks to stop, under the hand-node core's
/// session loop (`teleop_hand_node::session`): brings it up again (backing off from
/// [`FIRST_BACKOFF`] up to [`MAX_BACKOFF`]) whenever bring-up fails or the device is lost (a
/// failing host, e.g. a publish error inside the cycle, counts as lost too); a [`WrongDevice`]
/// is looked at again every [`MAX_BACKOFF`]. On stop the device gets its hold outputs for a few
/// cycles, then leaves OP. Returns an error only when the host fails to report the link down.
pub fn run<D: Driver, H: Host<D>>(
    bus: &Bus,
    driver: &mut D,
    host: &mut H,
    settings: &Settings,
) -> anyhow::Result<()> {
    std::thread::scope(|scope| {
        let mut master = Master {
            bus,
            driver,
            host,
            settings,
            scope,
            counters: Counters::default(),
        };
        let backoff = Backoff {
            first: FIRST_BACKOFF,
            most: MAX_BACKOFF,
        };
        session::run(&mut master, backoff)
    })?;
    tracing::info!("stopped");
    Ok(())
}

/// The master with a driver and its host, as the session loop's transport: a turn is one cycle.
struct Master<'a, 'scope, 'env, D, H> {
    bus: &'env Bus,
    driver: &'a mut D,
    host: &'a mut H,
    settings: &'a Settings,
    /// Where the side channel's thread runs (it borrows the bus).
    scope: &'scope std::thread::Scope<'scope, 'env>,
    counters: Counters,
}

/// The driver's side channel: its thread, its latest reading, and its stop.
struct SideChannel<'scope, P> {
    polled: Arc<Mutex<Option<P>>>,
    stop: Arc<AtomicBool>,
    thread: std::thread::ScopedJoinHandle<'scope, ()>,
}

/// A device in OP and the state of its cycle.
struct Cycling<'scope, 'env, D: Driver> {
    bus: CurrentBus<'env>,
    group: Arc<OpGroup>,
    exchanger: Exchanger,
    expected: u16,
    subdevices: usize,
    outputs: Image,
    inputs: Image,
    side: Option<SideChannel<'scope, D::Polled>>,
    deadline: Instant,
    last_inputs: Option<D::Inputs>,
    refused: bool,
    holding: bool,
    lost_in_a_row: u32,
    wrong_in_a_row: u32,
    last_good: Instant,
}

impl<'scope, 'env, D, H> Transport for Master<'_, 'scope, 'env, D, H>
where
    D: Driver + 'scope,
    H: Host<D>,
{
    type Session = Cycling<'scope, 'env, D>;
    type Error = anyhow::Error;

    fn name(&self) -> &str {
        self.driver.name()
    }

    fn stop_requested(&self) -> bool {
        self.host.stop_requested()
    }

    fn connect(&mut self) -> Result<Self::Session, ConnectError> {
        let bus = self.bus.current(); // a fresh bus once ethercrab's own task has ended (ethercrab:)
        let group = match block_on(bring_up(bus.md(), self.driver)) {
            Ok(group) => group,
            Err(e) => {
                return Err(match e.downcast::<WrongDevice>() {
                    Ok(wrong) => ConnectError::WrongDevice(format!("{:#}", wrong.0)),
                    Err(e) => ConnectError::Lost(format!("bring-up failed: {e:#}")),
                })
            }
        };
        let md = bus.md();
        let exchanger = Exchanger::new(self.driver.own_layout());
        let expected = exchanger.expected_wkc(md, &group);
        tracing::info!(
            period_us = self.settings.period.as_micros() as u64,
            expected_wkc = expected,
            "{} in OP",
            self.driver.name()
        );
        let subdevices = group.len();
        let (outputs, inputs) = exchanger.images(md, &group);
        let group = Arc::new(group);
        let side = match self.driver.poll_period() {
            Some(period) => {
                let polled = Arc::new(Mutex::new(None));
                let stop = Arc::new(AtomicBool::new(false));
                let (bus, group, out, halt) =
                    (bus.clone(), group.clone(), polled.clone(), stop.clone());
                let thread = std::thread::Builder::new()
                    .name("ecat-side-poll".into())
                    .spawn_scoped(self.scope, move || {
                        side_channel::<D>(bus.md(), &group, period, &out, &halt)
                    })
                    .map_err(|e| ConnectError::Lost(format!("side-channel thread: {e}")))?;
                Some(SideChannel {
                    polled,
                    stop,
                    thread,
                })
            }
            None => None,
        };
        self.host.connected(self.driver);
        // This thread cycles at the real-time priority launch.toml names (its side thread,
        // started above, stays normal).
        teleop_runtime::realtime::enter_realtime();
        Ok(Cycling {
            bus,
            group,
            exchanger,
            expected,
            subdevices,
            outputs,
            inputs,
            side,
            deadline: Instant::now(),
            last_inputs: None,
            refused: false,
            holding: false,
            lost_in_a_row: 0,
            wrong_in_a_row: 0,
            last_good: Instant::now(),
        })
    }

    fn serve(&mut self, c: &mut Self::Session) -> Result<(), Fault<anyhow::Error>> {
        cycle(self.driver, self.host, self.settings, &mut self.counters, c)
            .map_err(|e| Fault::Lost(format!("{e:#}")))
    }

    fn stop(&mut self, mut c: Self::Session, ending: Ending<'_>) {
        let md = c.bus.md();
        if ending == Ending::Stop {
            // Stopping: the driver's hold for a few cycles before leaving OP.
            if let Some(last) = &c.last_inputs {
                self.driver.hold(Some(last), &mut c.outputs);
                c.exchanger.write(md, &c.group, &c.outputs);
                for _ in 0..STOP_HOLD_CYCLES {
                    let _ = c.exchanger.exchange(md, &c.group, &mut c.inputs);
                    std::thread::sleep(self.settings.period);
                }
                tracing::info!("sent hold before leaving OP");
            }
        }
        teleop_runtime::realtime::leave_realtime();
        if let Some(side) = c.side.take() {
            side.stop.store(true, Ordering::SeqCst);
            if side.thread.join().is_err() {
                tracing::warn!("the side channel's thread panicked");
            }
        }
        if ending == Ending::Stop {
            match Arc::try_unwrap(c.group) {
                Ok(group) => leave_op(&c.bus, group, self.driver.name()),
                Err(_) => tracing::warn!("the group is still in use: not leaving OP"),
            }
        } else {
            self.host.event(Event::Lost);
        }
    }

    fn link_down(&mut self, _: &Down<'_>) -> anyhow::Result<()> {
        self.host.link_down(&self.counters)
    }
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

/// One cycle: waits for its absolute deadline, packs the host's command (or the driver's hold),
/// exchanges, checks the AL states and the working counter, and hands the decoded inputs to the
/// host. `Err`: the device is lost. No allocation while it goes well.
fn cycle<D: Driver, H: Host<D>>(
    driver: &mut D,
    host: &mut H,
    settings: &Settings,
    counters: &mut Counters,
    c: &mut Cycling<'_, '_, D>,
) -> anyhow::Result<()> {
    let md = c.bus.md();
    let group = &*c.group;
    let period = settings.period;
    // Absolute deadlines: a late cycle does not shift the ones after it.
    c.deadline += period;
    let now = Instant::now();
    if c.deadline > now {
        teleop_runtime::sleep_until(c.deadline);
    } else if now - c.deadline > period * 10 {
        c.deadline = now; // far behind (e.g. after a stall): re-anchor instead of bursting
    }
    // What to send: the host's command, or the driver's hold when it has none (the host's
    // policy: stale, e-stop, refused) or the driver cannot take it.
    let command = host.command();
    let fresh = command.is_some();
    let packed = command.is_some_and(|cmd| driver.pack(&cmd, &mut c.outputs));
    let write = if packed {
        c.refused = false;
        c.holding = false;
        true
    } else {
        if fresh {
            if !c.refused {
                tracing::warn!(
                    "the {} cannot take the hand command: the device holds",
                    driver.name()
                );
                c.refused = true;
            }
            host.event(Event::Refused);
        } else {
            c.refused = false;
        }
        if c.holding && !driver.hold_every_cycle() {
            false // keep sending the hold already in the outputs
        } else if c.last_inputs.is_some() || driver.hold_every_cycle() {
            driver.hold(c.last_inputs.as_ref(), &mut c.outputs);
            c.holding = true;
            true
        } else {
            false
        }
    };
    if write {
        c.exchanger.write(md, group, &c.outputs);
    }
    let response = c.exchanger.exchange(md, group, &mut c.inputs);
    let origin_ns = now_ns();
    let (response, working_counter) = match response {
        Ok(r) => {
            c.lost_in_a_row = 0;
            r
        }
        Err(e) => {
            counters.lost_frames += 1;
            c.lost_in_a_row += 1;
            tracing::debug!("cycle lost: {e}");
            if c.last_good.elapsed() > settings.link_timeout {
                anyhow::bail!(
                    "no answer for {} ms ({} cycles; {e})",
                    c.last_good.elapsed().as_millis(),
                    c.lost_in_a_row
                );
            }
            return Ok(());
        }
    };
    // The AL states come in the same frame; check them first: a SubDevice that lost OP
    // (watchdog, power cycle, emulator restart) also answers with a wrong working counter,
    // which must not hide it.
    if response.subdevice_states.len() != c.subdevices {
        anyhow::bail!(
            "the {} left OP: {} of {} SubDevices answered the state check",
            driver.name(),
            response.subdevice_states.len(),
            c.subdevices
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
        c.holding = false; // re-send the hold/command after recovery
        return Ok(());
    }
    if working_counter != c.expected {
        counters.wkc_errors += 1;
        c.wrong_in_a_row += 1;
        if counters.wkc_errors % 100 == 1 {
            tracing::warn!(
                wkc = working_counter,
                expected = c.expected,
                total = counters.wkc_errors,
                "wrong working counter: inputs of this cycle ignored"
            );
        }
        if c.last_good.elapsed() > settings.link_timeout {
            anyhow::bail!(
                "{} cycles in a row with a wrong working counter",
                c.wrong_in_a_row
            );
        }
        return Ok(());
    }
    c.wrong_in_a_row = 0;
    c.last_good = Instant::now();
    let side = c
        .side
        .as_ref()
        .and_then(|s| *s.polled.lock().unwrap_or_else(|e| e.into_inner()));
    let Some(decoded) = driver.unpack(&c.inputs, side.as_ref()) else {
        counters.wkc_errors += 1;
        return Ok(());
    };
    let exchange = Exchange {
        origin_ns,
        holding: !packed,
        counters: *counters,
    };
    host.exchanged(driver, &decoded, &exchange)
        .map_err(|e| e.context("the host failed"))?;
    c.last_inputs = Some(decoded);
    Ok(())
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
