//! The emulated Shadow Hand of the node's tests: a `sim-shadow` bus served on a Unix socket
//! (the `sim:` transport), as `teleop-sim-shadow` serves it.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use teleop_ecat_link::{serve_socket, StreamServer};
use teleop_sim_shadow::ethercat::ShadowBus;
use teleop_sim_shadow::palm::Palm;

/// The emulated bus, shared with its server thread.
pub type Sim = Arc<Mutex<ShadowBus>>;

/// Serves `palm` (behind the bridge, 1 ms cycle) on `socket` until the returned flag is set;
/// join the thread after setting it.
pub fn serve(socket: &Path, palm: Palm) -> (Sim, Arc<AtomicBool>, JoinHandle<()>) {
    let sim: Sim = Arc::new(Mutex::new(ShadowBus::new(
        palm,
        1178,
        Duration::from_millis(1),
    )));
    let stop = Arc::new(AtomicBool::new(false));
    let server = {
        let (sim, stop) = (sim.clone(), stop.clone());
        let listener = StreamServer::bind(socket).unwrap();
        std::thread::spawn(move || {
            let stopping = || stop.load(Ordering::SeqCst);
            serve_socket(&listener, &*sim, Instant::now(), &stopping, &mut |_, _| {}).unwrap();
        })
    };
    (sim, stop, server)
}
