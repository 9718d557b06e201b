//! The simulated glove on a pseudo-terminal: baud-rate timing, fault injection, unplug/replug.
//!
//! The device side of a pty pair is published under a stable path (a symlink, like a udev
//! by-id link) so that a driver can reopen the same path after the simulated cable is pulled and
//! put back (which creates a new pty).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use teleop_glove_protocol::{encode_response, wire_time, BaudRate, RequestDecoder, MAX_FRAME};

use crate::device::Device;
use crate::hand::Hand;

/// Probabilities (0..1) of each fault, per answer.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Faults {
    /// Send random bytes before the answer.
    pub garbage: f32,
    /// Do not answer.
    pub drop: f32,
    /// Corrupt the answer's checksum.
    pub corrupt: f32,
    /// Answer as another device id instead.
    pub other_id: f32,
}

impl Faults {
    /// Applies `name=probability` (names: garbage, drop, corrupt, other-id).
    pub fn set(&mut self, spec: &str) -> Result<(), String> {
        let (name, value) = spec
            .split_once('=')
            .ok_or_else(|| format!("fault {spec:?}: expected NAME=PROBABILITY"))?;
        let p: f32 = value
            .trim()
            .parse()
            .ok()
            .filter(|p: &f32| (0.0..=1.0).contains(p))
            .ok_or_else(|| format!("fault {spec:?}: probability must be in 0..1"))?;
        match name.trim() {
            "garbage" => self.garbage = p,
            "drop" => self.drop = p,
            "corrupt" => self.corrupt = p,
            "other-id" => self.other_id = p,
            other => {
                return Err(format!(
                    "unknown fault {other:?}: use garbage, drop, corrupt or other-id"
                ))
            }
        }
        Ok(())
    }
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
    /// Times the cable was pulled.
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
    unplug: Mutex<Option<Duration>>,
    late: Mutex<Option<Duration>>,
    stop: AtomicBool,
    stats: Mutex<SimStats>,
    last_answer_ns: AtomicU64,
    device: Mutex<Option<DeviceView>>,
    log: Mutex<Vec<String>>,
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
        let pair = open_pair(&link)?;
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
        *lock(&self.shared.unplug) = Some(duration);
    }

    /// Sends the next answer `by` later than usual, as a busy device would (for instance past
    /// the host's answer timeout). The device goes on as usual otherwise: requests that arrive
    /// meanwhile wait in the line's buffer and are answered in order afterwards.
    pub fn answer_late(&self, by: Duration) {
        *lock(&self.shared.late) = Some(by);
    }

    /// Counters so far.
    pub fn stats(&self) -> SimStats {
        *lock(&self.shared.stats)
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

    /// Takes the event log lines written since the last call (unplugs, baud changes, ...).
    pub fn take_log(&self) -> Vec<String> {
        std::mem::take(&mut *lock(&self.shared.log))
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

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

fn note(shared: &Shared, line: String) {
    tracing::info!("{line}");
    lock(&shared.log).push(line);
}

/// A pty pair with the device side linked at `link`. The simulator keeps the slave open too, so
/// the master never sees a hang-up while the driver closes and reopens the port.
fn open_pair(link: &Path) -> std::io::Result<(TTYPort, TTYPort)> {
    let (mut master, slave) = TTYPort::pair().map_err(std::io::Error::other)?;
    let name = slave
        .name()
        .ok_or_else(|| std::io::Error::other("pty without a name"))?;
    master
        .set_timeout(Duration::from_millis(5))
        .map_err(std::io::Error::other)?;
    let tmp = link.with_extension("tmp-link");
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(&name, &tmp)?;
    std::fs::rename(&tmp, link)?;
    Ok((master, slave))
}

/// xorshift64*: deterministic, seedable, good enough for fault dice.
struct Dice(u64);

impl Dice {
    fn roll(&mut self, p: f32) -> bool {
        if p <= 0.0 {
            return false;
        }
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((v >> 40) as f32 / (1u64 << 24) as f32) < p
    }

    fn byte(&mut self) -> u8 {
        self.roll(1.0);
        (self.0 >> 32) as u8
    }
}

fn serve(options: SimOptions, hand: Hand, first: (TTYPort, TTYPort), shared: &Shared) {
    let start = Instant::now();
    let mut device = Device::new(options.id, options.baud, hand);
    let mut dice = Dice(options.seed.max(1));
    let mut pair = Some(first);
    while !shared.stop.load(Ordering::SeqCst) {
        let (mut master, slave) = match pair.take() {
            Some(p) => p,
            None => match open_pair(&options.link) {
                Ok(p) => p,
                Err(e) => {
                    note(shared, format!("cannot create a pty: {e}; retrying"));
                    std::thread::sleep(Duration::from_millis(200));
                    continue;
                }
            },
        };
        note(
            shared,
            format!(
                "plugged in: {} -> {}",
                options.link.display(),
                slave.name().unwrap_or_default()
            ),
        );
        connection(&mut master, &mut device, &mut dice, &options, shared, start);
        drop(slave);
        drop(master);
        if let Some(pause) = lock(&shared.unplug).take() {
            let _ = std::fs::remove_file(&options.link);
            lock(&shared.stats).unplugs += 1;
            note(shared, format!("unplugged for {} ms", pause.as_millis()));
            let until = Instant::now() + pause;
            while Instant::now() < until && !shared.stop.load(Ordering::SeqCst) {
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }
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
        if shared.stop.load(Ordering::SeqCst) || lock(&shared.unplug).is_some() {
            return;
        }
        let n = match master.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => 0,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => 0,
            Err(_) => {
                // No reader on the device side right now (EIO): wait for the driver to reopen.
                std::thread::sleep(Duration::from_millis(5));
                0
            }
        };
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
                    note(
                        shared,
                        format!("baud rate now {} bit/s", baud.bits_per_second()),
                    );
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
