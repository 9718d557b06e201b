//! A loaded host delays the hand's frames on their way to the node (a serial line, a pty, a
//! simulator's threads not scheduled), then delivers them in a burst, while the hand streamed
//! without a gap. The loop tells that from a hand that really went silent by the link's
//! bus-time stamps (slcan `Z1`; here the timed local bus): frames delayed by 60 ms, stamped when
//! they were on the bus, count no missed period and never bring the hand up again; the same
//! delays with stamps not trusted (`late_frame_limit_ms = 0`, the loop before this change) do;
//! a real 60 ms silence of the hand still counts its missed periods and restarts it.
#![allow(clippy::unwrap_used)]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

mod common;

use common::{run_v3, Recorder};
use teleop_allegro::AllegroConfig;
use teleop_allegro_protocol::{doc, Generation, JointCalibration, JOINTS};
use teleop_can_link::local::LocalBus;
use teleop_can_link::{Bitrate, CanFrame, CanLink};

const PERIOD: Duration = Duration::from_millis(3);
/// Every this many periods the hand's frames stop for [`STALL`].
const EVERY: u32 = 60;
const STALL: Duration = Duration::from_millis(60);

#[derive(Clone, Copy, PartialEq)]
enum Stall {
    /// The frames wait (the hand sent them on time): they come in a burst, each at its bus time.
    Late,
    /// The hand is silent: those periods are never sent.
    Silent,
}

/// A v3 hand streaming every 3 ms after SYSTEM_ON, stalling as `stall` says.
fn hand(bus: &LocalBus, stall: Stall, stop: Arc<AtomicBool>) {
    let mut end = bus.end();
    std::thread::spawn(move || {
        let cal = JointCalibration::default();
        let order = Generation::V3.torque_order();
        let mut t0 = None;
        let mut k = 0u32;
        while !stop.load(Ordering::SeqCst) {
            while let Some(frame) = end.recv(Duration::ZERO).unwrap() {
                match doc::Request::decode(&frame, order) {
                    Ok(doc::Request::SystemOn) => t0 = t0.or(Some(Instant::now())),
                    Ok(doc::Request::SystemOff) => t0 = None,
                    _ => {}
                }
            }
            let Some(start) = t0 else {
                std::thread::sleep(Duration::from_millis(1));
                continue;
            };
            let due = start + PERIOD * k;
            let now = Instant::now();
            if due > now {
                std::thread::sleep((due - now).min(Duration::from_millis(1)));
                continue;
            }
            if k > 0 && k.is_multiple_of(EVERY) {
                // Not scheduled for a while.
                std::thread::sleep(STALL);
                if stall == Stall::Silent {
                    k += (STALL.as_millis() / PERIOD.as_millis()) as u32;
                    continue;
                }
            }
            for finger in 0..4u8 {
                let frame = doc::Report::Position {
                    finger,
                    raw: [cal.rad_to_doc_raw(0.1); 4],
                }
                .encode::<CanFrame>(doc::ID_DEVICE_MAIN);
                end.send_at(&frame, due).unwrap();
            }
            k += 1;
        }
    });
}

fn run(stall: Stall, late_frame_limit_ms: u64) -> Recorder {
    let bus = LocalBus::with_timing(Bitrate(1_000_000));
    let stop = Arc::new(AtomicBool::new(false));
    hand(&bus, stall, stop.clone());
    let config = AllegroConfig {
        reconnect_backoff_ms: [20, 100],
        late_frame_limit_ms,
        ..Default::default()
    };
    let host = run_v3(&bus, config, Duration::from_millis(1500));
    stop.store(true, Ordering::SeqCst);
    host
}

#[test]
fn frames_delayed_on_the_way_but_stamped_on_time_are_not_missed_periods() {
    let host = run(Stall::Late, 500);
    let c = host.cycles.last().unwrap().counters;
    assert!(host.downs.is_empty(), "no restart: {:?}", host.downs);
    assert_eq!(
        (c.missing_cycles, c.lost_frames, c.reconnects),
        (0, 0, 0),
        "{c:?}"
    );
    // Every period of the hand made a cycle, the late ones included, and the waits for them
    // were counted as late.
    assert!(
        host.cycles.len() > 350,
        "{} cycles in 1.5 s",
        host.cycles.len()
    );
    assert!(c.late_periods >= 5, "{c:?}");
    assert_eq!(JOINTS, 16);
}

#[test]
fn the_same_delays_without_trusting_stamps_restart_the_hand() {
    // The loop as it was: every 10 ms without a frame is a missed period, four in a row a fault.
    let host = run(Stall::Late, 0);
    assert!(
        !host.downs.is_empty(),
        "60 ms without frames counted as missed periods"
    );
    assert!(host.downs[0].contains("in a row"), "{:?}", host.downs);
}

#[test]
fn a_hand_that_really_went_silent_is_still_missed_and_restarted() {
    let host = run(Stall::Silent, 500);
    assert!(!host.downs.is_empty(), "the hand's silence is a fault");
    assert!(host.downs[0].contains("in a row"), "{:?}", host.downs);
    let c = host.cycles.last().unwrap().counters;
    assert!(c.missing_cycles >= 4);
    assert_eq!(c.late_periods, 0, "a real silence is not late: {c:?}");
}
