//! `teleop export`: recordings' episodes to a LeRobot v3.0 dataset.
//!
//! Owns what the dataset takes from a recording: which topics make which features and with
//! which names (from the hand profile), which episodes go in (kept, optionally only the
//! successful ones, and not those whose key topics ran too slowly), and the reading of the
//! recording, streamed once in log-time order. The resampling, statistics and files are
//! `teleop-dataset`'s; the episodes' rule is `teleop-recording`'s.
//!
//! # The rate rule
//!
//! An episode is refused when one of its key topics (`glove/state`, `hand/state`,
//! `hand/command` of every side) has, between the episode's START and STOP stamps, a rate
//! below `--min-rate-ratio` × the rate that topic had over the whole recording (messages over
//! log time, as `teleop recordings info` prints it). The recording's own rate is the reference
//! because it is what the same session achieved when nothing went wrong, whatever the hand or
//! the configuration; a slow loop, a stalled node or a lost link during the episode shows as a
//! lower rate.
//!
//! # Recordings of one session
//!
//! The files of one recorder session (the rotated parts of a recording, and the files of a
//! recorder restarted by `teleop launch`: the same `recorder_session` metadata record) are one
//! recording to the export, read in the order they started: an episode started in one file and
//! stopped or discarded in the next is one episode, its frames taken from both. Every other
//! file is a recording of its own.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use teleop_dataset::{
    check,
    resample::{Event, Resampler, Window},
    DatasetSpec, DatasetWriter, EpisodeBuffer, FeatureSpec,
};
use teleop_hand_profile::{HandProfile, TipSensor, GLOVE_CHANNELS, GLOVE_FINGERS};
use teleop_msgs::{
    episode_outcome, GloveForceCommand, GloveState, HandCommand, HandState, Message, Tactile,
};
use teleop_recording::{
    info as recording_info, read_episodes, read_messages, Filter, RecordingInfo,
};
use teleop_runtime::{qualified, split, Namespace};

/// The export's choices (`teleop export` arguments).
pub struct ExportOptions {
    /// Frames per second.
    pub fps: u32,
    /// The dataset's folder.
    pub out: PathBuf,
    /// Only episodes stopped with `--success`.
    pub only_success: bool,
    /// Refuse an episode whose key topic's rate is below this fraction of the recording's.
    pub min_rate_ratio: f64,
    /// Add `glove.force_command`.
    pub with_force_command: bool,
    /// The sides to export (none: the recording's).
    pub namespaces: Vec<Namespace>,
    /// The hand profile (none: the recording's).
    pub profile: Option<PathBuf>,
}

/// What one side's topics give a frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Source {
    Glove,
    State,
    Tactile,
    Command,
    Force,
}

impl Source {
    fn topic(self) -> &'static str {
        match self {
            Source::Glove => GloveState::TOPIC,
            Source::State => HandState::TOPIC,
            Source::Tactile => Tactile::TOPIC,
            Source::Command => HandCommand::TOPIC,
            Source::Force => GloveForceCommand::TOPIC,
        }
    }

    /// The topics whose rate decides whether an episode is kept.
    fn is_key(self) -> bool {
        matches!(self, Source::Glove | Source::State | Source::Command)
    }
}

/// One resampler slot: a topic of one side.
struct Slot {
    source: Source,
    topic: String,
    names: Vec<String>,
}

/// What one recording gives the dataset: the features, and the slots that fill them in order.
struct Layout {
    spec: DatasetSpec,
    slots: Vec<Slot>,
    joints: usize,
    efforts: bool,
    tips: Vec<TipSensor>,
}

/// The values one fingertip sensor contributes, by name.
fn tip_fields(sensor: TipSensor) -> &'static [&'static str] {
    match sensor {
        TipSensor::Revo2 => &["normal_n", "tangential_n"],
        TipSensor::Pst => &["pressure"],
        TipSensor::Biotac | TipSensor::None => &["normal_n"],
    }
}

impl Layout {
    fn new(
        profile: &HandProfile,
        sides: &[Option<Namespace>],
        efforts: bool,
        opts: &ExportOptions,
    ) -> Self {
        let tips: Vec<TipSensor> = profile.fingertips().map(|f| f.tip_sensor).collect();
        let prefix =
            |side: &Option<Namespace>| side.as_ref().map_or(String::new(), |ns| format!("{ns}/"));
        let slot = |side: &Option<Namespace>, source: Source, names: Vec<String>| Slot {
            source,
            topic: qualified(side.as_ref(), source.topic()),
            names,
        };
        let mut slots = Vec::new();
        for side in sides {
            let p = prefix(side);
            let glove = GLOVE_CHANNELS
                .iter()
                .map(|c| format!("{p}glove.{c}.pos"))
                .collect();
            slots.push(slot(side, Source::Glove, glove));
            let mut state: Vec<String> = Vec::new();
            for kind in ["pos", "vel", "effort"] {
                if kind == "effort" && !efforts {
                    continue;
                }
                state.extend(profile.joint_names().map(|j| format!("{p}{j}.{kind}")));
            }
            slots.push(slot(side, Source::State, state));
            if !tips.is_empty() {
                let p = &p;
                let names = profile
                    .fingertips()
                    .flat_map(|f| {
                        tip_fields(f.tip_sensor)
                            .iter()
                            .map(move |field| format!("{p}{}.tip.{field}", f.name))
                    })
                    .collect();
                slots.push(slot(side, Source::Tactile, names));
            }
        }
        let state_slots = slots.len();
        for side in sides {
            let p = prefix(side);
            let names = profile
                .joint_names()
                .map(|j| format!("{p}{j}.target"))
                .collect();
            slots.push(slot(side, Source::Command, names));
        }
        if opts.with_force_command {
            for side in sides {
                let p = prefix(side);
                let names = GLOVE_FINGERS
                    .iter()
                    .map(|f| format!("{p}glove.{f}.force"))
                    .collect();
                slots.push(slot(side, Source::Force, names));
            }
        }
        let names_of = |range: &[Slot]| range.iter().flat_map(|s| s.names.clone()).collect();
        let mut features = vec![
            FeatureSpec {
                key: "observation.state".into(),
                names: names_of(&slots[..state_slots]),
            },
            FeatureSpec {
                key: "action".into(),
                names: names_of(&slots[state_slots..state_slots + sides.len()]),
            },
        ];
        if opts.with_force_command {
            features.push(FeatureSpec {
                key: "glove.force_command".into(),
                names: names_of(&slots[state_slots + sides.len()..]),
            });
        }
        let robot_type = if sides.len() > 1 {
            format!("{}_bimanual", profile.name)
        } else {
            profile.name.clone()
        };
        Self {
            spec: DatasetSpec {
                fps: opts.fps,
                robot_type,
                features,
            },
            slots,
            joints: profile.joints.len(),
            efforts,
            tips,
        }
    }

    /// A sample's values for its slot and its stamp (`header.stamp_ns`), or why it cannot give
    /// them.
    fn values(&self, source: Source, payload: &[u8], out: &mut Vec<f32>) -> Result<u64, String> {
        out.clear();
        let bad = |e: &dyn std::fmt::Debug| format!("does not decode: {e:?}");
        let n = self.joints;
        match source {
            Source::Glove => {
                let s = GloveState::from_bytes(payload).map_err(|e| bad(&e))?;
                out.extend_from_slice(&s.position);
                Ok(s.header.stamp_ns)
            }
            Source::State => {
                let s = HandState::from_bytes(payload).map_err(|e| bad(&e))?;
                if usize::from(s.joint_count) < n {
                    return Err(format!(
                        "carries {} joints, the hand profile has {n}",
                        s.joint_count
                    ));
                }
                let joints = &s.joints[..n];
                out.extend(joints.iter().map(|j| j.position));
                out.extend(joints.iter().map(|j| j.speed));
                if self.efforts {
                    out.extend(joints.iter().map(|j| j.effort));
                }
                Ok(s.header.stamp_ns)
            }
            Source::Tactile => {
                let s = Tactile::from_bytes(payload).map_err(|e| bad(&e))?;
                for (tip, sensor) in s.fingertips.iter().zip(&self.tips) {
                    match sensor {
                        TipSensor::Revo2 => out.extend([tip.normal_n, tip.tangential_n]),
                        TipSensor::Pst => out.push(tip.pressure as f32),
                        TipSensor::Biotac | TipSensor::None => out.push(tip.normal_n),
                    }
                }
                Ok(s.header.stamp_ns)
            }
            Source::Command => {
                let s = HandCommand::from_bytes(payload).map_err(|e| bad(&e))?;
                if usize::from(s.joint_count) < n {
                    return Err(format!(
                        "carries {} joints, the hand profile has {n}",
                        s.joint_count
                    ));
                }
                out.extend(s.joints[..n].iter().map(|j| j.target));
                Ok(s.header.stamp_ns)
            }
            Source::Force => {
                let s = GloveForceCommand::from_bytes(payload).map_err(|e| bad(&e))?;
                out.extend(s.force.iter().map(|&f| f32::from(f)));
                Ok(s.header.stamp_ns)
            }
        }
    }
}

/// The sides of a recording: those given, else every namespace with a `hand/state` channel (the
/// topics without one when they have it).
fn sides_of(info: &RecordingInfo, given: &[Namespace]) -> Vec<Option<Namespace>> {
    if !given.is_empty() {
        return given.iter().cloned().map(Some).collect();
    }
    let mut sides: Vec<Option<Namespace>> = info
        .topics
        .iter()
        .filter_map(|t| split(&t.topic))
        .filter(|(_, topic)| topic.name == HandState::TOPIC)
        .map(|(ns, _)| ns)
        .collect();
    sides.sort_by(|a, b| {
        a.as_ref()
            .map(Namespace::as_str)
            .cmp(&b.as_ref().map(Namespace::as_str))
    });
    sides.dedup();
    sides
}

/// Whether the hand measures efforts: the first `hand/state` sample of the first side has a
/// finite effort (the Revo2 reports NaN: no column of NaN goes into the dataset).
fn measures_efforts(path: &Path, topic: &str, joints: usize) -> anyhow::Result<bool> {
    let first = read_messages(path, &Filter::topics([topic]))?
        .next()
        .transpose()?;
    Ok(first
        .and_then(|m| HandState::from_bytes(&m.payload).ok())
        .is_some_and(|s| {
            s.joints[..joints.min(s.joints.len())]
                .iter()
                .any(|j| j.effort.is_finite())
        }))
}

/// A recording's file and what it holds.
type RecordingFile = (PathBuf, RecordingInfo);

/// The recordings grouped into sessions (see the module's documentation): each group's files
/// in the order they started, the groups in the order their first files were given.
fn sessions(recordings: &[PathBuf]) -> anyhow::Result<Vec<Vec<RecordingFile>>> {
    let mut groups: Vec<(Option<String>, Vec<RecordingFile>)> = Vec::new();
    for path in recordings {
        let info = recording_info(path)?;
        let session = info
            .metadata
            .iter()
            .find(|(name, _)| name == teleop_recorder::SESSION_METADATA)
            .map(|(_, fields)| format!("{fields:?}"));
        match groups
            .iter_mut()
            .find(|(s, _)| session.is_some() && *s == session)
        {
            Some((_, files)) => files.push((path.clone(), info)),
            None => groups.push((session, vec![(path.clone(), info)])),
        }
    }
    Ok(groups
        .into_iter()
        .map(|(_, mut files)| {
            files.sort_by_key(|(_, info)| info.start_ns);
            files
        })
        .collect())
}

/// `teleop export`: every recording's episodes into the dataset at `opts.out`, in one commit.
pub fn run(recordings: &[PathBuf], opts: &ExportOptions) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(!recordings.is_empty(), "no recording given");
    anyhow::ensure!(
        (0.0..=1.0).contains(&opts.min_rate_ratio),
        "--min-rate-ratio {} is not between 0 and 1",
        opts.min_rate_ratio
    );
    let mut writer: Option<DatasetWriter> = None;
    let mut first: Option<(PathBuf, DatasetSpec)> = None;
    let mut exported = 0u64;
    let mut refused = 0u64;
    for group in sessions(recordings)? {
        let (path, info) = &group[0];
        let sides = sides_of(info, &opts.namespaces);
        anyhow::ensure!(
            !sides.is_empty(),
            "{}: no hand/state channel: nothing to export",
            path.display()
        );
        for side in &sides {
            let topic = qualified(side.as_ref(), HandState::TOPIC);
            anyhow::ensure!(
                info.topics.iter().any(|t| t.topic == topic),
                "{}: no channel {topic} (--namespace names a side the recording does not have)",
                path.display()
            );
        }
        let first_command: Vec<_> = read_messages(path, &Filter::topics([HandCommand::TOPIC]))?
            .take(1)
            .collect::<Result<_, _>>()?;
        let profile =
            crate::recordings::recording_profile(path, opts.profile.as_deref(), &first_command)?;
        let state_topic = qualified(sides[0].as_ref(), HandState::TOPIC);
        let efforts = measures_efforts(path, &state_topic, profile.joints.len())?;
        let layout = Layout::new(&profile, &sides, efforts, opts);
        match &first {
            None => first = Some((path.clone(), layout.spec.clone())),
            Some((first_path, spec)) if *spec != layout.spec => anyhow::bail!(
                "{}: other features than {} ({}): export them to separate datasets",
                path.display(),
                first_path.display(),
                spec_difference(spec, &layout.spec)
            ),
            Some(_) => {}
        }
        if writer.is_none() {
            writer = Some(DatasetWriter::open(&opts.out, layout.spec.clone())?);
        }
        let Some(w) = writer.as_mut() else {
            anyhow::bail!("the dataset writer did not open");
        };
        let (e, r) = export_recording(&group, &layout, opts, w)
            .with_context(|| format!("exporting {}", path.display()))?;
        exported += e;
        refused += r;
    }
    let Some(w) = writer else {
        anyhow::bail!("no recording to export");
    };
    w.commit()?;
    if exported == 0 {
        out!("no episode exported: {} is as it was", opts.out.display())?;
        return Ok(ExitCode::FAILURE);
    }
    let summary = check(&opts.out)?;
    out!(
        "{}: {} episodes exported, {} refused; the dataset now holds {} episodes, {} frames, {} tasks at {} fps",
        opts.out.display(),
        exported,
        refused,
        summary.total_episodes,
        summary.total_frames,
        summary.total_tasks,
        opts.fps
    )?;
    Ok(ExitCode::SUCCESS)
}

/// The rate rule (see the module's documentation): the first key topic whose rate within an
/// episode of `seconds`, from its `samples`, is below `ratio` × its rate over the recording
/// (`reference`, `None` for a topic that is not a key topic), said with both rates.
fn too_slow<'a>(
    topics: impl Iterator<Item = &'a str>,
    samples: &[u64],
    reference: &[Option<f64>],
    seconds: f64,
    ratio: f64,
) -> Option<String> {
    topics
        .zip(samples)
        .zip(reference)
        .find_map(|((topic, &n), reference)| {
            let reference = (*reference)?;
            let rate = if seconds > 0.0 {
                n as f64 / seconds
            } else {
                0.0
            };
            (rate < ratio * reference).then(|| {
                format!(
                    "{topic} at {rate:.1} Hz, below {ratio} x the recording's {reference:.1} Hz"
                )
            })
        })
}

/// A topic's rate over a recording's files: its intervals between messages over their log
/// time, summed over the files (the time between two files is no time of the topic's).
fn recording_rate(files: &[RecordingFile], topic: &str) -> f64 {
    let (mut intervals, mut seconds) = (0u64, 0.0f64);
    for (_, info) in files {
        if let Some(t) = info.topics.iter().find(|t| t.topic == topic) {
            if t.rate_hz > 0.0 {
                let n = t.messages.saturating_sub(1);
                intervals += n;
                seconds += n as f64 / t.rate_hz;
            }
        }
    }
    if seconds > 0.0 {
        intervals as f64 / seconds
    } else {
        0.0
    }
}

/// The first difference between two recordings' features.
fn spec_difference(a: &DatasetSpec, b: &DatasetSpec) -> String {
    for (fa, fb) in a.features.iter().zip(&b.features) {
        if fa != fb {
            let i = (0..fa.names.len().max(fb.names.len()))
                .find(|&i| fa.names.get(i) != fb.names.get(i))
                .unwrap_or(0);
            return format!(
                "feature `{}`, name {i}: `{}` vs `{}`",
                fa.key,
                fa.names.get(i).map_or("(none)", String::as_str),
                fb.names.get(i).map_or("(none)", String::as_str)
            );
        }
    }
    format!("{} vs {} features", a.features.len(), b.features.len())
}

/// One recording's episodes (its files in order) into `writer`: (exported, refused).
fn export_recording(
    files: &[RecordingFile],
    layout: &Layout,
    opts: &ExportOptions,
    writer: &mut DatasetWriter,
) -> anyhow::Result<(u64, u64)> {
    let paths: Vec<&PathBuf> = files.iter().map(|(p, _)| p).collect();
    let episodes = read_episodes(&paths)?;
    let name = files[0].0.display();
    if let Some(open) = episodes.open() {
        out!(
            "{name}: episode {} (\"{}\") was never stopped: not exported",
            open.index,
            open.task
        )?;
    }
    let mut chosen = Vec::new();
    for span in episodes.closed() {
        if span.discarded {
            out!(
                "{name}: episode {} (\"{}\") discarded: not exported",
                span.index,
                span.task
            )?;
        } else if opts.only_success && span.outcome != episode_outcome::SUCCESS {
            out!(
                "{name}: episode {} (\"{}\") {}: not exported (--only-success)",
                span.index,
                span.task,
                span.label()
            )?;
        } else {
            chosen.push(span.clone());
        }
    }
    if chosen.is_empty() {
        return Ok((0, 0));
    }
    // Each key topic's rate over the whole recording (all its files): the rate rule's reference.
    let reference: Vec<Option<f64>> = layout
        .slots
        .iter()
        .map(|s| s.source.is_key().then(|| recording_rate(files, &s.topic)))
        .collect();
    let windows = chosen
        .iter()
        .map(|s| Window {
            start_ns: s.start_ns,
            stop_ns: s.stop_ns,
        })
        .collect();
    let widths: Vec<usize> = layout.slots.iter().map(|s| s.names.len()).collect();
    let mut resampler = Resampler::new(&widths, opts.fps, windows);
    let mut buffer = EpisodeBuffer::new(&layout.spec);
    let topics: Vec<String> = layout.slots.iter().map(|s| s.topic.clone()).collect();
    let mut values = Vec::new();
    let (mut exported, mut refused) = (0, 0);
    let mut handle = |event: Event, buffer: &mut EpisodeBuffer| -> anyhow::Result<()> {
        match event {
            Event::Frame { values, .. } => buffer.push(&values),
            Event::WindowEnd { window, samples } => {
                let span = &chosen[window];
                let label = format!(
                    "{name}: episode {} (\"{}\", {})",
                    span.index,
                    span.task,
                    span.label()
                );
                let seconds = span.duration_s();
                let topics = layout.slots.iter().map(|s| s.topic.as_str());
                let slow = too_slow(topics, &samples, &reference, seconds, opts.min_rate_ratio);
                if let Some(why) = slow {
                    out!("{label}: refused: {why}")?;
                    refused += 1;
                } else if buffer.frames() == 0 {
                    let silent = layout
                        .slots
                        .iter()
                        .zip(&samples)
                        .find(|(_, &n)| n == 0)
                        .map_or("a topic".to_string(), |(s, _)| s.topic.clone());
                    out!("{label}: refused: no frame ({silent} has no sample in it)")?;
                    refused += 1;
                } else {
                    let written = writer.write_episode(&span.task, buffer)?;
                    out!(
                        "{label}: episode {} of the dataset, {} frames ({seconds:.1} s)",
                        written.episode_index,
                        written.length
                    )?;
                    exported += 1;
                }
                buffer.clear();
            }
        }
        Ok(())
    };
    let mut messages = Vec::with_capacity(files.len());
    for (path, _) in files {
        messages.push(read_messages(path, &Filter::topics(topics.clone()))?);
    }
    for msg in messages.into_iter().flatten() {
        let msg = msg?;
        let Some(slot) = layout.slots.iter().position(|s| s.topic == msg.topic) else {
            continue;
        };
        let source = layout.slots[slot].source;
        let stamp = layout
            .values(source, &msg.payload, &mut values)
            .map_err(|why| anyhow::anyhow!("{name}: a {} sample {why}", msg.topic))?;
        resampler.push(slot, stamp, msg.log_time_ns, &values);
        while let Some(event) = resampler.next_event() {
            handle(event, &mut buffer)?;
        }
    }
    resampler.finish();
    while let Some(event) = resampler.next_event() {
        handle(event, &mut buffer)?;
    }
    Ok((exported, refused))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_rule_refuses_the_first_key_topic_below_its_share() {
        let topics = ["glove/state", "hand/tactile", "hand/state"];
        let reference = [Some(250.0), None, Some(1000.0)];
        // 2 s: glove/state at 240 Hz (96 %), tactile silent (not a key topic), hand/state 950 Hz.
        assert_eq!(
            too_slow(topics.into_iter(), &[480, 0, 1900], &reference, 2.0, 0.9),
            None
        );
        // hand/state stalled: 800 Hz < 900 Hz.
        assert_eq!(
            too_slow(topics.into_iter(), &[480, 0, 1600], &reference, 2.0, 0.9).as_deref(),
            Some("hand/state at 800.0 Hz, below 0.9 x the recording's 1000.0 Hz")
        );
        // A ratio of 0 keeps everything.
        assert_eq!(
            too_slow(topics.into_iter(), &[0, 0, 0], &reference, 2.0, 0.0),
            None
        );
    }
}
