//! The bridge's configuration file and the zenoh configuration made from it.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::link::ClockMode;

/// Which way a topic crosses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Local iceoryx2 -> the peer.
    Out,
    /// The peer -> local iceoryx2.
    In,
}

/// This station's part in the e-stop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum EStopRole {
    /// The e-stop does not cross.
    #[default]
    None,
    /// This station's latch is the authority (the operator): its state goes in every heartbeat
    /// and at once when it changes.
    Send,
    /// This station follows the peer's latch (the robot): engaged there engages here; released
    /// there releases here only what the bridge engaged (a local `teleop estop` stays).
    Receive,
}

/// One forwarded topic.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopicConfig {
    /// A contract topic, e.g. `hand/command` (in the bridge's namespace, if it has one).
    pub name: String,
    /// Which way it crosses.
    pub direction: Direction,
    /// `in` only: samples older than this on arrival (by their own stamp, in this station's
    /// clock) plus the link's measured one-way delay (the median of the frames' transit, at
    /// most 1 s; 0 until measured and after the link went down) are not published here, and
    /// counted.
    pub max_age_ms: Option<u64>,
}

/// Mutual TLS: the session's CA and this station's certificate and key (PEM files, relative to
/// the configuration file).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TlsConfig {
    /// The CA that signed both stations' certificates.
    pub ca: PathBuf,
    /// This station's certificate.
    pub certificate: PathBuf,
    /// This station's private key.
    pub key: PathBuf,
    /// Check that the peer's certificate names the address connected to (default true).
    #[serde(default = "yes")]
    pub verify_name: bool,
}

fn yes() -> bool {
    true
}

/// The bridge's configuration file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BridgeConfig {
    /// This station's name (`[a-z0-9_-]`, at most 32 bytes).
    pub station: String,
    /// The station on the other end: only its samples are accepted.
    pub peer: String,
    /// The session's name: both stations must use the same; it starts every zenoh key.
    pub session: String,
    /// zenoh endpoints to listen on, e.g. `quic/192.0.2.2:7447` (UDP).
    #[serde(default)]
    pub listen: Vec<String>,
    /// zenoh endpoints of the peer, e.g. `quic/192.0.2.2:7447`.
    #[serde(default)]
    pub connect: Vec<String>,
    /// Heartbeat period.
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_ms: u64,
    /// No heartbeat from the peer for this long: the link is down.
    #[serde(default = "default_link_timeout_ms")]
    pub link_timeout_ms: u64,
    /// zenoh's link lease (a dead TCP link is closed after it, then reconnected).
    #[serde(default = "default_lease_ms")]
    pub lease_ms: u64,
    /// How the peer's stamps relate to this station's clock.
    #[serde(default = "default_clock")]
    pub clock: ClockMode,
    /// This station's part in the e-stop.
    #[serde(default)]
    pub estop: EStopRole,
    /// Seconds between link reports in the log.
    #[serde(default = "default_report_s")]
    pub report_s: u64,
    /// Mutual TLS over QUIC (required unless `insecure`).
    pub tls: Option<TlsConfig>,
    /// Plain TCP without authentication: anyone who reaches the port can command the hand.
    #[serde(default)]
    pub insecure: bool,
    /// The topics that cross.
    #[serde(default)]
    pub topic: Vec<TopicConfig>,
}

fn default_heartbeat_ms() -> u64 {
    20
}
fn default_link_timeout_ms() -> u64 {
    250
}
fn default_lease_ms() -> u64 {
    2000
}
fn default_clock() -> ClockMode {
    ClockMode::Estimate
}
fn default_report_s() -> u64 {
    5
}

/// A configuration that cannot work.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Reading or parsing failed (names file, line and field).
    #[error(transparent)]
    File(#[from] teleop_runtime::ConfigFileError),
    /// A value is refused.
    #[error("{file}: {field}: {reason}")]
    Invalid {
        /// The file.
        file: String,
        /// The field.
        field: String,
        /// Why.
        reason: String,
    },
}

/// True for a station or session name: `[a-z0-9_-]`, 1 to 32 bytes.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= crate::frame::MAX_STATION
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_' || b == b'-')
}

/// The longest time a configuration may give, in ms: a day. (Anything near `u64::MAX / 10^6`
/// would overflow the bridge's nanosecond clock.)
pub const MAX_MS: u64 = 24 * 3600 * 1000;

fn too_large(ms: u64) -> String {
    format!("{ms} ms is too large (at most {MAX_MS}, a day)")
}

/// True for an endpoint whose address is 0.0.0.0 or `[::]` (every interface).
fn listens_everywhere(endpoint: &str) -> bool {
    let address = endpoint.split_once('/').map_or(endpoint, |(_, a)| a);
    let address = address.split(['?', '#']).next().unwrap_or(address);
    address
        .parse::<std::net::SocketAddr>()
        .is_ok_and(|a| a.ip().is_unspecified())
}

/// A private key readable by group or others is refused, naming the fix; a missing one is left
/// to [`BridgeConfig::missing_files`].
fn check_key_mode(key: &Path) -> Result<(), String> {
    use std::os::unix::fs::PermissionsExt;
    let Ok(meta) = std::fs::metadata(key) else {
        return Ok(());
    };
    let mode = meta.permissions().mode() & 0o777;
    if mode & 0o077 != 0 {
        return Err(format!(
            "{} is readable by others (mode {mode:03o}): a private key must be its owner's \
             only; run `chmod 600 {}`",
            key.display(),
            key.display()
        ));
    }
    Ok(())
}

/// This station's certificate must be signed by the configured CA (the one the peer's
/// certificate is checked against and the peer checks this one against): otherwise the peer
/// refuses it in the handshake, with a message on the peer's side only. Missing files are left
/// to [`BridgeConfig::missing_files`].
fn check_issuer(ca: &Path, certificate: &Path) -> Result<(), String> {
    use x509_parser::pem::parse_x509_pem;
    let (Ok(ca_bytes), Ok(cert_bytes)) = (std::fs::read(ca), std::fs::read(certificate)) else {
        return Ok(());
    };
    let not_pem =
        |path: &Path, e: String| format!("{}: not a PEM certificate: {e}", path.display());
    let (_, ca_pem) = parse_x509_pem(&ca_bytes).map_err(|e| not_pem(ca, e.to_string()))?;
    let (_, cert_pem) =
        parse_x509_pem(&cert_bytes).map_err(|e| not_pem(certificate, e.to_string()))?;
    let ca_x509 = ca_pem
        .parse_x509()
        .map_err(|e| not_pem(ca, e.to_string()))?;
    let cert_x509 = cert_pem
        .parse_x509()
        .map_err(|e| not_pem(certificate, e.to_string()))?;
    let signed = cert_x509.issuer() == ca_x509.subject()
        && cert_x509
            .verify_signature(Some(ca_x509.public_key()))
            .is_ok();
    if signed {
        return Ok(());
    }
    Err(format!(
        "certificate from another CA: {} (issued by \"{}\") is not signed by the CA {} \
         (\"{}\"); use the ca.pem of the session that made this certificate, or make this \
         station's certificate with this CA (`teleop certs`)",
        certificate.display(),
        cert_x509.issuer(),
        ca.display(),
        ca_x509.subject()
    ))
}

impl BridgeConfig {
    /// Reads and checks the file at `path`; the certificate paths are relative to its folder.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let mut config: Self = teleop_runtime::load_toml(path)?;
        config.check(&path.display().to_string())?;
        if let (Some(tls), Some(dir)) = (&mut config.tls, path.parent()) {
            for file in [&mut tls.ca, &mut tls.certificate, &mut tls.key] {
                *file = dir.join(&*file);
            }
        }
        if let Some(tls) = &config.tls {
            let invalid = |field: &'static str| {
                let file = path.display().to_string();
                move |reason| ConfigError::Invalid {
                    file,
                    field: field.into(),
                    reason,
                }
            };
            check_key_mode(&tls.key).map_err(invalid("tls.key"))?;
            check_issuer(&tls.ca, &tls.certificate).map_err(invalid("tls.certificate"))?;
        }
        Ok(config)
    }

    /// Parses and checks `text` (`origin` names it in errors).
    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let config: Self = teleop_runtime::parse_toml(text, origin)?;
        config.check(origin)?;
        Ok(config)
    }

    fn check(&self, file: &str) -> Result<(), ConfigError> {
        let invalid = |field: &str, reason: String| ConfigError::Invalid {
            file: file.to_string(),
            field: field.to_string(),
            reason,
        };
        for (field, name) in [
            ("station", &self.station),
            ("peer", &self.peer),
            ("session", &self.session),
        ] {
            if !valid_name(name) {
                return Err(invalid(
                    field,
                    format!("{name:?}: use 1 to 32 of a-z, 0-9, '_' and '-'"),
                ));
            }
        }
        if self.station == self.peer {
            return Err(invalid("peer", "is this station itself".into()));
        }
        if self.listen.is_empty() && self.connect.is_empty() {
            return Err(invalid(
                "listen/connect",
                "neither is set: give the peer's endpoint under `connect`, or listen".into(),
            ));
        }
        match (&self.tls, self.insecure) {
            (None, false) => {
                return Err(invalid(
                    "tls",
                    "missing: give [tls] ca, certificate and key (`teleop certs` makes them), \
                     or set insecure = true for plain TCP"
                        .into(),
                ))
            }
            (Some(_), true) => {
                return Err(invalid(
                    "insecure",
                    "true with a [tls] section: choose one".into(),
                ))
            }
            _ => {}
        }
        let scheme = if self.insecure { "tcp/" } else { "quic/" };
        for endpoint in self.listen.iter().chain(&self.connect) {
            if !endpoint.starts_with(scheme) {
                return Err(invalid(
                    "listen/connect",
                    if self.insecure {
                        format!("{endpoint:?}: with insecure = true only tcp/ endpoints")
                    } else {
                        format!(
                            "{endpoint:?}: only quic/ endpoints (TLS 1.3 with mutual \
                             certificates; zenoh's tls/ transport is unsound under two-way \
                             traffic, eclipse-zenoh/zenoh#2557); plain tcp/ needs insecure = true"
                        )
                    },
                ));
            }
        }
        for endpoint in &self.listen {
            if listens_everywhere(endpoint) {
                return Err(invalid(
                    "listen",
                    format!(
                        "{endpoint:?} listens on every interface: give this station's own \
                         address (the one its certificate names and the peer connects to)"
                    ),
                ));
            }
        }
        for (field, ms) in [
            ("heartbeat_ms", self.heartbeat_ms),
            ("link_timeout_ms", self.link_timeout_ms),
            ("lease_ms", self.lease_ms),
        ] {
            if ms > MAX_MS {
                return Err(invalid(field, too_large(ms)));
            }
        }
        if self.heartbeat_ms == 0 || self.link_timeout_ms < 2 * self.heartbeat_ms {
            return Err(invalid(
                "link_timeout_ms",
                format!(
                    "{} must be at least two heartbeats ({} ms each, > 0)",
                    self.link_timeout_ms, self.heartbeat_ms
                ),
            ));
        }
        let mut seen = Vec::new();
        for (i, topic) in self.topic.iter().enumerate() {
            let field = format!("topic[{i}].name");
            if teleop_msgs::visit_topic(&topic.name, crate::Size).is_none() {
                let known: Vec<&str> = teleop_msgs::topics().iter().map(|t| t.name).collect();
                return Err(invalid(
                    &field,
                    format!(
                        "{:?} is not a contract topic ({})",
                        topic.name,
                        known.join(", ")
                    ),
                ));
            }
            // The e-stop crosses stations by the `estop` key (each station's own latch); as a
            // bridged topic a remote station's doorbell or acknowledgements would pose as this
            // station's nodes (`teleop estop` counts the nodes that acknowledge).
            if [
                <teleop_msgs::EStop as teleop_msgs::Message>::TOPIC,
                <teleop_msgs::EStopAck as teleop_msgs::Message>::TOPIC,
            ]
            .contains(&topic.name.as_str())
            {
                return Err(invalid(
                    &field,
                    format!(
                        "{:?} is not bridged: the e-stop crosses stations by the `estop` key",
                        topic.name
                    ),
                ));
            }
            if seen.contains(&topic.name.as_str()) {
                return Err(invalid(&field, format!("{:?} is listed twice", topic.name)));
            }
            if let Some(ms) = topic.max_age_ms.filter(|ms| *ms > MAX_MS) {
                return Err(invalid(&format!("topic[{i}].max_age_ms"), too_large(ms)));
            }
            if topic.max_age_ms.is_some() && topic.direction == Direction::Out {
                return Err(invalid(
                    &format!("topic[{i}].max_age_ms"),
                    "only for direction = \"in\"".into(),
                ));
            }
            seen.push(&topic.name);
        }
        Ok(())
    }

    /// The zenoh configuration: peer mode, no scouting, the explicit endpoints, the lease, and
    /// QUIC with mutual TLS (zenoh's `transport/link/tls` settings apply to QUIC), or plain TCP
    /// when `insecure`.
    pub fn zenoh(&self) -> Result<zenoh::Config, String> {
        let mut config = zenoh::Config::default();
        let mut set = |key: &str, value: serde_json::Value| {
            config
                .insert_json5(key, &value.to_string())
                .map_err(|e| format!("zenoh setting {key} = {value}: {e}"))
        };
        use serde_json::json;
        set("mode", json!("peer"))?;
        set("scouting/multicast/enabled", json!(false))?;
        set("scouting/gossip/enabled", json!(false))?;
        set("listen/endpoints", json!(self.listen))?;
        set("connect/endpoints", json!(self.connect))?;
        set(
            "connect/retry",
            json!({"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}),
        )?;
        set("transport/link/tx/lease", json!(self.lease_ms))?;
        set("transport/link/tx/keep_alive", json!(4))?;
        set(
            "transport/link/protocols",
            json!([if self.insecure { "tcp" } else { "quic" }]),
        )?;
        // zenoh's default is 1 GiB (DEFAULT_CONFIG.json5, transport.link.rx.max_message_size):
        // no frame of ours is near this bound; larger messages are dropped by zenoh.
        set(
            "transport/link/rx/max_message_size",
            json!(crate::frame::MAX_FRAME_LEN),
        )?;
        if self.tls.is_some() {
            set("access_control", self.access_control())?;
        }
        if let Some(tls) = &self.tls {
            let path = |p: &Path| json!(p.display().to_string());
            set("transport/link/tls/root_ca_certificate", path(&tls.ca))?;
            set(
                "transport/link/tls/listen_certificate",
                path(&tls.certificate),
            )?;
            set("transport/link/tls/listen_private_key", path(&tls.key))?;
            set(
                "transport/link/tls/connect_certificate",
                path(&tls.certificate),
            )?;
            set("transport/link/tls/connect_private_key", path(&tls.key))?;
            set("transport/link/tls/enable_mtls", json!(true))?;
            set(
                "transport/link/tls/verify_name_on_connect",
                json!(tls.verify_name),
            )?;
        }
        Ok(config)
    }

    /// zenoh's access control binding the link to the peer's certificate: only a link whose
    /// certificate's common name is the peer station's (`teleop certs` writes the station's name
    /// there) may put on the peer's keys and subscribe to this station's; only such a link is
    /// sent this station's samples and subscriptions. Everything else is denied, in zenoh, per
    /// link (zenoh 1.10 `src/net/routing/interceptor/access_control.rs`: subjects by
    /// `cert_common_names`, from the QUIC link's peer certificate, `zenoh-link-commons`
    /// `quic/utils.rs` `get_cert_common_name`).
    pub fn access_control(&self) -> serde_json::Value {
        use serde_json::json;
        let keys = |station: &str| json!([format!("teleop/{}/{station}/**", self.session)]);
        let rule = |id: &str, flow: &str, message: &str, station: &str| {
            json!({
                "id": id,
                "permission": "allow",
                "flows": [flow],
                "messages": [message],
                "key_exprs": keys(station),
            })
        };
        json!({
            "enabled": true,
            "default_permission": "deny",
            "rules": [
                rule("peer-puts", "ingress", "put", &self.peer),
                rule("peer-subscribes", "ingress", "declare_subscriber", &self.station),
                rule("puts-to-peer", "egress", "put", &self.station),
                rule("subscribes-at-peer", "egress", "declare_subscriber", &self.peer),
            ],
            "subjects": [{
                "id": "peer",
                "cert_common_names": [self.peer],
                "link_protocols": ["quic"],
            }],
            "policies": [{
                "rules": ["peer-puts", "peer-subscribes", "puts-to-peer", "subscribes-at-peer"],
                "subjects": ["peer"],
            }],
        })
    }

    /// Every file the configuration names that does not exist (certificates), with its field.
    pub fn missing_files(&self) -> Vec<(&'static str, PathBuf)> {
        let Some(tls) = &self.tls else {
            return Vec::new();
        };
        [
            ("tls.ca", &tls.ca),
            ("tls.certificate", &tls.certificate),
            ("tls.key", &tls.key),
        ]
        .into_iter()
        .filter(|(_, p)| !p.is_file())
        .map(|(f, p)| (f, p.clone()))
        .collect()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    const GOOD: &str = r#"
station = "operator"
peer = "robot"
session = "lab"
connect = ["quic/192.0.2.2:7447"]
[tls]
ca = "certs/ca.pem"
certificate = "certs/operator.pem"
key = "certs/operator.key"
[[topic]]
name = "hand/command"
direction = "out"
[[topic]]
name = "hand/state"
direction = "in"
max_age_ms = 100
"#;

    fn refusal(patch: impl Fn(&str) -> String) -> String {
        BridgeConfig::parse(&patch(GOOD), "bridge.toml")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn a_good_file_and_its_zenoh_configuration() {
        let config = BridgeConfig::parse(GOOD, "bridge.toml").unwrap();
        assert_eq!(config.topic.len(), 2);
        assert_eq!(config.clock, ClockMode::Estimate);
        // Every key exists in zenoh's configuration (insert_json5 refuses unknown ones).
        config.zenoh().unwrap();
    }

    #[test]
    fn refusals_name_file_and_field() {
        let e = refusal(|t| t.replace("\"robot\"", "\"Robot!\""));
        assert!(e.starts_with("bridge.toml: peer: \"Robot!\""), "{e}");
        let e = refusal(|t| t.replace("quic/192", "tcp/192"));
        assert!(
            e.contains("listen/connect") && e.contains("insecure = true"),
            "{e}"
        );
        let e = refusal(|t| t.replace("[tls]", "insecure = true\n[tls]"));
        assert!(e.contains("insecure: true with a [tls]"), "{e}");
        let e = refusal(|t| t.split("[tls]").next().unwrap().to_string());
        assert!(e.contains("tls: missing"), "{e}");
        let e = refusal(|t| t.replace("hand/state", "hand/stat"));
        assert!(
            e.contains("topic[1].name: \"hand/stat\" is not a contract topic"),
            "{e}"
        );
        let e = refusal(|t| t.replace("hand/state", "hand/command"));
        assert!(e.contains("listed twice"), "{e}");
        for estop in ["estop", "estop/ack"] {
            let e = refusal(|t| t.replace("\"hand/state\"", &format!("{estop:?}")));
            assert!(
                e.contains(&format!(
                    "topic[1].name: {estop:?} is not bridged: the e-stop crosses stations"
                )),
                "{e}"
            );
        }
        let e = refusal(|t| format!("{t}\nspeed = 3\n"));
        assert!(e.contains("unknown field `speed`"), "{e}");
        let e = refusal(|t| t.replace("connect = [\"quic/192.0.2.2:7447\"]", ""));
        assert!(e.contains("neither is set"), "{e}");
    }

    /// [`GOOD`] over plain TCP without `[tls]`, `insecure = true`.
    fn insecure_text() -> String {
        GOOD.replace("quic/192", "tcp/192")
            .split("[tls]")
            .next()
            .unwrap()
            .to_string()
            + "insecure = true\n"
    }

    #[test]
    fn insecure_is_plain_tcp_only() {
        let config = BridgeConfig::parse(&insecure_text(), "bridge.toml").unwrap();
        assert!(config.insecure && config.tls.is_none());
        assert!(config.missing_files().is_empty());
        config.zenoh().unwrap();
    }

    #[test]
    fn millisecond_values_that_overflow_the_nanosecond_clock_are_refused() {
        // i64::MAX is TOML's largest integer; in nanoseconds it overflows u64.
        let huge = "9223372036854775807";
        let e = refusal(|t| format!("link_timeout_ms = {huge}\n{t}"));
        assert!(
            e.contains("link_timeout_ms") && e.contains("too large"),
            "{e}"
        );
        let e = refusal(|t| t.replace("max_age_ms = 100", &format!("max_age_ms = {huge}")));
        assert!(
            e.contains("topic[1].max_age_ms") && e.contains("too large"),
            "{e}"
        );
        let e = refusal(|t| format!("lease_ms = {huge}\n{t}"));
        assert!(e.contains("lease_ms") && e.contains("too large"), "{e}");
    }

    #[test]
    fn a_station_listens_on_its_own_address_not_every_interface() {
        for any in ["quic/0.0.0.0:7447", "quic/[::]:7447"] {
            let e =
                refusal(|t| t.replace("connect = ", &format!("listen = [\"{any}\"]\nconnect = ")));
            assert!(
                e.contains("listen") && e.contains("every interface"),
                "{any}: {e}"
            );
        }
        let config = BridgeConfig::parse(
            &GOOD.replace(
                "connect = ",
                "listen = [\"quic/192.0.2.1:7447\"]\nconnect = ",
            ),
            "bridge.toml",
        )
        .unwrap();
        assert_eq!(config.listen, ["quic/192.0.2.1:7447"]);
        // As shipped, the robot's bridge listens on its own address.
        let shipped = include_str!("../../../../config/bridge/robot.toml");
        let robot = BridgeConfig::parse(shipped, "config/bridge/robot.toml").unwrap();
        assert_eq!(robot.listen, ["quic/192.0.2.2:7447"]);
    }

    #[test]
    fn key_files_readable_by_others_are_refused_naming_the_fix() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("bridge.toml");
        std::fs::write(&file, GOOD).unwrap();
        std::fs::create_dir(dir.path().join("certs")).unwrap();
        let key = dir.path().join("certs/operator.key");
        std::fs::write(&key, "not read").unwrap();
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = BridgeConfig::load(&file).unwrap_err().to_string();
        assert!(
            e.contains("tls.key") && e.contains("readable by others") && e.contains("chmod 600"),
            "{e}"
        );
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
        BridgeConfig::load(&file).unwrap();
    }

    #[test]
    fn zenoh_bounds_messages_and_binds_the_peer_to_its_certificate() {
        let config = BridgeConfig::parse(GOOD, "bridge.toml").unwrap();
        let zenoh = config.zenoh().unwrap();
        let get = |key: &str| zenoh.get_json(key).unwrap();
        let max: u64 = get("transport/link/rx/max_message_size").parse().unwrap();
        assert!(max <= 65_536, "zenoh takes messages up to {max} bytes");
        // Access control on: only a link whose certificate names the peer may put on the
        // peer's keys, and only it receives this station's.
        assert_eq!(get("access_control/enabled"), "true");
        assert_eq!(get("access_control/default_permission"), "\"deny\"");
        let subjects = get("access_control/subjects");
        assert!(
            subjects.contains("\"cert_common_names\":[\"robot\"]"),
            "{subjects}"
        );
        let rules = get("access_control/rules");
        assert!(
            rules.contains("teleop/lab/robot/**") && rules.contains("teleop/lab/operator/**"),
            "{rules}"
        );
        // Plain TCP has no certificate: no access control to bind it to.
        let insecure = BridgeConfig::parse(&insecure_text(), "bridge.toml")
            .unwrap()
            .zenoh()
            .unwrap();
        assert_eq!(
            insecure.get_json("access_control/enabled").unwrap(),
            "false"
        );
    }

    /// A CA named as every CA of `teleop certs` was before (issue 20), and its key.
    fn old_style_ca() -> (rcgen::Issuer<'static, rcgen::KeyPair>, String) {
        let key = rcgen::KeyPair::generate().unwrap();
        let mut params = rcgen::CertificateParams::new(Vec::<String>::new()).unwrap();
        params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Constrained(0));
        params
            .distinguished_name
            .push(rcgen::DnType::CommonName, "teleop session CA");
        let pem = params.self_signed(&key).unwrap().pem();
        (rcgen::Issuer::new(params, key), pem)
    }

    #[test]
    fn a_certificate_from_another_ca_is_named_as_such() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("certs")).unwrap();
        let write = |name: &str, text: &str| std::fs::write(dir.path().join(name), text).unwrap();
        // Two sessions' CAs of one name: the certificate of the first, the CA of the second.
        let ((first, _), (_, second_pem)) = (old_style_ca(), old_style_ca());
        let key = rcgen::KeyPair::generate().unwrap();
        let mut params = rcgen::CertificateParams::new(vec!["operator".to_string()]).unwrap();
        params
            .distinguished_name
            .push(rcgen::DnType::CommonName, "operator");
        let cert = params.signed_by(&key, &first).unwrap();
        write("certs/operator.pem", &cert.pem());
        write("certs/operator.key", &key.serialize_pem());
        let key_path = dir.path().join("certs/operator.key");
        std::fs::set_permissions(&key_path, std::fs::Permissions::from_mode(0o600)).unwrap();
        write("certs/ca.pem", &second_pem);
        write("bridge.toml", GOOD);
        let e = BridgeConfig::load(&dir.path().join("bridge.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("tls.certificate: certificate from another CA"),
            "{e}"
        );
        // Its own CA: accepted.
        write("certs/ca.pem", &cert_ca_pem(&first));
        BridgeConfig::load(&dir.path().join("bridge.toml")).unwrap();
    }

    fn cert_ca_pem(issuer: &rcgen::Issuer<'static, rcgen::KeyPair>) -> String {
        // The CA's self-signed certificate again, from its parameters and key.
        let mut params = rcgen::CertificateParams::new(Vec::<String>::new()).unwrap();
        params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Constrained(0));
        params
            .distinguished_name
            .push(rcgen::DnType::CommonName, "teleop session CA");
        params.self_signed(issuer.key()).unwrap().pem()
    }
}
