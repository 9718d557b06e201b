//! The simulated hand on its bus: the stream's pace over the local bus and the socket, and the
//! simulated slcan adapter on a real pty driven by the node's own `SlcanLink` (open, frames
//! both ways, BEL while closed, both ack styles, bus-off in the status flags, unplug and a new
//! pty behind the same link).
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::SerialPort;
use teleop_allegro_protocol::{doc, v4, Generation};
use teleop_can_link::local::SocketLink;
use teleop_can_link::{Bitrate, BusState, CanFrame, CanLink, LinkError, SlcanLink};
use teleop_sim_allegro::adapter::AckStyle;
use teleop_sim_allegro::firmware::{Firmware, FirmwareOptions};
use teleop_sim_allegro::hand::{Hand, HandParams};
use teleop_sim_allegro::{Sim, SimOptions};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("sim-allegro-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn sim(generation: Generation, slcan: Option<&Path>, socket: Option<&Path>, ack: AckStyle) -> Sim {
    let hand = Hand::allegro(HandParams::default(), None).unwrap();
    Sim::start(
        Firmware::new(FirmwareOptions::new(generation), hand),
        SimOptions {
            slcan: slcan.map(Path::to_path_buf),
            socket: socket.map(Path::to_path_buf),
            ack_style: ack,
            seed: 1,
        },
    )
    .unwrap()
}

fn start_v4(link: &mut dyn CanLink) {
    link.send(
        &v4::Request::SetPeriod {
            position_ms: 3,
            imu_ms: 0,
            temperature_ms: 0,
        }
        .encode(0),
    )
    .unwrap();
    link.send(&v4::Request::SystemOn.encode(0)).unwrap();
}

/// Frames received within `window`.
fn collect(link: &mut dyn CanLink, window: Duration) -> Vec<(Instant, CanFrame)> {
    let end = Instant::now() + window;
    let mut out = Vec::new();
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if let Ok(Some(f)) = link.recv(left) {
            out.push((Instant::now(), f));
        }
    }
    out
}

#[test]
fn the_stream_runs_at_its_period_on_the_local_bus() {
    let sim = sim(Generation::V4, None, None, AckStyle::Canable);
    let mut host = sim.bus().end();
    start_v4(&mut host);
    // Let the stream start, then count over 300 ms: 100 periods of four frames.
    collect(&mut host, Duration::from_millis(30));
    let frames = collect(&mut host, Duration::from_millis(300));
    let positions = frames
        .iter()
        .filter(|(_, f)| (0x080..=0x08C).contains(&f.raw_id()))
        .count();
    assert!(
        (360..=440).contains(&positions),
        "about 400 position frames in 300 ms: {positions}"
    );
    // Four frames back to back on the wire (about 0.11-0.13 ms each at 1 Mbit/s).
    let ids: Vec<u32> = frames.iter().take(8).map(|(_, f)| f.raw_id()).collect();
    assert!(
        ids.windows(4).any(|w| w == [0x080, 0x084, 0x088, 0x08C]),
        "{ids:X?}"
    );
    // SYSTEM_OFF stops it.
    host.send(&v4::Request::SystemOff.encode(0)).unwrap();
    collect(&mut host, Duration::from_millis(20));
    assert!(collect(&mut host, Duration::from_millis(50)).is_empty());
    assert!(!sim.status().streaming);
}

#[test]
fn a_socket_client_drives_the_hand() {
    let d = dir("socket");
    let path = d.join("bus.sock");
    let sim = sim(Generation::V3, None, Some(&path), AckStyle::Canable);
    let mut link = SocketLink::connect(&path).unwrap();
    let g = Generation::V3;
    link.send(&doc::Request::SetPeriod { ms: 3 }.encode(g.torque_order()))
        .unwrap();
    link.send(&doc::Request::SystemOn.encode(g.torque_order()))
        .unwrap();
    let frames = collect(&mut link, Duration::from_millis(100));
    assert!(frames.len() > 100, "{}", frames.len());
    assert!(frames
        .iter()
        .all(|(_, f)| (0x3D3..=0x3D6).contains(&f.raw_id())));
    drop(sim);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn slcan_link_opens_the_simulated_adapter_and_frames_pass_both_ways() {
    for ack in [AckStyle::Canable, AckStyle::Lawicel] {
        let d = dir(&format!("slcan-{ack:?}"));
        let link_path = d.join("can");
        let sim = sim(Generation::V4, Some(&link_path), None, ack);
        let mut link = SlcanLink::open(&link_path, 115_200, Bitrate(1_000_000)).unwrap();
        let info = v4::Request::QueryInfo.encode::<CanFrame>(0);
        link.send(&info).unwrap();
        let answer = collect(&mut link, Duration::from_millis(100));
        assert_eq!(
            answer.iter().map(|(_, f)| f.raw_id()).collect::<Vec<_>>(),
            [0x200],
            "{ack:?}"
        );
        start_v4(&mut link);
        collect(&mut link, Duration::from_millis(20));
        let frames = collect(&mut link, Duration::from_millis(150));
        assert!(frames.len() >= 160, "{ack:?}: {}", frames.len());
        assert_eq!(link.counters().errors, 0, "{ack:?}: {:?}", link.counters());
        let s = sim.status();
        assert!(s.system_on && s.streaming, "{ack:?}");
        assert_eq!(s.counters.frames_in, 3, "{ack:?}");
        assert_eq!(link.bus_state(), BusState::ErrorActive);
        drop(link);
        drop(sim);
        let _ = std::fs::remove_dir_all(&d);
    }
}

/// Writes `text` to the raw port and reads what comes back within 100 ms.
fn exchange(port: &mut dyn SerialPort, text: &str) -> Vec<u8> {
    port.write_all(text.as_bytes()).unwrap();
    let end = Instant::now() + Duration::from_millis(100);
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    while Instant::now() < end {
        match port.read(&mut buf) {
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => panic!("{e}"),
        }
    }
    got
}

#[test]
fn the_adapter_refuses_frames_while_closed_and_bit_rates_while_open() {
    let d = dir("raw");
    let link_path = d.join("can");
    let _sim = sim(Generation::V3, Some(&link_path), None, AckStyle::Lawicel);
    let mut port = serialport::new(link_path.to_string_lossy(), 115_200)
        .timeout(Duration::from_millis(10))
        .open_native()
        .unwrap();
    assert_eq!(exchange(&mut port, "t04A0\r"), b"\x07");
    assert_eq!(exchange(&mut port, "S8\rO\r"), b"\r\r");
    assert_eq!(exchange(&mut port, "S8\r"), b"\x07");
    assert_eq!(exchange(&mut port, "V\r"), b"V1013\r");
    // QUERY_STATE: acked with z, answered with the four fingers' 0x0E state frames as t lines.
    let got = String::from_utf8(exchange(&mut port, "t38A0\r")).unwrap();
    assert!(got.starts_with("z\r"), "{got:?}");
    let lines: Vec<&str> = got[2..].split('\r').filter(|l| !l.is_empty()).collect();
    assert_eq!(lines.len(), 4, "{got:?}");
    assert!(lines[0].starts_with("t3938"), "{got:?}");
    assert_eq!(exchange(&mut port, "C\r"), b"\r");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bus_off_shows_in_the_status_flags_and_nothing_passes() {
    let d = dir("busoff");
    let link_path = d.join("can");
    let sim = sim(Generation::V4, Some(&link_path), None, AckStyle::Canable);
    let mut link = SlcanLink::open(&link_path, 115_200, Bitrate(1_000_000)).unwrap();
    start_v4(&mut link);
    assert!(!collect(&mut link, Duration::from_millis(50)).is_empty());
    sim.bus_off(Duration::from_millis(400));
    // The link asks for the flags every 100 ms: it reports bus-off once, then nothing passes.
    let end = Instant::now() + Duration::from_millis(300);
    let mut bus_off = false;
    let mut after = 0;
    while Instant::now() < end {
        match link.recv(Duration::from_millis(20)) {
            Err(LinkError::BusOff { .. }) => bus_off = true,
            Ok(Some(_)) if bus_off => after += 1,
            _ => {}
        }
    }
    assert!(bus_off, "{:?}", link.bus_state());
    assert_eq!(after, 0);
    assert!(sim.stats().lost_bus_off > 0);
    // Back on: the stream passes again.
    std::thread::sleep(Duration::from_millis(200));
    assert!(!collect(&mut link, Duration::from_millis(200)).is_empty());
    drop(link);
    drop(sim);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn unplug_removes_the_pty_and_plugs_a_new_one_in_behind_the_same_link() {
    let d = dir("unplug");
    let link_path = d.join("can");
    let sim = sim(Generation::V4, Some(&link_path), None, AckStyle::Canable);
    let before = std::fs::read_link(&link_path).unwrap();
    let mut link = SlcanLink::open(&link_path, 115_200, Bitrate(1_000_000)).unwrap();
    start_v4(&mut link);
    assert!(!collect(&mut link, Duration::from_millis(50)).is_empty());
    assert!(sim.unplug(Duration::from_millis(300)));
    let end = Instant::now() + Duration::from_millis(250);
    let mut gone = None;
    while Instant::now() < end && gone.is_none() {
        if let Err(e) = link.recv(Duration::from_millis(20)) {
            gone = Some(e);
        }
    }
    let gone = gone.expect("the link notices the adapter is gone");
    assert!(gone.is_recoverable(), "{gone}");
    assert!(!link_path.exists() && !sim.plugged());
    assert!(matches!(
        SlcanLink::open(&link_path, 115_200, Bitrate(1_000_000)),
        Err(LinkError::NotFound { .. })
    ));
    let end = Instant::now() + Duration::from_secs(2);
    while !link_path.exists() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(10));
    }
    let after = std::fs::read_link(&link_path).unwrap();
    assert!(sim.plugged());
    assert_ne!(before, after, "a new pty");
    // The adapter came back closed; the hand kept streaming: reopening gets frames again.
    let mut link = SlcanLink::open(&link_path, 115_200, Bitrate(1_000_000)).unwrap();
    assert!(!collect(&mut link, Duration::from_millis(100)).is_empty());
    assert_eq!(sim.stats().unplugs, 1);
    drop(link);
    drop(sim);
    let _ = std::fs::remove_dir_all(&d);
}

/// The node's `SlcanLink` asks for `Z1` timestamps; the simulated adapter stamps each frame
/// with the time it was on the bus (the hand's due time), so the stream's stamps are 3 ms apart
/// whenever the frames reach the host (here read in bursts after 40 ms naps).
#[test]
fn the_adapter_stamps_frames_with_their_bus_time() {
    let d = dir("stamps");
    let link_path = d.join("can");
    let sim = sim(Generation::V4, Some(&link_path), None, AckStyle::Canable);
    let mut link = SlcanLink::open(&link_path, 115_200, Bitrate(1_000_000)).unwrap();
    start_v4(&mut link);
    collect(&mut link, Duration::from_millis(20));
    let mut stamps = Vec::new();
    let end = Instant::now() + Duration::from_millis(300);
    while Instant::now() < end {
        std::thread::sleep(Duration::from_millis(40));
        while let Ok(Some(f)) = link.recv(Duration::ZERO) {
            if f.raw_id() == 0x080 {
                stamps.push(link.rx_stamp_ms().expect("a stamped frame"));
            }
        }
    }
    assert!(stamps.len() > 50, "{}", stamps.len());
    for w in stamps.windows(2) {
        let gap = teleop_can_link::stamp_gap_ms(w[0], w[1]);
        assert!((2..=4).contains(&gap), "finger 0 stamps {w:?}: {stamps:?}");
    }
    drop(link);
    drop(sim);
    let _ = std::fs::remove_dir_all(&d);
}
