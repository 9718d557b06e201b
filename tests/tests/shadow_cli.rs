//! `teleop shadow ...` against the emulated Shadow Hand running as its own process
//! (`teleop-sim-shadow --socket`), through ethercrab and the node's own bring-up: the palm's
//! identity and the motors' slow data, a motor board flashed from a generated Intel HEX file
//! (read back by the flasher, restarted, reporting the image's revision), each refusal, a
//! crafted CAN message and its reply, and the ADC channel check.
#![allow(clippy::unwrap_used)]

use teleop_e2e::rig::Rig;
use teleop_shadow_protocol::can::APP_START;
use teleop_shadow_protocol::hex;

/// The emulated Shadow Hand as its own process on a socket in a fresh rig, and the transport
/// that reaches it.
fn start() -> (Rig, String) {
    let mut rig = Rig::new();
    let transport = rig.start_socket_sim("shadow");
    (rig, transport)
}

fn shadow(rig: &Rig, transport: &str, args: &[&str]) -> (bool, String) {
    rig.sandbox
        .cli(&[&["shadow", "--transport", transport], args].concat())
}

/// A pseudo-random application whose first word (the emulator's revision word) is `revision`.
fn application(len: usize, revision: u16) -> Vec<u8> {
    let mut app = teleop_sim_shadow::bootloader::generated_application(len, 0x2545_F491);
    app[..2].copy_from_slice(&revision.to_le_bytes());
    app
}

fn motor_line(info: &str, motor: u8) -> String {
    info.lines()
        .find(|l| l.split_whitespace().next() == Some(&motor.to_string()))
        .unwrap_or_else(|| panic!("no line for motor {motor}:\n{info}"))
        .to_string()
}

#[test]
fn info_names_the_palm_and_each_motors_revision_and_serial() {
    let (rig, transport) = start();
    let (ok, info) = shadow(&rig, &transport, &["info"]);
    assert!(ok, "{info}");
    assert!(
        info.contains("palm: product 6 (SR06, protocol 0220), vendor 0x00000530"),
        "{info}"
    );
    let line = motor_line(&info, 13);
    assert!(
        line.contains("2035") && line.contains("0x5a00000d"),
        "{line}"
    );
    assert!(!info.contains("not every motor"), "{info}");
}

#[test]
fn a_board_is_flashed_read_back_restarted_and_each_refusal_is_clear() {
    let (rig, transport) = start();
    let sandbox = &rig.sandbox;
    let app = application(1500, 0x0BEE);
    let good = sandbox.write("good.hex", &hex::write(APP_START, &app));

    // Refused before the bus is touched: a bad checksum (named by line), data in the
    // bootloader's area, a motor that does not exist.
    let mut bad = hex::write(APP_START, &app);
    let second = bad.lines().nth(1).unwrap().to_string();
    let broken = format!("{}00", &second[..second.len() - 2]);
    bad = bad.replacen(&second, &broken, 1);
    let bad = sandbox.write("bad.hex", &bad);
    let (ok, out) = shadow(
        &rig,
        &transport,
        &["flash", bad.to_str().unwrap(), "--motor", "13"],
    );
    assert!(
        !ok && out.contains("line 2") && out.contains("checksum"),
        "{out}"
    );
    let low = sandbox.write("low.hex", &hex::write(0x0400, &app));
    let (ok, out) = shadow(
        &rig,
        &transport,
        &["flash", low.to_str().unwrap(), "--motor", "13"],
    );
    assert!(
        !ok && out.contains("data at 0x0400 is outside the application area"),
        "{out}"
    );
    let (ok, out) = shadow(
        &rig,
        &transport,
        &["flash", good.to_str().unwrap(), "--motor", "20"],
    );
    assert!(!ok && out.contains("motors 0..19"), "{out}");

    // A board that does not answer MAGIC: named, then flashed once it answers.
    sandbox.control_ok("shadow.ctl", "silent 13");
    let (ok, out) = shadow(
        &rig,
        &transport,
        &["flash", good.to_str().unwrap(), "--motor", "13"],
    );
    assert!(!ok && out.contains("no acknowledgement of MAGIC"), "{out}");
    sandbox.control_ok("shadow.ctl", "silent none");

    // A board that stops acking mid-transfer: the step and address named; flashed again after.
    sandbox.control_ok("shadow.ctl", "flash-stall 13 200");
    let (ok, out) = shadow(
        &rig,
        &transport,
        &["flash", good.to_str().unwrap(), "--motor", "13"],
    );
    assert!(!ok && out.contains("0x"), "{out}");
    assert!(out.contains("flash it again"), "{out}");
    sandbox.control_ok("shadow.ctl", "flash-stall 13 off");

    let (ok, out) = shadow(
        &rig,
        &transport,
        &["flash", good.to_str().unwrap(), "--motor", "13"],
    );
    assert!(ok, "{out}");
    assert!(out.contains("motor 13 flashed and restarted"), "{out}");
    assert!(out.contains("47/47 rows"), "{out}");

    // The board runs the new image: its revision word is what it reports.
    let (ok, info) = shadow(&rig, &transport, &["info"]);
    assert!(ok, "{info}");
    assert!(motor_line(&info, 13).contains("3054"), "{info}");
    assert!(motor_line(&info, 12).contains("2035"), "{info}");
}

#[test]
fn a_crafted_can_message_is_answered_and_the_adc_channels_are_checked() {
    let (rig, transport) = start();
    // MAGIC to board 3 of bus 2 (motor 13): its application restarts into the bootloader,
    // which announces itself.
    let (ok, out) = shadow(
        &rig,
        &transport,
        &["can-send", "2", "0x66A", "55AA55AA55AA55AA"],
    );
    assert!(ok, "{out}");
    assert!(
        out.contains("reply bus 2 SID 0x67a [8] 55 AA 55 AA"),
        "{out}"
    );
    // VERSION, then RESET back into the application.
    let (ok, out) = shadow(&rig, &transport, &["can-send", "2", "664"]);
    assert!(ok && out.contains("SID 0x674 [4] 40 41 42 43"), "{out}");
    let (ok, out) = shadow(&rig, &transport, &["can-send", "2", "663"]);
    assert!(ok && out.contains("SID 0x673"), "{out}");
    let (ok, out) = shadow(&rig, &transport, &["can-send", "3", "663"]);
    assert!(!ok && out.contains("buses 1 and 2"), "{out}");

    let config = teleop_e2e::Sandbox::repo().join("config/shadow.toml");
    let (ok, out) = shadow(
        &rig,
        &transport,
        &["--config", config.to_str().unwrap(), "channels"],
    );
    assert!(ok, "{out}");
    assert!(out.contains("LFJ5    0x0605    5        6  ok"), "{out}");
    let wrong = std::fs::read_to_string(&config)
        .unwrap()
        .replace("LFJ5 = [5, 6]", "LFJ5 = [5, 7]");
    let wrong = rig.sandbox.write("wrong.toml", &wrong);
    let (ok, out) = shadow(
        &rig,
        &transport,
        &["--config", wrong.to_str().unwrap(), "channels"],
    );
    assert!(!ok && out.contains("MISMATCH: ADC 5 channel 7"), "{out}");
}
