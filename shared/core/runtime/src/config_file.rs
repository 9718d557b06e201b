//! Loading TOML configuration files with errors that name the file, line and field.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

/// A configuration file that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigFileError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not fit the expected fields (toml's message names
    /// the line, column and field).
    #[error("{origin}: {message}")]
    Parse {
        /// The file (or other origin) of the text.
        origin: String,
        /// toml's message.
        message: String,
    },
}

/// Reads and deserialises the TOML file at `path`.
pub fn load_toml<T: DeserializeOwned>(path: &Path) -> Result<T, ConfigFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigFileError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse_toml(&text, &path.display().to_string())
}

/// Deserialises TOML `text`; `origin` (usually the file path) prefixes error messages.
pub fn parse_toml<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, ConfigFileError> {
    toml::from_str(text).map_err(|e| ConfigFileError::Parse {
        origin: origin.to_string(),
        message: e.to_string().trim_end().to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Sample {
        rate_hz: u32,
    }

    #[test]
    fn errors_name_origin_line_and_field() {
        let err = parse_toml::<Sample>("\nrate_hz = \"fast\"\n", "node.toml").unwrap_err();
        let text = err.to_string();
        assert!(text.starts_with("node.toml: "), "{text}");
        assert!(text.contains("line 2"), "{text}");
        let err = parse_toml::<Sample>("rate_hz = 1\nrate = 2\n", "node.toml").unwrap_err();
        assert!(err.to_string().contains("unknown field `rate`"), "{err}");
        let err = load_toml::<Sample>(Path::new("/nonexistent/x.toml")).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("/nonexistent/x.toml: cannot read"),
            "{err}"
        );
    }
}

/// The longest timeout or period, in ms, a configuration file may give (a minute): anything
/// longer is a typo, and would wrap when turned into nanoseconds near `u64::MAX`.
pub const MAX_CONFIG_MS: u64 = 60_000;

/// Checks a duration field of a configuration file: `1..=MAX_CONFIG_MS` ms. The message names
/// the field, its value and the range.
pub fn check_ms(field: &str, value: u64) -> Result<(), String> {
    if (1..=MAX_CONFIG_MS).contains(&value) {
        Ok(())
    } else {
        Err(format!(
            "{field} = {value}: must be 1..={MAX_CONFIG_MS} ms (0 would never wait or never \
             time out; longer is not a timeout a session can use)"
        ))
    }
}

#[cfg(test)]
mod ms_tests {
    use super::*;

    #[test]
    fn durations_out_of_range_are_refused_by_name() {
        assert!(check_ms("tick_ms", 1).is_ok());
        assert!(check_ms("tick_ms", MAX_CONFIG_MS).is_ok());
        let zero = check_ms("tick_ms", 0).unwrap_err();
        assert!(
            zero.starts_with("tick_ms = 0: must be 1..=60000 ms"),
            "{zero}"
        );
        assert!(check_ms("hand_timeout_ms", u64::MAX)
            .unwrap_err()
            .contains("hand_timeout_ms = 18446744073709551615"));
    }
}
