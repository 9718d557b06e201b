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
