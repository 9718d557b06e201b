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
//! Must not depend on: the EtherCAT master (`ethercrab`) or any device: it moves bytes. The
//! master's frame pump lives with the node; the device emulation in `teleop-ecat-sim`.

mod raw;
mod stream;

use std::time::Duration;

pub use raw::{Accept, RawSocketLink};
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
    /// Receives one Ethernet frame into `buf`, waiting at most `timeout`; `Ok(None)` when none
    /// arrived in time.
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> Result<Option<usize>, LinkError>;
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
