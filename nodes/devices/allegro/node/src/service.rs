//! The Allegro Hand's service commands, `teleop allegro ...`: talk to the hand directly over its
//! CAN link (the Allegro node must not be running: both would send torque). `info` brings the
//! hand up, reads what it tells and stops it again; `home` and `move` run the node's own PD loop
//! for a few seconds and release the hand (zero torque, SYSTEM_OFF). The command-line arguments
//! ([`Target`], [`AllegroCommand`]) are here; `teleop` only dispatches to [`run`].

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Subcommand;
use teleop_allegro_protocol::{v4, Generation, Protocol, JOINTS};
use teleop_can_link::{CanLink, LinkError};
use teleop_hand_node::{Aim, RampedMove};
use teleop_hand_profile::HandProfile;
use teleop_runtime::args::parse_seconds;

use crate::bringup::{self, Hand, Identity};
use crate::driver::{self, Connected, Cycle, Down, Host, Target as Goal};
use crate::wire::{Incoming, Wire};
use crate::{ProtocolSetting, Settings};

/// Where the hand is and how it speaks.
#[derive(clap::Args)]
pub struct Target {
    /// The CAN link: `slcan:/dev/ttyACM0`, `socketcan:can0`, `local:SOCKET` (default: the
    /// configuration's `link`).
    #[arg(long, env = "TELEOP_ALLEGRO_LINK")]
    link: Option<String>,
    /// `auto`, `v1`, `v2`, `v3` or `v4` (default: the configuration's `protocol`).
    #[arg(long)]
    protocol: Option<ProtocolSetting>,
    /// The node's configuration (gains, limits, calibration, device id); default: the built-in
    /// defaults (link `slcan:/tmp/teleop-allegro`, protocol `auto`).
    #[arg(long)]
    config: Option<PathBuf>,
}

/// The Allegro commands.
#[derive(Subcommand)]
pub enum AllegroCommand {
    /// Protocol generation, versions, serial number, temperatures, joint positions.
    Info,
    /// Drive the hand to the home pose (docs/devices/allegro.md: index and middle 0 -10 45 45,
    /// ring 5 -5 50 45, thumb 60 25 15 45 degrees) with the PD loop, then release it.
    Home {
        /// Seconds to hold the pose before releasing.
        #[arg(long, default_value = "3", value_parser = parse_seconds, allow_hyphen_values = true)]
        seconds: Duration,
    },
    /// Move one joint to an angle (the others hold where they are), then release the hand.
    Move {
        /// The joint: 0..15 (index 0-3, middle 4-7, ring 8-11, thumb 12-15) or its profile name
        /// (`index_1`).
        joint: String,
        /// The angle in degrees (clamped to the joint's limits).
        #[arg(allow_hyphen_values = true)]
        degrees: f64,
        /// Seconds to hold before releasing.
        #[arg(long, default_value = "2", value_parser = parse_seconds, allow_hyphen_values = true)]
        seconds: Duration,
    },
}

/// The home pose, degrees (docs/devices/allegro.md, "Joints, limits, gains").
const HOME_DEG: [f64; JOINTS] = [
    0.0, -10.0, 45.0, 45.0, 0.0, -10.0, 45.0, 45.0, 5.0, -5.0, 50.0, 45.0, 60.0, 25.0, 15.0, 45.0,
];

const FINGER_NAMES: [&str; 4] = ["index", "middle", "ring", "thumb"];

/// Runs one Allegro command against the hand at `target`.
pub fn run(target: &Target, command: &AllegroCommand) -> anyhow::Result<ExitCode> {
    let (mut config, profile) = crate::load(target.config.as_deref())?;
    if let Some(link) = &target.link {
        config.link = link.clone();
    }
    if let Some(p) = target.protocol {
        config.protocol = p;
    }
    let settings = config.validate().map_err(|e| {
        anyhow::anyhow!(
            "{}: {e}",
            target
                .config
                .as_ref()
                .map_or("defaults".into(), |p| p.display().to_string())
        )
    })?;
    let link = open(&settings)?;
    match command {
        AllegroCommand::Info => info(link, &settings),
        AllegroCommand::Home { seconds } => {
            let mut goal = [0.0; JOINTS];
            for (g, d) in goal.iter_mut().zip(HOME_DEG) {
                *g = d.to_radians();
            }
            drive(link, &settings, &profile, Aim::Pose(goal), *seconds)
        }
        AllegroCommand::Move {
            joint,
            degrees,
            seconds,
        } => {
            let j = joint_index(&profile, joint)?;
            drive(
                link,
                &settings,
                &profile,
                Aim::Joint(j, degrees.to_radians()),
                *seconds,
            )
        }
    }?;
    Ok(ExitCode::SUCCESS)
}

/// Opens the link, naming a missing adapter plainly.
fn open(settings: &Settings) -> anyhow::Result<Box<dyn CanLink>> {
    teleop_can_link::open(&settings.link, crate::node::BITRATE).map_err(|e| match e {
        LinkError::NotFound { detail, .. } => anyhow::anyhow!(
            "{}: no such device; is the adapter plugged in? ({detail})",
            settings.link
        ),
        other => anyhow::anyhow!("{other}"),
    })
}

fn joint_index(profile: &HandProfile, text: &str) -> anyhow::Result<usize> {
    if let Ok(j) = text.parse::<usize>() {
        if j < JOINTS {
            return Ok(j);
        }
        anyhow::bail!("joint {j}: the Allegro's joints are 0..15");
    }
    profile.joint_index(text).ok_or_else(|| {
        anyhow::anyhow!(
            "joint {text:?}: not a joint of the Allegro profile (0..15 or one of {})",
            profile.joint_names().collect::<Vec<_>>().join(", ")
        )
    })
}

/// `info`: bring the hand up as set (`auto`: detected), listen a little for temperatures and the
/// info answer, stop it again, print what it told.
fn info(mut link: Box<dyn CanLink>, settings: &Settings) -> anyhow::Result<()> {
    let (hand, detected) = match settings.protocol {
        ProtocolSetting::Fixed(g) => (bringup::bring_up(&mut *link, g, settings)?, false),
        ProtocolSetting::Auto => {
            let generation = match bringup::detect_protocol(&mut *link, settings)? {
                Protocol::V4 => Generation::V4,
                // Reading only: within the document protocol the generation changes nothing
                // that is read.
                Protocol::Doc => Generation::V2,
            };
            (bringup::bring_up(&mut *link, generation, settings)?, true)
        }
    };
    let wire = Wire::new(hand.generation, settings.device_id, settings.calibration);
    let mut identity = hand.identity.clone();
    let mut positions = identity.positions;
    // Temperatures stream every `temperature_period_ms` (v4): wait for one round.
    let listen = match wire.protocol() {
        Protocol::V4 => Duration::from_millis(u64::from(settings.temperature_period_ms) + 100),
        Protocol::Doc => Duration::from_millis(100),
    };
    let end = Instant::now() + listen;
    let mut frames = 0u64;
    let mut unknown = 0u64;
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if let Some(frame) = link.recv(left)? {
            frames += 1;
            match wire.decode(&frame) {
                Incoming::Position { finger, q } => {
                    let base = usize::from(finger) * 4;
                    positions[base..base + 4].copy_from_slice(&q);
                }
                Incoming::Unknown | Incoming::Bad | Incoming::Foreign(_) => unknown += 1,
                other => {
                    identity.take(&other);
                }
            }
        }
    }
    bringup::shut_down(&mut *link, &wire)?;
    print_info(
        &*link, &hand, &identity, &positions, detected, frames, unknown,
    )?;
    Ok(())
}

fn print_info(
    link: &dyn CanLink,
    hand: &Hand,
    identity: &Identity,
    positions: &[f64; JOINTS],
    detected: bool,
    frames: u64,
    unknown: u64,
) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "link          {}", link.describe())?;
    let protocol = match (hand.generation.protocol(), detected) {
        (Protocol::V4, true) => "v4 (detected)".to_string(),
        (Protocol::Doc, true) => {
            "v1-v3, the document's protocol (detected; set protocol = v1, v2 or v3 by the \
             hand's version before driving it)"
                .to_string()
        }
        (_, false) => hand.generation.to_string(),
    };
    writeln!(out, "protocol      {protocol}")?;
    if let Some(i) = &identity.info {
        writeln!(
            out,
            "hardware      {:#06x} ({} PWM per N m)",
            i.hw_version,
            i.pwm_per_nm()
        )?;
        writeln!(out, "firmware      {:#06x}", i.fw_version)?;
        let side = match i.hand_type {
            0 => "right",
            1 => "left",
            _ => "unknown",
        };
        writeln!(out, "hand          {side} (type {})", i.hand_type)?;
        writeln!(
            out,
            "status        {:#04x}: servo {}",
            i.status,
            if i.servo_on() { "on" } else { "off" }
        )?;
        writeln!(out, "temperature   {} C (hand)", i.temperature)?;
    }
    if let Some((revision, firmware, hw_type)) = identity.doc_id {
        writeln!(
            out,
            "identity      revision {revision}, firmware {firmware}, hardware type {hw_type}"
        )?;
    }
    match &identity.serial {
        Some(s) => writeln!(out, "serial        {}", v4::serial_text(s))?,
        None if hand.generation.protocol() == Protocol::V4 => {
            writeln!(out, "serial        (no answer)")?
        }
        None => {}
    }
    for (f, name) in FINGER_NAMES.iter().enumerate() {
        let q = &positions[f * 4..f * 4 + 4];
        write!(out, "{name:<13} ")?;
        for v in q {
            write!(out, "{:>7.1}", v.to_degrees())?;
        }
        write!(out, " deg")?;
        let temps = &identity.temperatures[f * 4..f * 4 + 4];
        if temps.iter().any(Option::is_some) {
            write!(out, "   ")?;
            for t in temps {
                match t {
                    Some(t) => write!(out, " {t:>3}")?,
                    None => write!(out, "   ?")?,
                }
            }
            write!(out, " C")?;
        }
        writeln!(out)?;
    }
    writeln!(
        out,
        "frames        {frames} in the last listen ({unknown} unknown or bad)"
    )?;
    Ok(())
}

/// The CLI as the loop's host: the core's ramped move (toward the aim from where the hand was
/// at `resume_speed`, as the node ramps after a hold, for `seconds` after the hand came up),
/// then stop (the loop sends zero torque and SYSTEM_OFF).
struct CliHost {
    ramp: RampedMove<JOINTS>,
    last: Option<Cycle>,
    generation: Option<Generation>,
}

impl Host for CliHost {
    fn stop_requested(&self) -> bool {
        teleop_runtime::stop_signal().is_some() || self.ramp.over(Instant::now())
    }

    fn target(&mut self) -> Goal {
        self.ramp.target()
    }

    fn connected(&mut self, hand: &Connected<'_>) -> anyhow::Result<()> {
        self.ramp.started(Instant::now());
        self.generation = Some(hand.generation);
        Ok(())
    }

    fn cycle(&mut self, cycle: &Cycle) -> anyhow::Result<()> {
        self.ramp.seen(&cycle.q);
        self.last = Some(*cycle);
        Ok(())
    }

    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        anyhow::bail!("{}", down.why)
    }
}

fn drive(
    link: Box<dyn CanLink>,
    settings: &Settings,
    profile: &HandProfile,
    aim: Aim<JOINTS>,
    seconds: Duration,
) -> anyhow::Result<()> {
    teleop_runtime::install_stop_handlers();
    let mut host = CliHost {
        ramp: RampedMove::new(
            profile,
            aim,
            settings.resume_speed,
            settings.period,
            seconds,
        ),
        last: None,
        generation: None,
    };
    // The link is open already (a missing adapter was named there); the loop does not reopen
    // it: any fault ends the command through `link_down`.
    let mut first = Some(link);
    let mut open = move || {
        first.take().ok_or_else(|| LinkError::Disconnected {
            what: "the link".into(),
            detail: "lost during the command".into(),
        })
    };
    driver::run(settings, &mut host, &mut open)?;
    let Some(last) = host.last else {
        anyhow::bail!("stopped before the hand's first cycle");
    };
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{} on {}: released (zero torque, SYSTEM_OFF) after {:.1} s",
        host.generation.map_or("?".into(), |g| g.to_string()),
        settings.link,
        seconds.as_secs_f64()
    )?;
    host.ramp.report(&mut out, profile, &last.q, |j| {
        format!("effort {:>6.3} N m", last.torque[j])
    })?;
    Ok(())
}
