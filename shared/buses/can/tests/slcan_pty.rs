//! `SlcanLink` against a fake slcan adapter on a pseudo-terminal: the open sequence, both ack
//! styles, refusals, frames mixed with acks, status flags, and the adapter going away.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use teleop_can_link::slcan::{self, Command, CommandDecoder};
use teleop_can_link::{Bitrate, BusState, CanFrame, CanLink, LinkError, SlcanLink};

/// How the fake adapter acknowledges transmitted frames.
#[derive(Clone, Copy, PartialEq)]
enum Acks {
    /// A bare CR for every line, frames included (CANable).
    Canable,
    /// CR for commands, `z`/`Z` for `t`/`T` (CAN232, CANUSB).
    Lawicel,
    /// No ack for frames at all.
    Silent,
}

#[derive(Clone)]
struct Behaviour {
    acks: Acks,
    /// Commands answered with BEL (by their first letter).
    refuse: &'static [u8],
    /// Commands not answered at all.
    mute: &'static [u8],
    /// Whether `F` is known (else BEL).
    status: bool,
}

impl Default for Behaviour {
    fn default() -> Self {
        Self {
            acks: Acks::Canable,
            refuse: b"",
            mute: b"",
            status: true,
        }
    }
}

enum Action {
    /// Write these bytes to the host.
    Write(Vec<u8>),
    /// Pull the cable: close the pty.
    Unplug,
}

struct FakeAdapter {
    path: PathBuf,
    commands: Arc<Mutex<Vec<Command>>>,
    flags: Arc<Mutex<u8>>,
    actions: Sender<Action>,
    thread: Option<JoinHandle<()>>,
    _slave: TTYPort,
}

impl FakeAdapter {
    fn start(behaviour: Behaviour) -> Self {
        // The pair takes no lock on the slave side, so the link can open it exclusively.
        let (mut master, slave) = TTYPort::pair().expect("pty");
        let path = PathBuf::from(slave.name().expect("pty name"));
        master
            .set_timeout(Duration::from_millis(2))
            .expect("timeout");
        let commands = Arc::new(Mutex::new(Vec::new()));
        let flags = Arc::new(Mutex::new(0u8));
        let (tx, rx) = channel();
        let thread = {
            let (commands, flags) = (commands.clone(), flags.clone());
            std::thread::spawn(move || serve(master, behaviour, &commands, &flags, rx))
        };
        Self {
            path,
            commands,
            flags,
            actions: tx,
            thread: Some(thread),
            _slave: slave,
        }
    }

    fn commands(&self) -> Vec<Command> {
        self.commands.lock().expect("lock").clone()
    }

    fn write(&self, bytes: &[u8]) {
        self.actions
            .send(Action::Write(bytes.to_vec()))
            .expect("adapter running");
    }

    fn set_flags(&self, flags: u8) {
        *self.flags.lock().expect("lock") = flags;
    }

    fn unplug(&mut self) {
        let _ = self.actions.send(Action::Unplug);
        if let Some(t) = self.thread.take() {
            t.join().expect("adapter thread");
        }
    }
}

impl Drop for FakeAdapter {
    fn drop(&mut self) {
        self.unplug();
    }
}

fn serve(
    mut master: TTYPort,
    b: Behaviour,
    commands: &Mutex<Vec<Command>>,
    flags: &Mutex<u8>,
    actions: Receiver<Action>,
) {
    let mut decoder = CommandDecoder::new();
    let mut buf = [0u8; 256];
    let mut open = false;
    loop {
        loop {
            match actions.try_recv() {
                Ok(Action::Write(bytes)) => {
                    let _ = master.write_all(&bytes);
                }
                Ok(Action::Unplug) | Err(std::sync::mpsc::TryRecvError::Disconnected) => return,
                Err(std::sync::mpsc::TryRecvError::Empty) => break,
            }
        }
        let n = match master.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
            Err(_) => {
                std::thread::sleep(Duration::from_millis(1));
                continue;
            }
        };
        let mut out = Vec::new();
        decoder.push(&buf[..n], &mut |cmd| {
            let Ok(cmd) = cmd else {
                out.push(0x07);
                return;
            };
            commands.lock().expect("lock").push(cmd);
            let mut line = Vec::new();
            cmd.encode(&mut line);
            if b.mute.contains(&line[0]) {
                return;
            }
            if b.refuse.contains(&line[0]) {
                out.push(0x07);
                return;
            }
            match cmd {
                Command::Open => {
                    open = true;
                    out.push(b'\r');
                }
                Command::Close => {
                    if open {
                        open = false;
                        out.push(b'\r');
                    } else {
                        out.push(0x07);
                    }
                }
                Command::Status if b.status => {
                    let mut f = flags.lock().expect("lock");
                    out.extend_from_slice(format!("F{:02X}\r", *f).as_bytes());
                    // Reading clears the flags (Lawicel).
                    *f = 0;
                }
                Command::Status => out.push(0x07),
                Command::Transmit(frame) if open => match b.acks {
                    Acks::Canable => out.push(b'\r'),
                    Acks::Lawicel if frame.is_extended() => out.extend_from_slice(b"Z\r"),
                    Acks::Lawicel => out.extend_from_slice(b"z\r"),
                    Acks::Silent => {}
                },
                Command::Transmit(_) => out.push(0x07),
                _ => out.push(b'\r'),
            }
        });
        if !out.is_empty() {
            let _ = master.write_all(&out);
        }
    }
}

fn frame(id: u16, data: &[u8]) -> CanFrame {
    CanFrame::standard(id, data).expect("valid frame")
}

fn open(adapter: &FakeAdapter) -> SlcanLink {
    SlcanLink::open(&adapter.path, 115_200, Bitrate::MBIT_1).expect("open")
}

/// Receives until `n` frames came or `limit` passed.
fn recv_frames(link: &mut SlcanLink, n: usize, limit: Duration) -> Vec<CanFrame> {
    let deadline = Instant::now() + limit;
    let mut got = Vec::new();
    while got.len() < n && Instant::now() < deadline {
        if let Some(f) = link.recv(Duration::from_millis(20)).expect("recv") {
            got.push(f);
        }
    }
    got
}

#[test]
fn open_sequence_is_close_bitrate_status_timestamps_open() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let link = open(&adapter);
    assert_eq!(
        adapter.commands(),
        vec![
            Command::Close,
            Command::Bitrate(8),
            Command::Status,
            Command::Timestamps(true),
            Command::Open
        ]
    );
    assert!(link.status_supported());
    assert_eq!(link.bus_state(), BusState::ErrorActive);
    assert_eq!(link.describe(), format!("slcan:{}", adapter.path.display()));
}

/// Frames stamped by the adapter (`Z1`) give their stamp back with `rx_stamp_ms`; an adapter
/// that refuses `Z1` still opens, and its frames have none.
#[test]
fn adapter_timestamps_come_with_the_frames() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let mut link = open(&adapter);
    link.set_status_interval(None);
    assert_eq!(link.rx_stamp_ms(), None);
    adapter.write(b"t0803010203EA5F\rt0803010203000B\r");
    let mut stamps = Vec::new();
    for _ in 0..2 {
        let f = link
            .recv(Duration::from_secs(2))
            .expect("recv")
            .expect("frame");
        assert_eq!(f, frame(0x080, &[1, 2, 3]));
        stamps.push(link.rx_stamp_ms());
    }
    assert_eq!(stamps, [Some(59_999), Some(11)]);
    assert_eq!(teleop_can_link::stamp_gap_ms(59_999, 11), 12);

    let adapter = FakeAdapter::start(Behaviour {
        refuse: b"Z",
        ..Behaviour::default()
    });
    let mut link = open(&adapter);
    adapter.write(b"t0803010203\r");
    let f = link.recv(Duration::from_secs(2)).expect("recv");
    assert_eq!(f, Some(frame(0x080, &[1, 2, 3])));
    assert_eq!(link.rx_stamp_ms(), None);
}

#[test]
fn canable_acks_every_line_with_cr() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let mut link = open(&adapter);
    link.set_status_interval(None);
    let sent = [frame(0x100, &[]), frame(0x204, &[3, 0, 0, 0, 0, 0])];
    for f in &sent {
        link.send(f).expect("send");
    }
    // The acks (bare CRs) are skipped; a frame from the hand after them is received.
    adapter.write(b"t0803010203\r");
    let got = recv_frames(&mut link, 1, Duration::from_secs(2));
    assert_eq!(got, vec![frame(0x080, &[1, 2, 3])]);
    assert_eq!(link.recv(Duration::from_millis(30)).expect("recv"), None);
    let transmitted: Vec<Command> = adapter.commands().into_iter().skip(5).collect();
    assert_eq!(transmitted, sent.map(Command::Transmit).to_vec());
    let c = link.counters();
    assert_eq!((c.tx, c.rx, c.errors), (2, 1, 0));
}

#[test]
fn lawicel_acks_with_z() {
    let adapter = FakeAdapter::start(Behaviour {
        acks: Acks::Lawicel,
        ..Behaviour::default()
    });
    let mut link = open(&adapter);
    link.set_status_interval(None);
    link.send(&frame(0x18A, &[0, 0x50, 0, 0x50, 0, 0x50, 0, 0x50]))
        .expect("send");
    link.send(&CanFrame::extended(0x1234_5678, &[1]).expect("valid"))
        .expect("send");
    adapter.write(b"t3D480000000000000000\r");
    let got = recv_frames(&mut link, 1, Duration::from_secs(2));
    assert_eq!(got, vec![frame(0x3D4, &[0; 8])]);
    assert_eq!(link.counters().errors, 0);
}

#[test]
fn silent_adapter_needs_no_acks() {
    let adapter = FakeAdapter::start(Behaviour {
        acks: Acks::Silent,
        ..Behaviour::default()
    });
    let mut link = open(&adapter);
    for _ in 0..20 {
        link.send(&frame(0x100, &[])).expect("send");
    }
    adapter.write(b"t1000\r");
    assert_eq!(recv_frames(&mut link, 1, Duration::from_secs(2)).len(), 1);
}

#[test]
fn bel_on_open_names_the_command() {
    let adapter = FakeAdapter::start(Behaviour {
        refuse: b"O",
        ..Behaviour::default()
    });
    match SlcanLink::open(&adapter.path, 115_200, Bitrate::MBIT_1) {
        Err(LinkError::Adapter { what, detail }) => {
            assert!(what.starts_with("slcan:"), "{what}");
            assert!(detail.contains("`O`"), "{detail}");
            assert!(detail.contains("open the channel"), "{detail}");
            assert!(detail.contains("BEL"), "{detail}");
        }
        Err(e) => panic!("unexpected error: {e}"),
        Ok(_) => panic!("open succeeded though the adapter refused O"),
    }
}

#[test]
fn bel_on_bitrate_names_the_command() {
    let adapter = FakeAdapter::start(Behaviour {
        refuse: b"S",
        ..Behaviour::default()
    });
    let err = SlcanLink::open(&adapter.path, 115_200, Bitrate::MBIT_1)
        .err()
        .expect("refused");
    let shown = err.to_string();
    assert!(matches!(err, LinkError::Adapter { .. }), "{shown}");
    assert!(
        shown.contains("`S8`") && shown.contains("set bit rate"),
        "{shown}"
    );
    assert!(!err.is_recoverable());
}

#[test]
fn mute_adapter_is_named() {
    let adapter = FakeAdapter::start(Behaviour {
        mute: b"CS",
        ..Behaviour::default()
    });
    let err = SlcanLink::open(&adapter.path, 115_200, Bitrate::MBIT_1)
        .err()
        .expect("no answer");
    let shown = err.to_string();
    assert!(shown.contains("no answer to `S8`"), "{shown}");
}

#[test]
fn adapter_without_status_still_opens() {
    let adapter = FakeAdapter::start(Behaviour {
        status: false,
        ..Behaviour::default()
    });
    let link = open(&adapter);
    assert!(!link.status_supported());
    assert_eq!(adapter.commands().last(), Some(&Command::Open));
}

#[test]
fn frames_interleaved_with_acks_errors_and_empty_lines() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let mut link = open(&adapter);
    link.set_status_interval(None);
    // Acks of both styles, a BEL, empty lines, CRLF, a timestamped frame, garbage, and frames
    // split across writes.
    adapter.write(b"\rz\rt1230\r\x07Z\r\r\n\r\nt4563112233\rt3D3");
    adapter.write(b"20102EA5F\rxyz\rT12ABCDEF2AA55\r");
    let got = recv_frames(&mut link, 4, Duration::from_secs(2));
    assert_eq!(
        got,
        vec![
            frame(0x123, &[]),
            frame(0x456, &[0x11, 0x22, 0x33]),
            frame(0x3D3, &[0x01, 0x02]),
            CanFrame::extended(0x12AB_CDEF, &[0xAA, 0x55]).expect("valid"),
        ]
    );
    let c = link.counters();
    assert_eq!(c.rx, 4);
    assert_eq!(c.errors, 2, "one BEL and one garbage line");
}

#[test]
fn status_flags_give_the_bus_state() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let mut link = open(&adapter);
    link.set_status_interval(Some(Duration::from_millis(5)));
    adapter.set_flags(slcan::status::ERROR_PASSIVE);
    let deadline = Instant::now() + Duration::from_secs(2);
    while link.bus_state() != BusState::ErrorPassive && Instant::now() < deadline {
        link.recv(Duration::from_millis(10)).expect("recv");
    }
    assert_eq!(link.bus_state(), BusState::ErrorPassive);
    // Bus-off (the simulator sets bus error and error passive): reported once by recv.
    adapter.set_flags(slcan::status::BUS_ERROR | slcan::status::ERROR_PASSIVE);
    let deadline = Instant::now() + Duration::from_secs(2);
    let err = loop {
        match link.recv(Duration::from_millis(10)) {
            Err(e) => break e,
            Ok(_) if Instant::now() < deadline => {}
            Ok(_) => panic!("no bus-off reported"),
        }
    };
    assert!(matches!(err, LinkError::BusOff { .. }), "{err}");
    assert!(err.is_recoverable());
    assert_eq!(link.bus_state(), BusState::BusOff);
    // The flags clear when read: back to error-active, and no second report.
    let deadline = Instant::now() + Duration::from_secs(2);
    while link.bus_state() != BusState::ErrorActive && Instant::now() < deadline {
        link.recv(Duration::from_millis(10)).expect("recv");
    }
    assert_eq!(link.bus_state(), BusState::ErrorActive);
    // Overrun flags are counted.
    adapter.set_flags(slcan::status::DATA_OVERRUN);
    let deadline = Instant::now() + Duration::from_secs(2);
    while link.counters().overruns == 0 && Instant::now() < deadline {
        link.recv(Duration::from_millis(10)).expect("recv");
    }
    assert_eq!(link.counters().overruns, 1);
}

#[test]
fn linux_driver_state_lines() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let mut link = open(&adapter);
    link.set_status_interval(None);
    adapter.write(b"sw100020\rt1000\r");
    assert_eq!(recv_frames(&mut link, 1, Duration::from_secs(2)).len(), 1);
    assert_eq!(link.bus_state(), BusState::ErrorWarning);
    adapter.write(b"sb256256\r");
    let err = link.recv(Duration::from_secs(2)).expect_err("bus-off");
    assert!(matches!(err, LinkError::BusOff { .. }), "{err}");
}

#[test]
fn unplugged_adapter_is_disconnected() {
    let mut adapter = FakeAdapter::start(Behaviour::default());
    let mut link = open(&adapter);
    adapter.unplug();
    let err = link
        .recv(Duration::from_secs(2))
        .expect_err("the pty is closed");
    assert!(matches!(err, LinkError::Disconnected { .. }), "{err}");
    assert!(err.is_recoverable());
    assert!(err.to_string().contains("unplugged"), "{err}");
}

#[test]
fn recv_waits_without_spinning() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let mut link = open(&adapter);
    link.set_status_interval(None);
    let start = Instant::now();
    assert_eq!(link.recv(Duration::from_millis(50)).expect("recv"), None);
    let waited = start.elapsed();
    assert!(waited >= Duration::from_millis(50), "{waited:?}");
    // A zero timeout returns at once with what is there.
    assert_eq!(link.recv(Duration::ZERO).expect("recv"), None);
}

#[test]
fn missing_device_is_not_found() {
    let err = SlcanLink::open(
        std::path::Path::new("/dev/does-not-exist-slcan"),
        115_200,
        Bitrate::MBIT_1,
    )
    .err()
    .expect("missing");
    assert!(matches!(err, LinkError::NotFound { .. }), "{err}");
    assert!(err.to_string().contains("plugged in"), "{err}");
}

#[test]
fn odd_bitrate_is_unsupported() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let err = SlcanLink::open(&adapter.path, 115_200, Bitrate(83_333))
        .err()
        .expect("no S code");
    assert!(matches!(err, LinkError::Unsupported { .. }), "{err}");
}

#[test]
fn open_through_the_link_spec() {
    let adapter = FakeAdapter::start(Behaviour::default());
    let spec: teleop_can_link::LinkSpec = format!("slcan:{}", adapter.path.display())
        .parse()
        .expect("spec");
    let mut link = teleop_can_link::open(&spec, Bitrate::MBIT_1).expect("open");
    link.send(&frame(0x04A, &[])).expect("send");
    assert_eq!(link.counters().tx, 1);
}
