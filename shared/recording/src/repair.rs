//! Making a killed recorder's file readable again: [`repair`].

use std::{
    collections::{hash_map::Entry, HashMap},
    fs::File,
    io::BufWriter,
    path::{Path, PathBuf},
};

use mcap::records::{MessageHeader, Record};

use crate::{
    file::{open, RecordStream},
    write::write_options,
    RecordingError,
};

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
    /// The input was a finished file and was read to its end.
    pub input_complete: bool,
    /// Why reading stopped before the end of the data, if it did (for a killed recorder: the
    /// chunk that was open when it died).
    pub stopped: Option<String>,
}

/// Streams every closed chunk of `input` (and every complete record after the header) into a
/// new, properly finished file `out` (created with its folder; overwritten if it exists).
///
/// Reading stops at the first record that cannot be read: for a killed recorder that is the
/// chunk it had open, whose messages are lost. Schemas, channels, messages (with their
/// original times, sequence numbers and bytes), metadata and attachments are copied.
pub fn repair(input: &Path, out: &Path) -> Result<RepairReport, RecordingError> {
    let source = open(input)?;
    let has_footer = source.has_footer;
    if let (Ok(a), Ok(b)) = (input.canonicalize(), out.canonicalize()) {
        if a == b {
            return Err(RecordingError::invalid_use(
                out,
                "cannot repair a file onto itself",
            ));
        }
    }
    let mut stream = RecordStream::new(source)?;
    if let Some(parent) = out.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent).map_err(|e| RecordingError::io(parent, e))?;
        }
    }
    let file = File::create(out).map_err(|e| RecordingError::io(out, e))?;
    let mut writer = write_options(true)
        .create(BufWriter::new(file))
        .map_err(|e| RecordingError::mcap(out, e))?;
    let w = |e| RecordingError::mcap(out, e);

    let mut report = RepairReport {
        output: out.to_path_buf(),
        messages: 0,
        last_log_time_ns: None,
        metadata: 0,
        channels: 0,
        input_complete: false,
        stopped: None,
    };
    let mut schemas: HashMap<u16, u16> = HashMap::new();
    let mut channels: HashMap<u16, u16> = HashMap::new();
    let mut reached_end = false;
    while let Some(record) = stream.next_record() {
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                report.stopped = Some(e.to_string());
                break;
            }
        };
        match record {
            Record::Schema { header, data } => {
                if let Entry::Vacant(entry) = schemas.entry(header.id) {
                    entry.insert(
                        writer
                            .add_schema(&header.name, &header.encoding, &data)
                            .map_err(w)?,
                    );
                }
            }
            Record::Channel(c) => {
                if channels.contains_key(&c.id) {
                    continue;
                }
                let schema = if c.schema_id == 0 {
                    0
                } else if let Some(&id) = schemas.get(&c.schema_id) {
                    id
                } else {
                    report.stopped = Some(format!(
                        "channel `{}` refers to unknown schema {}",
                        c.topic, c.schema_id
                    ));
                    break;
                };
                let id = writer
                    .add_channel(schema, &c.topic, &c.message_encoding, &c.metadata)
                    .map_err(w)?;
                channels.insert(c.id, id);
                report.channels += 1;
            }
            Record::Message { header, data } => {
                let Some(&channel_id) = channels.get(&header.channel_id) else {
                    report.stopped = Some(format!(
                        "a message refers to unknown channel {}",
                        header.channel_id
                    ));
                    break;
                };
                writer
                    .write_to_known_channel(
                        &MessageHeader {
                            channel_id,
                            ..header
                        },
                        &data,
                    )
                    .map_err(w)?;
                report.messages += 1;
                report.last_log_time_ns = Some(header.log_time);
            }
            Record::Metadata(m) => {
                writer.write_metadata(&m).map_err(w)?;
                report.metadata += 1;
            }
            Record::Attachment { header, data, .. } => {
                writer
                    .attach(&mcap::Attachment {
                        log_time: header.log_time,
                        create_time: header.create_time,
                        name: header.name,
                        media_type: header.media_type,
                        data,
                    })
                    .map_err(w)?;
            }
            Record::DataEnd(_) => {
                reached_end = true;
                break;
            }
            _ => {}
        }
    }
    writer.finish().map_err(w)?;
    report.input_complete = has_footer && reached_end;
    Ok(report)
}
