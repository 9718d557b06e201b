//! `GloveLink` (the serial client of the node and of `teleop glove`) through `serialport` on the
//! simulated glove's pseudo-terminal: every answer the link returns is the one the device gave
//! to that request, also after an answer came too late.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use teleop_glove::{GloveLink, LinkError};
use teleop_glove_protocol::{reg, BaudRate, Request, Response};
use teleop_sim_glove::hand::{Hand, HandModel, Script};
use teleop_sim_glove::{Faults, SimGlove, SimOptions};

const TIMEOUT: Duration = Duration::from_millis(100);
/// Past the link's answer timeout, within the one more timeout its resynchronisation waits
/// (50 ms either side, for a loaded machine).
const LATE: Duration = Duration::from_millis(150);

/// What the test asks: both kinds that answer with the six positions.
#[derive(Debug, Clone, Copy)]
enum Ask {
    /// A force-control exchange (its answer carries no register address to check).
    Force,
    /// A read of the actual-position registers.
    Register,
}

/// The six positions the link returned for one request.
fn ask(link: &mut GloveLink, what: Ask) -> Result<[u16; 6], LinkError> {
    match what {
        Ask::Force => match link.exchange(&Request::ForceControl { forces: [0; 5] })?.0 {
            Response::ForceControl { positions } => Ok(positions),
            other => panic!("{other:?}"),
        },
        Ask::Register => {
            let values = link.read_register(&reg::POSITION_ACTUAL)?;
            Ok(core::array::from_fn(|i| values.as_slice()[i] as u16))
        }
    }
}

/// Asks, then checks the positions against those of the device's `answers`-th answer, which
/// must be the answer to this request.
fn ask_and_check(link: &mut GloveLink, sim: &SimGlove, what: Ask, answers: u64) {
    let got = ask(link, what).unwrap();
    let start = Instant::now();
    while sim.stats().answers < answers {
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "the device never sent answer {answers}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    let sent = sim.device().unwrap().positions;
    assert_eq!(
        got,
        sent,
        "{what:?}: the link returned other positions than the device's answer to it ({:?})",
        link.stats()
    );
}

#[test]
fn after_a_late_answer_every_exchange_gets_its_own_answer() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("glove");
    // A hand that keeps moving, so that answers to different requests differ.
    let sim = SimGlove::start(
        SimOptions {
            link: path.clone(),
            id: 1,
            baud: BaudRate::B115200,
            response_delay: Duration::from_micros(200),
            faults: Faults::default(),
            seed: 3,
        },
        Hand::new(Script::OpenClose { period_s: 1.0 }, HandModel::default()),
    )
    .unwrap();
    let mut link = GloveLink::open(&path.display().to_string(), 115_200, 1, TIMEOUT).unwrap();
    // The pseudo-terminal refuses low-latency mode, which does not stop the link.
    assert!(!link.low_latency());

    let mut answers = 0;
    let mut exchanges = 0;
    for late in [Ask::Force, Ask::Register] {
        for what in [Ask::Force, Ask::Register, Ask::Force, Ask::Force] {
            answers += 1;
            ask_and_check(&mut link, &sim, what, answers);
            exchanges += 1;
        }
        // The device answers this request past the timeout ...
        sim.answer_late(LATE);
        assert!(matches!(ask(&mut link, late), Err(LinkError::Timeout(_))));
        answers += 1;
        // ... and the next requests, of the same kind first, get their own answers.
        for what in [late, late, Ask::Force, Ask::Register, Ask::Force] {
            answers += 1;
            ask_and_check(&mut link, &sim, what, answers);
            exchanges += 1;
        }
    }
    let stats = link.stats();
    assert_eq!(sim.stats().late, 2);
    assert_eq!(
        (stats.timeouts, stats.late, stats.exchanges),
        (2, 2, exchanges),
        "{stats:?}"
    );
    assert_eq!(stats.errors(), 4, "{stats:?}");
}

#[test]
fn a_line_that_never_goes_quiet_ends_the_resynchronisation() {
    use serialport::SerialPort;
    use std::io::Write;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    let (mut device, slave) = serialport::TTYPort::pair().unwrap();
    let path = slave.name().unwrap();
    let mut link = GloveLink::open(&path, 115_200, 1, TIMEOUT).unwrap();
    // Noise, a few bytes every 2 ms, until the test has its answer (or for 20 s at most).
    let done = Arc::new(AtomicBool::new(false));
    let noise = {
        let done = done.clone();
        std::thread::spawn(move || {
            let start = Instant::now();
            while !done.load(Ordering::SeqCst) && start.elapsed() < Duration::from_secs(20) {
                let _ = device.write_all(&[0x55, 0xAA, 0x01, 0x02]);
                std::thread::sleep(Duration::from_millis(2));
            }
            start.elapsed() < Duration::from_secs(20)
        })
    };
    let result = link.exchange(&Request::ForceControl { forces: [0; 5] });
    done.store(true, Ordering::SeqCst);
    assert!(
        noise.join().unwrap(),
        "the exchange returned only once the noise stopped"
    );
    assert!(matches!(result, Err(LinkError::Timeout(_))), "{result:?}");
    let stats = link.stats();
    assert_eq!((stats.timeouts, stats.late), (1, 0), "{stats:?}");
    assert!(stats.garbage > 0, "{stats:?}");
    drop(slave);
}
