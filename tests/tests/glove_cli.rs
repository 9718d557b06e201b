//! `teleop glove ...` against the simulated glove running as its own process
//! (`teleop-sim-glove` on a pseudo-terminal), including its run-time control socket.
#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use teleop_e2e::{bin, Sandbox};

struct Sim {
    child: Child,
    link: String,
    control: String,
}

impl Sim {
    fn start(sandbox: &Sandbox, args: &[&str]) -> Self {
        let link = sandbox.dir.path().join("glove").display().to_string();
        let mut child = Command::new(bin("teleop-sim-glove"))
            .args(["--link", &link])
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.starts_with("device: "), "{line}");
        Self {
            child,
            control: format!("{link}.ctl"),
            link,
        }
    }

    fn control(&self, command: &str) -> String {
        let mut s = UnixStream::connect(&self.control).unwrap();
        writeln!(s, "{command}").unwrap();
        s.shutdown(std::net::Shutdown::Write).unwrap();
        let mut reply = String::new();
        BufReader::new(s).read_line(&mut reply).unwrap();
        reply
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        // SAFETY: kill(2) of our own child.
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, libc::SIGINT);
        }
        let _ = self.child.wait();
    }
}

fn glove(sandbox: &Sandbox, sim: &Sim, args: &[&str]) -> (bool, String) {
    let out = sandbox
        .teleop()
        .args(["glove", "--port", &sim.link, "--timeout-ms", "100"])
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

#[test]
fn glove_commands_configure_the_simulated_device() {
    let sandbox = Sandbox::new();
    let sim = Sim::start(&sandbox, &["--script", "hold"]);
    let (ok, info) = glove(&sandbox, &sim, &["info"]);
    assert!(ok, "{info}");
    assert!(
        info.contains("id            1") && info.contains("baud rate     115200"),
        "{info}"
    );
    assert!(info.contains("error little  ok"), "{info}");

    let (ok, out) = glove(&sandbox, &sim, &["set-id", "5"]);
    assert!(ok && out.contains("id is now 5"), "{out}");
    let (ok, out) = glove(&sandbox, &sim, &["info"]);
    assert!(
        !ok && out.contains("no answer"),
        "the old id gets no answer: {out}"
    );
    let (ok, out) = glove(&sandbox, &sim, &["--id", "5", "set-baud", "57600"]);
    assert!(ok && out.contains("baud rate is now 57600"), "{out}");
    let (ok, out) = glove(&sandbox, &sim, &["--id", "5", "--baud", "57600", "info"]);
    assert!(
        ok && out.contains("id            5") && out.contains("57600"),
        "{out}"
    );
    let (ok, out) = glove(&sandbox, &sim, &["--id", "5", "--baud", "57600", "save"]);
    assert!(ok, "{out}");
    let (ok, out) = glove(
        &sandbox,
        &sim,
        &["--id", "5", "--baud", "57600", "clear-errors"],
    );
    assert!(ok && out.contains("errors cleared"), "{out}");
    let (ok, out) = glove(
        &sandbox,
        &sim,
        &["--id", "5", "--baud", "57600", "factory-reset"],
    );
    assert!(
        !ok && out.contains("nothing changed"),
        "asks first, no answer = no: {out}"
    );
    let (ok, out) = glove(
        &sandbox,
        &sim,
        &["--id", "5", "--baud", "57600", "factory-reset", "--yes"],
    );
    assert!(ok, "{out}");
    let (ok, out) = glove(&sandbox, &sim, &["info"]);
    assert!(
        ok && out.contains("id            1"),
        "back to id 1 at 115200: {out}"
    );

    let (ok, out) = glove(&sandbox, &sim, &["set-baud", "9600"]);
    assert!(!ok && out.contains("115200, 57600 and 19200"), "{out}");
}

#[test]
fn control_socket_injects_faults_and_unplugs_at_run_time() {
    let sandbox = Sandbox::new();
    let sim = Sim::start(&sandbox, &["--script", "hold"]);
    assert!(glove(&sandbox, &sim, &["info"]).0);
    assert!(sim.control("fault drop=1").starts_with("ok"));
    let (ok, out) = glove(&sandbox, &sim, &["info"]);
    assert!(!ok && out.contains("no answer within"), "{out}");
    assert!(sim.control("clear").starts_with("ok"));
    assert!(glove(&sandbox, &sim, &["info"]).0);
    assert!(sim
        .control("fault nonsense=1")
        .starts_with("error: unknown fault"));
    assert!(sim.control("unplug 1.0").starts_with("ok"));
    std::thread::sleep(Duration::from_millis(200));
    let (ok, out) = glove(&sandbox, &sim, &["info"]);
    assert!(!ok, "unplugged: {out}");
    std::thread::sleep(Duration::from_millis(1200));
    let (ok, out) = glove(&sandbox, &sim, &["info"]);
    assert!(ok, "plugged back in: {out}");
    assert!(sim.control("stats").contains("unplugs: 1"));
}

#[test]
fn glove_calibration_follows_the_manuals_steps() {
    let sandbox = Sandbox::new();
    let sim = Sim::start(&sandbox, &["--script", "hold"]);
    let (ok, out) = glove(&sandbox, &sim, &["calibrate", "--yes"]);
    assert!(ok, "{out}");
    assert_eq!(out.matches("Step ").count(), 5, "{out}");
    assert!(out.contains("Calibration complete."), "{out}");
}
