//! Hardware errors and the control socket's faults over the real pty: overload and overheating
//! shut a servo down with the Alert bit until a reboot (silent for its boot time), a silent
//! servo in Sync Read and in both Fast Sync Read chain options, corrupted and dropped
//! statuses, unplugging (the servos power-cycled), and the words refused.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::Duration;

use common::{wait_for, Host, Sim, BAUD};
use teleop_leap_protocol::packet::{self, MAX_PACKET};
use teleop_leap_protocol::xc330::{self, HardwareError};

const ALL: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15];
const ALERT: u8 = 0x80;

fn torque_on(host: &mut Host, id: u8) {
    assert_eq!(host.write(id, xc330::OPERATING_MODE, &[5]), 0);
    assert_eq!(
        host.write(id, xc330::GOAL_CURRENT, &350i16.to_le_bytes()),
        0
    );
    assert_eq!(host.write(id, xc330::TORQUE_ENABLE, &[1]), 0);
}

#[test]
fn an_overloaded_servo_shuts_down_with_the_alert_until_a_reboot() {
    let sim = Sim::start(&["--boot-ms", "1000"]);
    let mut host = sim.host(BAUD);
    torque_on(&mut host, 4);
    sim.control_ok("overload 4");
    let r = host.read(4, xc330::TORQUE_ENABLE, 1);
    assert_eq!((r.error, r.value()), (ALERT, 0), "torque off, alert");
    let r = host.read(4, xc330::HARDWARE_ERROR_STATUS, 1);
    assert_eq!(r.value(), i64::from(HardwareError::OVERLOAD));
    assert_eq!(
        host.write(4, xc330::TORQUE_ENABLE, &[1]),
        ALERT,
        "answered with the alert"
    );
    assert_eq!(
        host.read(4, xc330::TORQUE_ENABLE, 1).value(),
        0,
        "stays off"
    );
    assert_eq!(
        host.read(5, xc330::TORQUE_ENABLE, 1).error,
        0,
        "others unaffected"
    );

    host.send(|out| packet::reboot(4, out));
    assert_eq!(host.status().error, ALERT, "Reboot is answered");
    host.send(|out| packet::ping(4, out));
    host.silence(Duration::from_millis(100));
    wait_for(Duration::from_secs(10), "servo 4 back", || {
        host.send(|out| packet::ping(4, out));
        host.statuses_within(1, Duration::from_millis(50)).pop()
    });
    let r = host.read(4, xc330::HARDWARE_ERROR_STATUS, 1);
    assert_eq!((r.error, r.value()), (0, 0));
    assert_eq!(host.read(4, xc330::TORQUE_ENABLE, 1).value(), 0);
    assert_eq!(
        host.read(4, xc330::GOAL_CURRENT, 2).value(),
        2352,
        "RAM back at its initial values"
    );
    assert_eq!(
        host.read(4, xc330::OPERATING_MODE, 1).value(),
        5,
        "EEPROM kept"
    );
    let p = host.read(4, xc330::PRESENT_POSITION, 4).signed();
    assert!((0..4096).contains(&p), "{p}");
    torque_on(&mut host, 4);
    assert_eq!(sim.stats()["hardware_error"].split(',').nth(4), Some("0"));
}

#[test]
fn an_overheated_servo_sets_its_overheating_bit_and_shuts_down() {
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    torque_on(&mut host, 6);
    sim.control_ok("overheat 6");
    let r = host.read(6, xc330::HARDWARE_ERROR_STATUS, 1);
    assert_eq!(r.error, ALERT);
    assert_eq!(r.value(), i64::from(HardwareError::OVERHEATING));
    assert_eq!(host.read(6, xc330::TORQUE_ENABLE, 1).value(), 0);
    assert!(host.read(6, xc330::PRESENT_TEMPERATURE, 1).value() > 70);
}

#[test]
fn a_silent_servo_is_left_out_of_sync_read_and_of_the_fast_sync_chain() {
    let sim = Sim::start(&["--fast-sync-missing", "omit"]);
    let mut host = sim.host(BAUD);
    sim.control_ok("silent 5");
    host.send(|out| packet::sync_read(xc330::PRESENT_POSITION, 4, &ALL, out));
    let ids: Vec<u8> = host
        .statuses_within(16, common::WAIT)
        .iter()
        .map(|r| r.id)
        .collect();
    assert_eq!(ids, [0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15]);
    let blocks = host.fast_sync_read(xc330::STATE_ADDR, xc330::STATE_LEN, &ALL);
    let ids: Vec<u8> = blocks.iter().map(|b| b.0).collect();
    assert_eq!(ids, [0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15]);
    assert_eq!(sim.stats()["silent"], "5");
    sim.control_ok("clear");
    assert_eq!(
        host.fast_sync_read(xc330::STATE_ADDR, xc330::STATE_LEN, &ALL)
            .len(),
        16
    );
    // For a while only.
    sim.control_ok("silent 9 1000");
    host.send(|out| packet::ping(9, out));
    host.silence(Duration::from_millis(50));
    wait_for(Duration::from_secs(10), "servo 9 back", || {
        host.send(|out| packet::ping(9, out));
        host.statuses_within(1, Duration::from_millis(50)).pop()
    });
    assert!(sim.counter("silenced") >= 2);
}

#[test]
fn by_default_the_fast_sync_reply_ends_at_the_silent_servo() {
    // `--fast-sync-missing truncate`, the default.
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    let full = host.fast_sync_read_raw(xc330::STATE_ADDR, xc330::STATE_LEN, &ALL);
    assert_eq!(full.len(), 8 + 16 * 14);
    sim.control_ok("silent 5");
    let cut = host.fast_sync_read_raw(xc330::STATE_ADDR, xc330::STATE_LEN, &ALL);
    assert_eq!(cut.len(), 8 + 5 * 14, "header and the blocks of 0..4");
    assert_eq!(
        cut[..5 * 14],
        full[..5 * 14],
        "the same LEN and blocks as far as they go"
    );
    let mut scratch = vec![0u8; MAX_PACKET];
    assert!(packet::parse(&cut, &mut scratch).is_err());
    sim.control_ok("silent 0");
    let none = host.fast_sync_read_raw(xc330::STATE_ADDR, xc330::STATE_LEN, &ALL);
    assert!(none.is_empty(), "the first servo silent: nothing");
}

#[test]
fn corrupted_and_dropped_statuses_are_counted() {
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    sim.control_ok("crc 1");
    host.send(|out| packet::ping(2, out));
    let raw = host.raw(Duration::from_millis(100));
    assert_eq!(raw.len(), 14, "a whole status");
    let mut scratch = vec![0u8; MAX_PACKET];
    assert!(packet::parse(&raw, &mut scratch).is_err(), "{raw:02X?}");
    assert_eq!(sim.counter("corrupted"), 1);
    sim.control_ok("clear");
    sim.control_ok("drop 1");
    host.send(|out| packet::ping(2, out));
    host.silence(Duration::from_millis(100));
    // Counted when the simulator gets to the status: waited for, then exactly once.
    wait_for(
        Duration::from_secs(10),
        "the dropped status counted",
        || (sim.counter("dropped") >= 1).then_some(()),
    );
    assert_eq!(sim.counter("dropped"), 1);
    sim.control_ok("drop 0");
    host.send(|out| packet::ping(2, out));
    assert_eq!(host.status().id, 2);
}

#[test]
fn unplugging_powers_the_servos_off_and_they_come_back_behind_the_same_link() {
    let sim = Sim::start(&["--boot-ms", "100"]);
    let mut host = sim.host(BAUD);
    torque_on(&mut host, 1);
    assert!(sim.control_ok("unplug 300").contains("300"));
    wait_for(
        Duration::from_secs(10),
        "unplugged and plugged back in",
        || {
            let s = sim.stats();
            (s["unplugs"] == "1" && s["link"] == "plugged").then_some(())
        },
    );
    drop(host);
    let mut host = sim.host(BAUD);
    wait_for(Duration::from_secs(10), "the servos booted", || {
        host.send(|out| packet::ping(1, out));
        host.statuses_within(1, Duration::from_millis(50)).pop()
    });
    assert_eq!(
        host.read(1, xc330::TORQUE_ENABLE, 1).value(),
        0,
        "power-cycled"
    );
    assert_eq!(
        host.read(1, xc330::OPERATING_MODE, 1).value(),
        5,
        "EEPROM kept"
    );
}

#[test]
fn the_words_and_their_arguments_are_checked() {
    let sim = Sim::start(&[]);
    for bad in [
        "silent",
        "silent 253",
        "silent 1 soon",
        "crc 2",
        "noise 0",
        "noise 5000",
        "overload",
        "overload 20",
        "overheat x",
        "frobnicate",
    ] {
        let reply = sim.control(bad);
        assert!(reply.starts_with("error"), "{bad}: {reply}");
    }
    assert_eq!(sim.control("silent 3 100"), "ok silent 3 100 ms");
    assert_eq!(sim.control("crc 0.5"), "ok crc 0.5");
    assert_eq!(sim.control("clear"), "ok");
    assert_eq!(sim.stats()["crc"], "0");
    assert_eq!(sim.control("object bar"), "ok object bar");
    assert_eq!(sim.stats()["object"], "bar");
}

#[test]
fn bad_options_stop_the_process_with_a_message() {
    for args in [
        &["--baud", "250000"][..],
        &["--return-delay-us", "3"][..],
        &["--return-delay-us", "600"][..],
        &["--fast-sync-missing", "maybe"][..],
        &["--model", "xm430"][..],
        &["--object", "cube"][..],
    ] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_teleop-sim-leap"))
            .args(["--link", "/tmp/sim-leap-never"])
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
    }
}
