//! `teleop shadow flash`'s service against the emulated hand over the local-socket transport,
//! with frames lost on the way to the palm (one in 20, and all of them for 300 ms): a lost
//! exchange ("timeout: PDU") is retried and a message that got no answer is sent again, as the shipped driver does (ros_ethercat's
//! `txandrx_PD` retries, sr_edc.cpp's flasher re-sends on its timeouts); the flash completes and
//! the board runs the new image.
#![allow(clippy::unwrap_used)]

mod common;

use std::time::{Duration, Instant};

use common::{serve, Sim};
use teleop_shadow::service::Service;
use teleop_shadow::ShadowConfig;
use teleop_shadow_protocol::can::{BootMessage, APP_START};
use teleop_shadow_protocol::hex;
use teleop_shadow_protocol::layout::CanBridge;
use teleop_sim_shadow::bootloader::{generated_application, Mode};
use teleop_sim_shadow::palm::Palm;

/// The emulated hand served on a socket in `dir`, and the service brought up on it.
fn hand(dir: &std::path::Path) -> (Sim, Service) {
    teleop_runtime::init_logging();
    let socket = dir.join("shadow.sock");
    let sim = serve(&socket, Palm::new());
    let config = ShadowConfig {
        transport: format!("sim:{}", socket.display()),
        ..ShadowConfig::default()
    };
    let checked = config.validate().unwrap();
    let service = Service::open(&config, checked).unwrap();
    (sim, service)
}

/// After normal mode the palm's bridge command sync manager still holds what the host wrote
/// then (the firmware reads it in CAN direct mode only): the service's first CAN-direct cycle
/// carries the shipped flasher's dummy message (id 0), so the message asked for is not refused.
#[test]
fn can_send_after_normal_mode_gets_its_answer() {
    let dir = tempfile::tempdir().unwrap();
    let (mut sim, mut service) = hand(dir.path());
    let magic = BootMessage::magic(3);
    let reply = service
        .can_send(&CanBridge {
            can_bus: 2,
            length: magic.len,
            id: magic.id,
            data: magic.data,
        })
        .unwrap();
    service.close();
    sim.stop();
    let reply = reply.expect("the bootloader's MAGIC answer");
    assert_eq!((reply.can_bus, reply.id), (2, 0x600 | 3 << 5 | 0x1A));
    assert_eq!(sim.lock().palm().boards[13].mode(), Mode::Bootloader);
}

#[test]
fn a_lost_exchange_during_a_flash_is_retried_and_the_flash_completes() {
    let dir = tempfile::tempdir().unwrap();
    let (mut sim, mut service) = hand(dir.path());

    // From now on one frame in 20 to the palm is lost (seeded: the same frames every run).
    {
        let mut bus = sim.lock();
        let faults = bus.palm.faults();
        faults.seed = 20;
        faults.drop_probability = 0.05;
    }
    // And once, mid-transfer, the cable is out for 300 ms: every try of those exchanges fails,
    // the messages are sent again afterwards.
    let cable = {
        let sim = sim.shared();
        std::thread::spawn(move || {
            let start = Instant::now();
            while sim.lock().unwrap().palm.app().stats.bridged < 40 {
                assert!(start.elapsed() < Duration::from_secs(20), "no flashing");
                std::thread::sleep(Duration::from_millis(1));
            }
            sim.lock().unwrap().palm.faults().link_down = true;
            std::thread::sleep(Duration::from_millis(300));
            sim.lock().unwrap().palm.faults().link_down = false;
        })
    };
    let app = generated_application(600, 5);
    let image = hex::parse(&hex::write(APP_START, &app)).unwrap();
    let result = service.flash(13, image, &mut |_, _| {});
    cable.join().unwrap();
    let dropped = sim.lock().palm.stats().dropped_frames;
    service.close();
    sim.stop();
    assert!(dropped > 0, "frames were lost");
    result.unwrap_or_else(|e| panic!("the flash failed after {dropped} lost frames: {e}"));
    let bus = sim.lock();
    let board = &bus.palm().boards[13];
    assert_eq!(board.mode(), Mode::Application);
    let at = APP_START as usize;
    assert_eq!(&board.flash()[at..at + app.len()], &app[..]);
}
