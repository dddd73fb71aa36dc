//! Writes a run log: one MCAP file, every message JSON on a channel of the
//! [`schema`](crate::schema) with its JSON Schema.
//!
//! The lifecycle is mcap's own: [`LogWriter::create`] writes the header,
//! the schemas and channels (a batch's other units' under their slots),
//! the `run` metadata and the procedure as an attachment;
//! [`LogWriter::write`] adds one message at a time; [`LogWriter::finish`]
//! writes the `result` metadata, the report as an attachment, the summary
//! and the footer, and returns what the file holds ([`Written`]).
//!
//! Messages are zstd-compressed in chunks; a chunk is closed at least
//! every second of wall time and every minute of device time, so a crash
//! loses at most the last second (or, on a simulated bench, the last
//! minute), and what reached the disk is read back whole by
//! [`read`](crate::read) and made a complete log by
//! [`recover`](crate::recover::recover).
//!
//! A write that fails (a full disk) is kept with its file and the first
//! cause: every later call returns that cause, not the writer's "another
//! write after a failed one", and what reached the disk stays there.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use mcap::records::MessageHeader;
use serde::Serialize;

use crate::schema::{
    CHANNELS, PROCEDURE_ATTACHMENT, REPORT_ATTACHMENT, RESULT_META, RUN_META, SLOT_TOPICS,
    slot_topic,
};

/// The writer options every gyrobench log is written with. zstd level 1:
/// on the acceptance's log (16.3 M frames) it wrote 14.2 MB in a 4.5 s
/// run where the crate's default level wrote 18.5 MB in 5.2 s, and the log
/// replays in 2.6 s instead of 4.0 (docs/benchmarks.md of the gyrobench
/// repository).
pub fn write_options(library: &str) -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(1)
        .chunk_size(Some(4 * 1024 * 1024))
        .profile("")
        .library(library.to_owned())
}

/// Where every message written is also sent as it is written (a live
/// view of the run): its topic, log time (ns since the epoch) and JSON.
pub trait Tap: Send + Sync {
    /// One message, after it was handed to the file.
    fn publish(&self, topic: &str, log_time_ns: u64, json: &[u8]);
}

/// What a log starts with.
#[derive(Debug, Clone)]
pub struct Opening<'a> {
    /// The writing software, as the file's header names it
    /// (`gyrobench 0.1.0`).
    pub library: String,
    /// The `run` metadata's entries.
    pub run: BTreeMap<String, String>,
    /// The procedure's text, attached as `procedure.toml`.
    pub procedure_toml: &'a str,
    /// The slots of a batch's units after the first: each gets its own
    /// frames, 1 Hz rate, table and link topics under `/slots/SLOT`.
    pub slots: Vec<String>,
    /// Wall time of device time zero, ns since the epoch: every message's
    /// log time is counted from it.
    pub start_ns: u64,
}

/// What a finished log holds.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Written {
    /// Messages per topic.
    pub messages: BTreeMap<String, u64>,
}

/// Writes one run log.
pub struct LogWriter {
    path: PathBuf,
    w: mcap::Writer<BufWriter<File>>,
    ch: BTreeMap<String, u16>,
    seq: u32,
    start_ns: u64,
    since_flush: Instant,
    /// Device time of the last flush, s.
    flushed_t_s: f64,
    buf: Vec<u8>,
    messages: BTreeMap<String, u64>,
    /// The first write failure, in words (file and cause).
    failed: Option<String>,
    /// Where every message is also published, if anywhere.
    tap: Option<Arc<dyn Tap>>,
    /// Device time from which every write fails, and the failure it is
    /// (a full disk played on a simulated bench).
    fail_from: Option<(f64, String)>,
}

impl std::fmt::Debug for LogWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogWriter")
            .field("path", &self.path)
            .field("messages", &self.messages)
            .field("failed", &self.failed)
            .finish_non_exhaustive()
    }
}

impl LogWriter {
    /// Create `path` (which must not exist: a log is never overwritten)
    /// and write what the log starts with.
    pub fn create(path: &Path, opening: &Opening<'_>) -> std::io::Result<Self> {
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)?;
        Self::from_file(file, path, opening)
    }

    /// The same on a file already open (a temporary renamed into place
    /// when the log is whole); `path` names it in messages.
    pub fn from_file(file: File, path: &Path, opening: &Opening<'_>) -> std::io::Result<Self> {
        let mut w = write_options(&opening.library)
            .create(BufWriter::new(file))
            .map_err(mcap_err)?;
        let mut ch = BTreeMap::new();
        for (topic, name, schema) in CHANNELS {
            let sid = w
                .add_schema(name, "jsonschema", schema.as_bytes())
                .map_err(mcap_err)?;
            let cid = w
                .add_channel(sid, topic, "json", &BTreeMap::new())
                .map_err(mcap_err)?;
            ch.insert(topic.to_owned(), cid);
        }
        // A batch's other units: each one's frames, 1 Hz rate and table
        // state as it sees it, under its slot (the first unit's are the
        // single-unit channels, so every reader of one-unit logs reads it).
        let mut slot_schemas = BTreeMap::new();
        for slot in &opening.slots {
            for (topic, name, schema) in CHANNELS {
                if !SLOT_TOPICS.contains(&topic) {
                    continue;
                }
                let sid = match slot_schemas.get(name) {
                    Some(&sid) => sid,
                    None => {
                        let sid = w
                            .add_schema(name, "jsonschema", schema.as_bytes())
                            .map_err(mcap_err)?;
                        slot_schemas.insert(name, sid);
                        sid
                    }
                };
                let topic = slot_topic(slot, topic);
                let cid = w
                    .add_channel(sid, &topic, "json", &BTreeMap::new())
                    .map_err(mcap_err)?;
                ch.insert(topic, cid);
            }
        }
        w.write_metadata(&mcap::records::Metadata {
            name: RUN_META.into(),
            metadata: opening.run.clone(),
        })
        .map_err(mcap_err)?;
        w.attach(&mcap::Attachment {
            log_time: opening.start_ns,
            create_time: opening.start_ns,
            name: PROCEDURE_ATTACHMENT.into(),
            media_type: "application/toml".into(),
            data: std::borrow::Cow::Borrowed(opening.procedure_toml.as_bytes()),
        })
        .map_err(mcap_err)?;
        Ok(Self {
            path: path.to_owned(),
            w,
            ch,
            seq: 0,
            start_ns: opening.start_ns,
            since_flush: Instant::now(),
            flushed_t_s: 0.0,
            buf: Vec::with_capacity(64 * 1024),
            messages: BTreeMap::new(),
            failed: None,
            tap: None,
            fail_from: None,
        })
    }

    /// Send every message written from now on to `tap` too.
    pub fn tap(&mut self, tap: Arc<dyn Tap>) {
        self.tap = Some(tap);
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Fail every write from device time `t_s` on with `why` (in words,
    /// file and cause), and write nothing more to the file: a full disk
    /// played on a simulated bench.
    pub fn fail_from(&mut self, t_s: f64, why: String) {
        self.fail_from = Some((t_s, why));
    }

    /// The first write failure, if any ("writing FILE: cause").
    pub fn failure(&self) -> Option<&str> {
        self.failed.as_deref()
    }

    /// Messages written per topic.
    pub fn message_counts(&self) -> &BTreeMap<String, u64> {
        &self.messages
    }

    /// The log time of device time `t_s`, ns since the epoch.
    pub fn ns(&self, t_s: f64) -> u64 {
        self.start_ns
            .saturating_add((t_s.max(0.0) * 1e9).min(u64::MAX as f64) as u64)
    }

    /// Run `f` on the writer unless it failed before; keep the first
    /// failure with the file's name.
    fn guarded(
        &mut self,
        f: impl FnOnce(&mut mcap::Writer<BufWriter<File>>) -> mcap::McapResult<()>,
    ) -> std::io::Result<()> {
        if let Some(why) = &self.failed {
            return Err(std::io::Error::other(why.clone()));
        }
        f(&mut self.w).map_err(|e| {
            let why = format!("writing {}: {}", self.path.display(), describe(&e));
            self.failed = Some(why.clone());
            std::io::Error::other(why)
        })
    }

    /// One message on `topic` (a channel the log has: a topic of the
    /// schema, or a slot's) at device time `t_s`, as JSON.
    pub fn write(&mut self, topic: &str, t_s: f64, value: &impl Serialize) -> std::io::Result<()> {
        if self.failed.is_none()
            && let Some((from, why)) = &self.fail_from
            && t_s >= *from
        {
            self.failed = Some(why.clone());
        }
        let Some(&channel_id) = self.ch.get(topic) else {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("writing {}: no channel {topic}", self.path.display()),
            ));
        };
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value)?;
        let time = self.ns(t_s);
        self.seq += 1;
        let header = MessageHeader {
            channel_id,
            sequence: self.seq,
            log_time: time,
            publish_time: time,
        };
        let buf = std::mem::take(&mut self.buf);
        // Each second of wall time, and each minute of device time (a
        // simulated bench runs far faster than the clock).
        let flush =
            self.since_flush.elapsed().as_secs_f64() >= 1.0 || t_s - self.flushed_t_s >= 60.0;
        let r = self.guarded(|w| {
            w.write_to_known_channel(&header, &buf)?;
            if flush { w.flush() } else { Ok(()) }
        });
        if r.is_ok()
            && let Some(tap) = &self.tap
        {
            tap.publish(topic, time, &buf);
        }
        self.buf = buf;
        r?;
        if flush {
            self.since_flush = Instant::now();
            self.flushed_t_s = t_s;
        }
        *self.messages.entry(topic.to_owned()).or_default() += 1;
        Ok(())
    }

    /// A batch's unit in `slot` (not the first): its result as the
    /// metadata record `result/SLOT` and its report as the attachment
    /// `report_name`, before [`LogWriter::finish`].
    pub fn unit_result(
        &mut self,
        slot: &str,
        result: BTreeMap<String, String>,
        report_name: String,
        report_json: &str,
        end_s: f64,
    ) -> std::io::Result<()> {
        let at = self.ns(end_s);
        self.guarded(|w| {
            write_result(
                w,
                format!("{RESULT_META}/{slot}"),
                result,
                Some((report_name, report_json)),
                at,
            )
        })
    }

    /// End the log: the `result` metadata, the report (when there is one)
    /// as an attachment, the summary, indexes and footer. After a write
    /// failure, returns that failure; what reached the disk is kept.
    pub fn finish(
        mut self,
        result: BTreeMap<String, String>,
        report_json: Option<&str>,
        end_s: f64,
    ) -> std::io::Result<Written> {
        let at = self.ns(end_s);
        let report = report_json.map(|r| (REPORT_ATTACHMENT.to_owned(), r));
        self.guarded(|w| {
            write_result(w, RESULT_META.into(), result, report, at)?;
            w.finish().map(|_| ())
        })?;
        Ok(Written {
            messages: std::mem::take(&mut self.messages),
        })
    }
}

/// A result metadata record `name`, and its report (attachment name, JSON)
/// when there is one, at log time `at`.
fn write_result(
    w: &mut mcap::Writer<BufWriter<File>>,
    name: String,
    entries: BTreeMap<String, String>,
    report: Option<(String, &str)>,
    at: u64,
) -> mcap::McapResult<()> {
    w.write_metadata(&mcap::records::Metadata {
        name,
        metadata: entries,
    })?;
    if let Some((name, json)) = report {
        w.attach(&mcap::Attachment {
            log_time: at,
            create_time: at,
            name,
            media_type: "application/json".into(),
            data: std::borrow::Cow::Borrowed(json.as_bytes()),
        })?;
    }
    Ok(())
}

/// An mcap error as an I/O error: the I/O error itself when there is one.
pub(crate) fn mcap_err(e: mcap::McapError) -> std::io::Error {
    match e {
        mcap::McapError::Io(e) => e,
        e => std::io::Error::other(e),
    }
}

/// The cause of a writer error in words: the I/O error itself when there
/// is one (`No space left on device`), not the writer's wrapper.
fn describe(e: &mcap::McapError) -> String {
    match e {
        mcap::McapError::Io(io) => io.to_string(),
        e => e.to_string(),
    }
}
