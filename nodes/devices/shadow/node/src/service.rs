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
//!
//! The command line of `teleop shadow` ([`Target`], [`ShadowCommand`], [`run`]) is here too:
//! `teleop` only dispatches to it.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Subcommand;
use futures_lite::future::block_on;
use teleop_ecat_master::{bring_up, Bus, Driver, Image, OpGroup, OwnExchange};
use teleop_shadow_protocol::can::{bus_of_motor, BootMessage};
use teleop_shadow_protocol::data::{flags, EdcCommand, FromMotor};
use teleop_shadow_protocol::flash::{FlashError, Flasher, Poll, Settings};
use teleop_shadow_protocol::hex::{self, Image as HexImage};
use teleop_shadow_protocol::layout::{CanBridge, Command, Status, MOTORS, SENSORS};
use teleop_shadow_protocol::mapping::SENSOR_NAMES;

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

// The command line of `teleop shadow ...`: its arguments and the printing of what the service
// modes above return; `teleop` only dispatches to [`run`].

/// Where the hand is.
#[derive(clap::Args)]
pub struct Target {
    /// The bus: `interface:eth0`, `ethercrab:eth0` or `sim:SOCKET` (default: the configuration's
    /// `transport`).
    #[arg(long, env = "TELEOP_SHADOW_TRANSPORT")]
    transport: Option<String>,
    /// The node's configuration (mapping, numbering, expected ADC channels); default: the
    /// built-in defaults (transport `sim:/tmp/teleop-shadow.sock`).
    #[arg(long)]
    config: Option<PathBuf>,
}

/// The Shadow commands.
#[derive(Subcommand)]
pub enum ShadowCommand {
    /// The palm's identity, and each motor's firmware revision, serial number (slow data),
    /// flags and temperature.
    Info,
    /// Flash a motor board from an Intel HEX file (MAGIC, ERASE, 32-byte rows, read-back,
    /// RESET), with a progress bar. A failed board stays in its bootloader: flash it again.
    Flash {
        /// The image (Intel HEX, as the PIC18F tool chain writes it).
        file: PathBuf,
        /// The motor, 0..19 (0..9 on CAN bus 1, 10..19 on bus 2).
        #[arg(long)]
        motor: u8,
    },
    /// Send one crafted CAN message in CAN direct mode and print what comes back (100 ms).
    CanSend {
        /// The CAN bus, 1 or 2.
        bus: u8,
        /// The 11-bit SID, hex (`0x64A` or `64A`).
        sid: String,
        /// Up to 8 data bytes, hex (`55AA55AA`; empty: none).
        #[arg(default_value = "")]
        bytes: String,
    },
    /// SENSOR_CHANNEL_NUMBERS mode: each joint sensor's ADC and channel, checked against the
    /// configuration's `[channels]` table (exit 1 on a mismatch).
    Channels,
}

fn load(target: &Target) -> anyhow::Result<Service> {
    let (mut config, origin) = match &target.config {
        Some(p) => (
            teleop_runtime::load_toml::<ShadowConfig>(p)?,
            p.display().to_string(),
        ),
        None => (ShadowConfig::default(), "defaults".to_string()),
    };
    if let Some(t) = &target.transport {
        config.transport = t.clone();
    }
    let checked = config
        .validate()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    Service::open(&config, checked).map_err(|e| {
        anyhow::anyhow!(
            "{e:#} (is the Shadow Hand on {}, and the Shadow node stopped?)",
            config.transport
        )
    })
}

/// Runs one Shadow command against the hand at `target`.
pub fn run(target: &Target, command: &ShadowCommand) -> anyhow::Result<ExitCode> {
    // What `flash` and `can-send` are given is checked before the bus is touched.
    let prepared = match command {
        ShadowCommand::Flash { file, motor } => {
            if *motor >= 20 {
                anyhow::bail!("--motor {motor}: the hand has motors 0..19");
            }
            Some(Prepared::Image(read_image(file)?))
        }
        ShadowCommand::CanSend { bus, sid, bytes } => {
            Some(Prepared::Message(message(*bus, sid, bytes)?))
        }
        _ => None,
    };
    let mut service = load(target)?;
    let result = match (command, prepared) {
        (ShadowCommand::Info, _) => info(&mut service),
        (ShadowCommand::Flash { motor, file }, Some(Prepared::Image(image))) => {
            flash(&mut service, *motor, file, image)
        }
        (ShadowCommand::CanSend { .. }, Some(Prepared::Message(m))) => can_send(&mut service, &m),
        (ShadowCommand::Channels, _) => channels(&mut service, target),
        _ => Ok(ExitCode::FAILURE),
    };
    service.close();
    result
}

enum Prepared {
    Image(HexImage),
    Message(CanBridge),
}

fn read_image(file: &Path) -> anyhow::Result<HexImage> {
    let text =
        std::fs::read_to_string(file).map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
    hex::parse(&text).map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))
}

fn message(bus: u8, sid: &str, bytes: &str) -> anyhow::Result<CanBridge> {
    if !(1..=2).contains(&bus) {
        anyhow::bail!("bus {bus}: the palm has CAN buses 1 and 2");
    }
    let id = u16::from_str_radix(sid.trim_start_matches("0x").trim_start_matches("0X"), 16)
        .ok()
        .filter(|id| *id <= 0x7FF)
        .ok_or_else(|| anyhow::anyhow!("SID {sid:?}: an 11-bit hex number (0..7FF)"))?;
    let hex: String = bytes.chars().filter(|c| !c.is_whitespace()).collect();
    if !hex.len().is_multiple_of(2) || hex.len() > 16 {
        anyhow::bail!("bytes {bytes:?}: up to 8 bytes as hex digit pairs");
    }
    let mut data = [0u8; 8];
    for (i, pair) in hex.as_bytes().chunks(2).enumerate() {
        let s = std::str::from_utf8(pair).unwrap_or("");
        data[i] = u8::from_str_radix(s, 16)
            .map_err(|_| anyhow::anyhow!("bytes {bytes:?}: {s:?} is not a hex byte"))?;
    }
    Ok(CanBridge {
        can_bus: bus,
        length: (hex.len() / 2) as u8,
        id,
        data,
    })
}

fn info(service: &mut Service) -> anyhow::Result<ExitCode> {
    let info = service.info()?;
    let p = info.palm;
    println!(
        "palm: product {} (SR06, protocol 0220), vendor {:#010x}, revision {}, serial {}",
        p.product_code, p.vendor_id, p.revision, p.serial
    );
    println!("motor  joint  revision  serial      flags   temp C  supply V");
    for (m, joint, motor) in &info.motors {
        let revision = motor.revision().map_or("-".into(), |r| r.to_string());
        let serial = motor.serial().map_or("-".into(), |s| format!("{s:#010x}"));
        let f = motor.flags;
        let named = flags::names(f);
        println!(
            "{m:>5}  {joint:<5}  {revision:>8}  {serial:<10}  {f:#06x}  {:>6.1}  {:>8.2}{}",
            motor.temperature_c,
            motor.voltage_v,
            if named.is_empty() {
                String::new()
            } else {
                format!("  ({})", named.join(", "))
            }
        );
    }
    if !info.complete {
        println!("(not every motor sent all its slow data within 5 s)");
    }
    Ok(ExitCode::SUCCESS)
}

fn flash(
    service: &mut Service,
    motor: u8,
    file: &Path,
    image: HexImage,
) -> anyhow::Result<ExitCode> {
    let rows = image.rows.len();
    println!(
        "flashing motor {motor} from {} ({rows} rows of 32 bytes)",
        file.display()
    );
    let started = std::time::Instant::now();
    let mut stderr = std::io::stderr();
    let result = service.flash(motor, image, &mut |done, total| {
        let width = 40;
        let filled = (done * width).checked_div(total).unwrap_or(0);
        let _ = write!(
            stderr,
            "\r[{}{}] {done}/{total} rows",
            "#".repeat(filled),
            " ".repeat(width - filled)
        );
        let _ = stderr.flush();
    });
    eprintln!();
    match result {
        Ok(()) => {
            println!(
                "motor {motor} flashed and restarted in {:.1} s",
                started.elapsed().as_secs_f64()
            );
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("error: motor {motor}: {e}");
            Ok(ExitCode::FAILURE)
        }
    }
}

fn can_send(service: &mut Service, m: &CanBridge) -> anyhow::Result<ExitCode> {
    let data = &m.data[..usize::from(m.length)];
    println!(
        "sent bus {} SID {:#05x} [{}] {}",
        m.can_bus,
        m.id,
        m.length,
        hex_bytes(data)
    );
    match service.can_send(m)? {
        Some(r) => {
            let data = &r.data[..usize::from(r.length.min(8))];
            println!(
                "reply bus {} SID {:#05x} [{}] {}",
                r.can_bus,
                r.id,
                r.length,
                hex_bytes(data)
            );
            Ok(ExitCode::SUCCESS)
        }
        None => {
            println!("no reply within 100 ms");
            Ok(ExitCode::FAILURE)
        }
    }
}

fn hex_bytes(data: &[u8]) -> String {
    data.iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn channels(service: &mut Service, target: &Target) -> anyhow::Result<ExitCode> {
    let expected = match &target.config {
        Some(p) => teleop_runtime::load_toml::<ShadowConfig>(p)?.channels,
        None => ShadowConfig::default().channels,
    };
    let words = service.channels()?;
    let mut mismatches = 0;
    println!("sensor  word    ADC  channel  expected");
    for (i, name) in SENSOR_NAMES.iter().enumerate().take(26) {
        let w = words[i];
        let (adc, channel) = ((w & 0xFF) as u8, (w >> 8) as u8);
        let verdict = match expected.get(*name) {
            Some([a, c]) if *a == adc && *c == channel => "ok".to_string(),
            Some([a, c]) => {
                mismatches += 1;
                format!("MISMATCH: ADC {a} channel {c}")
            }
            None => "(not in the table)".to_string(),
        };
        println!("{name:<6}  {w:#06x}  {adc:>3}  {channel:>7}  {verdict}");
    }
    if expected.is_empty() {
        println!("(no [channels] table in the configuration: nothing checked)");
    }
    if mismatches > 0 {
        println!("{mismatches} sensors are not wired as the table says");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}
