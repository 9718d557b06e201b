//! What `teleop launch` prints when a session ends: per-topic rates, latency since the host
//! received the device sample (`stamp - origin` from the headers, p50/p99/max; the time the
//! device took the sample is earlier and not known here), drops, the faults the nodes handled,
//! restarts, and where the recording is (every file a recorder started, finished or not, and
//! RECORDING STOPPED when recording did not last to the end: [`recording_lines`]). Collected
//! during the session by subscribing to every
//! topic of every namespace the launch file uses, with fixed-size histograms so that a long
//! session does not grow memory. A namespace none of whose topics carried a sample is left out when the session
//! has others (the recorder of a two-sided session runs without a namespace, for instance).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use teleop_msgs::{topics, visit_topic, Message, NodeHealth, TopicVisitor};
use teleop_runtime::{qualified, Namespace, NodeRuntime, Subscriber};

/// Latency histogram with about 5 % resolution from 1 us to about 100 s.
pub struct Histogram {
    buckets: Vec<u64>,
    count: u64,
    max_us: u64,
}

const GROWTH: f64 = 1.05;
const BUCKETS: usize = 400;

impl Histogram {
    fn new() -> Self {
        Self {
            buckets: vec![0; BUCKETS],
            count: 0,
            max_us: 0,
        }
    }

    fn add(&mut self, us: u64) {
        let i = (((us + 1) as f64).ln() / GROWTH.ln()) as usize;
        self.buckets[i.min(BUCKETS - 1)] += 1;
        self.count += 1;
        self.max_us = self.max_us.max(us);
    }

    /// The value below which `q` of the samples lie (upper bucket edge), in us.
    fn quantile(&self, q: f64) -> Option<f64> {
        if self.count == 0 {
            return None;
        }
        if q >= 1.0 {
            return Some(self.max_us as f64);
        }
        let target = (q * self.count as f64).ceil().max(1.0) as u64;
        let mut seen = 0;
        for (i, n) in self.buckets.iter().enumerate() {
            seen += n;
            if seen >= target {
                // The last bucket also holds everything above the range: report the maximum.
                if i == BUCKETS - 1 {
                    return Some(self.max_us as f64);
                }
                return Some((GROWTH.powi(i as i32 + 1) - 1.0).min(self.max_us as f64));
            }
        }
        Some(self.max_us as f64)
    }
}

trait Probe {
    fn poll(&mut self);
    fn line(&self, seconds: f64) -> String;
    fn count(&self) -> u64;
}

struct TopicProbe<M: Message> {
    sub: Subscriber<M>,
    /// The qualified topic name.
    name: String,
    count: u64,
    latency: Histogram,
    dropped_before: u64,
}

impl<M: Message> Probe for TopicProbe<M> {
    fn poll(&mut self) {
        let (count, latency) = (&mut self.count, &mut self.latency);
        self.sub.drain(|m| {
            let h = m.header();
            *count += 1;
            latency.add(h.stamp_ns.saturating_sub(h.origin_ns) / 1000);
        });
    }

    fn count(&self) -> u64 {
        self.count
    }

    fn line(&self, seconds: f64) -> String {
        let ms = |q: f64| {
            self.latency
                .quantile(q)
                .map_or("-".to_string(), |us| format!("{:.3}", us / 1000.0))
        };
        format!(
            "{:<28} {:>9.1} {:>9} {:>9} {:>9} {:>7}",
            self.name,
            self.count as f64 / seconds.max(1e-9),
            ms(0.5),
            ms(0.99),
            if self.latency.count > 0 {
                format!("{:.3}", self.latency.max_us as f64 / 1000.0)
            } else {
                "-".into()
            },
            self.sub.dropped().saturating_sub(self.dropped_before)
        )
    }
}

struct MakeProbe<'a>(&'a NodeRuntime, Option<&'a Namespace>);

impl TopicVisitor for MakeProbe<'_> {
    type Output = anyhow::Result<Box<dyn Probe>>;
    fn visit<M: Message>(self) -> Self::Output {
        let sub = self.0.subscriber_in::<M>(self.1)?;
        // The history sample predates the session.
        sub.drain(|_| {});
        let dropped_before = sub.dropped();
        Ok(Box::new(TopicProbe::<M> {
            sub,
            name: qualified(self.1, M::TOPIC),
            count: 0,
            latency: Histogram::new(),
            dropped_before,
        }))
    }
}

/// Watches a running session.
pub struct SessionWatch {
    /// Per namespace, a probe per topic.
    probes: Vec<Vec<Box<dyn Probe>>>,
    health: Vec<Subscriber<NodeHealth>>,
    latest: BTreeMap<String, NodeHealth>,
    /// When each node's newest health report arrived.
    health_at: BTreeMap<String, Instant>,
    _runtime: NodeRuntime,
}

impl SessionWatch {
    /// Subscribes to every topic of the contract in each of `namespaces`.
    pub fn new(
        ipc: &teleop_runtime::IpcSettings,
        namespaces: &[Option<Namespace>],
    ) -> anyhow::Result<Self> {
        let runtime = NodeRuntime::new("teleop-launch", ipc)?;
        let mut probes = Vec::new();
        let mut health = Vec::new();
        for ns in namespaces {
            let mut of_ns = Vec::new();
            for t in topics() {
                if let Some(p) = visit_topic(t.name, MakeProbe(&runtime, ns.as_ref())) {
                    of_ns.push(p?);
                }
            }
            probes.push(of_ns);
            health.push(runtime.subscriber_in(ns.as_ref())?);
        }
        Ok(Self {
            probes,
            health,
            latest: BTreeMap::new(),
            health_at: BTreeMap::new(),
            _runtime: runtime,
        })
    }

    /// Takes everything that arrived since the last call.
    pub fn poll(&mut self) {
        for p in self.probes.iter_mut().flatten() {
            p.poll();
        }
        let (latest, health_at) = (&mut self.latest, &mut self.health_at);
        let now = Instant::now();
        for health in &self.health {
            health.drain(|h| {
                let name = h.name();
                health_at.insert(name.clone(), now);
                latest.insert(name, *h);
            });
        }
    }

    /// When the node called `node` (with its namespace) last reported its health.
    pub fn last_health(&self, node: &str) -> Option<Instant> {
        self.health_at.get(node).copied()
    }

    /// The summary text.
    pub fn report(
        &self,
        elapsed: Duration,
        restarts: &[(String, u32)],
        recordings: &[String],
    ) -> String {
        let s = elapsed.as_secs_f64();
        let mut out = format!(
            "\nsession summary ({s:.1} s); latency = stamp - origin (when the host received the device sample, not when the device took it), ms\n{:<28} {:>9} {:>9} {:>9} {:>9} {:>7}\n",
            "TOPIC", "RATE_HZ", "LAT_P50", "LAT_P99", "LAT_MAX", "DROPS"
        );
        let several = self.probes.len() > 1;
        for of_ns in &self.probes {
            if several && of_ns.iter().all(|p| p.count() == 0) {
                continue;
            }
            for p in of_ns {
                out.push_str(&p.line(s));
                out.push('\n');
            }
        }
        out.push_str(&format!(
            "{:<28} {:>9} {:>9} {:>9} {:>9}\n",
            "NODE", "TIMEOUTS", "ERRORS", "CLAMPS", "DROPS"
        ));
        for (name, h) in &self.latest {
            out.push_str(&format!(
                "{name:<28} {:>9} {:>9} {:>9} {:>9}\n",
                h.timeouts, h.errors, h.clamps, h.dropped
            ));
        }
        let restarted: Vec<String> = restarts
            .iter()
            .filter(|(_, n)| *n > 0)
            .map(|(p, n)| format!("{p} x{n}"))
            .collect();
        out.push_str(&format!(
            "restarts: {}\n",
            if restarted.is_empty() {
                "none".to_string()
            } else {
                restarted.join(", ")
            }
        ));
        out.push_str(&recording_lines(recordings));
        out
    }
}

/// The prefix of the line a recorder prints when it cannot go on (its first error follows).
const STOPPED: &str = "recording stopped: ";

/// What the summary keeps of a recorder's output line: `recorded PATH.mcap` (printed when it
/// starts a file and again when it finishes) gives the path, `recording stopped: WHY` the line
/// itself; other lines nothing.
pub fn recorder_note(line: &str) -> Option<String> {
    if line.starts_with(STOPPED) {
        return Some(line.to_string());
    }
    line.strip_prefix("recorded ")
        .filter(|p| p.ends_with(".mcap"))
        .map(str::to_string)
}

/// The recording part of the summary, from the recorders' notes ([`recorder_note`]) in the
/// order they came: a `recording: PATH` line per file (each once), under it the file's state
/// (complete with its messages and drops, or not finished), then `RECORDING STOPPED` when
/// recording did not last to the end ([`recording_stopped`]) or a note when it stopped and
/// started again.
pub fn recording_lines(notes: &[String]) -> String {
    let mut out = String::new();
    let mut files: Vec<&str> = Vec::new();
    for note in notes {
        if !note.starts_with(STOPPED) && !files.contains(&note.as_str()) {
            files.push(note);
        }
    }
    for file in &files {
        out.push_str(&format!("recording: {file}\n"));
        match teleop_recording::info(std::path::Path::new(file)) {
            Ok(info) if info.complete => {
                let drops: u64 = info.topics.iter().filter_map(|t| t.drops).sum();
                out.push_str(&format!(
                    "  complete: {} messages, {drops} drops\n",
                    info.messages
                ));
            }
            Ok(info) => out.push_str(&format!(
                "  not finished (its recorder was killed or failed): {} messages in its closed \
                 chunks; `teleop recordings repair` makes it indexable\n",
                info.messages
            )),
            Err(e) => out.push_str(&format!("  not readable: {e}\n")),
        }
    }
    let stops = notes.iter().filter(|n| n.starts_with(STOPPED)).count();
    match recording_stopped(notes) {
        Some(why) => out.push_str(&format!("RECORDING STOPPED: {why}\n")),
        None if stops > 0 => {
            let first = notes.iter().find(|n| n.starts_with(STOPPED));
            out.push_str(&format!(
                "recording interrupted ({}), then resumed: the samples in between are counted \
                 as drops\n",
                first.map_or("", |f| &f[STOPPED.len()..])
            ));
        }
        None => {}
    }
    out
}

/// Why the session's recording did not last to its end, if it did not: a recorder said it
/// stopped (the first reason given; restarts that stopped again say more of the same) and no
/// file was started after that, or the last file was left unfinished. `None` when the session
/// had no recorder or recorded to the end.
pub fn recording_stopped(notes: &[String]) -> Option<String> {
    let last_stop = notes.iter().rposition(|n| n.starts_with(STOPPED));
    let last_file = notes.iter().rposition(|n| !n.starts_with(STOPPED));
    if let Some(stop) = last_stop {
        if last_file.is_none_or(|file| file < stop) {
            let first = notes
                .iter()
                .find(|n| n.starts_with(STOPPED))
                .map_or("", |n| &n[STOPPED.len()..]);
            let more = notes[..=stop]
                .iter()
                .filter(|n| n.starts_with(STOPPED))
                .count()
                - 1;
            return Some(if more > 0 {
                format!("{first} (and {more} more times after restarts)")
            } else {
                first.to_string()
            });
        }
    }
    let file = &notes[last_file?];
    match teleop_recording::info(std::path::Path::new(file)) {
        Ok(info) if info.complete => None,
        Ok(_) => Some(format!(
            "{file} was not finished (its recorder was killed?)"
        )),
        Err(e) => Some(format!("{file} cannot be read: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recorder_notes() {
        assert_eq!(
            recorder_note("recorded /r/a.mcap").as_deref(),
            Some("/r/a.mcap")
        );
        assert_eq!(recorder_note("recorded 12 samples"), None);
        assert_eq!(
            recorder_note("recording stopped: /r/b.mcap: No space left on device").as_deref(),
            Some("recording stopped: /r/b.mcap: No space left on device")
        );
        let notes = |n: &[&str]| n.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(recording_stopped(&[]), None);
        let stopped = notes(&[
            "/nonexistent/a.mcap",
            "recording stopped: disk full",
            "recording stopped: disk full again",
        ]);
        assert_eq!(
            recording_stopped(&stopped).as_deref(),
            Some("disk full (and 1 more times after restarts)")
        );
        let text = recording_lines(&stopped);
        assert!(
            text.starts_with("recording: /nonexistent/a.mcap\n  not readable"),
            "{text}"
        );
        assert!(text.contains("RECORDING STOPPED: disk full"), "{text}");
        // A missing last file: not finished, whatever was said before.
        let resumed = notes(&["recording stopped: disk full", "/nonexistent/b.mcap"]);
        assert!(recording_stopped(&resumed).is_some());
    }

    #[test]
    fn histogram_quantiles_within_five_percent() {
        let mut h = Histogram::new();
        for us in 1..=1000 {
            h.add(us);
        }
        let p50 = h.quantile(0.5).unwrap();
        assert!((p50 - 500.0).abs() / 500.0 < 0.06, "{p50}");
        let p99 = h.quantile(0.99).unwrap();
        assert!((p99 - 990.0).abs() / 990.0 < 0.06, "{p99}");
        assert_eq!(h.quantile(1.0).unwrap(), 1000.0);
        assert!(Histogram::new().quantile(0.5).is_none());
        h.add(u64::MAX / 2);
        assert!(h.quantile(1.0).unwrap() > 1e9);
    }
}
