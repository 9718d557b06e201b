//! The simulated glove on a pseudo-terminal: baud-rate timing, fault injection, unplug/replug.
//!
//! The pty, its stable link and the cable are the simulator kit's (`teleop_sim_kit::pty`), so
//! that a driver can reopen the same path after the simulated cable is pulled and put back.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::TTYPort;
use teleop_glove_protocol::{encode_response, wire_time, BaudRate, RequestDecoder, MAX_FRAME};
use teleop_sim_kit::dice::Dice;
use teleop_sim_kit::lock;
use teleop_sim_kit::pty::{self, Cable};

use crate::device::Device;
use crate::hand::Hand;

/// Probabilities (0..1) of each fault, per answer.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Faults {
    /// Send random bytes before the answer.
    pub garbage: f64,
    /// Do not answer.
    pub drop: f64,
    /// Corrupt the answer's checksum.
    pub corrupt: f64,
    /// Answer as another device id instead.
    pub other_id: f64,
}

/// Counters of what the simulator did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SimStats {
    /// Requests decoded (any id).
    pub requests: u64,
    /// Answers sent (including corrupted and other-id ones).
    pub answers: u64,
    /// Answers dropped on purpose.
    pub dropped: u64,
    /// Answers sent with a corrupted checksum.
    pub corrupted: u64,
    /// Garbage bursts sent.
    pub garbage: u64,
    /// Answers sent as another id.
    pub other_id: u64,
    /// Requests the decoder rejected (bad checksum, garbage runs, ...).
    pub bad_requests: u64,
    /// Times the cable was pulled (also counted while it is out).
    pub unplugs: u64,
    /// Answers sent late on purpose ([`SimGlove::answer_late`]).
    pub late: u64,
}

/// Start options.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Stable path of the device side (a symlink to the current pty).
    pub link: PathBuf,
    /// Device id.
    pub id: u8,
    /// Line speed at power-on.
    pub baud: BaudRate,
    /// Processing time between a request's last byte and the answer's first byte.
    pub response_delay: Duration,
    /// Faults from the start.
    pub faults: Faults,
    /// Seed of the fault generator.
    pub seed: u64,
}

#[derive(Default)]
struct Shared {
    faults: Mutex<Faults>,
    cable: Cable,
    late: Mutex<Option<Duration>>,
    stop: AtomicBool,
    stats: Mutex<SimStats>,
    last_answer_ns: AtomicU64,
    device: Mutex<Option<DeviceView>>,
    record: AtomicBool,
    answers: Mutex<Vec<AnswerTiming>>,
    forces: Mutex<Vec<ForceTiming>>,
}

/// When a force-control request's last byte arrived and the forces it carried, recorded for
/// benchmarks with [`SimGlove::record_answers`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ForceTiming {
    /// CLOCK_MONOTONIC ns when the request's last byte was on the device side of the line.
    pub received_ns: u64,
    /// The forces it carried (glove order).
    pub forces: [i16; 5],
}

/// When one answer's data was sampled and when its last byte was on the line (CLOCK_MONOTONIC
/// ns), recorded for benchmarks when enabled with [`SimGlove::record_answers`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AnswerTiming {
    /// The device read its sensors (just before answering).
    pub sampled_ns: u64,
    /// The answer's last byte left the device.
    pub sent_ns: u64,
}

/// Most answer timings kept.
const MAX_RECORDED: usize = 1 << 20;

/// What tests may look at in the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceView {
    /// Id it answers to.
    pub id: u8,
    /// Force set-points last received.
    pub force_set: [i16; 5],
    /// Raw positions it reports.
    pub positions: [u16; 6],
    /// Line speed.
    pub baud: BaudRate,
}

/// A running simulated glove.
pub struct SimGlove {
    shared: Arc<Shared>,
    link: PathBuf,
    thread: Option<JoinHandle<()>>,
}

impl SimGlove {
    /// Creates the pty, publishes its path at `options.link`, and serves in a thread.
    pub fn start(options: SimOptions, hand: Hand) -> std::io::Result<Self> {
        let shared = Arc::new(Shared::default());
        *lock(&shared.faults) = options.faults;
        let link = options.link.clone();
        // Create the first pty here so that errors reach the caller and the link exists on return.
        let pair = pty::open(&link, READ_TIMEOUT)?;
        let thread = {
            let shared = shared.clone();
            std::thread::Builder::new()
                .name("sim-glove".into())
                .spawn(move || serve(options, hand, pair, &shared))?
        };
        Ok(Self {
            shared,
            link,
            thread: Some(thread),
        })
    }

    /// The stable device path.
    pub fn link(&self) -> &Path {
        &self.link
    }

    /// Current faults.
    pub fn faults(&self) -> Faults {
        *lock(&self.shared.faults)
    }

    /// Replaces the faults (takes effect with the next answer).
    pub fn set_faults(&self, faults: Faults) {
        *lock(&self.shared.faults) = faults;
    }

    /// Pulls the cable for `duration`, then plugs it back in (as a new pty behind the same link).
    pub fn unplug(&self, duration: Duration) {
        self.shared.cable.pull(duration);
    }

    /// Sends the next answer `by` later than usual, as a busy device would (for instance past
    /// the host's answer timeout). The device goes on as usual otherwise: requests that arrive
    /// meanwhile wait in the line's buffer and are answered in order afterwards.
    pub fn answer_late(&self, by: Duration) {
        *lock(&self.shared.late) = Some(by);
    }

    /// Counters so far.
    pub fn stats(&self) -> SimStats {
        SimStats {
            unplugs: self.shared.cable.unplugs(),
            ..*lock(&self.shared.stats)
        }
    }

    /// The device's state after the last exchange (None before the first).
    pub fn device(&self) -> Option<DeviceView> {
        *lock(&self.shared.device)
    }

    /// CLOCK_MONOTONIC of the last answer's last byte on the line.
    pub fn last_answer_ns(&self) -> u64 {
        self.shared.last_answer_ns.load(Ordering::Relaxed)
    }

    /// Starts (or stops) recording the timing of every answer.
    pub fn record_answers(&self, on: bool) {
        self.shared.record.store(on, Ordering::SeqCst);
    }

    /// Takes the answer timings recorded so far, in order.
    pub fn take_answer_timings(&self) -> Vec<AnswerTiming> {
        std::mem::take(&mut *lock(&self.shared.answers))
    }

    /// Takes the force requests recorded so far, in order.
    pub fn take_force_timings(&self) -> Vec<ForceTiming> {
        std::mem::take(&mut *lock(&self.shared.forces))
    }
}

impl Drop for SimGlove {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.link);
    }
}

/// How long a read of the host's bytes waits before looking at unplug and stop requests.
const READ_TIMEOUT: Duration = Duration::from_millis(5);

fn serve(options: SimOptions, hand: Hand, first: pty::Pair, shared: &Shared) {
    let start = Instant::now();
    let mut device = Device::new(options.id, options.baud, hand);
    let mut dice = Dice::new(options.seed);
    pty::serve(
        &options.link,
        READ_TIMEOUT,
        first,
        &shared.cable,
        &shared.stop,
        |master| {
            connection(master, &mut device, &mut dice, &options, shared, start);
            Ok(())
        },
        || {},
    );
}

/// Serves one plugged-in period: until stop or unplug.
fn connection(
    master: &mut TTYPort,
    device: &mut Device,
    dice: &mut Dice,
    options: &SimOptions,
    shared: &Shared,
    start: Instant,
) {
    let mut decoder = RequestDecoder::new(None);
    let mut buf = [0u8; 256];
    let mut out = [0u8; MAX_FRAME + 32];
    // When the host's bytes finish arriving at the current baud rate.
    let mut rx_line_free = Instant::now();
    loop {
        if shared.stop.load(Ordering::SeqCst) || shared.cable.pulled() {
            return;
        }
        let n = pty::read(master, &mut buf, READ_TIMEOUT);
        device.advance_to(start.elapsed().as_secs_f32());
        let seen = Instant::now();
        let bps = device.baud().bits_per_second();
        let mut taken = 0;
        while taken < n {
            taken += decoder.push(&buf[taken..n]);
            while let Some(item) = decoder.next() {
                let frame = match item {
                    Ok(frame) => frame,
                    Err(_) => {
                        lock(&shared.stats).bad_requests += 1;
                        continue;
                    }
                };
                lock(&shared.stats).requests += 1;
                // The request's bytes take their wire time to arrive.
                let frame_len = frame.body.encoded_len();
                rx_line_free = rx_line_free.max(seen) + wire_time(frame_len, bps);
                teleop_runtime::sleep_until(rx_line_free);
                device.advance_to(start.elapsed().as_secs_f32());
                let sampled_ns = teleop_runtime::now_ns();
                if let (true, teleop_glove_protocol::Request::ForceControl { forces }) =
                    (shared.record.load(Ordering::Relaxed), &frame.body)
                {
                    let mut log = lock(&shared.forces);
                    if log.len() < MAX_RECORDED {
                        log.push(ForceTiming {
                            received_ns: sampled_ns,
                            forces: *forces,
                        });
                    }
                }
                let Some(answer) = device.handle(&frame) else {
                    continue;
                };
                let faults = *lock(&shared.faults);
                if dice.roll(faults.drop) {
                    lock(&shared.stats).dropped += 1;
                    continue;
                }
                let mut answer = answer;
                let other = dice.roll(faults.other_id);
                if other {
                    answer.id = answer.id.wrapping_add(1).max(1);
                }
                let mut len = 0;
                let garbage = dice.roll(faults.garbage);
                if garbage {
                    for b in out.iter_mut().take(8) {
                        *b = dice.byte();
                    }
                    len = 8;
                }
                let Ok(n) = encode_response(answer.id, &answer.body, &mut out[len..]) else {
                    continue;
                };
                let corrupt = dice.roll(faults.corrupt);
                if corrupt {
                    out[len + n - 1] ^= 0x5A;
                }
                len += n;
                let late = lock(&shared.late).take();
                // Processing (and a delay on purpose), then the answer's own wire time.
                let done = Instant::now()
                    + options.response_delay
                    + late.unwrap_or_default()
                    + wire_time(len, bps);
                teleop_runtime::sleep_until(done);
                if master.write_all(&out[..len]).is_err() {
                    continue;
                }
                let sent_ns = teleop_runtime::now_ns();
                shared.last_answer_ns.store(sent_ns, Ordering::Relaxed);
                if shared.record.load(Ordering::Relaxed) {
                    let mut answers = lock(&shared.answers);
                    if answers.len() < MAX_RECORDED {
                        answers.push(AnswerTiming {
                            sampled_ns,
                            sent_ns,
                        });
                    }
                }
                rx_line_free = Instant::now();
                if let Some(baud) = device.after_answer() {
                    tracing::info!("baud rate now {} bit/s", baud.bits_per_second());
                }
                // The view before the counters: whoever sees an answer counted sees its state.
                *lock(&shared.device) = Some(DeviceView {
                    id: device.id(),
                    force_set: device.force_set(),
                    positions: device.hand().positions(),
                    baud: device.baud(),
                });
                let mut s = lock(&shared.stats);
                s.answers += 1;
                s.garbage += u64::from(garbage);
                s.corrupted += u64::from(corrupt);
                s.other_id += u64::from(other);
                s.late += u64::from(late.is_some());
            }
        }
    }
}
