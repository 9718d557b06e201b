//! The LEAP Hand's service commands, `teleop leap ...`: talk to the servos directly over the
//! serial port (the LEAP node must not be running: it holds the port). `info` pings and reads
//! every servo; `reboot` clears a hardware error (the servo comes back with its torque off);
//! `home` and `move` run the node's own loop ([`crate::driver`]) for a few seconds, ramping with
//! the core's `RampedMove`, and end as every session does: torque off on every servo (the hand goes
//! limp). The command-line arguments ([`Target`], [`LeapCommand`]) are here; `teleop` only
//! dispatches to [`run`].

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Subcommand;
use teleop_hand_node::{Aim, RampedMove};
use teleop_hand_profile::HandProfile;
use teleop_leap_protocol::xc330;
use teleop_runtime::args::parse_seconds;

use crate::bringup::{self, model_text};
use crate::bus::{Bus, BusError, SerialLine};
use crate::config::{Settings, SERVOS};
use crate::driver::{self, Connected, Cycle, Down, Host, Target as Goal};
use crate::servos::{self, status};
use crate::timing::Timing;

/// Where the hand is.
#[derive(clap::Args)]
pub struct Target {
    /// The serial port (default: the configuration's `port`).
    #[arg(long, env = "TELEOP_LEAP_PORT")]
    port: Option<String>,
    /// Bits per second (default: the configuration's `baud`).
    #[arg(long)]
    baud: Option<u32>,
    /// The node's configuration (IDs, model, gains, current); default: the built-in defaults,
    /// which are `config/leap.toml`'s (port /tmp/teleop-leap, 4 Mbit/s, IDs 0..15).
    #[arg(long)]
    config: Option<PathBuf>,
}

/// The LEAP Hand commands.
#[derive(Subcommand)]
pub enum LeapCommand {
    /// Every servo: model, firmware, ID, input voltage, temperature, hardware error status,
    /// operating mode, torque.
    Info,
    /// Reboot one servo (`--id N`) or all: clears a hardware error (overload, overheating...);
    /// the servo comes back with its torque off.
    Reboot {
        /// The servo's ID (default: every servo).
        #[arg(long)]
        id: Option<u8>,
    },
    /// Ramp every joint to the profile's open pose, hold it, then torque off.
    Home {
        /// Seconds from bring-up to torque off.
        #[arg(long, default_value = "3", value_parser = parse_seconds, allow_hyphen_values = true)]
        seconds: Duration,
    },
    /// Ramp one joint to an angle (the others hold where they are), then torque off.
    Move {
        /// The joint: its profile name (`ring_dip`) or its servo ID (0..15).
        joint: String,
        /// The angle in degrees, the profile's (0 = flat; clamped to the joint's limits).
        #[arg(allow_hyphen_values = true)]
        degrees: f64,
        /// Seconds from bring-up to torque off.
        #[arg(long, default_value = "2", value_parser = parse_seconds, allow_hyphen_values = true)]
        seconds: Duration,
    },
}

/// Runs one LEAP command against the hand at `target`.
pub fn run(target: &Target, command: &LeapCommand) -> anyhow::Result<ExitCode> {
    let (mut config, profile) = crate::load(target.config.as_deref())?;
    if let Some(port) = &target.port {
        config.port = port.clone();
    }
    if let Some(baud) = target.baud {
        config.baud = baud;
    }
    let origin = target
        .config
        .as_ref()
        .map_or("defaults".into(), |p| p.display().to_string());
    let settings = config
        .validate()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    crate::node::check_profile(&profile)?;
    match command {
        LeapCommand::Info => info(&settings, &profile),
        LeapCommand::Reboot { id } => reboot(&settings, &profile, *id),
        LeapCommand::Home { seconds } => {
            let mut goal = [0.0; SERVOS];
            for (g, j) in goal.iter_mut().zip(&profile.joints) {
                *g = f64::from(j.open);
            }
            drive(&settings, &profile, Aim::Pose(goal), *seconds)
        }
        LeapCommand::Move {
            joint,
            degrees,
            seconds,
        } => {
            let j = joint_index(&settings, &profile, joint)?;
            drive(
                &settings,
                &profile,
                Aim::Joint(j, degrees.to_radians()),
                *seconds,
            )
        }
    }?;
    Ok(ExitCode::SUCCESS)
}

/// The joint a name or a servo ID means.
fn joint_index(settings: &Settings, profile: &HandProfile, text: &str) -> anyhow::Result<usize> {
    if let Ok(id) = text.parse::<u8>() {
        return settings.ids.iter().position(|i| *i == id).ok_or_else(|| {
            anyhow::anyhow!("servo ID {id} is none of the hand's ({:?})", settings.ids)
        });
    }
    profile.joint_index(text).ok_or_else(|| {
        anyhow::anyhow!(
            "joint {text:?}: not a joint of the LEAP profile (a servo ID or one of {})",
            profile.joint_names().collect::<Vec<_>>().join(", ")
        )
    })
}

/// The least a service command waits for a reply beyond its wire time and return delay: one
/// question at a time, nothing to keep up with, so a loaded host's stall is no lost reply.
const SERVICE_REPLY_SLACK: Duration = Duration::from_millis(100);

/// Opens the port, naming a missing adapter plainly; the bus allows the servos' longest
/// return delay (they may not have been brought up) and at least [`SERVICE_REPLY_SLACK`].
fn open(settings: &Settings) -> anyhow::Result<Bus<SerialLine>> {
    let line = SerialLine::open(&settings.port, settings.baud).map_err(|e| {
        anyhow::anyhow!(
            "{}: cannot open ({e}); is the adapter plugged in, and the LEAP node stopped?",
            settings.port
        )
    })?;
    let timing = Timing::new(
        settings.baud,
        u8::MAX - 1,
        settings.reply_slack.max(SERVICE_REPLY_SLACK),
    );
    Ok(Bus::new(line, timing))
}

/// Reads `len` bytes at `addr` of `id`, or why not in words.
fn read(bus: &mut Bus<SerialLine>, id: u8, addr: u16, len: u16) -> Result<Vec<u8>, String> {
    match bus.read(id, addr, len) {
        Ok(r) if r.error.number().is_some() => Err(format!("refused: {}", r.error)),
        Ok(r) if r.data().len() == usize::from(len) => Ok(r.data().to_vec()),
        Ok(r) => Err(format!("{} bytes, expected {len}", r.data().len())),
        Err(e) => Err(e.to_string()),
    }
}

/// `info`: every servo's identity and condition.
fn info(settings: &Settings, profile: &HandProfile) -> anyhow::Result<()> {
    let mut bus = open(settings)?;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "port      {} at {} bit/s",
        settings.port, settings.baud
    )?;
    writeln!(
        out,
        "{:<20} {:>3}  {:<14} {:>3}  {:<26} {:<6} {:>7} {:>6}  hardware error",
        "joint", "id", "model", "fw", "mode", "torque", "voltage", "temp"
    )?;
    let mut answered = 0;
    for (j, &id) in settings.ids.iter().enumerate() {
        let name = &profile.joints[j].name;
        let (model, fw) = match bringup::ping(&mut bus, id) {
            Ok(v) => v,
            Err(BusError::Io(kind)) => {
                anyhow::bail!("{}: {}", settings.port, std::io::Error::from(kind))
            }
            Err(e) => {
                writeln!(out, "{name:<20} {id:>3}  silent ({e})")?;
                continue;
            }
        };
        answered += 1;
        let byte = |r: Result<Vec<u8>, String>| r.map(|d| d[0]);
        let mode = match byte(read(&mut bus, id, xc330::OPERATING_MODE, 1)) {
            Ok(m) => xc330::OperatingMode::from_value(m).map_or_else(
                || format!("{m} (unknown)"),
                |m| format!("{m} ({})", m.value()),
            ),
            Err(e) => e,
        };
        let torque = match byte(read(&mut bus, id, xc330::TORQUE_ENABLE, 1)) {
            Ok(0) => "off".to_string(),
            Ok(_) => "on".to_string(),
            Err(e) => e,
        };
        let (voltage, temp) = match read(&mut bus, id, xc330::PRESENT_INPUT_VOLTAGE, 3) {
            Ok(d) => (
                format!(
                    "{:.1} V",
                    f64::from(u16::from_le_bytes([d[0], d[1]])) * xc330::VOLTS_PER_VOLTAGE_UNIT
                ),
                format!("{} C", d[2]),
            ),
            Err(e) => (e, String::new()),
        };
        let hardware = match byte(read(&mut bus, id, xc330::HARDWARE_ERROR_STATUS, 1)) {
            Ok(0) => "none".to_string(),
            Ok(s) => format!(
                "{} (torque held off until `teleop leap reboot --id {id}`)",
                bringup::hardware_error_text(s)
            ),
            Err(e) => e,
        };
        writeln!(
            out,
            "{name:<20} {id:>3}  {:<14} {fw:>3}  {mode:<26} {torque:<6} {voltage:>7} {temp:>6}  \
             {hardware}",
            model_text(model)
        )?;
    }
    let c = bus.counters();
    writeln!(
        out,
        "{answered} of {SERVOS} servos answer; line: {} CRC errors, {} garbage bytes, {} timeouts",
        c.crc_errors, c.garbage_bytes, c.timeouts
    )?;
    Ok(())
}

/// `reboot`: one servo or every one.
fn reboot(settings: &Settings, profile: &HandProfile, id: Option<u8>) -> anyhow::Result<()> {
    let mut bus = open(settings)?;
    let ids: Vec<u8> = match id {
        Some(id) => vec![id],
        None => settings.ids.to_vec(),
    };
    let mut out = std::io::stdout().lock();
    let mut failed = 0;
    for id in ids {
        let name = settings.ids.iter().position(|i| *i == id).map_or_else(
            || format!("id {id}"),
            |j| format!("{} (id {id})", profile.joints[j].name),
        );
        match bus.reboot(id) {
            Ok(r) if r.error.number().is_none() => writeln!(out, "{name}: rebooted (torque off)")?,
            Ok(r) => {
                failed += 1;
                writeln!(out, "{name}: reboot refused: {}", r.error)?
            }
            Err(e) => {
                failed += 1;
                writeln!(out, "{name}: no reply to the reboot: {e}")?
            }
        }
    }
    if failed > 0 {
        anyhow::bail!("{failed} servo(s) not rebooted");
    }
    Ok(())
}

/// The CLI as the loop's host: the core's ramped move (toward the aim from where the hand was
/// at `resume_speed`, as the node ramps after a hold, until `seconds` after bring-up); then
/// stop (the loop turns the torque off).
struct CliHost<'p> {
    profile: &'p HandProfile,
    ramp: RampedMove<SERVOS>,
    last: [f64; SERVOS],
    last_current: [f64; SERVOS],
    last_status: [u32; SERVOS],
    cycles: u64,
}

impl Host for CliHost<'_> {
    fn stop_requested(&self) -> bool {
        teleop_runtime::stop_signal().is_some() || self.ramp.over(Instant::now())
    }

    fn target(&mut self) -> Goal {
        self.ramp.target()
    }

    fn connected(&mut self, _: &Connected<'_>) -> anyhow::Result<()> {
        self.ramp.started(Instant::now());
        Ok(())
    }

    fn cycle(&mut self, cycle: &Cycle<'_>) -> anyhow::Result<()> {
        for (j, joint) in self.profile.joints.iter().enumerate().take(SERVOS) {
            let r = cycle.servos.reading(j);
            self.last[j] = servos::position_rad(joint, r.position);
            self.last_current[j] = f64::from(r.current_ma);
            self.last_status[j] = cycle.servos.status_word(j);
        }
        self.cycles += 1;
        self.ramp.seen(&self.last);
        Ok(())
    }

    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        anyhow::bail!("{}", down.why)
    }
}

fn drive(
    settings: &Settings,
    profile: &HandProfile,
    aim: Aim<SERVOS>,
    seconds: Duration,
) -> anyhow::Result<()> {
    teleop_runtime::install_stop_handlers();
    let mut host = CliHost {
        profile,
        ramp: RampedMove::new(
            profile,
            aim,
            settings.resume_speed,
            settings.period,
            seconds,
        ),
        last: [0.0; SERVOS],
        last_current: [0.0; SERVOS],
        last_status: [0; SERVOS],
        cycles: 0,
    };
    // The port is opened here, so a missing adapter is named; the loop does not reopen it:
    // any fault ends the command through `link_down`.
    let mut first = Some(
        SerialLine::open(&settings.port, settings.baud).map_err(|e| {
            anyhow::anyhow!(
                "{}: cannot open ({e}); is the adapter plugged in, and the LEAP node stopped?",
                settings.port
            )
        })?,
    );
    let mut open = move || first.take().ok_or_else(|| "the port was lost".to_string());
    driver::run_on(settings, profile, &mut host, &mut open)?;
    if host.cycles == 0 {
        anyhow::bail!("stopped before the hand's first cycle");
    }
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{} at {} bit/s: torque off after {:.1} s",
        settings.port,
        settings.baud,
        seconds.as_secs_f64()
    )?;
    host.ramp.report(&mut out, profile, &host.last, |j| {
        let note = if host.last_status[j] & status::SILENT != 0 {
            "  (silent)"
        } else if host.last_status[j] & status::ALERT != 0 {
            "  (hardware error)"
        } else {
            ""
        };
        format!("current {:>5.0} mA{note}", host.last_current[j])
    })?;
    Ok(())
}
