//! `teleop-sim-glove` as a process: its control socket's `late` command delays only the next
//! answer, which still comes, bad arguments are refused, and `stats` answers `key=value` words.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::time::Duration;

use teleop_glove_protocol::{encode_request, Request, ResponseDecoder, MAX_FRAME};
use teleop_sim_kit::testing::SimProcess;

fn start() -> SimProcess {
    SimProcess::start(
        Path::new(env!("CARGO_BIN_EXE_teleop-sim-glove")),
        |dir| {
            vec![
                "--link".into(),
                dir.join("glove").into(),
                "--script".into(),
                "hold".into(),
            ]
        },
        "device: ",
        "glove.ctl",
    )
}

/// One force-control exchange; the answer must come within `within`.
fn exchange(port: &mut dyn serialport::SerialPort, within: Duration) {
    let mut frame = [0u8; MAX_FRAME];
    let n = encode_request(1, &Request::ForceControl { forces: [0; 5] }, &mut frame).unwrap();
    port.write_all(&frame[..n]).unwrap();
    port.set_timeout(within).unwrap();
    let mut decoder = ResponseDecoder::new(Some(1));
    let mut buf = [0u8; 64];
    loop {
        let n = port.read(&mut buf).unwrap();
        decoder.push(&buf[..n]);
        if let Some(answer) = decoder.next() {
            answer.unwrap();
            return;
        }
    }
}

#[test]
fn late_makes_only_the_next_answer_late_and_refuses_bad_arguments() {
    let sim = start();
    for bad in ["late", "late soon", "late -5", "late 10001"] {
        let reply = sim.control(bad);
        assert!(
            reply.starts_with("error: late: expected MS (0..=10000), got"),
            "{bad}: {reply}"
        );
    }
    let mut port = serialport::new(sim.dir().join("glove").display().to_string(), 115_200)
        .open()
        .unwrap();
    exchange(&mut *port, Duration::from_secs(5));
    assert!(sim.control("stats").contains(" late=0"));
    assert_eq!(sim.control("late 200"), "ok late 200 ms");
    exchange(&mut *port, Duration::from_secs(5));
    assert!(sim.control("stats").contains(" late=1"));
    exchange(&mut *port, Duration::from_secs(5));
    let stats = sim.control("stats");
    assert!(
        stats.starts_with("ok requests=")
            && stats.contains(" answers=3")
            && stats.contains(" late=1"),
        "{stats}"
    );
}
