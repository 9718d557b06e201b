//! A document-protocol hand answers `QUERY_STATE_DATA` as the device document's command table
//! says: `ID_CMD_QUERY_STATE_DATA` (0x0E) from `ID_DEVICE_SUB_01..04` to `ID_DEVICE_MAIN`, not
//! with its stream's position frames (0x0F). The node tells one from the other: a state answer
//! is neither a finger frame of the period (no positions taken from it, no period counted
//! missing) nor an unknown frame, whatever its payload (the document gives none: 8 bytes laid
//! out as a position frame, or none at all). In-process against a scripted hand on a local bus.
#![allow(clippy::unwrap_used)]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

mod common;

use common::run_v3;
use teleop_allegro::AllegroConfig;
use teleop_allegro_protocol::{doc, Generation, JointCalibration, JOINTS};
use teleop_can_link::local::LocalBus;
use teleop_can_link::{CanFrame, CanLink};

/// What a state answer carries in this test.
#[derive(Clone, Copy)]
enum Payload {
    /// Four u16 counts, as a position frame would (here counts far from the hand's pose).
    Counts,
    /// None.
    Empty,
}

/// A v3 hand: streams its four position frames every 3 ms after SYSTEM_ON, answers
/// QUERY_STATE with four 0x0E frames, and sends four more every 30 ms while streaming (as if
/// another tool on the bus asked).
fn scripted_hand(bus: &LocalBus, payload: Payload, stop: Arc<AtomicBool>, q0: [f64; JOINTS]) {
    let mut end = bus.end();
    std::thread::spawn(move || {
        let cal = JointCalibration::default();
        let order = Generation::V3.torque_order();
        let mut streaming = false;
        let mut next = Instant::now();
        let mut periods = 0u64;
        let state_answer = |end: &mut dyn CanLink| {
            for finger in 0..4u8 {
                let id = doc::id(
                    doc::CMD_QUERY_STATE_DATA,
                    doc::ID_DEVICE_MAIN,
                    doc::ID_DEVICE_SUB_01 + finger,
                );
                let data: &[u8] = match payload {
                    Payload::Counts => &[0, 0, 0, 0, 0xFF, 0xFF, 0, 0],
                    Payload::Empty => &[],
                };
                end.send(&CanFrame::standard(id, data).unwrap()).unwrap();
            }
        };
        while !stop.load(Ordering::SeqCst) {
            while let Some(frame) = end.recv(Duration::ZERO).unwrap() {
                match doc::Request::decode(&frame, order) {
                    Ok(doc::Request::SystemOn) => streaming = true,
                    Ok(doc::Request::SystemOff) => streaming = false,
                    Ok(doc::Request::QueryState) => state_answer(&mut end),
                    _ => {}
                }
            }
            if !teleop_e2e::period_due(&mut next, Duration::from_millis(3)) {
                continue;
            }
            if !streaming {
                continue;
            }
            for finger in 0..4u8 {
                let b = usize::from(finger) * 4;
                let frame = doc::Report::Position {
                    finger,
                    raw: [0, 1, 2, 3].map(|i| cal.rad_to_doc_raw(q0[b + i])),
                }
                .encode::<CanFrame>(doc::ID_DEVICE_MAIN);
                end.send(&frame).unwrap();
            }
            periods += 1;
            if periods.is_multiple_of(10) {
                state_answer(&mut end);
            }
        }
    });
}

fn run_against(payload: Payload) {
    let bus = LocalBus::new();
    let stop = Arc::new(AtomicBool::new(false));
    let mut q0 = [0.0; JOINTS];
    for (j, q) in q0.iter_mut().enumerate() {
        *q = 0.04 * j as f64 - 0.2;
    }
    scripted_hand(&bus, payload, stop.clone(), q0);
    let config = AllegroConfig {
        // A generous timeout: this test is about what the frames are, not their timing.
        frame_timeout_ms: 200,
        ..Default::default()
    };
    let host = run_v3(&bus, config, Duration::from_millis(900));
    stop.store(true, Ordering::SeqCst);

    assert!(host.downs.is_empty(), "{:?}", host.downs);
    let last = host.cycles.last().expect("cycles ran");
    assert!(host.cycles.len() > 100, "{} cycles", host.cycles.len());
    let c = last.counters;
    assert_eq!(
        (c.unknown_frames, c.bad_frames),
        (0, 0),
        "state answers are known frames: {c:?}"
    );
    assert_eq!(
        (c.missing_cycles, c.lost_frames),
        (0, 0),
        "state answers are not finger frames of a period: {c:?}"
    );
    for cycle in &host.cycles {
        for (j, (q, want)) in cycle.q.iter().zip(q0).enumerate() {
            assert!(
                (q - want).abs() < 1e-3,
                "joint {j} at {q} rad: positions come from the stream only"
            );
        }
    }
}

#[test]
fn state_answers_with_counts_are_neither_positions_nor_unknown() {
    run_against(Payload::Counts);
}

#[test]
fn state_answers_without_payload_are_neither_positions_nor_unknown() {
    run_against(Payload::Empty);
}
