//! `teleop shadow ...`: talk to the Shadow Hand's palm directly over EtherCAT (the Shadow node
//! must not be running: both would drive the bus). Each command brings the hand up with the
//! node's own driver, does its one thing in the palm's service modes, and takes the hand out of
//! OP again: `info`, `flash`, `can-send`, `channels`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Subcommand;
use teleop_shadow::service::Service;
use teleop_shadow::ShadowConfig;
use teleop_shadow_protocol::data::flags;
use teleop_shadow_protocol::hex;
use teleop_shadow_protocol::layout::CanBridge;
use teleop_shadow_protocol::mapping::SENSOR_NAMES;

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
    Image(hex::Image),
    Message(CanBridge),
}

fn read_image(file: &Path) -> anyhow::Result<hex::Image> {
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
    image: hex::Image,
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
