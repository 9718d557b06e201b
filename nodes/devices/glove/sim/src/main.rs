//! `teleop-sim-glove`: the simulated EH55BF1 glove as a process. Prints the device path, serves
//! until SIGINT/SIGTERM, and takes commands at run time on a control socket (the simulator
//! kit's vocabulary, `teleop_sim_kit::command`):
//!
//! ```text
//! echo "drop 0.2" | socat - UNIX-CONNECT:/tmp/teleop-glove.ctl
//! ```
//! Common: `unplug MS`, `drop P` (answers lost), `clear`, `stats`. The glove's own: `garbage P`
//! (random bytes before an answer), `corrupt P` (a bad checksum), `other-id P` (the answer
//! comes from another id), `late MS` (the next answer comes MS ms late, e.g. past the host's
//! timeout), `state` (the force set-points the device has and the positions it reports).

use std::io::Write;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use clap::Parser;
use teleop_glove_protocol::BaudRate;
use teleop_sim_glove::hand::{Hand, HandModel, Script, SCRIPT_NAMES};
use teleop_sim_glove::{Faults, SimGlove, SimOptions};
use teleop_sim_kit::process::{self, SimArgs};

#[derive(Parser)]
#[command(
    version,
    about = "Simulated EH55BF1 exoskeleton glove on a pseudo-terminal"
)]
struct Args {
    /// Stable path for the device side (a symlink to the current pty); open this as the port.
    #[arg(long, default_value = "/tmp/teleop-glove")]
    link: std::path::PathBuf,
    /// Device id (1..=254).
    #[arg(long, default_value_t = 1)]
    id: u8,
    /// Line speed at power-on: 115200, 57600 or 19200.
    #[arg(long, default_value_t = 115200)]
    baud: u32,
    #[arg(long, default_value = "grasp",
          help = format!("Operator motion: {SCRIPT_NAMES}, or a trajectory CSV file"))]
    script: String,
    /// Device processing time per request, microseconds.
    #[arg(long, default_value_t = 200)]
    response_delay_us: u64,
    #[command(flatten)]
    sim: SimArgs,
}

fn main() -> ExitCode {
    process::main(run)
}

fn run(args: Args) -> anyhow::Result<()> {
    let baud = BaudRate::from_bps(args.baud).ok_or_else(|| {
        anyhow::anyhow!(
            "--baud {}: the glove supports 115200, 57600 and 19200",
            args.baud
        )
    })?;
    let script = Script::parse(&args.script).map_err(anyhow::Error::msg)?;
    let sim = Arc::new(SimGlove::start(
        SimOptions {
            link: args.link.clone(),
            id: args.id,
            baud,
            response_delay: Duration::from_micros(args.response_delay_us),
            faults: Faults::default(),
            seed: args.sim.seed,
        },
        Hand::new(script, HandModel::default()),
    )?);
    let control = args.sim.serve(sim, args.link.with_extension("ctl"))?;
    println!(
        "device: {} (control: {})",
        args.link.display(),
        control.path().display()
    );
    std::io::stdout().flush()?;
    process::wait_for_stop();
    Ok(())
}
