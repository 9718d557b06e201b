//! What a simulator's control socket drives, and the one answer format: each line gets one
//! line back, `ok` (with what was done or the answer) or `error: ...` (what was wrong, named
//! by the word). `stats` answers `ok key=value ...`, the same shape on every simulator.

use std::fmt::{Debug, Display};
use std::time::Duration;

use crate::command::{parse, Command, Common, DeviceCommand};
use crate::object::Object;

/// A simulator as its control socket sees it. Each method says what it did (`Ok`, shown after
/// `ok `) or why it could not (`Err`, shown after `error: `).
pub trait Simulator: Send + Sync + 'static {
    /// The device's own words.
    type Command: DeviceCommand;

    /// `unplug MS`: the cable pulled for `pause`, then plugged back in.
    fn unplug(&self, pause: Duration) -> Result<String, String>;

    /// `drop P`: what the device sends is lost with probability `p`.
    fn set_drop(&self, p: f64) -> Result<String, String>;

    /// `clear`: every fault probability back to 0.
    fn clear(&self) -> Result<String, String>;

    /// `stats`: the counters.
    fn stats(&self) -> Stats;

    /// `object ball|bar|none`: the object in the hand (by default: this simulator holds none).
    fn set_object(&self, object: Option<Object>) -> Result<String, String> {
        let _ = object;
        Err("object: this simulator holds no object".into())
    }

    /// One of the device's own commands.
    fn command(&self, command: Self::Command) -> Result<String, String>;
}

/// The answer to one control line.
pub fn answer<S: Simulator + ?Sized>(sim: &S, line: &str) -> String {
    let done = match parse::<S::Command>(line) {
        Err(e) => return format!("error: {e}"),
        Ok(Command::Common(Common::Unplug(pause))) => sim.unplug(pause),
        Ok(Command::Common(Common::Drop(p))) => sim.set_drop(p),
        Ok(Command::Common(Common::Clear)) => sim.clear(),
        Ok(Command::Common(Common::Stats)) => Ok(sim.stats().to_string()),
        Ok(Command::Common(Common::Object(o))) => sim.set_object(o),
        Ok(Command::Device(command)) => sim.command(command),
    };
    match done {
        Ok(text) if text.is_empty() => "ok".into(),
        Ok(text) => {
            tracing::debug!("control: {line}: {text}");
            format!("ok {text}")
        }
        Err(e) => format!("error: {e}"),
    }
}

/// A `stats` answer: `key=value` words in order.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Stats(Vec<(String, String)>);

impl Stats {
    /// No fields yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `key=value` (blanks in the value become `_`, so that the words stay words).
    pub fn field(mut self, key: &str, value: impl Display) -> Self {
        let value = value.to_string().replace(char::is_whitespace, "_");
        self.0.push((key.to_string(), value));
        self
    }

    /// Adds every field of a flat counter struct (its `Debug` text, `Name { a: 1, b: 2 }`), each
    /// key prefixed with `prefix` (e.g. `esc_`).
    pub fn counters(mut self, prefix: &str, counters: &impl Debug) -> Self {
        let text = format!("{counters:?}");
        let inner = match (text.find('{'), text.rfind('}')) {
            (Some(open), Some(close)) if open < close => &text[open + 1..close],
            _ => return self.field(prefix.trim_end_matches('_'), text),
        };
        for part in inner.split(", ") {
            if let Some((key, value)) = part.split_once(':') {
                self = self.field(&format!("{prefix}{}", key.trim()), value.trim());
            }
        }
        self
    }

    /// The value of `key`, if there is one.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.value(key).map(String::as_str)
    }

    fn value(&self, key: &str) -> Option<&String> {
        self.0.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }

    /// The values of a list field (`key=v1,v2,...`, e.g. one per joint); `Err` says which
    /// field is missing or which value does not parse.
    pub fn values<T: std::str::FromStr>(&self, key: &str) -> Result<Vec<T>, String> {
        let text = self
            .get(key)
            .ok_or_else(|| format!("no {key} in the stats {self}"))?;
        text.split(',')
            .map(|v| v.parse().map_err(|_| format!("{key}: {v:?} in {text:?}")))
            .collect()
    }

    /// A `stats` answer read back (`ok key=value ...`, as [`answer`] gives it, e.g. a test's
    /// from a simulator's control socket); `Err` says what it is not.
    pub fn parse(answer: &str) -> Result<Self, String> {
        let words = match answer.strip_prefix("ok") {
            Some("") => "",
            Some(rest) if rest.starts_with(' ') => rest,
            _ => return Err(format!("not an `ok` answer: {answer:?}")),
        };
        words
            .split_whitespace()
            .map(|w| {
                w.split_once('=')
                    .map(|(k, v)| (k.to_string(), v.to_string()))
                    .ok_or_else(|| format!("{w:?} is no key=value word in {answer:?}"))
            })
            .collect::<Result<_, _>>()
            .map(Self)
    }
}

/// `stats["key"]`: the value of `key`.
///
/// # Panics
/// When there is no `key` (as a map's index does).
impl std::ops::Index<&str> for Stats {
    type Output = String;

    fn index(&self, key: &str) -> &String {
        self.value(key)
            .unwrap_or_else(|| panic!("no {key} in the stats {self}"))
    }
}

impl Display for Stats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, (key, value)) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{key}={value}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{Args, ParseError};
    use std::sync::Mutex;

    /// Read through its `Debug` text only.
    #[allow(dead_code)]
    #[derive(Debug, Default)]
    struct Counters {
        frames: u64,
        dropped: u64,
    }

    struct Toy {
        drop: Mutex<f64>,
    }

    struct Ping;

    impl DeviceCommand for Ping {
        const WORDS: &'static str = "ping";

        fn parse(word: &str, _: &mut Args<'_>) -> Option<Result<Self, ParseError>> {
            (word == "ping").then_some(Ok(Ping))
        }
    }

    impl Simulator for Toy {
        type Command = Ping;

        fn unplug(&self, pause: Duration) -> Result<String, String> {
            Err(format!(
                "unplug: no cable to pull for {} ms",
                pause.as_millis()
            ))
        }

        fn set_drop(&self, p: f64) -> Result<String, String> {
            *crate::lock(&self.drop) = p;
            Ok(format!("drop {p}"))
        }

        fn clear(&self) -> Result<String, String> {
            self.set_drop(0.0).map(|_| String::new())
        }

        fn stats(&self) -> Stats {
            Stats::new()
                .field("drop", *crate::lock(&self.drop))
                .counters(
                    "",
                    &Counters {
                        frames: 3,
                        dropped: 1,
                    },
                )
        }

        fn command(&self, _: Ping) -> Result<String, String> {
            Ok("pong".into())
        }
    }

    #[test]
    fn every_line_gets_ok_or_error_and_stats_are_key_value_words() {
        let toy = Toy {
            drop: Mutex::new(0.0),
        };
        assert_eq!(answer(&toy, "drop 0.5"), "ok drop 0.5");
        assert_eq!(answer(&toy, "stats"), "ok drop=0.5 frames=3 dropped=1");
        assert_eq!(answer(&toy, "clear"), "ok");
        assert_eq!(answer(&toy, "ping"), "ok pong");
        assert_eq!(
            answer(&toy, "unplug 20"),
            "error: unplug: no cable to pull for 20 ms"
        );
        assert_eq!(
            answer(&toy, "object ball"),
            "error: object: this simulator holds no object"
        );
        assert!(answer(&toy, "pong").starts_with("error: unknown command \"pong\""));
        let stats = toy.stats();
        assert_eq!(stats.get("dropped"), Some("1"));
        assert_eq!(
            Stats::new().field("state", "SAFE OP").to_string(),
            "state=SAFE_OP"
        );
    }

    #[test]
    fn a_stats_answer_reads_back_as_it_was_written() {
        let toy = Toy {
            drop: Mutex::new(0.25),
        };
        let read = Stats::parse(&answer(&toy, "stats")).expect("an ok answer");
        assert_eq!(read, toy.stats());
        assert_eq!(read["frames"], "3");
        assert_eq!(Stats::parse("ok"), Ok(Stats::new()));
        for bad in [
            "error: stats: expected nothing more",
            "okay x=1",
            "ok x=1 y",
        ] {
            assert!(Stats::parse(bad).is_err(), "{bad}");
        }
        let lists = Stats::parse("ok pwm=0,120,-3 joint=0.5,x").expect("an ok answer");
        assert_eq!(lists.values::<i32>("pwm"), Ok(vec![0, 120, -3]));
        assert!(lists.values::<f64>("joint").is_err(), "x is no number");
        assert!(lists.values::<f64>("missing").is_err());
        let missing = std::panic::catch_unwind(|| read["missing"].clone());
        assert!(missing.is_err(), "no such key: a panic, as a map's index");
    }
}
