//! `teleop-shadow`: the Shadow Hand process (see the `teleop_shadow` library for what it does).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use teleop_runtime::{init_logging, load_toml, IpcSettings, NodeRuntime};
use teleop_shadow::{Checked, ShadowConfig};

#[derive(Parser)]
#[command(
    version,
    about = "Shadow Hand E over EtherCAT: hand command in, hand state and PST tactile out"
)]
struct Args {
    /// Node configuration (TOML).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Transport (`interface:NAME`, `ethercrab:NAME` or `sim:SOCKET`); overrides the configuration.
    #[arg(long)]
    transport: Option<String>,
    /// iceoryx2 node name.
    #[arg(long, default_value = "shadow")]
    name: String,
}

fn main() -> ExitCode {
    init_logging();
    let args = Args::parse();
    let result = load(&args).and_then(|(config, checked)| {
        let runtime = NodeRuntime::new(&args.name, &IpcSettings::from_env())?;
        let connect = teleop_ecat_master::connector(&checked.transport);
        teleop_shadow::run(&runtime, &config, checked, connect)
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("stopping: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn load(args: &Args) -> anyhow::Result<(ShadowConfig, Checked)> {
    let (mut config, origin) = match &args.config {
        Some(path) => (load_toml::<ShadowConfig>(path)?, path.display().to_string()),
        None => (ShadowConfig::default(), "defaults".to_string()),
    };
    if let Some(t) = &args.transport {
        config.transport = t.clone();
    }
    let checked = config
        .validate()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    Ok((config, checked))
}
