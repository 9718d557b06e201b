//! The recorder's episode book: the operator's marks on the `episode` topic applied by
//! `teleop_recording`'s one rule ([`Episodes`]), and each episode's health, computed when it
//! closes and written as the metadata record `episode.<n>` (readable by any MCAP tool), after
//! which the chunk is closed and synced, so a recorder killed later keeps every closed episode.
//!
//! An episode's health: the achieved rate of every channel that carried samples during it
//! (`rate_hz.<channel>`), the samples lost on each (`drops.<channel>`, only where some were),
//! the nodes' input timeouts (`timeouts`, from their `health` reports), the e-stop engagements
//! (`estops`, engaged `estop` samples), and its task, outcome, start, stop and duration.
//! Counting is by arrival at the recorder, so a rate is exact to a sample or so.

use std::collections::{BTreeMap, HashMap};

use teleop_msgs::{EStop, Episode, Message, NodeHealth};
use teleop_recording::{Change, EpisodeSpan, Episodes, Recorder, RecordingError};

/// Name of the metadata record of episode `index`.
pub fn record_name(index: u32) -> String {
    format!("episode.{index}")
}

/// What the recorder's taps had counted when an episode started.
struct Snapshot {
    messages: Vec<u64>,
    dropped: Vec<u64>,
    timeouts: u64,
    estops: u64,
}

/// The episodes of one recording session and the counters their health is computed from.
#[derive(Default)]
pub struct Book {
    episodes: Episodes,
    /// Per tap: samples written.
    messages: Vec<u64>,
    /// Per node: its last reported timeout count.
    node_timeouts: HashMap<String, u64>,
    /// Every node's timeouts seen so far (a restarted node's count starts again at 0).
    timeouts: u64,
    /// Engaged `estop` samples seen so far.
    estops: u64,
    /// Episode marks received.
    marks: u64,
    /// Changes not yet written.
    pending: Vec<Change>,
    at_start: Option<Snapshot>,
    /// The last record written, by episode: what a later DISCARD marks.
    last_written: Option<(u32, BTreeMap<String, String>)>,
}

impl Book {
    /// Counts one sample written by tap `tap` (of the contract topic `topic`) and takes what it
    /// means for the episodes: marks, health reports, e-stops.
    pub fn observe(&mut self, tap: usize, topic: &str, payload: &[u8]) {
        if self.messages.len() <= tap {
            self.messages.resize(tap + 1, 0);
        }
        self.messages[tap] += 1;
        if topic == Episode::TOPIC {
            if let Ok(mark) = Episode::from_bytes(payload) {
                self.marks += 1;
                let changes = self.episodes.apply(&mark);
                self.pending.extend(changes);
            }
        } else if topic == NodeHealth::TOPIC {
            if let Ok(h) = NodeHealth::from_bytes(payload) {
                let last = self.node_timeouts.entry(h.name()).or_insert(0);
                self.timeouts += if h.timeouts >= *last {
                    h.timeouts - *last
                } else {
                    h.timeouts
                };
                *last = h.timeouts;
            }
        } else if topic == EStop::TOPIC && EStop::from_bytes(payload).is_ok_and(|e| e.engaged == 1)
        {
            self.estops += 1;
        }
    }

    /// Writes what the marks since the last call changed: an episode's record when it closes
    /// or is discarded, then closes the chunk. `channels[i]` and `dropped[i]` are tap `i`'s
    /// channel and its drops so far. True when anything changed.
    pub fn settle(
        &mut self,
        channels: &[&str],
        dropped: &[u64],
        rec: &mut Recorder,
    ) -> Result<bool, Box<RecordingError>> {
        if self.pending.is_empty() {
            return Ok(false);
        }
        for change in std::mem::take(&mut self.pending) {
            match change {
                Change::Started(open) => {
                    tracing::info!(episode = open.index, task = %open.task, "episode started");
                    let mut messages = self.messages.clone();
                    messages.resize(channels.len(), 0);
                    self.at_start = Some(Snapshot {
                        messages,
                        dropped: dropped.to_vec(),
                        timeouts: self.timeouts,
                        estops: self.estops,
                    });
                }
                Change::Closed(span) => {
                    let fields = self.health(&span, channels, dropped);
                    tracing::info!(
                        episode = span.index,
                        outcome = span.label(),
                        seconds = span.duration_s(),
                        "episode closed"
                    );
                    self.write(rec, span.index, fields)?;
                }
                Change::Discarded { index, was_open } => {
                    tracing::info!(episode = index, "episode discarded");
                    let mut fields = match self.last_written.take() {
                        Some((i, fields)) if i == index && !was_open => fields,
                        _ => {
                            // Discarded while open: what there is of it.
                            self.at_start = None;
                            let span = self.episodes.closed().last().cloned();
                            span.map(|s| self.identity(&s)).unwrap_or_default()
                        }
                    };
                    fields.insert("outcome".into(), "discarded".into());
                    self.write(rec, index, fields)?;
                }
                Change::Ignored(why) => tracing::warn!("episode mark ignored: {why}"),
            }
        }
        Ok(true)
    }

    fn write(
        &mut self,
        rec: &mut Recorder,
        index: u32,
        fields: BTreeMap<String, String>,
    ) -> Result<(), Box<RecordingError>> {
        rec.add_metadata(&record_name(index), fields.clone())?;
        rec.flush()?;
        self.last_written = Some((index, fields));
        Ok(())
    }

    /// The fields that name an episode: index, task, outcome, times.
    fn identity(&self, span: &EpisodeSpan) -> BTreeMap<String, String> {
        BTreeMap::from([
            ("index".to_string(), span.index.to_string()),
            ("task".to_string(), span.task.clone()),
            ("outcome".to_string(), span.label().to_string()),
            ("start_ns".to_string(), span.start_ns.to_string()),
            ("stop_ns".to_string(), span.stop_ns.to_string()),
            (
                "duration_s".to_string(),
                format!("{:.3}", span.duration_s()),
            ),
        ])
    }

    /// The closed episode's record: its identity and health.
    fn health(
        &mut self,
        span: &EpisodeSpan,
        channels: &[&str],
        dropped: &[u64],
    ) -> BTreeMap<String, String> {
        let mut fields = self.identity(span);
        let Some(start) = self.at_start.take() else {
            return fields;
        };
        let seconds = span.duration_s();
        for (i, channel) in channels.iter().enumerate() {
            let now = self.messages.get(i).copied().unwrap_or(0);
            let count = now.saturating_sub(start.messages.get(i).copied().unwrap_or(0));
            if count > 0 && seconds > 0.0 {
                fields.insert(
                    format!("rate_hz.{channel}"),
                    format!("{:.1}", count as f64 / seconds),
                );
            }
            let lost = dropped
                .get(i)
                .copied()
                .unwrap_or(0)
                .saturating_sub(start.dropped.get(i).copied().unwrap_or(0));
            if lost > 0 {
                fields.insert(format!("drops.{channel}"), lost.to_string());
            }
        }
        fields.insert(
            "timeouts".into(),
            (self.timeouts - start.timeouts).to_string(),
        );
        fields.insert("estops".into(), (self.estops - start.estops).to_string());
        fields
    }

    /// The values the recorder reports in its health: the current (or last) episode's number,
    /// whether it is open, its seconds so far (or its length), the episodes kept, the marks
    /// received (`teleop episode` waits for this to count its mark).
    pub fn details(&self, now_ns: u64) -> [(&'static str, f64); 5] {
        let (index, open, seconds) = match (self.episodes.open(), self.episodes.closed().last()) {
            (Some(o), _) => (
                o.index,
                1.0,
                now_ns.saturating_sub(o.start_ns) as f64 * 1e-9,
            ),
            (None, Some(last)) => (last.index, 0.0, last.duration_s()),
            (None, None) => (0, 0.0, 0.0),
        };
        [
            ("episode", f64::from(index)),
            ("episode_open", open),
            ("episode_s", seconds),
            ("episodes_kept", self.episodes.kept().count() as f64),
            ("episode_marks", self.marks as f64),
        ]
    }
}
