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
    /// clock) are not published here, and counted.
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
            if seen.contains(&topic.name.as_str()) {
                return Err(invalid(&field, format!("{:?} is listed twice", topic.name)));
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
        let e = refusal(|t| format!("{t}\nspeed = 3\n"));
        assert!(e.contains("unknown field `speed`"), "{e}");
        let e = refusal(|t| t.replace("connect = [\"quic/192.0.2.2:7447\"]", ""));
        assert!(e.contains("neither is set"), "{e}");
    }

    #[test]
    fn insecure_is_plain_tcp_only() {
        let text = GOOD
            .replace("quic/192", "tcp/192")
            .split("[tls]")
            .next()
            .unwrap()
            .to_string()
            + "insecure = true\n";
        let config = BridgeConfig::parse(&text, "bridge.toml").unwrap();
        assert!(config.insecure && config.tls.is_none());
        assert!(config.missing_files().is_empty());
        config.zenoh().unwrap();
    }
}
