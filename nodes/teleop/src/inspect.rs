//! `teleop nodes | topics | echo | stats | estop`: look into and steer a running pipeline.
//!
//! Each takes `--namespace NS` (repeatable) to look at some sides only; without it `topics`,
//! `stats` and `estop` cover the topics without a namespace and every namespace in use
//! ([`discover_namespaces`]), and `nodes` lists every node. `echo` reads one topic, of the
//! namespace given or named in the topic (`left/hand/command`).

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;
use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::CallbackProgression;
use teleop_hand_profile::HandProfile;
use teleop_msgs::{text_of, visit_topic, EStop, EStopAck, Message, NodeHealth, TopicVisitor};
use teleop_runtime::{
    discover_namespaces, latch_path, latched_namespaces, now_ns, qualified, set_latch, split,
    EventLoop, Flow, Input, IpcSettings, Namespace, NodeRuntime, Service, StopReason, Subscriber,
    Wake,
};

use crate::echo::{Echo, Format};

/// Name of the short-lived iceoryx2 node the inspection commands create.
const CLI_NODE: &str = "teleop-cli";

/// The namespaces a command covers: those given, or the topics without a namespace (`None`)
/// and every namespace in use.
pub(crate) fn covered(
    ipc: &IpcSettings,
    given: &[Namespace],
) -> anyhow::Result<Vec<Option<Namespace>>> {
    if !given.is_empty() {
        return Ok(given.iter().cloned().map(Some).collect());
    }
    let mut all = vec![None];
    all.extend(discover_namespaces(ipc)?.into_iter().map(Some));
    Ok(all)
}

/// A namespace for people: its name, or `(none)` for the topics without a namespace.
/// How many nodes a per-namespace list names.
fn total(list: &[(Option<Namespace>, Vec<String>)]) -> usize {
    list.iter().map(|(_, who)| who.len()).sum()
}

pub(crate) fn shown(namespace: Option<&Namespace>) -> &str {
    namespace.map_or("(none)", Namespace::as_str)
}

/// One iceoryx2 node of the pipeline as `teleop nodes` lists it.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct NodeRow {
    /// Its name (`?` when its details cannot be read).
    pub name: String,
    /// `alive`, `dead`, `inaccessible` or `undefined`.
    pub status: &'static str,
    /// Its process id (`?` when unknown).
    pub pid: String,
    /// Its executable (`?` when unknown).
    pub exe: String,
}

/// Every iceoryx2 node of the pipeline of `ipc`, sorted by name.
pub(crate) fn node_rows(ipc: &IpcSettings) -> anyhow::Result<Vec<NodeRow>> {
    let config = ipc.config()?;
    let mut rows = Vec::new();
    Node::<Service>::list(&config, |state| {
        let (status, details) = match &state {
            NodeState::Alive(v) => ("alive", v.details().clone()),
            NodeState::Dead(v) => ("dead", v.details().clone()),
            NodeState::Inaccessible(_) => ("inaccessible", None),
            NodeState::Undefined(_) => ("undefined", None),
        };
        let (name, pid, exe) = details.map_or_else(
            || ("?".to_string(), "?".to_string(), "?".to_string()),
            |d| {
                (
                    d.name().as_str().to_string(),
                    d.process_id().value().to_string(),
                    d.executable().to_string(),
                )
            },
        );
        rows.push(NodeRow {
            name,
            status,
            pid,
            exe,
        });
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow::anyhow!("cannot list iceoryx2 nodes: {e:?}"))?;
    rows.sort();
    Ok(rows)
}

pub fn nodes(ipc: &IpcSettings, namespaces: &[Namespace]) -> anyhow::Result<ExitCode> {
    let mut rows = node_rows(ipc)?;
    if !namespaces.is_empty() {
        rows.retain(|row| {
            namespaces
                .iter()
                .any(|ns| row.name.starts_with(&format!("{ns}/")))
        });
    }
    out!("{:<20} {:<8} {:>8}  EXECUTABLE", "NODE", "STATE", "PID")?;
    for NodeRow {
        name,
        status,
        pid,
        exe,
    } in &rows
    {
        out!("{name:<20} {status:<8} {pid:>8}  {exe}")?;
    }
    if rows.is_empty() {
        out!("(no nodes: is a pipeline running with these IPC settings?)")?;
    }
    Ok(ExitCode::SUCCESS)
}

pub fn topics(ipc: &IpcSettings, namespaces: &[Namespace]) -> anyhow::Result<ExitCode> {
    let runtime = NodeRuntime::new(CLI_NODE, ipc)?;
    struct Ports<'a>(&'a NodeRuntime, Option<&'a Namespace>);
    impl TopicVisitor for Ports<'_> {
        type Output = Option<(usize, usize)>;
        fn visit<M: Message>(self) -> Self::Output {
            self.0.topic_ports_in::<M>(self.1)
        }
    }
    out!(
        "{:<28} {:<36} {:>6} {:>5} {:>5}",
        "TOPIC",
        "PAYLOAD",
        "BYTES",
        "PUBS",
        "SUBS"
    )?;
    for ns in covered(ipc, namespaces)? {
        for topic in teleop_msgs::topics() {
            let ports = visit_topic(topic.name, Ports(&runtime, ns.as_ref())).flatten();
            let (pubs, subs) = ports.map_or(("-".into(), "-".into()), |(p, s)| {
                (p.to_string(), s.to_string())
            });
            out!(
                "{:<28} {:<36} {:>6} {:>5} {:>5}",
                qualified(ns.as_ref(), topic.name),
                topic.schema_name,
                topic.size,
                pubs,
                subs
            )?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// A name that is no topic of the contract, refused with the list of those that are.
pub(crate) fn unknown_topic(topic: &str) -> anyhow::Error {
    let names: Vec<_> = teleop_msgs::topics().iter().map(|t| t.name).collect();
    anyhow::anyhow!("unknown topic {topic:?}; topics are: {}", names.join(", "))
}

/// `teleop echo`: the samples of one topic as they arrive, written by [`Echo`] in `format`,
/// hand samples named by the profile file `profile` if given (else by each sample's shipped
/// profile; a sample of another model than the given profile's is still named by it, with a
/// warning on standard error), [`Echo`]'s warnings on standard error.
pub fn echo(
    ipc: &IpcSettings,
    topic: &str,
    namespace: Option<&Namespace>,
    count: Option<u64>,
    format: Format,
    profile: Option<&Path>,
) -> anyhow::Result<ExitCode> {
    let (named, info) = split(topic).ok_or_else(|| unknown_topic(topic))?;
    let profile = profile
        .map(|path| HandProfile::load(path).with_context(|| "--profile"))
        .transpose()?;
    let namespace = match (named, namespace) {
        (Some(a), Some(b)) if a != *b => {
            anyhow::bail!("topic {topic:?} is in namespace \"{a}\", but --namespace says \"{b}\"")
        }
        (Some(a), _) => Some(a),
        (None, b) => b.cloned(),
    };
    let runtime = NodeRuntime::new(CLI_NODE, ipc)?;
    struct Visit<'a> {
        runtime: &'a NodeRuntime,
        namespace: Option<&'a Namespace>,
        count: Option<u64>,
        echo: Echo,
    }
    impl TopicVisitor for Visit<'_> {
        type Output = anyhow::Result<()>;
        fn visit<M: Message>(self) -> anyhow::Result<()> {
            let sub = self.runtime.subscriber_in::<M>(self.namespace)?;
            let printed = core::cell::Cell::new(0u64);
            let limit = self.count.unwrap_or(u64::MAX);
            // A failed write (the reader closed the pipe: `teleop echo ... | head`) ends the echo.
            let failed: RefCell<Option<std::io::Error>> = RefCell::new(None);
            let done = || printed.get() >= limit || failed.borrow().is_some();
            let echo = RefCell::new(self.echo);
            let print = |m: &M| {
                if !done() {
                    let mut echo = echo.borrow_mut();
                    let text = echo.show(m);
                    for warning in echo.take_warnings() {
                        eprintln!("warning: {warning}");
                    }
                    match out!("{text}") {
                        Ok(()) => printed.set(printed.get() + 1),
                        Err(e) => *failed.borrow_mut() = Some(e),
                    }
                }
            };
            // The newest sample published before we subscribed, if any.
            sub.drain(print);
            if !done() {
                EventLoop::new(Duration::from_secs(1)).run(
                    &[Input::new(sub.listener())],
                    |_| {
                        sub.drain(print);
                        if done() {
                            Flow::Break(())
                        } else {
                            Flow::Continue(())
                        }
                    },
                )?;
            }
            match failed.into_inner() {
                Some(e) => Err(e.into()),
                None => Ok(()),
            }
        }
    }
    visit_topic(
        info.name,
        Visit {
            runtime: &runtime,
            namespace: namespace.as_ref(),
            count,
            echo: Echo::new(format, profile),
        },
    )
    .ok_or_else(|| unknown_topic(topic))??;
    Ok(ExitCode::SUCCESS)
}

/// A latency's percentiles over a window, ms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Percentiles {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl Percentiles {
    /// The percentiles of `v` (ns), `None` when it is empty.
    fn of(mut v: Vec<u64>) -> Option<Self> {
        if v.is_empty() {
            return None;
        }
        v.sort_unstable();
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1e6;
        Some(Self {
            p50: at(0.5),
            p99: at(0.99),
            max: at(1.0),
        })
    }
}

/// What a [`Probe`] measured of its topic.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TopicSummary {
    /// The qualified topic name.
    pub name: String,
    /// Samples per second over the window.
    pub rate_hz: f64,
    /// Samples in the window.
    pub samples: u64,
    /// Samples lost (overwritten unread) since the probe started.
    pub drops: u64,
    /// stamp - origin: how old the device sample it descends from was when it was made.
    pub latency: Option<Percentiles>,
    /// receive - stamp: the transport.
    pub transport: Option<Percentiles>,
}

impl TopicSummary {
    /// `teleop stats`'s row.
    fn row(&self) -> String {
        let pct = |p: Option<Percentiles>| match p {
            None => format!("{:>8} {:>8} {:>8}", "-", "-", "-"),
            Some(p) => format!("{:>8.3} {:>8.3} {:>8.3}", p.p50, p.p99, p.max),
        };
        format!(
            "{:<28} {:>8.1} {:>7} {:>6}  {}  {}",
            self.name,
            self.rate_hz,
            self.samples,
            self.drops,
            pct(self.latency),
            pct(self.transport),
        )
    }
}

/// One topic of one namespace, subscribed to measure its rate, drops and latency from the
/// samples' headers: `teleop stats` over its window, `teleop top` over a sliding one
/// ([`Probe::forget_before`]). Its subscriber, like every one of the runtime's, overwrites the
/// oldest sample when it falls behind: a probe never holds a publisher up.
pub(crate) trait Probe {
    fn listener(&self) -> &Listener<Service>;
    /// Takes every queued sample.
    fn drain(&self);
    /// Forgets the samples received before `ns` (`now_ns` time).
    fn forget_before(&self, ns: u64);
    /// The samples kept, as received over `window`.
    fn summary(&self, window: Duration) -> TopicSummary;
    /// For [`newest`]: the probe as its concrete type.
    fn as_any(&self) -> &dyn std::any::Any;
}

struct TopicProbe<M: Message> {
    sub: Subscriber<M>,
    /// The qualified topic name.
    name: String,
    /// (received, stamp - origin, receive - stamp) in ns per sample.
    samples: RefCell<Vec<(u64, u64, u64)>>,
    dropped_before: u64,
    since_ns: u64,
}

impl<M: Message> Probe for TopicProbe<M> {
    fn listener(&self) -> &Listener<Service> {
        self.sub.listener()
    }
    fn drain(&self) {
        let mut samples = self.samples.borrow_mut();
        self.sub.drain(|m| {
            let h = m.header();
            if h.stamp_ns < self.since_ns {
                // The history sample a new subscriber gets: older than the window.
                return;
            }
            let now = now_ns();
            samples.push((
                now,
                h.stamp_ns.saturating_sub(h.origin_ns),
                now.saturating_sub(h.stamp_ns),
            ));
        });
    }
    fn forget_before(&self, ns: u64) {
        self.samples.borrow_mut().retain(|s| s.0 >= ns);
    }
    fn summary(&self, window: Duration) -> TopicSummary {
        let samples = self.samples.borrow();
        let n = samples.len() as u64;
        TopicSummary {
            name: self.name.clone(),
            rate_hz: n as f64 / window.as_secs_f64().max(1e-3),
            samples: n,
            drops: self.sub.dropped().saturating_sub(self.dropped_before),
            latency: Percentiles::of(samples.iter().map(|s| s.1).collect()),
            transport: Percentiles::of(samples.iter().map(|s| s.2).collect()),
        }
    }
    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

/// The newest sample a probe of topic `M` received (`None` for a probe of another topic).
pub(crate) fn newest<M: Message>(probe: &dyn Probe) -> Option<M> {
    let probe = probe.as_any().downcast_ref::<TopicProbe<M>>()?;
    probe.sub.latest()
}

/// A probe of every topic of the contract in `namespace`, measuring from now: the sample a new
/// subscriber gets from a topic's history (maybe old) is skipped.
pub(crate) fn probes(
    runtime: &NodeRuntime,
    namespace: Option<&Namespace>,
) -> anyhow::Result<Vec<Box<dyn Probe>>> {
    struct Make<'a>(&'a NodeRuntime, Option<&'a Namespace>);
    impl TopicVisitor for Make<'_> {
        type Output = anyhow::Result<Box<dyn Probe>>;
        fn visit<M: Message>(self) -> Self::Output {
            let sub = self.0.subscriber_in::<M>(self.1)?;
            // Skip the history sample: it may be old.
            sub.drain(|_| {});
            let dropped_before = sub.dropped();
            Ok(Box::new(TopicProbe {
                sub,
                name: qualified(self.1, M::TOPIC),
                samples: RefCell::new(Vec::with_capacity(4096)),
                dropped_before,
                since_ns: now_ns(),
            }))
        }
    }
    teleop_msgs::topics()
        .iter()
        .map(|t| {
            visit_topic(t.name, Make(runtime, namespace)).ok_or_else(|| unknown_topic(t.name))?
        })
        .collect()
}

pub fn stats(
    ipc: &IpcSettings,
    window: Duration,
    namespaces: &[Namespace],
) -> anyhow::Result<ExitCode> {
    let runtime = NodeRuntime::new(CLI_NODE, ipc)?;
    let mut probes = Vec::new();
    let mut health = Vec::new();
    for ns in covered(ipc, namespaces)? {
        probes.extend(self::probes(&runtime, ns.as_ref())?);
        let sub = runtime.subscriber_in::<NodeHealth>(ns.as_ref())?;
        // Reports from before the window are not this window's.
        sub.drain(|_| {});
        health.push(sub);
    }
    let inputs: Vec<Input> = probes
        .iter()
        .map(|p| p.listener())
        .chain(health.iter().map(Subscriber::listener))
        .map(Input::new)
        .collect();
    let mut latest: BTreeMap<String, NodeHealth> = BTreeMap::new();
    let start = Instant::now();
    let stop = EventLoop::new(Duration::from_millis(50)).run(&inputs, |wake| {
        if let Wake::Input(i) = wake {
            match probes.get(i) {
                Some(probe) => probe.drain(),
                None => {
                    health[i - probes.len()].drain(|h| {
                        latest.insert(h.name(), *h);
                    });
                }
            }
        }
        if start.elapsed() >= window {
            Flow::Break(())
        } else {
            Flow::Continue(())
        }
    })?;
    let measured = start.elapsed();
    out!(
        "over {:.1} s; latency = stamp - origin (origin: when the host received the device sample, not when the device took it), transport = receive - stamp; ms p50/p99/max",
        measured.as_secs_f64()
    )?;
    out!(
        "{:<28} {:>8} {:>7} {:>6}  {:>8} {:>8} {:>8}  {:>8} {:>8} {:>8}",
        "TOPIC",
        "RATE_HZ",
        "SAMPLES",
        "DROPS",
        "LAT_P50",
        "LAT_P99",
        "LAT_MAX",
        "TR_P50",
        "TR_P99",
        "TR_MAX"
    )?;
    for p in &probes {
        out!("{}", p.summary(measured).row())?;
    }
    out!("{}", health_table(&latest))?;
    if stop != StopReason::Requested {
        out!("(interrupted)")?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Each node's newest health report: its counters and its details by name.
fn health_table(latest: &BTreeMap<String, NodeHealth>) -> String {
    let mut out = format!(
        "{:<28} {:>8} {:>8} {:>8} {:>8}  DETAILS",
        "NODE", "TIMEOUTS", "ERRORS", "CLAMPS", "DROPS"
    );
    for (name, h) in latest {
        let details: Vec<String> = h
            .details()
            .map(|(name, value)| format!("{name}={value}"))
            .collect();
        out.push_str(&format!(
            "\n{name:<28} {:>8} {:>8} {:>8} {:>8}  {}",
            h.timeouts,
            h.errors,
            h.clamps,
            h.dropped,
            details.join(" ")
        ));
    }
    out
}

/// How long `teleop estop` waits for the nodes that obey the e-stop to acknowledge an engage
/// (a node that misses the doorbell still stops: it reads the latch every
/// `teleop_runtime::LATCH_POLL`).
const ESTOP_ACK_WAIT: Duration = Duration::from_secs(1);

/// How long `teleop estop --release` waits for every node that obeys the e-stop to take the
/// release. A node releases only on the doorbell's sample (never on a missing latch alone), and
/// iceoryx2 takes the sample back when the command's publisher goes: a node starved of the CPU
/// for longer than this stays engaged, and the command says so (exit 1).
const ESTOP_RELEASE_WAIT: Duration = Duration::from_secs(5);

/// What one `teleop estop` (or the console's e-stop key) did.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct EStopReport {
    /// Engaged (else released).
    pub engage: bool,
    /// The latch files written (engaged) or removed (released).
    pub latches: Vec<std::path::PathBuf>,
    /// How many namespaces' doorbells were rung.
    pub rung: usize,
    /// Per namespace, the nodes that acknowledged, sorted.
    pub acks: Vec<(Option<Namespace>, Vec<String>)>,
    /// Per namespace, the nodes that obey the e-stop there (a live node with an `estop/ack`
    /// publisher) and did not answer within the wait, sorted; only namespaces with some.
    pub unanswered: Vec<(Option<Namespace>, Vec<String>)>,
    /// A release only: per namespace, the nodes that took it and answered still engaged
    /// (another latch holds them), sorted; only namespaces with some.
    pub still_engaged: Vec<(Option<Namespace>, Vec<String>)>,
    /// What could not be done (engaging goes on past a failure).
    pub failures: Vec<String>,
}

impl EStopReport {
    /// How many nodes acknowledged.
    pub fn acknowledged(&self) -> usize {
        self.acks.iter().map(|(_, who)| who.len()).sum()
    }

    /// The first line `teleop estop` prints: what state the pipeline is now in.
    pub fn headline(&self) -> &'static str {
        match (self.engage, self.latches.is_empty(), self.rung) {
            (false, ..) if total(&self.unanswered) + total(&self.still_engaged) > 0 => {
                "e-stop latches cleared, but NOT released by every node: see below"
            }
            (false, ..) => "e-stop released",
            (true, true, 0) => "e-stop COULD NOT BE ENGAGED: no latch written, no doorbell rung",
            (true, true, _) => {
                "e-stop ENGAGED in the running nodes, NOT latched: a node that starts or restarts \
                 does not see it"
            }
            (true, false, _) => {
                "e-stop ENGAGED (latched): glove forces at zero, hands holding, until `teleop \
                 estop --release`"
            }
        }
    }

    /// How long this action waited for the acknowledgements.
    fn waited(&self) -> Duration {
        if self.engage {
            ESTOP_ACK_WAIT
        } else {
            ESTOP_RELEASE_WAIT
        }
    }

    /// Who acknowledged, per namespace: `namespace (none): acknowledged by feedback, revo2`,
    /// then who obeys the e-stop there and did not answer, and who answered a release still
    /// engaged.
    pub fn ack_lines(&self) -> impl Iterator<Item = String> + '_ {
        self.acks.iter().map(|(ns, answered)| {
            let mut line = format!(
                "namespace {}: acknowledged by {}",
                shown(ns.as_ref()),
                if answered.is_empty() {
                    "no node".to_string()
                } else {
                    answered.join(", ")
                }
            );
            for (what, list) in [
                (
                    format!("did not answer within {} ms", self.waited().as_millis()),
                    &self.unanswered,
                ),
                ("answered still engaged".to_string(), &self.still_engaged),
            ] {
                if let Some((_, who)) = list.iter().find(|(other, _)| other == ns) {
                    line.push_str(&format!("; {what}: {}", who.join(", ")));
                }
            }
            line
        })
    }

    /// Why the command fails, if it does: failures, or no node acknowledged.
    pub fn problem(&self) -> Option<String> {
        if !self.failures.is_empty() {
            let mut text = String::from("e-stop engaged with failures; what could not be done:");
            for f in &self.failures {
                text.push_str(&format!("\n  - {f}"));
            }
            return Some(text);
        }
        if !self.engage && total(&self.still_engaged) > 0 {
            return Some(format!(
                "{} node(s) took the release and stay engaged: another latch holds them (the \
                 plain one, set by `teleop estop` without `--namespace`, or an engage since); \
                 release without `--namespace`",
                total(&self.still_engaged),
            ));
        }
        if !self.engage && total(&self.unanswered) > 0 {
            return Some(format!(
                "the release did not reach {} node(s) that obey the e-stop within {} ms: they \
                 stay engaged (glove forces at zero, hands holding) until a release reaches \
                 them or they restart (the latch is cleared): run `teleop estop --release` again",
                total(&self.unanswered),
                ESTOP_RELEASE_WAIT.as_millis(),
            ));
        }
        if self.acknowledged() > 0 {
            return None;
        }
        if total(&self.unanswered) > 0 {
            return Some(format!(
                "no node acknowledged the e-stop within {} ms, though {} obey it: the latch is \
                 set, and each stops within {} ms of running",
                ESTOP_ACK_WAIT.as_millis(),
                total(&self.unanswered),
                teleop_runtime::LATCH_POLL.as_millis(),
            ));
        }
        Some(if self.engage {
            format!(
                "no node acknowledged the e-stop within {} ms: none that obeys it is running; the \
                 latch is set and every node that starts, in any namespace, will obey it",
                ESTOP_ACK_WAIT.as_millis(),
            )
        } else {
            "no node acknowledged the release: none that obeys the e-stop is running; the latch \
             is cleared"
                .to_string()
        })
    }
}

/// `teleop estop`: engages or releases ([`estop_action`]) and prints what happened; exit code 1
/// when something could not be done or no node acknowledged.
pub fn estop(
    ipc: &IpcSettings,
    engage: bool,
    namespaces: &[Namespace],
) -> anyhow::Result<ExitCode> {
    let report = estop_action(ipc, engage, namespaces)?;
    println!("{}", report.headline());
    if engage {
        for path in &report.latches {
            println!("  latch {}", path.display());
        }
    } else {
        for ((ns, _), path) in report.acks.iter().zip(&report.latches) {
            println!(
                "  namespace {}: latch {} removed",
                shown(ns.as_ref()),
                path.display()
            );
        }
    }
    for line in report.ack_lines() {
        println!("  {line}");
    }
    match report.problem() {
        Some(problem) => {
            eprintln!("{problem}");
            Ok(ExitCode::FAILURE)
        }
        None => Ok(ExitCode::SUCCESS),
    }
}

/// Engages or releases the e-stop of the namespaces given, or else of the topics without a
/// namespace, of every namespace in use and of every namespace latched (whose nodes may all be
/// down): one operator's e-stop stops every side, and a release releases every side. Prints
/// nothing: `teleop estop` and the console show the [`EStopReport`].
///
/// The state is the latch file of each namespace (see `teleop_runtime::EStopInput`), written
/// and synced before the `estop` topic wakes the running nodes, so it outlives this command
/// and any node's restart; the plain latch (no namespace) stops every namespace, also those that
/// start later. Then it waits for the nodes' acknowledgements (`estop/ack`), at most
/// [`ESTOP_ACK_WAIT`].
///
/// Engaging is the easy direction: the latches are written first, then every doorbell is rung,
/// and a step that fails does not keep the next from being tried; what could not be done is in
/// [`EStopReport::failures`]. A latch written but no doorbell rung still stops every node
/// within `teleop_runtime::LATCH_POLL`. Releasing is strict: the first error ends it (an `Err`).
pub(crate) fn estop_action(
    ipc: &IpcSettings,
    engage: bool,
    namespaces: &[Namespace],
) -> anyhow::Result<EStopReport> {
    if !engage {
        // Nothing else in this process engages: nothing can abandon the release.
        let requests = EngageRequests::default();
        return release(ipc, namespaces, &requests, requests.count());
    }
    Ok(ring_engaged(
        ipc,
        namespaces,
        engage_latches(ipc, namespaces),
    ))
}

/// The latches an engage wrote, and what it could not write.
#[derive(Debug, Clone, Default)]
pub(crate) struct Latched {
    pub paths: Vec<std::path::PathBuf>,
    pub failures: Vec<String>,
}

/// The first step of an engage: writes the latches of the namespaces given, or else the plain
/// latch; they alone stop every node that obeys the e-stop (within
/// `teleop_runtime::LATCH_POLL`).
pub(crate) fn engage_latches(ipc: &IpcSettings, namespaces: &[Namespace]) -> Latched {
    let mut latched = Latched::default();
    for ns in latches_of(namespaces) {
        let path = latch_path(ipc, ns.as_ref());
        match set_latch(&path, true) {
            Ok(()) => latched.paths.push(path),
            Err(e) => latched.failures.push(format!(
                "cannot write the e-stop latch {}: {e}",
                path.display()
            )),
        }
    }
    latched
}

/// The latches an engage of `namespaces` writes: theirs, or else the plain one.
fn latches_of(namespaces: &[Namespace]) -> Vec<Option<Namespace>> {
    if namespaces.is_empty() {
        vec![None]
    } else {
        namespaces.iter().cloned().map(Some).collect()
    }
}

/// The engages asked for in this process (the console's e-stop key), counted so that a release
/// that started before one never undoes it: [`release`] takes the count from when it was asked
/// for and gives up when the count moved.
#[derive(Debug, Default)]
pub(crate) struct EngageRequests(std::sync::atomic::AtomicU64);

impl EngageRequests {
    /// The engages asked for so far.
    pub fn count(&self) -> u64 {
        self.0.load(std::sync::atomic::Ordering::SeqCst)
    }

    /// Counts an engage, then writes its latches ([`engage_latches`]); counted first, so that a
    /// release that removes a latch at the same moment sees the count moved afterwards and puts
    /// its latch back.
    pub fn engage(&self, ipc: &IpcSettings, namespaces: &[Namespace]) -> Latched {
        self.0.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        engage_latches(ipc, namespaces)
    }
}

/// Why a release stopped before it was done: an engage was asked for since it was.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ReleaseAbandoned {
    /// Latches the release had removed before (the engage's latch stops their nodes again).
    pub removed: usize,
}

impl std::fmt::Display for ReleaseAbandoned {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the e-stop was engaged after the release was asked for: the release stopped after \
             removing {} latch(es); the engage's latches keep the e-stop engaged",
            self.removed
        )
    }
}

impl std::error::Error for ReleaseAbandoned {}

/// The second step of an engage: rings every doorbell (whatever happened to the latches) and
/// waits for the acknowledgements.
pub(crate) fn ring_engaged(
    ipc: &IpcSettings,
    namespaces: &[Namespace],
    latched: Latched,
) -> EStopReport {
    let Latched {
        paths: latched,
        mut failures,
    } = latched;
    let latches = latches_of(namespaces);
    let mut rung_count = 0;
    // 2. The doorbells, whatever happened to the latches.
    let mut sides = Vec::new();
    let mut doorbells = Vec::new();
    let runtime = match NodeRuntime::new(CLI_NODE, ipc) {
        Ok(runtime) => Some(runtime),
        Err(e) => {
            failures.push(format!(
                "cannot ring any doorbell ({e}): running nodes find the latch within {} ms",
                teleop_runtime::LATCH_POLL.as_millis()
            ));
            None
        }
    };
    let asked_at = now_ns();
    if let Some(runtime) = &runtime {
        let mut covered = covered(ipc, namespaces).unwrap_or_else(|e| {
            failures.push(format!("cannot list the namespaces in use: {e:#}"));
            latches.clone()
        });
        if namespaces.is_empty() {
            for ns in latched_namespaces(ipc) {
                if !covered.contains(&Some(ns.clone())) {
                    covered.push(Some(ns));
                }
            }
        }
        for ns in covered {
            // Subscribe to the answers before asking; without them the doorbell still rings.
            let acks = runtime
                .subscriber_in::<EStopAck>(ns.as_ref())
                .inspect_err(|e| {
                    failures.push(format!(
                        "namespace {}: cannot read acknowledgements: {e}",
                        shown(ns.as_ref())
                    ))
                })
                .ok();
            // The publisher stays until the end: iceoryx2 takes back the samples of a
            // publisher that is gone before its subscribers read them.
            let rung = runtime
                .publisher_in::<EStop>(ns.as_ref())
                .and_then(|mut p| {
                    p.publish(&EStop {
                        engaged: 1,
                        ..Default::default()
                    })?;
                    doorbells.push(p);
                    Ok(())
                });
            match rung {
                Ok(()) => rung_count += 1,
                Err(e) => failures.push(format!(
                    "namespace {}: cannot ring the doorbell: {e}",
                    shown(ns.as_ref())
                )),
            }
            sides.push(Side::new(ns, acks));
        }
        wait_for_acks(runtime, &mut sides, asked_at, true, &|| false);
    }
    let answers = answers(sides);
    EStopReport {
        engage: true,
        latches: latched,
        rung: rung_count,
        acks: answers.acks,
        unanswered: answers.unanswered,
        still_engaged: answers.still_engaged,
        failures,
    }
}

/// The release: strict, the first error ends it (the latches already removed stay removed; the
/// rest stay engaged). Asked for when `requests` counted `since` engages: right before it
/// removes each latch and before it rings each doorbell it checks that no engage was asked
/// for since, and else stops with [`ReleaseAbandoned`]; a latch removed while an engage was
/// asked for is put back.
pub(crate) fn release(
    ipc: &IpcSettings,
    namespaces: &[Namespace],
    requests: &EngageRequests,
    since: u64,
) -> anyhow::Result<EStopReport> {
    let runtime = NodeRuntime::new(CLI_NODE, ipc)?;
    let mut covered = covered(ipc, namespaces)?;
    if namespaces.is_empty() {
        // Namespaces latched while none of their nodes runs (not found by their services).
        for ns in latched_namespaces(ipc) {
            if !covered.contains(&Some(ns.clone())) {
                covered.push(Some(ns));
            }
        }
    }
    let mut sides = Vec::with_capacity(covered.len());
    let mut doorbells = Vec::with_capacity(covered.len());
    for ns in covered {
        // Subscribe to the answers before asking.
        let acks = runtime.subscriber_in::<EStopAck>(ns.as_ref())?;
        doorbells.push(runtime.publisher_in::<EStop>(ns.as_ref())?);
        sides.push(Side::new(ns, Some(acks)));
    }
    let asked_at = now_ns();
    let mut latches = Vec::with_capacity(sides.len());
    let abandoned = |removed: usize| ReleaseAbandoned { removed };
    for (side, publisher) in sides.iter().zip(&mut doorbells) {
        let path = latch_path(ipc, side.namespace.as_ref());
        if requests.count() != since {
            return Err(abandoned(latches.len()).into());
        }
        set_latch(&path, false).map_err(|e| {
            anyhow::anyhow!("cannot release the e-stop latch {}: {e}", path.display())
        })?;
        // An engage counted between the check and the removal may have written this very
        // latch before it was removed: put it back.
        if requests.count() != since {
            set_latch(&path, true).map_err(|e| {
                anyhow::anyhow!(
                    "the e-stop was engaged while the release ran, and the latch {} it had \
                     just removed could not be written again: {e}",
                    path.display()
                )
            })?;
            return Err(abandoned(latches.len()).into());
        }
        publisher.publish(&EStop::default())?;
        latches.push(path);
    }
    // An engage asked for while it waits ends the wait: its report would come after the
    // engage's and read as the state.
    let engaged_since = || requests.count() != since;
    if wait_for_acks(&runtime, &mut sides, asked_at, false, &engaged_since) {
        return Err(abandoned(latches.len()).into());
    }
    let answers = answers(sides);
    Ok(EStopReport {
        engage: false,
        latches,
        rung: doorbells.len(),
        acks: answers.acks,
        unanswered: answers.unanswered,
        still_engaged: answers.still_engaged,
        failures: Vec::new(),
    })
}

/// One namespace of `teleop estop`.
struct Side {
    namespace: Option<Namespace>,
    /// The acknowledgements, if they can be read.
    acks: Option<Subscriber<EStopAck>>,
    /// The nodes that answered the state asked for.
    answered: Vec<String>,
    /// A release: the nodes that answered still engaged.
    still: Vec<String>,
    /// The nodes that obey the e-stop (live, with an `estop/ack` publisher), last listed.
    obeying: Vec<String>,
}

impl Side {
    fn new(namespace: Option<Namespace>, acks: Option<Subscriber<EStopAck>>) -> Self {
        Self {
            namespace,
            acks,
            answered: Vec::new(),
            still: Vec::new(),
            obeying: Vec::new(),
        }
    }

    /// The nodes that obey the e-stop and have not answered, sorted; a name that more than one
    /// node has is always among them (their answers, which carry only the name, cannot be told
    /// apart, so an answer from one of them must not count for the other).
    fn silent(&self) -> Vec<String> {
        let mut silent: Vec<String> = Vec::new();
        for name in &self.obeying {
            let nodes = self.obeying.iter().filter(|n| *n == name).count();
            let who = if nodes > 1 {
                format!("{name} ({nodes} nodes of this name)")
            } else if self.answered.contains(name) || self.still.contains(name) {
                continue;
            } else {
                name.clone()
            };
            if !silent.contains(&who) {
                silent.push(who);
            }
        }
        silent
    }
}

/// Waits until every node that obeys the e-stop answered since `asked_at` (`engage`, or a
/// release: released, or still engaged), or for at most [`ESTOP_ACK_WAIT`] (engage) or
/// [`ESTOP_RELEASE_WAIT`] (release; the whole time for a side whose acknowledgements cannot be
/// read), or until `give_up` (then true). The doorbells' publishers must live until then:
/// iceoryx2 takes back the samples of a publisher that is gone.
fn wait_for_acks(
    runtime: &NodeRuntime,
    sides: &mut [Side],
    asked_at: u64,
    engage: bool,
    give_up: &dyn Fn() -> bool,
) -> bool {
    let deadline = Instant::now()
        + if engage {
            ESTOP_ACK_WAIT
        } else {
            ESTOP_RELEASE_WAIT
        };
    loop {
        if give_up() {
            return true;
        }
        let mut all = true;
        for side in sides.iter_mut() {
            let Some(acks) = &side.acks else {
                // Who answered cannot be seen: wait the whole time, so that the doorbell's
                // publisher (and with it the sample) outlives the nodes' reading it.
                all = false;
                continue;
            };
            let (answered, still) = (&mut side.answered, &mut side.still);
            acks.drain(|a| {
                let name = text_of(&a.node_name);
                if a.header.stamp_ns < asked_at {
                    return;
                }
                if (a.engaged != 0) == engage {
                    still.retain(|n| *n != name);
                    if !answered.contains(&name) {
                        answered.push(name);
                    }
                } else if !engage && !answered.contains(&name) && !still.contains(&name) {
                    still.push(name);
                }
            });
            side.obeying = runtime
                .topic_publisher_nodes_in::<EStopAck>(side.namespace.as_ref())
                .unwrap_or_default();
            all &= side.silent().is_empty();
        }
        if all || Instant::now() >= deadline {
            return false;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// What the nodes answered, per namespace (see [`EStopReport`]).
struct Answers {
    acks: Vec<(Option<Namespace>, Vec<String>)>,
    unanswered: Vec<(Option<Namespace>, Vec<String>)>,
    still_engaged: Vec<(Option<Namespace>, Vec<String>)>,
}

/// Who answered, per namespace, sorted; who obeys the e-stop and did not answer (not known,
/// so not listed, where the acknowledgements could not be read); who answered a release still
/// engaged.
fn answers(sides: Vec<Side>) -> Answers {
    let mut out = Answers {
        acks: Vec::with_capacity(sides.len()),
        unanswered: Vec::new(),
        still_engaged: Vec::new(),
    };
    for mut side in sides {
        side.answered.sort();
        side.still.sort();
        if side.acks.is_some() {
            let silent = side.silent();
            if !silent.is_empty() {
                out.unanswered.push((side.namespace.clone(), silent));
            }
        }
        if !side.still.is_empty() {
            out.still_engaged.push((side.namespace.clone(), side.still));
        }
        out.acks.push((side.namespace, side.answered));
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn a_release_that_missed_a_node_fails_and_an_engage_says_who_did_not_answer() {
        let names = |n: &[&str]| n.iter().map(|a| a.to_string()).collect::<Vec<_>>();
        let report = |engage: bool, answered: &[&str], silent: &[&str], still: &[&str]| {
            let per_ns = |n: &[&str]| {
                if n.is_empty() {
                    vec![]
                } else {
                    vec![(None, names(n))]
                }
            };
            EStopReport {
                engage,
                latches: vec!["/r/p_estop".into()],
                rung: 1,
                acks: vec![(None, names(answered))],
                unanswered: per_ns(silent),
                still_engaged: per_ns(still),
                failures: vec![],
            }
        };
        let missed = report(false, &["feedback"], &["revo2"], &[]);
        assert!(missed.headline().contains("NOT released by every node"));
        let problem = missed.problem().unwrap();
        assert!(problem.contains("did not reach 1 node(s)"), "{problem}");
        let lines: Vec<String> = missed.ack_lines().collect();
        assert_eq!(
            lines,
            ["namespace (none): acknowledged by feedback; did not answer within 5000 ms: revo2"]
        );
        // Held by another latch: released again it would stay so; said how to release it.
        let held = report(false, &["feedback"], &[], &["left/revo2"]);
        assert!(held.headline().contains("NOT released by every node"));
        let problem = held.problem().unwrap();
        assert!(
            problem.contains("release without `--namespace`"),
            "{problem}"
        );
        assert!(held
            .ack_lines()
            .next()
            .unwrap()
            .ends_with("answered still engaged: left/revo2"));
        let released = report(false, &["feedback"], &[], &[]);
        assert_eq!(released.headline(), "e-stop released");
        assert_eq!(released.problem(), None);
        // An engage that one node answered holds: the others read the latch.
        assert_eq!(report(true, &["feedback"], &["revo2"], &[]).problem(), None);
        let nobody = report(true, &[], &["glove", "revo2"], &[])
            .problem()
            .unwrap();
        assert!(nobody.contains("though 2 obey it"), "{nobody}");
    }

    #[test]
    fn two_nodes_of_one_name_never_count_as_answered() {
        let mut side = Side::new(None, None);
        side.obeying = vec!["feedback".into(), "revo2".into(), "revo2".into()];
        side.answered = vec!["feedback".into(), "revo2".into()];
        assert_eq!(side.silent(), ["revo2 (2 nodes of this name)"]);
        side.obeying = vec!["feedback".into(), "revo2".into()];
        assert!(side.silent().is_empty());
        side.answered.clear();
        side.still = vec!["revo2".into()];
        assert_eq!(side.silent(), ["feedback"]);
    }

    #[test]
    fn health_table_shows_counters_and_details_by_name() {
        let mut h = NodeHealth {
            errors: 3,
            ..Default::default()
        };
        h.set_name("left/allegro");
        h.set_detail("reconnects", 2.0);
        h.set_detail("rtt_ms", 0.25);
        let table = health_table(&BTreeMap::from([(h.name(), h)]));
        let row = table.lines().nth(1).unwrap();
        assert!(row.starts_with("left/allegro "), "{table}");
        assert!(row.ends_with("  reconnects=2 rtt_ms=0.25"), "{table}");
        let counters: Vec<&str> = row.split_whitespace().skip(1).take(4).collect();
        assert_eq!(counters, ["0", "3", "0", "0"], "{table}");
    }
}
