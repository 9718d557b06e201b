//! `teleop-revo2`: the Revo2 process (see the `teleop_revo2` library for what it does).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use teleop_revo2::{bus, Revo2Config};
use teleop_runtime::{init_logging, load_toml, IpcSettings, NodeRuntime};

#[derive(Parser)]
#[command(
    version,
    about = "BrainCo Revo2 over EtherCAT: hand command in, hand state and tactile out"
)]
struct Args {
    /// Node configuration (TOML).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Transport (`interface:NAME`, `ethercrab:NAME` or `sim:SOCKET`); overrides the configuration.
    #[arg(long)]
    transport: Option<String>,
    /// iceoryx2 node name.
    #[arg(long, default_value = "revo2")]
    name: String,
}

fn main() -> ExitCode {
    init_logging();
    let args = Args::parse();
    let result = load(&args).and_then(|(config, transport)| {
        let runtime = NodeRuntime::new(&args.name, &IpcSettings::from_env())?;
        teleop_revo2::run(&runtime, &config, bus::connector(&transport))
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("stopping: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn load(args: &Args) -> anyhow::Result<(Revo2Config, teleop_revo2::Transport)> {
    let (mut config, origin) = match &args.config {
        Some(path) => (load_toml::<Revo2Config>(path)?, path.display().to_string()),
        None => (Revo2Config::default(), "defaults".to_string()),
    };
    if let Some(t) = &args.transport {
        config.transport = t.clone();
    }
    let transport = config
        .validate()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    Ok((config, transport))
}
