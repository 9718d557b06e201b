//! Benchmark: the Shadow node's 1 kHz cycle with two SubDevices as the emulated palm sees it,
//! the glove sample -> motor demand latency, the PST sample -> glove force latency, and the time
//! to flash one motor board through the palm's CAN bridge.
//!
//! Method: the emulated hand (`teleop_sim_shadow::ethercat::ShadowBus`: bridge and palm, E v3 mapping,
//! the ball) is served in this process on a local socket as `teleop-sim-shadow` serves it,
//! recording every frame's arrival (CLOCK_MONOTONIC) and what the palm holds after it. The real
//! `teleop-shadow` (release, `config/shadow.toml`), `teleop-retarget`
//! (`config/shadow/retarget.toml` with the One Euro filter opened to 1 kHz and the slew limit at
//! 100 travel/s, so that the path is measured, not the filter) and `teleop-feedback`
//! (`config/shadow/feedback.toml`) run as processes.
//!
//! 1. Cycle: the arrival of each LRW frame (the one datagram frame; the AL state check that
//!    follows it has one datagram per SubDevice): period (nominal 1000 us) and its deviation.
//! 2. Glove -> motor demand: this process publishes `glove/state` at 300 Hz and every 200-300 ms
//!    (random) steps the middle-finger channel between 900 and 300; latency = the arrival of the
//!    first frame after which the palm applies an MFJ3 demand that moved more than 100 PWM from
//!    its value before the step - the step's publish stamp. It includes the palm's 610 us CAN
//!    round (the demand goes to the motors when the palm has taken the command).
//! 3. Hand sample -> glove force: each `glove/force_command` received, its receive time - its
//!    `origin_ns` (the node's receive time of the exchange, carried through `hand/state` and
//!    `hand/tactile` by the feedback node); and `hand/state` stamp - origin (the node alone).
//! 4. Flashing: after the session, `teleop shadow flash` (release) writes a 30,859-byte image
//!    (965 rows, the released motor firmware's size) into motor 13 through the same emulator;
//!    wall time and messages through the bridge per second (MAGIC, ERASE, 5 + 4 per row, RESET).
//!
//! 20 s after 2 s warm-up.
//!
//! Run: `cargo build --release --workspace --bins && cargo run --release -p teleop-e2e --example bench_shadow`
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use teleop_e2e::bench::{drive_hand_pipeline, late_periods, loadavg, percentiles, step_reactions};
use teleop_e2e::{bin, Sandbox};
use teleop_ecat_link::{serve_socket, StreamServer};
use teleop_runtime::now_ns;
use teleop_shadow_protocol::can::APP_START;
use teleop_shadow_protocol::hex;
use teleop_shadow_protocol::mapping::Mapping;
use teleop_sim_shadow::ethercat::ShadowBus;
use teleop_sim_shadow::hand::{Hand, VirtualObject};
use teleop_sim_shadow::palm::Palm;

const WARM_UP: Duration = Duration::from_secs(2);
const SECONDS: u64 = 20;
/// The glove's middle channel (little, ring, middle, index, thumb, thumb rotation).
const MIDDLE: usize = 2;
/// The size of the released motor firmware (docs/devices/shadow.md).
const IMAGE_BYTES: usize = 30_859;

/// One frame at the emulator: its arrival (ns, CLOCK_MONOTONIC), whether it was the LRW, and
/// the MFJ3 motor's demand after it.
#[derive(Clone, Copy)]
struct Seen {
    t_ns: u64,
    lrw: bool,
    demand: i16,
}

fn main() {
    println!(
        "Shadow Hand E (bridge + palm emulated, local socket), {SECONDS} s after {WARM_UP:?} warm-up"
    );
    println!("  load average (1 min) before: {}", loadavg());
    let sandbox = Sandbox::new();
    sandbox.session("launch/shadow.toml");
    let dir = sandbox.dir.path();
    let socket = dir.join("teleop-shadow.sock");

    let mfj3 = usize::from(Mapping::EV3.motor_of_joint("MFJ3").unwrap());
    let hand = Hand::new(Mapping::EV3, Some(VirtualObject::ball()));
    let sim = Arc::new(Mutex::new(ShadowBus::new(
        Palm::with_hand(hand),
        1178,
        Duration::from_millis(1),
    )));
    let seen = Arc::new(Mutex::new(Vec::<Seen>::with_capacity(200_000)));
    let recording = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    let server = {
        let (sim, seen, recording, stop) =
            (sim.clone(), seen.clone(), recording.clone(), stop.clone());
        let listener = StreamServer::bind(&socket).unwrap();
        std::thread::spawn(move || {
            let mut datagrams = 0u64;
            let stopping = || stop.load(Ordering::SeqCst);
            let mut on_frame = |_: Instant, dev: &ShadowBus| {
                let t_ns = now_ns();
                let total = dev.palm.stats().datagrams;
                let lrw = total - datagrams == 1;
                datagrams = total;
                if recording.load(Ordering::SeqCst) {
                    seen.lock().unwrap().push(Seen {
                        t_ns,
                        lrw,
                        demand: dev.palm().motors[mfj3].demand,
                    });
                }
            };
            serve_socket(&listener, &*sim, Instant::now(), &stopping, &mut on_frame).unwrap();
        })
    };

    let transport = format!("sim:{}", socket.display());
    // Glove samples at 300 Hz, the middle channel stepping every 200-300 ms.
    let drive = drive_hand_pipeline(
        &sandbox,
        "shadow",
        &["--transport", &transport],
        WARM_UP,
        SECONDS,
        MIDDLE,
        |m| recording.store(m, Ordering::SeqCst),
    );
    let seen = seen.lock().unwrap().clone();
    report(
        &seen,
        &drive.steps,
        drive.state_latency,
        drive.force_latency,
    );

    // Flashing motor 13 through the same emulator.
    let image = teleop_sim_shadow::bootloader::generated_application(IMAGE_BYTES, 0x9E37_79B9);
    let file = sandbox.write("motor.hex", &hex::write(APP_START, &image));
    let rows = hex::parse(&std::fs::read_to_string(&file).unwrap())
        .unwrap()
        .rows
        .len();
    let started = Instant::now();
    let out = Command::new(bin("teleop"))
        .args(["shadow", "--transport", &transport, "flash"])
        .arg(&file)
        .args(["--motor", "13"])
        .output()
        .unwrap();
    let took = started.elapsed().as_secs_f64();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let messages = 2 + 9 * rows + 1;
    println!(
        "  flash motor 13: {IMAGE_BYTES} bytes, {rows} rows, {messages} messages in {took:.1} s \
         (bring-up included): {:.0} messages/s through the bridge",
        messages as f64 / took
    );
    stop.store(true, Ordering::SeqCst);
    server.join().unwrap();
    println!("  load average (1 min) after: {}", loadavg());
}

fn report(seen: &[Seen], steps: &[(u64, bool)], state: Vec<u64>, force: Vec<u64>) {
    println!("        times in us: p50 / p99 / max");
    let lrw: Vec<&Seen> = seen.iter().filter(|f| f.lrw).collect();
    let periods: Vec<u64> = lrw.windows(2).map(|w| w[1].t_ns - w[0].t_ns).collect();
    let deviation: Vec<u64> = periods.iter().map(|p| p.abs_diff(1_000_000)).collect();
    let span_s = match (lrw.first(), lrw.last()) {
        (Some(a), Some(b)) if b.t_ns > a.t_ns => (b.t_ns - a.t_ns) as f64 * 1e-9,
        _ => 1.0,
    };
    println!(
        "  LRW exchanges {} ({:.1}/s), frames {} ({:.1}/s)",
        lrw.len(),
        lrw.len() as f64 / span_s,
        seen.len(),
        seen.len() as f64 / span_s
    );
    println!(
        "  cycle period at the palm (nominal 1000 us)            {}",
        percentiles(periods.clone())
    );
    println!(
        "  |period - 1000 us|                                    {}",
        percentiles(deviation)
    );
    println!("  {}", late_periods(&periods, [1.5, 2.0, 5.0]));
    let demand: Vec<(u64, i32)> = seen.iter().map(|f| (f.t_ns, i32::from(f.demand))).collect();
    let glove = step_reactions(&demand, steps, 100);
    println!(
        "  glove/state published -> MFJ3 demand applied by the palm ({} of {} steps)  {}",
        glove.len(),
        steps.len(),
        percentiles(glove)
    );
    println!(
        "  exchange at the node -> hand/state published          {}",
        percentiles(state)
    );
    println!(
        "  exchange at the node -> glove/force_command received  {}",
        percentiles(force)
    );
}
