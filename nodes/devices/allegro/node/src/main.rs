//! `teleop-allegro`: the Allegro Hand process (see the `teleop_allegro` library for what it does).

use std::process::ExitCode;

use clap::Parser;
use teleop_allegro::ProtocolSetting;
use teleop_runtime::{node_main, NodeArgs};

#[derive(Parser)]
#[command(
    version,
    about = "Wonik Allegro Hand over CAN: hand command in, 333 Hz PD torque loop, hand state out"
)]
struct Args {
    #[command(flatten)]
    node: NodeArgs,
    /// The CAN link (`slcan:PATH`, `socketcan:IFACE`, `local:SOCKET`); overrides the
    /// configuration's `link`.
    #[arg(long)]
    link: Option<String>,
    /// `auto`, `v1`, `v2`, `v3` or `v4`; overrides the configuration's `protocol`.
    #[arg(long)]
    protocol: Option<ProtocolSetting>,
}

fn main() -> ExitCode {
    node_main("allegro", |args: Args| -> anyhow::Result<()> {
        let (mut config, profile) = teleop_allegro::load(args.node.config.as_deref())?;
        if let Some(link) = args.link {
            config.link = link;
        }
        if let Some(p) = args.protocol {
            config.protocol = p;
        }
        let settings = args.node.check(config.validate())?;
        teleop_allegro::run(&args.node.runtime()?, &settings, &profile)
    })
}
