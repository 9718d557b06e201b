//! Topic namespaces: one pipeline can run several sides (a left and a right hand) whose topics
//! live under a namespace, `left/glove/state`, `right/hand/command`, ... Without a namespace a
//! topic keeps its plain contract name (`glove/state`), so a single-side session, its iceoryx2
//! services and its recordings are exactly what they were before namespaces existed.
//!
//! - [`Namespace`]: a checked namespace name: one or more non-empty path segments of
//!   `[a-z0-9_-]`, joined by `/`, no leading or trailing slash, at most [`MAX_LEN`] bytes.
//! - [`qualified`]: a topic's name in a namespace (the iceoryx2 service name is
//!   `teleop/<qualified name>`, a recording's channel is the qualified name).
//! - [`split`]: the reverse, from a qualified name to its namespace and contract topic.
//!
//! The split is unambiguous because no topic of the contract is a `/`-suffix of another (a unit
//! test checks the registry), so a plain topic name never reads as a namespaced one.
//!
//! Owns: namespace names and topic qualification. Must not depend on: iceoryx2, I/O, anything
//! but the message contract's topic registry.

use core::fmt;
use core::str::FromStr;

use teleop_msgs::TopicInfo;

/// Longest namespace name in bytes (it is part of node names, which `NodeHealth` stores in 32
/// bytes, and of iceoryx2 service names).
pub const MAX_LEN: usize = 16;

/// Why a namespace name was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NamespaceError {
    /// The name is empty.
    #[error("a namespace name cannot be empty")]
    Empty,
    /// The name is longer than [`MAX_LEN`].
    #[error("namespace {name:?} is {len} bytes long; at most {MAX_LEN} are allowed")]
    TooLong {
        /// The name.
        name: String,
        /// Its length.
        len: usize,
    },
    /// A leading, trailing or doubled `/`.
    #[error("namespace {name:?} has an empty path segment (a leading, trailing or doubled '/')")]
    EmptySegment {
        /// The name.
        name: String,
    },
    /// A character outside `[a-z0-9_-]` and `/`.
    #[error("namespace {name:?} contains {ch:?}; use lower-case letters, digits, '_', '-' and '/' between segments")]
    Character {
        /// The name.
        name: String,
        /// The first refused character.
        ch: char,
    },
}

/// A checked namespace name such as `left` or `cell2/left`.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Namespace(String);

impl Namespace {
    /// Checks `name`.
    pub fn new(name: &str) -> Result<Self, NamespaceError> {
        if name.is_empty() {
            return Err(NamespaceError::Empty);
        }
        if let Some(ch) = name
            .chars()
            .find(|&c| !(c.is_ascii_lowercase() || c.is_ascii_digit() || "_-/".contains(c)))
        {
            return Err(NamespaceError::Character {
                name: name.to_string(),
                ch,
            });
        }
        if name.split('/').any(str::is_empty) {
            return Err(NamespaceError::EmptySegment {
                name: name.to_string(),
            });
        }
        if name.len() > MAX_LEN {
            return Err(NamespaceError::TooLong {
                name: name.to_string(),
                len: name.len(),
            });
        }
        Ok(Self(name.to_string()))
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl FromStr for Namespace {
    type Err = NamespaceError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::new(s)
    }
}

impl fmt::Display for Namespace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// `name` in `namespace`: `left/<name>`, or `name` itself without a namespace. Used for topics
/// and for node names.
pub fn qualified(namespace: Option<&Namespace>, name: &str) -> String {
    match namespace {
        Some(ns) => format!("{ns}/{name}"),
        None => name.to_string(),
    }
}

/// The namespace and contract topic of a qualified topic name: `glove/state` is the topic
/// without a namespace, `left/glove/state` the same topic in `left`. `None` when the name does
/// not end in a contract topic or its namespace part is not a valid namespace.
pub fn split(name: &str) -> Option<(Option<Namespace>, &'static TopicInfo)> {
    let topics = teleop_msgs::topics();
    if let Some(t) = topics.iter().find(|t| t.name == name) {
        return Some((None, t));
    }
    topics.iter().find_map(|t| {
        let ns = name.strip_suffix(t.name)?.strip_suffix('/')?;
        Some((Some(Namespace::new(ns).ok()?), t))
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn valid_names() {
        for ok in ["left", "right", "l", "cell_2", "a-b", "cell2/left", "0"] {
            assert_eq!(Namespace::new(ok).unwrap().as_str(), ok);
        }
        assert_eq!("left".parse::<Namespace>().unwrap().to_string(), "left");
    }

    #[test]
    fn refused_names_say_why() {
        assert_eq!(Namespace::new(""), Err(NamespaceError::Empty));
        for bad in ["/left", "left/", "a//b", "/"] {
            assert!(
                matches!(
                    Namespace::new(bad),
                    Err(NamespaceError::EmptySegment { .. })
                ),
                "{bad}"
            );
        }
        for (bad, ch) in [("Left", 'L'), ("le ft", ' '), ("left.x", '.'), ("ü", 'ü')] {
            assert_eq!(
                Namespace::new(bad),
                Err(NamespaceError::Character {
                    name: bad.into(),
                    ch
                })
            );
        }
        let long = "a".repeat(MAX_LEN + 1);
        assert!(matches!(
            Namespace::new(&long),
            Err(NamespaceError::TooLong { len, .. }) if len == MAX_LEN + 1
        ));
        assert!(Namespace::new(&"a".repeat(MAX_LEN)).is_ok());
        let e = Namespace::new("Left").unwrap_err().to_string();
        assert!(e.contains("\"Left\"") && e.contains("'L'"), "{e}");
    }

    #[test]
    fn qualified_and_split_are_inverse() {
        let left = Namespace::new("left").unwrap();
        let nested = Namespace::new("cell2/right").unwrap();
        for t in teleop_msgs::topics() {
            assert_eq!(qualified(None, t.name), t.name);
            let (ns, topic) = split(t.name).unwrap();
            assert_eq!((ns, topic.name), (None, t.name));
            for n in [&left, &nested] {
                let name = qualified(Some(n), t.name);
                assert_eq!(name, format!("{n}/{}", t.name));
                let (ns, topic) = split(&name).unwrap();
                assert_eq!((ns.as_ref(), topic.name), (Some(n), t.name));
            }
        }
    }

    #[test]
    fn split_refuses_other_names() {
        for bad in [
            "",
            "glove",
            "left/glove",
            "Left/glove/state",
            "/glove/state",
            "left//glove/state",
            "glove/state/extra",
            "leftglove/state",
        ] {
            assert!(split(bad).is_none(), "{bad}");
        }
    }

    /// A plain topic name must never also read as another topic in a namespace, or `split` (and
    /// the service names) would be ambiguous. Holds for the registry as it is; a new topic that
    /// breaks it fails here.
    #[test]
    fn no_topic_is_a_suffix_of_another() {
        for a in teleop_msgs::topics() {
            for b in teleop_msgs::topics() {
                assert!(
                    !a.name.ends_with(&format!("/{}", b.name)),
                    "topic {} ends with /{}",
                    a.name,
                    b.name
                );
            }
        }
    }
}
