//! `teleop-glove`: the glove process (see the `teleop_glove` library for what it does).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use teleop_glove::GloveConfig;
use teleop_runtime::{init_logging, load_toml, IpcSettings, NodeRuntime};

#[derive(Parser)]
#[command(version, about = "EH55BF1 glove: glove state out, force commands in")]
struct Args {
    /// Node configuration (TOML).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Serial port; overrides the configuration.
    #[arg(long)]
    port: Option<PathBuf>,
    /// iceoryx2 node name.
    #[arg(long, default_value = "glove")]
    name: String,
}

fn main() -> ExitCode {
    init_logging();
    let args = Args::parse();
    let result = load(&args).and_then(|config| {
        let runtime = NodeRuntime::new(&args.name, &IpcSettings::from_env())?;
        teleop_glove::run(&runtime, &config)
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("stopping: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn load(args: &Args) -> anyhow::Result<GloveConfig> {
    let (mut config, origin) = match &args.config {
        Some(path) => (load_toml::<GloveConfig>(path)?, path.display().to_string()),
        None => (GloveConfig::default(), "defaults".to_string()),
    };
    if let Some(port) = &args.port {
        config.port = port.clone();
    }
    config
        .validate()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    Ok(config)
}
