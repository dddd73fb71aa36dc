//! Writes a run's MCAP log (`docs/report.md`, "The MCAP log").
//!
//! Channels, schemas, the `run` metadata and the procedure (as an
//! attachment) go in up front. Gyro frames are batched one message per
//! tick and zstd-compressed in chunks; a chunk is closed at least every
//! second of wall time and every minute of device time, so a crash loses
//! at most the last second (or, on a simulated bench, the last minute).
//! [`Recorder::finish_run`] writes the `result` metadata, the report as an
//! attachment, the summary and the footer.
//!
//! A write that fails (a full disk) is kept with its file and the first
//! cause: every later call returns that cause, not the writer's "another
//! write after a failed one", and what reached the disk stays there for
//! `gyrobench recover`.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::MessageHeader;
use serde::Serialize;

use super::live::Live;
use super::meta::{ResultMeta, RunMeta};
use super::schema::{
    CHANNELS, ChamberState, GyroFrames, Level, LinkSample, LogLine, PROCEDURE_ATTACHMENT,
    REPORT_ATTACHMENT, RESULT_META, RUN_META, Rate1Hz, SLOT_TOPICS, StepEvent, SupplyState,
    TableState, Timestamp, slot_topic, topics,
};
use crate::analysis::series::Interval;
use crate::clock::Stopwatch;
use crate::sequencer::{BenchState, Event, FrameRecord, Observer, Tick};

/// Writes a run's MCAP file.
pub struct Recorder {
    path: PathBuf,
    w: mcap::Writer<BufWriter<File>>,
    ch: BTreeMap<String, u16>,
    seq: u32,
    start_ns: u64,
    frame_dt_s: f64,
    lsb_arcsec: f64,
    temp_lsb_c: f64,
    since_flush: Stopwatch,
    /// Device time of the last flush, s.
    flushed_t_s: f64,
    buf: Vec<u8>,
    messages: BTreeMap<String, u64>,
    /// The first write failure, in words (file and cause).
    failed: Option<String>,
    /// Where every message is also published live, if anywhere.
    live: Option<Arc<Live>>,
    /// A batch's other units' topics (slots after the first).
    slots: Vec<SlotTopics>,
    /// Device time the link figures were last written at, s (they are
    /// written once a minute of device time).
    last_link_s: f64,
    /// Device time of the tick whose link figures are being written (a
    /// batch's other units' follow the first unit's).
    links_at: Option<f64>,
    /// Device time from which the disk is full (`--inject disk-full@T` on
    /// the simulated bench).
    full_from_s: Option<f64>,
    /// Whether the table angles of the states written are known (not for
    /// a run imported from another bench without them).
    table_angles_known: bool,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("path", &self.path)
            .field("messages", &self.messages)
            .field("failed", &self.failed)
            .finish_non_exhaustive()
    }
}

/// The writer options every gyrobench log is written with. zstd level 1:
/// on the acceptance's log (16.3 M frames) it wrote 14.2 MB in a 4.5 s
/// run where the crate's default level wrote 18.5 MB in 5.2 s, and the log
/// replays in 2.6 s instead of 4.0 (docs/benchmarks.md).
pub(super) fn write_options(library: &str) -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(1)
        .chunk_size(Some(4 * 1024 * 1024))
        .profile("")
        .library(library.to_owned())
}

/// The scales of the frames a run writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameScales {
    /// Frame period, s.
    pub dt_s: f64,
    /// Angle per count, arcsec.
    pub lsb_arcsec: f64,
    /// Temperature per LSB, degC.
    pub temp_lsb_c: f64,
}

/// The topics of one more unit of a batch.
#[derive(Debug)]
struct SlotTopics {
    frames: String,
    rate_1hz: String,
    table: String,
    link: String,
}

impl SlotTopics {
    fn of(slot: &str) -> Self {
        Self {
            frames: slot_topic(slot, topics::FRAMES),
            rate_1hz: slot_topic(slot, topics::RATE_1HZ),
            table: slot_topic(slot, topics::TABLE),
            link: slot_topic(slot, topics::LINK),
        }
    }
}

impl Recorder {
    /// Create `path` (which must not exist: a log is never overwritten)
    /// and write the header, schemas, channels, the `run` metadata and the
    /// procedure. `start_ns` is the wall time of device time zero (ns since
    /// the epoch).
    pub fn create(
        path: &Path,
        meta: &RunMeta,
        start_ns: u64,
        scales: FrameScales,
    ) -> std::io::Result<Self> {
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)?;
        Self::from_file(file, path, meta, start_ns, scales)
    }

    /// The same on a file already open (a [`crate::fsutil::Pending`]
    /// temporary); `path` names it in messages.
    pub fn from_file(
        file: File,
        path: &Path,
        meta: &RunMeta,
        start_ns: u64,
        scales: FrameScales,
    ) -> std::io::Result<Self> {
        let library = format!("gyrobench {}", env!("CARGO_PKG_VERSION"));
        let mut w = write_options(&library)
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
        for unit in meta.units.iter().skip(1) {
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
                let topic = slot_topic(&unit.slot, topic);
                let cid = w
                    .add_channel(sid, &topic, "json", &BTreeMap::new())
                    .map_err(mcap_err)?;
                ch.insert(topic, cid);
            }
        }
        let slots = meta
            .units
            .iter()
            .skip(1)
            .map(|u| SlotTopics::of(&u.slot))
            .collect();
        w.write_metadata(&mcap::records::Metadata {
            name: RUN_META.into(),
            metadata: meta.to_entries(),
        })
        .map_err(mcap_err)?;
        w.attach(&mcap::Attachment {
            log_time: start_ns,
            create_time: start_ns,
            name: PROCEDURE_ATTACHMENT.into(),
            media_type: "application/toml".into(),
            data: std::borrow::Cow::Borrowed(meta.procedure_toml.as_bytes()),
        })
        .map_err(mcap_err)?;
        Ok(Self {
            path: path.to_owned(),
            w,
            ch,
            seq: 0,
            start_ns,
            frame_dt_s: scales.dt_s,
            lsb_arcsec: scales.lsb_arcsec,
            temp_lsb_c: scales.temp_lsb_c,
            since_flush: Stopwatch::start(),
            flushed_t_s: 0.0,
            buf: Vec::with_capacity(64 * 1024),
            messages: BTreeMap::new(),
            failed: None,
            full_from_s: None,
            table_angles_known: true,
            live: None,
            slots,
            last_link_s: 0.0,
            links_at: None,
        })
    }

    /// Publish every message written from now on on `live` too.
    pub fn publish_live(&mut self, live: Arc<Live>) {
        self.live = Some(live);
    }

    /// Whether the table states written from now on carry table angles
    /// (an imported run knows its orientation, not always its table's).
    pub fn set_table_angles_known(&mut self, known: bool) {
        self.table_angles_known = known;
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Play a full disk from device time `t_s` on: every write from then
    /// fails as `No space left on device` would, and nothing more reaches
    /// the file (the simulated bench's `disk-full` fault).
    pub fn fill_disk_at(&mut self, t_s: f64) {
        self.full_from_s = Some(t_s);
    }

    /// The first write failure, if any ("writing FILE: cause").
    pub fn failure(&self) -> Option<&str> {
        self.failed.as_deref()
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

    fn write_json(&mut self, topic: &str, t_s: f64, value: &impl Serialize) -> std::io::Result<()> {
        if self.failed.is_none() && self.full_from_s.is_some_and(|t| t_s >= t) {
            self.failed = Some(format!(
                "writing {}: {} (simulated: --inject disk-full)",
                self.path.display(),
                std::io::Error::from_raw_os_error(28)
            ));
        }
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value)?;
        let time = self.ns(t_s);
        self.seq += 1;
        let header = MessageHeader {
            channel_id: self.ch[topic],
            sequence: self.seq,
            log_time: time,
            publish_time: time,
        };
        let buf = std::mem::take(&mut self.buf);
        // Each second of wall time, and each minute of device time (a
        // simulated bench runs far faster than the clock).
        let flush = self.since_flush.elapsed_s() >= 1.0 || t_s - self.flushed_t_s >= 60.0;
        let r = self.guarded(|w| {
            w.write_to_known_channel(&header, &buf)?;
            if flush { w.flush() } else { Ok(()) }
        });
        if r.is_ok()
            && let Some(live) = &self.live
        {
            live.publish(topic, time, &buf);
        }
        self.buf = buf;
        r?;
        if flush {
            self.since_flush.lap_s();
            self.flushed_t_s = t_s;
        }
        *self.messages.entry(topic.to_owned()).or_default() += 1;
        Ok(())
    }

    /// A tick's frames (nothing when there are none).
    fn write_frames(&mut self, topic: &str, t0_s: f64, f: &[FrameRecord]) -> std::io::Result<()> {
        if f.is_empty() {
            return Ok(());
        }
        let msg = GyroFrames {
            t0_s,
            dt_s: self.frame_dt_s,
            lsb_arcsec: self.lsb_arcsec,
            temp_lsb_c: self.temp_lsb_c,
            seq: f.iter().map(|x| x.seq).collect(),
            counts: f.iter().map(|x| x.counts).collect(),
            t1_raw: f.iter().map(|x| x.temps_raw[0]).collect(),
            t2_raw: f.iter().map(|x| x.temps_raw[1]).collect(),
            tcase_raw: f.iter().map(|x| x.temps_raw[2]).collect(),
            status: f.iter().map(|x| x.status).collect(),
        };
        self.write_json(topic, t0_s, &msg)
    }

    /// The table's state with a unit's orientation and reference.
    fn write_table(&mut self, topic: &str, s: &BenchState, step: &str) -> std::io::Result<()> {
        let known = self.table_angles_known;
        let table = TableState {
            t_s: s.t_s,
            outer_deg: known.then_some(s.table.angles.outer_deg),
            inner_deg: known.then_some(s.table.angles.inner_deg),
            outer_rate_dps: s.table.rates.outer_deg,
            inner_rate_dps: s.table.rates.inner_deg,
            commanded_outer_deg: known.then_some(s.commanded.outer_deg),
            commanded_inner_deg: known.then_some(s.commanded.inner_deg),
            azimuth_deg: s.orientation.azimuth_deg,
            elevation_deg: s.orientation.elevation_deg,
            roll_deg: s.orientation.roll_deg,
            earth_rate_dph: s.reference_dph,
            in_position: s.in_position,
            step: step.to_owned(),
        };
        self.write_json(topic, s.t_s, &table)
    }

    fn ns(&self, t_s: f64) -> u64 {
        self.start_ns
            .saturating_add((t_s.max(0.0) * 1e9).min(u64::MAX as f64) as u64)
    }

    /// Messages written per topic.
    pub fn message_counts(&self) -> &BTreeMap<String, u64> {
        &self.messages
    }

    /// A batch's unit in `slot` (not the first): its result as the
    /// metadata record `result/SLOT` and its report as the attachment
    /// `report-SERIAL.json`, before [`Recorder::finish_run`].
    pub fn unit_result(
        &mut self,
        slot: &str,
        serial: &str,
        result: &ResultMeta,
        report_json: &str,
        end_s: f64,
    ) -> std::io::Result<()> {
        let at = self.ns(end_s);
        let entries = result.to_entries();
        let report = format!("{}.json", crate::unit::report_name(serial));
        self.guarded(|w| {
            write_result(
                w,
                format!("{RESULT_META}/{slot}"),
                entries,
                Some((report, report_json)),
                at,
            )
        })
    }

    /// End the log of a run: the `result` metadata, the report (when there
    /// is one) as an attachment, the summary, indexes and footer. After a
    /// write failure, returns that failure; what reached the disk is kept.
    pub fn finish_run(
        mut self,
        result: &ResultMeta,
        report_json: Option<&str>,
        end_s: f64,
    ) -> std::io::Result<()> {
        let at = self.ns(end_s);
        let entries = result.to_entries();
        let report = report_json.map(|r| (REPORT_ATTACHMENT.to_owned(), r));
        self.guarded(|w| {
            write_result(w, RESULT_META.into(), entries, report, at)?;
            w.finish().map(|_| ())
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

fn mcap_err(e: mcap::McapError) -> std::io::Error {
    match e {
        mcap::McapError::Io(e) => e,
        e => std::io::Error::other(e),
    }
}

/// The cause of a writer error in words: the I/O error itself when there
/// is one (`No space left on device`), not the writer's wrapper.
/// The `/supply/state` message of a reading at `t_s`.
fn supply_state(t_s: f64, r: &crate::driver::SupplyReading) -> SupplyState {
    SupplyState {
        t_s,
        v: r.v,
        a: r.a,
        w: r.v * r.a,
        set_v: r.set_v,
        limit_a: r.limit_a,
        on: r.on,
        tripped: r.tripped,
    }
}

fn describe(e: &mcap::McapError) -> String {
    match e {
        mcap::McapError::Io(io) => io.to_string(),
        e => e.to_string(),
    }
}

/// The log keeps the run's data as it comes: ticks, intervals, steps,
/// lines, and the link figures once a minute of device time.
impl Observer for Recorder {
    fn observe(&mut self, event: &Event<'_>) -> std::io::Result<()> {
        match *event {
            Event::Tick { tick, record, step } => self.tick(tick, record, step),
            Event::Interval {
                slot: 0,
                iv,
                record,
            } => self.interval(iv, record),
            Event::Interval { slot, iv, record } => self.slot_interval(slot, iv, record),
            Event::Link {
                slot: 0,
                t_s,
                stats,
            } => {
                if t_s - self.last_link_s < 60.0 {
                    self.links_at = None;
                    return Ok(());
                }
                self.last_link_s = t_s;
                self.links_at = Some(t_s);
                self.link(t_s, stats)
            }
            Event::Link { slot, t_s, stats } if self.links_at == Some(t_s) => {
                self.slot_link(slot, t_s, stats)
            }
            Event::Line {
                t_s,
                level,
                message,
            } => self.event(t_s, level, message),
            Event::Step(e) => self.step(e),
            Event::Link { .. }
            | Event::Begin { .. }
            | Event::Doing { .. }
            | Event::State(_)
            | Event::Measured { .. }
            | Event::Warning(_) => Ok(()),
        }
    }
}

/// What the log writes, one kind of message each (the run's observer
/// above; an import writes through them too).
impl Recorder {
    /// The first unit's gyro link figures so far.
    pub fn link(&mut self, t_s: f64, s: &crate::protocol::frame::LinkStats) -> std::io::Result<()> {
        self.write_json(topics::LINK, t_s, &LinkSample { t_s, stats: *s })
    }

    /// A tick: every unit's frames, the chamber, table and supply states.
    pub fn tick(&mut self, tick: &Tick, _record: Option<&str>, step: &str) -> std::io::Result<()> {
        self.write_frames(topics::FRAMES, tick.t0_s, &tick.frames)?;
        for k in 0..self.slots.len().min(tick.slots.len()) {
            let topic = self.slots[k].frames.clone();
            self.write_frames(&topic, tick.t0_s, &tick.slots[k].frames)?;
        }
        if let Some(s) = &tick.state {
            let chamber = ChamberState {
                t_s: s.t_s,
                air_c: s.chamber.air_c,
                set_point_c: s.chamber.set_point_c,
                mode: s.chamber.mode.as_str().to_owned(),
                alarms: s.chamber.alarms.clone(),
            };
            self.write_json(topics::CHAMBER, s.t_s, &chamber)?;
            self.write_table(topics::TABLE, s, step)?;
            for k in 0..self.slots.len().min(tick.slots.len()) {
                let topic = self.slots[k].table.clone();
                self.write_table(&topic, &s.for_slot(k + 1, tick), step)?;
            }
            if let Some(p) = &s.power {
                self.write_json(topics::SUPPLY, s.t_s, &supply_state(s.t_s, p))?;
            }
        }
        Ok(())
    }

    /// Unit `slot`'s link figures (a batch's units after the first).
    pub fn slot_link(
        &mut self,
        slot: usize,
        t_s: f64,
        s: &crate::protocol::frame::LinkStats,
    ) -> std::io::Result<()> {
        let Some(topics) = slot.checked_sub(1).and_then(|k| self.slots.get(k)) else {
            return Ok(());
        };
        let topic = topics.link.clone();
        self.write_json(&topic, t_s, &LinkSample { t_s, stats: *s })
    }

    /// Unit `slot`'s 1 Hz interval (a batch's units after the first).
    pub fn slot_interval(
        &mut self,
        slot: usize,
        iv: &Interval,
        record: Option<&str>,
    ) -> std::io::Result<()> {
        let Some(topics) = slot.checked_sub(1).and_then(|k| self.slots.get(k)) else {
            return Ok(());
        };
        let topic = topics.rate_1hz.clone();
        self.write_json(&topic, iv.time_s, &Rate1Hz::new(iv, record))
    }

    /// The first unit's 1 Hz interval.
    pub fn interval(&mut self, iv: &Interval, record: Option<&str>) -> std::io::Result<()> {
        self.write_json(topics::RATE_1HZ, iv.time_s, &Rate1Hz::new(iv, record))
    }

    /// A line for people.
    pub fn event(&mut self, t_s: f64, level: Level, message: &str) -> std::io::Result<()> {
        let ns = self.ns(t_s);
        let line = LogLine {
            timestamp: Timestamp {
                sec: ns / 1_000_000_000,
                nsec: (ns % 1_000_000_000) as u32,
            },
            level,
            message: message.to_owned(),
            name: "sequencer".into(),
            file: String::new(),
            line: 0,
        };
        self.write_json(topics::EVENTS, t_s, &line)
    }

    /// A step started, ended or was run to restore a resumed run.
    pub fn step(&mut self, e: &StepEvent) -> std::io::Result<()> {
        self.write_json(topics::STEPS, e.t_s, e)
    }
}
