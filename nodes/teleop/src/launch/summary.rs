//! What `teleop launch` prints when a session ends: per-topic rates, latency since the host
//! received the device sample (`stamp - origin` from the headers, p50/p99/max; the time the
//! device took the sample is earlier and not known here), drops, the faults the nodes handled,
//! restarts, and where the recording is. Collected during the session by subscribing to every
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
        for r in recordings {
            out.push_str(&format!("recording: {r}\n"));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
