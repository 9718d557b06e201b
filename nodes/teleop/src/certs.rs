//! `teleop certs`: a session's certificate authority and one certificate per station, for the
//! bridge's mutual TLS, for a lab that has no PKI of its own.
//!
//! Writes into the output folder: `ca.pem` (the CA's certificate, copied to every station),
//! `ca.key` (its key: keep it off the stations, it signs new stations), and for each station
//! `<name>.pem` and `<name>.key` (ECDSA P-256, PKCS#8). Each station certificate names the
//! station and the addresses given for it (the peer checks the address it connects to against
//! them) and may act as TLS server and client; its common name is the station's name, which the
//! bridge binds its link to. Each CA has a name of its own (`teleop session CA <key hash>`), so a
//! certificate from another session's CA is refused as from an unknown issuer. An existing
//! `ca.pem`/`ca.key` pair in the folder signs the new stations (adding a station later); nothing
//! is overwritten.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};

/// One station to certify: `NAME` or `NAME=ADDRESS[,ADDRESS...]` (IP addresses or DNS names).
#[derive(Debug, Clone)]
pub struct StationSpec {
    name: String,
    addresses: Vec<String>,
}

impl std::str::FromStr for StationSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, addresses) = s.split_once('=').unwrap_or((s, ""));
        let valid = !name.is_empty()
            && name.len() <= 32
            && name
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_' || b == b'-');
        if !valid {
            return Err(format!(
                "station name {name:?}: use 1 to 32 of a-z, 0-9, '_' and '-'"
            ));
        }
        let addresses: Vec<String> = addresses
            .split(',')
            .filter(|a| !a.is_empty())
            .map(str::to_string)
            .collect();
        for address in &addresses {
            let hostname = address.len() <= 253
                && address.split('.').all(|label| {
                    !label.is_empty()
                        && label.len() <= 63
                        && label
                            .bytes()
                            .all(|b| b.is_ascii_alphanumeric() || b == b'-')
                });
            if address.parse::<std::net::IpAddr>().is_err() && !hostname {
                return Err(format!(
                    "station {name}: {address:?} is neither an IP address nor a host name"
                ));
            }
        }
        Ok(Self {
            name: name.to_string(),
            addresses,
        })
    }
}

/// Makes (or extends) the session's certificates in `out`.
pub fn run(out: &Path, stations: &[StationSpec], days: u32) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(!stations.is_empty(), "name at least one --station");
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let ca_pem = out.join("ca.pem");
    let ca_key = out.join("ca.key");
    let (not_before, not_after) = validity(days);
    let issuer = if ca_pem.exists() && ca_key.exists() {
        let key = KeyPair::from_pem(&read(&ca_key)?)
            .with_context(|| format!("{}: not a private key", ca_key.display()))?;
        let issuer = Issuer::from_ca_cert_pem(&read(&ca_pem)?, key)
            .with_context(|| format!("{}: not a CA certificate", ca_pem.display()))?;
        println!("signing with the existing CA {}", ca_pem.display());
        issuer
    } else {
        anyhow::ensure!(
            !ca_pem.exists() && !ca_key.exists(),
            "{} has only one of ca.pem and ca.key",
            out.display()
        );
        let key = KeyPair::generate()?;
        let mut params = CertificateParams::new(Vec::<String>::new())?;
        params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
        params
            .distinguished_name
            .push(DnType::CommonName, ca_name(&key));
        params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
        params.not_before = not_before;
        params.not_after = not_after;
        let cert = params.self_signed(&key)?;
        write_new(&ca_pem, &cert.pem(), false)?;
        write_new(&ca_key, &key.serialize_pem(), true)?;
        println!(
            "made the CA: {} (its key {})",
            ca_pem.display(),
            ca_key.display()
        );
        Issuer::new(params, key)
    };
    for station in stations {
        let (pem, key_path) = paths(out, &station.name);
        anyhow::ensure!(
            !pem.exists() && !key_path.exists(),
            "{} already has a certificate for {}; remove it first to make a new one",
            out.display(),
            station.name
        );
        let key = KeyPair::generate()?;
        let mut names = vec![station.name.clone()];
        names.extend(station.addresses.iter().cloned());
        let mut params = CertificateParams::new(names)
            .with_context(|| format!("station {}: bad address", station.name))?;
        params
            .distinguished_name
            .push(DnType::CommonName, station.name.as_str());
        params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        params.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        params.not_before = not_before;
        params.not_after = not_after;
        let cert = params.signed_by(&key, &issuer)?;
        write_new(&pem, &cert.pem(), false)?;
        write_new(&key_path, &key.serialize_pem(), true)?;
        println!(
            "station {}: {} and {} (names: {})",
            station.name,
            pem.display(),
            key_path.display(),
            std::iter::once(station.name.as_str())
                .chain(station.addresses.iter().map(String::as_str))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    println!(
        "copy ca.pem and the station's .pem/.key to each station; keep ca.key elsewhere; valid {days} days"
    );
    Ok(ExitCode::SUCCESS)
}

/// The CA's own name, `teleop session CA <16 hex digits of its key>`: two sessions' CAs differ
/// by name, so a certificate from another session's CA is refused as from an unknown issuer (TLS
/// finds no CA of that name), not as a bad signature (a CA of the same name that did not sign
/// it).
fn ca_name(key: &KeyPair) -> String {
    // FNV-1a, 64 bit, over the public key.
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for b in key.public_key_raw() {
        hash ^= u64::from(*b);
        hash = hash.wrapping_mul(0x0100_0000_01b3);
    }
    format!("teleop session CA {hash:016x}")
}

fn paths(out: &Path, station: &str) -> (PathBuf, PathBuf) {
    (
        out.join(format!("{station}.pem")),
        out.join(format!("{station}.key")),
    )
}

fn read(path: &Path) -> anyhow::Result<String> {
    std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))
}

/// Writes a file that must not exist yet; keys readable by the owner only.
fn write_new(path: &Path, text: &str, secret: bool) -> anyhow::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(if secret { 0o600 } else { 0o644 })
        .open(path)
        .with_context(|| format!("creating {}", path.display()))?;
    file.write_all(text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// From yesterday (clocks of two machines may differ) for `days` days.
fn validity(days: u32) -> (time::OffsetDateTime, time::OffsetDateTime) {
    let now = time::OffsetDateTime::now_utc();
    (
        now - time::Duration::days(1),
        now + time::Duration::days(i64::from(days)),
    )
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn station_specs() {
        let s: StationSpec = "robot=192.0.2.2,robot.lab".parse().unwrap();
        assert_eq!(s.name, "robot");
        assert_eq!(s.addresses, ["192.0.2.2", "robot.lab"]);
        let s: StationSpec = "operator".parse().unwrap();
        assert!(s.addresses.is_empty());
        assert!("Robot=1.2.3.4".parse::<StationSpec>().is_err());
        assert!("=1.2.3.4".parse::<StationSpec>().is_err());
        assert!("robot=not_an_ip!".parse::<StationSpec>().is_err());
        assert!("robot=fe80::1,robot-1.lab.example"
            .parse::<StationSpec>()
            .is_ok());
    }

    #[test]
    fn makes_a_ca_and_stations_then_adds_one_and_never_overwrites() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("certs");
        let specs: Vec<StationSpec> = ["operator=192.0.2.1", "robot=192.0.2.2"]
            .iter()
            .map(|s| s.parse().unwrap())
            .collect();
        run(&out, &specs, 30).unwrap();
        for f in [
            "ca.pem",
            "ca.key",
            "operator.pem",
            "operator.key",
            "robot.pem",
            "robot.key",
        ] {
            assert!(out.join(f).is_file(), "{f}");
        }
        let ca = std::fs::read_to_string(out.join("ca.pem")).unwrap();
        assert!(ca.starts_with("-----BEGIN CERTIFICATE-----"));
        let key = std::fs::read_to_string(out.join("robot.key")).unwrap();
        assert!(key.starts_with("-----BEGIN PRIVATE KEY-----"));
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(out.join("robot.key"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600);
        // A third station signed by the same CA; the CA is kept.
        run(&out, &["viewer".parse().unwrap()], 30).unwrap();
        assert_eq!(std::fs::read_to_string(out.join("ca.pem")).unwrap(), ca);
        assert!(out.join("viewer.pem").is_file());
        let e = run(&out, &["robot".parse().unwrap()], 30).unwrap_err();
        assert!(
            e.to_string()
                .contains("already has a certificate for robot"),
            "{e}"
        );
    }

    /// The common name of the CA in `dir/ca.pem`: the DER's UTF8String (tag 12, one length
    /// byte) that starts with "teleop session CA".
    fn ca_common_name(dir: &Path) -> String {
        let pem = std::fs::read_to_string(dir.join("ca.pem")).unwrap();
        let text: String = pem.lines().filter(|l| !l.starts_with("-----")).collect();
        let value = |c: u8| match c {
            b'A'..=b'Z' => u32::from(c - b'A'),
            b'a'..=b'z' => u32::from(c - b'a') + 26,
            b'0'..=b'9' => u32::from(c - b'0') + 52,
            b'+' => 62,
            _ => 63,
        };
        let mut der = Vec::new();
        for chunk in text.trim_end_matches('=').as_bytes().chunks(4) {
            let n = chunk
                .iter()
                .enumerate()
                .fold(0u32, |n, (i, c)| n | value(*c) << (18 - 6 * i));
            der.extend_from_slice(&n.to_be_bytes()[1..chunk.len()]);
        }
        let at = der
            .windows(17)
            .position(|w| w == b"teleop session CA")
            .unwrap();
        assert_eq!(der[at - 2], 12, "a UTF8String");
        let len = usize::from(der[at - 1]);
        String::from_utf8(der[at..at + len].to_vec()).unwrap()
    }

    #[test]
    fn each_session_ca_has_a_name_of_its_own() {
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        for dir in [&a, &b] {
            run(dir.path(), &["robot".parse().unwrap()], 30).unwrap();
        }
        let (a, b) = (ca_common_name(a.path()), ca_common_name(b.path()));
        assert_ne!(a, b, "two sessions' CAs have one name");
        assert!(a.len() > "teleop session CA ".len(), "{a}");
    }
}
