//! [`SocketCanLink`]: a Linux SocketCAN interface (`can0`) through the `socketcan` crate.
//!
//! A raw socket (docs/devices/allegro.md, "Adapters": W2, W5, fairo): data and remote frames are
//! passed on, error frames are not; they only update the bus state (controller warning and
//! passive reports, bus-off, restarted) and the error counters. The bit rate is set outside
//! (`ip link set can0 type can bitrate 1000000`, then `ip link set can0 up`). Receiving blocks
//! in `poll` with the caller's timeout.
//!
//! Without SocketCAN in the kernel (no AF_CAN, as on the development VMs, build.md) or on
//! another OS, [`SocketCanLink::open`] fails with [`LinkError::Unsupported`] naming the
//! interface and what is missing.

#[cfg(target_os = "linux")]
pub use linux::SocketCanLink;
#[cfg(not(target_os = "linux"))]
pub use other::SocketCanLink;

#[cfg(target_os = "linux")]
mod linux {
    use std::time::{Duration, Instant};

    use embedded_can::Frame as _;
    use socketcan::{CanSocket, Socket, SocketOptions};

    use crate::{BusState, CanFrame, CanLink, LinkCounters, LinkError};

    // linux/can/error.h: error classes in the id of an error frame, and data[1] bits of a
    // controller problem.
    const CAN_ERR_CRTL: u32 = 0x0004;
    const CAN_ERR_BUSOFF: u32 = 0x0040;
    const CAN_ERR_RESTARTED: u32 = 0x0100;
    const CAN_ERR_CRTL_RX_OVERFLOW: u8 = 0x01;
    const CAN_ERR_CRTL_TX_OVERFLOW: u8 = 0x02;
    const CAN_ERR_CRTL_WARNING: u8 = 0x04 | 0x08;
    const CAN_ERR_CRTL_PASSIVE: u8 = 0x10 | 0x20;
    const CAN_ERR_CRTL_ACTIVE: u8 = 0x40;

    /// An open SocketCAN raw socket on one interface.
    pub struct SocketCanLink {
        socket: CanSocket,
        what: String,
        state: BusState,
        bus_off_reported: bool,
        counters: LinkCounters,
    }

    impl SocketCanLink {
        /// Opens a raw CAN socket on `interface` (`can0`).
        ///
        /// Errors: [`LinkError::Unsupported`] when the kernel has no SocketCAN (AF_CAN);
        /// [`LinkError::NotFound`] when the interface does not exist; [`LinkError::Io`]
        /// otherwise.
        pub fn open(interface: &str) -> Result<Self, LinkError> {
            let what = format!("socketcan:{interface}");
            let socket = match CanSocket::open(interface) {
                Ok(s) => s,
                Err(e) => return Err(open_error(&what, interface, e)),
            };
            let io = |source| LinkError::Io {
                what: what.clone(),
                source,
            };
            // Error frames come in only to update the bus state; they are never returned.
            socket.set_error_filter_accept_all().map_err(io)?;
            socket
                .set_write_timeout(Duration::from_millis(100))
                .map_err(io)?;
            Ok(Self {
                socket,
                what,
                state: BusState::ErrorActive,
                bus_off_reported: false,
                counters: LinkCounters::default(),
            })
        }

        fn io_error(&self, e: std::io::Error, doing: &str) -> LinkError {
            match e.raw_os_error() {
                Some(libc::ENETDOWN) => LinkError::Disconnected {
                    what: self.what.clone(),
                    detail: format!(
                        "{doing}: the interface is down (ip link set {} up)",
                        self.interface()
                    ),
                },
                Some(libc::ENODEV) | Some(libc::ENXIO) => LinkError::Disconnected {
                    what: self.what.clone(),
                    detail: format!("{doing}: the interface went away (adapter unplugged?)"),
                },
                _ => LinkError::Io {
                    what: self.what.clone(),
                    source: std::io::Error::new(e.kind(), format!("{doing}: {e}")),
                },
            }
        }

        fn interface(&self) -> &str {
            self.what.trim_start_matches("socketcan:")
        }

        fn take_error_frame(&mut self, class: u32, data: &[u8]) {
            self.counters.errors += 1;
            let ctrl = data.get(1).copied().unwrap_or(0);
            if class & CAN_ERR_CRTL != 0
                && ctrl & (CAN_ERR_CRTL_RX_OVERFLOW | CAN_ERR_CRTL_TX_OVERFLOW) != 0
            {
                self.counters.overruns += 1;
            }
            let state = if class & CAN_ERR_BUSOFF != 0 {
                BusState::BusOff
            } else if class & CAN_ERR_RESTARTED != 0 {
                BusState::ErrorActive
            } else if class & CAN_ERR_CRTL != 0 {
                if ctrl & CAN_ERR_CRTL_PASSIVE != 0 {
                    BusState::ErrorPassive
                } else if ctrl & CAN_ERR_CRTL_WARNING != 0 {
                    BusState::ErrorWarning
                } else if ctrl & CAN_ERR_CRTL_ACTIVE != 0 {
                    BusState::ErrorActive
                } else {
                    self.state
                }
            } else {
                self.state
            };
            if state != BusState::BusOff {
                self.bus_off_reported = false;
            }
            self.state = state;
        }
    }

    fn open_error(what: &str, interface: &str, e: std::io::Error) -> LinkError {
        let no_af_can = |e: &std::io::Error| e.raw_os_error() == Some(libc::EAFNOSUPPORT);
        let unsupported = || LinkError::Unsupported {
            what: what.to_string(),
            detail: format!(
                "this kernel has no SocketCAN (socket(AF_CAN) fails: address family not \
                 supported), so there is no interface {interface}; load the can and can_raw \
                 modules (modprobe can_raw) on a kernel built with CONFIG_CAN, or use an slcan \
                 adapter (link = \"slcan:/dev/ttyACM0\")"
            ),
        };
        if no_af_can(&e) {
            return unsupported();
        }
        if e.raw_os_error() == Some(libc::ENODEV) || e.kind() == std::io::ErrorKind::NotFound {
            // The interface name did not resolve; say whether SocketCAN itself is missing.
            if let Err(probe) = CanSocket::open_iface(0) {
                if no_af_can(&probe) {
                    return unsupported();
                }
            }
            return LinkError::NotFound {
                what: what.to_string(),
                detail: format!(
                    "no network interface {interface}; check `ip -details link show`, plug in \
                     the adapter, then `ip link set {interface} type can bitrate 1000000` and \
                     `ip link set {interface} up`"
                ),
            };
        }
        LinkError::Io {
            what: what.to_string(),
            source: std::io::Error::new(e.kind(), format!("cannot open: {e}")),
        }
    }

    impl CanLink for SocketCanLink {
        fn send(&mut self, frame: &CanFrame) -> Result<(), LinkError> {
            let id = embedded_can::Frame::id(frame);
            let out = if frame.is_remote() {
                socketcan::CanFrame::new_remote(id, frame.dlc())
            } else {
                socketcan::CanFrame::new(id, frame.data())
            };
            // CanFrame's invariants (id width, DLC <= 8) are the crate's; this cannot fail.
            let Some(out) = out else {
                return Err(LinkError::Adapter {
                    what: self.what.clone(),
                    detail: format!("socketcan refused frame {frame}"),
                });
            };
            self.socket
                .write_frame(&out)
                .map_err(|e| self.io_error(e, "write"))?;
            self.counters.tx += 1;
            Ok(())
        }

        fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, LinkError> {
            let deadline = Instant::now() + timeout;
            loop {
                if self.state == BusState::BusOff && !self.bus_off_reported {
                    self.bus_off_reported = true;
                    return Err(LinkError::BusOff {
                        what: self.what.clone(),
                    });
                }
                let left = deadline.saturating_duration_since(Instant::now());
                let frame = match self.socket.read_frame_timeout(left) {
                    Ok(f) => f,
                    Err(e)
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::TimedOut
                                | std::io::ErrorKind::WouldBlock
                                | std::io::ErrorKind::Interrupted
                        ) =>
                    {
                        if Instant::now() >= deadline {
                            return Ok(None);
                        }
                        continue;
                    }
                    Err(e) => return Err(self.io_error(e, "read")),
                };
                let got = match frame {
                    socketcan::CanFrame::Error(err) => {
                        self.take_error_frame(err.error_bits(), err.data());
                        None
                    }
                    socketcan::CanFrame::Remote(f) => {
                        <CanFrame as embedded_can::Frame>::new_remote(f.id(), f.dlc())
                    }
                    socketcan::CanFrame::Data(f) => {
                        <CanFrame as embedded_can::Frame>::new(f.id(), f.data())
                    }
                };
                if let Some(f) = got {
                    self.counters.rx += 1;
                    return Ok(Some(f));
                }
                if Instant::now() >= deadline && self.state != BusState::BusOff {
                    return Ok(None);
                }
            }
        }

        fn bus_state(&self) -> BusState {
            self.state
        }

        fn counters(&self) -> LinkCounters {
            self.counters
        }

        fn describe(&self) -> &str {
            &self.what
        }
    }
}

#[cfg(not(target_os = "linux"))]
mod other {
    use std::time::Duration;

    use crate::{BusState, CanFrame, CanLink, LinkCounters, LinkError};

    /// SocketCAN exists only on Linux: this cannot be opened here.
    pub struct SocketCanLink {
        never: std::convert::Infallible,
    }

    impl SocketCanLink {
        /// Always [`LinkError::Unsupported`]: SocketCAN is Linux only.
        pub fn open(interface: &str) -> Result<Self, LinkError> {
            Err(LinkError::Unsupported {
                what: format!("socketcan:{interface}"),
                detail: "SocketCAN exists only on Linux; use an slcan adapter".into(),
            })
        }
    }

    impl CanLink for SocketCanLink {
        fn send(&mut self, _: &CanFrame) -> Result<(), LinkError> {
            match self.never {}
        }
        fn recv(&mut self, _: Duration) -> Result<Option<CanFrame>, LinkError> {
            match self.never {}
        }
        fn bus_state(&self) -> BusState {
            match self.never {}
        }
        fn counters(&self) -> LinkCounters {
            match self.never {}
        }
        fn describe(&self) -> &str {
            match self.never {}
        }
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;
    use crate::LinkError;

    /// This machine has no AF_CAN (build.md): opening says so, naming the interface.
    /// On a machine with SocketCAN but no can0 the error is NotFound, also naming it.
    #[test]
    fn open_without_socketcan_is_a_clear_error() {
        match SocketCanLink::open("can0") {
            Err(LinkError::Unsupported { what, detail }) => {
                assert_eq!(what, "socketcan:can0");
                assert!(detail.contains("no SocketCAN"), "{detail}");
                assert!(detail.contains("AF_CAN"), "{detail}");
                assert!(detail.contains("can0"), "{detail}");
                let shown = LinkError::Unsupported { what, detail }.to_string();
                assert!(shown.starts_with("socketcan:can0: unsupported:"), "{shown}");
            }
            Err(LinkError::NotFound { what, detail }) => {
                assert_eq!(what, "socketcan:can0");
                assert!(detail.contains("can0"), "{detail}");
            }
            Err(other) => panic!("unexpected error: {other}"),
            Ok(_) => eprintln!("this machine has SocketCAN and a can0: nothing to check"),
        }
    }

    #[test]
    fn open_unknown_interface_names_it() {
        match SocketCanLink::open("nocan7") {
            Err(LinkError::Unsupported { what, .. } | LinkError::NotFound { what, .. }) => {
                assert_eq!(what, "socketcan:nocan7")
            }
            Err(other) => panic!("unexpected error: {other}"),
            Ok(_) => panic!("nocan7 exists?"),
        }
    }
}
