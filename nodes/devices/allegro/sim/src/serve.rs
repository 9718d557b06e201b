//! The simulated hand on a bus: the firmware's thread, the slcan adapter on a pseudo-terminal,
//! the socket bus, and the faults injected at run time.
//!
//! The bus is a [`LocalBus`] serialising frames at 1 Mbit/s (their exact time on the wire,
//! `teleop_can_link::timing`), so frames from the hand and from the host queue behind each
//! other as on a real bus. On it:
//! - the firmware's end, driven by one thread that runs the hand on the simulation's clock
//!   and wakes when a stream frame is due or a frame arrives;
//! - with `--socket`, a [`BusServer`] whose clients (the node's `local:PATH` link) are ends;
//! - with `--slcan`, the simulated adapter ([`crate::adapter`]) on a pty whose device side is
//!   published under a stable symlink (the simulator kit's pty and cable, as the glove's);
//!   unplugging removes the pty and later plugs a new one in behind the same link. The adapter is two ends
//!   of the bus (one sends the host's frames, one receives everyone else's), so it never hears
//!   its own frames back.
//!
//! Time: the hand's frames go on the bus at their due time on the hand's clock even when the
//! firmware's thread runs late (a loaded host), and the adapter's `Z1` timestamps are the bus
//! time; so frames that wait in this process (its threads not scheduled) reach the host late
//! but stamped when they were sent, as with a real hand and adapter.
//!
//! Faults: frames from (or to) the hand dropped with a probability, the stream stopped, the
//! bus off for a while (the adapter's status flags show it; nothing passes), the adapter
//! unplugged for a while, another protocol generation, overheating, injected frames and
//! garbage lines.

use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use teleop_can_link::local::{BusServer, LocalBus, LocalEnd};
use teleop_can_link::slcan::CommandDecoder;
use teleop_can_link::{Bitrate, BusState, CanFrame, CanLink};
use teleop_sim_kit::dice::Dice;
use teleop_sim_kit::lock;
use teleop_sim_kit::outage::Outage;
use teleop_sim_kit::pty::{self, Cable};
use teleop_sim_kit::Stats;

use crate::adapter::{AckStyle, Adapter};
use crate::firmware::{Firmware, Status};

/// The Allegro's bus bit rate (the device document).
pub const BUS_BITRATE: Bitrate = Bitrate(1_000_000);
/// Longest the firmware thread sleeps, so that control commands take effect soon.
const MAX_WAIT: Duration = Duration::from_millis(2);
/// How long a write to the pty may block (a host that does not read loses frames).
const PTY_WRITE_TIMEOUT: Duration = Duration::from_millis(10);
/// How long a pty read waits before looking at unplug and stop requests.
const PTY_READ_TIMEOUT: Duration = Duration::from_millis(5);

/// Probabilities (0..1) of losing a frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Faults {
    /// A frame the hand sends is lost.
    pub drop_out: f64,
    /// A frame sent to the hand is lost.
    pub drop_in: f64,
}

/// Counters of the bus around the firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct BusStats {
    /// Frames the hand sent that were dropped on purpose.
    pub dropped_out: u64,
    /// Frames to the hand dropped on purpose.
    pub dropped_in: u64,
    /// Frames the hand sent while the bus was off.
    pub lost_bus_off: u64,
    /// Frames written to the pty.
    pub pty_frames: u64,
    /// Frames the adapter could not write (the host not reading).
    pub pty_overruns: u64,
    /// Frames the adapter put on the bus from the host.
    pub pty_frames_in: u64,
    /// Times the adapter was unplugged (also counted while it is out).
    pub unplugs: u64,
}

/// How the simulator is reached.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Stable path of the slcan adapter's pty (a symlink), if any.
    pub slcan: Option<PathBuf>,
    /// Socket of the local bus, if any.
    pub socket: Option<PathBuf>,
    /// The adapter's ack style.
    pub ack_style: AckStyle,
    /// Seed of the fault dice.
    pub seed: u64,
}

struct Shared {
    firmware: Mutex<Firmware>,
    start: Instant,
    stop: AtomicBool,
    faults: Mutex<Faults>,
    stats: Mutex<BusStats>,
    inject: Mutex<Vec<CanFrame>>,
    adapter: Mutex<Adapter>,
    ack_style: AckStyle,
    cable: Cable,
    garbage: AtomicU64,
    bus_off: Outage,
}

impl Shared {
    fn sim_now(&self) -> Duration {
        self.start.elapsed()
    }
}

/// A running simulated hand.
pub struct Sim {
    shared: Arc<Shared>,
    bus: LocalBus,
    slcan: Option<PathBuf>,
    server: Option<BusServer>,
    threads: Vec<JoinHandle<()>>,
}

impl Sim {
    /// Starts the firmware on a new bus and serves it as `options` say. The pty link and the
    /// socket exist on return.
    pub fn start(firmware: Firmware, options: SimOptions) -> std::io::Result<Self> {
        let bus = LocalBus::with_timing(BUS_BITRATE);
        let shared = Arc::new(Shared {
            firmware: Mutex::new(firmware),
            start: Instant::now(),
            stop: AtomicBool::new(false),
            faults: Mutex::new(Faults::default()),
            stats: Mutex::new(BusStats::default()),
            inject: Mutex::new(Vec::new()),
            adapter: Mutex::new(Adapter::new(options.ack_style)),
            ack_style: options.ack_style,
            cable: Cable::new(),
            garbage: AtomicU64::new(0),
            bus_off: Outage::new(),
        });
        let server = match &options.socket {
            Some(path) => Some(BusServer::serve(path, bus.clone())?),
            None => None,
        };
        let mut threads = Vec::new();
        let end = bus.end();
        {
            let shared = shared.clone();
            let seed = options.seed;
            threads.push(
                std::thread::Builder::new()
                    .name("allegro-firmware".into())
                    .spawn(move || run_firmware(&shared, end, seed))?,
            );
        }
        if let Some(link) = &options.slcan {
            let first = pty::open(link, PTY_READ_TIMEOUT)?;
            let (shared, bus, link) = (shared.clone(), bus.clone(), link.clone());
            threads.push(
                std::thread::Builder::new()
                    .name("slcan-adapter".into())
                    .spawn(move || serve_adapter(&shared, &bus, &link, first))?,
            );
        }
        Ok(Self {
            shared,
            bus,
            slcan: options.slcan,
            server,
            threads,
        })
    }

    /// The adapter's stable device path, if serving one.
    pub fn slcan_path(&self) -> Option<&Path> {
        self.slcan.as_deref()
    }

    /// The bus socket, if serving one.
    pub fn socket_path(&self) -> Option<&Path> {
        self.server.as_ref().map(BusServer::path)
    }

    /// The bus (for in-process tests: another end is a host).
    pub fn bus(&self) -> &LocalBus {
        &self.bus
    }

    /// Runs `f` on the firmware (and its hand).
    pub fn with_firmware<R>(&self, f: impl FnOnce(&mut Firmware) -> R) -> R {
        f(&mut lock(&self.shared.firmware))
    }

    /// The firmware's state.
    pub fn status(&self) -> Status {
        lock(&self.shared.firmware).status()
    }

    /// Current fault probabilities.
    pub fn faults(&self) -> Faults {
        *lock(&self.shared.faults)
    }

    /// Replaces the fault probabilities.
    pub fn set_faults(&self, faults: Faults) {
        *lock(&self.shared.faults) = faults;
    }

    /// Bus counters.
    pub fn stats(&self) -> BusStats {
        BusStats {
            unplugs: self.shared.cable.unplugs(),
            ..*lock(&self.shared.stats)
        }
    }

    /// The hand sends `frame` (as soon as the firmware thread wakes).
    pub fn inject(&self, frame: CanFrame) {
        lock(&self.shared.inject).push(frame);
    }

    /// The adapter writes an unparsable line to the host (false: no adapter).
    pub fn garbage(&self) -> bool {
        if self.slcan.is_none() {
            return false;
        }
        self.shared.garbage.fetch_add(1, Ordering::SeqCst);
        true
    }

    /// Pulls the adapter's cable for `pause`, then plugs a new pty in behind the same link
    /// (false: no adapter).
    pub fn unplug(&self, pause: Duration) -> bool {
        if self.slcan.is_none() {
            return false;
        }
        self.shared.cable.pull(pause);
        true
    }

    /// The adapter is plugged in (a pty behind the link).
    pub fn plugged(&self) -> bool {
        self.shared.cable.plugged()
    }

    /// The adapter's state, if serving one.
    pub fn adapter(&self) -> Option<Adapter> {
        self.slcan
            .as_ref()
            .map(|_| lock(&self.shared.adapter).clone())
    }

    /// Takes the bus off for `duration` (every end sees bus-off; nothing passes; the adapter's
    /// status flags show it), then back on. A later call replaces the end time.
    pub fn bus_off(&self, duration: Duration) {
        let (shared, bus) = (self.shared.clone(), self.bus.clone());
        self.shared.bus_off.start(
            "bus-on",
            duration,
            || {
                self.bus.set_bus_state(BusState::BusOff);
                lock(&self.shared.adapter).set_bus_off(true);
            },
            move || {
                bus.set_bus_state(BusState::ErrorActive);
                lock(&shared.adapter).set_bus_off(false);
                tracing::info!("bus on again");
            },
        );
    }

    /// The bus is off.
    pub fn is_bus_off(&self) -> bool {
        self.bus.bus_state() == BusState::BusOff
    }

    /// The state and counters as `key=value` words (arrays comma-separated, joint order), as
    /// the control socket's `stats` answers them after `ok `.
    pub fn stats_answer(&self) -> Stats {
        let s = self.status();
        let b = self.stats();
        let yes = |v: bool| if v { "yes" } else { "no" };
        let ms = |d: Option<Duration>| d.map_or(0, |d| d.as_millis());
        let adapter = match self.adapter() {
            None => "none",
            Some(_) if !self.plugged() => "unplugged",
            Some(a) if a.is_open() => "open",
            Some(_) => "closed",
        };
        let c = s.counters;
        Stats::new()
            .field("generation", s.generation)
            .field("system", if s.system_on { "on" } else { "off" })
            .field("streaming", yes(s.streaming))
            .field("period_ms", ms(s.period))
            .field("temperature_ms", ms(s.temperature_period))
            .field("stream_stopped", yes(s.stream_stopped))
            .field("overheated", yes(s.overheated))
            .field("mode", s.mode.unwrap_or("none"))
            .field("frames_in", c.frames_in)
            .field("frames_out", c.frames_out)
            .field("ignored", c.ignored)
            .field("torque_frames", c.torque_frames)
            .field("torque_refused", c.torque_refused)
            .field("torque_timeouts", c.torque_timeouts)
            .field("dropped_out", b.dropped_out)
            .field("dropped_in", b.dropped_in)
            .field("lost_bus_off", b.lost_bus_off)
            .field("bus", self.bus.bus_state())
            .field("adapter", adapter)
            .field("pty_frames_out", b.pty_frames)
            .field("pty_frames_in", b.pty_frames_in)
            .field("unplugs", b.unplugs)
            .field("pwm", list(s.pwm.iter().map(|p| p.to_string())))
            .field("torque", list(s.torque.iter().map(|v| format!("{v:.4}"))))
            .field(
                "position",
                list(s.position.iter().map(|v| format!("{v:.4}"))),
            )
            .field(
                "velocity",
                list(s.velocity.iter().map(|v| format!("{v:.3}"))),
            )
            .field(
                "temperature",
                list(s.temperature.iter().map(|v| format!("{v:.1}"))),
            )
            .field("contact", list(s.contact.iter().map(|v| format!("{v:.3}"))))
    }
}

fn list(items: impl Iterator<Item = String>) -> String {
    items.collect::<Vec<_>>().join(",")
}

impl Drop for Sim {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        if let Some(link) = &self.slcan {
            let _ = std::fs::remove_file(link);
        }
    }
}

/// The firmware's thread: runs the hand on the simulation's clock, sends what falls due,
/// takes frames from the bus.
fn run_firmware(shared: &Shared, mut end: LocalEnd, seed: u64) {
    let mut dice = Dice::new(seed);
    let mut out = Vec::with_capacity(16);
    while !shared.stop.load(Ordering::SeqCst) {
        let due = {
            let mut fw = lock(&shared.firmware);
            fw.advance(shared.sim_now(), &mut out);
            let now = fw.now();
            out.extend(lock(&shared.inject).drain(..).map(|f| (now, f)));
            fw.next_due()
        };
        send(shared, &mut end, &mut out, &mut dice);
        let wait = due
            .map_or(MAX_WAIT, |d| d.saturating_sub(shared.sim_now()))
            .min(MAX_WAIT);
        match end.recv(wait) {
            Ok(Some(frame)) => {
                if dice.roll(lock(&shared.faults).drop_in) {
                    lock(&shared.stats).dropped_in += 1;
                    continue;
                }
                lock(&shared.firmware).receive(shared.sim_now(), &frame, &mut out);
                send(shared, &mut end, &mut out, &mut dice);
            }
            Ok(None) => {}
            Err(e) if e.is_recoverable() => tracing::debug!("firmware's end: {e}"),
            Err(e) => {
                tracing::error!("firmware's end of the bus: {e}");
                return;
            }
        }
    }
}

fn send(shared: &Shared, end: &mut LocalEnd, out: &mut Vec<(Duration, CanFrame)>, dice: &mut Dice) {
    if out.is_empty() {
        return;
    }
    let drop_out = lock(&shared.faults).drop_out;
    for (due, frame) in out.drain(..) {
        if dice.roll(drop_out) {
            lock(&shared.stats).dropped_out += 1;
            continue;
        }
        let errors = end.counters().errors;
        // At its due time on the hand's clock: the hand runs on its own microcontroller, so a
        // frame this thread sends late (not scheduled in time on a loaded host) was on the
        // bus when it fell due. A local end's send only fails when the end is gone.
        let _ = end.send_at(&frame, shared.start + due);
        if end.counters().errors > errors {
            lock(&shared.stats).lost_bus_off += 1;
        }
    }
}

/// Plugs the adapter in (again) until stop: one pty per plugged-in period; unplugged, the
/// adapter loses power and comes back closed, without a bit rate.
fn serve_adapter(shared: &Shared, bus: &LocalBus, link: &Path, first: pty::Pair) {
    pty::serve(
        link,
        PTY_READ_TIMEOUT,
        first,
        &shared.cable,
        &shared.stop,
        |master| connection(shared, bus, master),
        || {
            let mut adapter = Adapter::new(shared.ack_style);
            adapter.set_bus_off(bus.bus_state() == BusState::BusOff);
            *lock(&shared.adapter) = adapter;
        },
    );
}

/// Frames this adapter put on the bus and has not yet heard back on its receiving end.
type Echoes = Arc<Mutex<VecDeque<CanFrame>>>;

/// Serves one plugged-in period: until stop or unplug.
fn connection(shared: &Shared, bus: &LocalBus, master: &mut TTYPort) -> std::io::Result<()> {
    let mut writer = master.try_clone_native().map_err(std::io::Error::other)?;
    writer
        .set_timeout(PTY_WRITE_TIMEOUT)
        .map_err(std::io::Error::other)?;
    let writer = Arc::new(Mutex::new(writer));
    let mut tx = bus.end();
    let rx = bus.end();
    let echoes: Echoes = Arc::new(Mutex::new(VecDeque::new()));
    let done = Arc::new(AtomicBool::new(false));
    let born = Instant::now();
    // The adapter's pointer to shared state outlives this function only inside the scope.
    std::thread::scope(|scope| -> std::io::Result<()> {
        let forward = {
            let (writer, echoes, done) = (writer.clone(), echoes.clone(), done.clone());
            std::thread::Builder::new()
                .name("slcan-to-host".into())
                .spawn_scoped(scope, move || {
                    forward(shared, rx, &writer, &echoes, &done, born)
                })?
        };
        let mut decoder = CommandDecoder::new();
        let mut buf = [0u8; 512];
        let mut reply = Vec::with_capacity(64);
        let result = loop {
            if shared.stop.load(Ordering::SeqCst) || shared.cable.pulled() {
                break Ok(());
            }
            // Nobody reads this end's queue otherwise (it only sends).
            while let Ok(Some(_)) = tx.recv(Duration::ZERO) {}
            let pending = shared.garbage.swap(0, Ordering::SeqCst);
            for _ in 0..pending {
                let _ = lock(&writer).write_all(b"\x01?garbage#\r");
            }
            let n = pty::read(master, &mut buf, PTY_READ_TIMEOUT);
            let mut lines = Vec::new();
            decoder.push(&buf[..n], &mut |line| lines.push(line));
            for line in lines {
                reply.clear();
                let frame = lock(&shared.adapter).command(line, &mut reply);
                if !reply.is_empty() {
                    let _ = lock(&writer).write_all(&reply);
                }
                if let Some(frame) = frame {
                    lock(&echoes).push_back(frame);
                    let sent = tx.counters().tx;
                    let _ = tx.send(&frame);
                    if tx.counters().tx > sent {
                        lock(&shared.stats).pty_frames_in += 1;
                    } else {
                        lock(&echoes).pop_back();
                    }
                }
            }
        };
        done.store(true, Ordering::SeqCst);
        let _ = forward.join();
        result
    })
}

/// Writes what the adapter receives from the bus to the host.
fn forward(
    shared: &Shared,
    mut rx: LocalEnd,
    writer: &Mutex<TTYPort>,
    echoes: &Mutex<VecDeque<CanFrame>>,
    done: &AtomicBool,
    born: Instant,
) {
    let mut line = Vec::with_capacity(32);
    while !done.load(Ordering::SeqCst) {
        let frame = match rx.recv(Duration::from_millis(20)) {
            Ok(Some(f)) => f,
            Ok(None) => continue,
            Err(e) if e.is_recoverable() => continue,
            Err(_) => return,
        };
        {
            let mut echoes = lock(echoes);
            if echoes.front() == Some(&frame) {
                echoes.pop_front();
                continue;
            }
        }
        line.clear();
        // The adapter stamps a frame when it was on the bus (its own clock), not when this
        // thread got to write it.
        let now_ms = rx
            .rx_at()
            .map_or_else(|| born.elapsed(), |at| at.saturating_duration_since(born))
            .as_millis() as u64;
        if !lock(&shared.adapter).deliver(&frame, now_ms, &mut line) {
            continue;
        }
        let ok = lock(writer).write_all(&line).is_ok();
        let mut stats = lock(&shared.stats);
        if ok {
            stats.pty_frames += 1;
        } else {
            stats.pty_overruns += 1;
        }
    }
}
