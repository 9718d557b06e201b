//! `teleop calibrate`: records the operator's calibration profile from the live `glove/state`
//! topic: four poses for the glove's ranges, each averaged over a capture window, then (unless
//! `--no-pinch`) four pinches, thumb to each finger, that fit the operator's thumb in the hand
//! model (the profile's `[operator]` table).

use std::io::{BufRead, Write};
use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use teleop_msgs::GloveState;
use teleop_retargeting::{Calibration, GLOVE_CHANNEL_NAMES};
use teleop_runtime::{IpcSettings, NodeRuntime, Subscriber};

const POSES: [(&str, &str); 4] = [
    (
        "open hand",
        "Open your hand fully, fingers straight, thumb out, and hold still.",
    ),
    (
        "fist",
        "Make a fist: all fingers and the thumb fully bent, and hold still.",
    ),
    (
        "thumb in",
        "Fingers straight; rotate the thumb as far in across the palm as you can.",
    ),
    (
        "thumb out",
        "Fingers straight; rotate the thumb as far out, away from the palm, as you can.",
    ),
];

/// The fingers the thumb pinches, in the order asked, as glove channels
/// ([`GLOVE_CHANNEL_NAMES`] index: index, middle, ring, little).
const PINCHES: [usize; 4] = [3, 2, 1, 0];

/// A pinch gap the fit leaves above this (mm) means the model cannot close that pinch: most
/// likely the thumb did not touch the finger while it was recorded.
const UNCLOSED_PINCH_MM: f32 = 3.0;

pub fn run(
    ipc: &IpcSettings,
    out: &Path,
    yes: bool,
    pinch: bool,
    settle: Duration,
    capture: Duration,
) -> anyhow::Result<ExitCode> {
    let runtime = NodeRuntime::new("teleop-calibrate", ipc)?;
    let glove = runtime.subscriber::<GloveState>()?;
    // Make sure the glove is there before asking anything of the operator.
    wait_for_glove(&glove, Duration::from_secs(3))?;
    let steps = POSES.len() + if pinch { PINCHES.len() } else { 0 };
    println!("Calibrating the operator profile: {steps} poses.");
    let mut captured = [[0u16; 6]; 4];
    for (i, (name, prompt)) in POSES.iter().enumerate() {
        println!("\nPose {}/{steps} ({name}): {prompt}", i + 1);
        wait_for_operator(yes, settle)?;
        captured[i] = mean(&record(&glove, capture)?);
        println!("  captured {name}: {:?}", captured[i]);
    }
    let [open, fist, thumb_in, thumb_out] = captured;
    let mut calibration = Calibration::from_poses(open, fist, thumb_in, thumb_out)
        .map_err(|e| anyhow::anyhow!("the captured poses do not make a usable profile: {e}"))?;
    if pinch {
        let mut pinches = Vec::with_capacity(PINCHES.len());
        for (i, &channel) in PINCHES.iter().enumerate() {
            let finger = GLOVE_CHANNEL_NAMES[channel];
            println!(
                "\nPose {}/{steps} (pinch thumb to {finger}): touch the pad of your thumb to the \
                 pad of your {finger} finger, the other fingers relaxed, and hold still.",
                POSES.len() + i + 1
            );
            wait_for_operator(yes, settle)?;
            // The middle, not the mean: a pinch held by hand wavers, and a twitch at the start
            // of the window must not pull the pose.
            let raw = median(&record(&glove, capture)?);
            println!("  captured pinch thumb to {finger}: {raw:?}");
            pinches.push((channel, raw));
        }
        let (fitted, fit) = calibration
            .with_pinches(&pinches)
            .map_err(|e| anyhow::anyhow!("the pinches do not fit the operator's hand: {e}"))?;
        println!(
            "\nFitted the operator's thumb to the pinches ({} iterations); thumb-finger pad gap:",
            fit.iterations
        );
        for (gap, &(channel, _)) in fit.gaps.iter().zip(&pinches) {
            let finger = GLOVE_CHANNEL_NAMES[channel];
            println!(
                "  thumb to {finger}: {:.1} mm before, {:.1} mm after",
                gap.before_mm, gap.after_mm
            );
            if gap.after_mm.abs() > UNCLOSED_PINCH_MM {
                println!(
                    "  warning: the hand model cannot close the pinch to {finger}; did the thumb \
                     touch it? (run again to repeat it)"
                );
            }
        }
        calibration = fitted;
    }
    std::fs::write(out, calibration.to_toml_string())
        .map_err(|e| anyhow::anyhow!("{}: cannot write profile: {e}", out.display()))?;
    println!("\nWrote {}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// Waits for the operator to be in the pose: `settle` counted down with `--yes`, otherwise
/// until Enter.
fn wait_for_operator(yes: bool, settle: Duration) -> anyhow::Result<()> {
    if yes {
        let mut left = settle;
        while !left.is_zero() {
            print!("  {:.0}...", left.as_secs_f64().ceil());
            std::io::stdout().flush()?;
            let step = left.min(Duration::from_secs(1));
            std::thread::sleep(step);
            left -= step;
        }
        println!();
    } else {
        print!("  Press Enter when you are in the pose.");
        std::io::stdout().flush()?;
        let mut line = String::new();
        if std::io::stdin().lock().read_line(&mut line)? == 0 {
            anyhow::bail!("standard input closed; use --yes for a timed calibration");
        }
    }
    Ok(())
}

fn wait_for_glove(glove: &Subscriber<GloveState>, timeout: Duration) -> anyhow::Result<()> {
    let start = Instant::now();
    while start.elapsed() < timeout {
        glove.drain(|_| {});
        if glove.is_fresh(Instant::now(), Duration::from_millis(500))
            && glove.latest().is_some_and(|s| s.link_up != 0)
        {
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    anyhow::bail!(
        "no live glove on glove/state within {} s: is the glove node running (teleop nodes)?",
        timeout.as_secs()
    )
}

/// The raw positions of the live samples over `window` (at least one).
fn record(glove: &Subscriber<GloveState>, window: Duration) -> anyhow::Result<Vec<[u16; 6]>> {
    glove.drain(|_| {});
    let mut samples = Vec::new();
    let start = Instant::now();
    while start.elapsed() < window || samples.is_empty() {
        glove.drain(|s| {
            if s.link_up != 0 {
                samples.push(s.raw_position);
            }
        });
        if start.elapsed() > window + Duration::from_secs(2) {
            anyhow::bail!("the glove stopped sending samples during the capture");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(samples)
}

/// Mean per channel (rounded down); zeros for no samples.
fn mean(samples: &[[u16; 6]]) -> [u16; 6] {
    let n = samples.len().max(1) as u64;
    std::array::from_fn(|ch| (samples.iter().map(|s| u64::from(s[ch])).sum::<u64>() / n) as u16)
}

/// Median per channel (the lower middle of an even count); zeros for no samples.
fn median(samples: &[[u16; 6]]) -> [u16; 6] {
    std::array::from_fn(|ch| {
        let mut values: Vec<u16> = samples.iter().map(|s| s[ch]).collect();
        values.sort_unstable();
        values
            .get(values.len().saturating_sub(1) / 2)
            .copied()
            .unwrap_or(0)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_median_per_channel() {
        let samples = [
            [10, 0, 1000, 5, 7, 1],
            [20, 0, 1000, 6, 7, 2],
            [90, 0, 1000, 7, 7, 3],
        ];
        assert_eq!(mean(&samples), [40, 0, 1000, 6, 7, 2]);
        // A twitch (90) moves the mean, not the median.
        assert_eq!(median(&samples), [20, 0, 1000, 6, 7, 2]);
        assert_eq!(median(&samples[..2]), [10, 0, 1000, 5, 7, 1]);
        assert_eq!(mean(&[]), [0; 6]);
        assert_eq!(median(&[]), [0; 6]);
    }

    #[test]
    fn pinches_name_the_long_fingers() {
        let names = PINCHES.map(|ch| GLOVE_CHANNEL_NAMES[ch]);
        assert_eq!(names, ["index", "middle", "ring", "little"]);
    }
}
