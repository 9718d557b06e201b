//! `teleop glove ...` against the simulated glove running as its own process
//! (`teleop-sim-glove` on a pseudo-terminal), including its run-time control socket.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use teleop_e2e::bin;
use teleop_e2e::rig::Rig;

/// The simulated glove as its own process on a pseudo-terminal in a fresh rig (with `args`),
/// and its device's path.
fn start(args: &[&str]) -> (Rig, String) {
    let mut rig = Rig::new();
    let link = rig.path("glove").display().to_string();
    let args = [&["--link", &link], args].concat();
    rig.start_sim("sim-glove", bin("teleop-sim-glove"), &args, "device: ");
    (rig, link)
}

fn glove(rig: &Rig, link: &str, args: &[&str]) -> (bool, String) {
    rig.sandbox
        .cli(&[&["glove", "--port", link, "--timeout-ms", "100"], args].concat())
}

#[test]
fn glove_commands_configure_the_simulated_device() {
    let (rig, link) = start(&["--script", "hold"]);
    let (ok, info) = glove(&rig, &link, &["info"]);
    assert!(ok, "{info}");
    assert!(
        info.contains("id            1") && info.contains("baud rate     115200"),
        "{info}"
    );
    assert!(info.contains("error little  ok"), "{info}");

    let (ok, out) = glove(&rig, &link, &["set-id", "5"]);
    assert!(ok && out.contains("id is now 5"), "{out}");
    let (ok, out) = glove(&rig, &link, &["info"]);
    assert!(
        !ok && out.contains("no answer"),
        "the old id gets no answer: {out}"
    );
    let (ok, out) = glove(&rig, &link, &["--id", "5", "set-baud", "57600"]);
    assert!(ok && out.contains("baud rate is now 57600"), "{out}");
    let (ok, out) = glove(&rig, &link, &["--id", "5", "--baud", "57600", "info"]);
    assert!(
        ok && out.contains("id            5") && out.contains("57600"),
        "{out}"
    );
    let (ok, out) = glove(&rig, &link, &["--id", "5", "--baud", "57600", "save"]);
    assert!(ok, "{out}");
    let (ok, out) = glove(
        &rig,
        &link,
        &["--id", "5", "--baud", "57600", "clear-errors"],
    );
    assert!(ok && out.contains("errors cleared"), "{out}");
    let (ok, out) = glove(
        &rig,
        &link,
        &["--id", "5", "--baud", "57600", "factory-reset"],
    );
    assert!(
        !ok && out.contains("nothing changed"),
        "asks first, no answer = no: {out}"
    );
    let (ok, out) = glove(
        &rig,
        &link,
        &["--id", "5", "--baud", "57600", "factory-reset", "--yes"],
    );
    assert!(ok, "{out}");
    let (ok, out) = glove(&rig, &link, &["info"]);
    assert!(
        ok && out.contains("id            1"),
        "back to id 1 at 115200: {out}"
    );

    let (ok, out) = glove(&rig, &link, &["set-baud", "9600"]);
    assert!(!ok && out.contains("115200, 57600 and 19200"), "{out}");
}

#[test]
fn control_socket_injects_faults_and_unplugs_at_run_time() {
    let (rig, link) = start(&["--script", "hold"]);
    assert!(glove(&rig, &link, &["info"]).0);
    assert!(rig.sandbox.control("glove.ctl", "drop 1").starts_with("ok"));
    let (ok, out) = glove(&rig, &link, &["info"]);
    assert!(!ok && out.contains("no answer within"), "{out}");
    assert!(rig.sandbox.control("glove.ctl", "clear").starts_with("ok"));
    assert!(glove(&rig, &link, &["info"]).0);
    assert!(rig
        .sandbox
        .control("glove.ctl", "nonsense 1")
        .starts_with("error: unknown command"));
    assert!(rig
        .sandbox
        .control("glove.ctl", "unplug 1000")
        .starts_with("ok"));
    std::thread::sleep(Duration::from_millis(200));
    let (ok, out) = glove(&rig, &link, &["info"]);
    assert!(!ok, "unplugged: {out}");
    std::thread::sleep(Duration::from_millis(1200));
    let (ok, out) = glove(&rig, &link, &["info"]);
    assert!(ok, "plugged back in: {out}");
    assert!(rig
        .sandbox
        .control("glove.ctl", "stats")
        .contains(" unplugs=1"));
}

#[test]
fn glove_calibration_follows_the_manuals_steps() {
    let (rig, link) = start(&["--script", "hold"]);
    let (ok, out) = glove(&rig, &link, &["calibrate", "--yes"]);
    assert!(ok, "{out}");
    assert_eq!(out.matches("Step ").count(), 5, "{out}");
    assert!(out.contains("Calibration complete."), "{out}");
}
