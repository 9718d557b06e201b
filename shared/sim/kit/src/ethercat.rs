//! Where an emulated EtherCAT device serves its frames: a local socket (`--socket PATH`, no
//! privileges) or a network interface with a raw socket (`--interface IF`, e.g. one end of a
//! veth pair; needs CAP_NET_RAW), with its control socket beside it.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use teleop_ecat_link::{Place, Responder};

use crate::control::Simulator;
use crate::process::{stopping, SimArgs};

/// The arguments of an EtherCAT simulator's place (flattened into its own).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct PlaceArgs {
    /// Serve on this Unix socket (the node connects with `transport = "sim:PATH"`).
    #[arg(long, conflicts_with = "interface")]
    pub socket: Option<PathBuf>,
    /// Serve on this network interface with a raw socket (needs CAP_NET_RAW).
    #[arg(long)]
    pub interface: Option<String>,
}

impl PlaceArgs {
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
