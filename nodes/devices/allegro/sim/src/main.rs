//! `teleop-sim-allegro`: the simulated Allegro Hand as a process. Serves the hand's CAN bus
//! through a simulated slcan adapter on a pty (`--slcan PATH`, the node's `slcan:PATH` link)
//! and/or on a local socket (`--socket PATH`, the node's `local:PATH` link), prints one line
//! saying where, and takes commands at run time on a control socket (one line each, answered
//! `ok ...` or `error ...`):
//!
//! ```text
//! echo "drop 0.1" | socat - UNIX-CONNECT:/tmp/teleop-allegro.ctl
//! ```
//! `drop P` (frames from the hand lost), `drop-in P` (frames to the hand lost),
//! `stop-stream`, `resume-stream`, `bus-off MS`, `unplug MS`, `generation v1|v2|v3|v4`,
//! `overheat` (motors at 95 deg C: the firmware switches them off), `overheat off` (back to
//! ambient), `inject ID#DATA` (the hand sends that frame, candump style, `ID#R` for a remote
//! frame), `garbage` (the adapter sends an unparsable line), `object ball|bar|none`,
//! `gravity on|off`, `status` (one line of `key=value` words, see [`Sim::status_line`]).

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixListener;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use clap::Parser;
use teleop_allegro_protocol::{Generation, JointCalibration};
use teleop_sim_allegro::adapter::AckStyle;
use teleop_sim_allegro::firmware::{Firmware, FirmwareOptions, StateAnswer};
use teleop_sim_allegro::hand::{Ball, Hand, HandParams, JOINTS};
use teleop_sim_allegro::{parse_frame, Sim, SimOptions};

#[derive(Parser)]
#[command(version, about = "Simulated Wonik Allegro Hand on a CAN bus")]
struct Args {
    /// Protocol generation: v1, v2, v3 (the document's protocol) or v4.
    #[arg(long, default_value = "v4")]
    generation: Generation,
    /// Emulate a USB slcan adapter on a pty whose device side is linked at this path.
    #[arg(long)]
    slcan: Option<PathBuf>,
    /// Serve the bus on this Unix socket (the node's `local:PATH` link).
    #[arg(long)]
    socket: Option<PathBuf>,
    /// Control socket (default: the slcan or socket path with `.ctl`).
    #[arg(long)]
    control: Option<PathBuf>,
    /// Virtual object: `ball` (a sphere under the middle finger), `bar` (a cylinder across
    /// the palm that the index, middle and ring fingers wrap) or `none`.
    #[arg(long, default_value = "ball")]
    object: String,
    /// Gravity on the fingers (the hand palm down).
    #[arg(long)]
    gravity: bool,
    /// v4 device id (0..3).
    #[arg(long, default_value_t = 0)]
    device_id: u8,
    /// v4 serial number (up to 8 ASCII characters, shown by drivers as "SAH040" + these).
    #[arg(long, default_value = "00AR0042")]
    serial: String,
    /// How the adapter acknowledges frames: `canable` (CR) or `lawicel` (`z`/`Z`).
    #[arg(long, default_value = "canable")]
    ack_style: AckStyle,
    /// Encoder offsets in counts, 16 comma-separated values (document protocol; what the
    /// driver's calibration must subtract).
    #[arg(long, allow_hyphen_values = true)]
    encoder_offset: Option<String>,
    /// Encoder directions, 16 comma-separated values of 1 or -1 (document protocol).
    #[arg(long, allow_hyphen_values = true)]
    encoder_dir: Option<String>,
    /// Motor directions, 16 comma-separated values of 1 or -1.
    #[arg(long, allow_hyphen_values = true)]
    motor_dir: Option<String>,
    /// Zero a finger's torque when its torque frames stop for this many ms (default: hold).
    #[arg(long)]
    torque_timeout_ms: Option<u64>,
    /// v4: stream positions on SET_PERIOD alone (default: only after SYSTEM_ON).
    #[arg(long)]
    v4_stream_on_period: bool,
    /// Document protocol: the payload of the 0x0E answer to QUERY_STATE_DATA (undocumented):
    /// `positions` (the four raw counts, as a position frame) or `empty`.
    #[arg(long, default_value = "positions")]
    state_answer: StateAnswer,
    /// PWM counts per N m (default: the generation's, 800 for v1/v2, 1200 for v3/v4).
    #[arg(long)]
    pwm_per_nm: Option<f64>,
    /// Largest PWM applied (default: the generation's).
    #[arg(long)]
    pwm_limit: Option<i16>,
    /// Seed of the fault dice.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn main() -> ExitCode {
    teleop_runtime::init_logging();
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

fn object(name: &str) -> anyhow::Result<Option<Ball>> {
    match name {
        "ball" => Ok(Some(Ball::default_ball())),
        "bar" => Ok(Some(Ball::bar())),
        "none" => Ok(None),
        other => anyhow::bail!("unknown object {other:?}: use ball, bar or none"),
    }
}

/// 16 comma-separated values of `what`.
fn joint_values<T: std::str::FromStr>(what: &str, text: &str) -> anyhow::Result<[T; JOINTS]> {
    let values = text
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<T>()
                .map_err(|_| anyhow::anyhow!("--{what}: {v:?} is not a number"))
        })
        .collect::<anyhow::Result<Vec<T>>>()?;
    let n = values.len();
    values
        .try_into()
        .map_err(|_| anyhow::anyhow!("--{what}: {n} values; give {JOINTS} (joint order)"))
}

fn directions(what: &str, text: &str) -> anyhow::Result<[i8; JOINTS]> {
    let dirs = joint_values::<i8>(what, text)?;
    if let Some(bad) = dirs.iter().find(|d| d.abs() != 1) {
        anyhow::bail!("--{what}: {bad} is not a direction; use 1 or -1");
    }
    Ok(dirs)
}

fn firmware_options(args: &Args) -> anyhow::Result<FirmwareOptions> {
    let mut o = FirmwareOptions::new(args.generation);
    if args.device_id > 3 {
        anyhow::bail!("--device-id {}: v4 device ids are 0..3", args.device_id);
    }
    o.device_id = args.device_id;
    if !args.serial.is_ascii() || args.serial.len() > 8 {
        anyhow::bail!("--serial {:?}: up to 8 ASCII characters", args.serial);
    }
    let mut serial = [b' '; 8];
    serial[..args.serial.len()].copy_from_slice(args.serial.as_bytes());
    o.serial = serial;
    let offsets = match &args.encoder_offset {
        Some(t) => joint_values::<i32>("encoder-offset", t)?,
        None => [0; JOINTS],
    };
    let encoder = match &args.encoder_dir {
        Some(t) => directions("encoder-dir", t)?,
        None => [1; JOINTS],
    };
    let motor = match &args.motor_dir {
        Some(t) => directions("motor-dir", t)?,
        None => [1; JOINTS],
    };
    o.calibration = core::array::from_fn(|j| JointCalibration {
        offset: offsets[j],
        encoder_dir: encoder[j],
        motor_dir: motor[j],
    });
    o.torque_timeout = args.torque_timeout_ms.map(Duration::from_millis);
    o.v4_stream_on_period = args.v4_stream_on_period;
    o.state_answer = args.state_answer;
    if let Some(k) = args.pwm_per_nm {
        if !(k.is_finite() && k > 0.0) {
            anyhow::bail!("--pwm-per-nm {k}: must be positive");
        }
        o.pwm_per_nm = k;
    }
    if let Some(limit) = args.pwm_limit {
        if limit <= 0 {
            anyhow::bail!("--pwm-limit {limit}: must be positive");
        }
        o.pwm_limit = limit;
    }
    Ok(o)
}

fn run(args: Args) -> anyhow::Result<()> {
    let options = firmware_options(&args)?;
    let params = HandParams {
        gravity: args.gravity,
        ..HandParams::default()
    };
    let hand = Hand::allegro(params, object(&args.object)?).map_err(anyhow::Error::msg)?;
    let control = match (&args.control, &args.slcan, &args.socket) {
        (Some(c), _, _) => c.clone(),
        (None, Some(p), _) | (None, None, Some(p)) => p.with_extension("ctl"),
        (None, None, None) => anyhow::bail!("give --slcan PATH and/or --socket PATH"),
    };
    teleop_runtime::install_stop_handlers();
    let sim = Arc::new(
        Sim::start(
            Firmware::new(options, hand),
            SimOptions {
                slcan: args.slcan.clone(),
                socket: args.socket.clone(),
                ack_style: args.ack_style,
                seed: args.seed,
            },
        )
        .map_err(|e| anyhow::anyhow!("cannot start the simulated hand: {e}"))?,
    );
    let listener = bind_control(&control)?;
    let show = |p: &Option<PathBuf>| {
        p.as_ref()
            .map_or("-".to_string(), |p| p.display().to_string())
    };
    println!(
        "allegro: generation {} slcan {} socket {} (control: {})",
        args.generation,
        show(&args.slcan),
        show(&args.socket),
        control.display()
    );
    std::io::stdout().flush()?;
    while teleop_runtime::stop_signal().is_none() {
        match listener.accept() {
            Ok((stream, _)) => {
                let _ = stream.set_nonblocking(false);
                let mut reply = stream.try_clone()?;
                for line in BufReader::new(stream).lines() {
                    let Ok(line) = line else { break };
                    let answer = command(&sim, line.trim());
                    let _ = writeln!(reply, "{answer}");
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => return Err(e.into()),
        }
    }
    let _ = std::fs::remove_file(&control);
    tracing::info!("stopped");
    Ok(())
}

fn bind_control(path: &Path) -> anyhow::Result<UnixListener> {
    let _ = std::fs::remove_file(path);
    let listener = UnixListener::bind(path)
        .map_err(|e| anyhow::anyhow!("{}: cannot create control socket: {e}", path.display()))?;
    listener.set_nonblocking(true)?;
    Ok(listener)
}

/// Longest bus-off or unplug, ms.
const MAX_FAULT_MS: u64 = 3_600_000;
/// Temperature `overheat` puts the motors at, deg C.
const OVERHEAT_TO_C: f64 = 95.0;

fn command(sim: &Sim, line: &str) -> String {
    let (word, rest) = line.split_once(' ').unwrap_or((line, ""));
    let rest = rest.trim();
    let prob = |s: &str| s.parse::<f64>().ok().filter(|p| (0.0..=1.0).contains(p));
    let millis = |s: &str| {
        s.parse::<u64>()
            .ok()
            .filter(|ms| *ms <= MAX_FAULT_MS)
            .map(Duration::from_millis)
    };
    match word {
        "drop" | "drop-in" => match prob(rest) {
            Some(p) => {
                let mut f = sim.faults();
                if word == "drop" {
                    f.drop_out = p;
                } else {
                    f.drop_in = p;
                }
                sim.set_faults(f);
                tracing::warn!("{word} {p}");
                format!("ok {word} {p}")
            }
            None => format!("error: {word} PROBABILITY (0..1)"),
        },
        "stop-stream" | "resume-stream" => {
            let stop = word == "stop-stream";
            sim.with_firmware(|fw| fw.stop_stream(stop));
            tracing::warn!("{word}");
            format!("ok {word}")
        }
        "bus-off" => match millis(rest) {
            Some(d) => {
                sim.bus_off(d);
                tracing::warn!("bus off for {} ms", d.as_millis());
                format!("ok bus-off {} ms", d.as_millis())
            }
            None => format!("error: bus-off MS (0..={MAX_FAULT_MS})"),
        },
        "unplug" => match millis(rest) {
            Some(d) if sim.unplug(d) => format!("ok unplug {} ms", d.as_millis()),
            Some(_) => "error: unplug: no slcan adapter (start with --slcan PATH)".into(),
            None => format!("error: unplug MS (0..={MAX_FAULT_MS})"),
        },
        "generation" => match rest.parse::<Generation>() {
            Ok(g) => {
                sim.with_firmware(|fw| fw.set_generation(g));
                tracing::warn!("protocol generation now {g}");
                format!("ok generation {g}")
            }
            Err(_) => "error: generation v1|v2|v3|v4".into(),
        },
        "overheat" => match rest {
            "" => {
                sim.with_firmware(|fw| fw.heat(OVERHEAT_TO_C));
                format!("ok overheat {OVERHEAT_TO_C} C")
            }
            "off" => {
                let ambient = HandParams::default().ambient_c;
                sim.with_firmware(|fw| fw.heat(ambient));
                format!("ok overheat off {ambient} C")
            }
            _ => "error: overheat [off]".into(),
        },
        "inject" => match parse_frame(rest) {
            Ok(frame) => {
                sim.inject(frame);
                format!("ok inject {frame}")
            }
            Err(e) => format!("error: inject: {e}"),
        },
        "garbage" => {
            if sim.garbage() {
                "ok garbage".into()
            } else {
                "error: garbage: no slcan adapter (start with --slcan PATH)".into()
            }
        }
        "object" => match object(rest) {
            Ok(o) => {
                sim.with_firmware(|fw| fw.hand_mut().set_object(o));
                format!("ok object {rest}")
            }
            Err(e) => format!("error: {e}"),
        },
        "gravity" => match rest {
            "on" | "off" => {
                sim.with_firmware(|fw| fw.hand_mut().set_gravity(rest == "on"));
                format!("ok gravity {rest}")
            }
            _ => "error: gravity on|off".into(),
        },
        "status" => format!("ok {}", sim.status_line()),
        _ => format!(
            "error: unknown command {word:?}: drop P, drop-in P, stop-stream, resume-stream, \
             bus-off MS, unplug MS, generation vN, overheat [off], inject ID#DATA, garbage, \
             object ball|bar|none, gravity on|off, status"
        ),
    }
}
