//! `teleop export`: recordings' episodes to a LeRobot v3.0 dataset.
//!
//! Owns what the dataset takes from a recording: which topics make which features and with
//! which names (from the hand profile), which episodes go in (kept, optionally only the
//! successful ones, and not those whose key topics ran too slowly, fell silent or gave values
//! that are not finite), and the reading of the recording, streamed once. The resampling, statistics and files are
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
//! lower rate. Within the episode the rate is taken over the intervals between its samples
//! (n - 1 over the first to the last stamp), so that a short episode is not judged by where its
//! ends fall between two samples. An episode shorter than one frame period is refused.
//!
//! # The gap rule
//!
//! A frame holds each topic's newest sample however old it is (zero-order hold), so a gap in a
//! recording (the tail a killed recorder lost, the time a restarted one took, a stalled node)
//! would become frames repeating stale values. An episode is therefore also refused when a key
//! topic is silent within it for longer than `--max-gap-ms` (default 100): the age its newest
//! sample reaches at some instant of the episode (counted from that sample's stamp, which may
//! be before the START). The message names the topic and the gap.
//!
//! # Values
//!
//! Efforts go into `observation.state` when the first `hand/state` sample of every side has a
//! finite effort for every joint (the Revo2 reports NaN). Any value that is not finite in an
//! episode's frames (an effort that turned NaN later, a broken sensor) refuses the episode,
//! naming the feature and the name: it would make the dataset's statistics NaN. A feature whose
//! topic the recording lacks (no `hand/tactile` for a hand with fingertip sensors, no
//! `glove/force_command` with `--with-force-command`) refuses the export once, before any
//! episode, naming it.
//!
//! # Recordings of one session
//!
//! The files of one recorder session (the rotated parts of a recording, and the files of a
//! recorder restarted by `teleop launch`: the same `recorder_session` metadata record) are one
//! recording to the export, read in the order they started (each file in its own order: log
//! time, or file order for a killed recorder's file that `recordings repair` saved): an
//! episode started in one file and stopped or discarded in the next is one episode, its frames
//! taken from both. Every other file is a recording of its own. A file's samples older than
//! what a frame already holds (a restarted recorder's history) are dropped by the resampler.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use teleop_dataset::{
    resample::{Event, Resampler, SlotInWindow, Window},
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

/// The export's choices: `teleop export`'s options (flattened into its arguments).
#[derive(clap::Args, Debug)]
pub struct ExportOptions {
    /// Frames per second.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub fps: u32,
    /// The dataset's folder (created, or appended to).
    #[arg(long)]
    pub out: PathBuf,
    /// Only episodes stopped with --success.
    #[arg(long)]
    pub only_success: bool,
    /// Refuse an episode whose glove/state, hand/state or hand/command rate within it is
    /// below this fraction of the topic's rate over the whole recording.
    #[arg(long, default_value_t = 0.9)]
    pub min_rate_ratio: f64,
    /// Refuse an episode in which glove/state, hand/state or hand/command is silent for
    /// longer than this (ms): its frames would repeat a stale value.
    #[arg(long, default_value_t = 100)]
    pub max_gap_ms: u64,
    /// Add the glove's force command (5 forces) as the feature `glove.force_command`.
    #[arg(long)]
    pub with_force_command: bool,
    /// The sides to export (repeatable); without it, every side with a hand/state channel.
    #[arg(long = "namespace", value_name = "NS")]
    pub namespaces: Vec<Namespace>,
    /// Hand profile (default: the one embedded in the recording, else the shipped profile of
    /// the recorded hand model).
    #[arg(long)]
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

    /// The first feature whose topic has no message in any of the recording's files, said with
    /// the feature and the name it would fill.
    fn missing_topic(&self, files: &[RecordingFile]) -> Option<String> {
        let slot = self.slots.iter().find(|slot| {
            !files.iter().any(|(_, info)| {
                info.topics
                    .iter()
                    .any(|t| t.topic == slot.topic && t.messages > 0)
            })
        })?;
        let feature = self
            .spec
            .features
            .iter()
            .find(|f| slot.names.first().is_some_and(|n| f.names.contains(n)))
            .map_or("a feature", |f| f.key.as_str());
        let why = match slot.source {
            Source::Tactile => " (the hand profile has fingertip sensors)",
            Source::Force => " (--with-force-command)",
            _ => "",
        };
        Some(format!(
            "no {} message: the dataset's `{feature}` needs it for `{}`{why}",
            slot.topic,
            slot.names.first().map_or("", String::as_str)
        ))
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

/// Whether the hands measure efforts: the first `hand/state` sample of every side (in the
/// session's first file) has a finite effort for every joint (the Revo2 reports NaN: no column
/// of NaN goes into the dataset). A later value that is not finite refuses its episode.
fn measures_efforts(
    path: &Path,
    sides: &[Option<Namespace>],
    joints: usize,
) -> anyhow::Result<bool> {
    for side in sides {
        let topic = qualified(side.as_ref(), HandState::TOPIC);
        let first = read_messages(path, &Filter::topics([topic]))?
            .next()
            .transpose()?;
        let finite = first
            .and_then(|m| HandState::from_bytes(&m.payload).ok())
            .is_some_and(|s| {
                s.joints[..joints.min(s.joints.len())]
                    .iter()
                    .all(|j| j.effort.is_finite())
            });
        if !finite {
            return Ok(false);
        }
    }
    Ok(true)
}

/// A recording's file and what it holds.
type RecordingFile = (PathBuf, RecordingInfo);
/// A metadata record's fields.
type Metadata = std::collections::BTreeMap<String, String>;

/// The recordings grouped into sessions (see the module's documentation): each group's files
/// in the order they started, the groups in the order their first files were given.
fn sessions(recordings: &[PathBuf]) -> anyhow::Result<Vec<Vec<RecordingFile>>> {
    let mut groups: Vec<(Option<Metadata>, Vec<RecordingFile>)> = Vec::new();
    let mut seen = Vec::with_capacity(recordings.len());
    for path in recordings {
        // The same file twice would export its episodes twice.
        let real = std::fs::canonicalize(path)
            .with_context(|| format!("{}: cannot open the recording", path.display()))?;
        anyhow::ensure!(
            !seen.contains(&real),
            "{} is given twice: each recording is exported once",
            path.display()
        );
        seen.push(real);
        let info = recording_info(path)?;
        let session = info
            .metadata
            .iter()
            .find(|(name, _)| name == teleop_recorder::SESSION_METADATA)
            .map(|(_, fields)| fields.clone());
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
        // The first side's command names the hand when no profile is embedded.
        let command_topic = qualified(sides[0].as_ref(), HandCommand::TOPIC);
        let first_command: Vec<_> = read_messages(path, &Filter::topics([command_topic]))?
            .take(1)
            .collect::<Result<_, _>>()?;
        let profile =
            crate::recordings::recording_profile(path, opts.profile.as_deref(), &first_command)?;
        let efforts = measures_efforts(path, &sides, profile.joints.len())?;
        let layout = Layout::new(&profile, &sides, efforts, opts);
        if let Some(missing) = layout.missing_topic(&group) {
            anyhow::bail!("{}: {missing}", path.display());
        }
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
    // The commit reads the new version back (`teleop_dataset::check`) before it swaps it in.
    let summary = w.commit()?;
    if exported == 0 {
        out!("no episode exported: {} is as it was", opts.out.display())?;
        return Ok(ExitCode::FAILURE);
    }
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

/// An episode of `seconds` shorter than one frame period at `fps`, said so (its one frame, or
/// none, would give no rate and no motion).
fn too_short(seconds: f64, fps: u32) -> Option<String> {
    (seconds < 1.0 / f64::from(fps.max(1)))
        .then(|| format!("shorter than one frame ({seconds:.3} s at {fps} fps)"))
}

/// The rate rule (see the module's documentation): the first key topic whose rate within an
/// episode of `seconds` (over its samples' intervals, else its samples over the episode's
/// length) is below `ratio` × its rate over the recording (`reference`, `None` for a topic that
/// is not a key topic), said with both rates.
fn too_slow<'a>(
    topics: impl Iterator<Item = &'a str>,
    seen: &[SlotInWindow],
    reference: &[Option<f64>],
    seconds: f64,
    ratio: f64,
) -> Option<String> {
    topics
        .zip(seen)
        .zip(reference)
        .find_map(|((topic, seen), reference)| {
            let reference = (*reference)?;
            let rate = seen.rate_hz().unwrap_or(if seconds > 0.0 {
                seen.samples as f64 / seconds
            } else {
                0.0
            });
            (rate < ratio * reference).then(|| {
                format!(
                    "{topic} at {rate:.1} Hz, below {ratio} x the recording's {reference:.1} Hz"
                )
            })
        })
}

/// The gap rule (see the module's documentation): the first key topic (`key`) silent within
/// the episode for longer than `max_gap_ns`, said with its gap.
fn too_silent<'a>(
    topics: impl Iterator<Item = &'a str>,
    seen: &[SlotInWindow],
    key: &[bool],
    max_gap_ns: u64,
) -> Option<String> {
    topics.zip(seen).zip(key).find_map(|((topic, seen), &key)| {
        (key && seen.longest_silence_ns > max_gap_ns).then(|| {
            format!(
                "{topic} silent for {:.0} ms, more than --max-gap-ms {}",
                seen.longest_silence_ns as f64 / 1e6,
                max_gap_ns / 1_000_000
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
    let key: Vec<bool> = layout.slots.iter().map(|s| s.source.is_key()).collect();
    let widths: Vec<usize> = layout.slots.iter().map(|s| s.names.len()).collect();
    let mut resampler = Resampler::new(&widths, opts.fps, windows);
    let mut buffer = EpisodeBuffer::new(&layout.spec);
    let topics: Vec<String> = layout.slots.iter().map(|s| s.topic.clone()).collect();
    let mut values = Vec::new();
    let (mut exported, mut refused) = (0, 0);
    let mut handle = |event: Event, buffer: &mut EpisodeBuffer| -> anyhow::Result<()> {
        match event {
            Event::Frame { values, .. } => buffer.push(&values),
            Event::WindowEnd { window, slots } => {
                let span = &chosen[window];
                let label = format!(
                    "{name}: episode {} (\"{}\", {})",
                    span.index,
                    span.task,
                    span.label()
                );
                let seconds = span.duration_s();
                let topics = || layout.slots.iter().map(|s| s.topic.as_str());
                let why = if let Some(short) = too_short(seconds, opts.fps) {
                    Some(short)
                } else if let Some(slow) =
                    too_slow(topics(), &slots, &reference, seconds, opts.min_rate_ratio)
                {
                    Some(slow)
                } else if let Some(silent) = too_silent(
                    topics(),
                    &slots,
                    &key,
                    opts.max_gap_ms.saturating_mul(1_000_000),
                ) {
                    Some(silent)
                } else if buffer.frames() == 0 {
                    let silent = layout
                        .slots
                        .iter()
                        .zip(&slots)
                        .find(|(_, seen)| seen.samples == 0)
                        .map_or("a topic".to_string(), |(s, _)| s.topic.clone());
                    Some(format!("no frame ({silent} has no sample in it)"))
                } else {
                    buffer.first_non_finite().map(|(f, name, frame)| {
                        let f = &layout.spec.features[f];
                        format!(
                            "feature `{}`, `{}`: a value that is not finite at frame {frame}",
                            f.key, f.names[name]
                        )
                    })
                };
                if let Some(why) = why {
                    out!("{label}: refused: {why}")?;
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
    // The files one after another: one reader (and its chunk index) open at a time.
    let filter = Filter::topics(topics);
    for (path, _) in files {
        for msg in read_messages(path, &filter)? {
            let msg = msg?;
            let Some(slot) = layout.slots.iter().position(|s| s.topic == msg.topic) else {
                continue;
            };
            let source = layout.slots[slot].source;
            let stamp = layout
                .values(source, &msg.payload, &mut values)
                .map_err(|why| {
                    anyhow::anyhow!("{}: a {} sample {why}", path.display(), msg.topic)
                })?;
            resampler.push(slot, stamp, msg.log_time_ns, &values);
            while let Some(event) = resampler.next_event() {
                handle(event, &mut buffer)?;
            }
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

    fn counts(samples: &[u64]) -> Vec<SlotInWindow> {
        samples
            .iter()
            .map(|&samples| SlotInWindow {
                samples,
                ..SlotInWindow::default()
            })
            .collect()
    }

    #[test]
    fn the_rate_rule_refuses_the_first_key_topic_below_its_share() {
        let topics = ["glove/state", "hand/tactile", "hand/state"];
        let reference = [Some(250.0), None, Some(1000.0)];
        // 2 s: glove/state at 240 Hz (96 %), tactile silent (not a key topic), hand/state 950 Hz.
        assert_eq!(
            too_slow(
                topics.into_iter(),
                &counts(&[480, 0, 1900]),
                &reference,
                2.0,
                0.9
            ),
            None
        );
        // hand/state stalled: 800 Hz < 900 Hz.
        assert_eq!(
            too_slow(
                topics.into_iter(),
                &counts(&[480, 0, 1600]),
                &reference,
                2.0,
                0.9
            )
            .as_deref(),
            Some("hand/state at 800.0 Hz, below 0.9 x the recording's 1000.0 Hz")
        );
        // A ratio of 0 keeps everything.
        assert_eq!(
            too_slow(
                topics.into_iter(),
                &counts(&[0, 0, 0]),
                &reference,
                2.0,
                0.0
            ),
            None
        );
    }

    #[test]
    fn a_short_episode_is_judged_by_its_samples_intervals() {
        // 49.9 ms of a 100 Hz topic whose samples fall at 10, 20, 30 and 40 ms: counted over
        // the episode's length, 80 Hz (refused at 0.9); over its 3 intervals, 100 Hz.
        let seen = SlotInWindow {
            samples: 4,
            stamps: Some((10_000_000, 40_000_000)),
            longest_silence_ns: 10_000_000,
        };
        let reference = [Some(100.0)];
        assert_eq!(
            too_slow(
                ["glove/state"].into_iter(),
                &[seen],
                &reference,
                0.0499,
                0.9
            ),
            None
        );
        // One sample: no interval; counted over the episode's length.
        let one = SlotInWindow {
            samples: 1,
            stamps: Some((10_000_000, 10_000_000)),
            longest_silence_ns: 10_000_000,
        };
        assert!(too_slow(["glove/state"].into_iter(), &[one], &reference, 0.0499, 0.9).is_some());
    }

    #[test]
    fn an_episode_shorter_than_one_frame_is_refused_with_that_reason() {
        assert_eq!(
            too_short(0.0, 30).as_deref(),
            Some("shorter than one frame (0.000 s at 30 fps)")
        );
        assert!(too_short(0.03, 30).is_some());
        assert_eq!(too_short(0.034, 30), None);
    }

    #[test]
    fn the_gap_rule_refuses_the_first_key_topic_silent_too_long() {
        let topics = ["glove/state", "hand/tactile", "hand/state"];
        let key = [true, false, true];
        let silent = |gaps: [u64; 3]| -> Vec<SlotInWindow> {
            gaps.iter()
                .map(|&ms| SlotInWindow {
                    longest_silence_ns: ms * 1_000_000,
                    ..SlotInWindow::default()
                })
                .collect()
        };
        let max = 100_000_000;
        // Tactile silent 5 s: not a key topic.
        assert_eq!(
            too_silent(topics.into_iter(), &silent([10, 5_000, 100]), &key, max),
            None
        );
        assert_eq!(
            too_silent(topics.into_iter(), &silent([10, 0, 600]), &key, max).as_deref(),
            Some("hand/state silent for 600 ms, more than --max-gap-ms 100")
        );
    }
}
