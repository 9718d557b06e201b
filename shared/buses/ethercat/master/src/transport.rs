//! Where the bus is: the transports a [`Bus`](crate::Bus) can be opened on.

use std::path::PathBuf;

/// Where the EtherCAT bus is.
///
/// For a real hand use `interface:NAME`: the node's own frame pump on a raw socket, which
/// survives interface resets (admin-down/up, a NIC driver reset) by reopening the socket while
/// the cycle rides out the lost frames. `ethercrab:NAME` runs ethercrab's own raw-socket task
/// (`ethercrab::std::tx_rx_task`) unmodified instead; that task ends for good on a send error
/// (e.g. the interface going down) or a late reply (after a stall longer than the PDU timeout),
/// after which the node opens a fresh bus (new PDU storage, MainDevice and task, and a new
/// bring-up to OP) once the interface is up. Both need CAP_NET_RAW (run as root or
/// `sudo setcap cap_net_raw,cap_net_admin=eip <binary>`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Transport {
    /// An emulated bus (e.g. the emulated Revo2 process) on a local socket.
    Sim(PathBuf),
    /// A network interface through a raw socket driven by the node's frame pump (real hardware,
    /// or a veth pair); needs CAP_NET_RAW. The recommended transport for hardware.
    Interface(String),
    /// A network interface through ethercrab's own raw-socket task (`ethercrab::std::tx_rx_task`,
    /// unmodified); needs CAP_NET_RAW. The task ends on a socket error; the node then reopens
    /// the bus.
    EthercrabInterface(String),
}

impl Transport {
    /// Parses `sim:PATH`, `interface:NAME` or `ethercrab:NAME`.
    pub fn parse(text: &str) -> Result<Self, String> {
        match text.split_once(':') {
            Some(("sim", path)) if !path.is_empty() => Ok(Self::Sim(PathBuf::from(path))),
            Some(("interface", name)) if !name.is_empty() => Ok(Self::Interface(name.to_string())),
            Some(("ethercrab", name)) if !name.is_empty() => {
                Ok(Self::EthercrabInterface(name.to_string()))
            }
            _ => Err(format!(
                "transport = {text:?}: use \"interface:NAME\" (e.g. interface:eth0; recommended \
                 for hardware), \"ethercrab:NAME\" (ethercrab's own raw-socket task) or \
                 \"sim:SOCKET\""
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transports_parse_and_bad_ones_say_what_is_accepted() {
        assert_eq!(
            Transport::parse("interface:eth1"),
            Ok(Transport::Interface("eth1".into()))
        );
        assert_eq!(
            Transport::parse("sim:/tmp/x"),
            Ok(Transport::Sim("/tmp/x".into()))
        );
        assert_eq!(
            Transport::parse("ethercrab:ecm0"),
            Ok(Transport::EthercrabInterface("ecm0".into()))
        );
        assert!(Transport::parse("ethercrab:").is_err());
        let err = Transport::parse("eth0").unwrap_err();
        assert!(
            err.contains("interface:NAME") && err.contains("ethercrab:NAME"),
            "{err}"
        );
    }
}
