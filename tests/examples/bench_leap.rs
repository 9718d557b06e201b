//! Benchmark: the LEAP node's full-state loop on the simulated Dynamixel bus at 4 Mbit/s, the
//! glove sample -> goal position latency, the servo current -> glove force latency, and the
//! shipped LEAP API's way (ROBOTIS's Python SDK) against the same simulator.
//!
//! Method: the simulated LEAP Hand (`teleop_sim_leap::Sim`: 16 XC330-M288, the ball, Return
//! Delay Time 250 = 500 us at start as the servos ship) serves its bus on a pseudo-terminal in
//! this process, as `teleop-sim-leap` does, timing every byte at the line's baud rate; its wire
//! tap (`teleop_sim_leap::serve::Tap`) stamps every request when its last byte ended on the line
//! and every status when the simulator wrote it (CLOCK_MONOTONIC). The real `teleop-leap`
//! (release, `config/leap.toml`: 4 Mbit/s, rate_hz 500, Return Delay Time written 0 at
//! bring-up, SCHED_OTHER), `teleop-retarget` (`config/leap/retarget.toml` with the One Euro
//! filter opened to 1 kHz and the slew limit at 100 travel/s, so that the path is measured, not
//! the filter's lag) and `teleop-feedback` (`config/leap/feedback.toml`) run as processes.
//!
//! 1. Full-state loop: a cycle = the node's Sync Write of 16 goal positions, then one Fast Sync
//!    Read of present current, velocity and position (126, 10 bytes) of all 16 servos answered
//!    whole (one 232-byte reply) before the next Sync Write. Cycles per second over the
//!    window; period = between consecutive Sync Writes' ends on the line; periods late by more
//!    than 1.5x / 2x / 5x the nominal; exchange = Sync Write's end -> its reply written. The
//!    wire-time floor of one cycle = its bytes on the line x 2.5 us + the return delay (the
//!    protocol crate's `wire` sizes). Then the node alone (no commands: it holds) with
//!    `rate_hz` 1000 and 2000 (more than the line allows: the loop runs back to back), 10 s each.
//! 2. Glove -> goal position: this process publishes `glove/state` at 300 Hz and every 200-300
//!    ms (random) steps the middle channel between 900 and 300; latency = the end on the line
//!    of the first Sync Write whose goal for servo 5 (middle MCP forward) moved more than 100
//!    counts (8.8 degrees) from its value before the step - the step's publish stamp.
//! 3. Servo current -> glove force: each `glove/force_command` received, its receive time - its
//!    `origin_ns` (the node's stamp of the cycle's reply, carried through `hand/state` by the
//!    feedback node); and `hand/state` stamp - origin (the node alone).
//! 4. The shipped API's way, the node stopped first (one bus, one master):
//!    `bench_leap_sdk.py` (next to this file) brings the hand up as the LEAP API does, then loops
//!    without sleeping over one GroupSyncWrite of Goal Position (`write_desired_pos`) and one
//!    `GroupSyncRead(126, 10).fastSyncRead()` with the values taken out (`read_pos_vel_cur`);
//!    timed by the same tap; twice, with the servos' Return Delay Time at 0 (as the API's
//!    readme advises, and as the node left it) and at 500 us (as the servos ship: the API never
//!    writes it). Skipped, with the reason, without python3 or `dynamixel_sdk`.
//!
//! 20 s after 2 s warm-up for 1-3, 10 s after 2 s for the others.
//!
//! Run: `cargo build --release --workspace --bins --examples && cargo run --release -p teleop-e2e --example bench_leap`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::cell::Cell;
use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use teleop_e2e::bench::{
    drive_hand_pipeline, interrupt_all, late_periods, loadavg, percentiles, spawn_quiet,
    step_reactions,
};
use teleop_e2e::netns::{python_module_missing, run_for};
use teleop_e2e::Sandbox;
use teleop_leap_protocol::packet::{instruction, BROADCAST_ID};
use teleop_leap_protocol::{wire, xc330};
use teleop_runtime::now_ns;
use teleop_sim_kit::Object;
use teleop_sim_leap::bus::{BusOptions, Missing};
use teleop_sim_leap::hand::leap_limits;
use teleop_sim_leap::serve::{Tap, TapEvent};
use teleop_sim_leap::servo::ServoOptions;
use teleop_sim_leap::table::Model;
use teleop_sim_leap::{Sim, SimOptions};

const WARM_UP: Duration = Duration::from_secs(2);
const SECONDS: u64 = 20;
/// Seconds of each raised-rate case and of the SDK's loop.
const SHORT: u64 = 10;
/// The glove's middle channel (little, ring, middle, index, thumb, thumb rotation).
const MIDDLE: usize = 2;
/// Servo 5: the middle finger's MCP forward (flexion).
const MIDDLE_MCP: usize = 5;
/// Counts a goal must move to count as the step's (100 x 0.088 degrees).
const GOAL_STEP: i32 = 100;
const BAUD: u32 = 4_000_000;
const SERVOS: usize = 16;
/// Present Current, Velocity and Position: 10 bytes from 126.
const STATE_LEN: usize = 10;
/// The node's Return Delay Time (`config/leap.toml`, `return_delay_us`).
const RETURN_DELAY_US: u64 = 0;
/// The servos' Return Delay Time register at power-up (250 x 2 us).
const SHIPPED_RETURN_DELAY: u8 = 250;

fn main() {
    println!(
        "LEAP Hand (16 x XC330-M288 simulated on a pty at 4 Mbit/s), {SECONDS} s after {WARM_UP:?} warm-up"
    );
    println!("  load average (1 min) before: {}", loadavg());
    floor();
    let sandbox = Sandbox::new();
    sandbox.session("launch/leap.toml");
    let dir = sandbox.dir.path();
    let link = dir.join("teleop-leap");

    let tap = Arc::new(Tap::new(1 << 16, now_ns));
    let sim = Sim::start(SimOptions {
        link: link.clone(),
        model: Model::Xc330M288,
        baud_code: xc330::BaudRate::from_bps(BAUD).unwrap().code(),
        return_delay: SHIPPED_RETURN_DELAY,
        servo: ServoOptions::default(),
        bus: BusOptions {
            fast_sync_missing: Missing::Truncate,
            crc_status: false,
        },
        limits: leap_limits().unwrap(),
        object: Some(Object::Ball),
        seed: 1,
        tap: Some(tap.clone()),
    })
    .unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let collector = {
        let (tap, stop) = (tap.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut events = Vec::with_capacity(1 << 20);
            while !stop.load(Ordering::SeqCst) {
                tap.drain_into(&mut events);
                std::thread::sleep(Duration::from_millis(10));
            }
            tap.drain_into(&mut events);
            events
        })
    };

    // 1-3: the pipeline at the configured 500 Hz.
    let (from, to) = (Cell::new(0), Cell::new(0));
    let drive = drive_hand_pipeline(&sandbox, "leap", &[], WARM_UP, SECONDS, MIDDLE, |m| {
        if m && from.get() == 0 {
            from.set(now_ns());
        }
        if !m && from.get() != 0 && to.get() == 0 {
            to.set(now_ns());
        }
    });
    let pipeline = (from.get(), to.get());
    // 1: the node alone at raised rates.
    let mut raised = Vec::new();
    for rate in [1000, 2000] {
        raised.push((rate, node_alone(&sandbox, rate)));
    }
    // 4: the shipped API's way, with the Return Delay Time its readme advises (0, as the node
    // left it) and as the servos ship (the API never writes it).
    let mut sdk = Vec::new();
    for delay in [0, SHIPPED_RETURN_DELAY] {
        sim.with_bus(|bus, _| {
            for id in 0..SERVOS as u8 {
                let error = bus
                    .servo_mut(id)
                    .map(|s| s.write(xc330::RETURN_DELAY_TIME, &[delay]));
                assert_eq!(error, Some(0), "Return Delay Time of servo {id}");
            }
        });
        sdk.push((delay, sdk_loop(&link)));
    }

    stop.store(true, Ordering::SeqCst);
    let events = collector.join().unwrap();
    drop(sim);

    println!("        times in us: p50 / p99 / max");
    println!("1-3. the pipeline, config/leap.toml (rate_hz 500)");
    let goals = full_state_loop(&events, pipeline, Some(2_000_000));
    let middle: Vec<(u64, i32)> = goals
        .iter()
        .filter_map(|&(t, g)| g[MIDDLE_MCP].map(|c| (t, c)))
        .collect();
    let glove = step_reactions(&middle, &drive.steps, GOAL_STEP);
    println!(
        "  glove/state published -> Sync Write carrying the step ended ({} of {} steps)  {}",
        glove.len(),
        drive.steps.len(),
        percentiles(glove)
    );
    println!(
        "  reply at the node -> hand/state published              {}",
        percentiles(drive.state_latency)
    );
    println!(
        "  reply at the node -> glove/force_command received      {}",
        percentiles(drive.force_latency)
    );
    for (rate, window) in raised {
        println!("1. the node alone (no commands), rate_hz {rate}");
        full_state_loop(&events, window, Some(1_000_000_000 / u64::from(rate)));
    }
    for (delay, run) in sdk {
        let delay_us = wire::return_delay_us(delay);
        match run {
            Ok(window) => {
                println!(
                    "4. the shipped API's way: dynamixel_sdk GroupSyncWrite + GroupSyncRead(126, 10).fastSyncRead(), no sleep, return delay {delay_us} us"
                );
                full_state_loop(&events, window, None);
            }
            Err(why) => println!("4. the shipped API's way: skipped: {why}"),
        }
    }
    println!("  tap events lost (full): {}", tap.overflow());
    println!("  load average (1 min) after: {}", loadavg());
}

/// Prints the wire-time floor of one full-state cycle at 4 Mbit/s.
fn floor() {
    let write = wire::sync_write_len(SERVOS, 4);
    let read = wire::sync_read_len(SERVOS);
    let reply = wire::fast_sync_reply_len(SERVOS, STATE_LEN);
    let bytes = write + read + reply;
    let delay_ns = |us: u64| us * 1000;
    let at = |delay_us: u64| wire::wire_time_ns(bytes, BAUD) + delay_ns(delay_us);
    let shipped = u64::from(wire::return_delay_us(SHIPPED_RETURN_DELAY));
    println!(
        "  wire-time floor of one cycle: Sync Write {write} + Fast Sync Read {read} + reply {reply} = {bytes} bytes x {:.1} us",
        wire::byte_time_ns(BAUD) as f64 / 1000.0
    );
    for (what, us) in [("the node's", RETURN_DELAY_US), ("the shipped", shipped)] {
        println!(
            "    + return delay {us} us ({what}) = {:.0} us: at most {:.0} cycles/s",
            at(us) as f64 / 1000.0,
            1e9 / at(us) as f64
        );
    }
}

/// Runs the node alone with `rate_hz` = `rate` for the warm-up and [`SHORT`] s; returns the
/// measured window (CLOCK_MONOTONIC ns).
fn node_alone(sandbox: &Sandbox, rate: u32) -> (u64, u64) {
    let config = std::fs::read_to_string(sandbox.dir.path().join("config/leap.toml"))
        .unwrap()
        .replace("rate_hz = 500", &format!("rate_hz = {rate}"));
    assert!(config.contains(&format!("rate_hz = {rate}")), "rate_hz");
    let name = format!("config/leap-{rate}.toml");
    sandbox.write(&name, &config);
    let mut node = [spawn_quiet(sandbox, "teleop-leap", &name, &[])];
    std::thread::sleep(WARM_UP);
    let from = now_ns();
    std::thread::sleep(Duration::from_secs(SHORT));
    let to = now_ns();
    interrupt_all(&mut node);
    (from, to)
}

/// Runs `bench_leap_sdk.py` on the bus; returns its loop's window (CLOCK_MONOTONIC ns, as
/// Python's `time.monotonic_ns`), or why it did not run.
fn sdk_loop(link: &Path) -> Result<(u64, u64), String> {
    if let Some(why) = python_module_missing("dynamixel_sdk") {
        return Err(why);
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/bench_leap_sdk.py");
    let (status, out, err) = run_for(
        Command::new("python3")
            .arg(&script)
            .arg(link)
            .arg(WARM_UP.as_secs().to_string())
            .arg(SHORT.to_string()),
        Duration::from_secs(SHORT + 60),
    );
    if !status.is_some_and(|s| s.success()) {
        return Err(format!("{script:?} failed ({status:?}): {out} {err}"));
    }
    print!("  {out}");
    let words: Vec<&str> = out
        .lines()
        .find_map(|l| l.strip_prefix("window "))
        .ok_or_else(|| format!("no window in {out:?}"))?
        .split_whitespace()
        .collect();
    match words[..] {
        [from, to, ..] => Ok((
            from.parse().map_err(|e| format!("{from}: {e}"))?,
            to.parse().map_err(|e| format!("{to}: {e}"))?,
        )),
        _ => Err(format!("window: {words:?}")),
    }
}

/// Prints the full-state loop within `(from, to)`: cycles per second, period (with late
/// periods against `nominal` ns), exchange; returns each Sync Write of Goal Position there:
/// its end on the line and its goals.
fn full_state_loop(
    events: &[TapEvent],
    (from, to): (u64, u64),
    nominal: Option<u64>,
) -> Vec<(u64, [Option<i32>; SERVOS])> {
    let whole = wire::fast_sync_reply_len(SERVOS, STATE_LEN);
    let mut writes = Vec::new();
    let mut cycles = 0u64;
    let mut reads = 0u64;
    let mut replies = 0u64;
    let mut exchange = Vec::new();
    let mut turnaround = Vec::new();
    let mut late_writes = Vec::new();
    // The Sync Write of the cycle under way and whether its read was asked.
    let mut open: Option<(u64, bool)> = None;
    let mut last_reply = None;
    for e in events {
        match *e {
            TapEvent::Request {
                end_ns,
                instruction: instruction::SYNC_WRITE,
                goals: Some(goals),
            } if (from..to).contains(&end_ns) => {
                writes.push((end_ns, goals));
                open = Some((end_ns, false));
                if let Some(r) = last_reply.take() {
                    turnaround.push(end_ns.saturating_sub(r));
                }
            }
            TapEvent::Request {
                end_ns,
                instruction: instruction::FAST_SYNC_READ,
                ..
            } if (from..to).contains(&end_ns) => {
                reads += 1;
                if let Some((_, asked)) = open.as_mut() {
                    *asked = true;
                }
            }
            TapEvent::Written {
                due_ns,
                written_ns,
                len,
                id: BROADCAST_ID,
            } if (from..to).contains(&due_ns) => {
                replies += 1;
                late_writes.push(written_ns.saturating_sub(due_ns));
                if let (true, Some((w, true))) = (len == whole, open.take()) {
                    cycles += 1;
                    exchange.push(written_ns.saturating_sub(w));
                    last_reply = Some(written_ns);
                }
            }
            _ => {}
        }
    }
    let periods: Vec<u64> = writes.windows(2).map(|w| w[1].0 - w[0].0).collect();
    let span = to.saturating_sub(from).max(1) as f64 * 1e-9;
    println!(
        "  full-state cycles {cycles} in {span:.1} s: {:.1}/s (goal Sync Writes {}, Fast Sync Reads {reads}, replies {replies})",
        cycles as f64 / span,
        writes.len()
    );
    let nominal_text = nominal.map_or(String::new(), |n| {
        format!(" (nominal {:.0} us)", n as f64 / 1000.0)
    });
    println!(
        "  loop period, Sync Write end to end{nominal_text:<17} {}",
        percentiles(periods.clone())
    );
    if let Some(n) = nominal {
        let ms = n as f64 / 1e6;
        println!(
            "  {}",
            late_periods(&periods, [1.5 * ms, 2.0 * ms, 5.0 * ms])
        );
    }
    println!(
        "  exchange, Sync Write end -> its reply written          {}",
        percentiles(exchange)
    );
    println!(
        "  reply written -> next Sync Write ended                 {}",
        percentiles(turnaround)
    );
    println!(
        "  simulator's lateness writing a reply (written - due)   {}",
        percentiles(late_writes)
    );
    writes
}
