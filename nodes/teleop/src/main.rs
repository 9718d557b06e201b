//! `teleop`: the one command users run. `teleop launch` starts the pipeline described in
//! `launch.toml` as separate processes; `nodes`, `topics`, `echo`, `stats` and `estop` inspect and
//! steer a running pipeline; `calibrate` records an operator calibration profile.
//!
//! Owns the command line and the supervisor; it runs no control loop itself. Must not contain
//! device protocols or control logic (those live in `shared/`).

mod calibrate;
mod glove;
mod inspect;
mod launch;
mod revo2;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{Parser, Subcommand};
use teleop_runtime::{init_logging, IpcSettings, ENV_IPC_PREFIX, ENV_IPC_ROOT};

#[derive(Parser)]
#[command(
    version,
    about = "Teleoperation of dexterous robot hands with force feedback"
)]
struct Cli {
    /// iceoryx2 root path of the pipeline to talk to.
    #[arg(long, global = true, env = ENV_IPC_ROOT)]
    ipc_root: Option<String>,
    /// iceoryx2 prefix of the pipeline to talk to (default `teleop_`).
    #[arg(long, global = true, env = ENV_IPC_PREFIX)]
    ipc_prefix: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Start every process of a launch file and supervise them until Ctrl-C.
    Launch {
        /// The launch file.
        #[arg(default_value = "launch.toml")]
        file: PathBuf,
        /// Stop after this many seconds.
        #[arg(long)]
        duration: Option<f64>,
        /// Check the launch file and exit.
        #[arg(long)]
        check: bool,
    },
    /// List the pipeline's processes (iceoryx2 nodes): name, alive or dead, pid.
    Nodes,
    /// List the topics with their payload, size, and publishers/subscribers.
    Topics,
    /// Print decoded samples of a topic as they arrive.
    Echo {
        /// Topic name, e.g. `glove/state` (see `teleop topics`).
        topic: String,
        /// Stop after this many samples.
        #[arg(long, short = 'n')]
        count: Option<u64>,
    },
    /// Per-topic rate, drops and latency (from the sample headers) over a window.
    Stats {
        /// Measurement window in seconds.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
    },
    /// Engage (or release) the emergency stop: all glove forces go to zero.
    Estop {
        /// Release instead of engage.
        #[arg(long)]
        release: bool,
    },
    /// Talk to the EH55BF1 glove directly (with the glove node stopped).
    Glove {
        #[command(flatten)]
        target: glove::Target,
        #[command(subcommand)]
        command: glove::GloveCommand,
    },
    /// Talk to the Revo2 directly over EtherCAT (with the Revo2 node stopped).
    Revo2 {
        #[command(flatten)]
        target: revo2::Target,
        #[command(subcommand)]
        command: revo2::Revo2Command,
    },
    /// Record an operator calibration profile from the live glove.
    Calibrate {
        /// Where to write the profile.
        #[arg(long, default_value = "calibration.toml")]
        out: PathBuf,
        /// Do not wait for Enter: count down `--settle` seconds before each pose instead.
        #[arg(long)]
        yes: bool,
        /// Seconds to get into each pose when `--yes` is given.
        #[arg(long, default_value_t = 3.0)]
        settle: f64,
        /// Seconds of glove samples averaged per pose.
        #[arg(long, default_value_t = 1.0)]
        capture: f64,
    },
}

fn main() -> ExitCode {
    init_logging();
    let cli = Cli::parse();
    let ipc = IpcSettings {
        root: cli.ipc_root.clone().filter(|s| !s.is_empty()),
        prefix: cli.ipc_prefix.clone().filter(|s| !s.is_empty()),
    };
    let result = match cli.command {
        Command::Launch {
            file,
            duration,
            check,
        } => run_launch(&file, &ipc, duration, check),
        Command::Nodes => inspect::nodes(&ipc),
        Command::Topics => inspect::topics(&ipc),
        Command::Echo { topic, count } => inspect::echo(&ipc, &topic, count),
        Command::Stats { seconds } => inspect::stats(&ipc, secs(seconds)),
        Command::Estop { release } => inspect::estop(&ipc, !release),
        Command::Glove { target, command } => glove::run(&target, &command),
        Command::Revo2 { target, command } => revo2::run(&target, &command),
        Command::Calibrate {
            out,
            yes,
            settle,
            capture,
        } => calibrate::run(&ipc, &out, yes, secs(settle), secs(capture)),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn secs(s: f64) -> Duration {
    Duration::from_secs_f64(s.clamp(0.0, 1e6))
}

fn run_launch(
    file: &std::path::Path,
    ipc: &IpcSettings,
    duration: Option<f64>,
    check: bool,
) -> anyhow::Result<ExitCode> {
    let launch = launch::config::load(file)?;
    if check {
        println!(
            "{}: {} processes: {}",
            file.display(),
            launch.processes.len(),
            launch
                .processes
                .iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
        return Ok(ExitCode::SUCCESS);
    }
    match launch::supervisor::run(&launch, ipc, duration.map(secs))? {
        launch::supervisor::Outcome::Stopped(_) => Ok(ExitCode::SUCCESS),
        launch::supervisor::Outcome::Failed(why) => {
            eprintln!("error: {why}");
            Ok(ExitCode::FAILURE)
        }
    }
}
