//! Low-level reading shared by `info`, `read_messages` and `repair`: opening a file with a clear
//! verdict on its start and end, streaming its records, reading its summary, and checking
//! channels against the message contract.

use std::{
    borrow::Cow,
    fs::File,
    io::{BufReader, ErrorKind, Read, Seek, SeekFrom},
    path::{Path, PathBuf},
};

use mcap::{
    records::{op, Record},
    sans_io::{
        LinearReadEvent, LinearReader, LinearReaderOptions, SummaryReadEvent, SummaryReader,
        SummaryReaderOptions,
    },
    Summary, MAGIC,
};
use teleop_msgs::{Message, TopicVisitor, CDR_LE_HEADER};

use crate::{legacy::Legacy, RecordingError};

/// Schema encoding of every contract schema.
pub(crate) const SCHEMA_ENCODING: &str = "ros2msg";
/// Message encoding of every contract channel.
pub(crate) const MESSAGE_ENCODING: &str = "cdr";
/// MCAP header profile of the files we write (what ROS 2 tools expect for `cdr`/`ros2msg`).
pub(crate) const PROFILE: &str = "ros2";

/// Opcode + record length.
const RECORD_PREFIX: usize = 9;
/// Footer record (opcode, length, 20-byte body) and the end magic.
const FOOTER_AND_MAGIC: u64 = 9 + 20 + 8;
/// A header record longer than this is not one we could have written.
const MAX_HEADER_LEN: u64 = 1 << 20;

/// An MCAP file whose start has been checked.
pub(crate) struct OpenFile {
    pub path: PathBuf,
    pub file: File,
    pub len: u64,
    /// The file ends with a footer record and the end magic: it was finished.
    pub has_footer: bool,
}

/// Opens `path` and checks it starts with the MCAP magic and a complete header record.
pub(crate) fn open(path: &Path) -> Result<OpenFile, RecordingError> {
    let mut file = File::open(path).map_err(|e| RecordingError::io(path, e))?;
    let len = file
        .metadata()
        .map_err(|e| RecordingError::io(path, e))?
        .len();
    check_start(path, &mut file, len)?;
    let has_footer = has_footer(&mut file, len).map_err(|e| RecordingError::io(path, e))?;
    Ok(OpenFile {
        path: path.to_path_buf(),
        file,
        len,
        has_footer,
    })
}

fn truncated(path: &Path, detail: String) -> RecordingError {
    RecordingError::Truncated {
        path: path.to_path_buf(),
        detail,
    }
}

/// Reads as many bytes as are there, up to `buf.len()`.
fn read_up_to(file: &mut File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match file.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

fn check_start(path: &Path, file: &mut File, len: u64) -> Result<(), RecordingError> {
    let mut head = [0u8; 8 + RECORD_PREFIX];
    let n = read_up_to(file, &mut head).map_err(|e| RecordingError::io(path, e))?;
    let magic_part = &head[..n.min(MAGIC.len())];
    if magic_part != &MAGIC[..magic_part.len()] {
        return Err(RecordingError::NotMcap {
            path: path.to_path_buf(),
        });
    }
    if n == 0 {
        return Err(truncated(path, "the file is empty".to_string()));
    }
    if n < MAGIC.len() {
        return Err(truncated(
            path,
            format!("the file ends after {n} bytes, inside the magic"),
        ));
    }
    if n < head.len() {
        return Err(truncated(
            path,
            format!("the file ends after {n} bytes, inside the header record"),
        ));
    }
    if head[8] != op::HEADER {
        return Err(RecordingError::Mcap {
            path: path.to_path_buf(),
            detail: format!("the first record is not a header (opcode {:#04x})", head[8]),
        });
    }
    let mut len_bytes = [0u8; 8];
    len_bytes.copy_from_slice(&head[9..17]);
    let header_len = u64::from_le_bytes(len_bytes);
    let available = len.saturating_sub(head.len() as u64);
    if header_len > available {
        if header_len > MAX_HEADER_LEN {
            return Err(RecordingError::Mcap {
                path: path.to_path_buf(),
                detail: format!("the header record claims {header_len} bytes"),
            });
        }
        return Err(truncated(
            path,
            format!(
                "the header record needs {header_len} bytes, the file has {available} after it"
            ),
        ));
    }
    if header_len > MAX_HEADER_LEN {
        return Err(RecordingError::Mcap {
            path: path.to_path_buf(),
            detail: format!("the header record claims {header_len} bytes"),
        });
    }
    // Bounded by MAX_HEADER_LEN above.
    let mut body = vec![0u8; header_len as usize];
    file.read_exact(&mut body)
        .map_err(|e| RecordingError::io(path, e))?;
    match mcap::parse_record(op::HEADER, &body) {
        Ok(_) => Ok(()),
        Err(e) => Err(RecordingError::Mcap {
            path: path.to_path_buf(),
            detail: format!("bad header record: {e}"),
        }),
    }
}

fn has_footer(file: &mut File, len: u64) -> std::io::Result<bool> {
    if len < MAGIC.len() as u64 + FOOTER_AND_MAGIC {
        return Ok(false);
    }
    let mut tail = [0u8; FOOTER_AND_MAGIC as usize];
    file.seek(SeekFrom::Start(len - FOOTER_AND_MAGIC))?;
    file.read_exact(&mut tail)?;
    let (record, magic) = tail.split_at(tail.len() - MAGIC.len());
    Ok(magic == MAGIC && record[0] == op::FOOTER && record[1..9] == 20u64.to_le_bytes())
}

/// The largest record a reader of a file of `len` bytes accepts: records outside chunks cannot
/// be larger than the file, records inside chunks are bounded by a generous compression ratio.
/// This keeps a damaged length field from allocating gigabytes.
pub(crate) fn record_limit(len: u64) -> usize {
    let limit = len.saturating_mul(64).clamp(1 << 20, 1 << 30);
    usize::try_from(limit).unwrap_or(usize::MAX)
}

/// Streams the records of a file from its start, with chunks opened and flattened.
pub(crate) struct RecordStream {
    path: PathBuf,
    source: BufReader<File>,
    reader: LinearReader,
    done: bool,
}

impl RecordStream {
    /// Starts at the beginning of `file` (the end magic is not required).
    pub(crate) fn new(file: OpenFile) -> Result<Self, RecordingError> {
        let OpenFile {
            path,
            mut file,
            len,
            ..
        } = file;
        file.seek(SeekFrom::Start(0))
            .map_err(|e| RecordingError::io(&path, e))?;
        let options = LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(record_limit(len));
        Ok(Self {
            path,
            source: BufReader::with_capacity(1 << 16, file),
            reader: LinearReader::new_with_options(options),
            done: false,
        })
    }

    /// The next record, an error (after which the stream ends), or `None` at the end.
    pub(crate) fn next_record(&mut self) -> Option<Result<Record<'static>, RecordingError>> {
        if self.done {
            return None;
        }
        loop {
            let want = match self.reader.next_event() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(RecordingError::mcap(&self.path, e)));
                }
                Some(Ok(LinearReadEvent::Record { data, opcode })) => {
                    let record = mcap::parse_record(opcode, data).map(Record::into_owned);
                    if record.is_err() {
                        self.done = true;
                    }
                    return Some(record.map_err(|e| RecordingError::mcap(&self.path, e)));
                }
                Some(Ok(LinearReadEvent::ReadRequest(n))) => n,
            };
            let buf = self.reader.insert(want);
            let read = loop {
                match self.source.read(buf) {
                    Ok(n) => break n,
                    Err(e) if e.kind() == ErrorKind::Interrupted => {}
                    Err(e) => {
                        self.done = true;
                        return Some(Err(RecordingError::io(&self.path, e)));
                    }
                }
            };
            self.reader.notify_read(read);
        }
    }
}

/// Reads the summary section of a finished file: `Ok(None)` when it has none.
pub(crate) fn read_summary(file: &mut OpenFile) -> Result<Option<Summary>, RecordingError> {
    let path = file.path.clone();
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(file.len)
            .with_record_length_limit(record_limit(file.len)),
    );
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| RecordingError::mcap(&path, e))? {
            SummaryReadEvent::ReadRequest(n) => {
                let read = read_up_to(&mut file.file, reader.insert(n))
                    .map_err(|e| RecordingError::io(&path, e))?;
                reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let pos = file
                    .file
                    .seek(to)
                    .map_err(|e| RecordingError::io(&path, e))?;
                reader.notify_seeked(pos);
            }
        }
    }
    Ok(reader.finish())
}

/// Reads one whole record at `offset` (as pointed to by an index) of at most `max_len` bytes.
pub(crate) fn read_record_at(
    file: &mut OpenFile,
    offset: u64,
    max_len: u64,
) -> Result<Record<'static>, RecordingError> {
    let path = file.path.clone();
    let bad_index = || RecordingError::Mcap {
        path: path.clone(),
        detail: format!("an index points outside the file (offset {offset})"),
    };
    if offset.saturating_add(RECORD_PREFIX as u64) > file.len {
        return Err(bad_index());
    }
    let mut prefix = [0u8; RECORD_PREFIX];
    file.file
        .seek(SeekFrom::Start(offset))
        .and_then(|_| file.file.read_exact(&mut prefix))
        .map_err(|e| RecordingError::io(&path, e))?;
    let mut len_bytes = [0u8; 8];
    len_bytes.copy_from_slice(&prefix[1..]);
    let len = u64::from_le_bytes(len_bytes);
    let end = offset
        .saturating_add(RECORD_PREFIX as u64)
        .saturating_add(len);
    if end > file.len || len > max_len {
        return Err(bad_index());
    }
    // Bounded by the file length above.
    let mut body = vec![0u8; len as usize];
    file.file
        .read_exact(&mut body)
        .map_err(|e| RecordingError::io(&path, e))?;
    mcap::parse_record(prefix[0], &body)
        .map(Record::into_owned)
        .map_err(|e| RecordingError::mcap(&path, e))
}

/// The contract's view of a topic.
pub(crate) struct ContractType {
    pub schema_name: &'static str,
    pub schema: String,
    pub size: usize,
}

struct Describe;

impl TopicVisitor for Describe {
    type Output = ContractType;
    fn visit<M: Message>(self) -> ContractType {
        ContractType {
            schema_name: M::SCHEMA_NAME,
            schema: M::schema(),
            size: std::mem::size_of::<M>(),
        }
    }
}

/// The contract's type for `topic`, if the topic is part of the contract, with or without a
/// namespace (`left/glove/state` is a `glove/state` channel).
pub(crate) fn contract_type(topic: &str) -> Option<ContractType> {
    let (_, contract) = teleop_namespace::split(topic)?;
    teleop_msgs::visit_topic(contract.name, Describe)
}

/// How a channel's messages are turned into payloads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ChannelKind {
    /// A contract topic: CDR little-endian header, then exactly `size` bytes.
    Contract { size: usize },
    /// A contract topic recorded with an earlier contract version's layout: CDR little-endian
    /// header, then exactly that layout's size, converted to the current payload on read.
    Converted(Legacy),
    /// A topic outside the contract: the 4-byte CDR header is removed when the channel is `cdr`,
    /// other encodings are passed through.
    Foreign { cdr: bool },
}

/// A schema as recorded, for checking.
pub(crate) struct RecordedSchema<'a> {
    pub name: &'a str,
    pub encoding: &'a str,
    pub data: &'a [u8],
}

/// Schema texts compared line by line, ignoring comments, blank lines and surrounding blanks.
pub(crate) fn normalised(text: &str) -> Vec<&str> {
    text.lines()
        .map(|line| line.split('#').next().unwrap_or("").trim())
        .filter(|line| !line.is_empty())
        .collect()
}

/// Checks a channel of `topic` against the contract: the current schema text gives
/// [`ChannelKind::Contract`], the schema text of an earlier contract version that this build
/// converts gives [`ChannelKind::Converted`], any other text is
/// [`RecordingError::WrongSchemaVersion`].
pub(crate) fn check_channel(
    path: &Path,
    topic: &str,
    schema: Option<&RecordedSchema<'_>>,
    message_encoding: &str,
) -> Result<ChannelKind, RecordingError> {
    let Some(contract) = contract_type(topic) else {
        return Ok(ChannelKind::Foreign {
            cdr: message_encoding == MESSAGE_ENCODING,
        });
    };
    let (name, encoding, data) = match schema {
        Some(s) => (s.name, s.encoding, s.data),
        None => ("", "", &[][..]),
    };
    if name != contract.schema_name
        || encoding != SCHEMA_ENCODING
        || message_encoding != MESSAGE_ENCODING
    {
        return Err(RecordingError::UnknownSchema {
            path: path.to_path_buf(),
            topic: topic.to_string(),
            schema: name.to_string(),
            encoding: format!("{encoding}/{message_encoding}"),
            expected: contract.schema_name.to_string(),
        });
    }
    let text = String::from_utf8_lossy(data);
    let found = normalised(&text);
    if found == normalised(&contract.schema) {
        return Ok(ChannelKind::Contract {
            size: contract.size,
        });
    }
    if let Some(legacy) = Legacy::recognise(contract.schema_name, &found) {
        return Ok(ChannelKind::Converted(legacy));
    }
    Err(RecordingError::WrongSchemaVersion {
        path: path.to_path_buf(),
        topic: topic.to_string(),
        schema: name.to_string(),
        expected: contract.schema,
        found: text.into_owned(),
    })
}

/// The earlier contract version whose layout a channel of `topic` was recorded with, when
/// [`check_channel`] would read it converted.
pub(crate) fn converted_from(
    path: &Path,
    topic: &str,
    schema: Option<&RecordedSchema<'_>>,
    message_encoding: &str,
) -> Option<u32> {
    match check_channel(path, topic, schema, message_encoding) {
        Ok(ChannelKind::Converted(legacy)) => Some(legacy.version()),
        _ => None,
    }
}

/// The payload of a message: without its CDR header, checked against the contract, and
/// converted to the current contract when recorded with an earlier one.
pub(crate) fn payload<'a>(
    path: &Path,
    topic: &str,
    kind: ChannelKind,
    data: &'a [u8],
) -> Result<Cow<'a, [u8]>, RecordingError> {
    let bad = |detail: String| RecordingError::BadMessage {
        path: path.to_path_buf(),
        topic: topic.to_string(),
        detail,
    };
    // `version`: the earlier contract version the channel was recorded with, if any.
    let contract_body = |size: usize, version: Option<u32>| {
        let Some(body) = data.strip_prefix(&CDR_LE_HEADER[..]) else {
            return Err(bad(format!(
                "the message does not start with the CDR little-endian header {:02x?}",
                CDR_LE_HEADER
            )));
        };
        if body.len() != size {
            let whose = match version {
                Some(v) => format!("the type of contract version {v}"),
                None => "the contract's type".to_string(),
            };
            return Err(bad(format!(
                "the payload has {} bytes, {whose} has {size}",
                body.len()
            )));
        }
        Ok(body)
    };
    match kind {
        ChannelKind::Contract { size } => contract_body(size, None).map(Cow::Borrowed),
        ChannelKind::Converted(legacy) => {
            let body = contract_body(legacy.size(), Some(legacy.version()))?;
            Ok(Cow::Owned(legacy.convert(body)))
        }
        ChannelKind::Foreign { cdr: true } => match data.get(4..) {
            Some(body) => Ok(Cow::Borrowed(body)),
            None => Err(bad(format!(
                "a CDR message of {} bytes has no room for the 4-byte CDR header",
                data.len()
            ))),
        },
        ChannelKind::Foreign { cdr: false } => Ok(Cow::Borrowed(data)),
    }
}
