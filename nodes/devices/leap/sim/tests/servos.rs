//! The servos' protocol behaviour over the real pty, with the protocol crate's encoders: Ping,
//! the control table's checks (EEPROM refused under torque, ranges, lengths, read-only and
//! undefined addresses), broadcast, Status Return Level, Sync and Fast Sync Read, return
//! delay, baud mismatch, requests with a bad CRC.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::{Duration, Instant};

use common::{wait_for, Sim, BAUD};
use teleop_leap_protocol::packet::{self, instruction, BROADCAST_ID};
use teleop_leap_protocol::xc330;

/// How long a wait for the simulator to get to bytes already sent may take before it fails:
/// generous (the wait ends as soon as it has), since the machine may be busy.
const PATIENCE: Duration = Duration::from_secs(10);

const ALL: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15];
const ACCESS: u8 = 7;

#[test]
fn every_servo_answers_ping_with_its_model_and_broadcast_ping_in_id_order() {
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    for id in ALL {
        host.send(|out| packet::ping(id, out));
        let r = host.status();
        assert_eq!((r.id, r.error), (id, 0));
        assert_eq!(
            u16::from_le_bytes([r.params[0], r.params[1]]),
            xc330::MODEL_XC330_M288
        );
        assert_eq!(r.params[2], 52, "firmware version");
    }
    host.send(|out| packet::ping(BROADCAST_ID, out));
    let ids: Vec<u8> = host.statuses(16).iter().map(|r| r.id).collect();
    assert_eq!(ids, ALL);
    host.send(|out| packet::ping(40, out));
    host.silence(Duration::from_millis(100));
    assert_eq!(sim.counter("ping"), 18);
}

#[test]
fn the_control_table_refuses_what_the_firmware_refuses() {
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    // The factory setup.
    assert_eq!(host.read(3, xc330::BAUD_RATE, 1).value(), 6);
    assert_eq!(host.read(3, xc330::RETURN_DELAY_TIME, 1).value(), 250);
    assert_eq!(host.read(3, xc330::OPERATING_MODE, 1).value(), 3);
    assert_eq!(host.read(3, xc330::TORQUE_ENABLE, 1).value(), 0);
    assert_eq!(host.read(3, xc330::STATUS_RETURN_LEVEL, 1).value(), 2);
    assert_eq!(host.read(3, xc330::PRESENT_POSITION, 4).value(), 2048);
    assert_eq!(host.read(3, xc330::PRESENT_INPUT_VOLTAGE, 2).value(), 50);

    // EEPROM: written with the torque off, refused with it on, nothing changed.
    assert_eq!(host.write(3, xc330::OPERATING_MODE, &[5]), 0);
    assert_eq!(host.write(3, xc330::TORQUE_ENABLE, &[1]), 0);
    assert_eq!(host.write(3, xc330::OPERATING_MODE, &[3]), ACCESS);
    assert_eq!(
        host.write(3, xc330::CURRENT_LIMIT, &600u16.to_le_bytes()),
        ACCESS
    );
    assert_eq!(host.read(3, xc330::OPERATING_MODE, 1).value(), 5);
    // RAM still takes writes under torque.
    assert_eq!(host.write(3, xc330::GOAL_CURRENT, &300i16.to_le_bytes()), 0);
    assert_eq!(host.write(3, xc330::TORQUE_ENABLE, &[0]), 0);
    assert_eq!(host.write(3, xc330::OPERATING_MODE, &[3]), 0);

    // Ranges, lengths, access.
    assert_eq!(host.write(3, xc330::OPERATING_MODE, &[2]), 4, "no mode 2");
    assert_eq!(host.write(3, xc330::STATUS_RETURN_LEVEL, &[3]), 4);
    assert_eq!(
        host.write(3, xc330::GOAL_POSITION, &[0, 8]),
        5,
        "half an item"
    );
    assert_eq!(host.write(3, xc330::PRESENT_POSITION, &[0; 4]), ACCESS);
    assert_eq!(host.write(3, 1, &[0]), ACCESS, "inside Model Number");
    assert_eq!(
        host.write(3, xc330::GOAL_CURRENT, &3000i16.to_le_bytes()),
        6,
        "beyond Current Limit"
    );
    assert_eq!(
        host.write(3, xc330::GOAL_POSITION, &5000i32.to_le_bytes()),
        6,
        "beyond Max Position Limit in mode 3"
    );
    let r = host.read(3, 200, 100);
    assert_eq!((r.error, r.params.len()), (ACCESS, 0), "beyond the table");
    // A write refused in part changes nothing.
    assert_eq!(host.write(3, xc330::GOAL_CURRENT, &[0x10, 0x27, 0, 0]), 6);
    assert_eq!(
        host.read(3, xc330::GOAL_CURRENT, 2).value(),
        2352,
        "Goal Current at Current Limit"
    );

    // An unknown instruction.
    host.send(|out| packet::encode(3, 0x7E, &[], out));
    assert_eq!(host.status().error, 2);
}

#[test]
fn broadcast_writes_are_silent_and_status_return_level_limits_answers() {
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    host.send(|out| packet::write(BROADCAST_ID, xc330::LED, &[1], out));
    host.silence(Duration::from_millis(100));
    for id in ALL {
        assert_eq!(host.read(id, xc330::LED, 1).value(), 1);
    }
    host.send(|out| packet::read(BROADCAST_ID, xc330::LED, 1, out));
    host.silence(Duration::from_millis(100));

    assert_eq!(host.write(2, xc330::STATUS_RETURN_LEVEL, &[1]), 0);
    host.send(|out| packet::write(2, xc330::LED, &[0], out));
    host.silence(Duration::from_millis(100));
    assert_eq!(
        host.read(2, xc330::LED, 1).value(),
        0,
        "written, unanswered"
    );
    host.send(|out| packet::write(2, xc330::STATUS_RETURN_LEVEL, &[0], out));
    host.silence(Duration::from_millis(100));
    host.send(|out| packet::read(2, xc330::LED, 1, out));
    host.silence(Duration::from_millis(100));
    host.send(|out| packet::ping(2, out));
    assert_eq!(host.status().id, 2, "Ping is always answered");
}

#[test]
fn sync_read_answers_in_request_order_and_fast_sync_read_in_one_packet() {
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    let goals: Vec<(u8, i32)> = ALL.iter().map(|&id| (id, 2000 + i32::from(id))).collect();
    host.sync_write(xc330::GOAL_POSITION, &goals, 4);
    host.silence(Duration::from_millis(50));
    let order = [7, 3, 15, 0, 9];
    host.send(|out| packet::sync_read(xc330::GOAL_POSITION, 4, &order, out));
    let replies = host.statuses(5);
    for (r, &id) in replies.iter().zip(&order) {
        assert_eq!((r.id, r.error, r.value()), (id, 0, 2000 + i64::from(id)));
    }
    let blocks = host.fast_sync_read(xc330::GOAL_POSITION, 4, &order);
    let got: Vec<(u8, u8, i32)> = blocks
        .iter()
        .map(|(id, e, d)| (*id, *e, i32::from_le_bytes([d[0], d[1], d[2], d[3]])))
        .collect();
    let want: Vec<(u8, u8, i32)> = order
        .iter()
        .map(|&id| (id, 0, 2000 + i32::from(id)))
        .collect();
    assert_eq!(got, want);
    // The state read of the LEAP node: current, velocity, position of all 16.
    let state = host.fast_sync_read(xc330::STATE_ADDR, xc330::STATE_LEN, &ALL);
    assert_eq!(state.len(), 16);
    for (id, _, data) in &state {
        let s = xc330::State::decode(data).unwrap();
        assert_eq!(s.position, 2048, "servo {id}");
    }
    let s = sim.stats();
    assert_eq!(
        (s["sync_write"].as_str(), s["fast_sync_read"].as_str()),
        ("1", "2")
    );
}

#[test]
fn each_status_waits_for_the_return_delay_and_the_line() {
    // 16 statuses one after the other, each at least 500 us after the one before: a Sync Read
    // of all 16 cannot be complete before 8 ms; with Return Delay Time 0, the first status
    // still comes after the request's own bytes.
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    host.send(|out| packet::sync_read(xc330::PRESENT_POSITION, 4, &ALL, out));
    let sent = Instant::now();
    let ids: Vec<u8> = host.statuses(16).iter().map(|r| r.id).collect();
    let took = sent.elapsed();
    assert_eq!(ids, ALL);
    assert!(took >= Duration::from_micros(16 * 500), "{took:?}");

    let fast = Sim::start(&["--return-delay-us", "0"]);
    let mut host = fast.host(BAUD);
    assert_eq!(host.read(0, xc330::RETURN_DELAY_TIME, 1).value(), 0);
    host.send(|out| packet::sync_read(xc330::PRESENT_POSITION, 4, &ALL, out));
    assert_eq!(host.statuses(16).len(), 16);
}

#[test]
fn a_host_at_another_baud_rate_gets_no_answer() {
    let sim = Sim::start(&[]);
    let mut host = sim.host(1_000_000);
    host.send(|out| packet::ping(1, out));
    host.silence(Duration::from_millis(200));
    // Counted when the simulator gets to the bytes: waited for, not assumed after a pause.
    wait_for(PATIENCE, "a baud mismatch counted", || {
        (sim.counter("baud_mismatches") >= 1).then_some(())
    });
    drop(host);
    let mut host = sim.host(BAUD);
    host.send(|out| packet::ping(1, out));
    assert_eq!(host.status().id, 1);
    // The servos at 1 Mbit/s: the host at 4 Mbit/s loses them after the write's status.
    assert_eq!(host.write(1, xc330::BAUD_RATE, &[3]), 0);
    host.send(|out| packet::ping(1, out));
    host.silence(Duration::from_millis(200));
    drop(host);
    let mut slow = sim.host(1_000_000);
    slow.send(|out| packet::ping(1, out));
    assert_eq!(slow.status().id, 1);
}

#[test]
fn bad_bytes_are_dropped_and_counted_and_the_line_recovers() {
    let sim = Sim::start(&[]);
    let mut host = sim.host(BAUD);
    let mut out = [0u8; 32];
    let n = packet::read(4, xc330::PRESENT_POSITION, 4, &mut out).unwrap();
    let mut bad = out[..n].to_vec();
    bad[n - 1] ^= 0x55;
    host.send_raw(&bad);
    host.silence(Duration::from_millis(100));
    // Counted when the simulator gets to the bytes: waited for, then exactly once.
    wait_for(PATIENCE, "the CRC error counted", || {
        (sim.counter("crc_errors") >= 1).then_some(())
    });
    assert_eq!(sim.counter("crc_errors"), 1);
    host.send_raw(&[0x00, 0x13, 0xFF, 0x42, 0xFF, 0xFF, 0x00]);
    host.silence(Duration::from_millis(100));
    wait_for(PATIENCE, "the noise counted", || {
        (sim.counter("noise_bytes") >= 5).then_some(())
    });
    // A header with a long LEN that never completes: cut after the byte-to-byte time.
    host.send_raw(&[0xFF, 0xFF, 0xFD, 0x00, 0x04, 0x40, 0x00, 0x02]);
    // A pause beyond the byte-to-byte time (the simulator cuts when the next bytes come after
    // it: a minimum, not a race).
    std::thread::sleep(Duration::from_millis(20));
    assert_eq!(host.read(4, xc330::PRESENT_POSITION, 4).value(), 2048);
    assert_eq!(sim.counter("cut_packets"), 1);
    // Noise on the line: the host hears it, the servos drop it.
    sim.control_ok("noise 200");
    let heard = host.raw(Duration::from_millis(100));
    assert_eq!(heard.len(), 200);
    assert_eq!(host.read(4, xc330::PRESENT_POSITION, 4).value(), 2048);
    // Answered with CRC Error when the option says so.
    let answering = Sim::start(&["--crc-status"]);
    let mut host = answering.host(BAUD);
    host.send_raw(&bad);
    assert_eq!(host.status().error, 3);
}

#[test]
fn reg_write_and_action_bulk_read_and_write_and_factory_reset_work_as_documented() {
    let sim = Sim::start(&["--boot-ms", "100"]);
    let mut host = sim.host(BAUD);
    // Reg Write waits for Action (broadcast: silent).
    host.send(|out| packet::encode(2, instruction::REG_WRITE, &[65, 0, 1], out));
    assert_eq!(host.status().error, 0);
    assert_eq!(host.read(2, xc330::REGISTERED_INSTRUCTION, 1).value(), 1);
    assert_eq!(host.read(2, xc330::LED, 1).value(), 0);
    host.send(|out| packet::encode(BROADCAST_ID, instruction::ACTION, &[], out));
    host.silence(Duration::from_millis(50));
    assert_eq!(host.read(2, xc330::LED, 1).value(), 1);
    host.send(|out| packet::encode(2, instruction::ACTION, &[], out));
    assert_eq!(host.status().error, 2, "Action without Reg Write");

    // Bulk Write (LED of 1, Goal Position of 3), Bulk Read of both, one status each in order.
    let mut params = vec![1, 65, 0, 1, 0, 1];
    params.extend_from_slice(&[3, 116, 0, 4, 0]);
    params.extend_from_slice(&1900i32.to_le_bytes());
    host.send(|out| packet::encode(BROADCAST_ID, instruction::BULK_WRITE, &params, out));
    host.silence(Duration::from_millis(50));
    let read = [3, 116, 0, 4, 0, 1, 65, 0, 1, 0];
    host.send(|out| packet::encode(BROADCAST_ID, instruction::BULK_READ, &read, out));
    let replies = host.statuses(2);
    assert_eq!((replies[0].id, replies[0].value()), (3, 1900));
    assert_eq!((replies[1].id, replies[1].value()), (1, 1));

    // Factory Reset keeping ID and baud rate: the mode back at 3, the servo reboots.
    assert_eq!(host.write(5, xc330::OPERATING_MODE, &[5]), 0);
    host.send(|out| packet::encode(5, instruction::FACTORY_RESET, &[0x02], out));
    assert_eq!(host.status().error, 0);
    wait_for(Duration::from_secs(10), "servo 5 back", || {
        host.send(|out| packet::ping(5, out));
        host.statuses_within(1, Duration::from_millis(50)).pop()
    });
    assert_eq!(host.read(5, xc330::OPERATING_MODE, 1).value(), 3);
    // A broadcast Factory Reset of everything is ignored.
    host.send(|out| packet::encode(BROADCAST_ID, instruction::FACTORY_RESET, &[0xFF], out));
    host.silence(Duration::from_millis(50));
    assert_eq!(host.read(7, xc330::ID, 1).value(), 7);
}

#[test]
fn the_lite_hands_servos_report_their_own_model() {
    let sim = Sim::start(&["--model", "xl330-m077"]);
    let mut host = sim.host(BAUD);
    host.send(|out| packet::ping(0, out));
    let r = host.status();
    assert_eq!(
        u16::from_le_bytes([r.params[0], r.params[1]]),
        xc330::MODEL_XL330_M077
    );
    assert_eq!(host.read(0, xc330::CURRENT_LIMIT, 2).value(), 1750);
}

#[test]
fn servos_before_firmware_46_do_not_take_fast_sync_read() {
    let sim = Sim::start(&["--firmware", "45"]);
    let mut host = sim.host(BAUD);
    assert!(host
        .fast_sync_read_raw(xc330::PRESENT_POSITION, 4, &ALL)
        .is_empty());
    host.send(|out| packet::sync_read(xc330::PRESENT_POSITION, 4, &ALL, out));
    assert_eq!(host.statuses(16).len(), 16);
}
