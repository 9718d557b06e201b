//! Every simulator speaks the simulator kit's vocabulary on its control socket: the same
//! common words with the same answers (`ok ...`, `error: ...` naming the word and what it
//! expected, `stats` as `key=value` words), times in milliseconds, and one refusal for a word
//! none of them knows. The glove, the Revo2, the Allegro Hand, the Shadow Hand and the LEAP Hand
//! alike.
#![allow(clippy::unwrap_used)]

use std::ffi::OsString;
use std::path::Path;

use teleop_e2e::bin;
use teleop_sim_kit::testing::SimProcess;

/// Each simulator as a process: its program, its arguments in its directory, its announce line
/// and its control socket.
fn simulators() -> Vec<(&'static str, SimProcess)> {
    let start = |name: &'static str,
                 program: &str,
                 args: fn(&Path) -> Vec<OsString>,
                 announce: &str,
                 control: &str| {
        (
            name,
            SimProcess::start(&bin(program), args, announce, control),
        )
    };
    vec![
        start(
            "glove",
            "teleop-sim-glove",
            |dir| vec!["--link".into(), dir.join("glove").into()],
            "device: ",
            "glove.ctl",
        ),
        start(
            "revo2",
            "teleop-sim-revo2",
            |dir| vec!["--socket".into(), dir.join("revo2.sock").into()],
            "revo2: socket ",
            "revo2.ctl",
        ),
        start(
            "allegro",
            "teleop-sim-allegro",
            |dir| vec!["--slcan".into(), dir.join("can").into()],
            "allegro: generation ",
            "can.ctl",
        ),
        start(
            "shadow",
            "teleop-sim-shadow",
            |dir| vec!["--socket".into(), dir.join("shadow.sock").into()],
            "shadow: socket ",
            "shadow.ctl",
        ),
        start(
            "leap",
            "teleop-sim-leap",
            |dir| vec!["--link".into(), dir.join("leap").into()],
            "leap: link ",
            "leap.ctl",
        ),
    ]
}

#[test]
fn every_simulator_takes_the_same_common_words_and_answers_them_alike() {
    for (name, sim) in simulators() {
        let stats = sim.control("stats");
        let words = stats
            .strip_prefix("ok ")
            .unwrap_or_else(|| panic!("{name}: {stats}"));
        assert!(
            words.split(' ').all(|w| w.split_once('=').is_some()),
            "{name}: stats are key=value words: {stats}"
        );
        assert_eq!(sim.control("drop 0.5"), "ok drop 0.5", "{name}");
        assert!(sim.control("clear").starts_with("ok"), "{name}");
        assert!(sim.control("unplug 200").starts_with("ok"), "{name}");
        for (bad, error) in [
            (
                "unplug 1.5",
                "error: unplug: expected MS (0..=3600000), got \"1.5\"",
            ),
            (
                "drop 2",
                "error: drop: expected PROBABILITY (0..1), got \"2\"",
            ),
            (
                "stats now",
                "error: stats: expected nothing more, got \"now\"",
            ),
            (
                "object cube",
                "error: object: expected ball|bar|none, got \"cube\"",
            ),
        ] {
            assert_eq!(sim.control(bad), error, "{name}: {bad}");
        }
        for old in ["link-down 1", "status", "fault drop=0.5"] {
            let reply = sim.control(old);
            assert!(
                reply.starts_with(&format!(
                    "error: unknown command {:?}: expected one of unplug MS, drop P, clear, stats",
                    old.split(' ').next().unwrap()
                )),
                "{name}: {old}: {reply}"
            );
        }
    }
}
