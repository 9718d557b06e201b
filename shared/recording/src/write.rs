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
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            chunk_flush: Duration::from_millis(100),
            rotate_bytes: None,
            rotate_after: None,
            compression: true,
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
    /// `<stem>_1.mcap`, `<stem>_2.mcap`, ... after rotations.
    pub files: Vec<PathBuf>,
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

/// Creates `path` (and its folder) and starts an MCAP file with `metadata` in it.
fn start_file(
    path: &Path,
    options: &WriterOptions,
    metadata: &[(String, BTreeMap<String, String>)],
    create_new: bool,
) -> Result<(Writer<BufWriter<File>>, File), RecordingError> {
    if let Some(parent) = path.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent).map_err(|e| RecordingError::io(parent, e))?;
        }
    }
    let file = File::options()
        .write(true)
        .read(true)
        .create(true)
        .create_new(create_new)
        .truncate(true)
        .open(path)
        .map_err(|e| RecordingError::io(path, e))?;
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
    // Header and metadata on disk now: a recorder killed from here on leaves a repairable file.
    writer.flush().map_err(|e| RecordingError::mcap(path, e))?;
    Ok((writer, probe))
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
        let (writer, size_probe) = start_file(path, &options, &metadata, true)?;
        Ok(Self {
            base: path.to_path_buf(),
            current: path.to_path_buf(),
            part: 0,
            options,
            metadata,
            writer,
            size_probe,
            file_bytes: 0,
            topics: Vec::new(),
            drops_total: BTreeMap::new(),
            drops_file: BTreeMap::new(),
            files: Vec::new(),
            file_start_ns: None,
            last_flush_ns: None,
            pending: false,
            buf: Vec::new(),
            finished: false,
        })
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
        if self.rotation_due(msg.log_time_ns) {
            self.rotate()?;
        }
        let topic = &mut self.topics[id.0];
        self.buf.clear();
        self.buf.extend_from_slice(&CDR_LE_HEADER);
        self.buf.extend_from_slice(msg.payload);
        self.writer
            .write_to_known_channel(
                &MessageHeader {
                    channel_id: topic.channel,
                    sequence: msg.sequence,
                    log_time: msg.log_time_ns,
                    publish_time: msg.publish_time_ns,
                },
                &self.buf,
            )
            .map_err(|e| RecordingError::mcap(&self.current, e))?;
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

    /// Closes the open chunk now and hands everything written so far to the operating system.
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.writer
            .flush()
            .map_err(|e| RecordingError::mcap(&self.current, e))?;
        self.pending = false;
        self.file_bytes = self
            .size_probe
            .metadata()
            .map_err(|e| RecordingError::io(&self.current, e))?
            .len();
        Ok(())
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
        if name == CONTRACT_METADATA {
            return Err(RecordingError::invalid_use(
                &self.current,
                format!("the `{CONTRACT_METADATA}` record is written by the recorder itself"),
            ));
        }
        self.writer
            .write_metadata(&Metadata {
                name: name.to_string(),
                metadata: fields.clone(),
            })
            .map_err(|e| RecordingError::mcap(&self.current, e))?;
        self.metadata.retain(|(n, _)| n != name);
        self.metadata.push((name.to_string(), fields));
        Ok(())
    }

    /// Finishes the current file properly (drops record, summary, indexes, footer) and returns
    /// every path written with per-topic counts and drops.
    pub fn finish(mut self) -> Result<RecordingSummary, RecordingError> {
        self.finish_current()?;
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
        Ok(RecordingSummary {
            files,
            topics,
            messages,
        })
    }

    /// Writes the drops record and the summary of the current file.
    fn finish_current(&mut self) -> Result<(), RecordingError> {
        if std::mem::replace(&mut self.finished, true) {
            return Ok(());
        }
        let mut drops: BTreeMap<String, String> = self
            .topics
            .iter()
            .map(|t| (t.name.clone(), "0".to_string()))
            .collect();
        for (topic, count) in std::mem::take(&mut self.drops_file) {
            drops.insert(topic, count.to_string());
        }
        self.writer
            .write_metadata(&Metadata {
                name: DROPS_METADATA.to_string(),
                metadata: drops,
            })
            .and_then(|()| self.writer.finish())
            .map_err(|e| RecordingError::mcap(&self.current, e))?;
        Ok(())
    }

    fn rotation_due(&self, log_time_ns: u64) -> bool {
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
    /// schemas and channels. The new file is made first: if that fails, recording goes on in
    /// the current one.
    fn rotate(&mut self) -> Result<(), RecordingError> {
        let part = self.part + 1;
        let path = part_path(&self.base, part);
        let (mut writer, probe) = start_file(&path, &self.options, &self.metadata, false)?;
        let mut channels = Vec::with_capacity(self.topics.len());
        for t in &self.topics {
            channels.push(register(
                &mut writer,
                &path,
                &t.name,
                &t.schema_name,
                &t.schema_text,
            )?);
        }
        let result = self.finish_current();
        // Already finished (or failed): dropping it does not write again.
        drop(std::mem::replace(&mut self.writer, writer));
        self.finished = false;
        let old_path = std::mem::replace(&mut self.current, path);
        self.files.push(old_path);
        self.size_probe = probe;
        self.part = part;
        self.file_bytes = 0;
        self.file_start_ns = None;
        self.last_flush_ns = None;
        self.pending = false;
        for (t, channel) in self.topics.iter_mut().zip(channels) {
            t.channel = channel;
        }
        result
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
