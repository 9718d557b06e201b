//! `teleop-revo2`: the Revo2 process (see the `teleop_revo2` library for what it does).

use std::process::ExitCode;

use clap::Parser;
use teleop_revo2::{bus, Revo2Config};
use teleop_runtime::{node_main, NodeArgs};

#[derive(Parser)]
#[command(
    version,
    about = "BrainCo Revo2 over EtherCAT: hand command in, hand state and tactile out"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
    /// Transport (`interface:NAME`, `ethercrab:NAME` or `sim:SOCKET`); overrides the configuration.
    #[arg(long)]
    transport: Option<String>,
}

fn main() -> ExitCode {
    node_main("revo2", |args: Args| -> anyhow::Result<()> {
        let mut config: Revo2Config = args.node.load_config()?;
        if let Some(t) = args.transport {
            config.transport = t;
        }
        let transport = args.node.check(config.validate())?;
        teleop_revo2::run(&args.node.runtime()?, &config, bus::connector(&transport))
    })
}
