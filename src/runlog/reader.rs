//! Streaming reader of a run's MCAP log: every message in file order, the
//! metadata records and the attachments, with memory bounded by one chunk,
//! however long the log. A log cut short (a run killed mid-way) is read up
//! to its last complete chunk; [`ReadSummary`] says what was missing.
//!
//! Built on the mcap crate's sans-IO reader with a record length limit, so
//! a corrupt length (a record "of 2^64 bytes", a chunk that claims to
//! inflate to terabytes) ends the read with an error instead of an
//! allocation.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

/// Longest record the reader accepts, bytes. gyrobench writes chunks of
/// 4 MiB; this leaves room for other writers without trusting a length
/// read from a damaged file.
pub const RECORD_LENGTH_LIMIT: usize = 64 * 1024 * 1024;

/// A schema as the log declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SchemaInfo {
    /// Schema name.
    pub name: String,
    /// Schema encoding (`jsonschema`).
    pub encoding: String,
    /// Schema text.
    pub data: Vec<u8>,
}

/// A channel as the log declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// Channel id in the file.
    pub id: u16,
    /// Topic.
    pub topic: String,
    /// Message encoding (`json`).
    pub message_encoding: String,
    /// Channel metadata.
    pub metadata: BTreeMap<String, String>,
    /// Its schema, when it has one.
    pub schema: Option<SchemaInfo>,
}

/// One item of a log, in file order.
#[derive(Debug)]
pub enum Item<'a> {
    /// A metadata record (`run`, `result`).
    Meta {
        /// Record name.
        name: &'a str,
        /// Its key/value pairs.
        entries: &'a BTreeMap<String, String>,
    },
    /// A message.
    Message {
        /// Channel topic.
        topic: &'a str,
        /// The channel it was written on.
        channel: &'a ChannelInfo,
        /// Sequence number.
        sequence: u32,
        /// Log time, ns since the epoch.
        log_time_ns: u64,
        /// Publish time, ns since the epoch.
        publish_time_ns: u64,
        /// Payload (JSON for every gyrobench topic).
        data: &'a [u8],
    },
    /// An attachment (the procedure, the report).
    Attachment {
        /// Its name (`procedure.toml`, `report.json`).
        name: &'a str,
        /// Media type.
        media_type: &'a str,
        /// Log time, ns since the epoch.
        log_time_ns: u64,
        /// Contents.
        data: &'a [u8],
    },
}

/// How the read went.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReadSummary {
    /// Size of the file, bytes.
    pub file_bytes: u64,
    /// Whether the log ended properly (summary and closing magic).
    pub complete: bool,
    /// Bytes after the last complete record (lost), when not complete.
    pub bytes_lost: u64,
    /// Messages read.
    pub messages: u64,
    /// Why the read stopped early, when it did.
    pub stopped: Option<String>,
}

/// Read errors that prevent any use of the file.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file cannot be opened or read.
    #[error("{path}: {cause}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        cause: std::io::Error,
    },
    /// Not an MCAP file at all.
    #[error("{path}: not an MCAP log ({reason})")]
    NotMcap {
        /// File.
        path: String,
        /// Why.
        reason: String,
    },
}

/// Read `path` from start to end, calling `f` for every item in file order.
/// Stops early (and says so in the summary) when `f` returns an error or
/// the file ends inside a record.
pub fn read(
    path: &Path,
    mut f: impl FnMut(Item<'_>) -> Result<(), String>,
) -> Result<ReadSummary, ReadError> {
    let io = |cause| ReadError::Io {
        path: path.display().to_string(),
        cause,
    };
    let mut file = File::open(path).map_err(io)?;
    let file_bytes = file.metadata().map_err(io)?.len();
    let mut magic = [0u8; 8];
    if file.read_exact(&mut magic).is_err() || magic != *mcap::MAGIC {
        return Err(ReadError::NotMcap {
            path: path.display().to_string(),
            reason: "it does not start with the MCAP magic".into(),
        });
    }
    file.seek(SeekFrom::Start(0)).map_err(io)?;

    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            // A chunk is checked whole before any of its messages is used,
            // so a chunk cut by a crash is dropped, not half-read.
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(RECORD_LENGTH_LIMIT),
    );
    let mut schemas: HashMap<u16, SchemaInfo> = HashMap::new();
    let mut channels: HashMap<u16, ChannelInfo> = HashMap::new();
    let unknown = ChannelInfo {
        id: u16::MAX,
        topic: String::new(),
        message_encoding: String::new(),
        metadata: BTreeMap::new(),
        schema: None,
    };
    let mut summary = ReadSummary {
        file_bytes,
        ..ReadSummary::default()
    };
    let mut in_summary_section = false;
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            Err(mcap::McapError::UnexpectedEof) => {
                summary.stopped = Some(
                    "the file ends inside a record (the run did not finish writing it)".into(),
                );
                break;
            }
            Err(e) => {
                summary.stopped = Some(format!("unreadable record: {e}"));
                break;
            }
        };
        match event {
            LinearReadEvent::ReadRequest(n) => {
                let buf = reader.insert(n.max(256 * 1024));
                let got = file.read(buf).map_err(io)?;
                reader.notify_read(got);
            }
            LinearReadEvent::Record { data, opcode } => {
                let rec = match mcap::parse_record(opcode, data) {
                    Ok(r) => r,
                    Err(e) => {
                        summary.stopped = Some(format!("unreadable record: {e}"));
                        break;
                    }
                };
                let res = match rec {
                    Record::Schema { header, data } => {
                        schemas.insert(
                            header.id,
                            SchemaInfo {
                                name: header.name,
                                encoding: header.encoding,
                                data: data.into_owned(),
                            },
                        );
                        Ok(())
                    }
                    Record::Channel(c) => {
                        let schema = schemas.get(&c.schema_id).cloned();
                        channels.insert(
                            c.id,
                            ChannelInfo {
                                id: c.id,
                                topic: c.topic,
                                message_encoding: c.message_encoding,
                                metadata: c.metadata,
                                schema,
                            },
                        );
                        Ok(())
                    }
                    Record::Message { header, data } if !in_summary_section => {
                        summary.messages += 1;
                        let channel = channels.get(&header.channel_id).unwrap_or(&unknown);
                        f(Item::Message {
                            topic: &channel.topic,
                            channel,
                            sequence: header.sequence,
                            log_time_ns: header.log_time,
                            publish_time_ns: header.publish_time,
                            data: &data,
                        })
                    }
                    Record::Attachment { header, data, .. } if !in_summary_section => {
                        f(Item::Attachment {
                            name: &header.name,
                            media_type: &header.media_type,
                            log_time_ns: header.log_time,
                            data: &data,
                        })
                    }
                    Record::Metadata(m) if !in_summary_section => f(Item::Meta {
                        name: &m.name,
                        entries: &m.metadata,
                    }),
                    Record::DataEnd(_) => {
                        in_summary_section = true;
                        Ok(())
                    }
                    Record::Footer(_) => {
                        summary.complete = true;
                        Ok(())
                    }
                    _ => Ok(()),
                };
                if let Err(e) = res {
                    summary.stopped = Some(e);
                    break;
                }
            }
        }
    }
    if !summary.complete {
        summary.bytes_lost = file_bytes.saturating_sub(complete_prefix(&mut file).map_err(io)?);
    }
    Ok(summary)
}

/// Offset just past the last top-level record that is whole.
fn complete_prefix(file: &mut File) -> std::io::Result<u64> {
    let len = file.metadata()?.len();
    let mut at = mcap::MAGIC.len() as u64;
    let mut head = [0u8; 9];
    loop {
        if at + 9 > len {
            return Ok(at);
        }
        file.seek(SeekFrom::Start(at))?;
        file.read_exact(&mut head)?;
        let body = u64::from_le_bytes(head[1..9].try_into().unwrap_or([0xff; 8]));
        let end = at.saturating_add(9).saturating_add(body);
        if end > len {
            return Ok(at);
        }
        at = end;
    }
}
