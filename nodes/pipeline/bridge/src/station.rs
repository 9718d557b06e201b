//! The running bridge: the zenoh session, the outgoing side on the calling thread (the local
//! topics' event loop, heartbeats, link state, health), the incoming side on a thread of its own
//! (zenoh's callbacks hand it frames through a channel; it runs the fault injector's delay line,
//! checks each frame's station and contract, publishes samples locally and follows the peer's
//! e-stop), and the fault-injection control socket.

use std::ffi::CString;
use std::os::unix::ffi::OsStrExt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use teleop_msgs::{EStop, CONTRACT_VERSION};
use teleop_runtime::link::LINK_DELAY_DETAIL;
use teleop_runtime::{
    control, latch_engaged, latch_holder, now_ns, qualified, release_latch_held_by, set_latch_by,
    EventLoop, Flow, Health, Input, IpcSettings, Namespace, NodeRuntime, Subscriber, Wake,
};
use zenoh::qos::{CongestionControl, Priority};
use zenoh::Wait;

use crate::config::{BridgeConfig, Direction, EStopRole, TopicConfig};
use crate::frame::{self, EStopState, Frame, Heartbeat, Origin};
use crate::link::{
    DelayLine, Faults, GapCounter, LatencyWindow, LinkState, PeerClock, PeerRun, SentBeats,
};
use crate::ports::{Arrival, MakeIn, MakeOut};

/// What the bridge is started with.
pub struct Options {
    /// The checked configuration.
    pub config: BridgeConfig,
    /// The iceoryx2 node name (the incoming side's node is `<name>-in`).
    pub name: String,
    /// A control socket for fault injection (`delay MS`, `loss PERCENT`, `clear`, `stats`).
    pub control: Option<PathBuf>,
}

/// State both sides read and write.
#[derive(Default)]
struct Shared {
    stop: AtomicBool,
    delay_ns: AtomicU64,
    loss_ppm: AtomicU32,
    /// When the newest accepted heartbeat arrived (local clock; 0: none).
    beat_recv_ns: AtomicU64,
    /// That heartbeat's send stamp (the peer's clock), echoed in ours.
    echo_send_ns: AtomicU64,
    rtt_ns: AtomicU64,
    offset_ns: AtomicI64,
    refused: AtomicBool,
    received: AtomicU64,
    stale: AtomicU64,
    /// Samples lost on the link (sequence gaps less what the sender superseded).
    gaps: AtomicU64,
    /// Samples the peer's bridge superseded (last value wins).
    superseded: AtomicU64,
    errors: AtomicU64,
    lost: AtomicU64,
    /// Frames dropped because the incoming queue or the delay line was full (also in `errors`).
    overflow: AtomicU64,
    /// The send stamps of the heartbeats sent: only their echoes make exchanges.
    sent_beats: Mutex<SentBeats>,
    latency: Mutex<Option<LatencyWindow>>,
    /// The link's measured one-way delay (the window's median, at most
    /// [`MAX_LINK_ALLOWANCE_NS`]) that `max_age_ms` allows for, updated with the health report
    /// and forgotten when the link goes down.
    allowance_ns: AtomicU64,
}

/// Most link delay a topic's `max_age_ms` allows for on top of itself.
const MAX_LINK_ALLOWANCE_NS: u64 = 1_000_000_000;

impl Shared {
    fn faults(&self) -> Faults {
        Faults {
            delay_ns: self.delay_ns.load(Ordering::Relaxed),
            loss_ppm: self.loss_ppm.load(Ordering::Relaxed),
        }
    }

    /// Forgets the link's measured delay: the window and the allowance it gave.
    fn forget_latency(&self) {
        if let Ok(mut window) = self.latency.lock() {
            if let Some(window) = window.as_mut() {
                window.clear();
            }
        }
        self.allowance_ns.store(0, Ordering::Relaxed);
    }

    fn percentiles(&self) -> Option<(u32, u32, u32)> {
        self.latency
            .lock()
            .ok()
            .and_then(|w| w.as_ref().and_then(LatencyWindow::percentiles))
    }
}

/// Frames waiting between zenoh's callbacks and the incoming side; more are dropped (counted).
const INBOX: usize = 256;

/// A frame from zenoh: which subscription, when, its bytes.
struct Received {
    slot: Slot,
    bytes: Vec<u8>,
}

#[derive(Clone, Copy)]
enum Slot {
    Topic(usize),
    Heartbeat,
}

/// The key of a topic sent by `station`: `teleop/<session>/<station>/<namespace>/<topic>`.
fn key(config: &BridgeConfig, station: &str, namespace: Option<&Namespace>, topic: &str) -> String {
    format!(
        "teleop/{}/{station}/{}",
        config.session,
        qualified(namespace, topic)
    )
}

const HEARTBEAT_TOPIC: &str = "_bridge/heartbeat";

/// Runs the bridge until SIGINT/SIGTERM.
pub fn run(options: Options) -> anyhow::Result<()> {
    let config = &options.config;
    let missing = config.missing_files();
    if !missing.is_empty() {
        let list: Vec<String> = missing
            .iter()
            .map(|(field, path)| format!("{field} = {}", path.display()))
            .collect();
        anyhow::bail!(
            "certificate files not found: {}; make them with `teleop certs` (README: two \
             machines)",
            list.join(", ")
        );
    }
    let settings = IpcSettings::from_env();
    let runtime = NodeRuntime::new(&options.name, &settings)?;
    if config.insecure {
        tracing::warn!(
            endpoints = ?config.listen.iter().chain(&config.connect).collect::<Vec<_>>(),
            "INSECURE: plain TCP without authentication or encryption; anyone who reaches these \
             endpoints can send hand commands (insecure = true in the bridge configuration)"
        );
    }
    let zenoh_config = config.zenoh().map_err(|e| anyhow::anyhow!(e))?;
    let session = zenoh::open(zenoh_config)
        .wait()
        .map_err(|e| anyhow::anyhow!("opening the zenoh session: {e}"))?;
    tracing::info!(
        station = %config.station,
        peer = %config.peer,
        listen = ?config.listen,
        connect = ?config.connect,
        tls = config.tls.is_some(),
        "zenoh session open (peer to peer, no scouting)"
    );

    let namespace = runtime.namespace().cloned();
    let shared = Arc::new(Shared::default());
    if let Some(path) = &options.control {
        let shared = Arc::clone(&shared);
        control::spawn(path, move |line| answer(&shared, line))?;
    }
    let ins: Vec<TopicConfig> = config
        .topic
        .iter()
        .filter(|t| t.direction == Direction::In)
        .cloned()
        .collect();
    let (tx, rx) = mpsc::sync_channel::<Received>(INBOX);
    let mut subscribers = Vec::new();
    let wanted = ins
        .iter()
        .enumerate()
        .map(|(i, t)| (Slot::Topic(i), t.name.as_str()))
        .chain([(Slot::Heartbeat, HEARTBEAT_TOPIC)]);
    for (slot, topic) in wanted {
        let key = key(config, &config.peer, namespace.as_ref(), topic);
        subscribers.push(subscribe(
            &session,
            key,
            slot,
            tx.clone(),
            Arc::clone(&shared),
        )?);
    }
    drop(tx);

    let incoming = {
        let shared = Arc::clone(&shared);
        let config = config.clone();
        let name = format!("{}-in", options.name);
        std::thread::Builder::new()
            .name("bridge-in".into())
            .spawn(move || {
                let result = incoming(&settings, &name, &config, &ins, &rx, &shared);
                shared.stop.store(true, Ordering::Relaxed);
                result
            })?
    };
    let result = outgoing(&runtime, config, namespace.as_ref(), &session, &shared);
    shared.stop.store(true, Ordering::Relaxed);
    drop(subscribers);
    let _ = session.close().wait();
    let incoming = incoming
        .join()
        .map_err(|_| anyhow::anyhow!("the incoming side panicked"))?;
    result.and(incoming)
}

/// Subscribes to `key`: each frame (at most [`frame::MAX_FRAME_LEN`] bytes; zenoh drops larger
/// messages, this is the second check) goes to `tx` unless [`INBOX`] frames wait there already
/// (then it is dropped and counted: a peer cannot queue without bound).
fn subscribe(
    session: &zenoh::Session,
    key: String,
    slot: Slot,
    tx: mpsc::SyncSender<Received>,
    shared: Arc<Shared>,
) -> anyhow::Result<zenoh::pubsub::Subscriber<()>> {
    session
        .declare_subscriber(key.clone())
        .callback(move |sample| {
            let payload = sample.payload();
            let full = if payload.len() > frame::MAX_FRAME_LEN {
                true
            } else {
                let bytes = payload.to_bytes().into_owned();
                matches!(
                    tx.try_send(Received { slot, bytes }),
                    Err(mpsc::TrySendError::Full(_))
                )
            };
            if full {
                shared.overflow.fetch_add(1, Ordering::Relaxed);
                shared.errors.fetch_add(1, Ordering::Relaxed);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))
}

/// The longest delay the fault injector takes.
const MAX_INJECTED_DELAY_MS: f64 = 10_000.0;

/// The control socket's answer to one command.
fn answer(shared: &Shared, line: &str) -> String {
    let mut words = line.split_whitespace();
    let number = |w: Option<&str>| w.and_then(|w| w.parse::<f64>().ok()).filter(|v| *v >= 0.0);
    match (words.next(), number(words.next())) {
        (Some("delay"), Some(ms)) if ms <= MAX_INJECTED_DELAY_MS => {
            shared.delay_ns.store((ms * 1e6) as u64, Ordering::Relaxed);
            tracing::warn!(ms, "fault injection: every received frame delayed");
            format!("ok delay {ms} ms")
        }
        (Some("loss"), Some(percent)) if percent <= 100.0 => {
            shared
                .loss_ppm
                .store((percent * 1e4) as u32, Ordering::Relaxed);
            tracing::warn!(percent, "fault injection: received frames lost at random");
            format!("ok loss {percent} %")
        }
        (Some("clear"), None) => {
            shared.delay_ns.store(0, Ordering::Relaxed);
            shared.loss_ppm.store(0, Ordering::Relaxed);
            tracing::info!("fault injection cleared");
            "ok clear".into()
        }
        (Some("stats"), None) => {
            let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
            let (p50, p99, max) = shared.percentiles().unwrap_or_default();
            format!(
                "ok received {} gaps {} superseded {} stale {} errors {} lost {} rtt_us {} one_way_us {p50} {p99} {max} overflow {}",
                load(&shared.received),
                load(&shared.gaps),
                load(&shared.superseded),
                load(&shared.stale),
                load(&shared.errors),
                load(&shared.lost),
                load(&shared.rtt_ns) / 1000,
                load(&shared.overflow),
            )
        }
        _ => format!(
            "error: commands are `delay MS` (0 to {MAX_INJECTED_DELAY_MS}), `loss PERCENT` (0 to \
             100), `clear`, `stats`"
        ),
    }
}

/// The outgoing side: local samples and heartbeats to the peer, link state, health.
fn outgoing(
    runtime: &NodeRuntime,
    config: &BridgeConfig,
    namespace: Option<&Namespace>,
    session: &zenoh::Session,
    shared: &Shared,
) -> anyhow::Result<()> {
    let fingerprint = crate::schema_fingerprint();
    let declare = |topic: &str| {
        let key = key(config, &config.station, namespace, topic);
        session
            .declare_publisher(key.clone())
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::RealTime)
            .express(true)
            .wait()
            .map_err(|e| anyhow::anyhow!("declaring the publisher {key}: {e}"))
    };
    let mut ports = Vec::new();
    let mut publishers = Vec::new();
    for topic in config
        .topic
        .iter()
        .filter(|t| t.direction == Direction::Out)
    {
        let port = teleop_msgs::visit_topic(&topic.name, MakeOut(runtime))
            .with_context(|| format!("topic {}", topic.name))??;
        ports.push(port);
        publishers.push(declare(&topic.name)?);
    }
    let heartbeat = declare(HEARTBEAT_TOPIC)?;
    let doorbell: Option<Subscriber<EStop>> = match config.estop {
        EStopRole::Send => Some(runtime.subscriber()?),
        _ => None,
    };
    let latch = CString::new(runtime.estop_latch().as_os_str().as_bytes())?;
    let mut health = Health::new(runtime)?;
    let mut buf = Vec::with_capacity(1024);
    let mut beat_seq = 0u64;
    let mut send_errors = 0u64;
    let mut state = LinkState::Down;
    let mut last_health = Instant::now();
    let mut last_report = Instant::now();
    let mut counted = (0u64, 0u64); // errors, stale already in health
    let mut refused_links = Vec::new();
    let timeout_ns = config.link_timeout_ms * 1_000_000;
    let origin = |now| Origin::new(&config.station, CONTRACT_VERSION, fingerprint, now);
    tracing::info!(
        out = ?ports.iter().map(|p| p.topic()).collect::<Vec<_>>(),
        "forwarding"
    );

    let mut send_beat = |buf: &mut Vec<u8>, send_errors: &mut u64| {
        beat_seq += 1;
        let now = now_ns();
        let echo = shared.echo_send_ns.load(Ordering::Relaxed);
        let received = shared.beat_recv_ns.load(Ordering::Relaxed);
        let estop = match config.estop {
            EStopRole::Send if latch_engaged(&latch) => EStopState::Engaged,
            EStopRole::Send => EStopState::Released,
            _ => EStopState::NotSent,
        };
        let beat = Heartbeat {
            seq: beat_seq,
            echo_send_ns: echo,
            hold_ns: if echo == 0 {
                0
            } else {
                now.saturating_sub(received)
            },
            estop,
        };
        frame::encode_heartbeat(buf, &origin(now), &beat);
        if let Ok(mut sent) = shared.sent_beats.lock() {
            sent.record(now);
        }
        if heartbeat.put(buf.as_slice()).wait().is_err() {
            *send_errors += 1;
        }
    };

    let mut inputs: Vec<Input<'_>> = ports.iter().map(|p| Input::new(p.listener())).collect();
    if let Some(doorbell) = &doorbell {
        inputs.push(Input::new(doorbell.listener()));
    }
    let stop = EventLoop::new(Duration::from_millis(config.heartbeat_ms)).run(&inputs, |wake| {
        match wake {
            Wake::Input(i) if i < ports.len() => {
                let publisher = &publishers[i];
                let mut sent = |payload: &[u8], superseded: u16| {
                    let mut origin = origin(now_ns());
                    origin.superseded = superseded;
                    frame::encode_sample(&mut buf, &origin, payload);
                    if publisher.put(buf.as_slice()).wait().is_err() {
                        send_errors += 1;
                    }
                };
                if ports[i].send_newest(&mut sent) {
                    health.count_loop();
                }
            }
            Wake::Input(_) => {
                // The e-stop's doorbell: tell the peer now, not at the next heartbeat.
                if let Some(doorbell) = &doorbell {
                    doorbell.drain(|_| {});
                }
                send_beat(&mut buf, &mut send_errors);
            }
            Wake::Timeout(_) | Wake::Tick => send_beat(&mut buf, &mut send_errors),
        }
        let now = now_ns();
        let received = shared.beat_recv_ns.load(Ordering::Relaxed);
        let new_state = if shared.refused.load(Ordering::Relaxed) {
            LinkState::Refused
        } else if received != 0 && now.saturating_sub(received) <= timeout_ns {
            LinkState::Up
        } else {
            LinkState::Down
        };
        if new_state != state {
            match new_state {
                LinkState::Up => tracing::info!(
                    peer = %config.peer,
                    rtt_us = shared.rtt_ns.load(Ordering::Relaxed) / 1000,
                    "link up"
                ),
                LinkState::Down => {
                    health.count_timeout();
                    // What arrives after the outage (a backlog, then the link as it is then)
                    // is measured afresh.
                    shared.forget_latency();
                    tracing::warn!(
                        peer = %config.peer,
                        timeout_ms = config.link_timeout_ms,
                        "link down: no heartbeat from the peer (its commands and states go \
                         stale: the hand holds, glove forces ramp to zero)"
                    );
                }
                LinkState::Refused => {
                    tracing::error!(peer = %config.peer, "link refused: the peer speaks another contract")
                }
            }
            state = new_state;
        }
        if last_health.elapsed() >= Duration::from_secs(1) {
            last_health = Instant::now();
            if config.tls.is_some() {
                audit_links(session, config, shared, &mut refused_links);
            }
            let errors = shared.errors.load(Ordering::Relaxed) + send_errors;
            let stale = shared.stale.load(Ordering::Relaxed);
            health.count_errors(errors - counted.0);
            for _ in counted.1..stale {
                health.count_timeout();
            }
            counted = (errors, stale);
            health.set_dropped(shared.gaps.load(Ordering::Relaxed));
            let ms = |ns: u64| ns as f64 / 1e6;
            health.set_detail("link_state", f64::from(state as u8));
            health.set_detail("rtt_ms", ms(shared.rtt_ns.load(Ordering::Relaxed)));
            let (p50, p99) = shared
                .percentiles()
                .map_or((0, 0), |(p50, p99, _)| (u64::from(p50) * 1000, u64::from(p99) * 1000));
            health.set_detail("latency_p99_ms", ms(p99));
            // The delay the nodes behind this bridge, and its own `max_age_ms`, allow for: the
            // median (the timeouts cover the jitter above it; a late backlog moves it only when
            // it is half the window).
            health.set_detail(LINK_DELAY_DETAIL, ms(p50));
            shared
                .allowance_ns
                .store(p50.min(MAX_LINK_ALLOWANCE_NS), Ordering::Relaxed);
            let since_beat = (received != 0).then(|| Duration::from_nanos(now.saturating_sub(received)));
            if let Err(e) = health.publish(&[since_beat]) {
                tracing::warn!("health: {e}");
            }
        }
        if last_report.elapsed() >= Duration::from_secs(config.report_s.max(1)) {
            last_report = Instant::now();
            let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
            let (p50, p99, max) = shared.percentiles().unwrap_or_default();
            tracing::info!(
                link = state.name(),
                peer = %config.peer,
                rtt_us = load(&shared.rtt_ns) / 1000,
                offset_us = shared.offset_ns.load(Ordering::Relaxed) / 1000,
                one_way_us = format!("p50 {p50} p99 {p99} max {max}"),
                received = load(&shared.received),
                gaps = load(&shared.gaps),
                superseded = load(&shared.superseded),
                stale = load(&shared.stale),
                errors = load(&shared.errors) + send_errors,
                injected_loss = load(&shared.lost),
                insecure = config.insecure,
                "link report"
            );
        }
        if shared.stop.load(Ordering::Relaxed) {
            Flow::Break(())
        } else {
            Flow::Continue(())
        }
    })?;
    tracing::info!(?stop, "stopped");
    Ok(())
}

/// Links reported as refused, remembered so that each is reported once.
const REFUSED_LINKS: usize = 64;

/// Each link whose peer certificate names another station than the configured peer is logged
/// once and counted in `errors`. zenoh's access control ([`BridgeConfig::access_control`])
/// already denies such a link every put on the peer's keys and sends it nothing; this makes the
/// attempt visible. (The name is the certificate's common name, as zenoh reads it from the QUIC
/// link: zenoh 1.10 `src/api/info.rs` `Link::auth_identifier`.)
fn audit_links(
    session: &zenoh::Session,
    config: &BridgeConfig,
    shared: &Shared,
    reported: &mut Vec<String>,
) {
    for link in session.info().links().wait() {
        let name = link.auth_identifier();
        if name == Some(config.peer.as_str()) {
            continue;
        }
        let id = format!("{} {}", link.zid(), link.dst());
        if reported.contains(&id) {
            continue;
        }
        if reported.len() == REFUSED_LINKS {
            reported.remove(0);
        }
        reported.push(id);
        shared.errors.fetch_add(1, Ordering::Relaxed);
        tracing::warn!(
            peer = %config.peer,
            link = %link.dst(),
            "refused a peer: its certificate names {:?}, only {:?} may be this station's peer \
             (zenoh's access control drops what it sends and sends it nothing)",
            name.unwrap_or("no station"),
            config.peer
        );
    }
}

/// Logs the first of a kind of refusal; the rest are counted and reported.
struct Once(bool);

impl Once {
    fn first(&mut self) -> bool {
        !core::mem::replace(&mut self.0, true)
    }
}

/// The incoming side: frames from the peer to local topics, heartbeats, the peer's e-stop.
fn incoming(
    settings: &IpcSettings,
    name: &str,
    config: &BridgeConfig,
    ins: &[TopicConfig],
    rx: &mpsc::Receiver<Received>,
    shared: &Shared,
) -> anyhow::Result<()> {
    let runtime = NodeRuntime::new(name, settings)?;
    let fingerprint = crate::schema_fingerprint();
    let mut ports = Vec::new();
    for topic in ins {
        ports.push(
            teleop_msgs::visit_topic(&topic.name, MakeIn(&runtime))
                .with_context(|| format!("topic {}", topic.name))??,
        );
    }
    let max_age: Vec<Option<u64>> = ins
        .iter()
        .map(|t| t.max_age_ms.map(|ms| ms * 1_000_000))
        .collect();
    let mut doorbell = match config.estop {
        EStopRole::Receive => Some(runtime.publisher::<EStop>()?),
        _ => None,
    };
    let latch = runtime.estop_latch().to_path_buf();
    let mut clock = PeerClock::new(config.clock);
    let mut gaps = vec![GapCounter::default(); ports.len()];
    let mut line = DelayLine::new(now_ns());
    let mut line_overflow = 0u64;
    let mut run = PeerRun::default();
    let mut stray_echo = Once(false);
    let mut stale_logged = vec![false; ports.len()];
    let (mut bad_frame, mut wrong_station, mut bad_payload) =
        (Once(false), Once(false), Once(false));
    let mut refused_by: Option<(u32, u64)> = None;
    *shared
        .latency
        .lock()
        .map_err(|_| anyhow::anyhow!("latency lock"))? = Some(LatencyWindow::new(4096));
    tracing::info!(
        r#in = ?ports.iter().map(|p| p.topic()).collect::<Vec<_>>(),
        "receiving"
    );
    while !shared.stop.load(Ordering::Relaxed) {
        let now = now_ns();
        let wait = line
            .next_due()
            .map_or(50_000_000, |due| due.saturating_sub(now))
            .min(50_000_000);
        match rx.recv_timeout(Duration::from_nanos(wait)) {
            Ok(r) => line.push(shared.faults(), now_ns(), r),
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
        while let Ok(r) = rx.try_recv() {
            line.push(shared.faults(), now_ns(), r);
        }
        shared.lost.store(line.lost, Ordering::Relaxed);
        if line.overflow > line_overflow {
            let more = line.overflow - line_overflow;
            line_overflow = line.overflow;
            shared.overflow.fetch_add(more, Ordering::Relaxed);
            shared.errors.fetch_add(more, Ordering::Relaxed);
        }
        let now = now_ns();
        while let Some(r) = line.pop_due(now) {
            let frame = match frame::decode(&r.bytes) {
                Ok(frame) => frame,
                Err(e) => {
                    shared.errors.fetch_add(1, Ordering::Relaxed);
                    if bad_frame.first() {
                        tracing::warn!(
                            "refused a frame from the peer's keys: {e} (further ones are counted)"
                        );
                    }
                    continue;
                }
            };
            let (Frame::Sample(origin, _) | Frame::Heartbeat(origin, _)) = frame;
            match frame::accept(&origin, &config.peer, CONTRACT_VERSION, fingerprint) {
                Ok(()) => {}
                Err(refusal @ frame::Refusal::Station { .. }) => {
                    shared.errors.fetch_add(1, Ordering::Relaxed);
                    if wrong_station.first() {
                        tracing::warn!("refused {refusal} (further ones are counted)");
                    }
                    continue;
                }
                Err(refusal @ frame::Refusal::Contract { .. }) => {
                    shared.errors.fetch_add(1, Ordering::Relaxed);
                    shared.refused.store(true, Ordering::Relaxed);
                    if refused_by != Some((origin.contract, origin.fingerprint)) {
                        refused_by = Some((origin.contract, origin.fingerprint));
                        tracing::error!("refusing the peer: {refusal}");
                    }
                    continue;
                }
            }
            if refused_by.take().is_some() {
                tracing::info!(peer = %config.peer, "the peer speaks this contract again");
            }
            shared.refused.store(false, Ordering::Relaxed);
            match (frame, r.slot) {
                (Frame::Heartbeat(origin, beat), Slot::Heartbeat) => {
                    if run.restarted(beat.seq) {
                        // Its clock may have restarted with it (another machine's reboot).
                        clock.restart();
                        shared.forget_latency();
                        tracing::info!(
                            peer = %config.peer,
                            "the peer's bridge restarted: its clock is estimated afresh"
                        );
                    }
                    let echoed = shared
                        .sent_beats
                        .lock()
                        .is_ok_and(|sent| sent.contains(beat.echo_send_ns));
                    if echoed {
                        clock.exchange(beat.echo_send_ns, beat.hold_ns, origin.send_ns, now);
                    } else if beat.echo_send_ns != 0 && stray_echo.first() {
                        tracing::warn!(
                            peer = %config.peer,
                            "a heartbeat echoes a stamp this bridge did not send (or sent before \
                             it started, or over {} heartbeats ago): no clock exchange from it \
                             (further ones are ignored silently)",
                            crate::link::SENT_WINDOW
                        );
                    }
                    shared
                        .rtt_ns
                        .store(clock.rtt_ns().unwrap_or(0), Ordering::Relaxed);
                    shared.offset_ns.store(clock.offset_ns(), Ordering::Relaxed);
                    shared.echo_send_ns.store(origin.send_ns, Ordering::Relaxed);
                    shared.beat_recv_ns.store(now, Ordering::Relaxed);
                    if let Some(doorbell) = &mut doorbell {
                        follow_estop(beat.estop, &latch, doorbell, &config.peer)?;
                    }
                }
                (Frame::Sample(origin, payload), Slot::Topic(i)) => {
                    // Every frame's transit counts toward the link's delay, also one too old to
                    // publish: a link slower than `max_age_ms` is measured, and then allowed for.
                    // Only once a heartbeat exchange has set the clock: before, the peer's stamps
                    // cannot be read on this clock.
                    let one_way = now.saturating_sub(clock.to_local(origin.send_ns));
                    if let (Some(_), Ok(mut window)) = (clock.rtt_ns(), shared.latency.lock()) {
                        if let Some(window) = window.as_mut() {
                            window.push(u32::try_from(one_way / 1000).unwrap_or(u32::MAX));
                        }
                    }
                    // Older on arrival than the topic's limit plus the link's measured delay:
                    // not published. Delayed but continuing samples go through; the subscribers
                    // judge their freshness against the same delay (the bridge's health).
                    let allowance = shared.allowance_ns.load(Ordering::Relaxed);
                    let max_age = max_age[i].map(|age| age.saturating_add(allowance));
                    match ports[i].publish(payload, &clock, now, max_age) {
                        Ok(Arrival::Published(header)) => {
                            stale_logged[i] = false;
                            shared.received.fetch_add(1, Ordering::Relaxed);
                            // Samples the sender superseded are not losses of the link.
                            let gap = gaps[i].count(header.source_id, header.seq);
                            shared.gaps.fetch_add(
                                gap.saturating_sub(u64::from(origin.superseded)),
                                Ordering::Relaxed,
                            );
                            shared
                                .superseded
                                .fetch_add(u64::from(origin.superseded), Ordering::Relaxed);
                        }
                        Ok(Arrival::Stale(_, age)) => {
                            shared.stale.fetch_add(1, Ordering::Relaxed);
                            if !core::mem::replace(&mut stale_logged[i], true) {
                                tracing::warn!(
                                    topic = ports[i].topic(),
                                    age_ms = age / 1_000_000,
                                    max_age_ms = max_age.unwrap_or(0) / 1_000_000,
                                    "samples arrive too old: not published (counted)"
                                );
                            }
                        }
                        Err(e) => {
                            shared.errors.fetch_add(1, Ordering::Relaxed);
                            if bad_payload.first() {
                                tracing::warn!("refused a sample: {e} (further ones are counted)");
                            }
                        }
                    }
                }
                _ => {
                    shared.errors.fetch_add(1, Ordering::Relaxed);
                    if bad_frame.first() {
                        tracing::warn!(
                            "a frame of the wrong kind on a key (further ones are counted)"
                        );
                    }
                }
            }
        }
    }
    Ok(())
}

/// Who the robot station's bridge says engaged its latch (in the latch file).
const LATCH_HOLDER: &str = "teleop-bridge for the peer station's e-stop";

/// The robot side of the e-stop: the operator's latch engaged engages this station's latch (if
/// it is not engaged already) and rings its doorbell; released releases this station's latch
/// only while it is still the one a bridge engaged (the file says so: a `teleop estop` on this
/// station since then stays, and a restarted bridge still releases what it engaged before).
fn follow_estop(
    peer: EStopState,
    latch: &std::path::Path,
    doorbell: &mut teleop_runtime::Publisher<EStop>,
    peer_name: &str,
) -> anyhow::Result<()> {
    let ring = |doorbell: &mut teleop_runtime::Publisher<EStop>, engaged: bool| {
        doorbell.publish(&EStop {
            engaged: u8::from(engaged),
            ..Default::default()
        })
    };
    let holder = latch_holder(latch);
    match peer {
        EStopState::Engaged if holder.is_none() && !latch.exists() => {
            set_latch_by(latch, true, LATCH_HOLDER)
                .with_context(|| format!("engaging the e-stop latch {}", latch.display()))?;
            ring(doorbell, true)?;
            tracing::warn!(station = peer_name, "e-stop engaged by the peer station");
        }
        EStopState::Released if holder.is_some_and(|h| h.contains(LATCH_HOLDER)) => {
            // Checked again under the latch lock: a `teleop estop` engaged since the read above
            // is not removed.
            let released = release_latch_held_by(latch, LATCH_HOLDER)
                .with_context(|| format!("releasing the e-stop latch {}", latch.display()))?;
            if released {
                ring(doorbell, false)?;
                tracing::info!(station = peer_name, "e-stop released by the peer station");
            }
        }
        _ => {}
    }
    Ok(())
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_control_socket_takes_faults_in_range_and_refuses_the_rest() {
        let shared = Shared::default();
        assert_eq!(answer(&shared, "delay 20"), "ok delay 20 ms");
        assert_eq!(shared.faults().delay_ns, 20_000_000);
        assert_eq!(answer(&shared, "loss 12.5"), "ok loss 12.5 %");
        assert_eq!(shared.faults().loss_ppm, 125_000);
        for bad in [
            "delay 1e30",
            "delay -1",
            "delay nan",
            "loss 101",
            "loss",
            "jam 3",
            "",
        ] {
            assert!(answer(&shared, bad).starts_with("error: "), "{bad}");
        }
        assert_eq!(
            shared.faults().delay_ns,
            20_000_000,
            "refusals change nothing"
        );
        assert_eq!(answer(&shared, "clear"), "ok clear");
        assert_eq!(shared.faults(), Faults::default());
        assert!(answer(&shared, "stats").starts_with("ok received 0 gaps 0 superseded 0"));
    }

    /// Two zenoh sessions over TCP on the loopback, as the bridges configure them: the robot's
    /// listening, the operator's connected.
    fn sessions(name: &str) -> (zenoh::Session, zenoh::Session) {
        let robot = format!(
            "station = \"robot\"\npeer = \"operator\"\nsession = \"{name}\"\n\
             listen = [\"tcp/127.0.0.1:0\"]\ninsecure = true\n"
        );
        let robot = BridgeConfig::parse(&robot, "robot.toml").unwrap();
        let robot = zenoh::open(robot.zenoh().unwrap()).wait().unwrap();
        let locator = robot.info().locators().wait()[0].to_string();
        let operator = format!(
            "station = \"operator\"\npeer = \"robot\"\nsession = \"{name}\"\n\
             connect = [\"{locator}\"]\ninsecure = true\n"
        );
        let operator = BridgeConfig::parse(&operator, "operator.toml").unwrap();
        (
            robot,
            zenoh::open(operator.zenoh().unwrap()).wait().unwrap(),
        )
    }

    #[test]
    fn a_peer_cannot_queue_frames_without_bound_nor_send_huge_ones() {
        let (robot, operator) = sessions("inbox");
        let key = "teleop/inbox/operator/hand/command";
        let shared = Arc::new(Shared::default());
        let (tx, rx) = mpsc::sync_channel(INBOX);
        let _sub = subscribe(&robot, key.into(), Slot::Topic(0), tx, Arc::clone(&shared)).unwrap();
        let publisher = operator
            .declare_publisher(key)
            .congestion_control(CongestionControl::Block)
            .wait()
            .unwrap();
        let start = Instant::now();
        // Once the subscription is known at the operator's end, frames arrive.
        while rx.try_recv().is_err() {
            assert!(start.elapsed() < Duration::from_secs(20), "nothing arrives");
            publisher.put(vec![1u8; 8]).wait().unwrap();
            std::thread::sleep(Duration::from_millis(20));
        }
        while rx.try_recv().is_ok() {}
        // Nobody takes them: the queue fills, the rest are dropped and counted.
        const FLOOD: usize = 1000;
        const { assert!(FLOOD > INBOX) };
        for _ in 0..FLOOD {
            publisher.put(vec![2u8; 8]).wait().unwrap();
        }
        while shared.overflow.load(Ordering::Relaxed) == 0 {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "no overflow counted"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        std::thread::sleep(Duration::from_millis(200));
        let queued = rx.try_iter().count();
        assert_eq!(queued, INBOX);
        assert_eq!(
            shared.errors.load(Ordering::Relaxed),
            shared.overflow.load(Ordering::Relaxed)
        );
        // A frame longer than any frame of ours never arrives; the link stays.
        publisher
            .put(vec![3u8; frame::MAX_FRAME_LEN + 1])
            .wait()
            .unwrap();
        publisher.put(vec![4u8; 8]).wait().unwrap();
        let mut got = Vec::new();
        while !got.contains(&4) {
            assert!(
                start.elapsed() < Duration::from_secs(20),
                "the link is gone"
            );
            if let Ok(r) = rx.recv_timeout(Duration::from_millis(100)) {
                assert!(
                    r.bytes.len() <= frame::MAX_FRAME_LEN,
                    "a huge frame arrived"
                );
                got.push(r.bytes[0]);
            }
        }
        assert!(!got.contains(&3));
    }
}
