//! The fault vocabulary: one command per line, a word and its arguments, parsed once.
//!
//! The common words mean the same on every simulator; times are milliseconds everywhere:
//!
//! | line | what |
//! |---|---|
//! | `unplug MS` | the device's cable (serial line, adapter, EtherCAT link) pulled for MS ms |
//! | `drop P` | each frame (or answer) the device would send is lost with probability P |
//! | `clear` | every probability back to 0 |
//! | `stats` | the counters, `ok key=value ...` |
//! | `object ball\|bar\|none` | the virtual object in the hand ([`crate::Object`]) |
//!
//! A device's own words ([`DeviceCommand`]) parse through the same [`Args`], so their errors
//! read alike. [`parse`] is total: any line gives a [`Command`] or a [`ParseError`].

use std::time::Duration;

use crate::object::Object;

/// Longest timed fault (`unplug`, and a device's own), ms: an hour.
pub const MAX_MS: u64 = 3_600_000;

/// A line that is not a command.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    /// Nothing but blanks.
    #[error("empty command: expected one of {expected}")]
    Empty {
        /// Every word this simulator takes.
        expected: String,
    },
    /// A word this simulator does not take.
    #[error("unknown command {word:?}: expected one of {expected}")]
    Unknown {
        /// The word.
        word: String,
        /// Every word this simulator takes.
        expected: String,
    },
    /// A known word with a missing, malformed or extra argument.
    #[error("{word}: expected {expected}, got {got:?}")]
    Argument {
        /// The word.
        word: String,
        /// What the word takes there.
        expected: String,
        /// What came instead (empty: nothing).
        got: String,
    },
}

/// The arguments after a command's word, taken one at a time.
#[derive(Debug, Clone)]
pub struct Args<'a> {
    word: &'a str,
    rest: std::iter::Peekable<std::str::SplitWhitespace<'a>>,
}

impl<'a> Args<'a> {
    /// The arguments of `word` in `rest`.
    pub fn new(word: &'a str, rest: &'a str) -> Self {
        Self {
            word,
            rest: rest.split_whitespace().peekable(),
        }
    }

    /// The error for `got` where `expected` belongs.
    pub fn error(&self, expected: &str, got: &str) -> ParseError {
        ParseError::Argument {
            word: self.word.to_string(),
            expected: expected.to_string(),
            got: got.to_string(),
        }
    }

    /// The next argument as it is.
    pub fn text(&mut self, expected: &str) -> Result<&'a str, ParseError> {
        self.rest.next().ok_or_else(|| self.error(expected, ""))
    }

    /// The next argument, if there is one (an optional argument).
    pub fn optional(&mut self) -> Option<&'a str> {
        self.rest.next()
    }

    /// The next argument parsed as `T` and accepted by `valid`; `expected` names it.
    pub fn value<T: std::str::FromStr>(
        &mut self,
        expected: &str,
        valid: impl Fn(&T) -> bool,
    ) -> Result<T, ParseError> {
        let text = self.text(expected)?;
        text.parse::<T>()
            .ok()
            .filter(|v| valid(v))
            .ok_or_else(|| self.error(expected, text))
    }

    /// A probability, 0..=1.
    pub fn probability(&mut self) -> Result<f64, ParseError> {
        self.value("PROBABILITY (0..1)", |p: &f64| (0.0..=1.0).contains(p))
    }

    /// A duration in whole milliseconds, at most `max_ms`.
    pub fn millis(&mut self, max_ms: u64) -> Result<Duration, ParseError> {
        self.value(&format!("MS (0..={max_ms})"), |ms: &u64| *ms <= max_ms)
            .map(Duration::from_millis)
    }

    /// One of `choices`.
    pub fn choice(&mut self, choices: &[&'static str]) -> Result<&'static str, ParseError> {
        let expected = choices.join("|");
        let text = self.text(&expected)?;
        choices
            .iter()
            .find(|c| **c == text)
            .copied()
            .ok_or_else(|| self.error(&expected, text))
    }

    /// Refuses anything left over.
    fn finish(mut self) -> Result<(), ParseError> {
        match self.rest.next() {
            None => Ok(()),
            Some(extra) => Err(self.error("nothing more", extra)),
        }
    }
}

/// A device's own words, parsed through [`Args`].
pub trait DeviceCommand: Sized {
    /// The device's words with their arguments, for the error naming an unknown word, e.g.
    /// `"late MS, state"`.
    const WORDS: &'static str;

    /// `None`: `word` is not one of this device's; else the command or what was wrong with its
    /// arguments (those left over are refused by [`parse`]).
    fn parse(word: &str, args: &mut Args<'_>) -> Option<Result<Self, ParseError>>;
}

/// The words every simulator takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Common {
    /// `unplug MS`: the cable pulled for a while, then plugged back in.
    Unplug(Duration),
    /// `drop P`: what the device sends is lost with this probability.
    Drop(f64),
    /// `clear`: every probability back to 0.
    Clear,
    /// `stats`: the counters.
    Stats,
    /// `object ball|bar|none`: the virtual object in the hand.
    Object(Option<Object>),
}

/// The common words with their arguments.
pub const COMMON_WORDS: &str = "unplug MS, drop P, clear, stats, object ball|bar|none";

/// One parsed line.
#[derive(Debug, Clone, PartialEq)]
pub enum Command<D> {
    /// A word every simulator takes.
    Common(Common),
    /// One of the device's own.
    Device(D),
}

/// Parses one line (surrounding blanks ignored) into a command of the common vocabulary or of
/// the device's `D`.
pub fn parse<D: DeviceCommand>(line: &str) -> Result<Command<D>, ParseError> {
    let line = line.trim();
    let expected = || format!("{COMMON_WORDS}, {}", D::WORDS);
    let (word, rest) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
    if word.is_empty() {
        return Err(ParseError::Empty {
            expected: expected(),
        });
    }
    let mut args = Args::new(word, rest);
    let command = match word {
        "unplug" => Command::Common(Common::Unplug(args.millis(MAX_MS)?)),
        "drop" => Command::Common(Common::Drop(args.probability()?)),
        "clear" => Command::Common(Common::Clear),
        "stats" => Command::Common(Common::Stats),
        "object" => {
            let name = args.choice(&["ball", "bar", "none"])?;
            Command::Common(Common::Object(Object::parse(name)))
        }
        _ => match D::parse(word, &mut args) {
            Some(command) => Command::Device(command?),
            None => {
                return Err(ParseError::Unknown {
                    word: word.to_string(),
                    expected: expected(),
                })
            }
        },
    };
    args.finish()?;
    Ok(command)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[derive(Debug, Clone, PartialEq)]
    enum Own {
        Late(Duration),
        Overheat(bool),
    }

    impl DeviceCommand for Own {
        const WORDS: &'static str = "late MS, overheat [off]";

        fn parse(word: &str, args: &mut Args<'_>) -> Option<Result<Self, ParseError>> {
            Some(match word {
                "late" => args.millis(10_000).map(Own::Late),
                "overheat" => match args.optional() {
                    None => Ok(Own::Overheat(true)),
                    Some("off") => Ok(Own::Overheat(false)),
                    Some(other) => Err(args.error("nothing or off", other)),
                },
                _ => return None,
            })
        }
    }

    #[test]
    fn common_and_device_words_parse() {
        let p = parse::<Own>;
        assert_eq!(
            p(" unplug 1500 "),
            Ok(Command::Common(Common::Unplug(Duration::from_millis(1500))))
        );
        assert_eq!(p("drop 0.25"), Ok(Command::Common(Common::Drop(0.25))));
        assert_eq!(p("clear"), Ok(Command::Common(Common::Clear)));
        assert_eq!(p("stats"), Ok(Command::Common(Common::Stats)));
        assert_eq!(
            p("object ball"),
            Ok(Command::Common(Common::Object(Some(Object::Ball))))
        );
        assert_eq!(p("object none"), Ok(Command::Common(Common::Object(None))));
        assert_eq!(
            p("late 200"),
            Ok(Command::Device(Own::Late(Duration::from_millis(200))))
        );
        assert_eq!(p("overheat off"), Ok(Command::Device(Own::Overheat(false))));
    }

    #[test]
    fn errors_name_the_word_and_what_was_expected() {
        let e = |line: &str| parse::<Own>(line).unwrap_err().to_string();
        assert_eq!(
            e("unplug 1.5"),
            "unplug: expected MS (0..=3600000), got \"1.5\""
        );
        assert_eq!(e("unplug"), "unplug: expected MS (0..=3600000), got \"\"");
        assert_eq!(e("drop 2"), "drop: expected PROBABILITY (0..1), got \"2\"");
        assert_eq!(e("stats now"), "stats: expected nothing more, got \"now\"");
        assert_eq!(
            e("late 10001"),
            "late: expected MS (0..=10000), got \"10001\""
        );
        assert_eq!(
            e("object cube"),
            "object: expected ball|bar|none, got \"cube\""
        );
        assert!(e("link-down 1")
            .starts_with("unknown command \"link-down\": expected one of unplug MS"));
        assert!(e("   ").starts_with("empty command"));
        assert!(e("overheat on").contains("expected nothing or off"));
    }

    #[test]
    fn any_line_parses_or_is_refused_without_a_panic() {
        for line in [
            "",
            "\0",
            "unplug -1",
            "unplug 99999999999999999999",
            "drop NaN",
            "drop inf",
            "object",
            "ø ø ø",
            "late\t5",
            "drop 0.5 0.5",
        ] {
            let _ = parse::<Own>(line);
        }
        assert_eq!(
            parse::<Own>("late\t5"),
            Ok(Command::Device(Own::Late(Duration::from_millis(5))))
        );
        assert!(parse::<Own>("drop NaN").is_err());
    }
}
