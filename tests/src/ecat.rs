//! An emulated EtherCAT bus (one SubDevice, or a device's several) served on a Unix socket from
//! the test's own process, for a node's `sim:` transport: the test reaches into the emulation
//! to inject faults and look at the device while the node drives it.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Instant;

use teleop_ecat_link::{serve_socket, Responder, StreamServer};

/// The bus, served on its socket until dropped.
pub struct Served<R: Responder + Send + 'static> {
    bus: Arc<Mutex<R>>,
    stop: Arc<AtomicBool>,
    server: Option<JoinHandle<()>>,
}

impl<R: Responder + Send + 'static> Served<R> {
    /// Binds `socket` and serves `bus` on it, on a thread of its own.
    pub fn start(socket: &Path, bus: R) -> Self {
        let bus = Arc::new(Mutex::new(bus));
        let stop = Arc::new(AtomicBool::new(false));
        let listener =
            StreamServer::bind(socket).unwrap_or_else(|e| panic!("{}: {e}", socket.display()));
        let server = {
            let (bus, stop) = (bus.clone(), stop.clone());
            std::thread::Builder::new()
                .name("emulated-bus".into())
                .spawn(move || {
                    let stopping = || stop.load(Ordering::SeqCst);
                    serve_socket(&listener, &*bus, Instant::now(), &stopping, &mut |_, _| {})
                        .expect("serve the emulated bus");
                })
                .expect("the bus's thread")
        };
        Self {
            bus,
            stop,
            server: Some(server),
        }
    }

    /// The emulation, locked (also after a panic elsewhere: the test reports that one).
    pub fn lock(&self) -> MutexGuard<'_, R> {
        self.bus.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The emulation, for a thread of the test's own.
    pub fn shared(&self) -> Arc<Mutex<R>> {
        self.bus.clone()
    }

    /// Stops serving (the emulation stays, to be looked at).
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(server) = self.server.take() {
            let _ = server.join();
        }
    }
}

impl<R: Responder + Send + 'static> Drop for Served<R> {
    fn drop(&mut self) {
        self.stop();
    }
}
