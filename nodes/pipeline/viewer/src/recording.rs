//! The recording source: a recording's messages in log-time order, on the recording's own
//! timelines (`recording_time` from each message's log time, `sample_time` from its stamp,
//! both counted from the recording's first message), with the robot hand of the profile the
//! recorder embedded ([`recorded_profile`]) unless the caller gives one.

use std::collections::BTreeSet;
use std::io::{IsTerminal, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use teleop_hand_profile::{HandProfile, RECORDING_METADATA};
use teleop_recording::{info, read_messages, Filter, RecordingInfo};
use teleop_runtime::{split, Namespace};

use crate::content::{Scene, SceneConfig};
use crate::kinematics::RobotHand;
use crate::logger::RerunLogger;
use crate::sample::Sample;

/// What was shown of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RecordingSummary {
    /// Messages read.
    pub messages: u64,
    /// Frames logged (the rest was decimated).
    pub frames: u64,
    /// Messages of another namespace or of topics the viewer does not show, or that did not
    /// decode.
    pub skipped: u64,
}

/// A progress bar on stderr: redrawn in place on a terminal, a line per quarter otherwise.
pub struct Progress {
    total: u64,
    done: u64,
    shown: u64,
    terminal: bool,
    enabled: bool,
    last_draw: Option<Instant>,
    label: String,
}

impl Progress {
    /// A bar for `total` steps, labelled; disabled bars print nothing.
    pub fn new(label: impl Into<String>, total: u64, enabled: bool) -> Self {
        Self {
            total: total.max(1),
            done: 0,
            shown: u64::MAX,
            terminal: std::io::stderr().is_terminal(),
            enabled,
            last_draw: None,
            label: label.into(),
        }
    }

    /// The bar for `done` of `total` steps, `width` characters wide.
    pub fn render(label: &str, done: u64, total: u64, width: usize) -> String {
        let total = total.max(1);
        let done = done.min(total);
        let filled = (done as u128 * width as u128 / total as u128) as usize;
        format!(
            "{label} [{}{}] {:>3}% {done}/{total}",
            "#".repeat(filled),
            " ".repeat(width - filled),
            done * 100 / total
        )
    }

    /// One step done.
    pub fn step(&mut self) {
        self.done += 1;
        if !self.enabled {
            return;
        }
        let percent = self.done.min(self.total) * 100 / self.total;
        if self.terminal {
            let due = self
                .last_draw
                .is_none_or(|t| t.elapsed() >= Duration::from_millis(100));
            if due && percent != self.shown {
                self.draw(percent);
            }
        } else if percent / 25 != self.shown / 25 || self.shown == u64::MAX {
            self.draw(percent);
        }
    }

    fn draw(&mut self, percent: u64) {
        self.shown = percent;
        self.last_draw = Some(Instant::now());
        let bar = Self::render(&self.label, self.done, self.total, 30);
        let mut err = std::io::stderr().lock();
        let _ = if self.terminal {
            write!(err, "\r{bar}")
        } else {
            writeln!(err, "{bar}")
        };
        let _ = err.flush();
    }

    /// Draws the final state (and ends the line on a terminal).
    pub fn finish(&mut self) {
        if !self.enabled || (!self.terminal && self.shown == 100 && self.done == self.total) {
            return;
        }
        self.total = self.done.max(1);
        let bar = Self::render(&self.label, self.done, self.total, 30);
        let mut err = std::io::stderr().lock();
        let _ = if self.terminal {
            writeln!(err, "\r{bar}")
        } else {
            writeln!(err, "{bar}")
        };
    }
}

/// The hand profile embedded in a recording's metadata, `None` when it has none (recordings
/// made before profiles existed). An embedded profile that does not load is an error naming
/// the recording, the embedded file, the line and the field.
pub fn recorded_profile(path: &Path, about: &RecordingInfo) -> anyhow::Result<Option<RobotHand>> {
    let recording = path.display().to_string();
    let Some(profile) = HandProfile::from_recording_metadata(&recording, &about.metadata) else {
        return Ok(None);
    };
    let profile = profile.context(
        "the recording's hand profile does not load; pass --profile FILE to use another",
    )?;
    let source = format!("{recording} (metadata {RECORDING_METADATA})");
    Ok(Some(RobotHand::new(profile, source)))
}

/// Logs the messages of the recording at `path` that `filter` selects, of the channels of
/// `namespace` (`NS/<topic>`; `None`: the channels without a namespace), to `logger`;
/// `config.time_origin_ns` is replaced by the recording's first log time (so times match
/// `teleop recordings info` and `teleop replay --start`). The robot hand is `robot` when
/// given, else the profile embedded in the recording, else the builtin profile of the first
/// hand sample's model. Shows a progress bar on stderr when `progress` is set.
pub fn view_recording(
    path: &Path,
    filter: &Filter,
    namespace: Option<&Namespace>,
    logger: &RerunLogger,
    config: SceneConfig,
    robot: Option<RobotHand>,
    progress: bool,
) -> anyhow::Result<RecordingSummary> {
    let about = info(path)?;
    check_namespace(path, &about, namespace)?;
    let robot = match robot {
        Some(robot) => Some(robot),
        None => recorded_profile(path, &about)?,
    };
    let mut scene = Scene::new(
        SceneConfig {
            time_origin_ns: about.start_ns,
            ..config
        },
        robot,
    );
    logger.log_scene(&scene)?;
    let mut bar = Progress::new(
        "reading",
        expected_messages(&about, filter, namespace),
        progress,
    );
    let mut summary = RecordingSummary::default();
    for message in read_messages(path, filter)? {
        let message = message?;
        summary.messages += 1;
        bar.step();
        let topic = match split(&message.topic) {
            Some((ns, t)) if ns.as_ref() == namespace => t.name,
            _ => {
                summary.skipped += 1;
                continue;
            }
        };
        let Some(sample) = Sample::decode(topic, &message.payload) else {
            summary.skipped += 1;
            continue;
        };
        if let Some(frame) = scene.frame(&sample, message.log_time_ns) {
            logger.log_frame(&frame)?;
            summary.frames += 1;
        }
    }
    bar.finish();
    Ok(summary)
}

/// Fails, naming the namespaces there are, when the recording has channels but none in
/// `namespace` (a namespaced session viewed without `--namespace`, or a wrong one).
fn check_namespace(
    path: &Path,
    about: &RecordingInfo,
    namespace: Option<&Namespace>,
) -> anyhow::Result<()> {
    let present: BTreeSet<Option<Namespace>> = about
        .topics
        .iter()
        .filter_map(|t| split(&t.topic).map(|(ns, _)| ns))
        .collect();
    if present.is_empty() || present.contains(&namespace.cloned()) {
        return Ok(());
    }
    let name = |ns: &Option<Namespace>| match ns {
        Some(ns) => format!("`{ns}`"),
        None => "none (no --namespace)".to_string(),
    };
    anyhow::bail!(
        "{}: no channels in namespace {}; its namespaces: {}",
        path.display(),
        name(&namespace.cloned()),
        present.iter().map(name).collect::<Vec<_>>().join(", ")
    )
}

/// About how many messages `filter` selects in `namespace` (for the progress bar): the
/// recording's count, scaled by the share of its duration the time window covers, and by the
/// topics selected.
fn expected_messages(about: &RecordingInfo, filter: &Filter, namespace: Option<&Namespace>) -> u64 {
    let topics: u64 = about
        .topics
        .iter()
        .filter(|t| {
            split(&t.topic).is_some_and(|(ns, _)| ns.as_ref() == namespace)
                && filter
                    .topics
                    .as_ref()
                    .is_none_or(|want| want.contains(&t.topic))
        })
        .map(|t| t.messages)
        .sum();
    let total = about.duration.as_secs_f64();
    if total <= 0.0 {
        return topics;
    }
    let from = filter.start.map_or(0.0, |d| d.as_secs_f64()).min(total);
    let to = filter
        .end
        .map_or(total, |d| d.as_secs_f64())
        .clamp(from, total);
    (topics as f64 * (to - from) / total).round() as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_bar_text() {
        assert_eq!(
            Progress::render("reading", 5, 10, 10),
            "reading [#####     ]  50% 5/10"
        );
        assert_eq!(Progress::render("x", 12, 10, 4), "x [####] 100% 10/10");
        assert_eq!(Progress::render("x", 0, 0, 2), "x [  ]   0% 0/1");
    }
}
