//! ethercrab's real MainDevice state machine against the emulated Revo2 in the same process
//! (the in-process transport: no sockets, no privileges), through the node's own bus code:
//! bring-up to OP, then every control mode in both unit modes moves the simulated fingers.
#![allow(clippy::unwrap_used)]

#[allow(dead_code)] // the IPC helpers are for the process tests; the command builder is used here
mod common;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use futures_lite::future::block_on;
use teleop_ecat_link::{FrameLink, InProcessLink};
use teleop_ecat_master::{Driver, Image};
use teleop_ecat_sim::{AlState, SubDevice};
use teleop_revo2::bus::{bring_up, Bus};
use teleop_revo2::config::{DeviceSettings, TactileSource};
use teleop_revo2::Revo2Config;
use teleop_revo2_protocol::{multi_command, ControlMode, Inputs, Outputs, UnitMode};
use teleop_sim_revo2::{revo2_behind, revo2_subdevice, Revo2};

type Sim = Arc<Mutex<SubDevice<Revo2>>>;

/// The emulator's clock, one per test: advanced by the test, 1 ms per cycle, so the hand's
/// motion does not depend on how loaded the machine is.
type Clock = Arc<AtomicU64>;

fn bus(sim: &Sim, clock: &Clock) -> Bus {
    let (sim, clock) = (sim.clone(), clock.clone());
    Bus::open(Box::new(move || {
        let (sim, clock) = (sim.clone(), clock.clone());
        Ok(Box::new(InProcessLink::new(move |frame: &[u8]| {
            let now = Duration::from_micros(clock.load(Ordering::SeqCst));
            sim.lock().unwrap().process_frame(frame, now)
        })) as Box<dyn FrameLink>)
    }))
    .unwrap()
}

/// Drives `outputs` for `cycles` 1 ms cycles and returns the last inputs.
fn drive(
    clock: &Clock,
    bus: &Bus,
    group: &teleop_revo2::bus::OpGroup,
    outputs: &Outputs,
    cycles: u32,
    assignment: &[u16],
) -> Inputs {
    let sd = group.subdevice(bus.md(), 0).unwrap();
    let mut last = None;
    let mut lost = 0;
    for _ in 0..cycles {
        clock.fetch_add(1000, Ordering::SeqCst);
        {
            let mut io = sd.io_raw_mut();
            outputs.pack(io.outputs()).unwrap();
        }
        // A cycle whose frame times out (20 ms, reachable when the machine is loaded) is lost, as
        // on a real bus: the next one goes on. What matters here is where the fingers go.
        match block_on(group.tx_rx(bus.md())) {
            Ok(r) => {
                assert_eq!(r.working_counter, 3);
                last = Some(Inputs::unpack(sd.io_raw().inputs(), assignment).unwrap());
            }
            Err(_) => lost += 1,
        }
        assert!(lost < cycles / 2, "most cycles lost ({lost})");
        std::thread::sleep(Duration::from_millis(1));
    }
    last.unwrap()
}

fn run_modes(unit_mode: u8) {
    let sim: Sim = Arc::new(Mutex::new(revo2_subdevice(None, 3)));
    let clock = Clock::default();
    let bus = bus(&sim, &clock);
    let config = Revo2Config {
        tactile: TactileSource::Pdo,
        device: DeviceSettings {
            unit_mode: Some(unit_mode),
            ..Default::default()
        },
        ..Default::default()
    };
    let (group, info) = block_on(bring_up(bus.md(), &config)).unwrap();
    assert_eq!(sim.lock().unwrap().al_state(), (AlState::Op, false, 0));
    assert_eq!(info.unit_mode, unit_mode);
    assert!(info.tactile_in_pdo());
    let units = info.units();
    let a = &info.tx_assignment;
    let (pos_open, pos_mid) = match units {
        UnitMode::Percent => (0.0, 600.0),
        UnitMode::Physical => (0.0, 54.0), // degrees: 60 % of the assumed 0..90 deg range
    };
    let cmd = |mode, p1: f32, p2: f32| Outputs {
        multi: multi_command(mode, [p1; 6], [p2; 6], units).unwrap(),
        ..Default::default()
    };
    let hand = |sim: &Sim| sim.lock().unwrap().app().hand().positions();

    // Position + speed.
    drive(
        &clock,
        &bus,
        &group,
        &cmd(ControlMode::PositionSpeed, pos_mid, 1000.0),
        600,
        a,
    );
    let p = hand(&sim);
    assert!(
        p.iter().all(|&x| (x - 600.0).abs() < 15.0),
        "position+speed ({units:?}): {p:?}"
    );
    // Position + time back to open in 300 ms.
    drive(
        &clock,
        &bus,
        &group,
        &cmd(ControlMode::PositionTime, pos_open, 300.0),
        150,
        a,
    );
    let halfway = hand(&sim)[2];
    assert!(
        halfway > 100.0 && halfway < 500.0,
        "position+time moves over its time: {halfway}"
    );
    drive(
        &clock,
        &bus,
        &group,
        &cmd(ControlMode::PositionTime, pos_open, 300.0),
        400,
        a,
    );
    assert!(hand(&sim)[2] < 10.0);
    // Speed, current, PWM close the hand.
    for mode in [ControlMode::Speed, ControlMode::Current, ControlMode::Pwm] {
        drive(&clock, &bus, &group, &cmd(mode, 300.0, 0.0), 200, a);
        assert!(hand(&sim)[3] > 50.0, "{mode:?} closes: {:?}", hand(&sim));
        drive(&clock, &bus, &group, &cmd(mode, -1000.0, 0.0), 600, a);
        assert!(hand(&sim)[3] < 5.0, "{mode:?} opens: {:?}", hand(&sim));
    }
    // The inputs report what the hand does, in the configured units.
    let inputs = drive(
        &clock,
        &bus,
        &group,
        &cmd(ControlMode::PositionSpeed, pos_mid, 1000.0),
        600,
        a,
    );
    let expected = if units == UnitMode::Percent { 600 } else { 54 };
    assert!(
        inputs
            .joints
            .position
            .iter()
            .all(|&p| p.abs_diff(expected) <= 10),
        "{:?}",
        inputs.joints.position
    );
    assert!(inputs.tactile.is_some());
}

#[test]
fn every_control_mode_moves_the_fingers_in_percent_units() {
    run_modes(0);
}

#[test]
fn every_control_mode_moves_the_fingers_in_physical_units() {
    run_modes(1);
}

#[test]
fn a_wrong_identity_is_refused_with_a_clear_error() {
    // Same ESC, another product: build it from the generic emulator with a foreign identity.
    let config = teleop_ecat_sim::EscConfig {
        identity: teleop_ecat_sim::Identity {
            vendor_id: 0x0000_0002,
            product_code: 0x044C_2C52,
            revision: 1,
            serial: 0,
        },
        name: "EK1100".into(),
        ..teleop_ecat_sim::EscConfig::default()
    };
    let sim: Sim = Arc::new(Mutex::new(revo2_behind(config, None)));
    let clock = Clock::default();
    let bus = bus(&sim, &clock);
    let err = block_on(bring_up(bus.md(), &Revo2Config::default()))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("not a Revo2") && err.contains("0x00000002"),
        "{err}"
    );
}

/// A Revo2 driver brought up on `sim` through the master's bring-up, in `unit_mode`.
fn driver_on(
    sim: &Sim,
    clock: &Clock,
    unit_mode: u8,
) -> (Bus, teleop_revo2::bus::OpGroup, teleop_revo2::Revo2) {
    let bus = bus(sim, clock);
    let mut driver = teleop_revo2::Revo2::new(Revo2Config {
        device: DeviceSettings {
            unit_mode: Some(unit_mode),
            ..Default::default()
        },
        ..Default::default()
    });
    let group = block_on(teleop_ecat_master::bring_up(bus.md(), &mut driver)).unwrap();
    (bus, group, driver)
}

/// What the driver wrote into `image`, as the outputs `drive` sends.
fn written(image: &Image) -> Outputs {
    Outputs::unpack(image.subdevice(0)).unwrap()
}

#[test]
fn physical_units_commands_go_out_through_the_drivers_conversion_in_degrees() {
    let sim: Sim = Arc::new(Mutex::new(revo2_subdevice(None, 4)));
    let clock = Clock::default();
    let (bus, group, mut driver) = driver_on(&sim, &clock, 1);
    assert_eq!(driver.info().units(), UnitMode::Physical);
    let mut image = Image::with_lengths([Outputs::LEN]);
    assert!(driver.pack(&common::position_command([0.6; 6]), &mut image));
    let a = driver.info().tx_assignment.clone();
    drive(&clock, &bus, &group, &written(&image), 800, &a);
    // 0.6 of the travel: 54 of 90 degrees, i.e. 600 per mille on the hand (was sent as 600
    // "degrees", which closes the hand fully).
    let p = sim.lock().unwrap().app().hand().positions();
    assert!(p.iter().all(|&x| (x - 600.0).abs() < 15.0), "{p:?}");
}

#[test]
fn the_hold_keeps_squeezing_a_grasped_object() {
    let sim: Sim = Arc::new(Mutex::new(revo2_subdevice(
        Some(teleop_sim_revo2::hand::VirtualObject::ball()),
        5,
    )));
    let clock = Clock::default();
    let (bus, group, mut driver) = driver_on(&sim, &clock, 0);
    let a = driver.info().tx_assignment.clone();
    let mut image = Image::with_lengths([Outputs::LEN]);
    // Close the hand around the ball, past where it stops the fingers: a squeeze.
    assert!(driver.pack(&common::position_command([0.6; 6]), &mut image));
    let last = drive(&clock, &bus, &group, &written(&image), 800, &a);
    let index =
        |inputs: &Inputs| teleop_revo2::convert::tactile(inputs).unwrap().fingertips[1].normal_n;
    let gripped = index(&last);
    assert!(gripped > 1.0, "index force on the ball: {gripped} N");
    // The command goes stale: the master sends the driver's hold for 2 s.
    driver.hold(Some(&last), &mut image);
    let held = drive(&clock, &bus, &group, &written(&image), 2000, &a);
    assert!(
        index(&held) > gripped / 2.0,
        "the grip stays: {} N after 2 s of hold (was {gripped} N)",
        index(&held)
    );
}

#[test]
fn unset_serial_numbers_do_not_stop_bring_up() {
    let sim: Sim = Arc::new(Mutex::new(revo2_subdevice(None, 6)));
    sim.lock().unwrap().app_mut().erase_serial_numbers();
    let clock = Clock::default();
    let (_bus, _group, driver) = driver_on(&sim, &clock, 0);
    assert_eq!(sim.lock().unwrap().al_state(), (AlState::Op, false, 0));
    assert_eq!(driver.info().control_sn, "(unset)");
    assert_eq!(driver.info().wrist_sn, "(unset)");
    assert_eq!(driver.info().control_fw, "1.4.2");
}

/// Bring-up's error on `sim`.
fn bring_up_error(sim: &Sim) -> String {
    let clock = Clock::default();
    let bus = bus(sim, &clock);
    let mut driver = teleop_revo2::Revo2::new(Revo2Config::default());
    format!(
        "{:#}",
        block_on(teleop_ecat_master::bring_up(bus.md(), &mut driver))
            .err()
            .unwrap()
    )
}

#[test]
fn a_device_with_another_pdo_mapping_is_refused_naming_the_object() {
    let sim: Sim = Arc::new(Mutex::new(revo2_subdevice(None, 7)));
    // Joint data with positions and speeds swapped.
    let mut swapped: Vec<u32> = teleop_revo2_protocol::JOINT_TX_MAPPING
        .iter()
        .map(|m| m.encode())
        .collect();
    swapped.swap(0, 1);
    sim.lock()
        .unwrap()
        .app_mut()
        .present_mapping(0x1A00, swapped);
    let err = bring_up_error(&sim);
    assert!(
        err.contains("0x1a00:01") && err.contains("PDO layout"),
        "{err}"
    );
    assert_ne!(sim.lock().unwrap().al_state().0, AlState::Op);
}

#[test]
fn an_unreadable_unit_mode_is_refused_not_taken_as_percent() {
    let sim: Sim = Arc::new(Mutex::new(revo2_subdevice(None, 8)));
    sim.lock().unwrap().app_mut().fail_reads(0x8000, 0x05);
    let err = bring_up_error(&sim);
    assert!(err.contains("unit_mode (0x8000:05)"), "{err}");
    assert_ne!(sim.lock().unwrap().al_state().0, AlState::Op);
}
