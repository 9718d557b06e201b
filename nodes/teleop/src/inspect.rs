//! `teleop nodes | topics | echo | stats | estop`: look into and steer a running pipeline.
//!
//! Each takes `--namespace NS` (repeatable) to look at some sides only; without it `topics`,
//! `stats` and `estop` cover the topics without a namespace and every namespace in use
//! ([`discover_namespaces`]), and `nodes` lists every node. `echo` reads one topic, of the
//! namespace given or named in the topic (`left/hand/command`).

use std::cell::RefCell;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use iceoryx2::node::{Node, NodeState, NodeView};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::CallbackProgression;
use teleop_msgs::{text_of, visit_topic, EStop, EStopAck, Message, TopicVisitor};
use teleop_runtime::{
    discover_namespaces, latch_path, latched_namespaces, now_ns, qualified, set_latch, split,
    EventLoop, Flow, Input, IpcSettings, Namespace, NodeRuntime, Service, StopReason, Subscriber,
    Wake,
};

/// Name of the short-lived iceoryx2 node the inspection commands create.
const CLI_NODE: &str = "teleop-cli";

/// The namespaces a command covers: those given, or the topics without a namespace (`None`)
/// and every namespace in use.
fn covered(ipc: &IpcSettings, given: &[Namespace]) -> anyhow::Result<Vec<Option<Namespace>>> {
    if !given.is_empty() {
        return Ok(given.iter().cloned().map(Some).collect());
    }
    let mut all = vec![None];
    all.extend(discover_namespaces(ipc)?.into_iter().map(Some));
    Ok(all)
}

/// A namespace for people: its name, or `(none)` for the topics without a namespace.
fn shown(namespace: Option<&Namespace>) -> &str {
    namespace.map_or("(none)", Namespace::as_str)
}

pub fn nodes(ipc: &IpcSettings, namespaces: &[Namespace]) -> anyhow::Result<ExitCode> {
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
        rows.push((name, status, pid, exe));
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow::anyhow!("cannot list iceoryx2 nodes: {e:?}"))?;
    if !namespaces.is_empty() {
        rows.retain(|(name, ..)| {
            namespaces
                .iter()
                .any(|ns| name.starts_with(&format!("{ns}/")))
        });
    }
    rows.sort();
    out!("{:<20} {:<8} {:>8}  EXECUTABLE", "NODE", "STATE", "PID")?;
    for (name, status, pid, exe) in &rows {
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

pub fn echo(
    ipc: &IpcSettings,
    topic: &str,
    namespace: Option<&Namespace>,
    count: Option<u64>,
) -> anyhow::Result<ExitCode> {
    let (named, info) = split(topic).ok_or_else(|| unknown_topic(topic))?;
    let namespace = match (named, namespace) {
        (Some(a), Some(b)) if a != *b => {
            anyhow::bail!("topic {topic:?} is in namespace \"{a}\", but --namespace says \"{b}\"")
        }
        (Some(a), _) => Some(a),
        (None, b) => b.cloned(),
    };
    let runtime = NodeRuntime::new(CLI_NODE, ipc)?;
    struct Echo<'a> {
        runtime: &'a NodeRuntime,
        namespace: Option<&'a Namespace>,
        count: Option<u64>,
    }
    impl TopicVisitor for Echo<'_> {
        type Output = anyhow::Result<()>;
        fn visit<M: Message>(self) -> anyhow::Result<()> {
            let sub = self.runtime.subscriber_in::<M>(self.namespace)?;
            let printed = core::cell::Cell::new(0u64);
            let limit = self.count.unwrap_or(u64::MAX);
            // A failed write (the reader closed the pipe: `teleop echo ... | head`) ends the echo.
            let failed: RefCell<Option<std::io::Error>> = RefCell::new(None);
            let done = || printed.get() >= limit || failed.borrow().is_some();
            let print = |m: &M| {
                if !done() {
                    match out!("{m:?}") {
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
        Echo {
            runtime: &runtime,
            namespace: namespace.as_ref(),
            count,
        },
    )
    .ok_or_else(|| unknown_topic(topic))??;
    Ok(ExitCode::SUCCESS)
}

/// What `stats` keeps per topic.
trait Probe {
    fn listener(&self) -> &Listener<Service>;
    fn drain(&self);
    fn report(&self, window: Duration) -> String;
}

struct TopicProbe<M: Message> {
    sub: Subscriber<M>,
    /// The qualified topic name.
    name: String,
    /// (stamp - origin, receive - stamp) in ns per sample.
    samples: RefCell<Vec<(u64, u64)>>,
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
                h.stamp_ns.saturating_sub(h.origin_ns),
                now.saturating_sub(h.stamp_ns),
            ));
        });
    }
    fn report(&self, window: Duration) -> String {
        let samples = self.samples.borrow();
        let n = samples.len() as u64;
        let rate = n as f64 / window.as_secs_f64();
        let pct = |mut v: Vec<u64>| -> String {
            if v.is_empty() {
                return format!("{:>8} {:>8} {:>8}", "-", "-", "-");
            }
            v.sort_unstable();
            let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] as f64 / 1e6;
            format!("{:>8.3} {:>8.3} {:>8.3}", at(0.5), at(0.99), at(1.0))
        };
        format!(
            "{:<28} {:>8.1} {:>7} {:>6}  {}  {}",
            self.name,
            rate,
            n,
            self.sub.dropped().saturating_sub(self.dropped_before),
            pct(samples.iter().map(|s| s.0).collect()),
            pct(samples.iter().map(|s| s.1).collect()),
        )
    }
}

pub fn stats(
    ipc: &IpcSettings,
    window: Duration,
    namespaces: &[Namespace],
) -> anyhow::Result<ExitCode> {
    let runtime = NodeRuntime::new(CLI_NODE, ipc)?;
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
    let mut probes = Vec::new();
    for ns in covered(ipc, namespaces)? {
        for t in teleop_msgs::topics() {
            probes.push(
                visit_topic(t.name, Make(&runtime, ns.as_ref()))
                    .ok_or_else(|| unknown_topic(t.name))??,
            );
        }
    }
    let inputs: Vec<Input> = probes.iter().map(|p| Input::new(p.listener())).collect();
    let start = Instant::now();
    let stop = EventLoop::new(Duration::from_millis(50)).run(&inputs, |wake| {
        if let Wake::Input(i) = wake {
            probes[i].drain();
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
        out!("{}", p.report(measured))?;
    }
    if stop != StopReason::Requested {
        out!("(interrupted)")?;
    }
    Ok(ExitCode::SUCCESS)
}

/// How long `teleop estop` waits for the nodes that obey the e-stop to acknowledge it.
const ESTOP_ACK_WAIT: Duration = Duration::from_secs(1);

/// Engages or releases the e-stop of the namespaces given, or else of the topics without a
/// namespace, of every namespace in use and of every namespace latched (whose nodes may all be
/// down): one operator's e-stop stops every side, and `--release` releases every side.
///
/// The state is the latch file of each namespace (see `teleop_runtime::EStopInput`), written
/// and synced before the `estop` topic wakes the running nodes, so it outlives this command
/// and any node's restart. Then it waits for the nodes' acknowledgements (`estop/ack`) and lists
/// them; none at all is a failure (exit code 1), although the latch stays as set.
pub fn estop(
    ipc: &IpcSettings,
    engage: bool,
    namespaces: &[Namespace],
) -> anyhow::Result<ExitCode> {
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
    for ns in covered {
        // Subscribe to the answers before asking.
        let acks = runtime.subscriber_in::<EStopAck>(ns.as_ref())?;
        let publisher = runtime.publisher_in::<EStop>(ns.as_ref())?;
        sides.push((ns, acks, publisher, Vec::<String>::new()));
    }
    let asked_at = now_ns();
    for (ns, _, publisher, _) in &mut sides {
        let path = latch_path(ipc, ns.as_ref());
        set_latch(&path, engage).map_err(|e| {
            anyhow::anyhow!(
                "cannot {} the e-stop latch {}: {e}",
                if engage { "engage" } else { "release" },
                path.display()
            )
        })?;
        publisher.publish(&EStop {
            engaged: u8::from(engage),
            ..Default::default()
        })?;
    }
    // Every node that obeys the e-stop has one `estop/ack` publisher: wait until each has
    // answered, or for at most ESTOP_ACK_WAIT.
    let deadline = Instant::now() + ESTOP_ACK_WAIT;
    loop {
        let mut all = true;
        for (ns, acks, _, answered) in &mut sides {
            acks.drain(|a| {
                let name = text_of(&a.node_name);
                if a.header.stamp_ns >= asked_at
                    && (a.engaged != 0) == engage
                    && !answered.contains(&name)
                {
                    answered.push(name);
                }
            });
            let expected = runtime
                .topic_ports_in::<EStopAck>(ns.as_ref())
                .map_or(0, |(publishers, _)| publishers);
            all &= answered.len() >= expected;
        }
        if all || Instant::now() >= deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    println!(
        "e-stop {}",
        if engage {
            "ENGAGED (latched): glove forces at zero, hands holding, until `teleop estop --release`"
        } else {
            "released"
        }
    );
    let mut acknowledged = 0;
    for (ns, _, _, answered) in &mut sides {
        answered.sort();
        acknowledged += answered.len();
        println!(
            "  namespace {}: latch {}; acknowledged by {}",
            shown(ns.as_ref()),
            latch_path(ipc, ns.as_ref()).display(),
            if answered.is_empty() {
                "no node".to_string()
            } else {
                answered.join(", ")
            }
        );
    }
    if acknowledged == 0 {
        eprintln!(
            "no node acknowledged the e-stop within {} ms: none that obeys it is running; the latch \
             is {} and every node that starts will obey it",
            ESTOP_ACK_WAIT.as_millis(),
            if engage { "set" } else { "cleared" }
        );
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}
