//! The emulated Shadow Hand of the node's tests: a `sim-shadow` bus served on a Unix socket
//! (the `sim:` transport), as `teleop-sim-shadow` serves it.

use std::path::Path;
use std::time::Duration;

use teleop_e2e::ecat::Served;
use teleop_sim_shadow::ethercat::ShadowBus;
use teleop_sim_shadow::palm::Palm;

/// The emulated bus, served until dropped (or stopped).
pub type Sim = Served<ShadowBus>;

/// Serves `palm` (behind the bridge, 1 ms cycle) on `socket`.
pub fn serve(socket: &Path, palm: Palm) -> Sim {
    Served::start(socket, ShadowBus::new(palm, 1178, Duration::from_millis(1)))
}
