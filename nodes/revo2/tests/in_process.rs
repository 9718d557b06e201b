//! ethercrab's real MainDevice state machine against the emulated Revo2 in the same process
//! (the in-process transport: no sockets, no privileges), through the node's own bus code:
//! bring-up to OP, then every control mode in both unit modes moves the simulated fingers.
#![allow(clippy::unwrap_used)]

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use futures_lite::future::block_on;
use sim_revo2::{revo2_subdevice, Revo2};
use teleop_ecat_link::{FrameLink, InProcessLink};
use teleop_ecat_sim::{AlState, SubDevice};
use teleop_revo2::bus::{bring_up, Bus};
use teleop_revo2::config::{DeviceSettings, TactileSource};
use teleop_revo2::Revo2Config;
use teleop_revo2_protocol::{multi_command, ControlMode, Inputs, Outputs, UnitMode};

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
    let sd = group.subdevice(&bus.md, 0).unwrap();
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
        match block_on(group.tx_rx(&bus.md)) {
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
    let (group, info) = block_on(bring_up(&bus.md, &config)).unwrap();
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
    let mut device = revo2_subdevice(None, 1);
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
    let app = std::mem::replace(
        device.app_mut(),
        Revo2::new(
            sim_revo2::hand::Hand::new(Default::default(), None),
            &Default::default(),
        ),
    );
    let sim: Sim = Arc::new(Mutex::new(SubDevice::new(config, app)));
    let clock = Clock::default();
    let bus = bus(&sim, &clock);
    let err = block_on(bring_up(&bus.md, &Revo2Config::default()))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("not a Revo2") && err.contains("0x00000002"),
        "{err}"
    );
}
