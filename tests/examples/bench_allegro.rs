//! Benchmark: the Allegro node's loop on the hand's 333 Hz stream as the CAN bus sees it, the
//! bus load, the glove sample -> torque frame latency and the hand sample -> glove force latency.
//!
//! Method: the simulated Allegro (`teleop_sim_allegro::Sim`, v4, the ball) runs in this process behind
//! its simulated slcan adapter on a pseudo-terminal, as `teleop-sim-allegro` does; the real
//! `teleop-allegro` process (release, `config/allegro.toml`: slcan, 3 ms period) drives it
//! through `SlcanLink`, `teleop-retarget` (`config/allegro/retarget.toml` with the One Euro filter
//! opened to 1 kHz and the slew limit at 100 travel/s, so that the path is measured, not the
//! filter's lag) and `teleop-feedback` (`config/allegro/feedback.toml`) run as processes. A
//! sniffer end on the simulated bus stamps every frame with CLOCK_MONOTONIC when it has ended on
//! the bus (frames are serialised at 1 Mbit/s with their exact stuffed length).
//!
//! 1. Reaction = the end of the torque frame of the fourth finger (0x18C) - the end of the
//!    fourth finger's position frame (0x08C) it answers: one period's frames up the adapter's
//!    pty, the node's wait for all four, the PD step, four torque frames down the pty, the
//!    adapter and the bus. Period = between consecutive 0x18C frames (nominal 3 ms).
//! 2. Bus load = frame bits on the bus (exact stuffing, with intermission) / 1 Mbit/s.
//! 3. Glove -> torque: this process publishes `glove/state` at 300 Hz (as the glove node does)
//!    and every 200-300 ms (random) steps the middle-finger channel between 900 and 300; latency
//!    = the end of the first middle-finger torque frame (0x184) whose joint 1 PWM moved more than
//!    150 counts from its value before the step - the step's publish stamp.
//! 4. Hand sample -> glove force: each `glove/force_command` received, its receive time - its
//!    `origin_ns` (the node's receive time of the period's last position frame, carried through
//!    `hand/state` by the feedback node); and `hand/state` stamp - origin (the node alone).
//!
//! 20 s after 2 s warm-up.
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example bench_allegro`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use teleop_allegro_protocol::{v4, Generation};
use teleop_can_link::{timing, CanLink};
use teleop_e2e::bench::{drive_hand_pipeline, late_periods, loadavg, percentiles, step_reactions};
use teleop_e2e::Sandbox;
use teleop_runtime::now_ns;
use teleop_sim_allegro::adapter::AckStyle;
use teleop_sim_allegro::firmware::{Firmware, FirmwareOptions};
use teleop_sim_allegro::hand::{Hand, HandParams, VirtualObject};
use teleop_sim_allegro::{Sim, SimOptions};

const WARM_UP: Duration = Duration::from_secs(2);
const SECONDS: u64 = 20;
/// The glove's middle channel (little, ring, middle, index, thumb, thumb rotation).
const MIDDLE: usize = 2;

/// One frame on the bus: when it ended there (ns, CLOCK_MONOTONIC), its id, its bits and for a
/// middle-finger torque frame joint 1's PWM.
#[derive(Clone, Copy)]
struct Seen {
    t_ns: u64,
    id: u16,
    bits: u32,
    pwm1: i16,
}

fn main() {
    println!(
        "Allegro (v4, simulated slcan adapter on a pty), {SECONDS} s after {WARM_UP:?} warm-up"
    );
    println!("  load average (1 min) before: {}", loadavg());
    let sandbox = Sandbox::new();
    sandbox.session("launch/allegro.toml");
    let dir = sandbox.dir.path();

    let hand = Hand::allegro(HandParams::default(), Some(VirtualObject::ball())).unwrap();
    let sim = Sim::start(
        Firmware::new(FirmwareOptions::new(Generation::V4), hand),
        SimOptions {
            slcan: Some(dir.join("teleop-allegro")),
            socket: None,
            ack_style: AckStyle::Canable,
            seed: 1,
        },
    )
    .unwrap();
    let seen = Arc::new(Mutex::new(Vec::<Seen>::with_capacity(200_000)));
    let recording = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    let sniffer = {
        let mut end = sim.bus().end();
        let (seen, recording, stop) = (seen.clone(), recording.clone(), stop.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::SeqCst) {
                if let Ok(Some(frame)) = end.recv(Duration::from_millis(50)) {
                    let t_ns = now_ns();
                    if !recording.load(Ordering::SeqCst) {
                        continue;
                    }
                    let id = u16::try_from(frame.raw_id()).unwrap_or(u16::MAX);
                    let pwm1 = match v4::Request::decode(&frame) {
                        Ok((_, v4::Request::Torque { finger: 1, pwm })) => pwm[1],
                        _ => 0,
                    };
                    let bits = timing::frame_bits_exact(&frame);
                    seen.lock().unwrap().push(Seen {
                        t_ns,
                        id,
                        bits,
                        pwm1,
                    });
                }
            }
        })
    };

    // Glove samples at 300 Hz, the middle channel stepping every 200-300 ms.
    let drive = drive_hand_pipeline(&sandbox, "allegro", &[], WARM_UP, SECONDS, MIDDLE, |m| {
        recording.store(m, Ordering::SeqCst)
    });
    stop.store(true, Ordering::SeqCst);
    sniffer.join().unwrap();
    let seen = seen.lock().unwrap().clone();
    report(
        &seen,
        &drive.steps,
        drive.state_latency,
        drive.force_latency,
    );
    println!("  load average (1 min) after: {}", loadavg());
    drop(sim);
}

fn report(seen: &[Seen], steps: &[(u64, bool)], state: Vec<u64>, force: Vec<u64>) {
    println!("        times in us: p50 / p99 / max");
    // 1. Reaction and period.
    let mut reaction = Vec::new();
    let mut torque_times = Vec::new();
    let mut last_position = None;
    for f in seen {
        match f.id {
            0x08C => last_position = Some(f.t_ns),
            0x18C => {
                if let Some(t) = last_position.take() {
                    reaction.push(f.t_ns - t);
                }
                torque_times.push(f.t_ns);
            }
            _ => {}
        }
    }
    let periods: Vec<u64> = torque_times.windows(2).map(|w| w[1] - w[0]).collect();
    let span_s = match (seen.first(), seen.last()) {
        (Some(a), Some(b)) if b.t_ns > a.t_ns => (b.t_ns - a.t_ns) as f64 * 1e-9,
        _ => 1.0,
    };
    let positions = seen.iter().filter(|f| f.id == 0x08C).count();
    println!(
        "  position periods {} ({:.1}/s), torque sets {} ({:.1}/s), periods without torque {}",
        positions,
        positions as f64 / span_s,
        torque_times.len(),
        torque_times.len() as f64 / span_s,
        positions.saturating_sub(reaction.len())
    );
    println!(
        "  last position frame -> last torque frame (reaction)   {}",
        percentiles(reaction)
    );
    println!(
        "  torque set period (nominal 3000 us)                   {}",
        percentiles(periods.clone())
    );
    println!("  torque {}", late_periods(&periods, [4.5, 6.0, 10.0]));
    // 2. Bus load.
    let bits: u64 = seen.iter().map(|f| u64::from(f.bits)).sum();
    println!(
        "  bus load: {:.1} % of 1 Mbit/s ({:.0} frames/s, {:.0} bits/s)",
        bits as f64 / span_s / 1e6 * 100.0,
        seen.len() as f64 / span_s,
        bits as f64 / span_s
    );
    // 3. Glove -> torque.
    let middle: Vec<(u64, i32)> = seen
        .iter()
        .filter(|f| f.id == 0x184)
        .map(|f| (f.t_ns, i32::from(f.pwm1)))
        .collect();
    let glove = step_reactions(&middle, steps, 150);
    println!(
        "  glove/state published -> middle torque frame carrying the step ({} of {} steps)  {}",
        glove.len(),
        steps.len(),
        percentiles(glove)
    );
    println!(
        "  position frame at the node -> hand/state published    {}",
        percentiles(state)
    );
    println!(
        "  position frame at the node -> glove/force_command received  {}",
        percentiles(force)
    );
}
