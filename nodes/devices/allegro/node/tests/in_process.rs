//! The torque loop in-process against a tiny scripted hand on `teleop_can_link::local::LocalBus`:
//! bring-up per generation, the hold before any command, PD toward a target, a stream that stops
//! (zero torque, SYSTEM_OFF, brought up again), unknown and bad frames counted, a hand of the
//! other generation named, and the stop sequence.
#![allow(clippy::unwrap_used)]

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use teleop_allegro::driver::{self, Connected, Cycle, Down, Host, Target};
use teleop_allegro::{AllegroConfig, ProtocolSetting, Settings};
use teleop_allegro_protocol::{
    doc, pwm_to_torque, rad_to_v4_raw, v4, Generation, JointCalibration, Protocol, JOINTS,
};
use teleop_can_link::local::LocalBus;
use teleop_can_link::{CanFrame, CanLink};

/// What the scripted hand saw and does.
#[derive(Default)]
struct HandLog {
    /// Host frames in order, as text.
    received: Vec<String>,
    streaming: bool,
    /// Torque applied per joint, N m.
    torque: [f64; JOINTS],
    /// Torque frames received (the node is in its loop once there is one).
    torque_frames: u64,
}

/// A hand: first-order joints (speed proportional to torque), streaming its four position
/// frames every 3 ms while on.
struct ScriptedHand {
    log: Arc<Mutex<HandLog>>,
    stop: Arc<AtomicBool>,
    /// Do not stream even when on.
    mute: Arc<AtomicBool>,
    /// Send this many unknown frames (id 0x7F0) and bad frames (a short position frame).
    junk: Arc<AtomicU32>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl ScriptedHand {
    fn start(bus: &LocalBus, generation: Generation, q0: [f64; JOINTS]) -> Self {
        let mut end = bus.end();
        let log = Arc::new(Mutex::new(HandLog::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let mute = Arc::new(AtomicBool::new(false));
        let junk = Arc::new(AtomicU32::new(0));
        let (l, s, m, j) = (log.clone(), stop.clone(), mute.clone(), junk.clone());
        let thread = std::thread::spawn(move || {
            let mut q = q0;
            let k = generation.default_pwm_per_nm();
            let cal = JointCalibration {
                offset: 0,
                encoder_dir: 1,
                motor_dir: 1,
            };
            let mut next = Instant::now();
            while !s.load(Ordering::SeqCst) {
                while let Some(frame) = end.recv(Duration::ZERO).unwrap() {
                    let mut log = l.lock().unwrap();
                    log.received.push(frame.to_string());
                    match generation.protocol() {
                        Protocol::V4 => match v4::Request::decode(&frame) {
                            Ok((_, v4::Request::SystemOn)) => log.streaming = true,
                            Ok((_, v4::Request::SystemOff)) => {
                                log.streaming = false;
                                log.torque = [0.0; JOINTS];
                            }
                            Ok((_, v4::Request::Torque { finger, pwm })) => {
                                log.torque_frames += 1;
                                for (i, p) in pwm.iter().enumerate() {
                                    log.torque[usize::from(finger) * 4 + i] =
                                        pwm_to_torque(*p, k, 1);
                                }
                            }
                            Ok((_, v4::Request::QueryInfo)) => {
                                let info = v4::Report::Info(v4::Info {
                                    hw_version: 0x0400,
                                    fw_version: 0x0102,
                                    hand_type: 0,
                                    temperature: 30,
                                    status: 1,
                                });
                                end.send(&info.encode::<CanFrame>(0)).unwrap();
                            }
                            _ => {}
                        },
                        Protocol::Doc => {
                            match doc::Request::decode(&frame, generation.torque_order()) {
                                Ok(doc::Request::SystemOn) => log.streaming = true,
                                Ok(doc::Request::SystemOff) => {
                                    log.streaming = false;
                                    log.torque = [0.0; JOINTS];
                                }
                                Ok(doc::Request::Torque { finger, pwm }) => {
                                    log.torque_frames += 1;
                                    for (i, p) in pwm.iter().enumerate() {
                                        log.torque[usize::from(finger) * 4 + i] =
                                            pwm_to_torque(*p, k, 1);
                                    }
                                }
                                _ => {}
                            }
                        }
                    }
                }
                if !teleop_e2e::period_due(&mut next, Duration::from_millis(3)) {
                    continue;
                }
                let (streaming, torque, looping) = {
                    let log = l.lock().unwrap();
                    (log.streaming, log.torque, log.torque_frames > 0)
                };
                for (qj, t) in q.iter_mut().zip(torque) {
                    *qj += t * 20.0 * 0.003;
                }
                if !streaming || m.load(Ordering::SeqCst) {
                    continue;
                }
                for finger in 0..4u8 {
                    let b = usize::from(finger) * 4;
                    let frame = match generation.protocol() {
                        Protocol::V4 => v4::Report::Position {
                            finger,
                            raw: [0, 1, 2, 3].map(|i| rad_to_v4_raw(q[b + i])),
                        }
                        .encode::<CanFrame>(0),
                        Protocol::Doc => doc::Report::Position {
                            finger,
                            raw: [0, 1, 2, 3].map(|i| cal.rad_to_doc_raw(q[b + i])),
                        }
                        .encode::<CanFrame>(doc::ID_DEVICE_MAIN),
                    };
                    end.send(&frame).unwrap();
                }
                // Junk once the node runs its loop (bring-up does not count what it drains).
                if looping && j.load(Ordering::SeqCst) > 0 {
                    j.fetch_sub(1, Ordering::SeqCst);
                    end.send(&CanFrame::standard(0x7F0, &[1, 2]).unwrap())
                        .unwrap();
                    let short = match generation.protocol() {
                        Protocol::V4 => 0x080,
                        Protocol::Doc => 0x3D3,
                    };
                    end.send(&CanFrame::standard(short, &[1]).unwrap()).unwrap();
                }
            }
        });
        Self {
            log,
            stop,
            mute,
            junk,
            thread: Some(thread),
        }
    }

    fn received(&self) -> Vec<String> {
        self.log.lock().unwrap().received.clone()
    }

    /// The host frames received, once the last one starts with `prefix` (the hand's thread
    /// reads the bus every 3 ms at most; waits up to a second).
    fn received_ending_with(&self, prefix: &str) -> Vec<String> {
        let start = Instant::now();
        loop {
            let rx = self.received();
            if rx.last().is_some_and(|f| f.starts_with(prefix))
                || start.elapsed() > Duration::from_secs(1)
            {
                return rx;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl Drop for ScriptedHand {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A host that follows a script: a target (or hold), stop after a time, everything recorded.
#[derive(Default)]
struct TestHost {
    target: Option<[f64; JOINTS]>,
    stop_after: Option<Duration>,
    started: Option<Instant>,
    cycles: Vec<Cycle>,
    connects: u32,
    downs: Vec<String>,
    /// Called on each cycle (to inject faults at a time).
    on_cycle: Option<OnCycle>,
}

/// A test's hook on each cycle: the cycle and the target it may change.
type OnCycle = Box<dyn FnMut(&Cycle, &mut Option<[f64; JOINTS]>)>;

impl Host for TestHost {
    fn stop_requested(&self) -> bool {
        match (self.started, self.stop_after) {
            (Some(s), Some(d)) => s.elapsed() >= d,
            _ => false,
        }
    }
    fn target(&mut self) -> Target {
        self.target.map_or(Target::Hold, Target::Follow)
    }
    fn connected(&mut self, _: &Connected<'_>) -> anyhow::Result<()> {
        self.connects += 1;
        Ok(())
    }
    fn cycle(&mut self, cycle: &Cycle) -> anyhow::Result<()> {
        self.cycles.push(*cycle);
        if let Some(f) = &mut self.on_cycle {
            f(cycle, &mut self.target);
        }
        Ok(())
    }
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        self.downs.push(down.why.to_string());
        Ok(())
    }
}

fn settings(protocol: ProtocolSetting) -> Settings {
    AllegroConfig {
        link: "local:/unused".into(),
        protocol,
        bringup_timeout_ms: 300,
        reconnect_backoff_ms: [20, 100],
        ..Default::default()
    }
    .validate()
    .unwrap()
}

fn run_for(bus: &LocalBus, settings: &Settings, host: &mut TestHost, d: Duration) {
    host.started = Some(Instant::now());
    host.stop_after = Some(d);
    let mut open = || Ok(Box::new(bus.end()) as Box<dyn CanLink>);
    driver::run(settings, host, &mut open).unwrap();
}

fn start_pose() -> [f64; JOINTS] {
    let mut q = [0.0; JOINTS];
    for (j, v) in q.iter_mut().enumerate() {
        *v = 0.05 * j as f64 - 0.3;
    }
    q
}

#[test]
fn every_generation_comes_up_holds_then_follows() {
    for generation in [
        Generation::V1,
        Generation::V2,
        Generation::V3,
        Generation::V4,
    ] {
        let bus = LocalBus::new();
        let hand = ScriptedHand::start(&bus, generation, start_pose());
        let mut goal = start_pose();
        goal[1] += 0.4;
        goal[13] -= 0.2;
        let mut host = TestHost {
            on_cycle: Some(Box::new(move |c, target| {
                if target.is_none() && c.counters.cycles >= 100 {
                    *target = Some(goal);
                }
            })),
            ..Default::default()
        };
        run_for(
            &bus,
            &settings(ProtocolSetting::Fixed(generation)),
            &mut host,
            Duration::from_millis(1500),
        );
        assert_eq!(host.connects, 1, "{generation}: {:?}", host.downs);
        let n = host.cycles.len();
        assert!(n > 200, "{generation}: only {n} cycles");
        // Holding where the hand was: the first cycles aim at the start pose.
        let first = &host.cycles[0];
        assert!(first.holding);
        for j in 0..JOINTS {
            assert!(
                (first.target[j] - start_pose()[j]).abs() < 1e-3,
                "{generation} joint {j}"
            );
        }
        let last = host.cycles.last().unwrap();
        assert!(!last.holding);
        for j in [1, 13] {
            assert!(
                (last.q[j] - goal[j]).abs() < 0.02,
                "{generation} joint {j}: {} vs {}",
                last.q[j],
                goal[j]
            );
        }
        // Stopping: zero torque frames, then SYSTEM_OFF.
        let off = match generation.protocol() {
            Protocol::V4 => "104#",
            Protocol::Doc => "08A#",
        };
        let rx = hand.received_ending_with(off);
        assert!(
            rx.last().unwrap().starts_with(off),
            "{generation}: {:?}",
            &rx[rx.len() - 6..]
        );
        assert!(hand.log.lock().unwrap().torque.iter().all(|t| *t == 0.0));
    }
}

#[test]
fn a_stopped_stream_stops_torque_and_the_hand_comes_back() {
    let bus = LocalBus::new();
    let hand = ScriptedHand::start(&bus, Generation::V4, start_pose());
    let mute = hand.mute.clone();
    let mut host = TestHost {
        target: Some(start_pose()),
        on_cycle: Some(Box::new(move |c, _| {
            if c.counters.cycles == 100 {
                let mute = mute.clone();
                std::thread::spawn(move || {
                    mute.store(true, Ordering::SeqCst);
                    std::thread::sleep(Duration::from_millis(200));
                    mute.store(false, Ordering::SeqCst);
                });
            }
        })),
        ..Default::default()
    };
    run_for(
        &bus,
        &settings(ProtocolSetting::Fixed(Generation::V4)),
        &mut host,
        Duration::from_millis(1500),
    );
    assert!(host.connects >= 2, "not brought up again: {:?}", host.downs);
    assert!(
        host.downs[0].contains("missing finger frame"),
        "{:?}",
        host.downs
    );
    let last = host.cycles.last().unwrap();
    assert!(last.counters.reconnects >= 1);
    assert!(last.counters.missing_cycles >= 4);
    // After the fault, SYSTEM_OFF went out before the next SYSTEM_ON.
    let rx = hand.received();
    let ons: Vec<usize> = (0..rx.len()).filter(|&i| rx[i] == "100#").collect();
    assert!(ons.len() >= 2, "{ons:?}");
    assert!(rx[ons[0]..ons[1]].iter().any(|f| f == "104#"));
}

#[test]
fn unknown_and_bad_frames_are_counted_and_survived() {
    let bus = LocalBus::new();
    let hand = ScriptedHand::start(&bus, Generation::V4, start_pose());
    hand.junk.store(20, Ordering::SeqCst);
    let mut host = TestHost::default();
    run_for(
        &bus,
        &settings(ProtocolSetting::Fixed(Generation::V4)),
        &mut host,
        Duration::from_millis(600),
    );
    assert_eq!(host.connects, 1, "{:?}", host.downs);
    let c = host.cycles.last().unwrap().counters;
    assert_eq!((c.unknown_frames, c.bad_frames), (20, 20), "{c:?}");
}

#[test]
fn the_other_generation_is_named_and_auto_detects_v4() {
    let bus = LocalBus::new();
    let _hand = ScriptedHand::start(&bus, Generation::V4, start_pose());
    let mut host = TestHost::default();
    run_for(
        &bus,
        &settings(ProtocolSetting::Fixed(Generation::V3)),
        &mut host,
        Duration::from_millis(800),
    );
    assert_eq!(host.connects, 0);
    assert!(
        host.downs
            .iter()
            .any(|d| d.contains("saw v4 IDs; set protocol = v4")),
        "{:?}",
        host.downs
    );
    let mut host = TestHost::default();
    run_for(
        &bus,
        &settings(ProtocolSetting::Auto),
        &mut host,
        Duration::from_millis(800),
    );
    assert_eq!(host.connects, 1, "{:?}", host.downs);

    let bus = LocalBus::new();
    let _hand = ScriptedHand::start(&bus, Generation::V2, start_pose());
    let mut host = TestHost::default();
    run_for(
        &bus,
        &settings(ProtocolSetting::Fixed(Generation::V4)),
        &mut host,
        Duration::from_millis(1200),
    );
    assert_eq!(host.connects, 0);
    assert!(
        host.downs
            .iter()
            .any(|d| d.contains("saw v1-v3 (document protocol) IDs; set protocol = v1, v2 or v3")),
        "{:?}",
        host.downs
    );
}

#[test]
fn a_silent_bus_is_named() {
    let bus = LocalBus::new();
    let mut host = TestHost::default();
    run_for(
        &bus,
        &settings(ProtocolSetting::Fixed(Generation::V4)),
        &mut host,
        Duration::from_millis(900),
    );
    assert!(
        host.downs
            .iter()
            .any(|d| d.contains("is the hand powered and the bit rate 1 Mbit/s?")),
        "{:?}",
        host.downs
    );
}

/// The loop holds the last target it followed while the host has none, and follows the host's
/// targets as they come: the ramp back after a hold is the host's (`teleop-hand-node`'s
/// `HandPorts` for the node, `Resume` for a service command), not a second one in the loop.
#[test]
fn a_hold_keeps_the_last_target_and_targets_are_followed_as_the_host_gives_them() {
    let bus = LocalBus::new();
    let _hand = ScriptedHand::start(&bus, Generation::V4, start_pose());
    let mut far = start_pose();
    far[1] += 0.2;
    far[13] -= 0.1;
    let mut host = TestHost {
        target: Some(start_pose()),
        on_cycle: Some(Box::new(move |c, target| match c.counters.cycles {
            150 => *target = None,      // the host has no command: hold
            250 => *target = Some(far), // back
            _ => {}
        })),
        ..Default::default()
    };
    run_for(
        &bus,
        &settings(ProtocolSetting::Fixed(Generation::V4)),
        &mut host,
        Duration::from_millis(2000),
    );
    assert_eq!(host.connects, 1, "{:?}", host.downs);
    let holds: Vec<&Cycle> = host.cycles.iter().filter(|c| c.holding).collect();
    assert!(holds.len() >= 90, "{} holding cycles", holds.len());
    assert!(
        holds.iter().all(|c| c.target == start_pose()),
        "the hold keeps the last target followed"
    );
    let resumed = host
        .cycles
        .iter()
        .position(|c| c.counters.cycles > 250 && !c.holding)
        .unwrap();
    assert_eq!(host.cycles[resumed].target, far, "followed as given");
    let last = host.cycles.last().unwrap();
    assert_eq!(last.target, far);
    assert!((last.q[1] - far[1]).abs() < 0.02, "{:?}", last.q);
}
