//! `teleop-allegro`: the Allegro Hand process (see the `teleop_allegro` library for what it does).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use teleop_allegro::ProtocolSetting;
use teleop_runtime::{init_logging, IpcSettings, NodeRuntime};

#[derive(Parser)]
#[command(
    version,
    about = "Wonik Allegro Hand over CAN: hand command in, 333 Hz PD torque loop, hand state out"
)]
struct Args {
    /// Node configuration (TOML).
    #[arg(long)]
    config: Option<PathBuf>,
    /// The CAN link (`slcan:PATH`, `socketcan:IFACE`, `local:SOCKET`); overrides the
    /// configuration's `link`.
    #[arg(long)]
    link: Option<String>,
    /// `auto`, `v1`, `v2`, `v3` or `v4`; overrides the configuration's `protocol`.
    #[arg(long)]
    protocol: Option<ProtocolSetting>,
    /// iceoryx2 node name.
    #[arg(long, default_value = "allegro")]
    name: String,
}

fn main() -> ExitCode {
    init_logging();
    let args = Args::parse();
    let result = (|| -> anyhow::Result<()> {
        let (mut config, profile) = teleop_allegro::load(args.config.as_deref())?;
        if let Some(link) = &args.link {
            config.link = link.clone();
        }
        if let Some(p) = args.protocol {
            config.protocol = p;
        }
        let origin = args
            .config
            .as_ref()
            .map_or("defaults".to_string(), |p| p.display().to_string());
        let settings = config
            .validate()
            .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
        let runtime = NodeRuntime::new(&args.name, &IpcSettings::from_env())?;
        teleop_allegro::run(&runtime, &settings, &profile)
    })();
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("stopping: {e:#}");
            ExitCode::FAILURE
        }
    }
}
