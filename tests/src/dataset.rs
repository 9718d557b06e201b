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
/// right. Without python3 or pyarrow it prints why and returns `None`, unless
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
    Some(report)
}
