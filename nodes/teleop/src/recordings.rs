//! `teleop record | replay | recordings info | recordings repair | reprocess`.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use teleop_feedback::{Event, FeedbackEngine};
use teleop_hand_profile::{HandProfile, RECORDING_METADATA};
use teleop_msgs::{
    source_id, visit_topic, DeviceInfo, EStop, EStopAck, GloveDiagnostics, GloveForceCommand,
    GloveState, HandCommand, HandState, Message, NodeHealth, Tactile, TopicVisitor,
};
use teleop_recorder::{record, report, standard_metadata, Output, RecordOptions};
use teleop_recording::{
    info as recording_info, read_messages, repair_with, Filter, OwnedMessage, RecordedMessage,
    Recorder, RepairOptions, TopicId, WriterOptions,
};
use teleop_retarget::RetargetEngine;
use teleop_runtime::{now_ns, qualified, split, IpcSettings, Namespace, NodeRuntime, Publisher};

pub fn record_cmd(
    ipc: &IpcSettings,
    out: Option<PathBuf>,
    topics: Option<Vec<String>>,
    namespaces: Vec<Namespace>,
    duration: Option<Duration>,
) -> anyhow::Result<ExitCode> {
    let runtime = NodeRuntime::new("teleop-record", ipc)?;
    let options = RecordOptions {
        out: out.map_or_else(
            || Output::Timestamped(PathBuf::from("recordings")),
            Output::File,
        ),
        topics,
        namespaces,
        writer: WriterOptions::default(),
        metadata: standard_metadata(),
        duration,
        announce: false,
    };
    let recorded = record(&runtime, &options)?;
    out!("{}", report(&recorded.summary).trim_end())?;
    match recorded.stopped {
        None => Ok(ExitCode::SUCCESS),
        Some(why) => {
            eprintln!("error: recording stopped: {why}");
            Ok(ExitCode::FAILURE)
        }
    }
}

pub fn info_cmd(path: &Path) -> anyhow::Result<ExitCode> {
    let info = recording_info(path)?;
    out!("file       {}", info.path.display())?;
    out!(
        "state      {}",
        if info.complete {
            "complete"
        } else {
            "not finished (killed recorder?): `teleop recordings repair` makes it indexable"
        }
    )?;
    out!("duration   {:.3} s", info.duration.as_secs_f64())?;
    out!("messages   {}", info.messages)?;
    out!(
        "{:<28} {:<36} {:>9} {:>9} {:>7}",
        "TOPIC",
        "SCHEMA",
        "MESSAGES",
        "RATE_HZ",
        "DROPS"
    )?;
    for t in &info.topics {
        out!(
            "{:<28} {:<36} {:>9} {:>9.1} {:>7}",
            t.topic,
            t.schema_name,
            t.messages,
            t.rate_hz,
            t.drops.map_or("?".to_string(), |d| d.to_string())
        )?;
    }
    for t in info.topics.iter().filter(|t| t.converted_from.is_some()) {
        out!(
            "converted  {}: recorded in the layout of contract version {}, read as version {}",
            t.topic,
            t.converted_from.unwrap_or_default(),
            teleop_msgs::CONTRACT_VERSION
        )?;
    }
    for (name, fields) in &info.metadata {
        let shown: Vec<String> = fields
            .iter()
            .map(|(k, v)| {
                if v.len() > 60 {
                    format!("{k}=<{} bytes>", v.len())
                } else {
                    format!("{k}={v}")
                }
            })
            .collect();
        out!("metadata   {name}: {}", shown.join(", "))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `teleop recordings repair`: exit status 0 when everything the input holds was copied (a
/// killed recorder's unfinished last chunk aside), 1 when damaged parts were skipped.
pub fn repair_cmd(path: &Path, out: Option<PathBuf>, force: bool) -> anyhow::Result<ExitCode> {
    let out = out.unwrap_or_else(|| path.with_extension("repaired.mcap"));
    if !force && std::fs::symlink_metadata(&out).is_ok() {
        anyhow::bail!(
            "{} exists already: pass --force to replace it, or --out to write elsewhere",
            out.display()
        );
    }
    let report = repair_with(path, &out, RepairOptions { overwrite: force })?;
    for s in &report.skipped {
        let lost = if s.messages > 0 {
            format!(" ({} messages lost)", s.messages)
        } else {
            String::new()
        };
        if s.length > 0 {
            out!(
                "skipped    {} bytes at offset {}: {}{lost}",
                s.length,
                s.offset,
                s.what
            )?;
        } else {
            out!("skipped    {}{lost}", s.what)?;
        }
    }
    if let Some(why) = &report.stopped {
        out!("ended      {why}")?;
    }
    out!(
        "recovered {} messages into {}{}",
        report.messages,
        report.output.display(),
        if report.input_complete {
            " (the input was complete already)"
        } else {
            ""
        }
    )?;
    if report.skipped.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!(
            "error: {}: {} damaged parts skipped ({} messages known lost); everything else was \
             recovered",
            path.display(),
            report.skipped.len(),
            report.lost_messages()
        );
        Ok(ExitCode::FAILURE)
    }
}

/// Republishes recorded samples of one topic.
trait Replay {
    /// Sends one recorded payload, its header's times moved by `shift_ns` (modulo 2^64).
    fn send(&mut self, payload: &[u8], shift_ns: u64) -> anyhow::Result<()>;
}

struct TopicReplay<M: Message>(Publisher<M>);

impl<M: Message> Replay for TopicReplay<M> {
    fn send(&mut self, payload: &[u8], shift_ns: u64) -> anyhow::Result<()> {
        let mut msg = M::from_bytes(payload).map_err(|e| anyhow::anyhow!("{}: {e}", M::TOPIC))?;
        // The recorded header is kept but moved in time: latency accounting downstream sees the
        // recorded differences (stamp - origin), and freshness, which counts from the stamp,
        // sees a sample made as long before it is sent as it was before it was recorded.
        let header = msg.header_mut();
        header.stamp_ns = header.stamp_ns.wrapping_add(shift_ns);
        if header.origin_ns != 0 {
            header.origin_ns = header.origin_ns.wrapping_add(shift_ns);
        }
        self.0.send_as_is(&msg)?;
        Ok(())
    }
}

/// Makes a topic's replay publisher; `.2`: beside live writers (`--allow-live`).
struct MakeReplay<'a>(&'a NodeRuntime, Option<&'a Namespace>, bool);

impl TopicVisitor for MakeReplay<'_> {
    type Output = anyhow::Result<Box<dyn Replay>>;
    fn visit<M: Message>(self) -> Self::Output {
        let publisher = if self.2 {
            self.0.publisher_beside_live_in(self.1)?
        } else {
            self.0.publisher_in(self.1)?
        };
        Ok(Box::new(TopicReplay::<M>(publisher)))
    }
}

/// `--remap FROM=TO`: channels of namespace `from` are published in `to` (`None`: the topics
/// without a namespace).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Remap {
    pub from: Option<Namespace>,
    pub to: Option<Namespace>,
}

/// Parses `FROM=TO`, where either side may be empty for the topics without a namespace.
pub fn parse_remap(s: &str) -> Result<Remap, String> {
    let (from, to) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?}: expected FROM=TO, e.g. left=right or =left"))?;
    let side = |n: &str| {
        (!n.is_empty())
            .then(|| Namespace::new(n).map_err(|e| e.to_string()))
            .transpose()
    };
    Ok(Remap {
        from: side(from)?,
        to: side(to)?,
    })
}

/// The topics `teleop replay` publishes when `--topics` is not given: what the devices measure.
/// Commands (`hand/command`, `glove/force_command`), `estop` and node health are left out:
/// replayed into a live pipeline they would move the hand, set the glove's forces, engage or
/// release the e-stop, or make a hung node look alive to the supervisor.
pub const SENSOR_TOPICS: [&str; 5] = [
    GloveState::TOPIC,
    GloveDiagnostics::TOPIC,
    HandState::TOPIC,
    Tactile::TOPIC,
    DeviceInfo::TOPIC,
];

/// Replay settings.
pub struct ReplayOptions {
    pub speed: Option<f64>,
    pub looped: bool,
    /// The channels to replay (`None`: those of the [`SENSOR_TOPICS`]).
    pub topics: Option<Vec<String>>,
    pub start: Option<Duration>,
    pub end: Option<Duration>,
    /// Only channels of these namespaces (all when empty).
    pub namespaces: Vec<Namespace>,
    pub remap: Vec<Remap>,
    /// Publish into topics that a running process publishes too.
    pub allow_live: bool,
}

impl ReplayOptions {
    /// Where a channel is published: its topic's namespace (remapped) and plain topic name;
    /// `None` for a channel outside the contract or outside the chosen namespaces.
    fn target(&self, channel: &str) -> Option<(Option<Namespace>, &'static str)> {
        let (ns, topic) = split(channel)?;
        if !self.namespaces.is_empty() && !ns.as_ref().is_some_and(|n| self.namespaces.contains(n))
        {
            return None;
        }
        let ns = match self.remap.iter().find(|r| r.from == ns) {
            Some(r) => r.to.clone(),
            None => ns,
        };
        Some((ns, topic.name))
    }
}

/// The channels to replay out of those `recorded`: the ones `--topics` names (each must be a
/// topic of the contract, optionally in a namespace, that the recording has), else the
/// recording's channels of the [`SENSOR_TOPICS`].
fn replayed_channels(
    recorded: &[String],
    topics: Option<&[String]>,
) -> anyhow::Result<Vec<String>> {
    let Some(given) = topics else {
        return Ok(recorded
            .iter()
            .filter(|c| split(c).is_some_and(|(_, t)| SENSOR_TOPICS.contains(&t.name)))
            .cloned()
            .collect());
    };
    for name in given {
        let Some((_, topic)) = split(name) else {
            return Err(crate::inspect::unknown_topic(name));
        };
        anyhow::ensure!(
            ![EStop::TOPIC, EStopAck::TOPIC].contains(&topic.name),
            "--topics {name}: the e-stop is never replayed: a recorded release would release a \
             live pipeline and recorded acknowledgements would pose as its nodes (use `teleop \
             estop`)"
        );
        anyhow::ensure!(
            recorded.contains(name),
            "--topics {name}: not in the recording; its channels are: {}",
            recorded.join(", ")
        );
    }
    Ok(given.to_vec())
}

/// Publishers on `M`'s topic in a namespace, other than our own (none yet when asked).
struct LivePublishers<'a>(&'a NodeRuntime, Option<&'a Namespace>);

impl TopicVisitor for LivePublishers<'_> {
    type Output = usize;
    fn visit<M: Message>(self) -> usize {
        self.0
            .topic_ports_in::<M>(self.1)
            .map_or(0, |(publishers, _)| publishers)
    }
}

pub fn replay_cmd(
    ipc: &IpcSettings,
    path: &Path,
    opts: &ReplayOptions,
) -> anyhow::Result<ExitCode> {
    let info = recording_info(path)?;
    let recorded: Vec<String> = info.topics.iter().map(|t| t.topic.clone()).collect();
    let channels = replayed_channels(&recorded, opts.topics.as_deref())?;
    let targets: Vec<(String, Option<Namespace>, &'static str)> = channels
        .into_iter()
        .filter_map(|c| {
            let (ns, topic) = opts.target(&c)?;
            Some((c, ns, topic))
        })
        .collect();
    anyhow::ensure!(
        !targets.is_empty(),
        "{}: nothing to replay{}; its channels are: {} (name the ones to replay with --topics)",
        path.display(),
        if opts.topics.is_none() {
            format!(
                " (by default only the sensor topics: {})",
                SENSOR_TOPICS.join(", ")
            )
        } else {
            " in the chosen namespaces".to_string()
        },
        recorded.join(", ")
    );
    let runtime = NodeRuntime::new("teleop-replay", ipc)?;
    let live: Vec<String> = targets
        .iter()
        .filter(|(_, ns, topic)| {
            visit_topic(topic, LivePublishers(&runtime, ns.as_ref())).unwrap_or(0) > 0
        })
        .map(|(_, ns, topic)| qualified(ns.as_ref(), topic))
        .collect();
    if opts.allow_live && !live.is_empty() {
        eprintln!(
            "WARNING --allow-live: replaying into {} ({} topic(s) a running process publishes \
             too): replayed and live samples mix there",
            live.join(", "),
            live.len()
        );
    }
    if !opts.allow_live {
        anyhow::ensure!(
            live.is_empty(),
            "refusing to publish into {}: a running process publishes there (replayed samples \
             would mix with live ones); stop it, choose other topics with --topics, or pass \
             --allow-live",
            live.join(", ")
        );
    }
    let mut publishers: HashMap<String, Box<dyn Replay>> = HashMap::new();
    for (channel, ns, topic) in &targets {
        let replay = visit_topic(topic, MakeReplay(&runtime, ns.as_ref(), opts.allow_live))
            .ok_or_else(|| crate::inspect::unknown_topic(topic))??;
        publishers.insert(channel.clone(), replay);
    }
    teleop_runtime::install_stop_handlers();
    let filter = Filter {
        topics: Some(publishers.keys().cloned().collect()),
        start: opts.start,
        end: opts.end,
    };
    let total = info.duration.as_secs_f64();
    loop {
        let mut first_log: Option<u64> = None;
        let start = Instant::now();
        let mut sent = 0u64;
        let mut last_progress = Instant::now();
        for msg in read_messages(path, &filter)? {
            if teleop_runtime::stop_signal().is_some() {
                eprintln!();
                return Ok(ExitCode::SUCCESS);
            }
            let msg = msg?;
            let first = *first_log.get_or_insert(msg.log_time_ns);
            let at = Duration::from_nanos(msg.log_time_ns.saturating_sub(first));
            if let Some(speed) = opts.speed {
                teleop_runtime::sleep_until(start + at.div_f64(speed));
            }
            if let Some(replay) = publishers.get_mut(&msg.topic) {
                // The recorder's log time is its CLOCK_MONOTONIC receive time.
                replay.send(&msg.payload, now_ns().wrapping_sub(msg.log_time_ns))?;
                sent += 1;
            }
            if last_progress.elapsed() >= Duration::from_millis(100) {
                last_progress = Instant::now();
                progress(at.as_secs_f64(), total, sent);
            }
        }
        progress(total, total, sent);
        eprintln!();
        // An empty window would make `--loop` spin through nothing for ever.
        anyhow::ensure!(
            sent > 0,
            "{}: no message of the chosen channels between --start and --end",
            path.display()
        );
        if !opts.looped {
            break;
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn progress(at: f64, total: f64, sent: u64) {
    let share = if total > 0.0 {
        (at / total).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let filled = (share * 30.0).round() as usize;
    let mut err = std::io::stderr().lock();
    let _ = write!(
        err,
        "\r[{}{}] {:5.1}% {:.1}/{:.1} s {sent} messages",
        "=".repeat(filled),
        " ".repeat(30 - filled),
        share * 100.0,
        at,
        total
    );
    let _ = err.flush();
}

/// Configuration files for reprocessing.
pub struct ReprocessOptions {
    pub retarget_config: Option<PathBuf>,
    pub calibration: Option<PathBuf>,
    pub feedback_config: Option<PathBuf>,
    pub profile: Option<PathBuf>,
    /// The side to reprocess in a recording of several (`None`: the topics without one).
    pub namespace: Option<Namespace>,
}

/// The hand a recording was made with: `--profile` when given; else the profile embedded in the
/// recording's metadata; else (recordings made before profiles existed) the shipped profile of
/// the recorded hand commands' model. Says which on stderr.
pub(crate) fn recording_profile(
    input: &Path,
    explicit: Option<&Path>,
    messages: &[OwnedMessage],
) -> anyhow::Result<HandProfile> {
    if let Some(path) = explicit {
        return Ok(HandProfile::load(path)?);
    }
    let info = recording_info(input)?;
    let recording = input.display().to_string();
    if let Some(profile) = HandProfile::from_recording_metadata(&recording, &info.metadata) {
        let profile = profile?;
        eprintln!(
            "hand profile `{}` from the recording's metadata",
            profile.name
        );
        return Ok(profile);
    }
    let model = messages
        .iter()
        // Any side's command (a bimanual recording has only qualified ones).
        .filter(|m| split(&m.topic).is_some_and(|(_, t)| t.name == HandCommand::TOPIC))
        .find_map(|m| HandCommand::from_bytes(&m.payload).ok())
        .map(|c| c.hand_model)
        .ok_or_else(|| {
            anyhow::anyhow!(
                "{}: no `{RECORDING_METADATA}` metadata and no hand command to tell the hand by: \
                 pass --profile",
                input.display()
            )
        })?;
    let mut profile = HandProfile::builtin_for_model(model).ok_or_else(|| {
            anyhow::anyhow!(
                "{}: no `{RECORDING_METADATA}` metadata and no shipped profile for hand model {model}: \
                 pass --profile",
                input.display()
            )
        })?;
    // A recording that embeds no profile was made before profiles, and so before fingertip
    // retargeting: its commands came from the glove map.
    profile.retarget.mode = teleop_hand_profile::RetargetMode::Joint;
    eprintln!(
        "hand profile `{}` (shipped; the recording names none, its hand commands are model \
         {model}), retargeting mode `joint` as then",
        profile.name
    );
    Ok(profile)
}

/// Differences between recomputed and recorded outputs of one topic.
#[derive(Default)]
struct Comparison {
    recomputed: u64,
    matched: u64,
    differing: u64,
    max_difference: f64,
}

/// Runs the retargeting and force-feedback engines (the nodes' own code) over the recorded
/// inputs as fast as possible, writes inputs and recomputed outputs to `out`, and compares them
/// with the outputs in the recording. Deterministic: no clock, no randomness; every time comes
/// from the recording.
pub fn reprocess_cmd(
    input: &Path,
    out: &Path,
    opts: &ReprocessOptions,
) -> anyhow::Result<ExitCode> {
    // The output replaces any file of that name: never the input itself (same file by any path).
    if let (Ok(a), Ok(b)) = (std::fs::canonicalize(input), std::fs::canonicalize(out)) {
        anyhow::ensure!(
            a != b,
            "--out {} is the recording being reprocessed; write to another file",
            out.display()
        );
    }
    // The chosen side's messages, under their contract topic names.
    let mut messages: Vec<OwnedMessage> = Vec::new();
    let mut sides: Vec<String> = Vec::new();
    for msg in read_messages(input, &Filter::all())? {
        let mut msg = msg?;
        let Some((ns, topic)) = split(&msg.topic) else {
            continue;
        };
        if ns == opts.namespace {
            msg.topic = topic.name.to_string();
            messages.push(msg);
        } else if let Some(ns) = ns.map(|n| n.to_string()).filter(|n| !sides.contains(n)) {
            sides.push(ns);
        }
    }
    if messages.is_empty() && !sides.is_empty() {
        anyhow::bail!(
            "{}: nothing recorded {}; choose a side with --namespace ({})",
            input.display(),
            opts.namespace
                .as_ref()
                .map_or("without a namespace".to_string(), |ns| format!(
                    "in namespace `{ns}`"
                )),
            sides.join(", ")
        );
    }
    let profile = recording_profile(input, opts.profile.as_deref(), &messages)?;
    let loaded = teleop_retarget::load(
        opts.retarget_config.as_deref(),
        opts.calibration.as_deref(),
        Some(profile.clone()),
    )?;
    let rcfg = loaded.config;
    let (fcfg, _) = teleop_feedback::load(opts.feedback_config.as_deref(), Some(profile.clone()))?;
    let mut retarget = RetargetEngine::new(&rcfg, loaded.calibration, &profile)?;
    let mut feedback = FeedbackEngine::new(&fcfg, &profile)?;
    // The live node ticks from its own start, which the recording does not hold: here the
    // ticks start with the first hand sample, the first input feedback follows.
    let first_hand = messages
        .iter()
        .find(|m| m.topic == HandState::TOPIC || m.topic == Tactile::TOPIC);
    if let Some(m) = first_hand {
        feedback.start(m.log_time_ns);
    }

    let mut metadata = vec![(
        "reprocess".to_string(),
        BTreeMap::from([("input".to_string(), input.display().to_string())]),
    )];
    for (name, path) in [
        ("retarget_config", &opts.retarget_config),
        ("calibration", &opts.calibration),
        ("feedback_config", &opts.feedback_config),
        (RECORDING_METADATA, &opts.profile),
    ] {
        if let Some(m) = path.as_deref().and_then(teleop_recorder::file_metadata) {
            metadata.push((name.to_string(), m));
        }
    }
    let _ = std::fs::remove_file(out);
    let mut rec = Recorder::create(out, WriterOptions::default(), &metadata)?;
    let glove_id = rec.add_message_type::<GloveState>()?;
    let state_id = rec.add_message_type::<HandState>()?;
    let tactile_id = rec.add_message_type::<Tactile>()?;
    let estop_id = rec.add_message_type::<EStop>()?;
    let health_id = rec.add_message_type::<NodeHealth>()?;
    let mut outputs = Outputs::new(&mut rec, &messages)?;

    for msg in &messages {
        let t = msg.log_time_ns;
        // The engines' schedules up to `t`, in time order: the glove's watchdog (held
        // commands), feedback's ticks and its inputs' watchdogs.
        loop {
            let retarget_first = match (retarget.next_due(), feedback.next_due()) {
                (Some(r), Some(f)) => r <= f,
                (r, _) => r.is_some(),
            };
            if retarget_first {
                let Some((at, out)) = retarget.poll(t) else {
                    break;
                };
                if let Some(c) = out.command {
                    let c = outputs.command(&mut rec, c, at)?;
                    feedback.handle(&Event::Command(c), at);
                }
            } else {
                let Some((at, out)) = feedback.poll(t) else {
                    break;
                };
                if let Some(c) = out.command {
                    outputs.force(&mut rec, c, at)?;
                }
            }
        }
        let event = match msg.topic.as_str() {
            "glove/state" => {
                let s: GloveState = copy_input(&mut rec, glove_id, msg)?;
                if let Some(c) = retarget.on_glove(&s, t).command {
                    let c = outputs.command(&mut rec, c, t)?;
                    feedback.handle(&Event::Command(c), t);
                }
                // The operator's fingers, for the passivity observer (as the node takes them).
                feedback.handle(&Event::Glove(s), t);
                continue;
            }
            // The bridge's health gives the link's delay (freshness, passivity's `auto`).
            "health" => Event::Health(copy_input(&mut rec, health_id, msg)?),
            "hand/state" => Event::State(copy_input(&mut rec, state_id, msg)?),
            "hand/tactile" => Event::Tactile(copy_input(&mut rec, tactile_id, msg)?),
            "estop" => Event::EStop(copy_input(&mut rec, estop_id, msg)?),
            _ => continue,
        };
        if let Some(c) = feedback.handle(&event, t).command {
            outputs.force(&mut rec, c, t)?;
        }
    }
    let (cmds, forces) = (outputs.cmds, outputs.forces);
    let summary = rec.finish()?;
    out!(
        "reprocessed {} messages of {} into {}",
        messages.len(),
        input.display(),
        out.display()
    )?;
    out!(
        "{:<22} {:>10} {:>10} {:>8} {:>12}",
        "OUTPUT",
        "RECOMPUTED",
        "MATCHED",
        "DIFFER",
        "MAX_DIFF"
    )?;
    for (name, c) in [("hand/command", &cmds), ("glove/force_command", &forces)] {
        out!(
            "{name:<22} {:>10} {:>10} {:>8} {:>12.6}",
            c.recomputed,
            c.matched,
            c.differing,
            c.max_difference
        )?;
    }
    let _ = summary;
    Ok(ExitCode::SUCCESS)
}

/// A recorded input, decoded and written to the reprocessed recording at its log time.
fn copy_input<M: Message>(
    rec: &mut Recorder,
    id: TopicId,
    msg: &OwnedMessage,
) -> anyhow::Result<M> {
    let sample: M = msg
        .decode()
        .ok_or_else(|| anyhow::anyhow!("bad {} payload", M::TOPIC))?;
    rec.write(id, &RecordedMessage::from_sample(&sample, msg.log_time_ns))?;
    Ok(sample)
}

/// Reprocessing's outputs: stamped as their node stamps them, written as they are made (the file
/// stays in time order) and compared with the recorded outputs of the same origin.
struct Outputs {
    cmd_id: TopicId,
    force_id: TopicId,
    source: u32,
    seq: u64,
    /// The recorded outputs, by the origin stamp they descend from (first occurrence).
    recorded_cmds: HashMap<u64, HandCommand>,
    recorded_forces: HashMap<u64, GloveForceCommand>,
    cmds: Comparison,
    forces: Comparison,
}

impl Outputs {
    /// Adds the output topics to `rec` and indexes the recorded outputs of `messages` (logged
    /// after the inputs they answer).
    fn new(rec: &mut Recorder, messages: &[OwnedMessage]) -> anyhow::Result<Self> {
        let mut outputs = Self {
            cmd_id: rec.add_message_type::<HandCommand>()?,
            force_id: rec.add_message_type::<GloveForceCommand>()?,
            source: source_id("reprocess"),
            seq: 0,
            recorded_cmds: HashMap::new(),
            recorded_forces: HashMap::new(),
            cmds: Comparison::default(),
            forces: Comparison::default(),
        };
        for msg in messages {
            match msg.topic.as_str() {
                "hand/command" => {
                    if let Some(c) = msg.decode::<HandCommand>() {
                        outputs.recorded_cmds.entry(c.header.origin_ns).or_insert(c);
                    }
                }
                "glove/force_command" => {
                    if let Some(c) = msg.decode::<GloveForceCommand>() {
                        outputs
                            .recorded_forces
                            .entry(c.header.origin_ns)
                            .or_insert(c);
                    }
                }
                _ => {}
            }
        }
        Ok(outputs)
    }

    /// The header of an output made at `t`.
    fn stamp(
        &mut self,
        mut header: teleop_msgs::SampleHeader,
        t: u64,
    ) -> teleop_msgs::SampleHeader {
        self.seq += 1;
        header.seq = self.seq;
        header.stamp_ns = t;
        if header.origin_ns == 0 {
            header.origin_ns = t;
        }
        header.source_id = self.source;
        header
    }

    /// Writes and compares a hand command made at `t`; returns it as published.
    fn command(
        &mut self,
        rec: &mut Recorder,
        mut c: HandCommand,
        t: u64,
    ) -> anyhow::Result<HandCommand> {
        c.header = self.stamp(c.header, t);
        rec.write(self.cmd_id, &RecordedMessage::from_sample(&c, t))?;
        compare_cmd(
            &mut self.cmds,
            &c,
            self.recorded_cmds.get(&c.header.origin_ns),
        );
        Ok(c)
    }

    /// Writes and compares a glove force command made at `t`.
    fn force(
        &mut self,
        rec: &mut Recorder,
        mut c: GloveForceCommand,
        t: u64,
    ) -> anyhow::Result<()> {
        c.header = self.stamp(c.header, t);
        rec.write(self.force_id, &RecordedMessage::from_sample(&c, t))?;
        compare_force(
            &mut self.forces,
            &c,
            self.recorded_forces.get(&c.header.origin_ns),
        );
        Ok(())
    }
}

fn compare_cmd(c: &mut Comparison, new: &HandCommand, old: Option<&HandCommand>) {
    c.recomputed += 1;
    let Some(old) = old else { return };
    c.matched += 1;
    let d = new
        .active_joints()
        .iter()
        .zip(old.active_joints())
        .map(|(a, b)| f64::from((a.target - b.target).abs()))
        .fold(0.0, f64::max);
    if d > 1e-6 {
        c.differing += 1;
    }
    c.max_difference = c.max_difference.max(d);
}

fn compare_force(c: &mut Comparison, new: &GloveForceCommand, old: Option<&GloveForceCommand>) {
    c.recomputed += 1;
    let Some(old) = old else { return };
    c.matched += 1;
    let d = new
        .force
        .iter()
        .zip(old.force)
        .map(|(a, b)| f64::from((i32::from(*a) - i32::from(b)).abs()))
        .fold(0.0, f64::max);
    if d > 0.0 {
        c.differing += 1;
    }
    c.max_difference = c.max_difference.max(d);
}

#[cfg(test)]
mod namespace_tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn ns(n: &str) -> Option<Namespace> {
        Some(Namespace::new(n).unwrap())
    }

    fn options(namespaces: &[&str], remap: &[&str]) -> ReplayOptions {
        ReplayOptions {
            speed: None,
            looped: false,
            topics: None,
            start: None,
            end: None,
            namespaces: namespaces.iter().map(|n| ns(n).unwrap()).collect(),
            remap: remap.iter().map(|r| parse_remap(r).unwrap()).collect(),
            allow_live: false,
        }
    }

    #[test]
    fn by_default_only_sensor_channels_of_every_namespace_are_replayed() {
        let recorded: Vec<String> = [
            "left/glove/state",
            "left/hand/command",
            "left/glove/force_command",
            "estop",
            "hand/tactile",
            "health",
            "right/device/info",
            "not/a/topic",
        ]
        .map(String::from)
        .to_vec();
        assert_eq!(
            replayed_channels(&recorded, None).unwrap(),
            ["left/glove/state", "hand/tactile", "right/device/info"]
        );
        let named = ["left/hand/command".to_string()];
        assert_eq!(
            replayed_channels(&recorded, Some(&named)).unwrap(),
            ["left/hand/command"]
        );
        let err = replayed_channels(&recorded, Some(&["hand/comand".to_string()])).unwrap_err();
        assert!(err.to_string().contains("\"hand/comand\""), "{err}");
        for estop in ["estop", "left/estop/ack"] {
            let err = replayed_channels(&recorded, Some(&[estop.to_string()])).unwrap_err();
            assert!(
                err.to_string()
                    .starts_with(&format!("--topics {estop}: the e-stop is never replayed")),
                "{err}"
            );
        }
    }

    #[test]
    fn remap_arguments() {
        assert_eq!(
            parse_remap("left=right").unwrap(),
            Remap {
                from: ns("left"),
                to: ns("right")
            }
        );
        assert_eq!(
            parse_remap("=left").unwrap(),
            Remap {
                from: None,
                to: ns("left")
            }
        );
        assert!(parse_remap("left").unwrap_err().contains("FROM=TO"));
        assert!(parse_remap("Left=right").unwrap_err().contains("'L'"));
    }

    #[test]
    fn channels_go_back_to_their_namespace_unless_remapped() {
        let all = options(&[], &[]);
        assert_eq!(all.target("hand/command"), Some((None, "hand/command")));
        assert_eq!(
            all.target("left/hand/command"),
            Some((ns("left"), "hand/command"))
        );
        assert_eq!(all.target("left/not_a_topic"), None);

        let only_right = options(&["right"], &["right=left", "=right"]);
        assert_eq!(only_right.target("left/glove/state"), None);
        assert_eq!(only_right.target("glove/state"), None);
        assert_eq!(
            only_right.target("right/glove/state"),
            Some((ns("left"), "glove/state"))
        );
        let root_to_left = options(&[], &["=left"]);
        assert_eq!(
            root_to_left.target("glove/state"),
            Some((ns("left"), "glove/state"))
        );
    }
}
