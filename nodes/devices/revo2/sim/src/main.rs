//! `teleop-sim-revo2`: the emulated Revo2 as a process. It serves EtherCAT frames either on a
//! local socket (`--socket PATH`, the default simulated session, no privileges) or on a network
//! interface with a raw socket (`--interface IF`, e.g. one end of a veth pair; needs
//! CAP_NET_RAW), and takes commands at run time on a control socket (the simulator kit's
//! vocabulary: `unplug MS`, `drop P`, `clear`, `stats`, `object ball|none`; and the Revo2's own,
//! see [`teleop_sim_revo2::control`]).

use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Parser;
use teleop_sim_kit::ethercat::PlaceArgs;
use teleop_sim_kit::process::{self, SimArgs};
use teleop_sim_kit::Object;
use teleop_sim_revo2::control::{virtual_object, Revo2Sim};
use teleop_sim_revo2::revo2_subdevice_with_loop;

#[derive(Parser)]
#[command(version, about = "Emulated BrainCo Revo2 EtherCAT SubDevice")]
struct Args {
    #[command(flatten)]
    place: PlaceArgs,
    /// Virtual object in the hand: `ball` or `none`.
    #[arg(long, default_value = "ball")]
    object: String,
    /// Serial number in the identity object.
    #[arg(long, default_value_t = 42)]
    serial: u32,
    /// Period of the firmware's main loop in microseconds: AL control is read once per loop,
    /// as a slave firmware does (0: every write acted on at once).
    #[arg(long, default_value_t = 1000)]
    firmware_loop_us: u64,
    #[command(flatten)]
    sim: SimArgs,
}

fn main() -> ExitCode {
    process::main(run)
}

fn run(args: Args) -> anyhow::Result<()> {
    let object = Object::from_arg(&args.object)
        .and_then(virtual_object)
        .map_err(anyhow::Error::msg)?;
    let device = Arc::new(Mutex::new(revo2_subdevice_with_loop(
        object,
        args.serial,
        Duration::from_micros(args.firmware_loop_us),
    )));
    let start = Instant::now();
    let sim = Arc::new(Revo2Sim::new(Arc::clone(&device), start));
    args.place.serve("revo2", &args.sim, sim, &device, start)
}
