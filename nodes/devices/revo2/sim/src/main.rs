//! `teleop-sim-revo2`: the emulated Revo2 as a process. It serves EtherCAT frames either on a
//! local socket (`--socket PATH`, the default simulated session, no privileges) or on a network
//! interface with a raw socket (`--interface IF`, e.g. one end of a veth pair; needs
//! CAP_NET_RAW), and takes commands at run time on a control socket (the simulator kit's
//! vocabulary: `unplug MS`, `drop P`, `clear`, `stats`, `object ball|bar|none`; and the Revo2's
//! own, see [`teleop_sim_revo2::control`]). Objects touch the fingers by geometry unless
//! `--contact joint` asks for the older joint-space model (each finger stops at a fixed position).

use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use clap::Parser;
use teleop_sim_kit::ethercat::EthercatArgs;
use teleop_sim_kit::object::ObjectArg;
use teleop_sim_kit::process::{self, SimArgs};
use teleop_sim_revo2::control::{object_model, Contact, Revo2Sim};
use teleop_sim_revo2::revo2_subdevice_with_loop;

#[derive(Parser)]
#[command(version, about = "Emulated BrainCo Revo2 EtherCAT SubDevice")]
struct Args {
    #[command(flatten)]
    ethercat: EthercatArgs,
    #[command(flatten)]
    object: ObjectArg,
    /// How objects touch the fingers: `geometric` (a shape that the fingertip pads press where
    /// the hand profile's kinematics put them) or `joint` (each finger stops at a fixed position
    /// whatever the pose; no bar).
    #[arg(long, value_enum, default_value_t = ContactArg::Geometric)]
    contact: ContactArg,
    /// The objects' surface stiffness with geometric contact, newtons per metre: a sponge a few
    /// hundred, a rigid block 1e4..1e5 [default: 3000, a firm object].
    #[arg(long, value_name = "N_PER_M", value_parser = stiffness)]
    stiffness: Option<f32>,
    /// Serial number in the identity object.
    #[arg(long, default_value_t = 42)]
    serial: u32,
    #[command(flatten)]
    sim: SimArgs,
}

/// The `--contact` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ContactArg {
    Geometric,
    Joint,
}

/// The default `--stiffness`, newtons per metre: a firm object.
const DEFAULT_STIFFNESS_N_PER_M: f32 = 3000.0;

/// A `--stiffness` value: a finite positive number.
fn stiffness(text: &str) -> Result<f32, String> {
    text.parse::<f32>()
        .ok()
        .filter(|k| k.is_finite() && *k > 0.0)
        .ok_or_else(|| format!("expected newtons per metre above 0, got {text:?}"))
}

fn main() -> ExitCode {
    process::main(run)
}

/// The contact model the arguments choose; `--stiffness` only with `--contact geometric`.
fn contact(args: &Args) -> anyhow::Result<Contact> {
    Ok(match (args.contact, args.stiffness) {
        (ContactArg::Geometric, k) => Contact::Geometric {
            stiffness_n_per_m: k.unwrap_or(DEFAULT_STIFFNESS_N_PER_M),
        },
        (ContactArg::Joint, None) => Contact::Joint,
        (ContactArg::Joint, Some(_)) => {
            anyhow::bail!("--stiffness applies to --contact geometric, not joint")
        }
    })
}

fn run(args: Args) -> anyhow::Result<()> {
    let contact = contact(&args)?;
    let object = object_model(args.object.object()?, contact).map_err(anyhow::Error::msg)?;
    let mut device = revo2_subdevice_with_loop(None, args.serial, args.ethercat.firmware_loop());
    device.app_mut().hand_mut().set_object(object);
    device.faults().seed = args.sim.seed;
    let device = Arc::new(Mutex::new(device));
    let start = Instant::now();
    let sim = Arc::new(Revo2Sim::new(Arc::clone(&device), start, contact));
    args.ethercat.serve("revo2", &args.sim, sim, &device, start)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contact_and_stiffness_arguments() {
        let parse = |extra: &[&str]| {
            let mut argv = vec!["teleop-sim-revo2", "--socket", "/tmp/x.sock"];
            argv.extend_from_slice(extra);
            Args::try_parse_from(argv)
        };
        let args = parse(&[]).unwrap();
        assert_eq!(
            (args.contact, args.stiffness),
            (ContactArg::Geometric, None)
        );
        let args = parse(&["--contact", "joint"]).unwrap();
        assert_eq!(args.contact, ContactArg::Joint);
        let args = parse(&["--stiffness", "1e5"]).unwrap();
        assert_eq!(args.stiffness, Some(1e5));
        for bad in ["0", "-300", "inf", "soft"] {
            assert!(parse(&["--stiffness", bad]).is_err(), "{bad}");
        }
        assert!(parse(&["--contact", "pad"]).is_err());
        // What the arguments choose.
        assert_eq!(
            contact(&parse(&[]).unwrap()).unwrap(),
            Contact::Geometric {
                stiffness_n_per_m: DEFAULT_STIFFNESS_N_PER_M
            }
        );
        assert_eq!(
            contact(&parse(&["--contact", "joint"]).unwrap()).unwrap(),
            Contact::Joint
        );
        let e = contact(&parse(&["--contact", "joint", "--stiffness", "300"]).unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("--stiffness") && e.contains("joint"), "{e}");
    }
}
