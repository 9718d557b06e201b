//! Command-line value parsers shared by `teleop` and the device service commands it dispatches
//! to, so that every time argument is checked one way and refused naming the argument (clap
//! adds the name) instead of panicking.

use std::time::Duration;

/// The longest time an argument may name: ten years (so that adding it to a clock reading can
/// never overflow).
pub const MAX_SECONDS: f64 = 10.0 * 365.25 * 86_400.0;

/// A time argument in seconds: a finite number from 0 to [`MAX_SECONDS`].
pub fn parse_seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| "not a number of seconds".to_string())?;
    if !(0.0..=MAX_SECONDS).contains(&v) {
        return Err(format!(
            "expected seconds from 0 to {MAX_SECONDS:.0} (ten years)"
        ));
    }
    Duration::try_from_secs_f64(v).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_are_finite_and_bounded() {
        assert_eq!(parse_seconds(" 1.5 "), Ok(Duration::from_millis(1500)));
        assert_eq!(parse_seconds("0"), Ok(Duration::ZERO));
        for bad in ["-1", "nan", "inf", "1e300", "", "two"] {
            assert!(parse_seconds(bad).is_err(), "{bad:?} accepted");
        }
    }
}
