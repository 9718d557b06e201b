//! `teleop revo2 ...` against the emulated Revo2 running as its own process
//! (`teleop-sim-revo2 --socket`), through ethercrab in PRE-OP.
#![allow(clippy::unwrap_used)]

use teleop_e2e::rig::Rig;
use teleop_e2e::Sandbox;

/// The emulated Revo2 as its own process on a socket in a fresh rig, and the transport that
/// reaches it.
fn start() -> (Rig, String) {
    let mut rig = Rig::new();
    let transport = rig.start_socket_sim("revo2");
    (rig, transport)
}

fn revo2(sandbox: &Sandbox, transport: &str, args: &[&str]) -> (bool, String) {
    sandbox.cli(&[&["revo2", "--transport", transport], args].concat())
}

#[test]
fn info_set_and_calibrate_on_the_emulated_revo2() {
    let (rig, transport) = start();
    let sandbox = &rig.sandbox;
    let (ok, info) = revo2(sandbox, &transport, &["info"]);
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

    let (ok, out) = revo2(sandbox, &transport, &["set", "led_switch", "1"]);
    assert!(ok && out.contains("led_switch = 1"), "{out}");
    let (ok, out) = revo2(sandbox, &transport, &["set", "index_pro_cur", "750"]);
    assert!(ok && out.contains("index_pro_cur = 750"), "{out}");
    let (_, info) = revo2(sandbox, &transport, &["info"]);
    assert!(
        info.contains("index_pro_cur              750"),
        "persisted: {info}"
    );

    let (ok, out) = revo2(sandbox, &transport, &["set", "unit_mode", "7"]);
    assert!(!ok && out.contains("unit_mode"), "{out}");
    let (ok, out) = revo2(
        sandbox,
        &transport,
        &["set", "ctrl_wrist_fw_version", "9.9.9"],
    );
    assert!(
        !ok && out.to_lowercase().contains("read"),
        "read-only: {out}"
    );
    let (ok, out) = revo2(sandbox, &transport, &["set", "ctrl_sn", "RV2C0001"]);
    assert!(
        !ok && out.contains("segmented"),
        "strings need a segmented download: {out}"
    );
    let (ok, out) = revo2(sandbox, &transport, &["set", "no_such_thing", "1"]);
    assert!(!ok && out.contains("no_such_thing"), "{out}");

    let (ok, out) = revo2(sandbox, &transport, &["calibrate", "--tactile"]);
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

/// A firmware file as the packaging tool makes it: magic, version (little-endian u32
/// 0x00MMmmpp), reserved zeros, then the image.
fn firmware(
    sandbox: &Sandbox,
    name: &str,
    magic: &[u8; 8],
    (major, minor, patch): (u8, u8, u8),
    image: usize,
) -> String {
    let mut bytes = magic.to_vec();
    bytes.extend_from_slice(&[patch, minor, major, 0, 0, 0, 0, 0]);
    bytes.extend((0..image).map(|i| (i * 13 % 251) as u8));
    let path = sandbox.dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    path.display().to_string()
}

#[test]
fn flash_both_boards_of_the_emulated_revo2() {
    let (rig, transport) = start();
    let sandbox = &rig.sandbox;
    let wrist = firmware(
        sandbox,
        "Revo2EC_1.0.3_2506231346.bin",
        b"BRCW2025",
        (1, 0, 3),
        6000,
    );
    let control_fw = firmware(
        sandbox,
        "Revo2_V2.1.0_2506231346.bin",
        b"BRCC2025",
        (2, 1, 0),
        9000,
    );
    let (ok, out) = revo2(sandbox, &transport, &["flash", &wrist, "--board", "wrist"]);
    assert!(
        ok && out.contains("wrist board firmware 0.9.7 -> 1.0.3") && out.contains("KiB/s"),
        "{out}"
    );
    let (ok, out) = revo2(
        sandbox,
        &transport,
        &["flash", &control_fw, "--board", "control"],
    );
    assert!(
        ok && out.contains("control board firmware 1.4.2 -> 2.1.0"),
        "{out}"
    );
    assert_eq!(
        sandbox.control("revo2.ctl", "versions").trim(),
        "ok control 2.1.0 wrist 1.0.3"
    );

    // Refused before the device is touched.
    let wrong_magic = firmware(
        sandbox,
        "Revo2EC_1.0.4_2506231346.bin",
        b"BRCC2025",
        (1, 0, 4),
        100,
    );
    let lower_case = firmware(
        sandbox,
        "revo2EC_1.0.4_2506231346.bin",
        b"BRCW2025",
        (1, 0, 4),
        100,
    );
    let truncated = sandbox.dir.path().join("Revo2EC_1.0.5_2506231346.bin");
    std::fs::write(&truncated, b"BRCW2025\x05\x00").unwrap();
    let truncated = truncated.display().to_string();
    for (file, board, expected) in [
        (
            &wrong_magic,
            "wrist",
            "magic number BRCC2025 is the control board's",
        ),
        (&control_fw, "wrist", "firmware is for the control board"),
        (&lower_case, "wrist", "must start with \"Revo2EC_\""),
        (&truncated, "wrist", "truncated"),
    ] {
        let (ok, out) = revo2(sandbox, &transport, &["flash", file, "--board", board]);
        assert!(
            !ok && out.contains(expected) && out.contains("refused before contacting the device"),
            "{out}"
        );
    }
    // Refused by the device.
    let again = firmware(
        sandbox,
        "Revo2EC_1.1.0_2506231346.bin",
        b"BRCW2025",
        (1, 1, 0),
        3000,
    );
    let (ok, out) = revo2(
        sandbox,
        &transport,
        &[
            "flash",
            &again,
            "--board",
            "wrist",
            "--auth-code",
            "BRCC2025",
        ],
    );
    assert!(
        !ok && out.contains("FoE error 0x800a") && out.contains("authentication code"),
        "{out}"
    );
    // A device that stops answering mid-transfer.
    sandbox.control_ok("revo2.ctl", "foe-stall 4");
    let (ok, out) = revo2(sandbox, &transport, &["flash", &again, "--board", "wrist"]);
    assert!(
        !ok && out.contains("no answer from the device to data packet 5")
            && out.contains("stopped answering"),
        "{out}"
    );
    // Still usable: its configuration reads, and the next upgrade works.
    let (ok, info) = revo2(sandbox, &transport, &["info"]);
    assert!(
        ok && info.contains("wrist_fw_version           1.0.3"),
        "{info}"
    );
    let (ok, out) = revo2(sandbox, &transport, &["flash", &again, "--board", "wrist"]);
    assert!(ok && out.contains("1.0.3 -> 1.1.0"), "{out}");
}
