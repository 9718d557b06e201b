//! `teleop-bridge`: one station's end of the link between stations (see the library's docs).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use teleop_bridge::config::BridgeConfig;
use teleop_bridge::station::{run, Options};
use teleop_runtime::node_main;

#[derive(Parser)]
#[command(
    version,
    about = "Forwards topics between this station and its peer over zenoh"
)]
struct Args {
    /// The bridge configuration (TOML).
    #[arg(long)]
    config: PathBuf,
    /// iceoryx2 node name.
    #[arg(long)]
    name: String,
    /// A control socket for fault injection in tests and benchmarks (`delay MS`,
    /// `loss PERCENT`, `clear`, `stats`).
    #[arg(long)]
    control: Option<PathBuf>,
}

fn main() -> ExitCode {
    node_main("bridge", |args: Args| -> anyhow::Result<()> {
        run(Options {
            config: BridgeConfig::load(&args.config)?,
            name: args.name,
            control: args.control,
        })
    })
}
