//! The emulated Shadow Hand over a real link with an independent master: a veth pair
//! `ecm0`/`ecs0` in a network namespace of its own, `teleop-sim-shadow --interface ecs0` on a raw
//! socket at one end, and SOEM (through pysoem, `tests/soem_op.py`) at the other, which must
//! program the palm's sync managers itself (as the shipped driver does) to bring the bridge and
//! the palm to OP, then gets the palm's answers to SENSOR_DATA commands.
//!
//! Privileged: skipped with the reason printed unless it runs as root with `ip` and
//! `unshare(CLONE_NEWNET)` working and python3 with pysoem (under `TELEOP_REQUIRE_CHECKS`, as
//! `.ci/run` sets it as root, it fails instead). The emulator's binary must have been built
//! (`cargo build --workspace --bins`).
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Child;
use std::time::{Duration, Instant};

use teleop_e2e::netns::{die_with_parent, pysoem_missing, run_for, skip, stop, Netns};
use teleop_e2e::{bin, skip_unless_privileged};

/// The emulator serving on `ecs0` in `ns`, its output in `dir/sim.log`.
fn start_sim(ns: &Netns, dir: &Path) -> Child {
    let log = std::fs::File::create(dir.join("sim.log")).unwrap();
    let mut cmd = ns.command(bin("teleop-sim-shadow"));
    cmd.args(["--interface", "ecs0", "--control"])
        .arg(dir.join("sim.ctl"))
        .env("TELEOP_LOG", "info")
        .stdout(log.try_clone().unwrap())
        .stderr(log);
    let mut sim = die_with_parent(&mut cmd).spawn().unwrap();
    let start = Instant::now();
    loop {
        let text = std::fs::read_to_string(dir.join("sim.log")).unwrap_or_default();
        if text.contains("shadow: interface ecs0") {
            return sim;
        }
        if let Ok(Some(status)) = sim.try_wait() {
            panic!("the emulator exited ({status}):\n{text}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "the emulator did not start:\n{text}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn soem_brings_both_emulated_subdevices_to_op_over_a_veth_pair() {
    skip_unless_privileged!();
    if let Some(reason) = pysoem_missing() {
        skip(&reason);
        return;
    }
    let ns = Netns::new("teleop-shadow-veth-");
    let dir = tempfile::tempdir().unwrap();
    let mut sim = start_sim(&ns, dir.path());
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/soem_op.py");
    let mut cmd = ns.command("python3");
    cmd.args([script, "ecm0", "200"]);
    let (status, out, err) = run_for(die_with_parent(&mut cmd), Duration::from_secs(60));
    stop(&mut sim);
    let sim_log = std::fs::read_to_string(dir.path().join("sim.log")).unwrap_or_default();
    let report = format!("soem_op.py: {status:?}\n{out}{err}\n---- emulator log ----\n{sim_log}");
    assert!(status.is_some_and(|s| s.success()), "{report}");
    assert!(
        out.contains("product 0x0") && out.contains("product 0x6"),
        "{report}"
    );
    assert!(
        out.contains("code 0x0017"),
        "SAFE-OP refused first: {report}"
    );
    assert!(out.contains("both in OP"), "{report}");
    assert_eq!(out.lines().last(), Some("OK"), "{report}");
}
