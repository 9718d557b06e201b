//! `teleop calibrate`: records the operator's calibration profile from the live `glove/state`
//! topic: four poses with on-screen prompts, each averaged over a capture window.

use std::io::{BufRead, Write};
use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use teleop_msgs::GloveState;
use teleop_retargeting::Calibration;
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

pub fn run(
    ipc: &IpcSettings,
    out: &Path,
    yes: bool,
    settle: Duration,
    capture: Duration,
) -> anyhow::Result<ExitCode> {
    let runtime = NodeRuntime::new("teleop-calibrate", ipc)?;
    let glove = runtime.subscriber::<GloveState>()?;
    // Make sure the glove is there before asking anything of the operator.
    wait_for_glove(&glove, Duration::from_secs(3))?;
    println!("Calibrating the operator profile: {} poses.", POSES.len());
    let mut captured = [[0u16; 6]; 4];
    let stdin = std::io::stdin();
    for (i, (name, prompt)) in POSES.iter().enumerate() {
        println!("\nPose {}/{} ({name}): {prompt}", i + 1, POSES.len());
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
            if stdin.lock().read_line(&mut line)? == 0 {
                anyhow::bail!("standard input closed; use --yes for a timed calibration");
            }
        }
        captured[i] = average(&glove, capture)?;
        println!("  captured {name}: {:?}", captured[i]);
    }
    let [open, fist, thumb_in, thumb_out] = captured;
    let calibration = Calibration::from_poses(open, fist, thumb_in, thumb_out)
        .map_err(|e| anyhow::anyhow!("the captured poses do not make a usable profile: {e}"))?;
    std::fs::write(out, calibration.to_toml_string())
        .map_err(|e| anyhow::anyhow!("{}: cannot write profile: {e}", out.display()))?;
    println!("\nWrote {}", out.display());
    Ok(ExitCode::SUCCESS)
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

/// Mean raw position per channel over `window` of live samples.
fn average(glove: &Subscriber<GloveState>, window: Duration) -> anyhow::Result<[u16; 6]> {
    glove.drain(|_| {});
    let mut sum = [0u64; 6];
    let mut n = 0u64;
    let start = Instant::now();
    while start.elapsed() < window || n == 0 {
        glove.drain(|s| {
            if s.link_up != 0 {
                for (acc, &v) in sum.iter_mut().zip(&s.raw_position) {
                    *acc += u64::from(v);
                }
                n += 1;
            }
        });
        if start.elapsed() > window + Duration::from_secs(2) {
            anyhow::bail!("the glove stopped sending samples during the capture");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(sum.map(|s| (s / n) as u16))
}
