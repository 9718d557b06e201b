//! The recorder's episode book: the operator's marks on the `episode` topic applied by
//! `teleop_recording`'s one rule ([`Episodes`]), and each episode's health, computed when it
//! closes and written as the metadata record `episode.<n>` (readable by any MCAP tool; in the
//! file where it closed only), after which the chunk is closed and synced, so a recorder killed
//! later keeps every closed episode.
//!
//! A mark counts as taken (the health detail `episode_marks`, which `teleop episode` waits
//! for) only once it is in the file and what it changed is written; a mark that changes nothing
//! (a STOP with no episode open) counts in `episode_ignored` instead, so the command can say so.
//! A recorder restarted in the same session continues its predecessor's episodes (read back
//! from its files): an episode open when the predecessor was killed can still be stopped or
//! discarded, and the numbering goes on.
//!
//! An episode's health: the achieved rate of every channel that carried samples during it
//! (`rate_hz.<channel>`, counted by arrival at the recorder: exact to a sample or so), the
//! samples lost on each (`drops.<channel>`, only where some were), the nodes' input timeouts
//! (`timeouts`, the growth of the counters in their `health` reports, so up to one report
//! period late), the e-stop engagements (`estops`, released-to-engaged changes per side) and
//! whether it was engaged at the start (`estop_at_start`), and its task, outcome, start, stop
//! and duration. An episode whose start this recorder did not see (its predecessor's) has no
//! health: `health = "partial: started under the previous recorder"`.

use std::collections::{BTreeMap, HashMap};

use teleop_msgs::{EStop, Episode, Message, NodeHealth};
use teleop_recording::{Change, EpisodeSpan, Episodes, Recorder, RecordingError};

/// Name of the metadata record of episode `index`.
fn record_name(index: u32) -> String {
    format!("episode.{index}")
}

/// What the recorder's taps had counted when an episode started.
struct Snapshot {
    messages: Vec<u64>,
    dropped: Vec<u64>,
    timeouts: u64,
    estops: u64,
    estop_engaged: bool,
}

/// The episodes of one recording session and the counters their health is computed from.
#[derive(Default)]
pub struct Book {
    episodes: Episodes,
    /// Per tap: samples written.
    messages: Vec<u64>,
    /// Per node: its last reported timeout count.
    node_timeouts: HashMap<String, u64>,
    /// The growth of every node's timeouts seen so far.
    timeouts: u64,
    /// Per `estop` tap (one per side): engaged now.
    estop_engaged: HashMap<usize, bool>,
    /// Released-to-engaged changes seen so far.
    estops: u64,
    /// Marks written with what they changed.
    marks: u64,
    /// Marks that changed nothing.
    ignored: u64,
    /// Marks in the file, not yet applied.
    pending: Vec<Episode>,
    at_start: Option<Snapshot>,
    /// The last record written: what a later DISCARD of that episode marks.
    last_written: Option<(u32, BTreeMap<String, String>)>,
}

impl Book {
    /// A book that continues `episodes` (a predecessor's, read back from its files).
    pub fn continuing(episodes: Episodes) -> Self {
        Self {
            episodes,
            ..Self::default()
        }
    }

    /// Counts one sample written by tap `tap` (of the contract topic `topic`) and takes what it
    /// means for the episodes: marks (applied by [`settle`](Self::settle)), health reports,
    /// e-stops. Call it only for samples that are in the file.
    pub fn observe(&mut self, tap: usize, topic: &str, payload: &[u8]) {
        if self.messages.len() <= tap {
            self.messages.resize(tap + 1, 0);
        }
        self.messages[tap] += 1;
        if topic == Episode::TOPIC {
            if let Ok(mark) = Episode::from_bytes(payload) {
                self.pending.push(mark);
            }
        } else if topic == NodeHealth::TOPIC {
            if let Ok(h) = NodeHealth::from_bytes(payload) {
                match self.node_timeouts.get_mut(&h.name()) {
                    // A restarted node counts from 0 again.
                    Some(last) => {
                        self.timeouts += h.timeouts.checked_sub(*last).unwrap_or(h.timeouts);
                        *last = h.timeouts;
                    }
                    // The first report only sets where the node's count stands.
                    None => {
                        self.node_timeouts.insert(h.name(), h.timeouts);
                    }
                }
            }
        } else if topic == EStop::TOPIC {
            if let Ok(e) = EStop::from_bytes(payload) {
                let engaged = e.engaged == 1;
                let was = self.estop_engaged.insert(tap, engaged).unwrap_or(false);
                if engaged && !was {
                    self.estops += 1;
                }
            }
        }
    }

    /// Applies the marks observed since the last call and writes what they changed: an
    /// episode's record when it closes or is discarded, then closes and syncs the chunk.
    /// `channels[i]` and `dropped[i]` are tap `i`'s channel and its drops so far. True when a
    /// mark was taken (the health report should go out now).
    pub fn settle(
        &mut self,
        channels: &[&str],
        dropped: &[u64],
        rec: &mut Recorder,
    ) -> Result<bool, Box<RecordingError>> {
        if self.pending.is_empty() {
            return Ok(false);
        }
        for mark in std::mem::take(&mut self.pending) {
            let mut ignored = false;
            for change in self.episodes.apply(&mark) {
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
                            estop_engaged: self.estop_engaged.values().any(|&e| e),
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
                                if was_open {
                                    self.at_start = None;
                                }
                                let span = self.episodes.closed().iter().find(|s| s.index == index);
                                span.map(identity).unwrap_or_default()
                            }
                        };
                        fields.insert("outcome".into(), "discarded".into());
                        self.write(rec, index, fields)?;
                    }
                    Change::Ignored(why) => {
                        tracing::warn!("episode mark ignored: {why}");
                        ignored = true;
                    }
                }
            }
            if ignored {
                self.ignored += 1;
            } else {
                self.marks += 1;
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
        rec.add_metadata_once(&record_name(index), fields.clone())?;
        rec.flush()?;
        self.last_written = Some((index, fields));
        Ok(())
    }

    /// The closed episode's record: its identity and health.
    fn health(
        &mut self,
        span: &EpisodeSpan,
        channels: &[&str],
        dropped: &[u64],
    ) -> BTreeMap<String, String> {
        let mut fields = identity(span);
        let Some(start) = self.at_start.take() else {
            fields.insert(
                "health".into(),
                "partial: started under the previous recorder".into(),
            );
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
        fields.insert("estop_at_start".into(), start.estop_engaged.to_string());
        fields
    }

    /// The episode still open, if any: its number and task (the recorder says so when it
    /// stops).
    pub fn open(&self) -> Option<(u32, &str)> {
        self.episodes.open().map(|o| (o.index, o.task.as_str()))
    }

    /// The values the recorder reports in its health: the current (or last) episode's number,
    /// whether it is open, its seconds so far (or its length), the episodes kept, the marks
    /// taken and the marks ignored (`teleop episode` waits for one of the two to count its
    /// mark).
    pub fn details(&self, now_ns: u64) -> [(&'static str, f64); 6] {
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
            ("episode_ignored", self.ignored as f64),
        ]
    }
}

/// The fields that name an episode: index, task, outcome, times.
fn identity(span: &EpisodeSpan) -> BTreeMap<String, String> {
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
