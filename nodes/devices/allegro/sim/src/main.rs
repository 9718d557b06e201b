//! `teleop-sim-allegro`: the simulated Allegro Hand as a process. Serves the hand's CAN bus
//! through a simulated slcan adapter on a pty (`--slcan PATH`, the node's `slcan:PATH` link)
//! and/or on a local socket (`--socket PATH`, the node's `local:PATH` link), prints one line
//! saying where, and takes commands at run time on a control socket (the simulator kit's
//! vocabulary, one line each, answered `ok ...` or `error: ...`):
//!
//! ```text
//! echo "drop 0.1" | socat - UNIX-CONNECT:/tmp/teleop-allegro.ctl
//! ```
//! Common: `unplug MS` (the adapter), `drop P` (frames from the hand lost), `clear`, `stats`
//! (one line of `key=value` words, see [`Sim::stats_answer`]), `object ball|bar|none`. The
//! hand's own: see [`teleop_sim_allegro::control`].
//!
//! [`Sim::stats_answer`]: teleop_sim_allegro::Sim::stats_answer

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use clap::Parser;
use teleop_allegro_protocol::{Generation, JointCalibration};
use teleop_sim_allegro::adapter::AckStyle;
use teleop_sim_allegro::firmware::{Firmware, FirmwareOptions, StateAnswer};
use teleop_sim_allegro::hand::{Hand, HandParams, VirtualObject, JOINTS};
use teleop_sim_allegro::{Sim, SimOptions};
use teleop_sim_kit::object::ObjectArg;
use teleop_sim_kit::process::{self, SimArgs};

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
    #[command(flatten)]
    object: ObjectArg,
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
    #[command(flatten)]
    sim: SimArgs,
}

fn main() -> ExitCode {
    process::main(run)
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
    let object = args.object.object()?;
    let hand = Hand::allegro(params, object.map(VirtualObject::of)).map_err(anyhow::Error::msg)?;
    let default_control = match (&args.slcan, &args.socket) {
        (Some(p), _) | (None, Some(p)) => p.with_extension("ctl"),
        (None, None) => anyhow::bail!("give --slcan PATH and/or --socket PATH"),
    };
    let sim = Arc::new(
        Sim::start(
            Firmware::new(options, hand),
            SimOptions {
                slcan: args.slcan.clone(),
                socket: args.socket.clone(),
                ack_style: args.ack_style,
                seed: args.sim.seed,
            },
        )
        .map_err(|e| anyhow::anyhow!("cannot start the simulated hand: {e}"))?,
    );
    let control = args.sim.serve(sim, default_control)?;
    let show = |p: &Option<PathBuf>| {
        p.as_ref()
            .map_or("-".to_string(), |p| p.display().to_string())
    };
    println!(
        "allegro: generation {} slcan {} socket {} (control: {})",
        args.generation,
        show(&args.slcan),
        show(&args.socket),
        control.path().display()
    );
    std::io::stdout().flush()?;
    process::wait_for_stop();
    Ok(())
}
