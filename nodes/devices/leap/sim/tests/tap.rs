//! The wire tap: a host on the simulator's pty writes goals and reads the state as the node
//! does; the tap reports both requests with the goals and the times their last bytes ended on
//! the line, and the reply with the time it left (the request's end, the return delay and the
//! reply's own bytes later); beyond its capacity it counts instead of keeping.
#![allow(clippy::unwrap_used)]

mod common;

use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use common::{Host, BAUD};
use teleop_leap_protocol::packet::{self, instruction};
use teleop_leap_protocol::{wire, xc330};
use teleop_sim_leap::bus::{BusOptions, Missing};
use teleop_sim_leap::hand::leap_limits;
use teleop_sim_leap::serve::{Tap, TapEvent};
use teleop_sim_leap::servo::ServoOptions;
use teleop_sim_leap::table::Model;
use teleop_sim_leap::{Sim, SimOptions};

/// A clock that ticks with CLOCK_MONOTONIC (as `Instant` does on Linux), ns.
fn clock() -> u64 {
    static START: OnceLock<Instant> = OnceLock::new();
    START.get_or_init(Instant::now).elapsed().as_nanos() as u64
}

#[test]
fn the_tap_reports_requests_with_goals_and_replies_with_their_times_and_counts_what_it_cannot_hold()
{
    let sandbox = teleop_e2e::Sandbox::new();
    let dir = &sandbox.dir;
    let tap = Arc::new(Tap::new(4, clock));
    let _sim = Sim::start(SimOptions {
        link: dir.path().join("leap"),
        model: Model::Xc330M288,
        baud_code: xc330::BaudRate::from_bps(BAUD).unwrap().code(),
        return_delay: 250,
        servo: ServoOptions::default(),
        bus: BusOptions {
            fast_sync_missing: Missing::Omit,
            crc_status: false,
        },
        limits: leap_limits().unwrap(),
        object: None,
        seed: 1,
        tap: Some(tap.clone()),
    })
    .unwrap();
    let mut host = Host::open(&dir.path().join("leap"), BAUD);
    let ids: Vec<u8> = (0..16).collect();
    let goals: Vec<(u8, i32)> = ids.iter().map(|&id| (id, 2000 + i32::from(id))).collect();
    host.sync_write(xc330::GOAL_POSITION, &goals, 4);
    let reply = host.fast_sync_read_raw(126, 10, &ids);
    assert_eq!(reply.len(), wire::fast_sync_reply_len(16, 10));
    host.send(|out| packet::ping(3, out));
    host.status();
    // The ping's status does not fit (the host may have read it before the simulator reported
    // it): counted, not kept.
    let until = Instant::now() + common::WAIT;
    while tap.overflow() == 0 && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(tap.overflow(), 1);

    let mut events = Vec::new();
    tap.drain_into(&mut events);
    let [TapEvent::Request {
        end_ns: write_end,
        instruction: instruction::SYNC_WRITE,
        goals: Some(written),
    }, TapEvent::Request {
        end_ns: read_end,
        instruction: instruction::FAST_SYNC_READ,
        goals: None,
    }, TapEvent::Written {
        due_ns,
        written_ns,
        len,
        id: packet::BROADCAST_ID,
    }, TapEvent::Request {
        instruction: instruction::PING,
        ..
    }] = events[..]
    else {
        panic!("events: {events:?}");
    };
    assert_eq!(written, std::array::from_fn(|id| Some(2000 + id as i32)));
    // The read's own 30 bytes came after the write had ended.
    assert!(read_end - write_end >= wire::wire_time_ns(wire::sync_read_len(16), BAUD));
    // The reply left 500 us and its 232 bytes (580 us) after the read ended, not before.
    assert_eq!(len, reply.len());
    let due = read_end + 500_000 + wire::wire_time_ns(len, BAUD);
    assert!(due_ns.abs_diff(due) < 1_000, "due {due_ns} vs {due}");
    assert!(written_ns >= due_ns);
    // Drained, the tap holds again.
    host.send(|out| packet::ping(3, out));
    host.status();
    // The host may have read the status before the simulator reported it.
    events.clear();
    let until = Instant::now() + common::WAIT;
    while events.len() < 2 && Instant::now() < until {
        tap.drain_into(&mut events);
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(
        matches!(
            events[..],
            [
                TapEvent::Request {
                    instruction: instruction::PING,
                    ..
                },
                TapEvent::Written { id: 3, .. }
            ]
        ),
        "{events:?}"
    );
    assert_eq!(tap.overflow(), 1);
}
