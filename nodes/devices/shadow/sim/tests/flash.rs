//! The flasher of `teleop-shadow-protocol` against the emulated PIC18F bootloader, message by
//! message on simulated time: a generated HEX image is written, read back equal and started;
//! a board that does not answer MAGIC and one that stops mid-transfer are named with the step
//! and address, and both can be flashed again.
#![allow(clippy::unwrap_used)]

use teleop_shadow_protocol::can::{APP_START, ROW};
use teleop_shadow_protocol::flash::{FlashError, Flasher, Poll, Settings, Step};
use teleop_shadow_protocol::hex::{self, Image};
use teleop_sim_shadow::bootloader::{generated_application, Board, Mode};

fn image(bytes: &[u8]) -> Image {
    hex::parse(&hex::write(APP_START, bytes)).unwrap()
}

/// Runs `flasher` against `board` until it ends; returns the result, the simulated time (ms)
/// and the messages sent.
fn run(flasher: &mut Flasher, board: &mut Board) -> (Result<(), FlashError>, u64, u64) {
    let (mut now, mut sent) = (0u64, 0u64);
    loop {
        for reply in board.take_sent(now) {
            flasher.receive(&reply);
        }
        match flasher.poll(now) {
            Poll::Send(msg) => {
                sent += 1;
                board.receive(&msg, now);
            }
            Poll::Wait(_) => now += 1,
            Poll::Done => return (Ok(()), now, sent),
            Poll::Failed(e) => return (Err(e), now, sent),
        }
        assert!(now < 600_000, "the flasher never ended");
    }
}

#[test]
fn an_image_is_written_read_back_and_started() {
    let app = generated_application(3000, 7);
    let img = image(&app);
    // A board running an older application: MAGIC sends it to its bootloader first.
    let mut board = Board::new(4, &generated_application(2000, 1));
    assert_eq!(board.mode(), Mode::Application);
    board.take_sent(0);
    let mut flasher = Flasher::new(4, img.clone(), Settings::default());
    let (result, ms, sent) = run(&mut flasher, &mut board);
    result.unwrap();
    assert_eq!(board.mode(), Mode::Application);
    let start = APP_START as usize;
    assert_eq!(&board.flash()[start..start + app.len()], &app[..]);
    // The rest of the last row and of the area is erased.
    assert!(board.flash()[start + app.len()..0x7DC0]
        .iter()
        .all(|b| *b == 0xFF));
    assert_eq!(board.rows_programmed, img.rows.len() as u64);
    assert_eq!(flasher.progress(), (img.rows.len(), img.rows.len()));
    // MAGIC, ERASE, 5 per row, 4 reads per row, RESET.
    let rows = img.rows.len() as u64;
    assert_eq!(sent, 2 + 5 * rows + (ROW as u64 / 8) * rows + 1);
    eprintln!("{rows} rows, {sent} messages, {ms} ms of simulated waiting (the erase)");
}

#[test]
fn a_board_that_does_not_answer_magic_is_named_and_can_be_flashed_later() {
    let img = image(&generated_application(500, 3));
    let mut board = Board::new(2, &[]);
    board.take_sent(0);
    board.silent = true;
    let mut flasher = Flasher::new(2, img.clone(), Settings::default());
    let (result, _, sent) = run(&mut flasher, &mut board);
    let e = result.unwrap_err();
    assert!(
        matches!(
            e,
            FlashError::NoAnswer {
                board: 2,
                step: Step::Magic,
                tries: 2,
                last: None
            }
        ),
        "{e:?}"
    );
    assert_eq!(sent, 2, "MAGIC and one retry, as the shipped flasher");
    assert!(e.to_string().contains("no acknowledgement of MAGIC"), "{e}");
    board.silent = false;
    let (result, _, _) = run(&mut Flasher::new(2, img, Settings::default()), &mut board);
    result.unwrap();
    assert_eq!(board.mode(), Mode::Application);
}

#[test]
fn a_board_that_stops_mid_transfer_is_named_with_the_address_and_stays_in_its_bootloader() {
    let app = generated_application(2000, 5);
    let img = image(&app);
    let mut board = Board::new(0, &[]);
    board.take_sent(0);
    board.stop_after = Some(150);
    let mut flasher = Flasher::new(0, img.clone(), Settings::default());
    let (result, _, _) = run(&mut flasher, &mut board);
    let e = result.unwrap_err();
    let FlashError::NoAnswer { step, tries, .. } = &e else {
        panic!("{e:?}");
    };
    assert!(
        matches!(step, Step::Address(a) | Step::Data(a, _) if *a >= APP_START),
        "{step:?}"
    );
    assert_eq!(*tries, Settings::default().tries);
    eprintln!("{e}");
    assert!(e.to_string().contains("0x0"), "the address is named: {e}");
    // The board is left in its bootloader: flashing again works.
    assert_eq!(board.mode(), Mode::Bootloader);
    board.stop_after = None;
    let (result, _, _) = run(&mut Flasher::new(0, img, Settings::default()), &mut board);
    result.unwrap();
    let start = APP_START as usize;
    assert_eq!(&board.flash()[start..start + app.len()], &app[..]);
}

#[test]
fn a_read_back_that_differs_is_a_mismatch_naming_the_address() {
    let img = image(&generated_application(64, 9));
    let mut board = Board::new(1, &[]);
    board.take_sent(0);
    let mut flasher = Flasher::new(1, img, Settings::default());
    // Let it write, then spoil a byte of the first row before the read-back.
    let mut now = 0;
    loop {
        for reply in board.take_sent(now) {
            flasher.receive(&reply);
        }
        if matches!(flasher.step(), Step::Verify(_)) {
            break;
        }
        match flasher.poll(now) {
            Poll::Send(msg) => board.receive(&msg, now),
            Poll::Wait(_) => now += 1,
            other => panic!("{other:?}"),
        }
    }
    // Program a zero over the first byte (flash bits only clear).
    use teleop_shadow_protocol::can::BootMessage;
    board.receive(&BootMessage::address(1, APP_START), now);
    board.receive(&BootMessage::write(1, [0; 8]), now);
    for _ in 0..3 {
        board.receive(&BootMessage::write(1, [0xFF; 8]), now);
    }
    board.take_sent(now);
    let (result, _, _) = run(&mut flasher, &mut board);
    let e = result.unwrap_err();
    assert!(
        matches!(e, FlashError::Mismatch { board: 1, address, .. } if address == APP_START),
        "{e:?}"
    );
    assert!(e.to_string().contains("0x04c0"), "{e}");
}

/// The whole path but EtherCAT: the flasher's messages go one per 1 ms cycle into the palm's
/// CAN bridge command in CAN direct mode (later cycles carry an idle bridge), and the bridge
/// status carries the bootloader's replies back (an ERASE's echo on a later cycle).
#[test]
fn flashing_motor_13_through_the_palm_in_can_direct_mode() {
    use teleop_shadow_protocol::can::BootMessage;
    use teleop_shadow_protocol::data::EdcNumbering;
    use teleop_shadow_protocol::layout::{CanBridge, Command};
    use teleop_sim_shadow::palm::Palm;

    let app = generated_application(700, 11);
    let img = image(&app);
    let mut palm = Palm::new();
    let direct = Command::can_direct_mode(EdcNumbering::Shipped);
    // Motor 13 is board 3 on bus 2.
    let mut flasher = Flasher::new(3, img, Settings::default());
    let mut now = Palm::BOOT_MS;
    let result = loop {
        let bridge = match flasher.poll(now) {
            Poll::Send(m) => Some(CanBridge {
                can_bus: 2,
                length: m.len,
                id: m.id,
                data: m.data,
            }),
            Poll::Wait(_) => None,
            Poll::Done => break Ok(()),
            Poll::Failed(e) => break Err(e),
        };
        let (status, reply) = palm.cycle(&direct, bridge.as_ref(), now);
        assert!(status.is_none());
        if let Some(r) = reply.or_else(|| palm.pending_reply(now)) {
            flasher.receive(&BootMessage {
                id: r.id,
                len: r.length,
                data: r.data,
            });
        }
        now += 1;
        assert!(now < 100_000, "never ended");
    };
    result.unwrap();
    assert_eq!(palm.boards[13].mode(), Mode::Application);
    let start = APP_START as usize;
    assert_eq!(&palm.boards[13].flash()[start..start + app.len()], &app[..]);
    eprintln!(
        "{} ms of 1 ms cycles for {} bytes",
        now - Palm::BOOT_MS,
        app.len()
    );
}
