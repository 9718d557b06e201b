//! The console's live gathering: on a thread of its own, subscribes to every topic of every side
//! (as `teleop stats` does: [`inspect::probes`], woken by each sample so that the transport
//! latency is measured when a sample arrives), keeps each node's newest health report and
//! acknowledgement, reads the e-stop latches and the iceoryx2 node list, and hands a [`Screen`]
//! to the console every [`REFRESH`]; without `--namespace` it looks for sides that started
//! since every [`REDISCOVER`]. Only subscribes: its subscribers, like every one of the
//! runtime's, overwrite their oldest sample when behind, so it never holds a publisher up.

use std::collections::BTreeMap;
use std::ffi::CString;
use std::os::unix::ffi::OsStrExt;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    device_model, force_flags, EStopAck, GloveForceCommand, GloveState, HandState, NodeHealth,
    Tactile,
};
use teleop_runtime::link::LINK_NODE;
use teleop_runtime::{
    discover_namespaces, latch_engaged, latch_path, latched_namespaces, now_ns, EventLoop, Flow,
    Input, IpcSettings, Namespace, NodeRuntime, Subscriber, Wake,
};

use super::screen::{EStopView, HandView, HealthLine, LinkView, NodeLine, RecorderView, Screen};
use crate::inspect::{self, newest, Probe};

/// How often the console is given a new screen.
pub const REFRESH: Duration = Duration::from_millis(250);
/// How often the namespaces in use are looked for again (without `--namespace`): a side that
/// starts after the console is shown from then on.
const REDISCOVER: Duration = Duration::from_secs(2);
/// The sliding window topic rates and latencies are measured over.
pub const WINDOW: Duration = Duration::from_secs(2);
/// The console's iceoryx2 node; nodes named `teleop-...` (the commands' short-lived ones) are
/// not listed as the session's.
const NODE: &str = "teleop-top";
/// The recorder's node name (in a namespace, `<ns>/recorder`).
const RECORDER: &str = "recorder";

/// With no new screen from the gathering for this long, the screen says its values are old.
pub const STALE_AFTER: Duration = Duration::from_secs(1);
/// How long after a failure the gathering is started again.
pub const RESTART_AFTER: Duration = Duration::from_secs(1);
/// How long dropping a [`Gatherer`] waits for its thread to end; a thread stuck longer (in
/// iceoryx2) is left to end with the process.
const JOIN_WAIT: Duration = Duration::from_millis(500);

/// What the gathering tells the console.
pub enum Update {
    /// It subscribed to every side: screens follow.
    Ready,
    /// What to show now.
    Screen(Box<Screen>),
    /// The gathering failed (at its start or later) and ended.
    Failed(String),
}

/// The gathering thread, seen from the console. SIGINT and SIGTERM end the gathering's loop
/// too; the console reads them itself (`teleop_runtime::stop_signal`).
pub struct Gatherer {
    /// [`Update::Ready`] or [`Update::Failed`] first, then a new screen every [`REFRESH`], or
    /// why the gathering ended.
    pub updates: Receiver<Update>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Gatherer {
    /// Starts gathering the namespaces `given`, or else the topics without a namespace and every
    /// namespace in use; returns once it subscribed (or could not).
    pub fn start(ipc: &IpcSettings, given: &[Namespace]) -> anyhow::Result<Self> {
        let gatherer = Self::spawn(ipc, given)?;
        match gatherer.updates.recv() {
            Ok(Update::Ready | Update::Screen(_)) => Ok(gatherer),
            Ok(Update::Failed(e)) => Err(anyhow::anyhow!(e)),
            Err(_) => Err(anyhow::anyhow!(
                "the console's gathering thread ended at its start"
            )),
        }
    }

    /// Starts gathering as [`Gatherer::start`] does, without waiting: whether it could subscribe
    /// comes as the first [`Update`].
    pub fn spawn(ipc: &IpcSettings, given: &[Namespace]) -> std::io::Result<Self> {
        let (tx, updates) = sync_channel(2);
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (ipc, given, stop) = (ipc.clone(), given.to_vec(), stop.clone());
            std::thread::Builder::new()
                .name("top-gather".into())
                .spawn(move || gather(&ipc, &given, &stop, &tx))?
        };
        Ok(Self {
            updates,
            stop,
            thread: Some(thread),
        })
    }
}

/// The gathering as the console's loop keeps it, never waiting for it: started again
/// [`RESTART_AFTER`] a failure, and stale when no screen came for [`STALE_AFTER`].
pub struct Gathering {
    gatherer: Option<Gatherer>,
    /// Why it failed, until a screen comes again.
    pub failed: Option<String>,
    restart_at: Instant,
    last_screen: Instant,
}

impl Gathering {
    /// The gathering of `gatherer`, started at `now`.
    pub fn new(gatherer: Gatherer, now: Instant) -> Self {
        Self {
            gatherer: Some(gatherer),
            failed: None,
            restart_at: now,
            last_screen: now,
        }
    }

    /// Takes what the gathering sent without waiting: the newest screen, if one came, and whether
    /// anything else changed (it failed or was started again). After a failure, at
    /// [`RESTART_AFTER`], it starts a new gathering with `spawn`.
    pub fn poll(
        &mut self,
        now: Instant,
        spawn: impl FnOnce() -> std::io::Result<Gatherer>,
    ) -> (Option<Screen>, bool) {
        let Some(gatherer) = &self.gatherer else {
            if now < self.restart_at {
                return (None, false);
            }
            match spawn() {
                Ok(g) => self.gatherer = Some(g),
                Err(e) => self.failed = Some(format!("cannot start the gathering: {e}")),
            }
            self.restart_at = now + RESTART_AFTER;
            return (None, true);
        };
        let mut newest = None;
        let failed = loop {
            match gatherer.updates.try_recv() {
                Ok(Update::Ready) => {}
                Ok(Update::Screen(screen)) => newest = Some(*screen),
                Ok(Update::Failed(e)) => break Some(e),
                Err(TryRecvError::Empty) => break None,
                Err(TryRecvError::Disconnected) => break Some("the gathering thread ended".into()),
            }
        };
        if newest.is_some() {
            self.last_screen = now;
            self.failed = None;
        }
        let changed = failed.is_some();
        if let Some(e) = failed {
            self.failed = Some(e);
            self.gatherer = None;
            self.restart_at = now + RESTART_AFTER;
        }
        (newest, changed)
    }

    /// Whole seconds without a new screen at `now`, once that is [`STALE_AFTER`] or more.
    pub fn stale_s(&self, now: Instant) -> Option<u64> {
        let since = now.saturating_duration_since(self.last_screen);
        (since >= STALE_AFTER).then_some(since.as_secs())
    }
}

impl Drop for Gatherer {
    /// Asks the thread to stop and waits at most [`JOIN_WAIT`] for it: a gathering stuck in
    /// iceoryx2 never keeps the console from quitting.
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let Some(thread) = self.thread.take() else {
            return;
        };
        let deadline = Instant::now() + JOIN_WAIT;
        while !thread.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        if thread.is_finished() {
            // A gathering that panicked has said so on stderr; nothing more to do here.
            let _ = thread.join();
        }
    }
}

/// One side looked at.
struct Side {
    namespace: Option<Namespace>,
    probes: Vec<Box<dyn Probe>>,
    health: Subscriber<NodeHealth>,
    acks: Subscriber<EStopAck>,
}

/// What the gathering remembers between refreshes.
#[derive(Default)]
struct Memory {
    /// Each node's newest health report and when it came (`now_ns`).
    health: BTreeMap<String, (NodeHealth, u64)>,
    /// Each node's newest e-stop acknowledgement: engaged.
    acks: BTreeMap<String, bool>,
    /// Each node's process id when last seen alive, and the restarts seen.
    pids: BTreeMap<String, (String, u32)>,
    /// Tactile fingertip names by hand model (from its shipped profile).
    tips: BTreeMap<u8, Vec<String>>,
}

fn gather(ipc: &IpcSettings, given: &[Namespace], stop: &AtomicBool, updates: &SyncSender<Update>) {
    let opened = (|| -> anyhow::Result<(NodeRuntime, Vec<Side>)> {
        let runtime = NodeRuntime::new(NODE, ipc)?;
        let mut sides = Vec::new();
        for namespace in inspect::covered(ipc, given)? {
            sides.push(Side::open(&runtime, namespace)?);
        }
        Ok((runtime, sides))
    })();
    let (runtime, mut sides) = match opened {
        Ok(opened) => opened,
        Err(e) => {
            let _ = updates.send(Update::Failed(format!("{e:#}")));
            return;
        }
    };
    if updates.send(Update::Ready).is_err() {
        return;
    }
    let mut memory = Memory::default();
    let started = Instant::now();
    let mut last = Instant::now();
    loop {
        let rediscover_at = Instant::now() + REDISCOVER;
        // Input i: per side its probes, then its health, then its acknowledgements.
        let mut inputs = Vec::new();
        let mut which = Vec::new();
        for (s, side) in sides.iter().enumerate() {
            for (p, probe) in side.probes.iter().enumerate() {
                inputs.push(Input::new(probe.listener()));
                which.push((s, Some(p)));
            }
            inputs.push(Input::new(side.health.listener()));
            which.push((s, None));
            inputs.push(Input::new(side.acks.listener()));
            which.push((s, None));
        }
        let mut failure = None;
        let result = EventLoop::new(Duration::from_millis(50)).run(&inputs, |wake| {
            if let Wake::Input(i) = wake {
                match which.get(i) {
                    Some(&(s, Some(p))) => sides[s].probes[p].drain(),
                    Some(&(s, None)) => take_reports(&sides[s], &mut memory),
                    None => {}
                }
            }
            if stop.load(Ordering::Relaxed) {
                return Flow::Break(());
            }
            if last.elapsed() >= REFRESH {
                last = Instant::now();
                for side in &sides {
                    take_reports(side, &mut memory);
                }
                match snapshot(ipc, &sides, &mut memory, started.elapsed().min(WINDOW)) {
                    // While the console has not taken the screens before (it is busy), this
                    // one is left out: the next refresh brings a newer one.
                    Ok(screen) => {
                        let _ = updates.try_send(Update::Screen(Box::new(screen)));
                    }
                    Err(e) => {
                        failure = Some(format!("{e:#}"));
                        return Flow::Break(());
                    }
                }
            }
            if given.is_empty() && Instant::now() >= rediscover_at {
                return Flow::Break(());
            }
            Flow::Continue(())
        });
        let why = match (result, failure) {
            (_, Some(failure)) => failure,
            (Ok(teleop_runtime::StopReason::Requested), None) if stop.load(Ordering::Relaxed) => {
                return
            }
            (Ok(teleop_runtime::StopReason::Requested), None) => {
                drop(inputs);
                // Sides that started since: looked at from now on.
                match add_new_sides(&runtime, ipc, &mut sides) {
                    Ok(()) => continue,
                    Err(e) => format!("{e:#}"),
                }
            }
            // SIGINT or SIGTERM: the console reads it and ends.
            (Ok(_signal), None) => return,
            (Err(e), None) => format!("{e:#}"),
        };
        let _ = updates.send(Update::Failed(why));
        return;
    }
}

impl Side {
    /// Subscribes to every topic of `namespace`.
    fn open(runtime: &NodeRuntime, namespace: Option<Namespace>) -> anyhow::Result<Self> {
        Ok(Self {
            probes: inspect::probes(runtime, namespace.as_ref())?,
            health: runtime.subscriber_in(namespace.as_ref())?,
            acks: runtime.subscriber_in(namespace.as_ref())?,
            namespace,
        })
    }
}

/// Adds a side for each namespace in use that has none yet.
fn add_new_sides(
    runtime: &NodeRuntime,
    ipc: &IpcSettings,
    sides: &mut Vec<Side>,
) -> anyhow::Result<()> {
    for namespace in discover_namespaces(ipc)? {
        if !sides
            .iter()
            .any(|s| s.namespace.as_ref() == Some(&namespace))
        {
            sides.push(Side::open(runtime, Some(namespace))?);
        }
    }
    Ok(())
}

/// Takes a side's queued health reports and acknowledgements into `memory`.
fn take_reports(side: &Side, memory: &mut Memory) {
    let now = now_ns();
    side.health.drain(|h| {
        memory.health.insert(h.name(), (*h, now));
    });
    side.acks.drain(|a| {
        memory
            .acks
            .insert(teleop_msgs::text_of(&a.node_name), a.engaged != 0);
    });
}

/// The screen from what was gathered, at `window` of topic measurements.
fn snapshot(
    ipc: &IpcSettings,
    sides: &[Side],
    memory: &mut Memory,
    window: Duration,
) -> anyhow::Result<Screen> {
    let now = now_ns();
    let age = |stamp_ns: u64| now.saturating_sub(stamp_ns) as f64 / 1e9;
    let mut screen = Screen {
        window_s: window.as_secs_f64(),
        ..Default::default()
    };
    let window_start = now.saturating_sub(WINDOW.as_nanos() as u64);
    for side in sides {
        let name = inspect::shown(side.namespace.as_ref()).to_string();
        screen.sides.push(name.clone());
        let mut hand = HandView {
            side: name,
            ..Default::default()
        };
        for probe in &side.probes {
            probe.forget_before(window_start);
            let summary = probe.summary(window);
            if summary.samples > 0 || summary.drops > 0 {
                screen.topics.push(summary);
            }
            let probe = probe.as_ref();
            if let Some(g) = newest::<GloveState>(probe) {
                hand.glove = Some((g.position, age(g.header.stamp_ns)));
            }
            if let Some(f) = newest::<GloveForceCommand>(probe) {
                let estop = f.flags & force_flags::ESTOP != 0;
                hand.force = Some((f.force, estop, age(f.header.stamp_ns)));
            }
            if let Some(t) = newest::<Tactile>(probe) {
                let names = memory.tips.entry(t.hand_model).or_insert_with(|| {
                    HandProfile::builtin_for_model(t.hand_model)
                        .map(|p| p.fingertips().map(|f| f.name.clone()).collect())
                        .unwrap_or_default()
                });
                let tips = t
                    .active_fingertips()
                    .iter()
                    .enumerate()
                    .map(|(i, tip)| {
                        let name = names.get(i).cloned().unwrap_or_else(|| format!("tip{i}"));
                        (name, tip.normal_n)
                    })
                    .collect();
                hand.tactile = Some((tips, age(t.header.stamp_ns)));
            }
            if let Some(s) = newest::<HandState>(probe) {
                hand.hand = Some((
                    device_model::name(s.hand_model).to_string(),
                    s.link_up == 1,
                    s.holding == 1,
                    age(s.header.stamp_ns),
                ));
            }
        }
        if hand.glove.is_some() || hand.force.is_some() || hand.hand.is_some() {
            screen.hands.push(hand);
        }
    }
    screen.estop = estop_view(ipc, sides, memory);
    screen.nodes = node_lines(ipc, memory, now)?;
    for (name, (h, received)) in &memory.health {
        let age_s = age(teleop_runtime::sample_time(h.header.stamp_ns, *received));
        let base = name.rsplit('/').next().unwrap_or(name);
        if base == LINK_NODE {
            screen.links.push(LinkView {
                node: name.clone(),
                // The bridge's `LinkState` numbers (teleop-bridge's link module).
                state: match h.detail("link_state").map(|v| v.round() as i64) {
                    Some(0) => "down",
                    Some(1) => "up",
                    Some(2) => "refused",
                    _ => "unknown",
                },
                rtt_ms: h.detail("rtt_ms"),
                latency_p99_ms: h.detail("latency_p99_ms"),
                age_s,
            });
        }
        if base == RECORDER {
            screen.recorders.push(RecorderView {
                node: name.clone(),
                episode: crate::episode::describe(h),
                dropped: h.dropped,
                age_s,
            });
        }
    }
    Ok(screen)
}

/// The e-stop as the latches of the sides (and of any namespace latched) and the nodes'
/// newest acknowledgements say.
fn estop_view(ipc: &IpcSettings, sides: &[Side], memory: &Memory) -> EStopView {
    let mut namespaces: Vec<Option<Namespace>> = vec![None];
    namespaces.extend(sides.iter().filter_map(|s| s.namespace.clone()).map(Some));
    namespaces.extend(latched_namespaces(ipc).into_iter().map(Some));
    namespaces.dedup();
    let mut view = EStopView::default();
    for ns in namespaces {
        let path = latch_path(ipc, ns.as_ref());
        // A path that cannot be made a C string cannot be read either: engaged (fail safe).
        let engaged =
            CString::new(path.as_os_str().as_bytes()).map_or(true, |path| latch_engaged(&path));
        let shown = inspect::shown(ns.as_ref()).to_string();
        if engaged && !view.latched.contains(&shown) {
            view.latched.push(shown);
        }
    }
    for (node, engaged) in &memory.acks {
        if *engaged {
            view.held_by.push(node.clone());
        } else {
            view.released_by.push(node.clone());
        }
    }
    view
}

/// The session's nodes: iceoryx2's list (but the commands' own `teleop-...` nodes) and every
/// node that sent a health report, with its newest report; restarts counted as process ids
/// that changed.
fn node_lines(ipc: &IpcSettings, memory: &mut Memory, now: u64) -> anyhow::Result<Vec<NodeLine>> {
    let mut lines: BTreeMap<String, NodeLine> = BTreeMap::new();
    for row in inspect::node_rows(ipc)? {
        if row.name.starts_with("teleop-") || row.name == "?" {
            continue;
        }
        let line = lines.entry(row.name.clone()).or_insert_with(|| NodeLine {
            name: row.name.clone(),
            status: row.status.to_string(),
            ..Default::default()
        });
        // A restarted node may be listed twice for a while: alive wins.
        if row.status == "alive" {
            line.status = row.status.to_string();
            let seen = memory
                .pids
                .entry(row.name.clone())
                .or_insert_with(|| (row.pid.clone(), 0));
            if seen.0 != row.pid {
                *seen = (row.pid.clone(), seen.1 + 1);
            }
        }
    }
    for (name, (h, received)) in &memory.health {
        let line = lines.entry(name.clone()).or_insert_with(|| NodeLine {
            name: name.clone(),
            status: "-".into(),
            ..Default::default()
        });
        let details: Vec<String> = h
            .details()
            .map(|(name, value)| format!("{name}={value:.4}"))
            .map(|s| trim_zeros(&s))
            .collect();
        line.health = Some(HealthLine {
            age_s: now.saturating_sub(teleop_runtime::sample_time(h.header.stamp_ns, *received))
                as f64
                / 1e9,
            loop_rate_hz: h.loop_rate_hz,
            input_ages_ms: h.input_age_ms[..usize::from(h.input_count).min(5)].to_vec(),
            timeouts: h.timeouts,
            errors: h.errors,
            details: details.join(" "),
        });
    }
    for line in lines.values_mut() {
        line.restarts = memory.pids.get(&line.name).map_or(0, |p| p.1);
    }
    Ok(lines.into_values().collect())
}

/// `1.2500` as `1.25`, `3.0000` as `3`.
fn trim_zeros(s: &str) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A gatherer without a thread, fed by the test.
    fn fed() -> (SyncSender<Update>, Gatherer) {
        let (tx, updates) = sync_channel(4);
        let gatherer = Gatherer {
            updates,
            stop: Arc::default(),
            thread: None,
        };
        (tx, gatherer)
    }

    #[test]
    fn a_failed_gathering_is_shown_and_started_again() {
        let t0 = Instant::now();
        let never = || -> std::io::Result<Gatherer> { panic!("started again too early") };
        let (tx, gatherer) = fed();
        let mut gathering = Gathering::new(gatherer, t0);
        tx.send(Update::Ready).unwrap();
        tx.send(Update::Screen(Box::default())).unwrap();
        let (screen, changed) = gathering.poll(t0, never);
        assert!(screen.is_some() && !changed);
        tx.send(Update::Failed("no such service".into())).unwrap();
        let failed_at = t0 + Duration::from_millis(10);
        let (screen, changed) = gathering.poll(failed_at, never);
        assert!(screen.is_none() && changed);
        assert_eq!(gathering.failed.as_deref(), Some("no such service"));
        let (screen, changed) = gathering.poll(failed_at + RESTART_AFTER / 2, never);
        assert!(screen.is_none() && !changed);
        // Started again; the failure stays shown until a screen comes.
        let (tx, gatherer) = fed();
        let (_, changed) = gathering.poll(failed_at + RESTART_AFTER, || Ok(gatherer));
        assert!(changed && gathering.failed.is_some());
        tx.send(Update::Screen(Box::default())).unwrap();
        let (screen, _) = gathering.poll(failed_at + RESTART_AFTER, never);
        assert!(screen.is_some() && gathering.failed.is_none());
        // A gathering thread that ended (a panic) counts as a failure.
        drop(tx);
        let (_, changed) = gathering.poll(failed_at + RESTART_AFTER, never);
        assert!(changed);
        assert_eq!(
            gathering.failed.as_deref(),
            Some("the gathering thread ended")
        );
    }

    #[test]
    fn no_screen_for_a_second_is_stale() {
        let t0 = Instant::now();
        let (tx, gatherer) = fed();
        let mut gathering = Gathering::new(gatherer, t0);
        assert_eq!(gathering.stale_s(t0 + Duration::from_millis(999)), None);
        assert_eq!(gathering.stale_s(t0 + STALE_AFTER), Some(1));
        assert_eq!(gathering.stale_s(t0 + Duration::from_millis(7300)), Some(7));
        tx.send(Update::Screen(Box::default())).unwrap();
        let later = t0 + Duration::from_secs(8);
        gathering.poll(later, || panic!("not failed"));
        assert_eq!(gathering.stale_s(later + Duration::from_millis(500)), None);
    }

    #[test]
    fn details_lose_their_trailing_zeros() {
        assert_eq!(trim_zeros("rtt_ms=1.2500"), "rtt_ms=1.25");
        assert_eq!(trim_zeros("link_state=1.0000"), "link_state=1");
        assert_eq!(trim_zeros("x=10"), "x=10");
    }
}
