//! Making a killed recorder's file (or a damaged one) readable again: [`repair`].

use std::{
    collections::{hash_map::Entry, HashMap},
    fs::File,
    io::{BufWriter, ErrorKind, Read, Seek, SeekFrom},
    os::unix::fs::MetadataExt,
    path::{Path, PathBuf},
};

use mcap::{
    records::{op, MessageHeader, Record},
    sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions},
    Writer,
};

use crate::{
    file::{open, read_summary, record_limit, OpenFile},
    write::write_options,
    RecordingError,
};

/// Opcode + record length.
const PREFIX: u64 = 9;
/// The smallest chunk record body: start and end time, uncompressed size and CRC, an empty
/// compression name and the records' length.
const MIN_CHUNK: u64 = 8 + 8 + 8 + 4 + 4 + 8;

/// Part of the input that [`repair`] could not read and skipped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Skipped {
    /// Where the unreadable bytes start in the input.
    pub offset: u64,
    /// How many bytes were skipped.
    pub length: u64,
    /// What was there, as far as known (`a chunk`, `unreadable bytes`), and why it could not be
    /// read.
    pub what: String,
    /// Messages known to be lost with it (from the message indexes after a skipped chunk, or
    /// messages of a channel whose definition was lost); 0 when none are known.
    pub messages: u64,
}

/// What [`repair`] recovered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RepairReport {
    /// The repaired file.
    pub output: PathBuf,
    /// Messages copied.
    pub messages: u64,
    /// Log time of the last message copied (ns), if any.
    pub last_log_time_ns: Option<u64>,
    /// Metadata records copied.
    pub metadata: u64,
    /// Channels copied.
    pub channels: u64,
    /// The input was a finished file and was read to its end without skipping anything.
    pub input_complete: bool,
    /// Why reading ended before the end of the data section, if it did: for a killed recorder
    /// the chunk it had open (its tail is an unfinished record), which is not damage.
    pub stopped: Option<String>,
    /// The damaged parts skipped in between, in file order: everything after each was read.
    pub skipped: Vec<Skipped>,
}

impl RepairReport {
    /// Messages known to be lost in skipped parts.
    pub fn lost_messages(&self) -> u64 {
        self.skipped.iter().map(|s| s.messages).sum()
    }
}

/// How [`repair_with`] writes its output.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RepairOptions {
    /// Replace an existing output file (never the input itself).
    pub overwrite: bool,
}

/// [`repair_with`] without replacing an existing output.
pub fn repair(input: &Path, out: &Path) -> Result<RepairReport, RecordingError> {
    repair_with(input, out, RepairOptions::default())
}

/// Copies every readable record of `input` into a new, properly finished file `out` (created
/// with its folder; an existing file is refused unless `options.overwrite`, and the input
/// itself, by any path or hard link, always). The output is written under a temporary name
/// and takes its place only when finished.
///
/// Reading goes record by record. A chunk that cannot be read (bad compression or CRC) is
/// skipped and reading goes on after it; bytes that are no record at all are skipped up to the
/// next record that reads: the next chunk of the file's chunk index where it has one, else the
/// next place where a whole chunk or metadata record reads. Each skipped part is reported
/// (offset, length, what and why, messages known lost). The unfinished record at the end of a
/// killed recorder's file is reported in [`RepairReport::stopped`]. Schemas, channels (also
/// those of the file's summary), messages (with their original times, sequence numbers and
/// bytes), metadata and attachments are copied.
pub fn repair_with(
    input: &Path,
    out: &Path,
    options: RepairOptions,
) -> Result<RepairReport, RecordingError> {
    let mut source = open(input)?;
    check_output(input, &source.file, out, options)?;
    if let Some(parent) = out.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent).map_err(|e| RecordingError::io(parent, e))?;
        }
    }
    let summary = if source.has_footer {
        // A damaged summary only costs the shortcuts it gives.
        read_summary(&mut source).ok().flatten()
    } else {
        None
    };
    let temp = temporary_name(out);
    let file = File::options()
        .write(true)
        .create_new(true)
        .open(&temp)
        .map_err(|e| RecordingError::io(&temp, e))?;
    let result = (|| {
        let writer = write_options(true)
            .create(BufWriter::new(file))
            .map_err(|e| RecordingError::mcap(out, e))?;
        let mut copy = Copy::new(out, writer);
        if let Some(summary) = &summary {
            copy.channels_of(summary)?;
        }
        // Per chunk of the index: where it starts and the messages its indexes list.
        let mut chunk_starts: Vec<(u64, Option<u64>)> = Vec::new();
        if let Some(summary) = &summary {
            for c in &summary.chunk_indexes {
                chunk_starts.push((c.chunk_start_offset, indexed_messages(&mut source, c)));
            }
            chunk_starts.sort_unstable();
        }
        let reached_end = copy.walk(&mut source, &chunk_starts)?;
        copy.writer
            .finish()
            .map_err(|e| RecordingError::mcap(out, e))?;
        let mut file = copy
            .writer
            .into_inner()
            .into_inner()
            .map_err(|e| RecordingError::io(out, e.into_error()))?;
        std::io::Write::flush(&mut file).map_err(|e| RecordingError::io(out, e))?;
        file.sync_all().map_err(|e| RecordingError::io(out, e))?;
        let mut report = copy.report;
        report.input_complete = source.has_footer && reached_end && report.skipped.is_empty();
        Ok(report)
    })();
    let report = match result {
        Ok(report) => report,
        Err(e) => {
            let _ = std::fs::remove_file(&temp);
            return Err(e);
        }
    };
    let placed = if options.overwrite {
        std::fs::rename(&temp, out)
    } else {
        // A link fails when the name exists: never replaces a file created meanwhile.
        std::fs::hard_link(&temp, out).and_then(|()| std::fs::remove_file(&temp))
    };
    if let Err(e) = placed {
        let _ = std::fs::remove_file(&temp);
        return Err(RecordingError::io(out, e));
    }
    Ok(report)
}

/// Refuses an output that is the input (same device and inode: by any path, symbolic or hard
/// link), and an existing one unless `overwrite`.
fn check_output(
    input: &Path,
    input_file: &File,
    out: &Path,
    options: RepairOptions,
) -> Result<(), RecordingError> {
    let Ok(existing) = std::fs::metadata(out) else {
        return Ok(());
    };
    let source = input_file
        .metadata()
        .map_err(|e| RecordingError::io(input, e))?;
    if (existing.dev(), existing.ino()) == (source.dev(), source.ino()) {
        return Err(RecordingError::invalid_use(
            out,
            format!(
                "is the same file as the input {} (device {}, inode {}): cannot repair a file \
                 onto itself",
                input.display(),
                source.dev(),
                source.ino()
            ),
        ));
    }
    if !options.overwrite {
        return Err(RecordingError::Io {
            path: out.to_path_buf(),
            source: std::io::Error::new(
                ErrorKind::AlreadyExists,
                "the output exists already and is not replaced",
            ),
        });
    }
    Ok(())
}

/// `.<name>.<pid>.repairing` next to `out`.
fn temporary_name(out: &Path) -> PathBuf {
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "repaired.mcap".to_string());
    out.with_file_name(format!(".{name}.{}.repairing", std::process::id()))
}

/// The copy in progress.
struct Copy<'a> {
    out: &'a Path,
    writer: Writer<BufWriter<File>>,
    schemas: HashMap<u16, u16>,
    channels: HashMap<u16, u16>,
    report: RepairReport,
}

/// What one top-level record at an offset turned out to be.
enum Read1 {
    /// Its records (one, or a chunk's), and where the next record starts.
    Records(Vec<Record<'static>>, u64),
    /// A well-framed record whose content cannot be read (a chunk with bad compression or
    /// CRC): skipped, reading goes on at the given offset.
    Bad { next: u64, what: String },
    /// No record starts here (a cut-off or damaged length, an unknown opcode).
    NoRecord(String),
}

impl<'a> Copy<'a> {
    fn new(out: &'a Path, writer: Writer<BufWriter<File>>) -> Self {
        Self {
            out,
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            report: RepairReport {
                output: out.to_path_buf(),
                messages: 0,
                last_log_time_ns: None,
                metadata: 0,
                channels: 0,
                input_complete: false,
                stopped: None,
                skipped: Vec::new(),
            },
        }
    }

    fn w(&self, e: mcap::McapError) -> RecordingError {
        RecordingError::mcap(self.out, e)
    }

    /// Registers the schemas and channels of a finished file's summary first: messages whose
    /// channel was defined in a damaged chunk are still copied.
    fn channels_of(&mut self, summary: &mcap::Summary) -> Result<(), RecordingError> {
        let mut ids: Vec<&u16> = summary.channels.keys().collect();
        ids.sort_unstable();
        for id in ids {
            let c = &summary.channels[id];
            let schema = match &c.schema {
                Some(s) => match self.schemas.entry(s.id) {
                    Entry::Occupied(e) => *e.get(),
                    Entry::Vacant(e) => *e.insert(
                        self.writer
                            .add_schema(&s.name, &s.encoding, &s.data)
                            .map_err(|e| RecordingError::mcap(self.out, e))?,
                    ),
                },
                None => 0,
            };
            let new = self
                .writer
                .add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)
                .map_err(|e| RecordingError::mcap(self.out, e))?;
            self.channels.insert(c.id, new);
            self.report.channels += 1;
        }
        Ok(())
    }

    /// Reads the top-level records from after the magic to the data end (`true`) or the end of
    /// the file (`false`), copying what reads and skipping what does not.
    fn walk(
        &mut self,
        source: &mut OpenFile,
        chunk_starts: &[(u64, Option<u64>)],
    ) -> Result<bool, RecordingError> {
        let len = source.len;
        let limit = record_limit(len) as u64;
        let mut pos = mcap::MAGIC.len() as u64;
        // The skipped chunk that the message indexes after it describe.
        let mut last_skipped: Option<usize> = None;
        while pos < len {
            match read_one(source, pos, limit)? {
                Read1::Records(records, next) => {
                    for record in records {
                        match record {
                            Record::MessageIndex(index) => {
                                if let Some(i) = last_skipped {
                                    self.report.skipped[i].messages += index.records.len() as u64;
                                }
                                continue;
                            }
                            Record::DataEnd(_) => return Ok(true),
                            other => {
                                last_skipped = None;
                                self.copy(other)?;
                            }
                        }
                    }
                    pos = next;
                }
                Read1::Bad { next, what } => {
                    self.report.skipped.push(Skipped {
                        offset: pos,
                        length: next - pos,
                        what,
                        messages: 0,
                    });
                    last_skipped = Some(self.report.skipped.len() - 1);
                    pos = next;
                }
                Read1::NoRecord(why) => {
                    let next = match chunk_starts.iter().find(|(c, _)| *c > pos) {
                        Some(&(c, _)) => Some(c),
                        None if chunk_starts.is_empty() => resync(source, pos + 1, limit)?,
                        None => None,
                    };
                    // A chunk of the index starts here: its indexes say what it held.
                    let indexed = chunk_starts
                        .iter()
                        .find(|(c, _)| *c == pos)
                        .and_then(|(_, n)| *n);
                    match next {
                        Some(next) => {
                            self.report.skipped.push(Skipped {
                                offset: pos,
                                length: next - pos,
                                what: match indexed {
                                    Some(_) => format!("a chunk of the index, unreadable ({why})"),
                                    None => format!("unreadable bytes ({why})"),
                                },
                                messages: indexed.unwrap_or(0),
                            });
                            // Message indexes found after it (no chunk index) are its own.
                            last_skipped = Some(self.report.skipped.len() - 1);
                            pos = next;
                        }
                        None if !source.has_footer => {
                            // A killed recorder's tail: the chunk it had open.
                            self.report.stopped = Some(format!(
                                "the last {} bytes (from offset {pos}) are not a whole record: \
                                 the chunk a killed recorder had open ({why})",
                                len - pos
                            ));
                            return Ok(false);
                        }
                        None => {
                            self.report.skipped.push(Skipped {
                                offset: pos,
                                length: len - pos,
                                what: format!("unreadable bytes up to the end ({why})"),
                                messages: 0,
                            });
                            return Ok(false);
                        }
                    }
                }
            }
        }
        Ok(false)
    }

    fn copy(&mut self, record: Record<'static>) -> Result<(), RecordingError> {
        match record {
            Record::Schema { header, data } => {
                if let Entry::Vacant(entry) = self.schemas.entry(header.id) {
                    entry.insert(
                        self.writer
                            .add_schema(&header.name, &header.encoding, &data)
                            .map_err(|e| RecordingError::mcap(self.out, e))?,
                    );
                }
            }
            Record::Channel(c) => {
                if self.channels.contains_key(&c.id) {
                    return Ok(());
                }
                let schema = if c.schema_id == 0 {
                    0
                } else if let Some(&id) = self.schemas.get(&c.schema_id) {
                    id
                } else {
                    self.lost(format!(
                        "channel `{}` refers to schema {}, which was lost",
                        c.topic, c.schema_id
                    ));
                    return Ok(());
                };
                let id = self
                    .writer
                    .add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)
                    .map_err(|e| self.w(e))?;
                self.channels.insert(c.id, id);
                self.report.channels += 1;
            }
            Record::Message { header, data } => {
                let Some(&channel_id) = self.channels.get(&header.channel_id) else {
                    // Its channel was defined in a skipped part.
                    let what = format!(
                        "messages of channel {}, whose definition was lost",
                        header.channel_id
                    );
                    match self.report.skipped.iter_mut().find(|s| s.what == what) {
                        Some(s) => s.messages += 1,
                        None => self.report.skipped.push(Skipped {
                            offset: 0,
                            length: 0,
                            what,
                            messages: 1,
                        }),
                    }
                    return Ok(());
                };
                self.writer
                    .write_to_known_channel(
                        &MessageHeader {
                            channel_id,
                            ..header
                        },
                        &data,
                    )
                    .map_err(|e| self.w(e))?;
                self.report.messages += 1;
                self.report.last_log_time_ns = Some(header.log_time);
            }
            Record::Metadata(m) => {
                self.writer.write_metadata(&m).map_err(|e| self.w(e))?;
                self.report.metadata += 1;
            }
            Record::Attachment { header, data, .. } => {
                self.writer
                    .attach(&mcap::Attachment {
                        log_time: header.log_time,
                        create_time: header.create_time,
                        name: header.name,
                        media_type: header.media_type,
                        data,
                    })
                    .map_err(|e| self.w(e))?;
            }
            _ => {}
        }
        Ok(())
    }

    fn lost(&mut self, what: String) {
        self.report.skipped.push(Skipped {
            offset: 0,
            length: 0,
            what,
            messages: 0,
        });
    }
}

/// Reads the top-level record at `pos`: its prefix must be a known opcode and a length that
/// fits in the file; a chunk is opened (and its CRC checked) entirely before any of its
/// records is used.
fn read_one(source: &mut OpenFile, pos: u64, limit: u64) -> Result<Read1, RecordingError> {
    let len = source.len;
    if pos + PREFIX > len {
        return Ok(Read1::NoRecord(format!(
            "{} bytes left, a record prefix needs {PREFIX}",
            len - pos
        )));
    }
    let mut prefix = [0u8; PREFIX as usize];
    read_at(source, pos, &mut prefix)?;
    let opcode = prefix[0];
    let mut len_bytes = [0u8; 8];
    len_bytes.copy_from_slice(&prefix[1..]);
    let body_len = u64::from_le_bytes(len_bytes);
    if !(op::HEADER..=op::DATA_END).contains(&opcode) {
        return Ok(Read1::NoRecord(format!("unknown opcode {opcode:#04x}")));
    }
    if body_len > len - pos - PREFIX || body_len > limit {
        return Ok(Read1::NoRecord(format!(
            "a record (opcode {opcode:#04x}) of {body_len} bytes, {} bytes left in the file",
            len - pos - PREFIX
        )));
    }
    let next = pos + PREFIX + body_len;
    // Bounded by the file length and the record limit above.
    let mut bytes = vec![0u8; (PREFIX + body_len) as usize];
    read_at(source, pos, &mut bytes)?;
    if opcode == op::CHUNK {
        return Ok(match open_chunk(&bytes, limit) {
            Ok(records) => Read1::Records(records, next),
            Err(e) => Read1::Bad {
                next,
                what: format!("a chunk of {} bytes: {e}", bytes.len()),
            },
        });
    }
    if opcode == op::FOOTER || opcode == op::DATA_END {
        let record = match opcode {
            op::DATA_END => Record::DataEnd(mcap::records::DataEnd {
                data_section_crc: 0,
            }),
            _ => return Ok(Read1::Records(Vec::new(), next)),
        };
        return Ok(Read1::Records(vec![record], next));
    }
    Ok(
        match mcap::parse_record(opcode, &bytes[PREFIX as usize..]) {
            Ok(record) => Read1::Records(vec![record.into_owned()], next),
            Err(e) => Read1::Bad {
                next,
                what: format!("a record (opcode {opcode:#04x}): {e}"),
            },
        },
    )
}

fn read_at(source: &mut OpenFile, pos: u64, buf: &mut [u8]) -> Result<(), RecordingError> {
    source
        .file
        .seek(SeekFrom::Start(pos))
        .and_then(|_| source.file.read_exact(buf))
        .map_err(|e| RecordingError::io(&source.path, e))
}

/// The records inside one chunk record (`bytes` = opcode, length, body), all or an error.
fn open_chunk(bytes: &[u8], limit: u64) -> Result<Vec<Record<'static>>, mcap::McapError> {
    let options = LinearReaderOptions::default()
        .with_skip_start_magic(true)
        .with_skip_end_magic(true)
        .with_validate_chunk_crcs(true)
        .with_prevalidate_chunk_crcs(true)
        .with_record_length_limit(usize::try_from(limit).unwrap_or(usize::MAX));
    let mut reader = LinearReader::new_with_options(options);
    let mut rest = bytes;
    let mut records = Vec::new();
    while let Some(event) = reader.next_event() {
        match event? {
            LinearReadEvent::ReadRequest(n) => {
                let n = n.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
            }
            LinearReadEvent::Record { data, opcode } => {
                records.push(mcap::parse_record(opcode, data)?.into_owned());
            }
        }
    }
    Ok(records)
}

/// Messages a chunk held according to its message indexes (`None` when they cannot be read).
fn indexed_messages(source: &mut OpenFile, chunk: &mcap::records::ChunkIndex) -> Option<u64> {
    let mut total = 0;
    for &offset in chunk.message_index_offsets.values() {
        match crate::file::read_record_at(source, offset, chunk.message_index_length).ok()? {
            Record::MessageIndex(index) => total += index.records.len() as u64,
            _ => return None,
        }
    }
    Some(total)
}

/// The offset of the next whole chunk, message index or metadata record at or after `from`
/// (for a file without a chunk index), by looking at every byte that could start one.
fn resync(source: &mut OpenFile, from: u64, limit: u64) -> Result<Option<u64>, RecordingError> {
    const BLOCK: usize = 1 << 16;
    let len = source.len;
    let mut block = vec![0u8; BLOCK];
    let mut start = from;
    while start + PREFIX <= len {
        let n = usize::try_from((len - start).min(BLOCK as u64)).unwrap_or(BLOCK);
        read_at(source, start, &mut block[..n])?;
        for (i, &byte) in block[..n].iter().enumerate() {
            if byte != op::CHUNK && byte != op::METADATA && byte != op::MESSAGE_INDEX {
                continue;
            }
            let at = start + i as u64;
            if at + PREFIX > len {
                return Ok(None);
            }
            let mut prefix = [0u8; PREFIX as usize];
            read_at(source, at, &mut prefix)?;
            let mut len_bytes = [0u8; 8];
            len_bytes.copy_from_slice(&prefix[1..]);
            let body = u64::from_le_bytes(len_bytes);
            let min = match byte {
                op::CHUNK => MIN_CHUNK,
                // Channel id and the entries' length: an empty index is too weak a sign.
                op::MESSAGE_INDEX => 2 + 4 + 16,
                _ => 8,
            };
            if body < min || body > len - at - PREFIX || body > limit {
                continue;
            }
            if matches!(read_one(source, at, limit)?, Read1::Records(..)) {
                return Ok(Some(at));
            }
        }
        // Overlap nothing: candidates are read from the file, not the block.
        start += n as u64;
    }
    Ok(None)
}
