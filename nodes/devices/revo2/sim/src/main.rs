//! `teleop-sim-revo2`: the emulated Revo2 as a process. It serves EtherCAT frames either on a
//! local socket (`--socket PATH`, the default simulated session, no privileges) or on a network
//! interface with a raw socket (`--interface IF`, e.g. one end of a veth pair; needs
//! CAP_NET_RAW), and takes commands at run time on a control socket (the simulator kit's
//! vocabulary: `unplug MS`, `drop P`, `clear`, `stats`, `object ball|none`; and the Revo2's own,
//! see [`teleop_sim_revo2::control`]).

use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use clap::Parser;
use teleop_sim_kit::ethercat::EthercatArgs;
use teleop_sim_kit::object::ObjectArg;
use teleop_sim_kit::process::{self, SimArgs};
use teleop_sim_revo2::control::{virtual_object, Revo2Sim};
use teleop_sim_revo2::revo2_subdevice_with_loop;

#[derive(Parser)]
#[command(version, about = "Emulated BrainCo Revo2 EtherCAT SubDevice")]
struct Args {
    #[command(flatten)]
    ethercat: EthercatArgs,
    #[command(flatten)]
    object: ObjectArg,
    /// Serial number in the identity object.
    #[arg(long, default_value_t = 42)]
    serial: u32,
    #[command(flatten)]
    sim: SimArgs,
}

fn main() -> ExitCode {
    process::main(run)
}

fn run(args: Args) -> anyhow::Result<()> {
    let object = virtual_object(args.object.object()?).map_err(anyhow::Error::msg)?;
    let mut device = revo2_subdevice_with_loop(object, args.serial, args.ethercat.firmware_loop());
    device.faults().seed = args.sim.seed;
    let device = Arc::new(Mutex::new(device));
    let start = Instant::now();
    let sim = Arc::new(Revo2Sim::new(Arc::clone(&device), start));
    args.ethercat.serve("revo2", &args.sim, sim, &device, start)
}
