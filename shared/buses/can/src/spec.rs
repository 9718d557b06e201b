//! Where the CAN bus is ([`LinkSpec`], the `link` setting) and how fast it runs ([`Bitrate`]).

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use crate::LinkError;

/// Serial line speed of an slcan adapter when the spec gives none. USB-CDC adapters
/// (CANable, CANtact) ignore it; a real UART needs 500000 or more for the Allegro's traffic
/// (docs/devices/allegro.md, "Bus timing").
pub const DEFAULT_SERIAL_BAUD: u32 = 115_200;

/// Where the CAN bus is: `slcan:PATH[@SERIAL_BAUD]`, `socketcan:IFACE`, `local:SOCKET_PATH`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum LinkSpec {
    /// An slcan adapter on a serial port (`slcan:/dev/ttyACM0`, `slcan:/dev/ttyUSB0@1000000`).
    Slcan {
        /// The serial device.
        path: PathBuf,
        /// Serial line speed (default 115200; ignored by USB-CDC adapters).
        serial_baud: u32,
    },
    /// A SocketCAN interface (`socketcan:can0`).
    SocketCan {
        /// The interface name.
        interface: String,
    },
    /// The simulator's bus socket (`local:/tmp/allegro-bus.sock`).
    Local {
        /// The Unix socket path.
        socket: PathBuf,
    },
}

const EXPECTED: &str =
    "expected slcan:PATH[@SERIAL_BAUD], socketcan:INTERFACE or local:SOCKET_PATH";

impl FromStr for LinkSpec {
    type Err = LinkError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |detail: String| LinkError::Spec {
            spec: s.to_string(),
            detail,
        };
        let text = s.trim();
        let Some((kind, rest)) = text.split_once(':') else {
            let hint = if text.starts_with('/') {
                format!("; for a serial adapter write slcan:{text}")
            } else if !text.is_empty() && !text.contains(['/', ' ']) {
                format!("; for a SocketCAN interface write socketcan:{text}")
            } else {
                String::new()
            };
            return Err(err(format!("no link kind: {EXPECTED}{hint}")));
        };
        match kind {
            "slcan" => {
                let (path, serial_baud) = match rest.rsplit_once('@') {
                    Some((path, baud)) => {
                        let baud: u32 = baud.parse().map_err(|_| {
                            err(format!(
                                "serial baud {baud:?} after '@' is not a number (e.g. \
                                 slcan:/dev/ttyUSB0@1000000)"
                            ))
                        })?;
                        if baud == 0 {
                            return Err(err("serial baud must be above 0".into()));
                        }
                        (path, baud)
                    }
                    None => (rest, DEFAULT_SERIAL_BAUD),
                };
                if path.is_empty() {
                    return Err(err("no serial device path (e.g. slcan:/dev/ttyACM0)".into()));
                }
                Ok(LinkSpec::Slcan {
                    path: PathBuf::from(path),
                    serial_baud,
                })
            }
            "socketcan" => {
                if rest.is_empty() {
                    return Err(err("no interface name (e.g. socketcan:can0)".into()));
                }
                // IFNAMSIZ is 16 with the terminating zero.
                if rest.len() > 15 || rest.contains(['/', ' ', '\t', ':']) {
                    return Err(err(format!(
                        "{rest:?} is not an interface name (at most 15 characters, no '/', \
                         ':' or spaces)"
                    )));
                }
                Ok(LinkSpec::SocketCan {
                    interface: rest.to_string(),
                })
            }
            "local" => {
                if rest.is_empty() {
                    return Err(err(
                        "no socket path (e.g. local:/tmp/teleop-allegro-bus.sock)".into(),
                    ));
                }
                Ok(LinkSpec::Local {
                    socket: PathBuf::from(rest),
                })
            }
            other => Err(err(format!("unknown link kind {other:?}: {EXPECTED}"))),
        }
    }
}

/// The spec as it is written (`slcan:/dev/ttyUSB0@1000000`; the default baud is left out).
impl fmt::Display for LinkSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkSpec::Slcan { path, serial_baud } => {
                write!(f, "slcan:{}", path.display())?;
                if *serial_baud != DEFAULT_SERIAL_BAUD {
                    write!(f, "@{serial_baud}")?;
                }
                Ok(())
            }
            LinkSpec::SocketCan { interface } => write!(f, "socketcan:{interface}"),
            LinkSpec::Local { socket } => write!(f, "local:{}", socket.display()),
        }
    }
}

/// A CAN bit rate in bit/s (the Allegro runs at 1 Mbit/s: [`Bitrate::MBIT_1`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Bitrate(pub u32);

impl Bitrate {
    /// 1 Mbit/s.
    pub const MBIT_1: Bitrate = Bitrate(1_000_000);

    /// The slcan `Sn` code: 10k 0, 20k 1, 50k 2, 100k 3, 125k 4, 250k 5, 500k 6, 800k 7
    /// (Lawicel, Linux slcan) or 750k 7 (CANable firmware: its S7 means 750k; ask for 750000
    /// with such an adapter), 1M 8. `None` for other rates (those need `sxxyy` BTR values).
    pub fn slcan_code(self) -> Option<u8> {
        Some(match self.0 {
            10_000 => 0,
            20_000 => 1,
            50_000 => 2,
            100_000 => 3,
            125_000 => 4,
            250_000 => 5,
            500_000 => 6,
            750_000 | 800_000 => 7,
            1_000_000 => 8,
            _ => return None,
        })
    }
}

impl Default for Bitrate {
    fn default() -> Self {
        Bitrate::MBIT_1
    }
}

/// `1000000`, `1M`, `500k` (case-insensitive suffixes k and M).
impl FromStr for Bitrate {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim();
        let (digits, scale) = match t.char_indices().last() {
            Some((i, 'k' | 'K')) => (&t[..i], 1_000),
            Some((i, 'm' | 'M')) => (&t[..i], 1_000_000),
            _ => (t, 1),
        };
        digits
            .parse::<u32>()
            .ok()
            .and_then(|v| v.checked_mul(scale))
            .filter(|&v| v > 0)
            .map(Bitrate)
            .ok_or_else(|| format!("bit rate {s:?}: expected bit/s such as 1000000, 1M or 500k"))
    }
}

impl fmt::Display for Bitrate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            v if v % 1_000_000 == 0 => write!(f, "{}M", v / 1_000_000),
            v if v % 1_000 == 0 => write!(f, "{}k", v / 1_000),
            v => write!(f, "{v}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn detail(s: &str) -> String {
        match s.parse::<LinkSpec>() {
            Err(LinkError::Spec { spec, detail }) => {
                assert_eq!(spec, s);
                detail
            }
            other => panic!("{s:?}: expected a spec error, got {other:?}"),
        }
    }

    #[test]
    fn parses_each_kind() {
        assert_eq!(
            "slcan:/dev/ttyACM0".parse::<LinkSpec>().expect("valid"),
            LinkSpec::Slcan {
                path: "/dev/ttyACM0".into(),
                serial_baud: 115_200
            }
        );
        assert_eq!(
            "slcan:/dev/ttyUSB0@1000000"
                .parse::<LinkSpec>()
                .expect("valid"),
            LinkSpec::Slcan {
                path: "/dev/ttyUSB0".into(),
                serial_baud: 1_000_000
            }
        );
        assert_eq!(
            " socketcan:can0 ".parse::<LinkSpec>().expect("valid"),
            LinkSpec::SocketCan {
                interface: "can0".into()
            }
        );
        assert_eq!(
            "local:/tmp/bus.sock".parse::<LinkSpec>().expect("valid"),
            LinkSpec::Local {
                socket: "/tmp/bus.sock".into()
            }
        );
    }

    #[test]
    fn display_round_trips() {
        for s in [
            "slcan:/tmp/teleop-allegro",
            "slcan:/dev/ttyUSB0@500000",
            "socketcan:can1",
            "local:/run/x.sock",
        ] {
            let spec: LinkSpec = s.parse().expect("valid");
            assert_eq!(spec.to_string(), s);
            assert_eq!(spec.to_string().parse::<LinkSpec>().expect("valid"), spec);
        }
    }

    #[test]
    fn errors_say_what_is_wrong() {
        assert!(detail("").contains("expected slcan:PATH"));
        assert!(detail("/dev/ttyACM0").contains("slcan:/dev/ttyACM0"));
        assert!(detail("can0").contains("socketcan:can0"));
        assert!(detail("pcan:usb1").contains("unknown link kind \"pcan\""));
        assert!(detail("slcan:").contains("no serial device path"));
        assert!(detail("slcan:/dev/ttyUSB0@fast").contains("\"fast\""));
        assert!(detail("slcan:/dev/ttyUSB0@0").contains("above 0"));
        assert!(detail("socketcan:").contains("no interface name"));
        assert!(detail("socketcan:averyveryverylongname").contains("not an interface name"));
        assert!(detail("local:").contains("no socket path"));
    }

    #[test]
    fn bitrates() {
        assert_eq!("1M".parse::<Bitrate>(), Ok(Bitrate::MBIT_1));
        assert_eq!("500k".parse::<Bitrate>(), Ok(Bitrate(500_000)));
        assert_eq!("125000".parse::<Bitrate>(), Ok(Bitrate(125_000)));
        assert!("fast".parse::<Bitrate>().is_err());
        assert!("0".parse::<Bitrate>().is_err());
        assert!("5000M".parse::<Bitrate>().is_err());
        assert_eq!(Bitrate::MBIT_1.to_string(), "1M");
        assert_eq!(Bitrate(83_333).to_string(), "83333");
        assert_eq!(Bitrate::MBIT_1.slcan_code(), Some(8));
        assert_eq!(Bitrate(800_000).slcan_code(), Some(7));
        assert_eq!(Bitrate(750_000).slcan_code(), Some(7));
        assert_eq!(Bitrate(10_000).slcan_code(), Some(0));
        assert_eq!(Bitrate(83_333).slcan_code(), None);
    }
}
