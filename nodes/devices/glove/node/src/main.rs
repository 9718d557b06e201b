//! `teleop-glove`: the glove process (see the `teleop_glove` library for what it does).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use teleop_glove::GloveConfig;
use teleop_runtime::{node_main, NodeArgs};

#[derive(Parser)]
#[command(version, about = "EH55BF1 glove: glove state out, force commands in")]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
    /// Serial port; overrides the configuration.
    #[arg(long)]
    port: Option<PathBuf>,
}

fn main() -> ExitCode {
    node_main("glove", |args: Args| -> anyhow::Result<()> {
        let mut config: GloveConfig = args.node.load_config()?;
        if let Some(port) = args.port {
            config.port = port;
        }
        args.node.check(config.validate())?;
        teleop_glove::run(&args.node.runtime()?, &config)
    })
}
