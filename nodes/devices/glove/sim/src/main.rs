//! `teleop-sim-glove`: the simulated EH55BF1 glove as a process. Prints the device path, serves
//! until SIGINT/SIGTERM, and takes fault commands at run time on a control socket:
//!
//! ```text
//! echo "fault drop=0.2" | socat - UNIX-CONNECT:/tmp/glove.ctl
//! ```
//! Commands: `fault NAME=P` (garbage, drop, corrupt, other-id), `clear`, `unplug SECONDS`,
//! `late MS` (the next answer comes MS milliseconds late, e.g. past the host's timeout),
//! `stats`, `state` (the force set-points the device has and the positions it reports).

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixListener;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use clap::Parser;
use teleop_glove_protocol::BaudRate;
use teleop_sim_glove::hand::{Hand, HandModel, Script};
use teleop_sim_glove::{Faults, SimGlove, SimOptions};

#[derive(Parser)]
#[command(
    version,
    about = "Simulated EH55BF1 exoskeleton glove on a pseudo-terminal"
)]
struct Args {
    /// Stable path for the device side (a symlink to the current pty); open this as the port.
    #[arg(long, default_value = "/tmp/teleop-glove")]
    link: PathBuf,
    /// Device id (1..=254).
    #[arg(long, default_value_t = 1)]
    id: u8,
    /// Line speed at power-on: 115200, 57600 or 19200.
    #[arg(long, default_value_t = 115200)]
    baud: u32,
    /// Operator motion: hold, open-close, pinch, grasp, or a trajectory CSV file.
    #[arg(long, default_value = "grasp")]
    script: String,
    /// Faults from the start, e.g. `--fault drop=0.05 --fault garbage=0.01`.
    #[arg(long)]
    fault: Vec<String>,
    /// Device processing time per request, microseconds.
    #[arg(long, default_value_t = 200)]
    response_delay_us: u64,
    /// Seed for the fault dice.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Unix socket for run-time commands (default: the link path with `.ctl`).
    #[arg(long)]
    control: Option<PathBuf>,
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

fn run(args: Args) -> anyhow::Result<()> {
    let baud = BaudRate::from_bps(args.baud).ok_or_else(|| {
        anyhow::anyhow!(
            "--baud {}: the glove supports 115200, 57600 and 19200",
            args.baud
        )
    })?;
    let script = Script::parse(&args.script).map_err(anyhow::Error::msg)?;
    let mut faults = Faults::default();
    for f in &args.fault {
        faults.set(f).map_err(anyhow::Error::msg)?;
    }
    teleop_runtime::install_stop_handlers();
    let sim = Arc::new(SimGlove::start(
        SimOptions {
            link: args.link.clone(),
            id: args.id,
            baud,
            response_delay: Duration::from_micros(args.response_delay_us),
            faults,
            seed: args.seed,
        },
        Hand::new(script, HandModel::default()),
    )?);
    let control = args
        .control
        .unwrap_or_else(|| args.link.with_extension("ctl"));
    let _ = std::fs::remove_file(&control);
    let listener = UnixListener::bind(&control)
        .map_err(|e| anyhow::anyhow!("{}: cannot create control socket: {e}", control.display()))?;
    listener.set_nonblocking(true)?;
    println!(
        "device: {} (control: {})",
        args.link.display(),
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

/// Longest `late` delay: the simulator serves nothing else meanwhile (not even a stop).
const MAX_LATE_MS: u64 = 10_000;

fn command(sim: &SimGlove, line: &str) -> String {
    let (word, rest) = line.split_once(' ').unwrap_or((line, ""));
    match word {
        "fault" => {
            let mut faults = sim.faults();
            match faults.set(rest) {
                Ok(()) => {
                    sim.set_faults(faults);
                    tracing::warn!("fault injection now {faults:?}");
                    format!("ok {faults:?}")
                }
                Err(e) => format!("error: {e}"),
            }
        }
        "clear" => {
            sim.set_faults(Faults::default());
            "ok".into()
        }
        "unplug" => match rest.trim().parse::<f64>() {
            Ok(s) if (0.0..3600.0).contains(&s) => {
                sim.unplug(Duration::from_secs_f64(s));
                "ok".into()
            }
            _ => "error: unplug SECONDS".into(),
        },
        "late" => match rest.trim().parse::<u64>() {
            Ok(ms) if ms <= MAX_LATE_MS => {
                sim.answer_late(Duration::from_millis(ms));
                "ok".into()
            }
            _ => format!("error: late MS (0..={MAX_LATE_MS})"),
        },
        "stats" => format!("{:?}", sim.stats()),
        "state" => match sim.device() {
            Some(d) => format!(
                "id={} baud={} force_set={:?} positions={:?}",
                d.id,
                d.baud.bits_per_second(),
                d.force_set,
                d.positions
            ),
            None => "no exchange yet".into(),
        },
        _ => format!(
            "error: unknown command {word:?}: fault NAME=P, clear, unplug SECONDS, late MS, stats, state"
        ),
    }
}
