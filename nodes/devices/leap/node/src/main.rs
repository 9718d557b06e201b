//! `teleop-leap`: the LEAP Hand process (see the `teleop_leap` library for what it does).

use std::process::ExitCode;

use clap::Parser;
use teleop_runtime::{node_main, NodeArgs};

#[derive(Parser)]
#[command(
    version,
    about = "LEAP Hand (16 Dynamixel XC330 servos on one serial bus): hand command in, \
             goal positions and the full servo state polled at rate_hz, hand state out"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
    /// The serial port; overrides the configuration's `port`.
    #[arg(long)]
    port: Option<String>,
}

fn main() -> ExitCode {
    node_main("leap", |args: Args| -> anyhow::Result<()> {
        let (mut config, profile) = teleop_leap::load(args.node.config.as_deref())?;
        if let Some(port) = args.port {
            config.port = port;
        }
        let settings = args.node.check(config.validate())?;
        teleop_leap::run(&args.node.runtime()?, &settings, &profile)
    })
}
