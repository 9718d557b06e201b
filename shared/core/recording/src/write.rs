//! Writing recordings: [`Recorder`].

use std::{
    collections::BTreeMap,
    fs::File,
    io::BufWriter,
    path::{Path, PathBuf},
    time::Duration,
};

use mcap::{
    records::{MessageHeader, Metadata},
    Compression, WriteOptions, Writer,
};
use teleop_msgs::{Message, CDR_LE_HEADER};

use crate::{
    file::{
        check_channel, contract_type, ChannelKind, RecordedSchema, MESSAGE_ENCODING, PROFILE,
        SCHEMA_ENCODING,
    },
    RecordingError,
};

/// Name of the metadata record with the per-topic drop counts, written when a file is finished.
pub const DROPS_METADATA: &str = "drops";

/// Name of the metadata record that starts every file: `version` = the message contract
/// version ([`teleop_msgs::CONTRACT_VERSION`]) of the recorder that wrote it. Files of contract
/// version 1 have none. Readers go by each topic's schema text, which fixes its layout.
pub const CONTRACT_METADATA: &str = "contract";

/// One message to record: where it came from and when.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordedMessage<'a> {
    /// Topic name (must have been registered with [`Recorder::add_topic`]; only used in errors).
    pub topic: &'a str,
    /// When the recorder received it (CLOCK_MONOTONIC ns); the file is ordered and indexed by it.
    pub log_time_ns: u64,
    /// The sample's own header `stamp_ns`.
    pub publish_time_ns: u64,
    /// The sample's header `seq` (truncated to 32 bits, as MCAP stores it).
    pub sequence: u32,
    /// The raw `repr(C)` payload bytes, without the CDR header.
    pub payload: &'a [u8],
}

impl<'a> RecordedMessage<'a> {
    /// Describes a contract sample received at `log_time_ns`: its topic, header stamp and
    /// sequence number, and its bytes.
    pub fn from_sample<M: Message>(sample: &'a M, log_time_ns: u64) -> Self {
        let header = sample.header();
        Self {
            topic: M::TOPIC,
            log_time_ns,
            publish_time_ns: header.stamp_ns,
            // MCAP sequence numbers are 32-bit; the low bits keep gaps visible.
            sequence: header.seq as u32,
            payload: sample.as_bytes(),
        }
    }
}

/// How a [`Recorder`] writes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriterOptions {
    /// Closes the open chunk (making it readable after a crash) once this much log time has
    /// passed since the last close. Default 100 ms: a killed recorder loses at most that much.
    pub chunk_flush: Duration,
    /// Starts a new file once the current one has reached this many bytes on disk (checked
    /// when a chunk is closed, so a file overshoots by up to one chunk).
    pub rotate_bytes: Option<u64>,
    /// Starts a new file once a message is logged this long after the file's first message.
    pub rotate_after: Option<Duration>,
    /// Compresses chunks with zstd (on the calling thread). Default true.
    pub compression: bool,
    /// Makes every closed chunk durable (`fdatasync`), and each finished file and its folder
    /// (`fsync`): a power cut loses at most the open chunk too, as a killed recorder does.
    /// Default true; see BENCHMARKS.md for what it costs.
    pub sync: bool,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            chunk_flush: Duration::from_millis(100),
            rotate_bytes: None,
            rotate_after: None,
            compression: true,
            sync: true,
        }
    }
}

/// A registered topic, as returned by [`Recorder::add_topic`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TopicId(usize);

/// What one topic contributed to a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicCount {
    /// Topic name.
    pub topic: String,
    /// Schema name.
    pub schema_name: String,
    /// Messages written, over all files.
    pub messages: u64,
    /// Drops reported with [`Recorder::note_drops`], over all files.
    pub drops: u64,
}

/// What [`Recorder::finish`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordingSummary {
    /// Every file written, in order: the path given to [`Recorder::create`], then
    /// `<stem>_1.mcap`, `<stem>_2.mcap`, ... after rotations (a number whose file exists
    /// already is skipped).
    pub files: Vec<PathBuf>,
    /// The last file when recording failed: it could not be finished, and holds what its
    /// closed chunks hold (as a killed recorder's file; `repair` makes it indexable).
    pub unfinished: Option<PathBuf>,
    /// Per registered topic (and per topic only named in [`Recorder::note_drops`]), in
    /// registration order.
    pub topics: Vec<TopicCount>,
    /// Messages written, over all topics and files.
    pub messages: u64,
}

struct Topic {
    name: String,
    schema_name: String,
    schema_text: String,
    /// Payload size of the contract type, for contract topics.
    size: Option<usize>,
    /// Channel id in the current file.
    channel: u16,
    messages: u64,
}

/// Writes one recording: MCAP files of ROS 2 CDR messages, closed chunk by chunk so that a
/// killed recorder leaves a repairable file, rotated by size or duration.
///
/// Dropping a `Recorder` without [`finish`](Self::finish) (an early return, a panic) still
/// finishes the current file, ignoring errors.
pub struct Recorder {
    base: PathBuf,
    current: PathBuf,
    part: u32,
    options: WriterOptions,
    metadata: Vec<(String, BTreeMap<String, String>)>,
    writer: Writer<BufWriter<File>>,
    /// A second handle on the current file, to measure its size.
    size_probe: File,
    file_bytes: u64,
    topics: Vec<Topic>,
    /// Drops over all files, and since the current file started.
    drops_total: BTreeMap<String, u64>,
    drops_file: BTreeMap<String, u64>,
    files: Vec<PathBuf>,
    /// Log time of the first message of the current file.
    file_start_ns: Option<u64>,
    /// Log time of the last chunk close (or of the first message).
    last_flush_ns: Option<u64>,
    /// A chunk is open with messages in it.
    pending: bool,
    /// Reused for CDR header + payload.
    buf: Vec<u8>,
    /// The current file has been finished (or finishing it failed).
    finished: bool,
    /// The first error that stopped recording: every later call returns it again, because
    /// the MCAP writer refuses everything after a failed write ("attempted another write
    /// after a write method failed") and would hide the cause.
    failed: Option<String>,
    /// Why the last rotation could not start a new file (recording went on in the current
    /// one), until [`Recorder::take_rotation_error`] takes it.
    rotation_error: Option<String>,
    /// No new rotation attempt before this log time after one failed.
    rotation_retry_ns: Option<u64>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("current", &self.current)
            .field("part", &self.part)
            .field("options", &self.options)
            .field("topics", &self.topics.len())
            .finish_non_exhaustive()
    }
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// Creates `path` (and its folder; never an existing file) and starts an MCAP file with
/// `metadata` in it, on disk when this returns. Returns the writer, a second handle on the
/// file, and its length. When anything fails after the file was created, the file is removed:
/// no empty or headless file is left behind (a full disk).
fn start_file(
    path: &Path,
    options: &WriterOptions,
    metadata: &[(String, BTreeMap<String, String>)],
) -> Result<(Writer<BufWriter<File>>, File, u64), RecordingError> {
    if let Some(parent) = path.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent).map_err(|e| RecordingError::io(parent, e))?;
        }
    }
    let file = File::options()
        .write(true)
        .read(true)
        .create_new(true)
        .open(path)
        .map_err(|e| RecordingError::io(path, e))?;
    let started = (|| {
        let probe = file.try_clone().map_err(|e| RecordingError::io(path, e))?;
        let mut writer = write_options(options.compression)
            .create(BufWriter::new(file))
            .map_err(|e| RecordingError::mcap(path, e))?;
        for (name, fields) in metadata {
            writer
                .write_metadata(&Metadata {
                    name: name.clone(),
                    metadata: fields.clone(),
                })
                .map_err(|e| RecordingError::mcap(path, e))?;
        }
        // Header and metadata on disk now: a recorder killed from here on leaves a repairable
        // file.
        writer.flush().map_err(|e| RecordingError::mcap(path, e))?;
        if options.sync {
            probe.sync_data().map_err(|e| RecordingError::io(path, e))?;
            sync_folder(path)?;
        }
        let len = probe
            .metadata()
            .map_err(|e| RecordingError::io(path, e))?
            .len();
        Ok((writer, probe, len))
    })();
    if started.is_err() {
        // Ours (created above): a file without its header is of no use to anyone.
        let _ = std::fs::remove_file(path);
    }
    started
}

/// Makes the folder entry of `path` durable (a new or finished file survives a power cut).
fn sync_folder(path: &Path) -> Result<(), RecordingError> {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    File::open(folder)
        .and_then(|f| f.sync_all())
        .map_err(|e| RecordingError::io(folder, e))
}

/// The MCAP writer settings of every file this crate writes.
pub(crate) fn write_options(compression: bool) -> WriteOptions {
    WriteOptions::new()
        .profile(PROFILE)
        .library(format!(
            "teleop-recording/{} {}",
            env!("CARGO_PKG_VERSION"),
            mcap::LIBRARY_IDENTIFIER
        ))
        .compression(compression.then_some(Compression::Zstd))
        // No worker threads: compression runs on the recorder's own thread.
        .compression_threads(0)
}

/// The path of part `part` (1, 2, ...) of a recording started at `base`.
pub fn part_path(base: &Path, part: u32) -> PathBuf {
    let stem = base
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "recording".to_string());
    base.with_file_name(format!("{stem}_{part}.mcap"))
}

impl Recorder {
    /// Creates the file (and its parent folder; an existing file is not overwritten) and writes
    /// the [`CONTRACT_METADATA`] record, then `metadata` records, at its start (a `contract`
    /// record in `metadata`, e.g. copied from another recording, is replaced). The same records
    /// start every file after a rotation. Typical names: `launch` (`file`, `text`), `devices`,
    /// `calibration`, `software` (`version`).
    pub fn create(
        path: &Path,
        options: WriterOptions,
        metadata: &[(String, BTreeMap<String, String>)],
    ) -> Result<Self, RecordingError> {
        let contract = BTreeMap::from([(
            "version".to_string(),
            teleop_msgs::CONTRACT_VERSION.to_string(),
        )]);
        let metadata: Vec<_> = std::iter::once((CONTRACT_METADATA.to_string(), contract))
            .chain(
                metadata
                    .iter()
                    .filter(|(name, _)| name != CONTRACT_METADATA)
                    .cloned(),
            )
            .collect();
        if options.rotate_bytes == Some(0) || options.rotate_after == Some(Duration::ZERO) {
            return Err(RecordingError::invalid_use(
                path,
                "a rotation limit of zero would start a new file for every message",
            ));
        }
        let (writer, size_probe, file_bytes) = start_file(path, &options, &metadata)?;
        Ok(Self {
            base: path.to_path_buf(),
            current: path.to_path_buf(),
            part: 0,
            options,
            metadata,
            writer,
            size_probe,
            file_bytes,
            topics: Vec::new(),
            drops_total: BTreeMap::new(),
            drops_file: BTreeMap::new(),
            files: Vec::new(),
            file_start_ns: None,
            last_flush_ns: None,
            pending: false,
            buf: Vec::new(),
            finished: false,
            failed: None,
            rotation_error: None,
            rotation_retry_ns: None,
        })
    }

    /// The first error that stopped this recorder, if one did.
    pub fn first_error(&self) -> Option<&str> {
        self.failed.as_deref()
    }

    /// Why the last rotation failed, once: recording went on in the current file (it is
    /// tried again a `chunk_flush` of log time later).
    pub fn take_rotation_error(&mut self) -> Option<String> {
        self.rotation_error.take()
    }

    /// Refuses to go on after an earlier failure, naming it.
    fn check_failed(&self) -> Result<(), RecordingError> {
        match &self.failed {
            Some(first) => Err(RecordingError::Stopped {
                path: self.current.clone(),
                first: first.clone(),
            }),
            None => Ok(()),
        }
    }

    /// Keeps the first error (the later ones are its consequences) and returns it.
    fn fail(&mut self, error: RecordingError) -> RecordingError {
        if self.failed.is_none() {
            self.failed = Some(error.to_string());
        }
        error
    }

    /// The file being written now.
    pub fn path(&self) -> &Path {
        &self.current
    }

    /// Registers a topic (schema `ros2msg` with its name and text, channel encoding `cdr`) and
    /// returns its id. Topics can be added at any time. Registering the same topic again with
    /// the same schema returns the same id; with another schema it is an error, and so is a
    /// contract topic with a schema other than the contract's.
    pub fn add_topic(
        &mut self,
        topic: &str,
        schema_name: &str,
        schema_text: &str,
    ) -> Result<TopicId, RecordingError> {
        if let Some(index) = self.topics.iter().position(|t| t.name == topic) {
            let existing = &self.topics[index];
            if existing.schema_name == schema_name && existing.schema_text == schema_text {
                return Ok(TopicId(index));
            }
            return Err(RecordingError::invalid_use(
                &self.current,
                format!(
                    "topic `{topic}` is already registered with schema `{}`",
                    existing.schema_name
                ),
            ));
        }
        let kind = check_channel(
            &self.current,
            topic,
            Some(&RecordedSchema {
                name: schema_name,
                encoding: SCHEMA_ENCODING,
                data: schema_text.as_bytes(),
            }),
            MESSAGE_ENCODING,
        )?;
        let size = match kind {
            ChannelKind::Contract { size } => Some(size),
            ChannelKind::Foreign { .. } => None,
            // Earlier contract versions are read, never written.
            ChannelKind::Converted(_) => {
                return Err(RecordingError::WrongSchemaVersion {
                    path: self.current.clone(),
                    topic: topic.to_string(),
                    schema: schema_name.to_string(),
                    expected: contract_type(topic).map(|c| c.schema).unwrap_or_default(),
                    found: schema_text.to_string(),
                })
            }
        };
        let channel = register(
            &mut self.writer,
            &self.current,
            topic,
            schema_name,
            schema_text,
        )?;
        self.topics.push(Topic {
            name: topic.to_string(),
            schema_name: schema_name.to_string(),
            schema_text: schema_text.to_string(),
            size,
            channel,
            messages: 0,
        });
        Ok(TopicId(self.topics.len() - 1))
    }

    /// Registers the topic of a contract type.
    pub fn add_message_type<M: Message>(&mut self) -> Result<TopicId, RecordingError> {
        self.add_topic(M::TOPIC, M::SCHEMA_NAME, &M::schema())
    }

    /// Writes one message (the 4-byte CDR little-endian header, then the payload). `msg.topic`
    /// must be the topic of `id`, and a contract topic's payload must have its type's size.
    ///
    /// Before writing, starts a new file when a rotation limit is reached. After writing,
    /// closes the open chunk when `chunk_flush` of log time has passed since the last close:
    /// the caller's log times are the clock (see also [`flush_if_due`](Self::flush_if_due)).
    pub fn write(&mut self, id: TopicId, msg: &RecordedMessage) -> Result<(), RecordingError> {
        let Some(topic) = self.topics.get(id.0) else {
            return Err(RecordingError::invalid_use(
                &self.current,
                format!(
                    "topic id {} of `{}` was not registered with this recorder",
                    id.0, msg.topic
                ),
            ));
        };
        if topic.name != msg.topic {
            return Err(RecordingError::invalid_use(
                &self.current,
                format!(
                    "a message of `{}` written with the id of `{}`",
                    msg.topic, topic.name
                ),
            ));
        }
        if topic.size.is_some_and(|size| size != msg.payload.len()) {
            return Err(RecordingError::BadMessage {
                path: self.current.clone(),
                topic: topic.name.clone(),
                detail: format!(
                    "the payload has {} bytes, the contract's type has {}",
                    msg.payload.len(),
                    topic.size.unwrap_or(0)
                ),
            });
        }
        self.check_failed()?;
        if self.rotation_due(msg.log_time_ns) {
            self.rotate(msg.log_time_ns)?;
        }
        let topic = &mut self.topics[id.0];
        self.buf.clear();
        self.buf.extend_from_slice(&CDR_LE_HEADER);
        self.buf.extend_from_slice(msg.payload);
        let written = self.writer.write_to_known_channel(
            &MessageHeader {
                channel_id: topic.channel,
                sequence: msg.sequence,
                log_time: msg.log_time_ns,
                publish_time: msg.publish_time_ns,
            },
            &self.buf,
        );
        if let Err(e) = written {
            let e = RecordingError::mcap(&self.current, e);
            return Err(self.fail(e));
        }
        topic.messages += 1;
        self.pending = true;
        self.file_start_ns.get_or_insert(msg.log_time_ns);
        let last = *self.last_flush_ns.get_or_insert(msg.log_time_ns);
        if msg.log_time_ns < last {
            // The clock went backwards: measure from here.
            self.last_flush_ns = Some(msg.log_time_ns);
        }
        self.flush_if_due(msg.log_time_ns)
    }

    /// Closes the open chunk if `chunk_flush` has passed since the last close (for idle
    /// periods: call it from the recorder's timer with the current monotonic time).
    pub fn flush_if_due(&mut self, now_ns: u64) -> Result<(), RecordingError> {
        let due = match self.last_flush_ns {
            Some(last) => now_ns.saturating_sub(last) >= nanos(self.options.chunk_flush),
            None => false,
        };
        if self.pending && due {
            self.flush()?;
            self.last_flush_ns = Some(now_ns);
        }
        Ok(())
    }

    /// Closes the open chunk now and hands everything written so far to the operating system
    /// (and, with `sync`, to the disk).
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.check_failed()?;
        let result = self
            .writer
            .flush()
            .map_err(|e| RecordingError::mcap(&self.current, e))
            .and_then(|()| {
                if self.options.sync {
                    self.size_probe
                        .sync_data()
                        .map_err(|e| RecordingError::io(&self.current, e))?;
                }
                self.size_probe
                    .metadata()
                    .map_err(|e| RecordingError::io(&self.current, e))
            });
        match result {
            Ok(meta) => {
                self.pending = false;
                self.file_bytes = meta.len();
                Ok(())
            }
            Err(e) => Err(self.fail(e)),
        }
    }

    /// Adds `dropped` samples to the drop count of `topic` (from gaps in the samples' own
    /// header `seq`, counted by the caller). Written as the metadata record `drops` (topic ->
    /// count) when each file is finished, and returned by [`finish`](Self::finish).
    pub fn note_drops(&mut self, topic: &str, dropped: u64) {
        for map in [&mut self.drops_total, &mut self.drops_file] {
            let count = map.entry(topic.to_string()).or_insert(0);
            *count = count.saturating_add(dropped);
        }
    }

    /// Adds a metadata record now (e.g. a device identity learnt while recording). It is written
    /// into the current file and repeated at the start of every later part; a record of the same
    /// name given at creation is replaced for later parts.
    pub fn add_metadata(
        &mut self,
        name: &str,
        fields: BTreeMap<String, String>,
    ) -> Result<(), RecordingError> {
        self.add_metadata_once(name, fields.clone())?;
        self.metadata.retain(|(n, _)| n != name);
        self.metadata.push((name.to_string(), fields));
        Ok(())
    }

    /// Adds a metadata record to the current file only (an event of this file's time, such as
    /// an episode's record): unlike [`add_metadata`](Self::add_metadata) it is not repeated in
    /// later parts.
    pub fn add_metadata_once(
        &mut self,
        name: &str,
        fields: BTreeMap<String, String>,
    ) -> Result<(), RecordingError> {
        if name == CONTRACT_METADATA {
            return Err(RecordingError::invalid_use(
                &self.current,
                format!("the `{CONTRACT_METADATA}` record is written by the recorder itself"),
            ));
        }
        self.check_failed()?;
        let written = self.writer.write_metadata(&Metadata {
            name: name.to_string(),
            metadata: fields,
        });
        written.map_err(|e| {
            let e = RecordingError::mcap(&self.current, e);
            self.fail(e)
        })
    }

    /// Finishes the current file properly (drops record, summary, indexes, footer) and returns
    /// every path written with per-topic counts and drops. After a failure (see
    /// [`finish_all`](Self::finish_all)) it returns the first error.
    pub fn finish(self) -> Result<RecordingSummary, RecordingError> {
        match self.finish_all() {
            (summary, None) => Ok(summary),
            (_, Some(e)) => Err(e),
        }
    }

    /// Finishes what can be finished and says what could not: the summary (every file, the
    /// counts, and the file left unfinished if any) and the first error, if recording failed
    /// or the current file could not be finished. A file that could not be finished is cut
    /// back to the end of its last closed chunk, so it reads like a killed recorder's file.
    pub fn finish_all(mut self) -> (RecordingSummary, Option<RecordingError>) {
        let result = self.finish_current();
        let mut files = std::mem::take(&mut self.files);
        files.push(self.current.clone());
        let mut topics: Vec<TopicCount> = self
            .topics
            .iter()
            .map(|t| TopicCount {
                topic: t.name.clone(),
                schema_name: t.schema_name.clone(),
                messages: t.messages,
                drops: self.drops_total.get(&t.name).copied().unwrap_or(0),
            })
            .collect();
        for (topic, drops) in &self.drops_total {
            if !self.topics.iter().any(|t| &t.name == topic) {
                topics.push(TopicCount {
                    topic: topic.clone(),
                    schema_name: String::new(),
                    messages: 0,
                    drops: *drops,
                });
            }
        }
        let messages = self.topics.iter().map(|t| t.messages).sum();
        let error = match (result, &self.failed) {
            (Err(e), _) => Some(e),
            (Ok(()), Some(first)) => Some(RecordingError::Stopped {
                path: self.current.clone(),
                first: first.clone(),
            }),
            (Ok(()), None) => None,
        };
        let summary = RecordingSummary {
            files,
            unfinished: self.failed.is_some().then(|| self.current.clone()),
            topics,
            messages,
        };
        (summary, error)
    }

    /// Writes the drops record and the summary of the current file, and syncs it. After a
    /// failure the file is cut back to its last closed chunk instead.
    fn finish_current(&mut self) -> Result<(), RecordingError> {
        if std::mem::replace(&mut self.finished, true) {
            return Ok(());
        }
        if self.failed.is_some() {
            return self.cut_back();
        }
        let mut drops: BTreeMap<String, String> = self
            .topics
            .iter()
            .map(|t| (t.name.clone(), "0".to_string()))
            .collect();
        for (topic, count) in std::mem::take(&mut self.drops_file) {
            drops.insert(topic, count.to_string());
        }
        let result = self
            .writer
            .write_metadata(&Metadata {
                name: DROPS_METADATA.to_string(),
                metadata: drops,
            })
            .and_then(|()| self.writer.finish().map(drop))
            .map_err(|e| RecordingError::mcap(&self.current, e))
            .and_then(|()| {
                if self.options.sync {
                    self.size_probe
                        .sync_all()
                        .map_err(|e| RecordingError::io(&self.current, e))?;
                    sync_folder(&self.current)?;
                }
                Ok(())
            });
        if let Err(e) = result {
            let e = self.fail(e);
            // What the failed finish left after the last closed chunk is of no use.
            let _ = self.cut_back();
            return Err(e);
        }
        Ok(())
    }

    /// Cuts the current file back to the end of its last closed chunk (what a failed write
    /// left after it is a partial record), so readers see a killed recorder's file.
    fn cut_back(&mut self) -> Result<(), RecordingError> {
        self.size_probe
            .set_len(self.file_bytes)
            .and_then(|()| self.size_probe.sync_all())
            .map_err(|e| RecordingError::io(&self.current, e))
    }

    fn rotation_due(&self, log_time_ns: u64) -> bool {
        if self
            .rotation_retry_ns
            .is_some_and(|retry| log_time_ns < retry)
        {
            return false;
        }
        let by_time = match (self.options.rotate_after, self.file_start_ns) {
            (Some(after), Some(start)) => log_time_ns.saturating_sub(start) >= nanos(after),
            _ => false,
        };
        let by_size = match self.options.rotate_bytes {
            Some(limit) => self.file_bytes >= limit,
            None => false,
        };
        by_time || by_size
    }

    /// Finishes the current file and continues in the next part, which repeats the metadata,
    /// schemas and channels. The new file is made first, under the next part number whose file
    /// does not exist (an existing file is never touched): if that fails, recording goes on in
    /// the current file, the reason is kept for [`take_rotation_error`](Self::take_rotation_error),
    /// and rotating is tried again a `chunk_flush` of log time later. Only failing to finish
    /// the current file stops recording.
    fn rotate(&mut self, log_time_ns: u64) -> Result<(), RecordingError> {
        let (part, path, mut writer, probe, file_bytes) = match self.start_part() {
            Ok(started) => started,
            Err(e) => {
                self.rotation_error = Some(e.to_string());
                self.rotation_retry_ns =
                    Some(log_time_ns.saturating_add(nanos(self.options.chunk_flush)));
                return Ok(());
            }
        };
        self.rotation_retry_ns = None;
        let mut channels = Vec::with_capacity(self.topics.len());
        for t in &self.topics {
            match register(&mut writer, &path, &t.name, &t.schema_name, &t.schema_text) {
                Ok(channel) => channels.push(channel),
                Err(e) => {
                    drop(writer);
                    let _ = std::fs::remove_file(&path);
                    self.rotation_error = Some(e.to_string());
                    self.rotation_retry_ns =
                        Some(log_time_ns.saturating_add(nanos(self.options.chunk_flush)));
                    return Ok(());
                }
            }
        }
        if let Err(e) = self.finish_current() {
            // The current file stays the one that failed; the new one is not needed.
            drop(writer);
            let _ = std::fs::remove_file(&path);
            return Err(e);
        }
        // Already finished: dropping it does not write again.
        drop(std::mem::replace(&mut self.writer, writer));
        self.finished = false;
        let old_path = std::mem::replace(&mut self.current, path);
        self.files.push(old_path);
        self.size_probe = probe;
        self.part = part;
        self.file_bytes = file_bytes;
        self.file_start_ns = None;
        self.last_flush_ns = None;
        self.pending = false;
        for (t, channel) in self.topics.iter_mut().zip(channels) {
            t.channel = channel;
        }
        Ok(())
    }

    /// Creates the next part: the first number after the current one whose file does not
    /// exist (at most 1000 tries).
    #[allow(clippy::type_complexity)]
    fn start_part(
        &self,
    ) -> Result<(u32, PathBuf, Writer<BufWriter<File>>, File, u64), RecordingError> {
        let mut part = self.part;
        loop {
            part = part.saturating_add(1);
            let path = part_path(&self.base, part);
            match start_file(&path, &self.options, &self.metadata) {
                Ok((writer, probe, len)) => return Ok((part, path, writer, probe, len)),
                Err(RecordingError::Io { source, .. })
                    if source.kind() == std::io::ErrorKind::AlreadyExists
                        && part < self.part.saturating_add(1000) => {}
                Err(e) => return Err(e),
            }
        }
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        // Errors cannot be reported here; `finish` reports them.
        let _ = self.finish_current();
    }
}

fn register(
    writer: &mut Writer<BufWriter<File>>,
    path: &Path,
    topic: &str,
    schema_name: &str,
    schema_text: &str,
) -> Result<u16, RecordingError> {
    let schema = writer
        .add_schema(schema_name, SCHEMA_ENCODING, schema_text.as_bytes())
        .map_err(|e| RecordingError::mcap(path, e))?;
    writer
        .add_channel(schema, topic, MESSAGE_ENCODING, &BTreeMap::new())
        .map_err(|e| RecordingError::mcap(path, e))
}
