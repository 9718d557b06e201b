//! `teleop revo2 ...` against the emulated Revo2 running as its own process
//! (`teleop-sim-revo2 --socket`), through ethercrab in PRE-OP.
#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

use teleop_e2e::{bin, Sandbox};

struct Sim(Child);

impl Drop for Sim {
    fn drop(&mut self) {
        // SAFETY: kill(2) of our own child.
        unsafe {
            libc::kill(self.0.id() as libc::pid_t, libc::SIGINT);
        }
        let _ = self.0.wait();
    }
}

fn start(sandbox: &Sandbox) -> (Sim, String) {
    let socket = sandbox.dir.path().join("revo2.sock").display().to_string();
    let mut child = Command::new(bin("teleop-sim-revo2"))
        .args(["--socket", &socket])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.starts_with("revo2: socket"), "{line}");
    (Sim(child), format!("sim:{socket}"))
}

fn revo2(sandbox: &Sandbox, transport: &str, args: &[&str]) -> (bool, String) {
    let out = sandbox
        .teleop()
        .args(["revo2", "--transport", transport])
        .args(args)
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
fn info_set_and_calibrate_on_the_emulated_revo2() {
    let sandbox = Sandbox::new();
    let (_sim, transport) = start(&sandbox);
    let (ok, info) = revo2(&sandbox, &transport, &["info"]);
    assert!(ok, "{info}");
    assert!(
        info.contains("vendor 0x00bc0000 product 0x00009252 revision 1"),
        "{info}"
    );
    assert!(info.contains("ctrl_wrist_fw_version      1.4.2"), "{info}");
    assert!(
        info.contains("wrist_sn                   RV2W24110000042"),
        "{info}"
    );
    assert!(info.contains("touch_vendor               1"), "{info}");

    let (ok, out) = revo2(&sandbox, &transport, &["set", "led_switch", "1"]);
    assert!(ok && out.contains("led_switch = 1"), "{out}");
    let (ok, out) = revo2(&sandbox, &transport, &["set", "index_pro_cur", "750"]);
    assert!(ok && out.contains("index_pro_cur = 750"), "{out}");
    let (_, info) = revo2(&sandbox, &transport, &["info"]);
    assert!(
        info.contains("index_pro_cur              750"),
        "persisted: {info}"
    );

    let (ok, out) = revo2(&sandbox, &transport, &["set", "unit_mode", "7"]);
    assert!(!ok && out.contains("unit_mode"), "{out}");
    let (ok, out) = revo2(
        &sandbox,
        &transport,
        &["set", "ctrl_wrist_fw_version", "9.9.9"],
    );
    assert!(
        !ok && out.to_lowercase().contains("read"),
        "read-only: {out}"
    );
    let (ok, out) = revo2(&sandbox, &transport, &["set", "ctrl_sn", "RV2C0001"]);
    assert!(
        !ok && out.contains("segmented"),
        "strings need a segmented download: {out}"
    );
    let (ok, out) = revo2(&sandbox, &transport, &["set", "no_such_thing", "1"]);
    assert!(!ok && out.contains("no_such_thing"), "{out}");

    let (ok, out) = revo2(&sandbox, &transport, &["calibrate", "--tactile"]);
    assert!(
        ok && out.contains("position calibration started") && out.contains("pinky started"),
        "{out}"
    );
}

#[test]
fn a_missing_device_is_a_clear_error() {
    let sandbox = Sandbox::new();
    let missing = format!("sim:{}", sandbox.dir.path().join("nothing.sock").display());
    let (ok, out) = revo2(&sandbox, &missing, &["info"]);
    assert!(
        !ok && out.contains("bus scan failed") && out.contains("nothing.sock"),
        "{out}"
    );
}
