//! A complete, indexed log from what a killed run had flushed: every
//! message of every complete chunk, the metadata and the attachments are
//! copied; what follows the last complete record is lost.

use std::collections::HashMap;
use std::io::BufWriter;
use std::path::Path;

use crate::reader::{self, Item, ReadError};
use crate::schema::{RUN_META, topics};
use crate::writer::write_options;

/// What [`recover`] salvaged.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Recovered {
    /// Messages copied.
    pub messages: u64,
    /// Gyro frames inside the copied `/gyro/frames` messages.
    pub frames: u64,
    /// Bytes of the input after the last complete record (lost).
    pub bytes_lost: u64,
    /// Whether the input was complete already (had its footer).
    pub was_complete: bool,
    /// Why the read of the input stopped early, when it did.
    pub stopped: Option<String>,
    /// Damaged parts of the input that were skipped (their messages are
    /// not in the output), in words; none when nothing was.
    pub damage: Option<String>,
}

/// Why nothing could be recovered.
#[derive(Debug, thiserror::Error)]
pub enum RecoverError {
    /// The input cannot be read or is not MCAP.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// An MCAP file with no message of a run in it.
    #[error(
        "{path}: nothing of a run could be recovered ({}{}){}",
        if *.had_meta { "the run's metadata but no message" } else { "no run metadata and no message" },
        .stopped.as_ref().map_or(String::new(), |s| format!("; the read stopped: {s}")),
        if *.had_meta { "; the run ended before its first record was written" } else { "; is this the log of a gyrobench run?" }
    )]
    Empty {
        /// The input.
        path: String,
        /// Whether the run's metadata was found.
        had_meta: bool,
        /// Why the read stopped, when it did.
        stopped: Option<String>,
    },
    /// The output could not be written.
    #[error("writing {path}: {cause}")]
    Write {
        /// The output.
        path: String,
        /// Cause.
        #[source]
        cause: std::io::Error,
    },
}

/// Where the part's device time starts, ns since the epoch (its `run`
/// metadata's `part_start_time_utc`): message log times are counted from
/// it.
pub fn part_start_ns(entries: &std::collections::BTreeMap<String, String>) -> Option<u64> {
    crate::meta::utc_ns(entries.get("part_start_time_utc")?)
}

/// Copy one message to `w` on the output's channel for its input channel
/// (added on its first message, with its schema), counting it (and its
/// frames) in `r`. `header`'s channel id is set here.
fn copy_message(
    w: &mut mcap::Writer<BufWriter<std::fs::File>>,
    ids: &mut HashMap<u16, u16>,
    r: &mut Recovered,
    topic: &str,
    channel: &reader::ChannelInfo,
    mut header: mcap::records::MessageHeader,
    data: &[u8],
) -> Result<(), mcap::McapError> {
    header.channel_id = match ids.get(&channel.id) {
        Some(id) => *id,
        None => {
            let schema = match &channel.schema {
                Some(s) => w.add_schema(&s.name, &s.encoding, &s.data)?,
                None => 0,
            };
            let id = w.add_channel(schema, topic, &channel.message_encoding, &channel.metadata)?;
            ids.insert(channel.id, id);
            id
        }
    };
    if topic == topics::FRAMES
        && let Ok(v) = serde_json::from_slice::<serde_json::Value>(data)
    {
        r.frames += v["counts"].as_array().map_or(0, |a| a.len() as u64);
    }
    r.messages += 1;
    w.write_to_known_channel(&header, data)
}

/// Rewrite the possibly truncated log at `input` as a complete, indexed
/// log in `file` (named `out` in messages), its header naming `library`
/// as the writer. When nothing could be recovered the error says why and
/// what `file` holds is not a log: the caller drops it.
pub fn recover(
    input: &Path,
    file: std::fs::File,
    out: &Path,
    library: &str,
) -> Result<Recovered, RecoverError> {
    let write_err = |cause: std::io::Error| RecoverError::Write {
        path: out.display().to_string(),
        cause,
    };
    let mcap_err = |e: mcap::McapError| write_err(std::io::Error::other(e));
    let mut w = write_options(library)
        .create(BufWriter::new(file))
        .map_err(mcap_err)?;
    let mut r = Recovered::default();
    let mut saw_run = false;
    let mut start_ns = None;
    // Channel id in the input -> channel id in the output.
    let mut ids: HashMap<u16, u16> = HashMap::new();
    let mut failure: Option<mcap::McapError> = None;
    let read = reader::read(
        input,
        reader::refusing(|item| {
            let res = match item {
                Item::Meta { name, entries } => {
                    if name == RUN_META {
                        saw_run = true;
                        start_ns = start_ns.or_else(|| part_start_ns(entries));
                    }
                    w.write_metadata(&mcap::records::Metadata {
                        name: name.to_owned(),
                        metadata: entries.clone(),
                    })
                }
                Item::Attachment {
                    name,
                    media_type,
                    log_time_ns,
                    data,
                } => w.attach(&mcap::Attachment {
                    log_time: log_time_ns,
                    create_time: log_time_ns,
                    name: name.to_owned(),
                    media_type: media_type.to_owned(),
                    data: std::borrow::Cow::Borrowed(data),
                }),
                Item::Message {
                    topic,
                    channel,
                    sequence,
                    log_time_ns,
                    publish_time_ns,
                    data,
                } => {
                    let header = mcap::records::MessageHeader {
                        channel_id: 0,
                        sequence,
                        log_time: log_time_ns,
                        publish_time: publish_time_ns,
                    };
                    copy_message(&mut w, &mut ids, &mut r, topic, channel, header, data)
                }
            };
            res.map_err(|e| {
                let text = e.to_string();
                failure = Some(e);
                text
            })
        }),
    )?;
    if let Some(e) = failure {
        return Err(mcap_err(e));
    }
    r.was_complete = read.complete;
    r.bytes_lost = read.bytes_lost;
    r.stopped = read.stopped.clone();
    r.damage = read.damage(start_ns);
    if r.messages == 0 {
        return Err(RecoverError::Empty {
            path: input.display().to_string(),
            had_meta: saw_run,
            stopped: read.stopped,
        });
    }
    w.finish().map_err(mcap_err)?;
    Ok(r)
}
