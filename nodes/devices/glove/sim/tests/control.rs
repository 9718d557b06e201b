//! `teleop-sim-glove` as a process: its control socket's `late` command delays only the next
//! answer, which still comes, bad arguments are refused, and `stats` answers `key=value` words.
#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use teleop_glove_protocol::{encode_request, Request, ResponseDecoder, MAX_FRAME};

struct Sim {
    child: Child,
    dir: PathBuf,
}

impl Sim {
    fn start() -> Self {
        let dir = std::env::temp_dir().join(format!("sim-glove-control-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_teleop-sim-glove"))
            .arg("--link")
            .arg(dir.join("glove"))
            .args(["--script", "hold"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.starts_with("device: "), "{line}");
        Self { child, dir }
    }

    fn control(&self, command: &str) -> String {
        let mut s = UnixStream::connect(self.dir.join("glove.ctl")).unwrap();
        writeln!(s, "{command}").unwrap();
        s.shutdown(std::net::Shutdown::Write).unwrap();
        let mut reply = String::new();
        BufReader::new(s).read_line(&mut reply).unwrap();
        reply
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
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
    let sim = Sim::start();
    for bad in ["late", "late soon", "late -5", "late 10001"] {
        let reply = sim.control(bad);
        assert!(
            reply.starts_with("error: late: expected MS (0..=10000), got"),
            "{bad}: {reply}"
        );
    }
    let mut port = serialport::new(sim.dir.join("glove").display().to_string(), 115_200)
        .open()
        .unwrap();
    exchange(&mut *port, Duration::from_secs(5));
    assert!(sim.control("stats").contains(" late=0"));
    assert_eq!(sim.control("late 200"), "ok late 200 ms\n");
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
