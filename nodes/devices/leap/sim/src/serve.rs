//! The simulated hand in real time: the bus ([`crate::bus`]) on the simulator kit's pty behind
//! a stable link (as a U2D2 appears under `/dev/serial/by-id`), its cable, and the faults
//! injected at run time.
//!
//! One thread serves the line: it reads what the host wrote, hands it to the bus with the time
//! its first byte started on the line (when it was read, or when the line's previous byte was
//! done, whichever is later) and the pty's baud rate as the host set it (the termios of the
//! device side, which the simulator's side reads), then writes each status when its last byte
//! would have left the servo (sleeping to that absolute time; never earlier). The plant runs
//! on the same clock, advanced to each request's end and to each look from the control socket.
//!
//! Unplugging removes the link, powers the servos off, and plugs a new pty in behind the same
//! link after the pause; the servos boot (silent for their boot time) with their EEPROM kept.
//!
//! A wire tap ([`Tap`], off unless [`SimOptions::tap`] sets one) reports, for measurements,
//! every request the servos heard whole with the time its last byte ended on the line, and
//! every status written with the time its last byte left, on the tap's clock.

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::SerialPort;
use teleop_sim_kit::pty::{self, Cable};
use teleop_sim_kit::{lock, Object, Stats};

use crate::bus::{Bus, BusOptions, Heard, Outbox};
use crate::hand::{Hand, HandParams, JOINTS};
use crate::servo::{Servo, ServoOptions};
use crate::table::Model;

/// How long a pty read waits before looking at unplug and stop requests (and how long a write
/// may block: a host that does not read loses statuses, counted).
const PTY_READ_TIMEOUT: Duration = Duration::from_millis(2);
/// Pause when nobody has the device side open.
const IDLE: Duration = Duration::from_millis(5);
/// Longest noise burst, bytes.
pub const MAX_NOISE: usize = 4096;

/// The simulated hand's setup.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Stable path of the pty's device side (a symlink).
    pub link: PathBuf,
    /// The servos' model.
    pub model: Model,
    /// The servos' Baud Rate register at start (code 0..6).
    pub baud_code: u8,
    /// The servos' Return Delay Time register at start (2 us units).
    pub return_delay: u8,
    /// What the firmware does where the documents leave it open.
    pub servo: ServoOptions,
    /// What the bus does where the documents leave it open.
    pub bus: BusOptions,
    /// The joints' limits (URDF rad, motor-ID order).
    pub limits: [(f64, f64); JOINTS],
    /// The object in the hand at start.
    pub object: Option<Object>,
    /// Seed of the fault dice.
    pub seed: u64,
    /// A wire tap, for measurements (`None`: off).
    pub tap: Option<Arc<Tap>>,
}

/// What a [`Tap`] saw on the line, times in ns on its clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TapEvent {
    /// A request the servos heard whole ([`Heard`]): when its last byte ended on the line, its
    /// instruction, and for a Sync Write of Goal Position the goal counts by ID.
    Request {
        /// When its last byte ended on the line.
        end_ns: u64,
        /// Its instruction byte.
        instruction: u8,
        /// The goal counts by ID (0..15) of a Sync Write of Goal Position.
        goals: Option<[Option<i32>; JOINTS]>,
    },
    /// Bytes written to the host: a status packet or a Fast Sync Read reply (or a noise burst,
    /// `noise N`).
    Written {
        /// When its last byte left by the line's timing.
        due_ns: u64,
        /// When the simulator had written it to the pty (no earlier than `due_ns`).
        written_ns: u64,
        /// Its length in bytes.
        len: usize,
        /// Its ID byte (byte 4; 0 when shorter).
        id: u8,
    },
}

/// A wire tap: the line's events ([`TapEvent`]) with times on a clock of the caller's (e.g.
/// CLOCK_MONOTONIC ns), for measurements. Bounded: events beyond its capacity are counted
/// ([`Tap::overflow`]), not kept, until [`Tap::drain_into`] takes the ones it holds; it
/// allocates nothing after [`Tap::new`].
#[derive(Debug)]
pub struct Tap {
    clock: fn() -> u64,
    events: Mutex<Vec<TapEvent>>,
    overflow: AtomicU64,
}

impl Tap {
    /// A tap that holds up to `capacity` events, its times read from `clock` (ns; the
    /// simulator's own times are converted with one reading of it at start, so `clock` must
    /// tick with CLOCK_MONOTONIC, as `std::time::Instant` does on Linux).
    pub fn new(capacity: usize, clock: fn() -> u64) -> Self {
        Self {
            clock,
            events: Mutex::new(Vec::with_capacity(capacity)),
            overflow: AtomicU64::new(0),
        }
    }

    /// Moves the events held, in order, to the end of `into`.
    pub fn drain_into(&self, into: &mut Vec<TapEvent>) {
        into.extend(lock(&self.events).drain(..));
    }

    /// Events lost because the tap was full.
    pub fn overflow(&self) -> u64 {
        self.overflow.load(Ordering::SeqCst)
    }

    fn push(&self, event: TapEvent) {
        let mut events = lock(&self.events);
        if events.len() < events.capacity() {
            events.push(event);
        } else {
            self.overflow.fetch_add(1, Ordering::SeqCst);
        }
    }
}

struct Shared {
    bus: Mutex<Bus>,
    start: Instant,
    stop: AtomicBool,
    cable: Cable,
    /// Noise bytes to put on the line at the next look.
    noise: AtomicUsize,
    /// The power went off (unplugged): the servos boot when plugged back in.
    powered_off: AtomicBool,
    /// The line's baud rate as the host set it last, bit/s.
    line_baud: AtomicU64,
    /// Statuses the pty would not take (the host not reading).
    overruns: AtomicU64,
    /// The wire tap and its clock's reading at `start`.
    tap: Option<(Arc<Tap>, u64)>,
}

impl Shared {
    fn now(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// Reports what `out` heard to the tap, if there is one.
    fn tap_heard(&self, out: &Outbox) {
        if let Some((tap, start_ns)) = &self.tap {
            for &Heard {
                end,
                instruction,
                goals,
            } in out.heard()
            {
                tap.push(TapEvent::Request {
                    end_ns: tap_ns(*start_ns, end),
                    instruction,
                    goals,
                });
            }
        }
    }

    /// Reports bytes written to the host (due at `at` s) to the tap, if there is one.
    fn tap_written(&self, at: f64, bytes: &[u8]) {
        if let Some((tap, start_ns)) = &self.tap {
            tap.push(TapEvent::Written {
                due_ns: tap_ns(*start_ns, at),
                written_ns: (tap.clock)(),
                len: bytes.len(),
                id: bytes.get(4).copied().unwrap_or(0),
            });
        }
    }
}

/// A time of the simulator's (`t` s after start) on the tap's clock, which read `start_ns` at
/// start.
fn tap_ns(start_ns: u64, t: f64) -> u64 {
    start_ns.saturating_add((t.max(0.0) * 1e9).round() as u64)
}

/// A running simulated hand.
pub struct Sim {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl Sim {
    /// Starts the hand's bus on a pty linked at `options.link` (which exists on return).
    pub fn start(options: SimOptions) -> std::io::Result<Self> {
        let servos = (0..JOINTS as u8)
            .map(|id| {
                Servo::new(
                    options.model,
                    id,
                    options.baud_code,
                    options.return_delay,
                    options.servo,
                )
            })
            .collect();
        let hand = Hand::new(HandParams::default(), options.limits, options.object);
        let start = Instant::now();
        let tap = options.tap.map(|tap| {
            let start_ns = (tap.clock)();
            (tap, start_ns)
        });
        let shared = Arc::new(Shared {
            bus: Mutex::new(Bus::new(servos, hand, options.bus, options.seed)),
            start,
            stop: AtomicBool::new(false),
            cable: Cable::new(),
            noise: AtomicUsize::new(0),
            powered_off: AtomicBool::new(false),
            line_baud: AtomicU64::new(0),
            overruns: AtomicU64::new(0),
            tap,
        });
        let first = pty::open(&options.link, PTY_READ_TIMEOUT)?;
        let thread = {
            let (shared, link) = (shared.clone(), options.link.clone());
            std::thread::Builder::new()
                .name("leap-bus".into())
                .spawn(move || serve_line(&shared, &link, first))?
        };
        Ok(Self {
            shared,
            thread: Some(thread),
        })
    }

    /// Runs `f` on the bus, its plant advanced to now first; `f` gets the time too, s.
    pub fn with_bus<R>(&self, f: impl FnOnce(&mut Bus, f64) -> R) -> R {
        let now = self.shared.now();
        let mut bus = lock(&self.shared.bus);
        bus.advance(now);
        f(&mut bus, now)
    }

    /// Pulls the cable for `pause`, then plugs a new pty in behind the same link.
    pub fn unplug(&self, pause: Duration) {
        self.shared.cable.pull(pause);
    }

    /// Puts `n` bytes of noise on the line (the host and the servos hear them).
    pub fn noise(&self, n: usize) {
        self.shared.noise.fetch_add(n, Ordering::SeqCst);
    }

    /// The state and counters as `key=value` words (lists comma-separated, motor-ID order),
    /// as the control socket's `stats` answers them after `ok `.
    pub fn stats_answer(&self) -> Stats {
        let plugged = self.shared.cable.plugged();
        let unplugs = self.shared.cable.unplugs();
        let baud = self.shared.line_baud.load(Ordering::SeqCst);
        let overruns = self.shared.overruns.load(Ordering::SeqCst);
        self.with_bus(|bus, now| {
            let servos = bus.servos();
            let each =
                |f: &dyn Fn(&Servo) -> String| servos.iter().map(f).collect::<Vec<_>>().join(",");
            let silent: Vec<String> = bus.silenced(now).map(|id| id.to_string()).collect();
            let faults = bus.faults();
            let q = bus.hand().positions();
            let object = bus.hand().object().map_or("none", Object::name);
            Stats::new()
                .field("link", if plugged { "plugged" } else { "unplugged" })
                .field("line_baud", baud)
                .field("object", object)
                .field("drop", faults.drop)
                .field("crc", faults.crc)
                .field(
                    "silent",
                    if silent.is_empty() {
                        "none".to_string()
                    } else {
                        silent.join(",")
                    },
                )
                .counters("", &bus.counters())
                .field("unplugs", unplugs)
                .field("pty_overruns", overruns)
                .field("torque", each(&|s| u8::from(s.torque_on()).to_string()))
                .field("hardware_error", each(&|s| s.hardware_error().to_string()))
                .field("booting", each(&|s| u8::from(s.booting(now)).to_string()))
                .field(
                    "mode",
                    each(&|s| {
                        s.table()
                            .get(teleop_leap_protocol::xc330::OPERATING_MODE)
                            .to_string()
                    }),
                )
                .field(
                    "position",
                    each(&|s| {
                        s.table()
                            .get(teleop_leap_protocol::xc330::PRESENT_POSITION)
                            .to_string()
                    }),
                )
                .field("current", each(&|s| format!("{:.0}", s.current_ma())))
                .field("temperature", each(&|s| format!("{:.1}", s.temperature())))
                .field(
                    "joint",
                    q.iter()
                        .map(|v| format!("{v:.4}"))
                        .collect::<Vec<_>>()
                        .join(","),
                )
                .field(
                    "contact",
                    bus.hand()
                        .contact()
                        .iter()
                        .map(|v| format!("{v:.3}"))
                        .collect::<Vec<_>>()
                        .join(","),
                )
        })
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Serves the line until stopped: plugged in, unplugged, plugged in again.
fn serve_line(shared: &Shared, link: &std::path::Path, first: pty::Pair) {
    let mut out = Outbox::new();
    let mut buf = [0u8; 4096];
    pty::serve(
        link,
        PTY_READ_TIMEOUT,
        first,
        &shared.cable,
        &shared.stop,
        |master| {
            if shared.powered_off.swap(false, Ordering::SeqCst) {
                lock(&shared.bus).power_cycle(shared.now());
            }
            while !shared.cable.pulled() && !shared.stop.load(Ordering::SeqCst) {
                let n = pty::read(master, &mut buf, IDLE);
                let noise = shared.noise.swap(0, Ordering::SeqCst).min(MAX_NOISE);
                if n == 0 && noise == 0 {
                    continue;
                }
                let baud = master.baud_rate().unwrap_or(0);
                shared.line_baud.store(u64::from(baud), Ordering::SeqCst);
                out.clear();
                {
                    let mut bus = lock(&shared.bus);
                    let now = shared.now();
                    if noise > 0 {
                        bus.noise(noise, baud, now, &mut out);
                    }
                    bus.receive(&buf[..n], baud, now, &mut out);
                }
                shared.tap_heard(&out);
                for (at, bytes) in out.parts() {
                    let due = Duration::try_from_secs_f64(at.max(0.0))
                        .ok()
                        .and_then(|d| shared.start.checked_add(d));
                    if let Some(wait) = due.and_then(|d| d.checked_duration_since(Instant::now())) {
                        std::thread::sleep(wait);
                    }
                    if master.write_all(bytes).is_err() {
                        shared.overruns.fetch_add(1, Ordering::SeqCst);
                    } else {
                        shared.tap_written(at, bytes);
                    }
                }
            }
            Ok(())
        },
        || shared.powered_off.store(true, Ordering::SeqCst),
    );
}
