//! Links that carry whole EtherCAT Ethernet frames between a MainDevice and SubDevices.
//!
//! One trait, [`FrameLink`], and three ways to move frames:
//! - [`InProcessLink`]: a function call into an emulated SubDevice in the same process (tests;
//!   no privileges);
//! - [`StreamLink`] / [`StreamServer`]: a local Unix stream socket, each frame behind a 2-byte
//!   length, to an emulator running as its own process (the default simulated session; no
//!   privileges);
//! - [`RawSocketLink`]: an AF_PACKET socket on a network interface for EtherType 0x88A4, as on
//!   real hardware or one end of a veth pair (needs CAP_NET_RAW).
//!
//! [`serve_link`] and [`serve_socket`] are the SubDevice side: emulated devices (a
//! [`Responder`]) answering a master's frames on any of these links.
//!
//! Must not depend on: the EtherCAT master (`ethercrab`) or any device: it moves bytes. The
//! master's frame pump lives with the node; the device emulation in `teleop-ecat-sim`.

mod raw;
mod serve;
mod stream;

use std::time::Duration;

pub use raw::{Accept, RawSocketLink};
pub use serve::{serve_link, serve_socket, Place, Responder};
pub use stream::{ServerConnection, StreamLink, StreamServer};

/// EtherType of EtherCAT frames.
pub const ETHERCAT_ETHERTYPE: u16 = 0x88A4;
/// Largest Ethernet frame carried (without FCS).
pub const MAX_FRAME: usize = 1514;

/// Why a link failed. `Down` is expected during cable pulls and restarts: callers reconnect.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The other side is gone (connection closed, interface down).
    #[error("link down: {0}")]
    Down(String),
    /// Missing privileges for raw sockets.
    #[error("{0}")]
    Permission(String),
    /// Any other I/O error.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The error.
        source: std::io::Error,
    },
}

/// Something that sends frames and receives frames.
pub trait FrameLink: Send {
    /// Sends one Ethernet frame.
    fn send(&mut self, frame: &[u8]) -> Result<(), LinkError>;
    /// Receives one Ethernet frame into `buf`, waiting at most `timeout` (zero: only what is
    /// already there); `Ok(None)` when none arrived in time.
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> Result<Option<usize>, LinkError>;
    /// The file descriptor that becomes readable when a frame arrives, for waiting on it
    /// together with other events (`None` for links without one).
    fn fd(&self) -> Option<std::os::fd::RawFd> {
        None
    }
}

/// Waits until one of `fds` is readable or `timeout` passes (microsecond precision, unlike
/// socket receive timeouts, which the kernel rounds up to whole scheduler ticks). Returns a bit
/// per descriptor that is readable (or has hung up).
pub fn wait_readable(fds: &[std::os::fd::RawFd], timeout: Duration) -> std::io::Result<u64> {
    let mut pfds: Vec<libc::pollfd> = fds
        .iter()
        .map(|&fd| libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        })
        .collect();
    let ts = libc::timespec {
        tv_sec: timeout.as_secs().min(i64::MAX as u64) as libc::time_t,
        tv_nsec: libc::c_long::from(timeout.subsec_nanos() as i32),
    };
    loop {
        // SAFETY: pfds is a valid array of pfds.len() pollfds; ts is a valid timespec.
        let rc = unsafe {
            libc::ppoll(
                pfds.as_mut_ptr(),
                pfds.len() as libc::nfds_t,
                &ts,
                core::ptr::null(),
            )
        };
        if rc < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            return Err(e);
        }
        let mut ready = 0u64;
        for (i, p) in pfds.iter().enumerate().take(64) {
            if p.revents & (libc::POLLIN | libc::POLLHUP | libc::POLLERR) != 0 {
                ready |= 1 << i;
            }
        }
        return Ok(ready);
    }
}

/// A link to SubDevices emulated in this process: `process` gets each frame the master sends and
/// returns the frame that comes back (or `None` when the frame is lost).
pub struct InProcessLink<F> {
    process: F,
    pending: std::collections::VecDeque<Vec<u8>>,
}

impl<F: FnMut(&[u8]) -> Option<Vec<u8>> + Send> InProcessLink<F> {
    /// A link that runs `process` on every frame.
    pub fn new(process: F) -> Self {
        Self {
            process,
            pending: std::collections::VecDeque::new(),
        }
    }
}

impl<F: FnMut(&[u8]) -> Option<Vec<u8>> + Send> FrameLink for InProcessLink<F> {
    fn send(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        if let Some(reply) = (self.process)(frame) {
            self.pending.push_back(reply);
        }
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> Result<Option<usize>, LinkError> {
        match self.pending.pop_front() {
            Some(frame) => {
                let n = frame.len().min(buf.len());
                buf[..n].copy_from_slice(&frame[..n]);
                Ok(Some(n))
            }
            None => {
                // Nothing can arrive later on its own: honour the wait so callers do not spin.
                std::thread::sleep(timeout.min(Duration::from_millis(1)));
                Ok(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_process_link_returns_replies_in_order_and_loses_dropped_frames() {
        let mut n = 0;
        let mut link = InProcessLink::new(move |f: &[u8]| {
            n += 1;
            (n != 2).then(|| f.iter().map(|b| b + 1).collect())
        });
        link.send(&[1, 2]).unwrap();
        link.send(&[5]).unwrap(); // lost
        link.send(&[7]).unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(link.recv(&mut buf, Duration::ZERO).unwrap(), Some(2));
        assert_eq!(&buf[..2], &[2, 3]);
        assert_eq!(link.recv(&mut buf, Duration::ZERO).unwrap(), Some(1));
        assert_eq!(buf[0], 8);
        assert_eq!(link.recv(&mut buf, Duration::ZERO).unwrap(), None);
    }
}
