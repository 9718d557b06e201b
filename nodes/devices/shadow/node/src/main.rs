//! `teleop-shadow`: the Shadow Hand process (see the `teleop_shadow` library for what it does).

use std::process::ExitCode;

use clap::Parser;
use teleop_runtime::{node_main, NodeArgs};
use teleop_shadow::ShadowConfig;

#[derive(Parser)]
#[command(
    version,
    about = "Shadow Hand E over EtherCAT: hand command in, hand state and PST tactile out"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
    /// Transport (`interface:NAME`, `ethercrab:NAME` or `sim:SOCKET`); overrides the configuration.
    #[arg(long)]
    transport: Option<String>,
}

fn main() -> ExitCode {
    node_main("shadow", |args: Args| -> anyhow::Result<()> {
        let mut config: ShadowConfig = args.node.load_config()?;
        if let Some(t) = args.transport {
            config.transport = t;
        }
        let checked = args.node.check(config.validate())?;
        let connect = teleop_ecat_master::connector(&checked.transport);
        teleop_shadow::run(&args.node.runtime()?, &config, checked, connect)
    })
}
