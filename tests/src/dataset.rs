//! The independent check of a LeRobot dataset (`tests/python/check_lerobot.py`, pyarrow only):
//! run by the export test and by any test that exports a session.

use std::path::Path;
use std::process::Command;

use crate::Sandbox;

/// What the check found: its JSON report (`ok`, totals, and the frame asked for as `frame`,
/// one key per column).
pub type Report = serde_json::Value;

/// Checks the dataset at `dir` with the Python reader and returns its report, with the frame of
/// global index `frame` when given. Panics naming the failure when the dataset does not read
/// right (with numpy, the statistics by lerobot's method included). Without python3 or pyarrow it prints why and returns `None`, unless
/// `TELEOP_REQUIRE_CHECKS` is set (CI, which installs pyarrow): then that fails too.
pub fn check_lerobot(dir: &Path, frame: Option<u64>) -> Option<Report> {
    let script = Sandbox::repo().join("tests/python/check_lerobot.py");
    let mut cmd = Command::new("python3");
    cmd.arg(&script).arg(dir);
    if let Some(frame) = frame {
        cmd.args(["--frame", &frame.to_string()]);
    }
    let out = match cmd.output() {
        Ok(out) => out,
        Err(e) => {
            crate::netns::skip(&format!(
                "python3 does not run ({e}): the LeRobot check needs it"
            ));
            return None;
        }
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.code() == Some(2) {
        crate::netns::skip(&format!(
            "the LeRobot check needs pyarrow (pip install -r .ci/requirements.txt): {stderr}"
        ));
        return None;
    }
    assert!(
        out.status.success(),
        "the LeRobot check of {} failed: {stderr}",
        dir.display()
    );
    let report: Report = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "the LeRobot check printed no JSON ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    });
    assert_eq!(report["ok"], true, "{report}");
    if report["stats_checked_by_lerobots_method"] != true {
        // numpy comes with CI's Python packages (rerun-sdk, torch).
        crate::netns::skip(
            "numpy is not importable: the statistics were not checked by lerobot's method",
        );
    }
    Some(report)
}

/// Loads the dataset at `dir` with lerobot's own `LeRobotDataset`
/// (`tests/python/load_lerobot.py`) and returns its report (episode and frame counts, each
/// episode's first frame). lerobot pulls in torch, so it is optional everywhere, CI included:
/// without it this prints why and returns `None`. The Python that has it is
/// `TELEOP_LEROBOT_PYTHON` (e.g. a virtual environment's), else `python3`.
pub fn load_with_lerobot(dir: &Path) -> Option<Report> {
    let python = std::env::var("TELEOP_LEROBOT_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Sandbox::repo().join("tests/python/load_lerobot.py");
    let out = match Command::new(&python).arg(&script).arg(dir).output() {
        Ok(out) => out,
        Err(e) => {
            eprintln!("skipped loading with lerobot: {python} does not run ({e})");
            return None;
        }
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.code() == Some(2) {
        eprintln!(
            "skipped loading with lerobot (optional; set TELEOP_LEROBOT_PYTHON to a Python \
             that has it): {stderr}"
        );
        return None;
    }
    assert!(
        out.status.success(),
        "lerobot could not load {}: {stderr}",
        dir.display()
    );
    let report: Report = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "load_lerobot.py printed no JSON ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    });
    eprintln!("lerobot loaded {}: {report}", dir.display());
    Some(report)
}
