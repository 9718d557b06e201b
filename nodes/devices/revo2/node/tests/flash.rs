//! The firmware upgrade over FoE (document section 6) with ethercrab against the emulated Revo2
//! in the same process: both boards flashed and their new versions read back after the
//! restart; every refusal (file checks before the device is touched, the device's own checks
//! with their FoE error codes, a wrong authentication code, a device that stops answering or
//! leaves the bus in the middle of the transfer) reported clearly, with the device usable
//! afterwards.
#![allow(clippy::unwrap_used)]

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use futures_lite::future::block_on;
use teleop_ecat_link::{FrameLink, InProcessLink};
use teleop_ecat_sim::{mailbox_protocols, AlState, SubDevice};
use teleop_foe::{Client, ClientConfig, ErrorCode, FoeError};
use teleop_revo2::bus::{bring_up, discover, Bus};
use teleop_revo2::flash::{
    enter_boot, flash, leave_boot, mailboxes, write_upgrade_settings, Firmware, FlashError,
    FlashEvent, FlashOptions,
};
use teleop_revo2::mailbox::EcatMailbox;
use teleop_revo2::Revo2Config;
use teleop_revo2_protocol::{Board, FirmwareHeader, Version};
use teleop_sim_revo2::{revo2_behind, revo2_subdevice, Revo2};

type Sim = Arc<Mutex<SubDevice<Revo2>>>;

/// One test at a time: each runs a MainDevice with 20 ms PDU timeouts and an emulator in
/// threads of its own; side by side on a small, busy machine they would starve each other.
static SERIAL: Mutex<()> = Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn sim() -> Sim {
    Arc::new(Mutex::new(revo2_subdevice(None, 7)))
}

fn bus(sim: &Sim) -> Bus {
    let start = Instant::now();
    let sim = sim.clone();
    Bus::open(Box::new(move || {
        let sim = sim.clone();
        Ok(Box::new(InProcessLink::new(move |frame: &[u8]| {
            sim.lock().unwrap().process_frame(frame, start.elapsed())
        })) as Box<dyn FrameLink>)
    }))
    .unwrap()
}

fn name(board: Board, (major, minor, patch): Version) -> String {
    format!(
        "{}{major}.{minor}.{patch}_2506231346.bin",
        board.file_name_prefix()
    )
}

/// A firmware file as the packaging tool makes it: the 16-byte header, then the image.
fn file(board: Board, version: Version, image: usize) -> Vec<u8> {
    let mut bytes = FirmwareHeader::new(board, version).to_bytes().to_vec();
    bytes.extend((0..image).map(|i| (i * 31 % 253) as u8));
    bytes
}

fn options() -> FlashOptions {
    FlashOptions {
        foe: ClientConfig {
            reply_timeout: Duration::from_millis(200),
            retries: 4,
            ..ClientConfig::default()
        },
        restart_timeout: Duration::from_secs(5),
        ..FlashOptions::default()
    }
}

/// The device comes up to OP and exchanges process data.
fn usable(sim: &Sim, bus: &Bus) -> teleop_revo2::bus::DeviceInfo {
    let (group, info) = block_on(bring_up(bus.md(), &Revo2Config::default())).unwrap();
    for _ in 0..20 {
        let r = block_on(group.tx_rx(bus.md())).unwrap();
        assert_eq!(r.working_counter, 3);
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(sim.lock().unwrap().al_state(), (AlState::Op, false, 0));
    info
}

#[test]
fn both_boards_are_flashed_and_show_their_new_versions() {
    let _serial = serial();
    let sim = sim();
    let bus = bus(&sim);
    assert_eq!(
        sim.lock().unwrap().app().firmware_versions(),
        ("1.4.2".to_string(), "0.9.7".to_string())
    );

    let wrist = file(Board::Wrist, (1, 0, 3), 5000);
    let firmware =
        Firmware::new(&name(Board::Wrist, (1, 0, 3)), wrist.clone(), Board::Wrist).unwrap();
    let mut events = Vec::new();
    let report = flash(bus.md(), &firmware, &options(), &mut |e| {
        events.push(e.clone())
    })
    .unwrap();
    assert_eq!(
        (report.before.as_str(), report.after.as_str()),
        ("0.9.7", "1.0.3")
    );
    assert_eq!(report.transfer.bytes, 5016);
    // 256-byte bootstrap mailbox: 244 bytes per packet.
    assert_eq!(report.transfer.packets, 21);
    assert!(report.transfer.busy > 0, "the flash write answers BUSY");
    let steps: Vec<&str> = events
        .iter()
        .filter_map(|e| match e {
            FlashEvent::Step(s) => Some(s.as_str()),
            _ => None,
        })
        .collect();
    assert!(steps.iter().any(|s| s.contains("BOOT")), "{steps:?}");
    let progress: Vec<_> = events
        .iter()
        .filter_map(|e| match e {
            FlashEvent::Transfer(p) => Some(p),
            _ => None,
        })
        .collect();
    assert_eq!(progress.last().unwrap().acknowledged, 5016);
    assert!(progress.iter().any(|p| p.busy.is_some()));
    {
        let sim = sim.lock().unwrap();
        assert_eq!(sim.app().firmware_versions().1, "1.0.3");
        assert_eq!(
            sim.app().upgrade().flashed(Board::Wrist).unwrap().file,
            wrist,
            "the flash holds the file as sent"
        );
        assert_eq!(sim.stats().restarts, 1);
        assert!(
            sim.stats().frames_while_restarting > 0,
            "off the bus while restarting"
        );
    }

    let control = file(Board::Control, (2, 1, 0), 8000);
    let firmware =
        Firmware::new(&name(Board::Control, (2, 1, 0)), control, Board::Control).unwrap();
    let report = flash(bus.md(), &firmware, &options(), &mut |_| {}).unwrap();
    assert_eq!(
        (report.before.as_str(), report.after.as_str()),
        ("1.4.2", "2.1.0")
    );

    let info = usable(&sim, &bus);
    assert_eq!(
        (info.control_fw.as_str(), info.wrist_fw.as_str()),
        ("2.1.0", "1.0.3")
    );
}

#[test]
fn files_are_refused_before_the_device_is_touched() {
    let _serial = serial();
    let wrist_name = name(Board::Wrist, (1, 0, 3));
    let cases: Vec<(&str, String, Vec<u8>, Board, &str)> = vec![
        (
            "wrong magic",
            wrist_name.clone(),
            file(Board::Control, (1, 0, 3), 100),
            Board::Wrist,
            "magic number BRCC2025 is the control board's, not the wrist board's (BRCW2025)",
        ),
        (
            "unknown magic",
            wrist_name.clone(),
            {
                let mut f = file(Board::Wrist, (1, 0, 3), 100);
                f[..8].copy_from_slice(b"BRCX2025");
                f
            },
            Board::Wrist,
            "\"BRCX2025\" is not a Revo2 firmware's",
        ),
        (
            "wrong board",
            name(Board::Control, (1, 0, 3)),
            file(Board::Control, (1, 0, 3), 100),
            Board::Wrist,
            "firmware is for the control board, expected the wrist board",
        ),
        (
            "wrong file name (case)",
            "revo2EC_1.0.3_2506231346.bin".into(),
            file(Board::Wrist, (1, 0, 3), 100),
            Board::Wrist,
            "must start with \"Revo2EC_\"",
        ),
        (
            "wrong file name (extension case)",
            "Revo2EC_1.0.3_2506231346.BIN".into(),
            file(Board::Wrist, (1, 0, 3), 100),
            Board::Wrist,
            "must end with \".bin\"",
        ),
        (
            "truncated file",
            wrist_name.clone(),
            file(Board::Wrist, (1, 0, 3), 0)[..10].to_vec(),
            Board::Wrist,
            "the file has 10 bytes, fewer than the 16-byte firmware header: truncated",
        ),
        (
            "header only",
            wrist_name.clone(),
            file(Board::Wrist, (1, 0, 3), 0),
            Board::Wrist,
            "no firmware image: truncated",
        ),
        (
            "version differs",
            wrist_name.clone(),
            file(Board::Wrist, (1, 0, 4), 100),
            Board::Wrist,
            "the file name says version 1.0.3, the header 1.0.4",
        ),
    ];
    for (case, file_name, bytes, board, expected) in cases {
        let err = Firmware::new(&file_name, bytes, board).unwrap_err();
        let text = err.to_string();
        assert!(matches!(err, FlashError::Invalid { .. }), "{case}: {err:?}");
        assert!(
            text.contains(expected) && text.contains("refused before contacting the device"),
            "{case}: {text}"
        );
    }
    // From a file: the FoE name is the path's last component; a missing file is named.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name(Board::Control, (3, 0, 1)));
    std::fs::write(&path, file(Board::Control, (3, 0, 1), 64)).unwrap();
    let firmware = Firmware::load(&path, Board::Control).unwrap();
    assert_eq!(firmware.name(), "Revo2_V3.0.1_2506231346.bin");
    assert_eq!(firmware.version(), (3, 0, 1));
    let err = Firmware::load(
        &dir.path().join("Revo2_V3.0.2_2506231346.bin"),
        Board::Control,
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("Revo2_V3.0.2_2506231346.bin"),
        "{err}"
    );
}

#[test]
fn a_wrong_authentication_code_is_refused_by_the_device() {
    let _serial = serial();
    let sim = sim();
    let bus = bus(&sim);
    let firmware = Firmware::new(
        &name(Board::Wrist, (1, 1, 0)),
        file(Board::Wrist, (1, 1, 0), 1000),
        Board::Wrist,
    )
    .unwrap();
    let wrong_code = FlashOptions {
        auth_code: Some("BRCC2025".into()),
        ..options()
    };
    let err = flash(bus.md(), &firmware, &wrong_code, &mut |_| {}).unwrap_err();
    let text = err.to_string();
    match &err {
        FlashError::Transfer(e) => assert_eq!(e.code(), Some(ErrorCode::NO_RIGHTS)),
        other => panic!("{other:?}"),
    }
    assert!(
        text.contains("refused the write request")
            && text.contains("0x800a")
            && text.contains("authentication code (0x8000:16) is not the wrist board's"),
        "{text}"
    );
    {
        let sim = sim.lock().unwrap();
        assert_eq!(sim.al_state().0, AlState::Init, "sent back to INIT");
        assert_eq!(sim.app().firmware_versions().1, "0.9.7");
        assert!(sim.app().upgrade().flashed(Board::Wrist).is_none());
    }
    usable(&sim, &bus);
    // The right code works on the same device.
    let report = flash(bus.md(), &firmware, &options(), &mut |_| {}).unwrap();
    assert_eq!(report.after, "1.1.0");
    usable(&sim, &bus);
}

/// FoE straight to the device, past the file checks of `Firmware`: the device's own checks.
fn send(
    bus: &Bus,
    address: u16,
    layout: &teleop_revo2::flash::Mailboxes,
    name: &str,
    data: &[u8],
) -> FoeError {
    let (rx, tx) = layout.bootstrap;
    let port = EcatMailbox::new(bus.md(), address, rx, tx);
    let config = ClientConfig {
        reply_timeout: Duration::from_millis(300),
        ..ClientConfig::default()
    };
    Client::new(port, config)
        .write(name, data, &mut |_| {})
        .unwrap_err()
}

#[test]
fn the_device_checks_what_it_receives() {
    let _serial = serial();
    let sim = sim();
    let bus = bus(&sim);
    let md = bus.md();
    let timeout = Duration::from_secs(2);
    let good_name = name(Board::Wrist, (1, 2, 0));
    let good = file(Board::Wrist, (1, 2, 0), 600);

    let group = block_on(discover(md)).unwrap();
    let layout = mailboxes(md, &group).unwrap();
    assert_eq!(
        (
            layout.bootstrap.0.start,
            layout.bootstrap.0.len,
            layout.bootstrap.1.start
        ),
        (0x1000, 256, 0x1200),
        "the bootstrap mailbox from the SII"
    );
    assert_eq!(
        (layout.standard.0.len, layout.standard.1.start),
        (128, 0x1080)
    );
    // FoE outside BOOT: "bootstrap only".
    let (rx, tx) = layout.standard;
    let err = Client::new(
        EcatMailbox::new(md, layout.address, rx, tx),
        ClientConfig::default(),
    )
    .write(&good_name, &good, &mut |_| {})
    .unwrap_err();
    assert_eq!(err.code(), Some(ErrorCode::BOOTSTRAP_ONLY), "{err}");
    // BOOT without the upgrade type: "access denied".
    enter_boot(md, &layout, timeout).unwrap();
    assert_eq!(sim.lock().unwrap().al_state().0, AlState::Boot);
    let err = send(&bus, layout.address, &layout, &good_name, &good);
    assert_eq!(err.code(), Some(ErrorCode::ACCESS_DENIED), "{err}");
    assert!(err.to_string().contains("0x8000:15"), "{err}");
    leave_boot(md, layout.address, timeout);

    let group = block_on(discover(md)).unwrap();
    let layout = mailboxes(md, &group).unwrap();
    write_upgrade_settings(md, &layout, Board::Wrist, "BRCW2025", timeout).unwrap();
    enter_boot(md, &layout, timeout).unwrap();
    let cases: Vec<(&str, String, Vec<u8>, ErrorCode, &str)> = vec![
        (
            "wrong magic",
            good_name.clone(),
            file(Board::Control, (1, 2, 0), 600),
            ErrorCode::INVALID_FIRMWARE,
            "magic number BRCC2025 is the control board's, the upgrade type is the wrist board",
        ),
        (
            "file name case",
            good_name.to_lowercase(),
            good.clone(),
            ErrorCode::NOT_IN_BOOTSTRAP,
            "must start with \"Revo2EC_\"",
        ),
        (
            "other board's file name",
            name(Board::Control, (1, 2, 0)),
            good.clone(),
            ErrorCode::NOT_IN_BOOTSTRAP,
            "firmware is for the control board, expected the wrist board",
        ),
        (
            "truncated",
            good_name.clone(),
            good[..12].to_vec(),
            ErrorCode::INVALID_FIRMWARE,
            "shorter than the 16-byte header",
        ),
    ];
    for (case, file_name, data, code, text) in cases {
        let err = send(&bus, layout.address, &layout, &file_name, &data);
        assert_eq!(err.code(), Some(code), "{case}: {err}");
        assert!(err.to_string().contains(text), "{case}: {err}");
    }
    assert_eq!(sim.lock().unwrap().app().upgrade().refusals, 6);
    assert!(sim
        .lock()
        .unwrap()
        .app()
        .upgrade()
        .flashed(Board::Wrist)
        .is_none());
    leave_boot(md, layout.address, timeout);
    usable(&sim, &bus);
}

#[test]
fn a_device_that_stops_answering_mid_transfer_is_reported_and_recovers() {
    let _serial = serial();
    let sim = sim();
    let bus = bus(&sim);
    sim.lock().unwrap().app_mut().upgrade_mut().stall_after = Some(5);
    let firmware = Firmware::new(
        &name(Board::Wrist, (1, 3, 0)),
        file(Board::Wrist, (1, 3, 0), 4000),
        Board::Wrist,
    )
    .unwrap();
    let started = Instant::now();
    let err = flash(bus.md(), &firmware, &options(), &mut |_| {}).unwrap_err();
    match &err {
        FlashError::Transfer(FoeError::NoAnswer {
            packet, attempts, ..
        }) => assert_eq!((*packet, *attempts), (6, 5)),
        other => panic!("{other:?}"),
    }
    assert!(
        err.to_string()
            .contains("no answer from the device to data packet 6 after 5 attempts"),
        "{err}"
    );
    assert!(started.elapsed() < Duration::from_secs(5));
    {
        let sim = sim.lock().unwrap();
        assert_eq!(sim.al_state().0, AlState::Init, "sent back to INIT");
        assert!(
            !sim.app().upgrade().stalled(),
            "the boot loader answers again"
        );
        assert_eq!(sim.app().firmware_versions().1, "0.9.7");
    }
    usable(&sim, &bus);
    let report = flash(bus.md(), &firmware, &options(), &mut |_| {}).unwrap();
    assert_eq!(report.after, "1.3.0");
}

#[test]
fn a_device_that_leaves_the_bus_mid_transfer_is_reported_and_recovers() {
    let _serial = serial();
    let sim = sim();
    let bus = bus(&sim);
    let firmware = Firmware::new(
        &name(Board::Control, (1, 5, 0)),
        file(Board::Control, (1, 5, 0), 6000),
        Board::Control,
    )
    .unwrap();
    // The cable is pulled once a few packets went through.
    let pull = {
        let sim = sim.clone();
        std::thread::spawn(move || {
            let deadline = Instant::now() + Duration::from_secs(10);
            while Instant::now() < deadline {
                {
                    let mut s = sim.lock().unwrap();
                    if s.app().upgrade().data_packets >= 5 {
                        s.faults().link_down = true;
                        return true;
                    }
                }
                std::thread::sleep(Duration::from_micros(200));
            }
            false
        })
    };
    let err = flash(bus.md(), &firmware, &options(), &mut |_| {}).unwrap_err();
    assert!(
        pull.join().unwrap(),
        "the link went down during the transfer"
    );
    let text = err.to_string();
    assert!(
        matches!(
            err,
            FlashError::Transfer(FoeError::Link { .. } | FoeError::NoAnswer { .. })
        ),
        "{err:?}"
    );
    assert!(text.starts_with("firmware transfer failed: "), "{text}");
    sim.lock().unwrap().faults().link_down = false;
    let info = usable(&sim, &bus);
    assert_eq!(info.control_fw, "1.4.2", "the old firmware still runs");
}

#[test]
fn a_device_without_foe_or_bootstrap_mailbox_is_refused() {
    let _serial = serial();
    for (protocols, bootstrap, expected) in [
        (
            mailbox_protocols::COE,
            (0x1000, 256),
            "does not support FoE",
        ),
        (
            mailbox_protocols::COE | mailbox_protocols::FOE,
            (0, 0),
            "no bootstrap mailbox",
        ),
    ] {
        let config = teleop_ecat_sim::EscConfig {
            mailbox_protocols: protocols,
            bootstrap_rx_mailbox: bootstrap,
            bootstrap_tx_mailbox: (bootstrap.0 + 0x200, bootstrap.1),
            ..revo2_subdevice(None, 1).config().clone()
        };
        let sim: Sim = Arc::new(Mutex::new(revo2_behind(config, None)));
        let bus = bus(&sim);
        let firmware = Firmware::new(
            &name(Board::Wrist, (1, 0, 0)),
            file(Board::Wrist, (1, 0, 0), 100),
            Board::Wrist,
        )
        .unwrap();
        let err = flash(bus.md(), &firmware, &options(), &mut |_| {}).unwrap_err();
        assert!(err.to_string().contains(expected), "{err}");
        assert_eq!(sim.lock().unwrap().stats().mailbox_requests, 0);
    }
}
