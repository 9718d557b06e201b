//! A local CAN bus: in-process ([`LocalBus`], for tests) and over a Unix socket
//! ([`BusServer`] in the simulator, [`SocketLink`] in the node) so that the node's code runs
//! against a simulated hand in another process.
//!
//! A CAN bus is a broadcast medium: every end sees the frames every other end sends, never its
//! own. Each end has a bounded receive queue ([`QUEUE`] frames); when it is full the oldest
//! frame is dropped and counted as an overrun.
//!
//! Frame-level timing: with [`LocalBus::set_timing`] the bus carries one frame at a time at the
//! bit rate, each taking its exact time on the wire ([`crate::timing::frame_time_exact`]):
//! a frame reaches the other ends when its transmission would end, frames queue behind each
//! other, and a sender whose own [`TX_QUEUE`] frames are all still waiting blocks until the
//! first has gone (as a controller's transmit queue). So bus time is real time.
//!
//! Each frame received keeps its bus time (when its transmission ended): [`LocalEnd::rx_at`],
//! and as [`CanLink::rx_stamp_ms`] milliseconds since the bus was made, as an slcan adapter's
//! timestamp would give it. [`LocalEnd::send_at`] puts a frame on the bus at a time in the
//! past (a simulated device that was not scheduled in time sends what fell due, at its due
//! time).
//!
//! Bus-off can be simulated with [`LocalBus::set_bus_state`]: every end's
//! [`CanLink::bus_state`] follows, [`CanLink::recv`] returns [`LinkError::BusOff`] once when
//! the bus goes off, and while it is off frames are dropped (a send counts an error).
//!
//! Socket protocol: a stream of 16-byte records, like Linux's `struct can_frame`: u32
//! little-endian id word (bit 31 extended, bit 30 remote, bit 29 bus-state record), u8 DLC,
//! 3 reserved bytes, 8 data bytes (a state record carries the state in data byte 0: 0
//! active, 1 warning, 2 passive, 3 bus-off).

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::timing::frame_time_exact;
use crate::{Bitrate, BusState, CanFrame, CanLink, LinkCounters, LinkError};

/// Frames each end's receive queue holds.
pub const QUEUE: usize = 1024;
/// Frames an end may have waiting for the bus (with timing on) before `send` blocks (Linux's
/// default `txqueuelen` for CAN interfaces).
pub const TX_QUEUE: usize = 10;
/// Size of one record on the socket.
pub const RECORD: usize = 16;

const FLAG_EXTENDED: u32 = 1 << 31;
const FLAG_REMOTE: u32 = 1 << 30;
const FLAG_STATE: u32 = 1 << 29;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// What an end receives: a frame, or a change of bus state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Event {
    Frame(CanFrame),
    State(BusState),
}

struct Queue {
    inner: Mutex<QueueInner>,
    ready: Condvar,
}

struct QueueInner {
    /// Events and the time from which they may be received.
    events: VecDeque<(Instant, Event)>,
    closed: bool,
    overruns: u64,
    state: BusState,
}

struct Hub {
    inner: Mutex<HubInner>,
    /// The bus's time zero (for receive stamps).
    epoch: Instant,
}

struct HubInner {
    ends: Vec<(u64, Arc<Queue>)>,
    next_id: u64,
    timing: Option<Bitrate>,
    bus_free_at: Instant,
    state: BusState,
}

/// An in-process CAN bus. Cloning gives another handle to the same bus.
#[derive(Clone)]
pub struct LocalBus {
    hub: Arc<Hub>,
}

impl Default for LocalBus {
    fn default() -> Self {
        Self::new()
    }
}

impl LocalBus {
    /// A bus without timing (frames arrive at once) and no ends yet.
    pub fn new() -> Self {
        Self {
            hub: Arc::new(Hub {
                inner: Mutex::new(HubInner {
                    ends: Vec::new(),
                    next_id: 1,
                    timing: None,
                    bus_free_at: Instant::now(),
                    state: BusState::ErrorActive,
                }),
                epoch: Instant::now(),
            }),
        }
    }

    /// A bus that serialises frames at `bitrate` (see [`Self::set_timing`]).
    pub fn with_timing(bitrate: Bitrate) -> Self {
        let bus = Self::new();
        bus.set_timing(Some(bitrate));
        bus
    }

    /// Serialises frames at this bit rate from now on (`None`: frames arrive at once).
    pub fn set_timing(&self, bitrate: Option<Bitrate>) {
        lock(&self.hub.inner).timing = bitrate.filter(|b| b.0 > 0);
    }

    /// The bit rate frames are serialised at, if any.
    pub fn timing(&self) -> Option<Bitrate> {
        lock(&self.hub.inner).timing
    }

    /// A new end of the bus (a node on it), described as `local:bus/N`.
    pub fn end(&self) -> LocalEnd {
        self.end_named(None)
    }

    fn end_named(&self, what: Option<String>) -> LocalEnd {
        let mut hub = lock(&self.hub.inner);
        let id = hub.next_id;
        hub.next_id += 1;
        let queue = Arc::new(Queue {
            inner: Mutex::new(QueueInner {
                events: VecDeque::with_capacity(QUEUE),
                closed: false,
                overruns: 0,
                state: hub.state,
            }),
            ready: Condvar::new(),
        });
        hub.ends.push((id, queue.clone()));
        LocalEnd {
            hub: self.hub.clone(),
            id,
            queue,
            what: what.unwrap_or_else(|| format!("local:bus/{id}")),
            counters: LinkCounters::default(),
            tx_pending: VecDeque::with_capacity(TX_QUEUE),
            bus_off_reported: false,
            last_rx_at: None,
            own_free_at: None,
        }
    }

    /// Ends attached now.
    pub fn ends(&self) -> usize {
        lock(&self.hub.inner).ends.len()
    }

    /// Sets the bus state every end sees (to simulate error-passive or bus-off).
    pub fn set_bus_state(&self, state: BusState) {
        let mut hub = lock(&self.hub.inner);
        if hub.state == state {
            return;
        }
        hub.state = state;
        let now = Instant::now();
        for (_, queue) in &hub.ends {
            let mut q = lock(&queue.inner);
            q.state = state;
            push_event(&mut q, now, Event::State(state));
            queue.ready.notify_all();
        }
    }

    /// The bus state set with [`Self::set_bus_state`].
    pub fn bus_state(&self) -> BusState {
        lock(&self.hub.inner).state
    }
}

fn push_event(q: &mut QueueInner, at: Instant, event: Event) {
    if q.events.len() >= QUEUE {
        q.events.pop_front();
        q.overruns += 1;
    }
    q.events.push_back((at, event));
}

/// One end of a [`LocalBus`] (a node on it). Dropping it detaches it from the bus.
pub struct LocalEnd {
    hub: Arc<Hub>,
    id: u64,
    queue: Arc<Queue>,
    what: String,
    counters: LinkCounters,
    /// When this end's frames waiting for the bus will have been sent (timing on).
    tx_pending: VecDeque<Instant>,
    bus_off_reported: bool,
    /// Bus time of the frame `recv` returned last.
    last_rx_at: Option<Instant>,
    /// When this end's last frame left the bus (timing on).
    own_free_at: Option<Instant>,
}

impl LocalEnd {
    /// Sends `frame` as if at `at` (no later than now): on a timed bus its transmission starts
    /// when the bus is free from then on, so frames a late sender sends in a burst keep the
    /// bus times they were due at. Otherwise as [`CanLink::send`].
    pub fn send_at(&mut self, frame: &CanFrame, at: Instant) -> Result<(), LinkError> {
        if self.broadcast_at(frame, Some(at)) {
            self.counters.tx += 1;
        } else {
            self.counters.errors += 1;
        }
        Ok(())
    }

    /// The bus time of the frame [`CanLink::recv`] returned last (when its transmission
    /// ended).
    pub fn rx_at(&self) -> Option<Instant> {
        self.last_rx_at
    }

    /// Puts `frame` on the bus; false when the bus is off (the frame is dropped).
    fn broadcast(&mut self, frame: &CanFrame) -> bool {
        self.broadcast_at(frame, None)
    }

    /// Puts `frame` on the bus as if sent at `at` (None: now).
    fn broadcast_at(&mut self, frame: &CanFrame, at: Option<Instant>) -> bool {
        let timed = lock(&self.hub.inner).timing.is_some();
        if timed {
            // A full transmit queue: wait until its oldest frame has gone.
            let now = Instant::now();
            while self.tx_pending.front().is_some_and(|&t| t <= now) {
                self.tx_pending.pop_front();
            }
            if self.tx_pending.len() >= TX_QUEUE {
                if let Some(first) = self.tx_pending.pop_front() {
                    std::thread::sleep(first.saturating_duration_since(now));
                }
            }
        }
        let mut hub = lock(&self.hub.inner);
        if hub.state == BusState::BusOff {
            return false;
        }
        let real_now = Instant::now();
        let now = at.map_or(real_now, |at| at.min(real_now));
        let at = match hub.timing {
            Some(bitrate) => {
                // A frame sent as if earlier queues behind this end's own frames only: the bus
                // time others booked since then (in real time) is not taken back from them.
                let free = if now < real_now {
                    self.own_free_at.unwrap_or(now)
                } else {
                    hub.bus_free_at
                };
                let start = free.max(now);
                let end = start + frame_time_exact(frame, bitrate);
                hub.bus_free_at = hub.bus_free_at.max(end);
                self.own_free_at = Some(end);
                self.tx_pending.push_back(end);
                end
            }
            None => now,
        };
        for (id, queue) in &hub.ends {
            if *id == self.id {
                continue;
            }
            let mut q = lock(&queue.inner);
            push_event(&mut q, at, Event::Frame(*frame));
            queue.ready.notify_all();
        }
        true
    }

    /// Waits up to `timeout` for the next event; Err when the end was closed.
    fn recv_event(&mut self, timeout: Duration) -> Result<Option<Event>, LinkError> {
        let deadline = Instant::now() + timeout;
        let mut q = lock(&self.queue.inner);
        loop {
            let now = Instant::now();
            let wake = match q.events.front() {
                Some(&(at, _)) if at <= now => {
                    return Ok(q.events.pop_front().map(|(at, e)| {
                        if let Event::Frame(_) = e {
                            self.last_rx_at = Some(at);
                        }
                        e
                    }));
                }
                Some(&(at, _)) => at.min(deadline),
                None if q.closed => {
                    return Err(LinkError::Disconnected {
                        what: self.what.clone(),
                        detail: "the bus was closed".into(),
                    })
                }
                None => deadline,
            };
            if now >= deadline {
                return Ok(None);
            }
            q = self
                .queue
                .ready
                .wait_timeout(q, wake.saturating_duration_since(now))
                .map(|(g, _)| g)
                .unwrap_or_else(|e| e.into_inner().0);
        }
    }

    fn close(&self) {
        lock(&self.hub.inner).ends.retain(|(id, _)| *id != self.id);
        let mut q = lock(&self.queue.inner);
        q.closed = true;
        self.queue.ready.notify_all();
    }
}

impl CanLink for LocalEnd {
    fn send(&mut self, frame: &CanFrame) -> Result<(), LinkError> {
        if self.broadcast(frame) {
            self.counters.tx += 1;
        } else {
            self.counters.errors += 1;
        }
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, LinkError> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv_event(left)? {
                Some(Event::Frame(f)) => {
                    self.counters.rx += 1;
                    return Ok(Some(f));
                }
                Some(Event::State(BusState::BusOff)) => {
                    if !self.bus_off_reported {
                        self.bus_off_reported = true;
                        return Err(LinkError::BusOff {
                            what: self.what.clone(),
                        });
                    }
                }
                Some(Event::State(_)) => self.bus_off_reported = false,
                None => return Ok(None),
            }
        }
    }

    fn bus_state(&self) -> BusState {
        lock(&self.queue.inner).state
    }

    fn counters(&self) -> LinkCounters {
        LinkCounters {
            overruns: lock(&self.queue.inner).overruns,
            ..self.counters
        }
    }

    fn describe(&self) -> &str {
        &self.what
    }

    fn rx_stamp_ms(&self) -> Option<u16> {
        let at = self.last_rx_at?;
        let ms = at.saturating_duration_since(self.hub.epoch).as_millis();
        Some((ms % u128::from(crate::STAMP_WRAP_MS)) as u16)
    }
}

impl Drop for LocalEnd {
    fn drop(&mut self) {
        self.close();
    }
}

fn encode_record(event: &Event) -> [u8; RECORD] {
    let mut r = [0u8; RECORD];
    match event {
        Event::Frame(f) => {
            let mut word = f.raw_id();
            if f.is_extended() {
                word |= FLAG_EXTENDED;
            }
            if f.is_remote() {
                word |= FLAG_REMOTE;
            }
            r[..4].copy_from_slice(&word.to_le_bytes());
            // At most 8.
            r[4] = f.dlc() as u8;
            r[8..8 + f.data().len()].copy_from_slice(f.data());
        }
        Event::State(s) => {
            r[..4].copy_from_slice(&FLAG_STATE.to_le_bytes());
            r[4] = 1;
            r[8] = match s {
                BusState::ErrorActive => 0,
                BusState::ErrorWarning => 1,
                BusState::ErrorPassive => 2,
                BusState::BusOff => 3,
            };
        }
    }
    r
}

/// Decodes one record; a description of what is wrong otherwise.
fn decode_record(r: &[u8; RECORD]) -> Result<Event, String> {
    let word = u32::from_le_bytes([r[0], r[1], r[2], r[3]]);
    let dlc = r[4];
    if word & FLAG_STATE != 0 {
        return match (word & !FLAG_STATE, dlc, r[8]) {
            (0, 1, 0) => Ok(Event::State(BusState::ErrorActive)),
            (0, 1, 1) => Ok(Event::State(BusState::ErrorWarning)),
            (0, 1, 2) => Ok(Event::State(BusState::ErrorPassive)),
            (0, 1, 3) => Ok(Event::State(BusState::BusOff)),
            _ => Err(format!("bad bus-state record {r:02X?}")),
        };
    }
    let id = word & !(FLAG_EXTENDED | FLAG_REMOTE);
    let n = usize::from(dlc.min(8));
    let frame = match (word & FLAG_EXTENDED != 0, word & FLAG_REMOTE != 0) {
        (false, false) => u16::try_from(id)
            .ok()
            .and_then(|id| CanFrame::standard(id, &r[8..8 + n])),
        (false, true) => u16::try_from(id)
            .ok()
            .and_then(|id| CanFrame::standard_remote(id, dlc)),
        (true, false) => CanFrame::extended(id, &r[8..8 + n]),
        (true, true) => CanFrame::extended_remote(id, dlc),
    };
    match frame {
        Some(f) if dlc <= 8 => Ok(Event::Frame(f)),
        _ => Err(format!(
            "bad frame record {r:02X?} (id or DLC out of range)"
        )),
    }
}

/// The simulator's side of the socket bus: a [`LocalBus`] served on a Unix socket. Each
/// connected client is one more end; the server's own ends ([`Self::end`]) are in-process.
/// Dropping it disconnects the clients and removes the socket file.
pub struct BusServer {
    bus: LocalBus,
    path: PathBuf,
    stop: Arc<AtomicBool>,
    clients: Arc<Mutex<Vec<(u64, UnixStream)>>>,
    threads: Arc<Mutex<Vec<JoinHandle<()>>>>,
    accept: Option<JoinHandle<()>>,
}

impl BusServer {
    /// Binds `path` (replacing a stale socket file nobody listens on) and accepts clients
    /// in a thread. Fails with `AddrInUse` when another server is listening there.
    pub fn bind(path: &Path) -> std::io::Result<Self> {
        Self::serve(path, LocalBus::new())
    }

    /// As [`Self::bind`], serving an existing bus (its in-process ends see the clients).
    pub fn serve(path: &Path, bus: LocalBus) -> std::io::Result<Self> {
        if path.exists() {
            if UnixStream::connect(path).is_ok() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::AddrInUse,
                    format!("{}: another bus server is listening", path.display()),
                ));
            }
            std::fs::remove_file(path)?;
        }
        let listener = UnixListener::bind(path)?;
        let stop = Arc::new(AtomicBool::new(false));
        let clients = Arc::new(Mutex::new(Vec::new()));
        let threads = Arc::new(Mutex::new(Vec::new()));
        let accept = {
            let (bus, stop, clients, threads) =
                (bus.clone(), stop.clone(), clients.clone(), threads.clone());
            let path = path.to_path_buf();
            std::thread::Builder::new()
                .name("can-bus-accept".into())
                .spawn(move || accept_loop(listener, &path, &bus, &stop, &clients, &threads))?
        };
        Ok(Self {
            bus,
            path: path.to_path_buf(),
            stop,
            clients,
            threads,
            accept: Some(accept),
        })
    }

    /// A new in-process end of the served bus.
    pub fn end(&self) -> LocalEnd {
        self.bus.end()
    }

    /// The served bus (timing, bus state).
    pub fn bus(&self) -> &LocalBus {
        &self.bus
    }

    /// The socket path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        lock(&self.clients).len()
    }
}

impl Drop for BusServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        for (_, stream) in lock(&self.clients).iter() {
            let _ = stream.shutdown(std::net::Shutdown::Both);
        }
        // Wake the accept loop; if the socket file was taken away meanwhile it cannot be
        // woken, and is left to end with the process rather than hang here.
        if UnixStream::connect(&self.path).is_ok() {
            if let Some(t) = self.accept.take() {
                let _ = t.join();
            }
        }
        let threads = std::mem::take(&mut *lock(&self.threads));
        for t in threads {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.path);
    }
}

fn accept_loop(
    listener: UnixListener,
    path: &Path,
    bus: &LocalBus,
    stop: &AtomicBool,
    clients: &Arc<Mutex<Vec<(u64, UnixStream)>>>,
    threads: &Arc<Mutex<Vec<JoinHandle<()>>>>,
) {
    for stream in listener.incoming() {
        if stop.load(Ordering::SeqCst) {
            break;
        }
        let stream = match stream {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(socket = %path.display(), "accept failed: {e}");
                std::thread::sleep(Duration::from_millis(10));
                continue;
            }
        };
        if let Err(e) = start_client(stream, path, bus, clients, threads) {
            tracing::warn!(socket = %path.display(), "cannot serve a client: {e}");
        }
    }
}

fn start_client(
    stream: UnixStream,
    path: &Path,
    bus: &LocalBus,
    clients: &Arc<Mutex<Vec<(u64, UnixStream)>>>,
    threads: &Arc<Mutex<Vec<JoinHandle<()>>>>,
) -> std::io::Result<()> {
    let reader = stream.try_clone()?;
    let mut writer = stream.try_clone()?;
    let mut end = bus.end_named(None);
    let id = end.id;
    end.what = format!("local:{}#{id}", path.display());
    // A client that stops reading must not stall the bus for long.
    writer.set_write_timeout(Some(Duration::from_secs(1)))?;
    lock(clients).push((id, stream));
    // The client learns the bus state first.
    let state = lock(&end.queue.inner).state;
    writer.write_all(&encode_record(&Event::State(state)))?;
    let queue = end.queue.clone();
    let hub = end.hub.clone();
    let tx = std::thread::Builder::new()
        .name(format!("can-bus-tx-{id}"))
        .spawn(move || {
            // This end's receive side: bus -> client.
            let mut end = end;
            loop {
                match end.recv_event(Duration::from_millis(500)) {
                    Ok(Some(event)) => {
                        if writer.write_all(&encode_record(&event)).is_err() {
                            break;
                        }
                        if let Event::Frame(_) = event {
                            end.counters.rx += 1;
                        }
                    }
                    Ok(None) => {}
                    Err(_) => break,
                }
            }
            let _ = writer.shutdown(std::net::Shutdown::Both);
        })?;
    let clients2 = clients.clone();
    let rx = std::thread::Builder::new()
        .name(format!("can-bus-rx-{id}"))
        .spawn(move || {
            // client -> bus, as this client's end.
            let mut sender = LocalEnd {
                hub,
                id,
                queue,
                what: String::new(),
                counters: LinkCounters::default(),
                tx_pending: VecDeque::with_capacity(TX_QUEUE),
                bus_off_reported: false,
                last_rx_at: None,
                own_free_at: None,
            };
            let mut reader = reader;
            let mut record = [0u8; RECORD];
            loop {
                if reader.read_exact(&mut record).is_err() {
                    break;
                }
                match decode_record(&record) {
                    Ok(Event::Frame(f)) => {
                        sender.broadcast(&f);
                    }
                    Ok(Event::State(_)) => {}
                    Err(e) => tracing::debug!("client {id}: {e}"),
                }
            }
            // Detaches the end: the tx thread ends.
            sender.close();
            lock(&clients2).retain(|(c, _)| *c != id);
        })?;
    lock(threads).extend([tx, rx]);
    Ok(())
}

/// The node's side of the socket bus: a client of a [`BusServer`].
pub struct SocketLink {
    stream: UnixStream,
    what: String,
    record: [u8; RECORD],
    filled: usize,
    read_timeout: Option<Duration>,
    state: BusState,
    bus_off_reported: bool,
    counters: LinkCounters,
}

impl SocketLink {
    /// Connects to the bus socket at `path`. [`LinkError::NotFound`] when nobody serves it.
    pub fn connect(path: &Path) -> Result<Self, LinkError> {
        let what = format!("local:{}", path.display());
        let stream = UnixStream::connect(path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound | std::io::ErrorKind::ConnectionRefused => {
                LinkError::NotFound {
                    what: what.clone(),
                    detail: format!(
                        "no bus server there ({e}); is the simulator running with --socket {}?",
                        path.display()
                    ),
                }
            }
            _ => LinkError::Io {
                what: what.clone(),
                source: e,
            },
        })?;
        stream
            .set_write_timeout(Some(Duration::from_secs(1)))
            .map_err(|source| LinkError::Io {
                what: what.clone(),
                source,
            })?;
        Ok(Self {
            stream,
            what,
            record: [0; RECORD],
            filled: 0,
            read_timeout: None,
            state: BusState::ErrorActive,
            bus_off_reported: false,
            counters: LinkCounters::default(),
        })
    }

    fn disconnected(&self, detail: String) -> LinkError {
        LinkError::Disconnected {
            what: self.what.clone(),
            detail,
        }
    }
}

impl CanLink for SocketLink {
    fn send(&mut self, frame: &CanFrame) -> Result<(), LinkError> {
        if self.state == BusState::BusOff {
            self.counters.errors += 1;
            return Ok(());
        }
        match self.stream.write_all(&encode_record(&Event::Frame(*frame))) {
            Ok(()) => {
                self.counters.tx += 1;
                Ok(())
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                ) =>
            {
                Err(LinkError::Io {
                    what: self.what.clone(),
                    source: std::io::Error::new(e.kind(), "the bus server takes no frames"),
                })
            }
            Err(e) => Err(self.disconnected(format!("write failed: {e}; the bus server is gone"))),
        }
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<CanFrame>, LinkError> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.filled == RECORD {
                self.filled = 0;
                match decode_record(&self.record) {
                    Ok(Event::Frame(f)) => {
                        self.counters.rx += 1;
                        return Ok(Some(f));
                    }
                    Ok(Event::State(s)) => {
                        self.state = s;
                        if s != BusState::BusOff {
                            self.bus_off_reported = false;
                        } else if !self.bus_off_reported {
                            self.bus_off_reported = true;
                            return Err(LinkError::BusOff {
                                what: self.what.clone(),
                            });
                        }
                    }
                    Err(e) => {
                        self.counters.errors += 1;
                        tracing::debug!(link = %self.what, "{e}");
                    }
                }
                continue;
            }
            let now = Instant::now();
            // SO_RCVTIMEO cannot be zero (that means "forever"): a microsecond instead.
            let wait = deadline
                .saturating_duration_since(now)
                .max(Duration::from_micros(1));
            if self.read_timeout != Some(wait) {
                self.stream
                    .set_read_timeout(Some(wait))
                    .map_err(|source| LinkError::Io {
                        what: self.what.clone(),
                        source,
                    })?;
                self.read_timeout = Some(wait);
            }
            match self.stream.read(&mut self.record[self.filled..]) {
                Ok(0) => {
                    return Err(self.disconnected("the bus server closed the connection".into()))
                }
                Ok(n) => self.filled += n,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                    ) =>
                {
                    if Instant::now() >= deadline {
                        return Ok(None);
                    }
                }
                Err(e) => return Err(self.disconnected(format!("read failed: {e}"))),
            }
        }
    }

    fn bus_state(&self) -> BusState {
        self.state
    }

    fn counters(&self) -> LinkCounters {
        self.counters
    }

    fn describe(&self) -> &str {
        &self.what
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn frame(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::standard(id, data).expect("valid frame")
    }

    const NO_WAIT: Duration = Duration::ZERO;
    const WAIT: Duration = Duration::from_secs(2);

    #[test]
    fn every_end_sees_the_others_never_its_own() {
        let bus = LocalBus::new();
        let (mut a, mut b, mut c) = (bus.end(), bus.end(), bus.end());
        assert_eq!(bus.ends(), 3);
        a.send(&frame(0x100, &[1])).expect("send");
        b.send(&frame(0x200, &[2])).expect("send");
        assert_eq!(a.recv(WAIT).expect("recv"), Some(frame(0x200, &[2])));
        assert_eq!(a.recv(NO_WAIT).expect("recv"), None);
        assert_eq!(b.recv(WAIT).expect("recv"), Some(frame(0x100, &[1])));
        assert_eq!(b.recv(NO_WAIT).expect("recv"), None);
        assert_eq!(c.recv(WAIT).expect("recv"), Some(frame(0x100, &[1])));
        assert_eq!(c.recv(WAIT).expect("recv"), Some(frame(0x200, &[2])));
        let counters = c.counters();
        assert_eq!((counters.rx, counters.tx), (2, 0));
        assert_eq!(a.counters().tx, 1);
        drop(c);
        assert_eq!(bus.ends(), 2);
        assert!(a.describe().starts_with("local:bus/"));
    }

    #[test]
    fn recv_blocks_until_a_frame_or_the_timeout() {
        let bus = LocalBus::new();
        let (mut a, mut b) = (bus.end(), bus.end());
        let start = Instant::now();
        assert_eq!(b.recv(Duration::from_millis(30)).expect("recv"), None);
        assert!(start.elapsed() >= Duration::from_millis(30));
        let sender = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            a.send(&frame(0x7FF, &[])).expect("send");
            a
        });
        assert_eq!(b.recv(WAIT).expect("recv"), Some(frame(0x7FF, &[])));
        drop(sender.join().expect("sender"));
    }

    #[test]
    fn full_queue_drops_the_oldest_as_overruns() {
        let bus = LocalBus::new();
        let (mut a, mut b) = (bus.end(), bus.end());
        for i in 0..QUEUE + 5 {
            a.send(&frame((i % 0x800) as u16, &[])).expect("send");
        }
        assert_eq!(b.counters().overruns, 5);
        assert_eq!(b.recv(NO_WAIT).expect("recv"), Some(frame(5, &[])));
    }

    #[test]
    fn timing_serialises_frames_at_the_bit_rate() {
        let bus = LocalBus::with_timing(Bitrate::MBIT_1);
        assert_eq!(bus.timing(), Some(Bitrate::MBIT_1));
        let (mut a, mut b) = (bus.end(), bus.end());
        let frames: Vec<CanFrame> = (0..8u8)
            .map(|i| frame(0x3D3, &[i, 0x80, 0, 0x80, 0, 0x80, 0, 0x80]))
            .collect();
        let bus_time: Duration = frames
            .iter()
            .map(|f| frame_time_exact(f, Bitrate::MBIT_1))
            .sum();
        let start = Instant::now();
        for f in &frames {
            a.send(f).expect("send");
        }
        // Queued, not waited for: the sender is not held up by 8 frames (TX_QUEUE is 10).
        let mut got = Vec::new();
        while got.len() < frames.len() {
            got.push(b.recv(WAIT).expect("recv").expect("a frame"));
        }
        let took = start.elapsed();
        assert_eq!(got, frames);
        // About 1 ms of bus time: the last frame cannot arrive before it.
        assert!(took >= bus_time, "{took:?} < {bus_time:?}");
        // Nothing arrives before its own transmission ended.
        let start = Instant::now();
        a.send(&frames[0]).expect("send");
        assert_eq!(b.recv(NO_WAIT).expect("recv"), None);
        assert_eq!(b.recv(WAIT).expect("recv"), Some(frames[0]));
        assert!(start.elapsed() >= frame_time_exact(&frames[0], Bitrate::MBIT_1));
    }

    #[test]
    fn frames_sent_late_keep_their_bus_time_in_the_receive_stamps() {
        let bus = LocalBus::with_timing(Bitrate::MBIT_1);
        let (mut hand, mut host, mut other) = (bus.end(), bus.end(), bus.end());
        let f = frame(0x3D3, &[0; 8]);
        std::thread::sleep(Duration::from_millis(50));
        // A hand that was not scheduled for 40 ms sends its overdue periods at once, while
        // another end sent in real time meanwhile.
        let due0 = Instant::now() - Duration::from_millis(40);
        other.send(&frame(0x18A, &[0; 8])).expect("send");
        for k in 0..4u32 {
            hand.send_at(&f, due0 + Duration::from_millis(3) * k)
                .expect("send");
        }
        assert_eq!(host.recv(WAIT).expect("recv"), Some(frame(0x18A, &[0; 8])));
        let now_stamp = host.rx_stamp_ms().expect("a stamp");
        let mut stamps = Vec::new();
        for _ in 0..4 {
            assert_eq!(host.recv(WAIT).expect("recv"), Some(f));
            stamps.push(host.rx_stamp_ms().expect("a stamp"));
        }
        let gaps: Vec<u16> = stamps
            .windows(2)
            .map(|w| crate::stamp_gap_ms(w[0], w[1]))
            .collect();
        assert_eq!(gaps, [3, 3, 3], "{stamps:?}");
        assert!(
            crate::stamp_gap_ms(stamps[0], now_stamp) >= 38,
            "the first was due 40 ms ago: {stamps:?} vs {now_stamp}"
        );
        assert!(host.rx_at().is_some());
        // Stamps wrap as slcan's do.
        assert_eq!(crate::stamp_gap_ms(59_999, 2), 3);
    }

    #[test]
    fn timing_blocks_a_sender_with_a_full_transmit_queue() {
        // At 10 kbit/s an 8-byte frame takes over 11 ms: the 11th send waits for the first.
        let bus = LocalBus::with_timing(Bitrate(10_000));
        let (mut a, _b) = (bus.end(), bus.end());
        let f = frame(0x100, &[0; 8]);
        let start = Instant::now();
        for _ in 0..TX_QUEUE {
            a.send(&f).expect("send");
        }
        assert!(start.elapsed() < frame_time_exact(&f, Bitrate(10_000)));
        a.send(&f).expect("send");
        assert!(start.elapsed() >= frame_time_exact(&f, Bitrate(10_000)));
    }

    #[test]
    fn bus_off_is_reported_once_and_drops_frames() {
        let bus = LocalBus::new();
        let (mut a, mut b) = (bus.end(), bus.end());
        bus.set_bus_state(BusState::BusOff);
        assert_eq!(b.bus_state(), BusState::BusOff);
        let err = b.recv(WAIT).expect_err("bus-off");
        assert!(matches!(err, LinkError::BusOff { .. }), "{err}");
        a.send(&frame(0x100, &[])).expect("send");
        assert_eq!(a.counters().errors, 1);
        assert_eq!(b.recv(Duration::from_millis(10)).expect("recv"), None);
        bus.set_bus_state(BusState::ErrorActive);
        assert!(a.recv(WAIT).is_err(), "a sees the bus-off too");
        assert_eq!(a.recv(NO_WAIT).expect("recv"), None);
        a.send(&frame(0x100, &[])).expect("send");
        assert_eq!(b.recv(WAIT).expect("recv"), Some(frame(0x100, &[])));
        assert_eq!(b.bus_state(), BusState::ErrorActive);
    }

    fn wait_for_clients(server: &BusServer, n: usize) {
        let deadline = Instant::now() + WAIT;
        while server.clients() != n && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(1));
        }
        assert_eq!(server.clients(), n);
    }

    #[test]
    fn socket_bus_connects_processes() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("bus.sock");
        let server = BusServer::bind(&path).expect("bind");
        let mut sim = server.end();
        let mut node = SocketLink::connect(&path).expect("connect");
        let mut other = SocketLink::connect(&path).expect("connect");
        wait_for_clients(&server, 2);
        assert_eq!(node.describe(), format!("local:{}", path.display()));

        sim.send(&frame(0x3D3, &[1, 2, 3, 4, 5, 6, 7, 8]))
            .expect("send");
        assert_eq!(
            node.recv(WAIT).expect("recv"),
            Some(frame(0x3D3, &[1, 2, 3, 4, 5, 6, 7, 8]))
        );
        assert_eq!(
            other.recv(WAIT).expect("recv"),
            Some(frame(0x3D3, &[1, 2, 3, 4, 5, 6, 7, 8]))
        );
        let rtr = CanFrame::standard_remote(0x200, 0).expect("valid");
        node.send(&rtr).expect("send");
        assert_eq!(sim.recv(WAIT).expect("recv"), Some(rtr));
        // The other client sees it, the sender does not.
        assert_eq!(other.recv(WAIT).expect("recv"), Some(rtr));
        assert_eq!(node.recv(Duration::from_millis(20)).expect("recv"), None);
        let ext = CanFrame::extended(0x1ABC_DEF0, &[9]).expect("valid");
        other.send(&ext).expect("send");
        assert_eq!(node.recv(WAIT).expect("recv"), Some(ext));
        assert_eq!(node.counters().rx, 2);
        assert_eq!(node.counters().tx, 1);

        // Bus state reaches the clients.
        server.bus().set_bus_state(BusState::BusOff);
        let err = node.recv(WAIT).expect_err("bus-off");
        assert!(matches!(err, LinkError::BusOff { .. }), "{err}");
        assert_eq!(node.bus_state(), BusState::BusOff);
        server.bus().set_bus_state(BusState::ErrorActive);
        assert_eq!(node.recv(Duration::from_millis(50)).expect("recv"), None);
        assert_eq!(node.bus_state(), BusState::ErrorActive);

        // A client that leaves is detached.
        drop(other);
        wait_for_clients(&server, 1);

        // The server going away disconnects the client.
        drop(sim);
        drop(server);
        assert!(!path.exists());
        let err = node.recv(WAIT).expect_err("server gone");
        assert!(matches!(err, LinkError::Disconnected { .. }), "{err}");
        assert!(err.is_recoverable());
    }

    #[test]
    fn socket_bus_through_the_link_spec() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("bus.sock");
        let server = BusServer::bind(&path).expect("bind");
        let mut sim = server.end();
        let spec: crate::LinkSpec = format!("local:{}", path.display()).parse().expect("spec");
        let mut link = crate::open(&spec, Bitrate::MBIT_1).expect("open");
        link.send(&frame(0x04A, &[])).expect("send");
        assert_eq!(sim.recv(WAIT).expect("recv"), Some(frame(0x04A, &[])));
    }

    #[test]
    fn stale_socket_is_replaced_and_a_live_one_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("bus.sock");
        {
            let _listener = UnixListener::bind(&path).expect("bind");
        }
        // The listener is gone; its file is left behind.
        assert!(path.exists());
        let server = BusServer::bind(&path).expect("replaces the stale file");
        let err = BusServer::bind(&path).err().expect("in use");
        assert_eq!(err.kind(), std::io::ErrorKind::AddrInUse);
        drop(server);
    }

    #[test]
    fn connect_without_a_server_is_not_found() {
        let dir = tempfile::tempdir().expect("tempdir");
        let err = SocketLink::connect(&dir.path().join("none.sock"))
            .err()
            .expect("no server");
        assert!(matches!(err, LinkError::NotFound { .. }), "{err}");
        assert!(err.to_string().contains("--socket"), "{err}");
    }

    proptest! {
        #[test]
        fn records_decode_totally(bytes in proptest::array::uniform16(any::<u8>())) {
            if let Ok(event) = decode_record(&bytes) {
                // Whatever decodes encodes to a record that decodes the same.
                prop_assert_eq!(decode_record(&encode_record(&event)), Ok(event));
            }
        }

        #[test]
        fn records_round_trip(id in 0u32..=0x1FFF_FFFF, ext: bool, remote: bool,
                              data in proptest::collection::vec(any::<u8>(), 0..=8)) {
            let f = match (ext, remote) {
                (false, false) => CanFrame::standard((id & 0x7FF) as u16, &data),
                (false, true) => CanFrame::standard_remote((id & 0x7FF) as u16, data.len() as u8),
                (true, false) => CanFrame::extended(id, &data),
                (true, true) => CanFrame::extended_remote(id, data.len() as u8),
            }.expect("valid");
            prop_assert_eq!(decode_record(&encode_record(&Event::Frame(f))), Ok(Event::Frame(f)));
        }
    }
}
