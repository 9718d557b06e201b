//! `teleop-sim-shadow`: the emulated Shadow Hand E as a process. It serves EtherCAT frames on a
//! local socket (`--socket PATH`, no privileges) or on a network interface with a raw socket
//! (`--interface IF`, e.g. one end of a veth pair; needs CAP_NET_RAW), and takes commands at
//! run time on a control socket (the simulator kit's vocabulary: `unplug MS`, `drop P`,
//! `clear`, `stats`, `object ball|none`; and the hand's own, see
//! [`teleop_sim_shadow::control`]).

use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use clap::Parser;
use teleop_shadow_protocol::mapping::Mapping;
use teleop_sim_kit::ethercat::EthercatArgs;
use teleop_sim_kit::object::ObjectArg;
use teleop_sim_kit::process::{self, SimArgs};
use teleop_sim_shadow::control::{hand_object, ShadowSim};
use teleop_sim_shadow::ethercat::ShadowBus;
use teleop_sim_shadow::hand::Hand;
use teleop_sim_shadow::palm::Palm;

#[derive(Parser)]
#[command(version, about = "Emulated Shadow Hand E (EtherCAT bridge and palm)")]
struct Args {
    #[command(flatten)]
    ethercat: EthercatArgs,
    #[command(flatten)]
    object: ObjectArg,
    /// Joint -> motor mapping of the hand: `E_v3`, `E_v4` or `E_v5`.
    #[arg(long, default_value = "E_v3")]
    mapping: String,
    /// Serial number of the palm (names the hand on a real system).
    #[arg(long, default_value_t = 1178)]
    serial: u32,
    #[command(flatten)]
    sim: SimArgs,
}

fn main() -> ExitCode {
    process::main(run)
}

fn mapping(name: &str) -> anyhow::Result<Mapping> {
    match name {
        "E_v3" => Ok(Mapping::EV3),
        "E_v4" => Ok(Mapping::EV4),
        "E_v5" => Ok(Mapping::EV5),
        other => anyhow::bail!("unknown mapping {other:?}: use E_v3, E_v4 or E_v5"),
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let object = hand_object(args.object.object()?).map_err(anyhow::Error::msg)?;
    let hand = Hand::new(mapping(&args.mapping)?, object);
    let mut bus = ShadowBus::new(
        Palm::with_hand(hand),
        args.serial,
        args.ethercat.firmware_loop(),
    );
    bus.bridge.faults().seed = args.sim.seed;
    let bus = Arc::new(Mutex::new(bus));
    let start = Instant::now();
    let sim = Arc::new(ShadowSim::new(Arc::clone(&bus), start));
    args.ethercat.serve("shadow", &args.sim, sim, &bus, start)
}
