//! Recording the live pipeline: subscribes to every topic of the message contract (any topic
//! added to `teleop_msgs::topics!` is recorded without code changes here) and writes each sample,
//! with its receive time, to MCAP through `teleop-recording` (ROS 2 CDR, `ros2msg` schemas,
//! chunks closed at least every 100 ms). Used by the `teleop-recorder` process and by
//! `teleop record`.
//!
//! Without namespaces it records the plain topics into channels of the same names. Given
//! namespaces (`left`, `right`) it records each one's topics into channels named with their
//! namespace (`left/hand/command`); device identities go into `<namespace>/device.<kind>`
//! metadata records.
//!
//! The recorder never slows a producer down: iceoryx2 overwrites the oldest queued sample when a
//! subscriber falls behind; those losses show as gaps in the samples' sequence numbers, which are
//! counted per topic, logged while recording, written into the file and printed at the end.
//!
//! Under `teleop launch` each file carries a [`SESSION_METADATA`] record naming the launcher
//! and the recorder's node. A recorder restarted in the same session (the previous one was
//! killed or failed) reads the last sequence number per topic and publisher from its
//! predecessor's newest file in the same folder, and counts the samples published in between
//! (while no recorder ran) as drops of its first file.
//!
//! Episodes: the operator's marks on the `episode` topic (`teleop episode`, the console) are
//! recorded like any sample (channel `episode`, once, without a namespace); when an episode
//! closes or is discarded the recorder writes its record `episode.<n>` with its health (see
//! `episode`) and syncs the chunk, so a killed recorder keeps every closed episode. Its own
//! `health` report (once it records, every 500 ms and at once after a mark) says the current episode
//! (`episode`, `episode_open`, `episode_s`), the episodes kept and the marks taken and ignored.
//! A recorder restarted in the same session continues its predecessor's episodes.
//!
//! Every file is announced (`recorded PATH` on stderr) as soon as it is started, so that the
//! launcher's summary lists a killed recorder's file too. A recorder that cannot go on (a full
//! disk) keeps the first error, finishes what can be finished, and says `recording stopped:
//! <first error>` on stderr.

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use iceoryx2::port::listener::Listener;
use teleop_msgs::Message;
use teleop_msgs::{device_model, topics, visit_topic, DeviceInfo, Episode, TopicVisitor};
use teleop_recording::{
    RecordedMessage, Recorder, RecordingError, RecordingSummary, TopicId, WriterOptions,
};
use teleop_runtime::{
    now_ns, qualified, EventLoop, Flow, Health, Input, Namespace, NodeRuntime, Service, StopReason,
    Subscriber, Wake,
};

mod episode;
use episode::Book;

/// Where a recording goes (rotated parts get `_1`, `_2`, ... before `.mcap`).
#[derive(Debug, Clone)]
pub enum Output {
    /// This file; an existing file is not overwritten (refused).
    File(PathBuf),
    /// A new file in this folder named after the UTC start time to the millisecond
    /// (`2026-11-23_20-37-35.123.mcap`); when another recorder took that name (started in the
    /// same millisecond) `-2`, `-3`, ... goes before `.mcap`. Never overwrites a file.
    Timestamped(PathBuf),
}

/// What to record and where.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// Where to write.
    pub out: Output,
    /// Topics to record (all when `None`), by their plain names (`hand/command`).
    pub topics: Option<Vec<String>>,
    /// Namespaces whose topics are recorded; empty: the topics without a namespace.
    pub namespaces: Vec<Namespace>,
    /// Chunking and rotation.
    pub writer: WriterOptions,
    /// Metadata records written at the start of every file.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// Stop after this long (`None`: until SIGINT/SIGTERM).
    pub duration: Option<Duration>,
    /// Prints `recorded PATH` on stderr as each file is started (for `teleop launch`, which
    /// lists the files in its summary even when the recorder is killed).
    pub announce: bool,
}

/// What [`record`] did.
#[derive(Debug, Clone)]
pub struct Recorded {
    /// The files, counts and drops.
    pub summary: RecordingSummary,
    /// The first error when recording stopped before it was asked to (a full disk).
    pub stopped: Option<String>,
}

/// Name of the metadata record that says which recorder of which `teleop launch` session wrote
/// a file: `launcher` (the launcher's pid and start time) and `node` (the recorder's node name).
pub const SESSION_METADATA: &str = "recorder_session";

/// The [`SESSION_METADATA`] record of a recorder called `node` started by `teleop launch`
/// (`TELEOP_SUPERVISOR_PID` set), `None` otherwise. The launcher is named by its pid and its
/// start time since boot, so a later launcher that gets the same pid is another session.
pub fn launch_session(node: &str) -> Option<BTreeMap<String, String>> {
    let pid: u32 = std::env::var(teleop_runtime::ENV_SUPERVISOR_PID)
        .ok()?
        .parse()
        .ok()?;
    let started = process_start_ticks(pid)?;
    Some(BTreeMap::from([
        ("launcher".to_string(), format!("{pid}@{started}")),
        ("node".to_string(), node.to_string()),
    ]))
}

/// Field 22 of `/proc/<pid>/stat`: when the process started, in clock ticks since boot.
fn process_start_ticks(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) may hold spaces and parentheses: count after the last ')'.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// The newest recordings in `dir` (newest first) whose [`SESSION_METADATA`] record is
/// `session`: the files of this recorder's predecessors in the same session.
fn session_files(dir: &Path, session: &BTreeMap<String, String>) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut found: Vec<(SystemTime, PathBuf)> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .filter_map(|p| {
            let modified = std::fs::metadata(&p).ok()?.modified().ok()?;
            let head = teleop_recording::head_metadata(&p).ok()?;
            head.iter()
                .any(|(name, fields)| name == SESSION_METADATA && fields == session)
                .then_some((modified, p))
        })
        .collect();
    found.sort_by_key(|(modified, _)| std::cmp::Reverse(*modified));
    found.into_iter().map(|(_, p)| p).collect()
}

/// Per channel, the last sequence number each publisher (source id) reached in the newest of
/// `files` that holds any message.
fn last_sequences(files: &[PathBuf]) -> HashMap<String, Vec<(u32, u64)>> {
    let mut last: HashMap<String, Vec<(u32, u64)>> = HashMap::new();
    for file in files {
        let Ok(messages) = teleop_recording::read_messages(file, &teleop_recording::Filter::all())
        else {
            continue;
        };
        for msg in messages.map_while(Result::ok) {
            let Some((seq, source)) = header_of(&msg.payload) else {
                continue;
            };
            let sources = last.entry(msg.topic).or_default();
            match sources.iter_mut().find(|(id, _)| *id == source) {
                Some(entry) => entry.1 = entry.1.max(seq),
                None => sources.push((source, seq)),
            }
        }
        if !last.is_empty() {
            tracing::info!(
                file = %file.display(),
                "continuing after the previous recorder of this session: the samples published \
                 between its last and our first are counted as drops"
            );
            break;
        }
    }
    last
}

/// The episodes of this recorder's predecessors in the same session (`files`, newest first),
/// for the book to continue: an episode they left open can still be stopped here.
fn continue_episodes(files: &[PathBuf]) -> Book {
    if files.is_empty() {
        return Book::default();
    }
    let oldest_first: Vec<&PathBuf> = files.iter().rev().collect();
    match teleop_recording::read_episodes(&oldest_first) {
        Ok(episodes) => {
            if let Some(open) = episodes.open() {
                tracing::info!(
                    episode = open.index,
                    task = %open.task,
                    "continuing the previous recorder's open episode"
                );
            }
            Book::continuing(episodes)
        }
        Err(e) => {
            tracing::warn!(
                "cannot read the previous recorder's episodes ({e}): numbering starts again at 1"
            );
            Book::default()
        }
    }
}

/// `seq` and `source_id` of a payload's `SampleHeader` (every contract payload starts with one).
fn header_of(payload: &[u8]) -> Option<(u64, u32)> {
    let seq = u64::from_le_bytes(payload.get(0..8)?.try_into().ok()?);
    let source = u32::from_le_bytes(payload.get(24..28)?.try_into().ok()?);
    Some((seq, source))
}

/// The name a recording started at `at` gets: `<UTC date>_<time>.<milliseconds>`, without
/// `.mcap`.
fn timestamped_stem(at: SystemTime) -> String {
    let since = at.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = since.as_secs();
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    let t = secs % 86_400;
    format!(
        "{y:04}-{m:02}-{d:02}_{:02}-{:02}-{:02}.{:03}",
        t / 3600,
        t / 60 % 60,
        t % 60,
        since.subsec_millis()
    )
}

/// Creates a new recording in `dir` named after `at` ([`Output::Timestamped`]): the first free
/// name of `<stem>.mcap`, `<stem>-2.mcap`, `<stem>-3.mcap`, ... Each try creates the file only
/// if it does not exist, so recorders started at the same moment never share a file.
fn create_timestamped(
    dir: &Path,
    at: SystemTime,
    writer: &WriterOptions,
    metadata: &[(String, BTreeMap<String, String>)],
) -> anyhow::Result<Recorder> {
    let stem = timestamped_stem(at);
    let mut n = 1u32;
    loop {
        let path = if n == 1 {
            dir.join(format!("{stem}.mcap"))
        } else {
            dir.join(format!("{stem}-{n}.mcap"))
        };
        match Recorder::create(&path, writer.clone(), metadata) {
            Err(RecordingError::Io { source, .. })
                if source.kind() == std::io::ErrorKind::AlreadyExists && n < 1000 =>
            {
                n += 1;
            }
            created => return Ok(created?),
        }
    }
}

/// The path from the root (files are announced to a launcher with another working folder).
fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// Days since 1970-01-01 to (year, month, day) (Howard Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// Metadata every recording carries: the software version, and the launch file named by
/// `TELEOP_LAUNCH_FILE` (set by `teleop launch`) when there is one.
pub fn standard_metadata() -> Vec<(String, BTreeMap<String, String>)> {
    let mut out = vec![(
        "software".to_string(),
        BTreeMap::from([
            ("name".to_string(), "teleop".to_string()),
            ("version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
        ]),
    )];
    if let Some(path) = std::env::var_os("TELEOP_LAUNCH_FILE") {
        if let Some(m) = file_metadata(Path::new(&path)) {
            out.push(("launch".to_string(), m));
        }
    }
    out
}

/// A file's path and text as a metadata record (`None` if unreadable).
pub fn file_metadata(path: &Path) -> Option<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).ok()?;
    Some(BTreeMap::from([
        ("file".to_string(), path.display().to_string()),
        ("text".to_string(), text),
    ]))
}

/// One recorded topic of one namespace.
trait Tap {
    /// The channel: the topic's qualified name.
    fn channel(&self) -> &str;
    fn listener(&self) -> &Listener<Service>;
    /// Writes every queued sample, showing each to the episode book as tap `index`; returns
    /// how many.
    fn drain(
        &self,
        rec: &mut Recorder,
        book: &mut Book,
        index: usize,
    ) -> Result<usize, Box<RecordingError>>;
    fn dropped(&self) -> u64;
}

struct TopicTap<M: Message> {
    sub: Subscriber<M>,
    id: TopicId,
    channel: String,
    /// The previous recorder's last sequence number per publisher, until each publisher's
    /// first sample here: the gap between them is counted as drops.
    previous: RefCell<Vec<(u32, u64)>>,
}

impl<M: Message> Tap for TopicTap<M> {
    fn channel(&self) -> &str {
        &self.channel
    }
    fn listener(&self) -> &Listener<Service> {
        self.sub.listener()
    }
    fn drain(
        &self,
        rec: &mut Recorder,
        book: &mut Book,
        index: usize,
    ) -> Result<usize, Box<RecordingError>> {
        let mut result = Ok(());
        let mut previous = self.previous.borrow_mut();
        let n = self.sub.drain(|m| {
            let header = m.header();
            if let Some(i) = previous.iter().position(|(id, _)| *id == header.source_id) {
                let (_, last) = previous.swap_remove(i);
                // A publisher that restarted begins at 1 again: not a loss.
                if header.seq > last + 1 {
                    let gap = header.seq - last - 1;
                    tracing::warn!(
                        topic = %self.channel,
                        lost = gap,
                        "samples published while no recorder ran (between the previous \
                         recorder's last sample and this one's first): counted as drops"
                    );
                    rec.note_drops(&self.channel, gap);
                }
            }
            if result.is_ok() {
                let msg = RecordedMessage {
                    topic: &self.channel,
                    ..RecordedMessage::from_sample(m, now_ns())
                };
                result = rec.write(self.id, &msg);
                if result.is_ok() {
                    book.observe(index, M::TOPIC, m.as_bytes());
                }
            }
        });
        result.map(|()| n).map_err(Box::new)
    }
    fn dropped(&self) -> u64 {
        self.sub.dropped()
    }
}

struct MakeTap<'a> {
    runtime: &'a NodeRuntime,
    rec: &'a mut Recorder,
    namespace: Option<&'a Namespace>,
    previous: &'a HashMap<String, Vec<(u32, u64)>>,
}

impl TopicVisitor for MakeTap<'_> {
    type Output = anyhow::Result<Box<dyn Tap>>;
    fn visit<M: Message>(self) -> Self::Output {
        let channel = qualified(self.namespace, M::TOPIC);
        let id = self.rec.add_topic(&channel, M::SCHEMA_NAME, &M::schema())?;
        let previous = self.previous.get(&channel).cloned().unwrap_or_default();
        Ok(Box::new(TopicTap::<M> {
            sub: self.runtime.subscriber_in(self.namespace)?,
            id,
            channel,
            previous: RefCell::new(previous),
        }))
    }
}

/// How often the recorder reports its health (and at once when an episode changes).
const HEALTH_PERIOD: Duration = Duration::from_millis(500);

/// Records until SIGINT/SIGTERM or the end of `options.duration`, then finishes the file
/// properly and returns what was written (drops included). An error while recording (a full
/// disk) ends recording early: what can be finished is finished, and [`Recorded::stopped`]
/// holds the first error. Errors before recording started (the file cannot be created, an
/// unknown topic) are returned.
pub fn record(runtime: &NodeRuntime, options: &RecordOptions) -> anyhow::Result<Recorded> {
    // A recorder restarted in a `teleop launch` session continues its predecessor's count.
    let folder = match &options.out {
        Output::File(path) => path.parent().map(Path::to_path_buf).unwrap_or_default(),
        Output::Timestamped(dir) => dir.clone(),
    };
    let (previous, mut book) = match options.metadata.iter().find(|(n, _)| n == SESSION_METADATA) {
        Some((_, session)) => {
            let folder = if folder.as_os_str().is_empty() {
                PathBuf::from(".")
            } else {
                folder
            };
            let files = session_files(&folder, session);
            (last_sequences(&files), continue_episodes(&files))
        }
        None => (HashMap::new(), Book::default()),
    };
    let mut rec = match &options.out {
        Output::File(path) => Recorder::create(path, options.writer.clone(), &options.metadata)?,
        Output::Timestamped(dir) => {
            create_timestamped(dir, SystemTime::now(), &options.writer, &options.metadata)?
        }
    };
    // Each file is announced as soon as it exists: a recorder killed later still has it listed.
    let mut announced = PathBuf::new();
    let mut announce = |rec: &Recorder| {
        if options.announce && rec.path() != announced {
            announced = rec.path().to_path_buf();
            eprintln!("recorded {}", absolute(&announced).display());
        }
    };
    announce(&rec);
    let names: Vec<&str> = match &options.topics {
        Some(list) => list.iter().map(String::as_str).collect(),
        None => topics().iter().map(|t| t.name).collect(),
    };
    let namespaces: Vec<Option<&Namespace>> = if options.namespaces.is_empty() {
        vec![None]
    } else {
        options.namespaces.iter().map(Some).collect()
    };
    let mut taps: Vec<Box<dyn Tap>> = Vec::new();
    for (n, &namespace) in namespaces.iter().enumerate() {
        for &name in &names {
            // Episodes are the operator's, on the topic without a namespace: recorded once.
            let namespace = if name == Episode::TOPIC {
                if n > 0 {
                    continue;
                }
                None
            } else {
                namespace
            };
            let tap = visit_topic(
                name,
                MakeTap {
                    runtime,
                    rec: &mut rec,
                    namespace,
                    previous: &previous,
                },
            )
            .ok_or_else(|| {
                let all: Vec<_> = topics().iter().map(|t| t.name).collect();
                anyhow::anyhow!("unknown topic {name:?}; topics are: {}", all.join(", "))
            })??;
            taps.push(tap);
        }
    }
    // Device identities also go into metadata records ("device.glove", "device.revo2"; in a
    // namespace "left/device.glove").
    let mut devices = Vec::new();
    for &namespace in &namespaces {
        devices.push(Devices {
            sub: runtime.subscriber_in::<DeviceInfo>(namespace)?,
            prefix: namespace.map_or(String::new(), |ns| format!("{ns}/")),
            known: RefCell::default(),
        });
    }
    tracing::info!(file = %rec.path().display(), topics = taps.len(), "recording");
    let start = std::time::Instant::now();
    let mut reported = vec![0u64; taps.len()];
    let mut last_report = std::time::Instant::now();
    let mut failure: Option<anyhow::Error> = None;
    let mut health = Health::new(runtime)?;
    // The first report goes out at once: it tells `teleop launch` the recorder is recording
    // (`ready_timeout_ms`), so the next process starts.
    let mut last_health: Option<std::time::Instant> = None;
    let channels: Vec<String> = taps.iter().map(|t| t.channel().to_string()).collect();
    let channels: Vec<&str> = channels.iter().map(String::as_str).collect();
    let mut inputs: Vec<Input> = taps.iter().map(|t| Input::new(t.listener())).collect();
    inputs.extend(devices.iter().map(|d| Input::new(d.sub.listener())));
    let stop = EventLoop::new(Duration::from_millis(20)).run(&inputs, |wake| {
        let result = match wake {
            Wake::Input(i) if i >= taps.len() => devices[i - taps.len()].drain(&mut rec),
            Wake::Input(i) => taps[i].drain(&mut rec, &mut book, i).map(|_| ()),
            Wake::Timeout(_) | Wake::Tick => rec.flush_if_due(now_ns()).map_err(Box::new),
        };
        // An episode that closed is written (and its chunk synced) before anything else.
        let dropped: Vec<u64> = taps.iter().map(|t| t.dropped()).collect();
        let result = result.and_then(|()| book.settle(&channels, &dropped, &mut rec));
        let changed = matches!(result, Ok(true));
        let result = result.map(|_| ());
        health.count_loop();
        if changed || last_health.is_none_or(|t| t.elapsed() >= HEALTH_PERIOD) {
            last_health = Some(std::time::Instant::now());
            for (name, value) in book.details(now_ns()) {
                health.set_detail(name, value);
            }
            health.set_dropped(dropped.iter().sum());
            if let Err(e) = health.publish(&[]) {
                tracing::warn!("cannot publish the recorder's health: {e}");
            }
        }
        if let Some(why) = rec.take_rotation_error() {
            tracing::warn!("cannot start the next file, recording goes on in this one: {why}");
        }
        announce(&rec);
        if let Err(e) = result {
            failure = Some(e.into());
            return Flow::Break(());
        }
        if last_report.elapsed() >= Duration::from_secs(1) {
            last_report = std::time::Instant::now();
            for (tap, seen) in taps.iter().zip(reported.iter_mut()) {
                let now = tap.dropped();
                if now > *seen {
                    tracing::warn!(
                        topic = tap.channel(),
                        lost = now - *seen,
                        total = now,
                        "samples lost before the recorder got them"
                    );
                    *seen = now;
                }
            }
        }
        if options.duration.is_some_and(|d| start.elapsed() >= d) {
            Flow::Break(())
        } else {
            Flow::Continue(())
        }
    })?;
    // What is still queued belongs in the file too (unless writing failed: the first error
    // is the one to report, not the refusals after it).
    for (i, tap) in taps.iter().enumerate() {
        if failure.is_none() {
            if let Err(e) = tap.drain(&mut rec, &mut book, i) {
                failure = Some((*e).into());
            }
        }
        rec.note_drops(tap.channel(), tap.dropped());
    }
    if failure.is_none() {
        let dropped: Vec<u64> = taps.iter().map(|t| t.dropped()).collect();
        match book.settle(&channels, &dropped, &mut rec) {
            Ok(true) => {
                // A mark taken while stopping: `teleop episode` is waiting for this report.
                for (name, value) in book.details(now_ns()) {
                    health.set_detail(name, value);
                }
                if let Err(e) = health.publish(&[]) {
                    tracing::warn!("cannot publish the recorder's health: {e}");
                }
            }
            Ok(false) => {}
            Err(e) => failure = Some((*e).into()),
        }
    }
    if let Some((index, task)) = book.open() {
        tracing::warn!(
            episode = index,
            task,
            "recording stops with an episode open: it has no record here; a recorder restarted \
             in this session continues it, else the export leaves it out"
        );
    }
    announce(&rec);
    let (summary, error) = rec.finish_all();
    // The first error: the one that stopped recording, else the one finishing met.
    let stopped = failure
        .map(|e| e.to_string())
        .or_else(|| error.map(|e| e.to_string()));
    match &stopped {
        None => {
            tracing::info!(reason = ?stop_reason(stop), messages = summary.messages, "recording finished")
        }
        Some(why) => tracing::error!(messages = summary.messages, "recording stopped: {why}"),
    }
    Ok(Recorded { summary, stopped })
}

/// The device identities of one namespace, each written once as metadata.
struct Devices {
    sub: Subscriber<DeviceInfo>,
    /// Before the record name: "" or "<namespace>/".
    prefix: String,
    /// Borrowed mutably while the event loop holds the subscriber's listener.
    known: RefCell<Vec<DeviceInfo>>,
}

impl Devices {
    fn drain(&self, rec: &mut Recorder) -> Result<(), Box<RecordingError>> {
        let mut result = Ok(());
        let mut known = self.known.borrow_mut();
        let prefix = &self.prefix;
        self.sub.drain(|d| {
            if result.is_ok() && !known.iter().any(|k| same_identity(k, d)) {
                known.retain(|k| !same_device(k, d));
                known.push(*d);
                result = rec.add_metadata(
                    &format!("{prefix}device.{}", device_model::name(d.device_model)),
                    device_fields(d),
                );
            }
        });
        result.map_err(Box::new)
    }
}

fn same_device(a: &DeviceInfo, b: &DeviceInfo) -> bool {
    (a.device_model, a.bus_address, a.identity_serial)
        == (b.device_model, b.bus_address, b.identity_serial)
}

/// Same device with the same identity in every field (the header differs every time).
fn same_identity(a: &DeviceInfo, b: &DeviceInfo) -> bool {
    let identity = |d: &DeviceInfo| DeviceInfo {
        header: Default::default(),
        ..*d
    };
    identity(a) == identity(b)
}

/// A device identity as metadata fields (by the contract's field names).
fn device_fields(d: &DeviceInfo) -> BTreeMap<String, String> {
    d.named_fields()
        .into_iter()
        .map(|(name, value)| (name.to_string(), value))
        .collect()
}

fn stop_reason(stop: StopReason) -> &'static str {
    match stop {
        StopReason::Interrupt => "Ctrl-C",
        StopReason::Terminate => "SIGTERM",
        StopReason::Requested => "duration elapsed",
    }
}

/// The end-of-recording report: files (`recorded PATH`, and for a file that could not be
/// finished a `not finished` line), then per topic messages and drops.
pub fn report(summary: &RecordingSummary) -> String {
    let mut out = String::new();
    for f in &summary.files {
        out.push_str(&format!("recorded {}\n", absolute(f).display()));
    }
    if let Some(f) = &summary.unfinished {
        out.push_str(&format!(
            "not finished {}: it holds what its closed chunks hold; `teleop recordings repair` \
             makes it indexable\n",
            absolute(f).display()
        ));
    }
    out.push_str(&format!(
        "{:<28} {:>9} {:>7}\n",
        "TOPIC", "MESSAGES", "DROPS"
    ));
    for t in &summary.topics {
        out.push_str(&format!(
            "{:<28} {:>9} {:>7}\n",
            t.topic, t.messages, t.drops
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(20_778), (2026, 11, 21));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        let at = UNIX_EPOCH + Duration::from_millis(20_778 * 86_400_000 + 8 * 3_600_000 + 7);
        assert_eq!(timestamped_stem(at), "2026-11-21_08-00-00.007");
    }

    #[test]
    fn a_restarted_recorder_finds_its_predecessors_last_samples() {
        use teleop_msgs::GloveState;
        let dir = tempfile::tempdir().unwrap();
        let session = |node: &str| {
            BTreeMap::from([
                ("launcher".to_string(), "42@1000".to_string()),
                ("node".to_string(), node.to_string()),
            ])
        };
        // Our predecessor's file (two publishers), and another recorder's of the same session.
        for (name, node, seqs) in [("ours", "recorder", 1..=5u64), ("theirs", "other", 1..=9)] {
            let path = dir.path().join(format!("{name}.mcap"));
            let metadata = [(SESSION_METADATA.to_string(), session(node))];
            let mut rec = Recorder::create(&path, WriterOptions::default(), &metadata).unwrap();
            let id = rec.add_message_type::<GloveState>().unwrap();
            for seq in seqs {
                for source in [7u32, 8] {
                    let mut s = GloveState::default();
                    s.header.seq = seq * u64::from(source);
                    s.header.source_id = source;
                    rec.write(id, &RecordedMessage::from_sample(&s, seq))
                        .unwrap();
                }
            }
            rec.finish().unwrap();
        }
        let files = session_files(dir.path(), &session("recorder"));
        assert_eq!(files, [dir.path().join("ours.mcap")]);
        let mut last = last_sequences(&files).remove("glove/state").unwrap();
        last.sort_unstable();
        assert_eq!(last, [(7, 35), (8, 40)]);
        assert!(session_files(dir.path(), &session("nobody")).is_empty());
        assert!(process_start_ticks(std::process::id()).is_some());
    }

    #[test]
    fn recorders_started_at_the_same_moment_get_their_own_files() {
        let dir = tempfile::tempdir().unwrap();
        let at = SystemTime::now();
        let metadata = [];
        let a = create_timestamped(dir.path(), at, &WriterOptions::default(), &metadata).unwrap();
        let b = create_timestamped(dir.path(), at, &WriterOptions::default(), &metadata).unwrap();
        let c = create_timestamped(dir.path(), at, &WriterOptions::default(), &metadata).unwrap();
        let stem = timestamped_stem(at);
        assert_eq!(a.path(), dir.path().join(format!("{stem}.mcap")));
        assert_eq!(b.path(), dir.path().join(format!("{stem}-2.mcap")));
        assert_eq!(c.path(), dir.path().join(format!("{stem}-3.mcap")));
        for rec in [a, b, c] {
            let path = rec.path().to_path_buf();
            rec.finish().unwrap();
            assert!(
                teleop_recording::info(&path).unwrap().complete,
                "{}",
                path.display()
            );
        }
    }
}
