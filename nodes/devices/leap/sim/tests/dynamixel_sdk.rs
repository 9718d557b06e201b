//! The independent check: ROBOTIS's own Python SDK (`dynamixel-sdk` 4.1.0 from PyPI, in
//! `.ci/requirements.txt`) drives the simulator's pty at 4 Mbit/s with `dynamixel_sdk_check.py`
//! (next to this file): Ping of all 16 servos with their model number, GroupSyncWrite read back
//! by Read, GroupSyncRead by Sync Read and by Fast Sync Read, an EEPROM write refused under
//! torque (Access Error) and accepted without. Skipped, with the reason printed, when python3
//! or the module is missing, unless `TELEOP_REQUIRE_CHECKS` is set: then that fails.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use common::Sim;
use teleop_e2e::netns::{python_module_missing, run_for, skip};

#[test]
fn robotis_python_sdk_pings_reads_writes_and_is_refused_an_eeprom_write_under_torque() {
    if let Some(reason) = python_module_missing("dynamixel_sdk") {
        skip(&reason);
        return;
    }
    let sim = Sim::start(&["--object", "none"]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/dynamixel_sdk_check.py");
    let (status, out, err) = run_for(
        Command::new("python3").arg(&script).arg(sim.link()),
        Duration::from_secs(120),
    );
    println!("{out}");
    assert!(
        status.is_some_and(|s| s.success()),
        "the ROBOTIS SDK's check failed ({status:?}):\n{out}\n{err}"
    );
    assert_eq!(out.lines().filter(|l| l.starts_with("FAIL")).count(), 0);
    assert!(out.contains("ok   GroupSyncRead.fastSyncRead present positions"));
    let s = sim.stats();
    assert_eq!(s["ping"], "16");
    assert_eq!(s["sync_write"], "1");
    assert_eq!(
        (s["sync_read"].as_str(), s["fast_sync_read"].as_str()),
        ("1", "1")
    );
}
