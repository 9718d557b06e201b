//! The pseudo-terminal device: a pty pair whose device side is published under a stable path
//! (a symlink, like a udev by-id link), so that a host can reopen the same path after the
//! simulated cable was pulled and put back (which makes a new pty).
//!
//! The simulator keeps the device side open too, so its own side never sees a hang-up while
//! the host closes and reopens the port.

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

/// A pty pair: the simulator's side (reads time out after the given time) and the device
/// side, linked at the stable path.
pub struct Pair {
    /// The simulator's side.
    pub master: TTYPort,
    /// The device side (kept open).
    pub slave: TTYPort,
}

/// A new pty pair with its device side linked at `link` (replacing what was there);
/// reads on the simulator's side time out after `read_timeout`.
pub fn open(link: &Path, read_timeout: Duration) -> std::io::Result<Pair> {
    let (mut master, slave) = TTYPort::pair().map_err(std::io::Error::other)?;
    let name = slave
        .name()
        .ok_or_else(|| std::io::Error::other("pty without a name"))?;
    master
        .set_timeout(read_timeout)
        .map_err(std::io::Error::other)?;
    let tmp = link.with_extension("tmp-link");
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(&name, &tmp)?;
    std::fs::rename(&tmp, link)?;
    Ok(Pair { master, slave })
}

/// Reads what the host wrote: 0 bytes when nothing came in time or nobody has the device side
/// open (the host reopening it; then after a pause of `idle`).
pub fn read(master: &mut TTYPort, buf: &mut [u8], idle: Duration) -> usize {
    use std::io::Read;
    match master.read(buf) {
        Ok(n) => n,
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted
            ) =>
        {
            0
        }
        Err(_) => {
            // No reader on the device side right now (EIO): wait for the host.
            std::thread::sleep(idle);
            0
        }
    }
}

/// The device's cable: pulled on request for a while, counted.
#[derive(Debug, Default)]
pub struct Cable {
    pull: Mutex<Option<Duration>>,
    plugged: AtomicBool,
    unplugs: AtomicU64,
}

impl Cable {
    /// A cable not yet plugged in.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks for the cable to be pulled for `pause` (the connection ends at its next look).
    pub fn pull(&self, pause: Duration) {
        *crate::lock(&self.pull) = Some(pause);
    }

    /// A pull was asked for: the connection should end.
    pub fn pulled(&self) -> bool {
        crate::lock(&self.pull).is_some()
    }

    /// The device is plugged in (a pty behind the link).
    pub fn plugged(&self) -> bool {
        self.plugged.load(Ordering::SeqCst)
    }

    /// Times the cable was pulled.
    pub fn unplugs(&self) -> u64 {
        self.unplugs.load(Ordering::SeqCst)
    }
}

/// Serves a device on a pty behind `link` until `stop`: plugged in with `first`, then with a
/// new pty after each pull. `connection` serves one plugged-in period and returns when
/// [`Cable::pulled`] or `stop` (an error is logged, and the device plugged in again after a
/// moment). On a pull the link goes first (whoever sees the port fail finds no device behind
/// it), `unplugged` runs (the device loses power), the pause passes, and the count goes up.
/// The link is removed at the end.
pub fn serve(
    link: &Path,
    read_timeout: Duration,
    first: Pair,
    cable: &Cable,
    stop: &AtomicBool,
    mut connection: impl FnMut(&mut TTYPort) -> std::io::Result<()>,
    mut unplugged: impl FnMut(),
) {
    let mut pair = Some(first);
    while !stop.load(Ordering::SeqCst) {
        let Pair { mut master, slave } = match pair.take() {
            Some(p) => p,
            None => match open(link, read_timeout) {
                Ok(p) => p,
                Err(e) => {
                    tracing::warn!("{}: cannot create a pty: {e}; retrying", link.display());
                    std::thread::sleep(Duration::from_millis(200));
                    continue;
                }
            },
        };
        cable.plugged.store(true, Ordering::SeqCst);
        tracing::info!(
            "plugged in: {} -> {}",
            link.display(),
            slave.name().unwrap_or_default()
        );
        let result = connection(&mut master);
        let pause = crate::lock(&cable.pull).take();
        if pause.is_some() {
            let _ = std::fs::remove_file(link);
            cable.plugged.store(false, Ordering::SeqCst);
        }
        drop(master);
        drop(slave);
        if let Err(e) = result {
            tracing::warn!("{}: connection ended: {e}", link.display());
            std::thread::sleep(Duration::from_millis(100));
        }
        if let Some(pause) = pause {
            unplugged();
            cable.unplugs.fetch_add(1, Ordering::SeqCst);
            tracing::info!("unplugged for {} ms", pause.as_millis());
            let until = Instant::now() + pause;
            while Instant::now() < until && !stop.load(Ordering::SeqCst) {
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }
    let _ = std::fs::remove_file(link);
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use std::io::Write;
    use std::sync::Arc;

    #[test]
    fn the_device_is_behind_the_link_and_comes_back_after_a_pull() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("dev");
        let first = open(&link, Duration::from_millis(5)).unwrap();
        let (cable, stop) = (Arc::new(Cable::new()), Arc::new(AtomicBool::new(false)));
        let served = {
            let (link, cable, stop) = (link.clone(), cable.clone(), stop.clone());
            std::thread::spawn(move || {
                let mut powered_off = 0;
                serve(
                    &link,
                    Duration::from_millis(5),
                    first,
                    &cable,
                    &stop,
                    |master| {
                        let mut buf = [0u8; 16];
                        while !cable.pulled() && !stop.load(Ordering::SeqCst) {
                            let n = read(master, &mut buf, Duration::from_millis(5));
                            master.write_all(&buf[..n])?;
                        }
                        Ok(())
                    },
                    || powered_off += 1,
                );
                powered_off
            })
        };
        let wait = |what: &dyn Fn() -> bool| {
            let until = Instant::now() + Duration::from_secs(30);
            while !what() {
                assert!(Instant::now() < until, "timed out");
                std::thread::sleep(Duration::from_millis(5));
            }
        };
        wait(&|| cable.plugged());
        cable.pull(Duration::from_millis(100));
        wait(&|| cable.unplugs() == 1 && cable.plugged());
        assert!(link.exists(), "plugged back in behind the same link");
        stop.store(true, Ordering::SeqCst);
        assert_eq!(served.join().unwrap(), 1);
        assert!(!link.exists());
    }
}
