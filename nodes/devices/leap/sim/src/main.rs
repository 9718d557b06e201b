//! `teleop-sim-leap`: the simulated LEAP Hand as a process. Serves the 16 servos' bus on a pty
//! whose device side is linked at `--link PATH` (the node's serial port), prints one line
//! saying where (`leap: link PATH ... (control: PATH)`), and takes commands at run time on a
//! control socket (the simulator kit's vocabulary, one line each, answered `ok ...` or
//! `error: ...`; the hand's own words in [`teleop_sim_leap::control`]):
//!
//! ```text
//! teleop-sim-leap --link /tmp/teleop-leap --object ball --control /tmp/teleop-sim-leap.ctl
//! echo "silent 5" | socat - UNIX-CONNECT:/tmp/teleop-sim-leap.ctl
//! ```

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use clap::Parser;
use teleop_leap_protocol::xc330::BaudRate;
use teleop_sim_kit::object::ObjectArg;
use teleop_sim_kit::process::{self, SimArgs};
use teleop_sim_leap::bus::{BusOptions, Missing};
use teleop_sim_leap::hand::leap_limits;
use teleop_sim_leap::servo::ServoOptions;
use teleop_sim_leap::table::{LimitError, Model};
use teleop_sim_leap::{Sim, SimOptions};

#[derive(Parser)]
#[command(
    version,
    about = "Simulated LEAP Hand: 16 Dynamixel XC330 servos on a serial bus",
    after_help = "Control socket words (one line each, answered `ok ...` or `error: ...`):
  unplug MS       the USB cable pulled for MS ms (servos powered off, boot when back)
  drop P          each status lost with probability P
  crc P           each status with one corrupted byte with probability P
  silent ID [MS]  servo ID neither hears nor answers (for MS ms, else until clear)
  noise [N]       N random bytes on the line, heard by host and servos (default 64)
  overload ID     servo ID overloaded: torque off, Alert, until a reboot
  overheat ID     servo ID at 80 C, over its Temperature Limit: the same
  object ball|bar|none; clear (every fault off); stats (key=value words)
With the torque off a joint stays where it is (no gravity)."
)]
struct Args {
    /// The pty's device side is linked at this path (the node's serial port).
    #[arg(long)]
    link: PathBuf,
    #[command(flatten)]
    object: ObjectArg,
    /// The servos' Baud Rate at start, bit/s (9600, 57600, 115200, 1000000, 2000000, 3000000
    /// or 4000000; the LEAP Hand's servos are set to 4000000). A host whose port runs at
    /// another rate gets no answer.
    #[arg(long, default_value_t = 4_000_000)]
    baud: u32,
    /// The servos' Return Delay Time at start, us (0..=508, even; the factory's 500).
    #[arg(long, default_value_t = 500)]
    return_delay_us: u32,
    /// What the servos after a silent one in a Fast Sync Read chain do (not documented):
    /// `truncate` the reply at it (the default: the first servo has announced the whole
    /// length before the others answer) or `omit` its block (the reply is shorter).
    #[arg(long, default_value = "truncate")]
    fast_sync_missing: Missing,
    /// The servos: `xc330-m288` (the LEAP Hand's) or `xl330-m077` (the Lite hand's).
    #[arg(long, default_value = "xc330-m288")]
    model: Model,
    /// Boot time after a Reboot or a power cycle, ms (silent meanwhile; not documented).
    #[arg(long, default_value_t = 300)]
    boot_ms: u64,
    /// Firmware Version the servos report (Fast Sync Read needs 46 or later).
    #[arg(long, default_value_t = 52)]
    firmware: u8,
    /// The error of a goal beyond its limit item (Goal Current beyond Current Limit, Goal
    /// Position beyond the position limits in mode 3; not documented): `limit` (Data Limit
    /// Error, 6) or `range` (Data Range Error, 4).
    #[arg(long, default_value = "limit")]
    limit_error: LimitError,
    /// Answer a request with a bad CRC with a CRC Error status (default: dropped unanswered).
    #[arg(long)]
    crc_status: bool,
    #[command(flatten)]
    sim: SimArgs,
}

fn main() -> ExitCode {
    process::main(run)
}

fn options(args: &Args) -> anyhow::Result<SimOptions> {
    let baud = BaudRate::from_bps(args.baud)
        .ok_or_else(|| anyhow::anyhow!("--baud {}: not a rate the XC330 takes", args.baud))?;
    if args.return_delay_us > 508 || !args.return_delay_us.is_multiple_of(2) {
        anyhow::bail!(
            "--return-delay-us {}: 0..=508 in steps of 2",
            args.return_delay_us
        );
    }
    Ok(SimOptions {
        link: args.link.clone(),
        model: args.model,
        baud_code: baud.code(),
        return_delay: (args.return_delay_us / 2) as u8,
        servo: ServoOptions {
            boot: Duration::from_millis(args.boot_ms).as_secs_f64(),
            firmware: args.firmware,
            limit_error: args.limit_error,
        },
        bus: BusOptions {
            fast_sync_missing: args.fast_sync_missing,
            crc_status: args.crc_status,
        },
        limits: leap_limits().map_err(anyhow::Error::msg)?,
        object: args.object.object()?,
        seed: args.sim.seed,
        tap: None,
    })
}

fn run(args: Args) -> anyhow::Result<()> {
    let options = options(&args)?;
    let sim = Arc::new(
        Sim::start(options).map_err(|e| anyhow::anyhow!("cannot start the simulated hand: {e}"))?,
    );
    let control = args.sim.serve(sim, args.link.with_extension("ctl"))?;
    println!(
        "leap: link {} baud {} model {} (control: {})",
        args.link.display(),
        args.baud,
        args.model.name(),
        control.path().display()
    );
    std::io::stdout().flush()?;
    process::wait_for_stop();
    Ok(())
}
