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

use teleop_e2e::netns::{python_module_missing, skip, Netns};
use teleop_e2e::skip_unless_privileged;

#[test]
fn soem_brings_both_emulated_subdevices_to_op_over_a_veth_pair() {
    skip_unless_privileged!();
    if let Some(reason) = python_module_missing("pysoem") {
        skip(&reason);
        return;
    }
    let ns = Netns::new("teleop-shadow-veth-");
    let dir = tempfile::tempdir().unwrap();
    let mut sim = ns.start_emulator(
        "teleop-sim-shadow",
        &[],
        dir.path(),
        "shadow: interface ecs0",
    );
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/soem_op.py");
    let (out, report) = ns.run_soem(script, 200, &mut sim, dir.path());
    assert!(
        out.contains("product 0x0") && out.contains("product 0x6"),
        "{report}"
    );
    assert!(
        out.contains("code 0x0017"),
        "SAFE-OP refused first: {report}"
    );
    assert!(out.contains("both in OP"), "{report}");
}
