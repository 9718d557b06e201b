//! A process whose stderr pipe nobody reads keeps cycling: log lines are dropped and counted
//! instead of blocking the loop that logs.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

const CHILD: &str = "TELEOP_TEST_STALLED_STDERR_CHILD";
/// Cycles the child runs, each logging a 200-byte line: 4 MB, far beyond a pipe's 64 KiB.
const CYCLES: u64 = 20_000;

#[test]
fn a_loop_that_logs_keeps_cycling_when_stderr_is_not_read() {
    if std::env::var_os(CHILD).is_some() {
        // The child: a loop that logs every cycle.
        teleop_runtime::init_logging();
        let padding = "x".repeat(200);
        for cycle in 0..CYCLES {
            tracing::info!(cycle, "{padding}");
        }
        println!(
            "CYCLED {CYCLES} DROPPED {}",
            teleop_runtime::dropped_log_lines()
        );
        return;
    }
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "a_loop_that_logs_keeps_cycling_when_stderr_is_not_read",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD, "1")
        .env("TELEOP_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped()) // never read
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            // The test harness prints its own text before ours on the same line.
            if let Some(at) = line.find("CYCLED") {
                let _ = tx.send(line[at..].to_string());
            }
        }
    });
    // A generous bound that only a blocked loop misses (it is not a speed requirement).
    let line = rx.recv_timeout(Duration::from_secs(120));
    let _ = child.kill();
    let _ = child.wait();
    let line = line.expect("the loop stopped: logging blocked on the unread stderr pipe");
    let dropped: u64 = line.rsplit(' ').next().unwrap().parse().unwrap();
    assert!(line.starts_with(&format!("CYCLED {CYCLES} ")), "{line}");
    assert!(
        dropped > 0,
        "{line}: nothing was dropped, yet the pipe was never read"
    );
}
