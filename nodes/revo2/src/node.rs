//! The Revo2 node's cycle: absolute-deadline scheduling at `cycle_hz`; each cycle writes the
//! latest hand command (or, when it is stale, a hold at the measured position, flagged),
//! exchanges process data, checks the working counter and the AL state, and publishes hand state
//! and tactile data. Lost frames are counted and ridden out; an AL error is acknowledged and OP
//! requested again; a lost link brings the bus up again without a process restart. On stop the
//! hand gets a hold command, then leaves OP.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use futures_lite::future::block_on;
use teleop_msgs::{device_kind, fixed_text, DeviceInfo, HandCommand, HandState, Tactile};
use teleop_revo2_protocol::{obj, Inputs, Outputs, TactileData};
use teleop_runtime::{now_ns, Health, NodeRuntime, Publisher, Subscriber};

use crate::bus::{bring_up, recover_op, Bus, DeviceInfo as FoundDevice, OpGroup};
use crate::config::{Revo2Config, TactileSource};
use crate::convert::{hand_state, hold_outputs, outputs_for, tactile};
use crate::pump::Connect;

/// Working counter of one Revo2 with an output and an input FMMU under LRW: 1 + 2.
pub const EXPECTED_WKC: u16 = 3;

struct Ports {
    device: Publisher<DeviceInfo>,
    /// The connected device, published with every health report.
    connected: Option<DeviceInfo>,
    commands: Subscriber<HandCommand>,
    state: Publisher<HandState>,
    tactile: Publisher<Tactile>,
    health: Health,
}

/// Counters kept across reconnects.
#[derive(Debug, Default, Clone, Copy)]
struct Counters {
    wkc_errors: u32,
    lost_frames: u32,
    recoveries: u32,
}

/// Runs until SIGINT/SIGTERM.
pub fn run(runtime: &NodeRuntime, config: &Revo2Config, connect: Connect) -> anyhow::Result<()> {
    teleop_runtime::install_stop_handlers();
    let mut ports = Ports {
        device: runtime.publisher()?,
        connected: None,
        commands: runtime.subscriber()?,
        state: runtime.publisher()?,
        tactile: runtime.publisher()?,
        health: Health::new(runtime)?,
    };
    let bus = Bus::open(connect)?;
    let mut counters = Counters::default();
    let mut backoff = Duration::from_millis(100);
    while teleop_runtime::stop_signal().is_none() {
        let bus = bus.current(); // a fresh bus once ethercrab's own task has ended (ethercrab:)
        match block_on(bring_up(&bus.md, config)) {
            Ok((group, info)) => {
                tracing::info!(
                    tactile_in_pdo = info.tactile_in_pdo(),
                    cycle_hz = config.cycle_hz,
                    "Revo2 in OP"
                );
                backoff = Duration::from_millis(100);
                ports.connected = Some(device_info(&info));
                let outcome = cycle(&bus, &group, &info, config, &mut ports, &mut counters);
                match outcome {
                    Ok(()) => {
                        leave_op(&bus, group, &info, config);
                        break;
                    }
                    Err(e) => {
                        tracing::warn!("lost the Revo2: {e:#}; bringing the bus up again");
                        ports.health.count_error();
                        publish_link_down(&mut ports, &counters)?;
                    }
                }
            }
            Err(e) => {
                tracing::warn!(
                    "Revo2 bring-up failed: {e:#}; retrying in {} ms",
                    backoff.as_millis()
                );
                publish_link_down(&mut ports, &counters)?;
                sleep_interruptible(backoff);
                backoff = (backoff * 2).min(Duration::from_secs(2));
            }
        }
    }
    tracing::info!("stopped");
    Ok(())
}

/// The identity the device reported, for the recorder and `teleop echo device/info`.
fn device_info(info: &FoundDevice) -> DeviceInfo {
    DeviceInfo {
        kind: device_kind::REVO2,
        id: info.serial,
        model: fixed_text(teleop_revo2_protocol::DEVICE_NAME),
        firmware_a: fixed_text(&info.control_fw),
        firmware_b: fixed_text(&info.wrist_fw),
        serial_a: fixed_text(&info.control_sn),
        serial_b: fixed_text(&info.wrist_sn),
        ..Default::default()
    }
}

fn sleep_interruptible(d: Duration) {
    let end = Instant::now() + d;
    while Instant::now() < end && teleop_runtime::stop_signal().is_none() {
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn publish_link_down(ports: &mut Ports, counters: &Counters) -> anyhow::Result<()> {
    let state = HandState {
        hand_model: teleop_msgs::hand_model::REVO2,
        joint_count: 6,
        link_up: 0,
        wkc_errors: counters.wkc_errors,
        lost_frames: counters.lost_frames,
        ..Default::default()
    };
    ports.state.publish(&state)?;
    Ok(())
}

/// Cycles until stop (`Ok`) or until the device is lost (`Err`).
fn cycle(
    bus: &Bus,
    group: &OpGroup,
    info: &FoundDevice,
    config: &Revo2Config,
    ports: &mut Ports,
    counters: &mut Counters,
) -> anyhow::Result<()> {
    let md = &bus.md;
    let sd = group.subdevice(md, 0)?;
    let period = Duration::from_secs_f64(1.0 / config.cycle_hz);
    let stale_after = Duration::from_millis(config.stale_command_ms);
    let health_period = Duration::from_millis(config.health_period_ms);
    let units = info.units();
    let assignment = info.tx_assignment.clone();
    let polled: Mutex<Option<TactileData>> = Mutex::new(None);
    let poll_tactile = !info.tactile_in_pdo() && config.tactile != TactileSource::Off;
    let stop_poll = std::sync::atomic::AtomicBool::new(false);

    std::thread::scope(|scope| -> anyhow::Result<()> {
        if poll_tactile {
            let (polled, stop_poll) = (&polled, &stop_poll);
            std::thread::Builder::new()
                .name("tactile-sdo".into())
                .spawn_scoped(scope, move || {
                    poll_tactile_sdo(bus, group, config, polled, stop_poll)
                })?;
        }
        let result = (|| -> anyhow::Result<()> {
            let mut deadline = Instant::now();
            let mut last_inputs: Option<Inputs> = None;
            let mut stale = true;
            let mut holding = false;
            let mut lost_in_a_row = 0u32;
            let mut wrong_in_a_row = 0u32;
            let mut last_good = Instant::now();
            let link_timeout = Duration::from_millis(config.link_timeout_ms);
            let mut last_health = Instant::now();
            let mut last_state = teleop_msgs::HandState::default();
            while teleop_runtime::stop_signal().is_none() {
                // Absolute deadlines: a late cycle does not shift the ones after it.
                deadline += period;
                let now = Instant::now();
                if deadline > now {
                    teleop_runtime::sleep_until(deadline);
                } else if now - deadline > period * 10 {
                    deadline = now; // far behind (e.g. after a stall): re-anchor instead of bursting
                }
                // What to send.
                let cmd = ports.commands.poll_latest();
                let fresh = ports.commands.is_fresh(Instant::now(), stale_after);
                let outputs: Option<Outputs> =
                    match cmd.filter(|_| fresh).and_then(|c| outputs_for(&c, config)) {
                        Some((out, clamps)) => {
                            if stale {
                                tracing::info!("hand commands fresh: following them");
                            }
                            stale = false;
                            holding = false;
                            ports.health.count_clamps(u64::from(clamps));
                            Some(out)
                        }
                        None => {
                            if !stale {
                                tracing::warn!(
                                    stale_ms = config.stale_command_ms,
                                    "hand command stale: holding position"
                                );
                                ports.health.count_timeout();
                                stale = true;
                            }
                            if !holding {
                                holding = last_inputs.is_some();
                                last_inputs.as_ref().map(|i| {
                                    hold_outputs(&i.joints, units, config.hold_speed_per_mille)
                                })
                            } else {
                                None // keep sending the hold already in the outputs
                            }
                        }
                    };
                if let Some(out) = outputs {
                    let mut io = sd.io_raw_mut();
                    let _ = out.pack(io.outputs());
                }
                let t0 = Instant::now();
                let response = block_on(group.tx_rx(md));
                let origin = now_ns();
                tracing::trace!(us = t0.elapsed().as_micros() as u64, "tx_rx");
                let response = match response {
                    Ok(r) => {
                        lost_in_a_row = 0;
                        r
                    }
                    Err(e) => {
                        counters.lost_frames += 1;
                        lost_in_a_row += 1;
                        tracing::debug!("cycle lost: {e}");
                        if last_good.elapsed() > link_timeout {
                            anyhow::bail!(
                                "no answer for {} ms ({lost_in_a_row} cycles; {e})",
                                last_good.elapsed().as_millis()
                            );
                        }
                        continue;
                    }
                };
                // The AL state comes in the same frame; check it first: a device that lost OP
                // (watchdog, power cycle, emulator restart) also answers with a wrong working
                // counter, which must not hide it.
                let state = response.subdevice_states.first().copied();
                match state {
                    Some(ethercrab::SubDeviceState::Op) => {}
                    Some(ethercrab::SubDeviceState::SafeOp) => {
                        let code = block_on(recover_op(md, group))?;
                        counters.recoveries += 1;
                        tracing::warn!(
                            al_status_code = format!("{code:#06x}"),
                            "Revo2 dropped to SAFE-OP: acknowledged, OP requested"
                        );
                        ports.health.count_error();
                        holding = false; // re-send the hold/command after recovery
                        continue;
                    }
                    other => anyhow::bail!("the Revo2 left OP ({other:?})"),
                }
                if response.working_counter != EXPECTED_WKC {
                    counters.wkc_errors += 1;
                    wrong_in_a_row += 1;
                    if counters.wkc_errors % 100 == 1 {
                        tracing::warn!(
                            wkc = response.working_counter,
                            expected = EXPECTED_WKC,
                            total = counters.wkc_errors,
                            "wrong working counter: inputs of this cycle ignored"
                        );
                    }
                    if last_good.elapsed() > link_timeout {
                        anyhow::bail!(
                            "{wrong_in_a_row} cycles in a row with a wrong working counter"
                        );
                    }
                    continue;
                }
                wrong_in_a_row = 0;
                last_good = Instant::now();
                let inputs = {
                    let io = sd.io_raw();
                    Inputs::unpack(io.inputs(), &assignment)
                };
                let Ok(mut inputs) = inputs else {
                    counters.wkc_errors += 1;
                    continue;
                };
                if poll_tactile {
                    inputs.tactile = *polled.lock().unwrap_or_else(|e| e.into_inner());
                }
                let mut state = hand_state(&inputs, units, config.full_speed_travel_per_s);
                state.link_up = 1;
                state.al_state = 8;
                state.holding = u8::from(stale);
                state.wkc_errors = counters.wkc_errors;
                state.lost_frames = counters.lost_frames;
                state.header.origin_ns = origin;
                ports.state.publish(&state)?;
                if let Some(mut t) = tactile(&inputs) {
                    t.header.origin_ns = origin;
                    ports.tactile.publish(&t)?;
                }
                last_state = state;
                last_inputs = Some(inputs);
                ports.health.count_loop();
                if last_health.elapsed() >= health_period {
                    last_health = Instant::now();
                    ports.health.set_dropped(ports.commands.dropped());
                    ports
                        .health
                        .publish(&[ports.commands.age(Instant::now())])?;
                    if let Some(d) = &ports.connected {
                        ports.device.publish(d)?;
                    }
                }
            }
            let _ = last_state;
            // Stopping: hold where the hand is for a few cycles before leaving OP.
            if let Some(i) = &last_inputs {
                let out = hold_outputs(&i.joints, units, config.hold_speed_per_mille);
                {
                    let mut io = sd.io_raw_mut();
                    let _ = out.pack(io.outputs());
                }
                for _ in 0..10 {
                    let _ = block_on(group.tx_rx(md));
                    std::thread::sleep(period);
                }
                tracing::info!("sent hold before leaving OP");
            }
            Ok(())
        })();
        stop_poll.store(true, std::sync::atomic::Ordering::SeqCst);
        result
    })
}

/// Reads 0x6010 by SDO at `tactile_poll_hz` when tactile data is not in the process data. Runs in
/// its own thread so that a slow or failing mailbox never delays the cycle.
fn poll_tactile_sdo(
    bus: &Bus,
    group: &OpGroup,
    config: &Revo2Config,
    out: &Mutex<Option<TactileData>>,
    stop: &std::sync::atomic::AtomicBool,
) {
    let period = Duration::from_secs_f64(1.0 / config.tactile_poll_hz);
    let mut failures = 0u32;
    while !stop.load(std::sync::atomic::Ordering::SeqCst) {
        let started = Instant::now();
        let read = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            block_on(read_tactile(bus, group))
        }));
        match read {
            Ok(Ok(t)) => {
                failures = 0;
                *out.lock().unwrap_or_else(|e| e.into_inner()) = Some(t);
            }
            Ok(Err(e)) => {
                failures += 1;
                if failures == 1 {
                    tracing::warn!("tactile SDO poll failed: {e}");
                }
            }
            Err(_) => tracing::error!(
                "tactile SDO poll panicked inside ethercrab (CoE emergency?); polling goes on"
            ),
        }
        let left = period.saturating_sub(started.elapsed());
        std::thread::sleep(left);
    }
}

async fn read_tactile(bus: &Bus, group: &OpGroup) -> anyhow::Result<TactileData> {
    let sd = group.subdevice(&bus.md, 0)?;
    let mut raw = [0u8; 60];
    let mut at = 0;
    for (sub, len) in [(1u8, 10usize), (2, 10), (3, 10), (4, 20), (5, 10)] {
        // `[u16; N]` reads are broken in ethercrab 0.7 (buffer sized N bytes): read bytes.
        let v: heapless::Vec<u8, 32> = sd.sdo_read(obj::TACTILE_INPUTS, sub).await?;
        if v.len() != len {
            anyhow::bail!("0x6010:{sub:02} has {} bytes, expected {len}", v.len());
        }
        raw[at..at + len].copy_from_slice(&v);
        at += len;
    }
    Ok(TactileData::unpack(&raw)?)
}

fn leave_op(bus: &Bus, group: OpGroup, _info: &FoundDevice, _config: &Revo2Config) {
    match block_on(async {
        let g = group.into_safe_op(&bus.md).await?;
        let g = g.into_pre_op(&bus.md).await?;
        g.into_init(&bus.md).await
    }) {
        Ok(_) => tracing::info!("Revo2 back in INIT"),
        Err(e) => tracing::warn!("leaving OP failed: {e}"),
    }
}
