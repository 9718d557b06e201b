//! EtherCAT frames on a raw AF_PACKET socket bound to one interface.

use std::ffi::CString;
use std::time::Duration;

use crate::{FrameLink, LinkError, ETHERCAT_ETHERTYPE};

/// A raw socket for EtherType 0x88A4 on one network interface (needs CAP_NET_RAW).
pub struct RawSocketLink {
    fd: libc::c_int,
    interface: String,
    /// Frames whose source MAC has the locally-administered bit set are replies that already
    /// passed a SubDevice; the master wants them, an emulator wants the others.
    accept: Accept,
}

/// Which frames a [`RawSocketLink`] receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accept {
    /// Every EtherCAT frame.
    All,
    /// Only frames not yet processed by a SubDevice (an emulator's end of a veth pair, which also
    /// sees its own replies).
    FromMaster,
}

impl RawSocketLink {
    /// Opens `interface`. Without CAP_NET_RAW the error says how to grant it.
    pub fn open(interface: &str, accept: Accept) -> Result<Self, LinkError> {
        let name = CString::new(interface)
            .map_err(|_| LinkError::Down(format!("bad interface name {interface:?}")))?;
        // SAFETY: plain libc calls with valid arguments; the fd is owned by the returned value.
        unsafe {
            let index = libc::if_nametoindex(name.as_ptr());
            if index == 0 {
                return Err(LinkError::Down(format!(
                    "no network interface {interface:?}"
                )));
            }
            let protocol = (ETHERCAT_ETHERTYPE).to_be() as libc::c_int;
            let fd = libc::socket(
                libc::AF_PACKET,
                libc::SOCK_RAW | libc::SOCK_CLOEXEC,
                protocol,
            );
            if fd < 0 {
                let e = std::io::Error::last_os_error();
                if e.kind() == std::io::ErrorKind::PermissionDenied {
                    return Err(LinkError::Permission(format!(
                        "raw EtherCAT socket on {interface}: {e}; run as root or grant the capability: \
                         sudo setcap cap_net_raw,cap_net_admin=eip <binary>"
                    )));
                }
                return Err(LinkError::Io {
                    context: format!("raw socket on {interface}"),
                    source: e,
                });
            }
            let mut addr: libc::sockaddr_ll = core::mem::zeroed();
            addr.sll_family = libc::AF_PACKET as u16;
            addr.sll_protocol = ETHERCAT_ETHERTYPE.to_be();
            addr.sll_ifindex = index as i32;
            let rc = libc::bind(
                fd,
                (&addr as *const libc::sockaddr_ll).cast(),
                core::mem::size_of::<libc::sockaddr_ll>() as u32,
            );
            if rc < 0 {
                let e = std::io::Error::last_os_error();
                libc::close(fd);
                return Err(LinkError::Io {
                    context: format!("bind raw socket to {interface}"),
                    source: e,
                });
            }
            Ok(Self {
                fd,
                interface: interface.to_string(),
                accept,
            })
        }
    }
}

impl Drop for RawSocketLink {
    fn drop(&mut self) {
        // SAFETY: we own the fd.
        unsafe {
            libc::close(self.fd);
        }
    }
}

impl FrameLink for RawSocketLink {
    fn send(&mut self, frame: &[u8]) -> Result<(), LinkError> {
        // SAFETY: frame is a valid buffer of frame.len() bytes.
        let n = unsafe { libc::send(self.fd, frame.as_ptr().cast(), frame.len(), 0) };
        if n < 0 {
            return Err(LinkError::Down(format!(
                "{}: {}",
                self.interface,
                std::io::Error::last_os_error()
            )));
        }
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> Result<Option<usize>, LinkError> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            let ready = crate::wait_readable(&[self.fd], left)
                .map_err(|e| LinkError::Down(format!("{}: {e}", self.interface)))?;
            if ready == 0 {
                return Ok(None);
            }
            // SAFETY: buf is valid for buf.len() bytes.
            let n = unsafe {
                libc::recv(
                    self.fd,
                    buf.as_mut_ptr().cast(),
                    buf.len(),
                    libc::MSG_DONTWAIT,
                )
            };
            if n < 0 {
                let e = std::io::Error::last_os_error();
                if e.kind() == std::io::ErrorKind::WouldBlock {
                    continue;
                }
                return Err(LinkError::Down(format!("{}: {e}", self.interface)));
            }
            let n = n as usize;
            let processed = n >= 12 && buf[6] & 0x02 != 0;
            if self.accept == Accept::FromMaster && processed {
                continue;
            }
            return Ok(Some(n));
        }
    }

    fn fd(&self) -> Option<std::os::fd::RawFd> {
        Some(self.fd)
    }
}
