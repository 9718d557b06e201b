//! Where an emulated EtherCAT device serves its frames: a local socket (`--socket PATH`, no
//! privileges) or a network interface with a raw socket (`--interface IF`, e.g. one end of a
//! veth pair; needs CAP_NET_RAW), with its control socket beside it.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use teleop_ecat_link::{Place, Responder};

use crate::control::Simulator;
use crate::process::{stopping, SimArgs};

/// The arguments every emulated EtherCAT device takes (flattened into its own).
#[derive(Debug, Clone, clap::Args)]
pub struct EthercatArgs {
    /// Serve on this Unix socket (the node connects with `transport = "sim:PATH"`).
    #[arg(long, conflicts_with = "interface")]
    pub socket: Option<PathBuf>,
    /// Serve on this network interface with a raw socket (needs CAP_NET_RAW).
    #[arg(long)]
    pub interface: Option<String>,
    /// Period of the firmware's main loop in microseconds: AL control is read once per loop,
    /// as a SubDevice's firmware does (0: every write acted on at once).
    #[arg(long, default_value_t = 1000)]
    pub firmware_loop_us: u64,
}

impl EthercatArgs {
    /// The firmware's main loop period.
    pub fn firmware_loop(&self) -> Duration {
        Duration::from_micros(self.firmware_loop_us)
    }

    /// Serves `devices` as `name` until a stop signal, with `sim`'s control socket (by default
    /// the socket path with `.ctl`, or `/tmp/teleop-NAME-IF.ctl`); `start` is the devices'
    /// time zero.
    pub fn serve<S: Simulator, R: Responder + ?Sized>(
        &self,
        name: &str,
        sim_args: &SimArgs,
        sim: Arc<S>,
        devices: &Mutex<R>,
        start: Instant,
    ) -> anyhow::Result<()> {
        let place = Place::from_args(self.socket.clone(), self.interface.clone())
            .ok_or_else(|| anyhow::anyhow!("give --socket PATH or --interface IF"))?;
        let control = sim_args.serve(sim, place.default_control(name))?;
        place.serve(name, control.path(), devices, start, &stopping)?;
        Ok(())
    }
}
