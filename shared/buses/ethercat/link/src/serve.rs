//! The SubDevice side of a link: emulated devices answering a master's frames.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use crate::{FrameLink, LinkError, StreamServer, MAX_FRAME};

/// Emulated SubDevices on a link, answering each frame as a bus does: the frame passes them
/// and comes back.
pub trait Responder {
    /// Processes one frame at `now` (the device clock), writing the frame that comes back into
    /// `out` (as long as `frame`); its length, or `None` when the frame is lost.
    fn respond(&mut self, frame: &[u8], out: &mut [u8], now: Duration) -> Option<usize>;

    /// Time passes without a frame (timers, watchdogs, firmware loops).
    fn idle(&mut self, now: Duration);
}

fn lock<R: ?Sized>(devices: &Mutex<R>) -> std::sync::MutexGuard<'_, R> {
    devices.lock().unwrap_or_else(|e| e.into_inner())
}

/// Answers the frames of one master link until it fails or `stop()` says so. `on_frame` runs
/// after each frame with the time it was received (CLOCK_MONOTONIC ns, as `clock` gives it) and
/// the devices after processing it (benchmarks and tests record what the devices saw). The
/// devices' clock is `start.elapsed()`; between frames they are idled every millisecond.
pub fn serve_link<R: Responder + ?Sized>(
    link: &mut dyn FrameLink,
    devices: &Mutex<R>,
    start: Instant,
    stop: &dyn Fn() -> bool,
    on_frame: &mut dyn FnMut(Instant, &R),
) {
    let mut buf = vec![0u8; MAX_FRAME];
    let mut out = vec![0u8; MAX_FRAME];
    while !stop() {
        match link.recv(&mut buf, Duration::from_millis(1)) {
            Ok(Some(n)) => {
                let received = Instant::now();
                let mut dev = lock(devices);
                let reply = dev.respond(&buf[..n], &mut out, start.elapsed());
                on_frame(received, &dev);
                drop(dev);
                if let Some(len) = reply {
                    if let Err(e) = link.send(&out[..len]) {
                        // A device whose reply cannot go out just loses that frame; only a
                        // closed connection ends the session (the next recv reports it).
                        tracing::debug!("reply lost: {e}");
                    }
                }
            }
            Ok(None) => lock(devices).idle(start.elapsed()),
            Err(e) => {
                tracing::debug!("link: {e}");
                return;
            }
        }
    }
}

/// Serves masters connecting to `server`, one at a time, until `stop()` says so (see
/// [`serve_link`]).
pub fn serve_socket<R: Responder + ?Sized>(
    server: &StreamServer,
    devices: &Mutex<R>,
    start: Instant,
    stop: &dyn Fn() -> bool,
    on_frame: &mut dyn FnMut(Instant, &R),
) -> Result<(), LinkError> {
    while !stop() {
        match server.accept()? {
            Some(mut conn) => {
                tracing::info!("master connected");
                serve_link(&mut conn, devices, start, stop, on_frame);
                tracing::info!("master disconnected");
            }
            None => {
                lock(devices).idle(start.elapsed());
                std::thread::sleep(Duration::from_millis(2));
            }
        }
    }
    Ok(())
}

/// Where an emulator serves: a local socket (the master connects with `sim:PATH`) or a network
/// interface with a raw socket (needs CAP_NET_RAW).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Place {
    /// A Unix stream socket at this path.
    Socket(std::path::PathBuf),
    /// This network interface.
    Interface(String),
}

impl Place {
    /// From an emulator's `--socket` / `--interface` arguments (`None`: neither given).
    pub fn from_args(
        socket: Option<std::path::PathBuf>,
        interface: Option<String>,
    ) -> Option<Self> {
        match (socket, interface) {
            (Some(path), _) => Some(Self::Socket(path)),
            (None, Some(interface)) => Some(Self::Interface(interface)),
            (None, None) => None,
        }
    }

    /// The default control socket of emulator `name` here: the socket's path with `.ctl`, or
    /// `/tmp/teleop-NAME-IF.ctl`.
    pub fn default_control(&self, name: &str) -> std::path::PathBuf {
        match self {
            Self::Socket(path) => path.with_extension("ctl"),
            Self::Interface(i) => std::path::PathBuf::from(format!("/tmp/teleop-{name}-{i}.ctl")),
        }
    }

    /// Serves `devices` here until `stop()` says so; once listening, prints
    /// `NAME: socket PATH (control: CTL)` (or `NAME: interface IF ...`) on stdout, the line
    /// launchers and tests wait for.
    pub fn serve<R: Responder + ?Sized>(
        &self,
        name: &str,
        control: &std::path::Path,
        devices: &Mutex<R>,
        start: Instant,
        stop: &dyn Fn() -> bool,
    ) -> Result<(), LinkError> {
        use std::io::Write;
        let announce = |what: String| {
            println!("{name}: {what} (control: {})", control.display());
            let _ = std::io::stdout().flush();
        };
        match self {
            Self::Socket(path) => {
                let server = StreamServer::bind(path)?;
                announce(format!("socket {}", path.display()));
                serve_socket(&server, devices, start, stop, &mut |_, _| {})
            }
            Self::Interface(interface) => {
                let mut link = crate::RawSocketLink::open(interface, crate::Accept::FromMaster)?;
                announce(format!("interface {interface}"));
                serve_link(&mut link, devices, start, stop, &mut |_, _| {});
                Ok(())
            }
        }
    }
}
