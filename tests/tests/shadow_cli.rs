//! `teleop shadow ...` against the emulated Shadow Hand running as its own process
//! (`teleop-sim-shadow --socket`), through ethercrab and the node's own bring-up: the palm's
//! identity and the motors' slow data, a motor board flashed from a generated Intel HEX file
//! (read back by the flasher, restarted, reporting the image's revision), each refusal, a
//! crafted CAN message and its reply, and the ADC channel check.
#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

use teleop_e2e::{bin, Sandbox};
use teleop_shadow_protocol::can::APP_START;
use teleop_shadow_protocol::hex;

struct Sim {
    child: Child,
    control: PathBuf,
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

impl Sim {
    fn control(&self, command: &str) -> String {
        let stream = UnixStream::connect(&self.control).unwrap();
        writeln!(&stream, "{command}").unwrap();
        let mut line = String::new();
        BufReader::new(stream).read_line(&mut line).unwrap();
        assert!(line.starts_with("ok"), "{command}: {line}");
        line
    }
}

fn start(sandbox: &Sandbox) -> (Sim, String) {
    let socket = sandbox.dir.path().join("shadow.sock");
    let mut child = Command::new(bin("teleop-sim-shadow"))
        .arg("--socket")
        .arg(&socket)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.starts_with("shadow: socket"), "{line}");
    let control = socket.with_extension("ctl");
    (Sim { child, control }, format!("sim:{}", socket.display()))
}

fn shadow(sandbox: &Sandbox, transport: &str, args: &[&str]) -> (bool, String) {
    let out = sandbox
        .teleop()
        .args(["shadow", "--transport", transport])
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
    let sandbox = Sandbox::new();
    let (_sim, transport) = start(&sandbox);
    let (ok, info) = shadow(&sandbox, &transport, &["info"]);
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
    let sandbox = Sandbox::new();
    let (sim, transport) = start(&sandbox);
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
        &sandbox,
        &transport,
        &["flash", bad.to_str().unwrap(), "--motor", "13"],
    );
    assert!(
        !ok && out.contains("line 2") && out.contains("checksum"),
        "{out}"
    );
    let low = sandbox.write("low.hex", &hex::write(0x0400, &app));
    let (ok, out) = shadow(
        &sandbox,
        &transport,
        &["flash", low.to_str().unwrap(), "--motor", "13"],
    );
    assert!(
        !ok && out.contains("data at 0x0400 is outside the application area"),
        "{out}"
    );
    let (ok, out) = shadow(
        &sandbox,
        &transport,
        &["flash", good.to_str().unwrap(), "--motor", "20"],
    );
    assert!(!ok && out.contains("motors 0..19"), "{out}");

    // A board that does not answer MAGIC: named, then flashed once it answers.
    sim.control("silent 13");
    let (ok, out) = shadow(
        &sandbox,
        &transport,
        &["flash", good.to_str().unwrap(), "--motor", "13"],
    );
    assert!(!ok && out.contains("no acknowledgement of MAGIC"), "{out}");
    sim.control("silent none");

    // A board that stops acking mid-transfer: the step and address named; flashed again after.
    sim.control("flash-stall 13 200");
    let (ok, out) = shadow(
        &sandbox,
        &transport,
        &["flash", good.to_str().unwrap(), "--motor", "13"],
    );
    assert!(!ok && out.contains("0x"), "{out}");
    assert!(out.contains("flash it again"), "{out}");
    sim.control("flash-stall 13 off");

    let (ok, out) = shadow(
        &sandbox,
        &transport,
        &["flash", good.to_str().unwrap(), "--motor", "13"],
    );
    assert!(ok, "{out}");
    assert!(out.contains("motor 13 flashed and restarted"), "{out}");
    assert!(out.contains("47/47 rows"), "{out}");

    // The board runs the new image: its revision word is what it reports.
    let (ok, info) = shadow(&sandbox, &transport, &["info"]);
    assert!(ok, "{info}");
    assert!(motor_line(&info, 13).contains("3054"), "{info}");
    assert!(motor_line(&info, 12).contains("2035"), "{info}");
}

#[test]
fn a_crafted_can_message_is_answered_and_the_adc_channels_are_checked() {
    let sandbox = Sandbox::new();
    let (_sim, transport) = start(&sandbox);
    // MAGIC to board 3 of bus 2 (motor 13): its application restarts into the bootloader,
    // which announces itself.
    let (ok, out) = shadow(
        &sandbox,
        &transport,
        &["can-send", "2", "0x66A", "55AA55AA55AA55AA"],
    );
    assert!(ok, "{out}");
    assert!(
        out.contains("reply bus 2 SID 0x67a [8] 55 AA 55 AA"),
        "{out}"
    );
    // VERSION, then RESET back into the application.
    let (ok, out) = shadow(&sandbox, &transport, &["can-send", "2", "664"]);
    assert!(ok && out.contains("SID 0x674 [4] 40 41 42 43"), "{out}");
    let (ok, out) = shadow(&sandbox, &transport, &["can-send", "2", "663"]);
    assert!(ok && out.contains("SID 0x673"), "{out}");
    let (ok, out) = shadow(&sandbox, &transport, &["can-send", "3", "663"]);
    assert!(!ok && out.contains("buses 1 and 2"), "{out}");

    let config = Sandbox::repo().join("config/shadow.toml");
    let (ok, out) = shadow(
        &sandbox,
        &transport,
        &["--config", config.to_str().unwrap(), "channels"],
    );
    assert!(ok, "{out}");
    assert!(out.contains("LFJ5    0x0605    5        6  ok"), "{out}");
    let wrong = std::fs::read_to_string(&config)
        .unwrap()
        .replace("LFJ5 = [5, 6]", "LFJ5 = [5, 7]");
    let wrong = sandbox.write("wrong.toml", &wrong);
    let (ok, out) = shadow(
        &sandbox,
        &transport,
        &["--config", wrong.to_str().unwrap(), "channels"],
    );
    assert!(!ok && out.contains("MISMATCH: ADC 5 channel 7"), "{out}");
}
