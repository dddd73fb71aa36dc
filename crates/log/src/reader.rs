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
use std::ops::ControlFlow;
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
    /// Parts of the file skipped because they were damaged (a chunk whose
    /// checksum, compression or records do not hold; a record whose
    /// length is garbage), in file order: the read went on after each.
    pub damaged: Vec<Gap>,
}

/// A damaged part of a log the read skipped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Gap {
    /// Log time of its first message, ns since the epoch (none when the
    /// damage hid it).
    pub from_ns: Option<u64>,
    /// Log time of its last message.
    pub to_ns: Option<u64>,
    /// Messages lost (from the message indexes after the chunk; none when
    /// they do not say).
    pub messages: Option<u64>,
    /// Bytes skipped.
    pub bytes: u64,
    /// What was wrong.
    pub why: String,
}

impl ReadSummary {
    /// The damaged parts in words, with `start_ns` the run's start (their
    /// times as seconds into the run), or none when nothing was skipped.
    pub fn damage(&self, start_ns: Option<u64>) -> Option<String> {
        if self.damaged.is_empty() {
            return None;
        }
        let s = |t: Option<u64>| match (t, start_ns) {
            (Some(t), Some(s)) => format!("{:.0} s", t.saturating_sub(s) as f64 / 1e9),
            (Some(t), None) => format!("log time {t} ns"),
            _ => "an unknown time".into(),
        };
        let parts: Vec<String> = self
            .damaged
            .iter()
            .map(|g| {
                let what = g
                    .messages
                    .map_or("messages of an unknown count".into(), |n| {
                        format!("{n} message(s)")
                    });
                let when = match (g.from_ns, g.to_ns) {
                    (Some(a), Some(b)) => format!(" from {} to {}", s(Some(a)), s(Some(b))),
                    (Some(a), None) => format!(" from {}", s(Some(a))),
                    _ => " at an unknown time".into(),
                };
                format!("{what}{when} ({} bytes: {})", g.bytes, g.why)
            })
            .collect();
        Some(format!(
            "{} damaged part(s) skipped, the rest read: {}",
            self.damaged.len(),
            parts.join("; ")
        ))
    }

    /// What went wrong with the read, for an error that follows from it
    /// (" (the read stopped: ...; 1 damaged part(s) skipped ...)"), or
    /// nothing when the read was clean.
    pub fn trouble(&self) -> String {
        let parts: Vec<String> = self
            .stopped
            .iter()
            .map(|s| format!("the read stopped: {s}"))
            .chain(self.damage(None))
            .collect();
        if parts.is_empty() {
            String::new()
        } else {
            format!(" ({})", parts.join("; "))
        }
    }
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
        #[source]
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

/// What the reader keeps while it goes through a file.
struct Reading {
    schemas: HashMap<u16, SchemaInfo>,
    channels: HashMap<u16, ChannelInfo>,
    unknown: ChannelInfo,
    summary: ReadSummary,
    in_summary_section: bool,
    /// The damaged chunk the message indexes that follow it count for.
    counting: Option<usize>,
    /// The sink said it had what it needed.
    enough: bool,
}

/// What a record (or a chunk) came to.
enum Flow {
    /// Go on.
    On,
    /// The read ends here, for this reason (the sink refused the log, or
    /// the file holds a record that cannot be read).
    Stop(String),
    /// The sink has what it needs.
    Enough,
}

impl From<ControlFlow<Stop>> for Flow {
    fn from(c: ControlFlow<Stop>) -> Self {
        match c {
            ControlFlow::Continue(()) => Self::On,
            ControlFlow::Break(Stop::Enough) => Self::Enough,
            ControlFlow::Break(Stop::Refused(why)) => Self::Stop(why),
        }
    }
}

/// Why a sink (the function [`read`] hands each item to) ends the read
/// early: it answers `ControlFlow::Continue(())` to go on, or breaks with
/// this.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Stop {
    /// It has what it needs: the rest of the file is left unread (the
    /// summary says neither complete nor stopped, and counts nothing lost).
    Enough,
    /// It refuses the log, saying why ([`ReadSummary::stopped`]).
    Refused(String),
}

/// A sink from a function that answers each item with a `Result`: on while
/// it is `Ok`, refusing the log with the error's text at its first `Err`.
pub fn refusing<E: std::fmt::Display>(
    mut f: impl FnMut(Item<'_>) -> Result<(), E>,
) -> impl FnMut(Item<'_>) -> ControlFlow<Stop> {
    move |item| match f(item) {
        Ok(()) => ControlFlow::Continue(()),
        Err(e) => ControlFlow::Break(Stop::Refused(e.to_string())),
    }
}

/// A chunk's records, decompressed and checked (its CRC and every record
/// whole), or why not.
fn unpack_chunk(
    body: &[u8],
) -> Result<(mcap::records::ChunkHeader, Vec<u8>), (Option<mcap::records::ChunkHeader>, String)> {
    let (header, compressed) = match mcap::parse_record(mcap::records::op::CHUNK, body) {
        Ok(Record::Chunk { header, data }) => (header, data),
        Ok(_) => return Err((None, "not a chunk".into())),
        Err(e) => return Err((None, format!("its header: {e}"))),
    };
    let size = usize::try_from(header.uncompressed_size).unwrap_or(usize::MAX);
    if size > RECORD_LENGTH_LIMIT {
        let h = header.clone();
        return Err((Some(h), format!("it claims {size} bytes uncompressed")));
    }
    let data = match header.compression.as_str() {
        "" => compressed.into_owned(),
        "zstd" => match zstd::bulk::decompress(&compressed, size) {
            Ok(d) => d,
            Err(e) => return Err((Some(header.clone()), format!("zstd: {e}"))),
        },
        other => {
            return Err((
                Some(header.clone()),
                format!("compression {other:?} this reader does not take"),
            ));
        }
    };
    if data.len() != size {
        return Err((
            Some(header.clone()),
            format!("{} bytes uncompressed, the header says {size}", data.len()),
        ));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(&data);
        if crc != header.uncompressed_crc {
            return Err((
                Some(header.clone()),
                format!(
                    "bad checksum (saved {:08x}, computed {crc:08x})",
                    header.uncompressed_crc
                ),
            ));
        }
    }
    // Every record whole and parsed before any is used.
    let mut at = 0;
    while at < data.len() {
        match record_at(&data, at) {
            Some((opcode, body, next)) => {
                if let Err(e) = parse_record(opcode, body) {
                    return Err((Some(header.clone()), format!("a record inside: {e}")));
                }
                at = next;
            }
            None => return Err((Some(header.clone()), "a record inside is cut".into())),
        }
    }
    Ok((header, data))
}

/// What kept a record from being parsed.
#[derive(Debug, thiserror::Error)]
enum RecordError {
    /// An attachment record too short to hold its header, the length of
    /// its data and its CRC.
    #[error("an attachment record of {0} bytes cannot hold its header and CRC")]
    ShortAttachment(usize),
    /// What mcap's parser said.
    #[error(transparent)]
    Mcap(#[from] mcap::McapError),
}

/// `mcap::parse_record`, with an attachment's body checked first: mcap
/// 0.26 takes an attachment's last four bytes as its CRC and slices its
/// data up to them without checking that they lie past its header, so a
/// record cut or damaged inside its header panicked there (found by the
/// fuzz properties: one byte changed in a log).
fn parse_record(opcode: u8, body: &[u8]) -> Result<Record<'_>, RecordError> {
    if opcode == mcap::records::op::ATTACHMENT && !attachment_fits(body) {
        return Err(RecordError::ShortAttachment(body.len()));
    }
    Ok(mcap::parse_record(opcode, body)?)
}

/// Whether an attachment record's body holds its header (two times, a name
/// and a media type, each string a u32 length and its bytes), the u64
/// length of its data and a u32 CRC.
fn attachment_fits(body: &[u8]) -> bool {
    let len_at = |i: usize| {
        body.get(i..i.checked_add(4)?)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes)
    };
    // log_time and create_time, then the two strings.
    let mut at = 16_usize;
    for _ in 0..2 {
        let Some(n) = len_at(at) else {
            return false;
        };
        match usize::try_from(n)
            .ok()
            .and_then(|n| at.checked_add(4)?.checked_add(n))
        {
            Some(next) => at = next,
            None => return false,
        }
    }
    at.checked_add(8 + 4).is_some_and(|end| end <= body.len())
}

/// The record at `at` of `buf`: opcode, body and where the next begins.
fn record_at(buf: &[u8], at: usize) -> Option<(u8, &[u8], usize)> {
    let opcode = *buf.get(at)?;
    let len = u64::from_le_bytes(buf.get(at + 1..at + 9)?.try_into().ok()?);
    let end = (at + 9).checked_add(usize::try_from(len).ok()?)?;
    Some((opcode, buf.get(at + 9..end)?, end))
}

impl Reading {
    fn record(
        &mut self,
        rec: Record<'_>,
        f: &mut impl FnMut(Item<'_>) -> ControlFlow<Stop>,
    ) -> Flow {
        let res = match rec {
            Record::Schema { header, data } => {
                self.schemas.insert(
                    header.id,
                    SchemaInfo {
                        name: header.name,
                        encoding: header.encoding,
                        data: data.into_owned(),
                    },
                );
                ControlFlow::Continue(())
            }
            Record::Channel(c) => {
                let schema = self.schemas.get(&c.schema_id).cloned();
                self.channels.insert(
                    c.id,
                    ChannelInfo {
                        id: c.id,
                        topic: c.topic,
                        message_encoding: c.message_encoding,
                        metadata: c.metadata,
                        schema,
                    },
                );
                ControlFlow::Continue(())
            }
            Record::Message { header, data } if !self.in_summary_section => {
                self.summary.messages += 1;
                let channel = self
                    .channels
                    .get(&header.channel_id)
                    .unwrap_or(&self.unknown);
                f(Item::Message {
                    topic: &channel.topic,
                    channel,
                    sequence: header.sequence,
                    log_time_ns: header.log_time,
                    publish_time_ns: header.publish_time,
                    data: &data,
                })
            }
            Record::Attachment { header, data, .. } if !self.in_summary_section => {
                f(Item::Attachment {
                    name: &header.name,
                    media_type: &header.media_type,
                    log_time_ns: header.log_time,
                    data: &data,
                })
            }
            Record::Metadata(m) if !self.in_summary_section => f(Item::Meta {
                name: &m.name,
                entries: &m.metadata,
            }),
            Record::MessageIndex(ix) => {
                if let Some(g) = self.counting.and_then(|i| self.summary.damaged.get_mut(i)) {
                    *g.messages.get_or_insert(0) += ix.records.len() as u64;
                }
                ControlFlow::Continue(())
            }
            Record::DataEnd(_) => {
                self.in_summary_section = true;
                ControlFlow::Continue(())
            }
            Record::Footer(_) => {
                self.summary.complete = true;
                ControlFlow::Continue(())
            }
            _ => ControlFlow::Continue(()),
        };
        res.into()
    }

    /// A chunk: its records, or (damaged) a gap noted and the read on.
    fn chunk(&mut self, body: &[u8], f: &mut impl FnMut(Item<'_>) -> ControlFlow<Stop>) -> Flow {
        self.counting = None;
        match unpack_chunk(body) {
            Ok((_, data)) => {
                let mut at = 0;
                while let Some((opcode, rec_body, next)) = record_at(&data, at) {
                    at = next;
                    // Checked whole by unpack_chunk.
                    let Ok(rec) = parse_record(opcode, rec_body) else {
                        continue;
                    };
                    match self.record(rec, f) {
                        Flow::On => {}
                        stop => return stop,
                    }
                }
                Flow::On
            }
            Err((header, why)) => {
                self.summary.damaged.push(Gap {
                    from_ns: header.as_ref().map(|h| h.message_start_time),
                    to_ns: header.as_ref().map(|h| h.message_end_time),
                    messages: None,
                    bytes: 9 + body.len() as u64,
                    why: format!("a damaged chunk: {why}"),
                });
                self.counting = Some(self.summary.damaged.len() - 1);
                Flow::On
            }
        }
    }
}

/// The first offset at or after `from` where a chunk whose records all
/// check out begins (after damage that hid where the next record starts).
fn next_whole_chunk(file: &mut File, from: u64, len: u64) -> std::io::Result<Option<u64>> {
    if from >= len {
        return Ok(None);
    }
    file.seek(SeekFrom::Start(from))?;
    let mut rest = Vec::new();
    file.take(len - from).read_to_end(&mut rest)?;
    for i in 0..rest.len() {
        if rest[i] != mcap::records::op::CHUNK {
            continue;
        }
        let Some((_, body, _)) = record_at(&rest, i) else {
            continue;
        };
        if body.len() <= RECORD_LENGTH_LIMIT && unpack_chunk(body).is_ok() {
            return Ok(Some(from + i as u64));
        }
    }
    Ok(None)
}

/// Read `path` from start to end, calling `f` for every item in file order.
/// A damaged chunk (or a record whose length is garbage) is skipped, the
/// read goes on with the next whole chunk, and [`ReadSummary::damaged`]
/// says what was lost. Stops early when `f` breaks ([`Stop`]: enough, or
/// refused and said in the summary) or the file ends inside a record.
pub fn read(
    path: &Path,
    mut f: impl FnMut(Item<'_>) -> ControlFlow<Stop>,
) -> Result<ReadSummary, ReadError> {
    let io = |cause| ReadError::Io {
        path: path.display().to_string(),
        cause,
    };
    // A FIFO's open would wait for a writer, and a device never ends: a
    // log is a regular file, and anything else is said before it is opened.
    if let Ok(m) = std::fs::metadata(path)
        && !m.is_file()
    {
        return Err(ReadError::NotMcap {
            path: path.display().to_string(),
            reason: if m.is_dir() {
                "it is a directory, not a regular file".into()
            } else {
                "it is not a regular file: a FIFO, a device or a socket".into()
            },
        });
    }
    let mut file = File::open(path).map_err(io)?;
    let file_bytes = file.metadata().map_err(io)?.len();
    let mut magic = [0u8; 8];
    if file.read_exact(&mut magic).is_err() || magic != *mcap::MAGIC {
        return Err(ReadError::NotMcap {
            path: path.display().to_string(),
            reason: "it does not start with the MCAP magic".into(),
        });
    }
    let mut st = Reading::new(file_bytes);
    // Where the current pass starts: the file's start, or after damage the
    // next whole chunk.
    let mut pass_start: u64 = 0;
    while let Some(next) = st
        .pass(&mut file, pass_start, file_bytes, &mut f)
        .map_err(io)?
    {
        pass_start = next;
    }
    let enough = st.enough;
    let mut summary = st.summary;
    if !summary.complete && !enough {
        summary.bytes_lost = file_bytes.saturating_sub(complete_prefix(&mut file).map_err(io)?);
    }
    Ok(summary)
}

impl Reading {
    /// Nothing read yet of a file of `file_bytes`.
    fn new(file_bytes: u64) -> Self {
        Reading {
            schemas: HashMap::new(),
            channels: HashMap::new(),
            unknown: ChannelInfo {
                id: u16::MAX,
                topic: String::new(),
                message_encoding: String::new(),
                metadata: BTreeMap::new(),
                schema: None,
            },
            summary: ReadSummary {
                file_bytes,
                ..ReadSummary::default()
            },
            in_summary_section: false,
            counting: None,
            enough: false,
        }
    }

    /// One pass over the file from `pass_start` (its start, or a whole
    /// chunk after damage), handing items to `f`: where the next pass
    /// starts when it met damage it can read past, else `None` (the end,
    /// or a stop said in the summary).
    fn pass(
        &mut self,
        file: &mut File,
        pass_start: u64,
        file_bytes: u64,
        f: &mut impl FnMut(Item<'_>) -> ControlFlow<Stop>,
    ) -> std::io::Result<Option<u64>> {
        file.seek(SeekFrom::Start(pass_start))?;
        let mut reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                // Chunks come whole, checked here before any of their
                // messages is used: a chunk cut by a crash is dropped, a
                // damaged one skipped.
                .with_emit_chunks(true)
                .with_skip_start_magic(pass_start != 0)
                .with_record_length_limit(RECORD_LENGTH_LIMIT),
        );
        let mut at = if pass_start == 0 {
            mcap::MAGIC.len() as u64
        } else {
            pass_start
        };
        while let Some(event) = reader.next_event() {
            let event = match event {
                Ok(e) => e,
                Err(mcap::McapError::UnexpectedEof) => {
                    self.summary.stopped = Some(
                        "the file ends inside a record (the run did not finish writing it)".into(),
                    );
                    return Ok(None);
                }
                Err(e) => {
                    // The record at `at` is not whole: look for the next
                    // chunk that is, and go on from there.
                    return Ok(match next_whole_chunk(file, at + 1, file_bytes)? {
                        Some(next) => {
                            self.summary.damaged.push(Gap {
                                from_ns: None,
                                to_ns: None,
                                messages: None,
                                bytes: next - at,
                                why: format!("unreadable records: {e}"),
                            });
                            self.counting = None;
                            Some(next)
                        }
                        None => {
                            self.summary.stopped = Some(format!("unreadable record: {e}"));
                            None
                        }
                    });
                }
            };
            match event {
                LinearReadEvent::ReadRequest(n) => {
                    let buf = reader.insert(n.max(256 * 1024));
                    let got = file.read(buf)?;
                    reader.notify_read(got);
                }
                LinearReadEvent::Record { data, opcode } => {
                    at += 9 + data.len() as u64;
                    let flow = if opcode == mcap::records::op::CHUNK {
                        self.chunk(data, f)
                    } else {
                        match parse_record(opcode, data) {
                            Ok(rec) => self.record(rec, f),
                            Err(e) => Flow::Stop(format!("unreadable record: {e}")),
                        }
                    };
                    match flow {
                        Flow::On => {}
                        Flow::Stop(e) => {
                            self.summary.stopped = Some(e);
                            return Ok(None);
                        }
                        Flow::Enough => {
                            self.enough = true;
                            return Ok(None);
                        }
                    }
                }
            }
        }
        Ok(None)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// An attachment's body: two times, a name and a media type of one
    /// byte each, the length of its data, `data` and `tail` (the CRC, or
    /// less of it).
    fn attachment(data_len: u64, data: &[u8], tail: &[u8]) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(&1_u64.to_le_bytes());
        b.extend_from_slice(&2_u64.to_le_bytes());
        for s in [b"a", b"b"] {
            b.extend_from_slice(&1_u32.to_le_bytes());
            b.extend_from_slice(s);
        }
        b.extend_from_slice(&data_len.to_le_bytes());
        b.extend_from_slice(data);
        b.extend_from_slice(tail);
        b
    }

    #[test]
    fn an_attachment_cut_inside_its_crc_is_refused_not_a_panic() {
        let op = mcap::records::op::ATTACHMENT;
        let whole = attachment(2, b"xy", &[0; 4]);
        match parse_record(op, &whole) {
            Ok(Record::Attachment { data, .. }) => assert_eq!(&data[..], b"xy"),
            other => panic!("a whole attachment: {other:?}"),
        }
        // Its header ends two bytes short of where the CRC would begin:
        // mcap 0.26 alone slices past the body here and panics.
        let cut = attachment(0, &[], &[0; 2]);
        assert!(matches!(
            parse_record(op, &cut),
            Err(RecordError::ShortAttachment(36))
        ));
        // A string length that runs past the body.
        let mut long_name = whole.clone();
        long_name[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(parse_record(op, &long_name).is_err());
        for n in 0..whole.len() {
            let _ = parse_record(op, &whole[..n]);
        }
    }
}
