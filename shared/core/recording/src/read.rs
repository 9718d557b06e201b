//! Reading recordings: [`info`], [`read_messages`] and [`read_samples`].

use std::{
    borrow::Cow,
    collections::{BTreeMap, HashMap, HashSet},
    fs::File,
    io::{Read, Seek, SeekFrom},
    path::{Path, PathBuf},
    sync::Arc,
    time::Duration,
};

use mcap::{
    records::{ChunkIndex, Record, SchemaHeader},
    sans_io::{indexed_reader::ReadOrder, IndexedReadEvent, IndexedReader, IndexedReaderOptions},
    Summary,
};

use teleop_msgs::Message;
use teleop_namespace::{qualified, Namespace};

use crate::{
    file::{
        check_channel, converted_from, open, payload, read_record_at, read_summary, record_limit,
        ChannelKind, OpenFile, RecordStream, RecordedSchema,
    },
    write::DROPS_METADATA,
    RecordingError,
};

/// One topic of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    /// Topic name.
    pub topic: String,
    /// Schema name (empty when the channel has none).
    pub schema_name: String,
    /// Message encoding (`cdr` for everything this crate writes).
    pub message_encoding: String,
    /// Messages recorded.
    pub messages: u64,
    /// Log time of the first message (ns), if any.
    pub first_log_ns: Option<u64>,
    /// Log time of the last message (ns), if any.
    pub last_log_ns: Option<u64>,
    /// Mean rate between the first and the last message, in Hz (0 with fewer than 2 messages).
    pub rate_hz: f64,
    /// Drops recorded in the `drops` metadata record; `None` when the file has none (a killed
    /// recorder writes it only when finishing).
    pub drops: Option<u64>,
    /// `Some(version)`: recorded with the layout of that earlier contract version, which
    /// [`read_messages`] converts to the current payload. `None`: the current layout, a topic
    /// outside the contract, or a schema that reading refuses.
    pub converted_from: Option<u32>,
}

/// What a recording holds.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingInfo {
    /// The file.
    pub path: PathBuf,
    /// Size of the file in bytes.
    pub size_bytes: u64,
    /// Topics, sorted by name.
    pub topics: Vec<TopicInfo>,
    /// Messages over all topics.
    pub messages: u64,
    /// Log time from the first to the last message.
    pub duration: Duration,
    /// Log time of the first message (ns; 0 without messages).
    pub start_ns: u64,
    /// Log time of the last message (ns; 0 without messages).
    pub end_ns: u64,
    /// Metadata records in file order (name, fields), including `drops` when present.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// The file was finished (summary and footer present). `false` for a killed recorder's
    /// file: what is listed then is what its closed chunks hold.
    pub complete: bool,
}

/// Which messages [`read_messages`] yields.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Filter {
    /// Only these topics (`None` = all).
    pub topics: Option<Vec<String>>,
    /// Only messages logged at least this long after the recording's first message.
    pub start: Option<Duration>,
    /// Only messages logged less than this long after the recording's first message.
    pub end: Option<Duration>,
}

impl Filter {
    /// Every message.
    pub fn all() -> Self {
        Self::default()
    }

    /// Only messages of `topics`.
    pub fn topics<I, S>(topics: I) -> Self
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        Self {
            topics: Some(topics.into_iter().map(Into::into).collect()),
            ..Self::default()
        }
    }
}

/// One message read back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OwnedMessage {
    /// Topic name.
    pub topic: String,
    /// Schema name of its channel.
    pub schema_name: String,
    /// Message encoding of its channel (`cdr` for everything this crate writes).
    pub message_encoding: String,
    /// When the recorder received it (ns).
    pub log_time_ns: u64,
    /// The sample's own stamp (ns).
    pub publish_time_ns: u64,
    /// The sample's sequence number (low 32 bits).
    pub sequence: u32,
    /// The payload: for `cdr` channels without the 4-byte CDR header (for contract topics,
    /// exactly the `repr(C)` bytes of the current contract's type, converted when the file was
    /// recorded with an earlier contract version); other encodings as recorded.
    pub payload: Vec<u8>,
}

impl OwnedMessage {
    /// The payload as the contract type `M`, if this message is on `M`'s topic.
    pub fn decode<M: teleop_msgs::Message>(&self) -> Option<M> {
        if self.topic != M::TOPIC {
            return None;
        }
        M::from_bytes(&self.payload).ok()
    }
}

/// Per-channel bookkeeping.
#[derive(Default)]
struct ChannelStats {
    topic: String,
    schema_name: String,
    message_encoding: String,
    converted_from: Option<u32>,
    messages: u64,
    first: Option<u64>,
    last: Option<u64>,
}

impl ChannelStats {
    fn add(&mut self, log_time: u64) {
        self.messages += 1;
        self.first = Some(self.first.map_or(log_time, |f| f.min(log_time)));
        self.last = Some(self.last.map_or(log_time, |l| l.max(log_time)));
    }
}

fn drops_of(metadata: &[(String, BTreeMap<String, String>)]) -> Option<HashMap<String, u64>> {
    let mut drops: Option<HashMap<String, u64>> = None;
    for (name, fields) in metadata {
        if name != DROPS_METADATA {
            continue;
        }
        let map = drops.get_or_insert_with(HashMap::new);
        for (topic, count) in fields {
            if let Ok(count) = count.trim().parse::<u64>() {
                *map.entry(topic.clone()).or_insert(0) += count;
            }
        }
    }
    drops
}

fn assemble(
    path: &Path,
    size_bytes: u64,
    channels: Vec<ChannelStats>,
    metadata: Vec<(String, BTreeMap<String, String>)>,
    complete: bool,
) -> RecordingInfo {
    let drops = drops_of(&metadata);
    let mut by_topic: BTreeMap<String, TopicInfo> = BTreeMap::new();
    for c in channels {
        let entry = by_topic
            .entry(c.topic.clone())
            .or_insert_with(|| TopicInfo {
                topic: c.topic.clone(),
                schema_name: c.schema_name.clone(),
                message_encoding: c.message_encoding.clone(),
                messages: 0,
                first_log_ns: None,
                last_log_ns: None,
                rate_hz: 0.0,
                drops: drops
                    .as_ref()
                    .map(|d| d.get(&c.topic).copied().unwrap_or(0)),
                converted_from: c.converted_from,
            });
        entry.messages += c.messages;
        entry.first_log_ns = min_opt(entry.first_log_ns, c.first);
        entry.last_log_ns = max_opt(entry.last_log_ns, c.last);
    }
    let mut topics: Vec<TopicInfo> = by_topic.into_values().collect();
    for t in &mut topics {
        if let (Some(first), Some(last)) = (t.first_log_ns, t.last_log_ns) {
            if t.messages >= 2 && last > first {
                t.rate_hz = (t.messages - 1) as f64 / ((last - first) as f64 * 1e-9);
            }
        }
    }
    let start_ns = topics.iter().filter_map(|t| t.first_log_ns).min();
    let end_ns = topics.iter().filter_map(|t| t.last_log_ns).max();
    let (start_ns, end_ns) = match (start_ns, end_ns) {
        (Some(s), Some(e)) => (s, e),
        _ => (0, 0),
    };
    RecordingInfo {
        path: path.to_path_buf(),
        size_bytes,
        messages: topics.iter().map(|t| t.messages).sum(),
        topics,
        duration: Duration::from_nanos(end_ns.saturating_sub(start_ns)),
        start_ns,
        end_ns,
        metadata,
        complete,
    }
}

fn min_opt(a: Option<u64>, b: Option<u64>) -> Option<u64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

fn max_opt(a: Option<u64>, b: Option<u64>) -> Option<u64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.max(b)),
        (a, b) => a.or(b),
    }
}

/// Describes a recording: topics with counts, first/last times, rates and drops, the metadata
/// records, and whether the file was finished.
///
/// A finished file is described from its summary and indexes without reading its messages. A
/// killed recorder's file (no summary, no footer) is streamed to the end of its last closed
/// chunk, and `complete` is false.
pub fn info(path: &Path) -> Result<RecordingInfo, RecordingError> {
    let mut file = open(path)?;
    if file.has_footer {
        if let Some(summary) = read_summary(&mut file)? {
            return info_from_summary(file, &summary);
        }
    }
    info_by_streaming(file)
}

fn info_from_summary(
    mut file: OpenFile,
    summary: &Summary,
) -> Result<RecordingInfo, RecordingError> {
    let mut metadata = Vec::with_capacity(summary.metadata_indexes.len());
    for index in &summary.metadata_indexes {
        match read_record_at(&mut file, index.offset, index.length)? {
            Record::Metadata(m) => metadata.push((m.name, m.metadata)),
            _ => {
                return Err(RecordingError::Mcap {
                    path: file.path.clone(),
                    detail: format!(
                        "the metadata index at {} does not point to a metadata record",
                        index.offset
                    ),
                })
            }
        }
    }
    let counts = summary
        .stats
        .as_ref()
        .map(|s| s.channel_message_counts.clone());
    let mut channels: Vec<(u16, ChannelStats)> = summary
        .channels
        .iter()
        .map(|(id, c)| {
            (
                *id,
                ChannelStats {
                    topic: c.topic.clone(),
                    schema_name: c
                        .schema
                        .as_ref()
                        .map(|s| s.name.clone())
                        .unwrap_or_default(),
                    message_encoding: c.message_encoding.clone(),
                    converted_from: converted_from(
                        &file.path,
                        &c.topic,
                        c.schema
                            .as_ref()
                            .map(|s| RecordedSchema::from(&**s))
                            .as_ref(),
                        &c.message_encoding,
                    ),
                    ..ChannelStats::default()
                },
            )
        })
        .collect();
    channels.sort_by_key(|(id, _)| *id);
    let indexed = match &counts {
        Some(counts) => channel_times_from_indexes(&mut file, summary, counts, &mut channels)?,
        None => false,
    };
    if !indexed {
        // No statistics or message indexes: count by reading the messages.
        return info_by_streaming(open(&file.path)?);
    }
    Ok(assemble(
        &file.path,
        file.len,
        channels.into_iter().map(|(_, c)| c).collect(),
        metadata,
        true,
    ))
}

/// Fills counts and first/last log times from the statistics and the message indexes, reading
/// only the indexes of the first and last chunks of each channel. `false` when the file lacks
/// the indexes to do so.
fn channel_times_from_indexes(
    file: &mut OpenFile,
    summary: &Summary,
    counts: &BTreeMap<u16, u64>,
    channels: &mut [(u16, ChannelStats)],
) -> Result<bool, RecordingError> {
    let mut by_start: Vec<&ChunkIndex> = summary.chunk_indexes.iter().collect();
    by_start.sort_by_key(|c| (c.message_start_time, c.chunk_start_offset));
    let mut by_end: Vec<&ChunkIndex> = summary.chunk_indexes.iter().collect();
    by_end.sort_by_key(|c| std::cmp::Reverse((c.message_end_time, c.chunk_start_offset)));
    for (id, stats) in channels.iter_mut() {
        let count = counts.get(id).copied().unwrap_or(0);
        stats.messages = count;
        if count == 0 {
            continue;
        }
        let mut first: Option<u64> = None;
        for chunk in &by_start {
            if first.is_some_and(|f| chunk.message_start_time >= f) {
                break;
            }
            if let Some(&offset) = chunk.message_index_offsets.get(id) {
                let times = index_times(file, offset, chunk.message_index_length)?;
                first = min_opt(first, times.map(|(lo, _)| lo));
            }
        }
        let mut last: Option<u64> = None;
        for chunk in &by_end {
            if last.is_some_and(|l| chunk.message_end_time <= l) {
                break;
            }
            if let Some(&offset) = chunk.message_index_offsets.get(id) {
                let times = index_times(file, offset, chunk.message_index_length)?;
                last = max_opt(last, times.map(|(_, hi)| hi));
            }
        }
        if first.is_none() || last.is_none() {
            return Ok(false);
        }
        stats.first = first;
        stats.last = last;
    }
    Ok(true)
}

/// Earliest and latest log time in the message index record at `offset`.
fn index_times(
    file: &mut OpenFile,
    offset: u64,
    max_len: u64,
) -> Result<Option<(u64, u64)>, RecordingError> {
    match read_record_at(file, offset, max_len)? {
        Record::MessageIndex(index) => {
            let lo = index.records.iter().map(|e| e.log_time).min();
            let hi = index.records.iter().map(|e| e.log_time).max();
            Ok(lo.zip(hi))
        }
        _ => Err(RecordingError::Mcap {
            path: file.path.clone(),
            detail: format!("the chunk index entry at {offset} is not a message index"),
        }),
    }
}

fn info_by_streaming(file: OpenFile) -> Result<RecordingInfo, RecordingError> {
    let finished = file.has_footer;
    let path = file.path.clone();
    let len = file.len;
    let mut stream = RecordStream::new(file)?;
    let mut schemas: HashMap<u16, StreamSchema> = HashMap::new();
    let mut channels: BTreeMap<u16, ChannelStats> = BTreeMap::new();
    let mut metadata = Vec::new();
    let mut in_data = true;
    let mut complete = false;
    while let Some(record) = stream.next_record() {
        let record = match record {
            Ok(r) => r,
            // A finished file must read to its end; a killed one ends where it ends.
            Err(e) if finished => return Err(e),
            Err(_) => break,
        };
        match record {
            Record::Schema { header, data } => {
                schemas.insert(header.id, StreamSchema::new(header, data));
            }
            Record::Channel(c) => {
                let schema = schemas.get(&c.schema_id);
                let entry = channels.entry(c.id).or_default();
                entry.converted_from = converted_from(
                    &path,
                    &c.topic,
                    schema.map(RecordedSchema::from).as_ref(),
                    &c.message_encoding,
                );
                entry.topic = c.topic;
                entry.schema_name = schema.map(|s| s.name.clone()).unwrap_or_default();
                entry.message_encoding = c.message_encoding;
            }
            Record::Message { header, .. } if in_data => {
                channels
                    .entry(header.channel_id)
                    .or_default()
                    .add(header.log_time);
            }
            Record::Metadata(m) if in_data => metadata.push((m.name, m.metadata)),
            Record::DataEnd(_) => in_data = false,
            Record::Footer(_) => complete = true,
            _ => {}
        }
    }
    Ok(assemble(
        &path,
        len,
        channels.into_values().collect(),
        metadata,
        complete,
    ))
}

/// Reads messages: in log-time order from a finished file (through its indexes), in file order
/// from a killed recorder's file (up to the end of its last closed chunk, without an error
/// for the cut-off tail). Filtered by topics and by a time window relative to the recording's
/// first message.
///
/// Channels of contract topics are checked against the contract: a different schema name or
/// encoding is [`RecordingError::UnknownSchema`]; the schema text of an earlier contract
/// version that this build converts (see [`crate::legacy`]) is read and each
/// message converted to the current payload; any other schema text is
/// [`RecordingError::WrongSchemaVersion`]. Each message must carry the CDR little-endian
/// header and the exact size of its recorded type. For finished files the channels selected by
/// the filter are checked before this returns. Topics outside the contract are yielded as
/// recorded (CDR header removed for `cdr` channels): callers decide. The iterator ends after
/// its first error.
pub fn read_messages(path: &Path, filter: &Filter) -> Result<Messages, RecordingError> {
    if let (Some(start), Some(end)) = (filter.start, filter.end) {
        if end < start {
            return Err(RecordingError::invalid_use(
                path,
                format!("the time window ends ({end:?}) before it starts ({start:?})"),
            ));
        }
    }
    let mut file = open(path)?;
    if file.has_footer {
        if let Some(summary) = read_summary(&mut file)? {
            return indexed_messages(file, summary, filter);
        }
    }
    streamed_messages(file, filter)
}

/// A selected channel.
struct Selected {
    topic: Arc<str>,
    schema_name: Arc<str>,
    message_encoding: Arc<str>,
    kind: ChannelKind,
}

impl Selected {
    fn message(
        &self,
        path: &Path,
        header: &mcap::records::MessageHeader,
        data: &[u8],
    ) -> Result<OwnedMessage, RecordingError> {
        let body = payload(path, &self.topic, self.kind, data)?;
        Ok(OwnedMessage {
            topic: self.topic.to_string(),
            schema_name: self.schema_name.to_string(),
            message_encoding: self.message_encoding.to_string(),
            log_time_ns: header.log_time,
            publish_time_ns: header.publish_time,
            sequence: header.sequence,
            payload: body.into_owned(),
        })
    }
}

fn window(filter: &Filter, start_ns: u64) -> (Option<u64>, Option<u64>) {
    let at = |d: Duration| start_ns.saturating_add(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
    (filter.start.map(at), filter.end.map(at))
}

fn wanted(filter: &Filter, topic: &str) -> bool {
    filter
        .topics
        .as_ref()
        .is_none_or(|topics| topics.iter().any(|t| t == topic))
}

fn indexed_messages(
    file: OpenFile,
    summary: Summary,
    filter: &Filter,
) -> Result<Messages, RecordingError> {
    let mut selected = HashMap::new();
    for (id, channel) in &summary.channels {
        if !wanted(filter, &channel.topic) {
            continue;
        }
        let schema = channel.schema.as_ref().map(|s| RecordedSchema::from(&**s));
        let kind = check_channel(
            &file.path,
            &channel.topic,
            schema.as_ref(),
            &channel.message_encoding,
        )?;
        selected.insert(
            *id,
            Selected {
                topic: channel.topic.as_str().into(),
                schema_name: channel
                    .schema
                    .as_ref()
                    .map(|s| s.name.as_str())
                    .unwrap_or("")
                    .into(),
                message_encoding: channel.message_encoding.as_str().into(),
                kind,
            },
        );
    }
    let path = file.path.clone();
    if selected.is_empty() {
        return Ok(Messages::empty(path));
    }
    let start_ns = summary
        .stats
        .as_ref()
        .filter(|s| s.message_count > 0)
        .map(|s| s.message_start_time)
        .or_else(|| {
            summary
                .chunk_indexes
                .iter()
                .map(|c| c.message_start_time)
                .min()
        })
        .unwrap_or(0);
    let (from, to) = window(filter, start_ns);
    let mut options = IndexedReaderOptions::new()
        .with_order(ReadOrder::LogTime)
        .with_record_length_limit(record_limit(file.len));
    if filter.topics.is_some() {
        options = options.include_topics(selected.values().map(|s| s.topic.to_string()));
    }
    if let Some(from) = from {
        options = options.starting_at(from);
    }
    if let Some(to) = to {
        options = options.ending_before(to);
    }
    let reader = IndexedReader::new_with_options(&summary, options)
        .map_err(|e| RecordingError::mcap(&path, e))?;
    Ok(Messages {
        path,
        inner: Inner::Indexed(Box::new(IndexedState {
            file: file.file,
            len: file.len,
            reader,
            selected,
            buf: Vec::new(),
        })),
    })
}

fn streamed_messages(file: OpenFile, filter: &Filter) -> Result<Messages, RecordingError> {
    let path = file.path.clone();
    let strict = file.has_footer;
    let (from, to) = if filter.start.is_some() || filter.end.is_some() {
        // The window is relative to the first message: find it first.
        let start_ns = first_log_time(open(&path)?, strict)?.unwrap_or(0);
        window(filter, start_ns)
    } else {
        (None, None)
    };
    Ok(Messages {
        path,
        inner: Inner::Streamed(Box::new(StreamState {
            stream: RecordStream::new(file)?,
            strict,
            topics: filter.topics.as_ref().map(|t| t.iter().cloned().collect()),
            from,
            to,
            schemas: HashMap::new(),
            channels: HashMap::new(),
        })),
    })
}

fn first_log_time(file: OpenFile, strict: bool) -> Result<Option<u64>, RecordingError> {
    let mut stream = RecordStream::new(file)?;
    let mut first: Option<u64> = None;
    while let Some(record) = stream.next_record() {
        match record {
            Ok(Record::Message { header, .. }) => first = min_opt(first, Some(header.log_time)),
            Ok(Record::DataEnd(_)) => break,
            Ok(_) => {}
            Err(e) if strict => return Err(e),
            Err(_) => break,
        }
    }
    Ok(first)
}

/// The samples of one contract type in a recording, from [`read_samples`].
#[derive(Debug, Clone, PartialEq)]
pub struct Samples<M> {
    /// The decoded samples, in [`read_messages`]'s order (log time for a finished file).
    pub samples: Vec<M>,
    /// Messages on the topic whose payload did not decode as `M`, skipped.
    pub undecodable: u64,
}

/// Every sample of contract type `M` in a recording: the messages on `M`'s topic in
/// `namespace` (`left/glove/state` in `left`, `glove/state` with `None`), decoded. Errors as
/// [`read_messages`]'s, with the reading stopped at the first.
pub fn read_samples<M: Message>(
    path: &Path,
    namespace: Option<&Namespace>,
) -> Result<Samples<M>, RecordingError> {
    let topic = qualified(namespace, M::TOPIC);
    let mut out = Samples {
        samples: Vec::new(),
        undecodable: 0,
    };
    for msg in read_messages(path, &Filter::topics([topic]))? {
        // Not `OwnedMessage::decode`: that wants the topic without a namespace.
        match M::from_bytes(&msg?.payload) {
            Ok(sample) => out.samples.push(sample),
            Err(_) => out.undecodable += 1,
        }
    }
    Ok(out)
}

/// The messages of a recording, from [`read_messages`].
pub struct Messages {
    path: PathBuf,
    inner: Inner,
}

enum Inner {
    Done,
    Indexed(Box<IndexedState>),
    Streamed(Box<StreamState>),
}

struct IndexedState {
    file: File,
    len: u64,
    reader: IndexedReader,
    selected: HashMap<u16, Selected>,
    buf: Vec<u8>,
}

struct StreamSchema {
    name: String,
    encoding: String,
    data: Vec<u8>,
}

impl StreamSchema {
    /// The schema of a `Schema` record met while streaming.
    fn new(header: SchemaHeader, data: Cow<'_, [u8]>) -> Self {
        Self {
            name: header.name,
            encoding: header.encoding,
            data: data.into_owned(),
        }
    }
}

impl<'a> From<&'a StreamSchema> for RecordedSchema<'a> {
    fn from(s: &'a StreamSchema) -> Self {
        Self {
            name: &s.name,
            encoding: &s.encoding,
            data: &s.data,
        }
    }
}

impl<'a> From<&'a mcap::Schema<'_>> for RecordedSchema<'a> {
    fn from(s: &'a mcap::Schema<'_>) -> Self {
        Self {
            name: &s.name,
            encoding: &s.encoding,
            data: &s.data,
        }
    }
}

struct StreamState {
    stream: RecordStream,
    /// Errors from the MCAP layer are reported (finished file) or end the iteration quietly
    /// (a killed recorder's cut-off tail).
    strict: bool,
    topics: Option<HashSet<String>>,
    from: Option<u64>,
    to: Option<u64>,
    schemas: HashMap<u16, StreamSchema>,
    /// `None`: the channel is filtered out.
    channels: HashMap<u16, Option<Selected>>,
}

impl std::fmt::Debug for Messages {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mode = match self.inner {
            Inner::Done => "done",
            Inner::Indexed(_) => "indexed",
            Inner::Streamed(_) => "streamed",
        };
        f.debug_struct("Messages")
            .field("path", &self.path)
            .field("mode", &mode)
            .finish()
    }
}

impl Messages {
    fn empty(path: PathBuf) -> Self {
        Self {
            path,
            inner: Inner::Done,
        }
    }

    /// The file being read.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Iterator for Messages {
    type Item = Result<OwnedMessage, RecordingError>;

    fn next(&mut self) -> Option<Self::Item> {
        let item = match &mut self.inner {
            Inner::Done => return None,
            Inner::Indexed(state) => state.next(&self.path),
            Inner::Streamed(state) => state.next(&self.path),
        };
        if !matches!(item, Some(Ok(_))) {
            self.inner = Inner::Done;
        }
        item
    }
}

impl IndexedState {
    fn next(&mut self, path: &Path) -> Option<Result<OwnedMessage, RecordingError>> {
        loop {
            let (offset, length) = match self.reader.next_event()? {
                Err(e) => return Some(Err(RecordingError::mcap(path, e))),
                Ok(IndexedReadEvent::Message { header, data }) => {
                    // Unselected channels only appear when no topic filter was given to the
                    // reader; they were all selected then, so this is a damaged file.
                    let Some(selected) = self.selected.get(&header.channel_id) else {
                        return Some(Err(RecordingError::Mcap {
                            path: path.to_path_buf(),
                            detail: format!(
                                "a message refers to unknown channel {}",
                                header.channel_id
                            ),
                        }));
                    };
                    return Some(selected.message(path, &header, data));
                }
                Ok(IndexedReadEvent::ReadChunkRequest { offset, length }) => (offset, length),
            };
            if offset.saturating_add(length as u64) > self.len {
                return Some(Err(RecordingError::Mcap {
                    path: path.to_path_buf(),
                    detail: format!("a chunk index points outside the file (offset {offset})"),
                }));
            }
            self.buf.resize(length, 0);
            let read = self
                .file
                .seek(SeekFrom::Start(offset))
                .and_then(|_| self.file.read_exact(&mut self.buf));
            if let Err(e) = read {
                return Some(Err(RecordingError::io(path, e)));
            }
            if let Err(e) = self.reader.insert_chunk_record_data(offset, &self.buf) {
                return Some(Err(RecordingError::mcap(path, e)));
            }
        }
    }
}

impl StreamState {
    fn next(&mut self, path: &Path) -> Option<Result<OwnedMessage, RecordingError>> {
        loop {
            let record = match self.stream.next_record()? {
                Ok(record) => record,
                Err(e) if self.strict => return Some(Err(e)),
                Err(_) => return None,
            };
            match record {
                Record::Schema { header, data } => {
                    self.schemas
                        .insert(header.id, StreamSchema::new(header, data));
                }
                Record::Channel(c) => {
                    let wanted = self.topics.as_ref().is_none_or(|t| t.contains(&c.topic));
                    if !wanted {
                        self.channels.insert(c.id, None);
                        continue;
                    }
                    let schema = self.schemas.get(&c.schema_id);
                    if c.schema_id != 0 && schema.is_none() {
                        return Some(Err(RecordingError::Mcap {
                            path: path.to_path_buf(),
                            detail: format!(
                                "channel `{}` refers to unknown schema {}",
                                c.topic, c.schema_id
                            ),
                        }));
                    }
                    let recorded = schema.map(RecordedSchema::from);
                    let kind =
                        match check_channel(path, &c.topic, recorded.as_ref(), &c.message_encoding)
                        {
                            Ok(kind) => kind,
                            Err(e) => return Some(Err(e)),
                        };
                    let schema_name: Arc<str> =
                        schema.map(|s| s.name.as_str()).unwrap_or("").into();
                    self.channels.insert(
                        c.id,
                        Some(Selected {
                            topic: c.topic.into(),
                            schema_name,
                            message_encoding: c.message_encoding.into(),
                            kind,
                        }),
                    );
                }
                Record::Message { header, data } => {
                    let Some(channel) = self.channels.get(&header.channel_id) else {
                        return Some(Err(RecordingError::Mcap {
                            path: path.to_path_buf(),
                            detail: format!(
                                "a message refers to unknown channel {}",
                                header.channel_id
                            ),
                        }));
                    };
                    let Some(selected) = channel else { continue };
                    if self.from.is_some_and(|from| header.log_time < from)
                        || self.to.is_some_and(|to| header.log_time >= to)
                    {
                        continue;
                    }
                    return Some(selected.message(path, &header, &data));
                }
                // The summary section only repeats what was read.
                Record::DataEnd(_) => return None,
                _ => {}
            }
        }
    }
}

/// Metadata records: name and fields, in file order.
pub type Metadata = Vec<(String, BTreeMap<String, String>)>;

/// The metadata records at the start of a file, before its first schema, channel, message or
/// chunk (where [`crate::Recorder`] writes the records it was created with): cheap to read, for
/// telling files apart without reading them.
pub fn head_metadata(path: &Path) -> Result<Metadata, RecordingError> {
    let mut stream = RecordStream::new(open(path)?)?;
    let mut metadata = Vec::new();
    while let Some(record) = stream.next_record() {
        match record? {
            Record::Header(_) => {}
            Record::Metadata(m) => metadata.push((m.name, m.metadata)),
            _ => break,
        }
    }
    Ok(metadata)
}
