//! The palm's service modes, outside the control cycle, for `teleop shadow` (the node must not
//! be running: both would drive the bus). A [`Service`] brings the hand up with the node's own
//! driver (identity, sync managers, FMMUs) and then exchanges one LRW per millisecond as the
//! tool needs:
//! - [`Service::info`]: normal mode with zero demands until every motor has sent its slow data
//!   (revision, serial) or 5 s passed;
//! - [`Service::channels`]: SENSOR_CHANNEL_NUMBERS mode: each sensor word's ADC and channel;
//! - [`Service::can_send`]: CAN direct mode, one crafted message and the reply;
//! - [`Service::flash`]: CAN direct mode, a motor board flashed by the shipped sequence
//!   (`teleop_shadow_protocol::flash`), one message per cycle. A failed exchange does not end
//!   it: the exchange is retried, then the message is sent again when its wait runs out, as the
//!   shipped driver does (see [`EXCHANGE_TRIES`]); only a bus without a single good exchange
//!   for [`BUS_GONE`] ends it.
//!
//! Freshness is judged by content: the inputs go out as zeros, so a status the palm did not
//! refill reads EDC command 0 and a bridge status it did not write reads bus 0.

use std::time::{Duration, Instant};

use futures_lite::future::block_on;
use teleop_ecat_master::{bring_up, Bus, Driver, Image, OpGroup, OwnExchange};
use teleop_shadow_protocol::can::{bus_of_motor, BootMessage};
use teleop_shadow_protocol::data::{EdcCommand, FromMotor};
use teleop_shadow_protocol::flash::{FlashError, Flasher, Poll, Settings};
use teleop_shadow_protocol::hex::Image as HexImage;
use teleop_shadow_protocol::layout::{CanBridge, Command, Status, MOTORS, SENSORS};

use crate::config::{Checked, ShadowConfig};
use crate::driver::{PalmInfo, Shadow, PALM};
use crate::motors::Motor;

/// How long `info` waits for every motor's slow data.
const INFO_TIMEOUT: Duration = Duration::from_millis(5500);
/// How long a palm may take to answer its first command.
const BOOT_TIMEOUT: Duration = Duration::from_secs(2);
/// How long `can_send` waits for a reply.
const REPLY_TIMEOUT: Duration = Duration::from_millis(100);
/// Tries of one exchange while flashing. The shipped driver's loop (shadow-robot/ros_ethercat,
/// `ethercat_hardware.cpp`, `EthercatHardware::txandrx_PD`) sends the process data again when it
/// does not come back, up to `max_pd_retries` = 100 ms / its 20 ms timeout = 5 times, and the
/// flasher (sr-ros-interface-ethercat, `sr_edc.cpp`) only sees a message without its
/// acknowledgement, which it sends again when its wait runs out. Here the retries carry an
/// idle bridge: a frame whose reply was lost may have reached the palm, and a DATA sent twice
/// would put 8 bytes too many into the bootloader's row buffer.
pub const EXCHANGE_TRIES: u32 = 5;
/// A flash ends with the bus's error after this long without one good exchange.
pub const BUS_GONE: Duration = Duration::from_secs(2);

/// The hand in OP, driven one cycle at a time.
pub struct Service {
    bus: Bus,
    group: Option<OpGroup>,
    exchange: OwnExchange,
    outputs: Image,
    inputs: Image,
    driver: Shadow,
    period: Duration,
    next: Instant,
}

/// What `info` found.
#[derive(Debug, Clone)]
pub struct Info {
    /// The palm's identity.
    pub palm: PalmInfo,
    /// Each motor's state, by motor number, with the joint it drives.
    pub motors: Vec<(usize, &'static str, Motor)>,
    /// Whether every motor sent every slow data type.
    pub complete: bool,
}

impl Service {
    /// Opens the bus of `config` and brings the hand up to OP.
    pub fn open(config: &ShadowConfig, checked: Checked) -> anyhow::Result<Self> {
        let period = Duration::from_secs_f64(1.0 / config.cycle_hz);
        let bus = Bus::open(teleop_ecat_master::connector(&checked.transport))?;
        let mut driver = Shadow::new(config.clone(), checked);
        let group = block_on(bring_up(bus.md(), &mut driver))?;
        let layout = driver
            .own_layout()
            .ok_or_else(|| anyhow::anyhow!("the Shadow driver has no process data layout"))?;
        let exchange = OwnExchange::new(layout);
        let (outputs, inputs) = exchange.images();
        let mut service = Self {
            bus,
            group: Some(group),
            exchange,
            outputs,
            inputs,
            driver,
            period,
            next: Instant::now(),
        };
        service.wait_running()?;
        Ok(service)
    }

    /// Normal cycles until the palm answers one (a palm that just powered up reports its boot
    /// status, 0xCC, and acts on nothing until it runs).
    fn wait_running(&mut self) -> anyhow::Result<()> {
        let until = Instant::now() + BOOT_TIMEOUT;
        while Instant::now() < until {
            self.driver.hold(None, &mut self.outputs);
            self.cycle()?;
            if self.status().is_some_and(|s| s.edc_command == 1) {
                return Ok(());
            }
        }
        anyhow::bail!(
            "the palm did not answer a SENSOR_DATA command within {} ms (still booting?)",
            BOOT_TIMEOUT.as_millis()
        )
    }

    /// The palm found.
    pub fn palm(&self) -> PalmInfo {
        self.driver.palm()
    }

    /// One cycle at the next deadline: the outputs as they are, the inputs back.
    fn cycle(&mut self) -> anyhow::Result<()> {
        self.next += self.period;
        let now = Instant::now();
        if self.next > now {
            teleop_runtime::sleep_until(self.next);
        } else {
            self.next = now;
        }
        self.exchange.write(&self.outputs);
        block_on(self.exchange.exchange_any(self.bus.md(), &mut self.inputs))
            .map_err(|e| anyhow::anyhow!("exchange with the palm failed: {e}"))
    }

    fn put(&mut self, command: &Command, bridge: &CanBridge) {
        let out = self.outputs.subdevice_mut(PALM);
        if out.len() >= Command::SIZE + CanBridge::SIZE {
            out[..Command::SIZE].copy_from_slice(&command.pack());
            out[Command::SIZE..Command::SIZE + CanBridge::SIZE].copy_from_slice(&bridge.pack());
        }
    }

    fn status(&self) -> Option<Status> {
        let part = self.inputs.subdevice(PALM);
        Status::unpack(part.get(..Status::SIZE)?)
            .ok()
            .filter(|s| s.edc_command != 0)
    }

    fn bridge_reply(&self) -> Option<CanBridge> {
        let part = self.inputs.subdevice(PALM);
        CanBridge::unpack(part.get(Status::SIZE..Status::SIZE + CanBridge::SIZE)?)
            .ok()
            .filter(|b| b.can_bus != 0)
    }

    fn direct(&self) -> Command {
        Command {
            edc_command: EdcCommand::CanDirectMode
                .value(self.driver.numbering())
                .unwrap_or(4),
            ..Command::default()
        }
    }

    /// Normal mode with zero demands until every motor has sent every slow data type (or
    /// 5.5 s): the palm and each motor's revision, serial, flags and temperature.
    pub fn info(&mut self) -> anyhow::Result<Info> {
        let start = Instant::now();
        while start.elapsed() < INFO_TIMEOUT && !self.driver.motors().started() {
            self.driver.hold(None, &mut self.outputs);
            self.cycle()?;
            let _ = self.driver.unpack(&self.inputs, None);
        }
        // A little longer for a voltage and a temperature reading of each motor.
        let until = Instant::now() + Duration::from_millis(2100);
        while Instant::now() < until {
            self.driver.hold(None, &mut self.outputs);
            self.cycle()?;
            let _ = self.driver.unpack(&self.inputs, None);
        }
        let dofs = self.driver.dofs();
        Ok(Info {
            palm: self.palm(),
            motors: (0..MOTORS)
                .map(|m| {
                    let joint = dofs[m].map_or("?", |d| d.name);
                    (m, joint, self.driver.motors().motors[m])
                })
                .collect(),
            complete: self.driver.motors().started(),
        })
    }

    /// SENSOR_CHANNEL_NUMBERS mode: each sensor word as `channel << 8 | ADC`.
    pub fn channels(&mut self) -> anyhow::Result<[u16; SENSORS]> {
        let numbering = self.driver.numbering();
        let command = Command {
            edc_command: EdcCommand::SensorChannelNumbers
                .value(numbering)
                .unwrap_or(2),
            from_motor_data_type: FromMotor::Flags as u32,
            ..Command::default()
        };
        let wanted = command.edc_command;
        for _ in 0..100 {
            self.put(&command, &CanBridge::default());
            self.cycle()?;
            if let Some(s) = self.status().filter(|s| s.edc_command == wanted) {
                return Ok(s.sensors);
            }
        }
        anyhow::bail!(
            "the palm did not answer SENSOR_CHANNEL_NUMBERS (EDC command {wanted}) in 100 ms"
        )
    }

    /// The first CAN-direct cycle carries an idle bridge message (the shipped flasher's dummy,
    /// id 0, before MAGIC: sr_edc.cpp `simple_motor_flasher`). The palm reads its bridge
    /// command sync manager only in CAN direct mode (E11 `this_node.c`), so whatever the host
    /// wrote there in normal mode is still in it: that cycle takes it, and a message written in
    /// the same frame would be refused.
    fn enter_direct(&mut self, direct: &Command) -> anyhow::Result<()> {
        self.put(direct, &CanBridge::default());
        self.cycle()
    }

    /// CAN direct mode: sends `message` on its bus once and returns the first message that
    /// comes back within 100 ms.
    pub fn can_send(&mut self, message: &CanBridge) -> anyhow::Result<Option<CanBridge>> {
        let direct = self.direct();
        self.enter_direct(&direct)?;
        self.put(&direct, message);
        self.cycle()?;
        if let Some(reply) = self.bridge_reply() {
            return Ok(Some(reply));
        }
        let until = Instant::now() + REPLY_TIMEOUT;
        while Instant::now() < until {
            self.put(&direct, &CanBridge::default());
            self.cycle()?;
            if let Some(reply) = self.bridge_reply() {
                return Ok(Some(reply));
            }
        }
        Ok(None)
    }

    /// Flashes motor `motor` (0..19) with `image` in CAN direct mode, one message per cycle;
    /// `progress(done, total)` after each verified row. The board is left in its bootloader on
    /// failure, ready to be flashed again.
    pub fn flash(
        &mut self,
        motor: u8,
        image: HexImage,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<(), FlashOutcome> {
        let (bus, id) = bus_of_motor(motor).ok_or(FlashOutcome::NoSuchMotor(motor))?;
        let mut flasher = Flasher::new(id, image, Settings::default());
        let direct = self.direct();
        if let Err(e) = self.enter_direct(&direct) {
            // Only a stale message is lost; MAGIC is retried on its timeout.
            tracing::debug!("flashing: the first CAN-direct cycle failed: {e:#}");
        }
        let start = Instant::now();
        let mut last_good = Instant::now();
        let mut shown = (usize::MAX, 0);
        loop {
            let now_ms = start.elapsed().as_millis() as u64;
            let bridge = match flasher.poll(now_ms) {
                Poll::Send(msg) => CanBridge {
                    can_bus: bus,
                    length: msg.len,
                    id: msg.id,
                    data: msg.data,
                },
                Poll::Wait(_) => CanBridge::default(),
                Poll::Done => return Ok(()),
                Poll::Failed(e) => return Err(FlashOutcome::Failed(e)),
            };
            self.put(&direct, &bridge);
            match self.cycle_retried(&direct) {
                Ok(()) => last_good = Instant::now(),
                Err(e) if last_good.elapsed() >= BUS_GONE => {
                    return Err(FlashOutcome::Bus(e));
                }
                // Nothing came back: the flasher sends its message again when its wait runs
                // out. The inputs are those of an earlier cycle: not read again.
                Err(e) => {
                    tracing::warn!("flashing: no exchange in {EXCHANGE_TRIES} tries: {e:#}");
                    continue;
                }
            }
            if let Some(reply) = self.bridge_reply().filter(|r| r.can_bus == bus) {
                flasher.receive(&BootMessage {
                    id: reply.id,
                    len: reply.length.min(8),
                    data: reply.data,
                });
            }
            let p = flasher.progress();
            if p != shown {
                shown = p;
                progress(p.0, p.1);
            }
        }
    }

    /// One cycle, and up to [`EXCHANGE_TRIES`] in all while the exchange fails, the retries
    /// with an idle bridge (in `mode`).
    fn cycle_retried(&mut self, mode: &Command) -> anyhow::Result<()> {
        let mut tries = 1;
        loop {
            match self.cycle() {
                Ok(()) => return Ok(()),
                Err(e) if tries >= EXCHANGE_TRIES => return Err(e),
                Err(e) => {
                    tracing::debug!("flashing: exchange {tries} failed ({e:#}), retrying");
                    tries += 1;
                    self.put(mode, &CanBridge::default());
                }
            }
        }
    }

    /// Takes the hand out of OP.
    pub fn close(mut self) {
        if let Some(group) = self.group.take() {
            teleop_ecat_master::leave_op(&self.bus, group, "Shadow Hand");
        }
    }
}

/// Why a flash did not complete.
#[derive(Debug, thiserror::Error)]
pub enum FlashOutcome {
    /// The motor number is not 0..19.
    #[error("motor {0}: the hand has motors 0..19")]
    NoSuchMotor(u8),
    /// The flasher gave up (the step, the address and what came back).
    #[error("{0}; the board stays in its bootloader: flash it again")]
    Failed(FlashError),
    /// The bus failed.
    #[error("{0:#}")]
    Bus(anyhow::Error),
}
