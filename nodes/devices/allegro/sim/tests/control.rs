//! `teleop-sim-allegro` as a process: the control socket's commands act on the hand a node
//! sees over the socket bus, `stats` parses, bad arguments are refused.
#![allow(clippy::unwrap_used)]

use std::ffi::OsString;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use teleop_allegro_protocol::{doc, v4, Generation};
use teleop_can_link::local::SocketLink;
use teleop_can_link::{CanFrame, CanLink};
use teleop_sim_kit::testing::SimProcess;
use teleop_sim_kit::Stats;

struct Sim(SimProcess);

impl Sim {
    fn start(args: &[&str]) -> Self {
        let args: Vec<OsString> = args.iter().map(OsString::from).collect();
        Self(SimProcess::start(
            Path::new(env!("CARGO_BIN_EXE_teleop-sim-allegro")),
            |dir| {
                let mut all = vec![
                    "--slcan".into(),
                    dir.join("can").into(),
                    "--socket".into(),
                    dir.join("bus.sock").into(),
                ];
                all.extend(args);
                all
            },
            "allegro: generation ",
            "can.ctl",
        ))
    }

    fn control(&self, command: &str) -> String {
        self.0.control(command)
    }

    fn status(&self) -> Stats {
        self.0.stats()
    }

    fn link(&self) -> SocketLink {
        SocketLink::connect(&self.0.dir().join("bus.sock")).unwrap()
    }
}

fn collect(link: &mut dyn CanLink, window: Duration) -> Vec<CanFrame> {
    let end = Instant::now() + window;
    let mut out = Vec::new();
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if let Ok(Some(f)) = link.recv(left) {
            out.push(f);
        }
    }
    out
}

fn start_doc(link: &mut dyn CanLink, g: Generation) {
    let o = g.torque_order();
    link.send(&doc::Request::SetPeriod { ms: 3 }.encode(o))
        .unwrap();
    link.send(&doc::Request::SystemOn.encode(o)).unwrap();
}

#[test]
fn faults_act_on_the_stream_and_status_reports_them() {
    let sim = Sim::start(&["--generation", "v3"]);
    let mut link = sim.link();
    start_doc(&mut link, Generation::V3);
    assert!(collect(&mut link, Duration::from_millis(60)).len() > 40);
    let s = sim.status();
    assert_eq!(s["generation"], "v3");
    assert_eq!(s["system"], "on");
    assert_eq!(s["streaming"], "yes");
    assert_eq!(s["period_ms"], "3");
    assert_eq!(s["adapter"], "closed");
    assert_eq!(s["bus"], "error-active");
    assert_eq!(s["position"].split(',').count(), 16);

    assert_eq!(sim.control("stop-stream"), "ok stop-stream");
    collect(&mut link, Duration::from_millis(10));
    assert!(collect(&mut link, Duration::from_millis(50)).is_empty());
    assert_eq!(sim.status()["stream_stopped"], "yes");
    assert_eq!(sim.control("resume-stream"), "ok resume-stream");
    assert!(collect(&mut link, Duration::from_millis(50)).len() > 40);

    assert_eq!(sim.control("drop 1"), "ok drop 1");
    collect(&mut link, Duration::from_millis(10));
    assert!(collect(&mut link, Duration::from_millis(50)).is_empty());
    assert_eq!(sim.control("drop 0"), "ok drop 0");
    assert!(sim.status()["dropped_out"].parse::<u64>().unwrap() > 20);

    // The wrong protocol generation: the node set for v3 now sees v4 ids.
    assert_eq!(sim.control("generation v4"), "ok generation v4");
    collect(&mut link, Duration::from_millis(10));
    let frames = collect(&mut link, Duration::from_millis(30));
    assert!(!frames.is_empty());
    assert!(frames.iter().all(|f| (0x080..=0x08C).contains(&f.raw_id())));

    // Torque through the socket shows in the status.
    link.send(
        &v4::Request::Torque {
            finger: 0,
            pwm: [0, 120, 0, 0],
        }
        .encode(0),
    )
    .unwrap();
    std::thread::sleep(Duration::from_millis(50));
    let s = sim.status();
    assert!(s["pwm"].starts_with("0,120,0,0,"), "{s:?}");
    assert!(s["torque"].starts_with("0.0000,0.1000,"), "{s:?}");

    assert_eq!(sim.control("overheat"), "ok overheat 95 C");
    assert_eq!(sim.status()["overheated"], "yes");
    assert!(sim.control("overheat off").starts_with("ok overheat off"));

    assert_eq!(sim.control("inject 7F0#0102"), "ok inject 7F0#0102");
    assert!(collect(&mut link, Duration::from_millis(30))
        .iter()
        .any(|f| f.raw_id() == 0x7F0));
    assert!(sim.control("bus-off 100").starts_with("ok bus-off"));
    assert_eq!(sim.status()["bus"], "bus-off");
    assert!(sim.control("unplug 100").starts_with("ok unplug"));
    assert_eq!(sim.control("garbage"), "ok garbage");
    assert_eq!(sim.control("object bar"), "ok object bar");
    assert_eq!(sim.control("gravity on"), "ok gravity on");
}

#[test]
fn bad_commands_and_arguments_are_refused() {
    let sim = Sim::start(&[]);
    for bad in [
        "drop",
        "drop 2",
        "drop-in x",
        "bus-off",
        "bus-off -1",
        "unplug soon",
        "generation v5",
        "overheat hot",
        "inject 7FF",
        "object cube",
        "gravity maybe",
        "frobnicate",
    ] {
        let reply = sim.control(bad);
        assert!(reply.starts_with("error"), "{bad}: {reply}");
    }
    assert_eq!(sim.status()["generation"], "v4");
}

#[test]
fn bad_options_stop_the_process_with_a_message() {
    for args in [
        &["--encoder-offset", "1,2,3"][..],
        &["--motor-dir", "1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,2"][..],
        &["--device-id", "4"][..],
        &["--serial", "TOO-LONG-SERIAL"][..],
        &["--object", "cube"][..],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_teleop-sim-allegro"))
            .args(["--socket", "/tmp/sim-allegro-never.sock"])
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
    }
}
