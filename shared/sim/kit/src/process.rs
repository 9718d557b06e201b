//! The simulator process: its `main` (logging, stop signals, arguments, exit status), the
//! arguments every simulator takes ([`SimArgs`]) and its control socket, served until the
//! process stops and removed then.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use crate::control::{answer, Simulator};

/// The arguments every simulator takes (flattened into its own).
#[derive(Debug, Clone, clap::Args)]
pub struct SimArgs {
    /// Unix socket for run-time commands (default: the device's path with `.ctl`).
    #[arg(long)]
    pub control: Option<PathBuf>,
    /// A command run at start as if sent on the control socket, e.g. `--fault "drop 0.05"`
    /// (repeatable).
    #[arg(long = "fault", value_name = "COMMAND")]
    pub faults: Vec<String>,
    /// Seed of the fault dice.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// The whole of a simulator's `main`: logging, the arguments `A`, the stop signals (SIGINT,
/// SIGTERM: [`stopping`]), then `run`; its error is logged and makes the exit status 1.
pub fn main<A: clap::Parser>(run: impl FnOnce(A) -> anyhow::Result<()>) -> ExitCode {
    teleop_runtime::init_logging();
    let args = A::parse();
    teleop_runtime::install_stop_handlers();
    match run(args) {
        Ok(()) => {
            tracing::info!("stopped");
            ExitCode::SUCCESS
        }
        Err(e) => {
            tracing::error!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

/// A stop signal came.
pub fn stopping() -> bool {
    teleop_runtime::stop_signal().is_some()
}

/// Sleeps until a stop signal comes.
pub fn wait_for_stop() {
    while !stopping() {
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A control socket being served; its file is removed when this is dropped.
#[derive(Debug)]
pub struct Control {
    path: PathBuf,
}

impl Control {
    /// The socket's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for Control {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

impl SimArgs {
    /// Runs the `--fault` commands on `sim` (the first refused one is the error), then serves
    /// its control socket at `--control` or `default`.
    pub fn serve<S: Simulator>(&self, sim: Arc<S>, default: PathBuf) -> anyhow::Result<Control> {
        for line in &self.faults {
            let reply = answer(&*sim, line);
            if let Some(why) = reply.strip_prefix("error: ") {
                anyhow::bail!("--fault {line:?}: {why}");
            }
            tracing::warn!("--fault {line}: {reply}");
        }
        let path = self.control.clone().unwrap_or(default);
        teleop_runtime::control::spawn(&path, move |line| answer(&*sim, line))?;
        Ok(Control { path })
    }
}
