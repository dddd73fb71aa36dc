//! The run's log: the sequencer's events as the log's messages, written
//! through the log crate's [`LogWriter`] (`docs/report.md`, "The MCAP
//! log").
//!
//! The `run` metadata and the procedure go in up front; gyro frames are
//! batched one message per tick; the link figures once a minute of device
//! time. [`Recorder::finish_run`] writes the `result` metadata and the
//! report, and ends the file.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use gyrobench_log::{LogWriter, Opening, Tap};

use super::live::Live;
use super::meta::{ResultMeasurement, ResultMeta, RunMeta};
use super::schema::{
    ChamberState, GyroFrames, Level, LinkSample, LogLine, Rate1Hz, StepEvent, SupplyState,
    TableState, Timestamp, slot_topic, topics,
};
use crate::analysis::series::Interval;
use crate::sequencer::{BenchState, Event, FrameRecord, Observer, RunResult, Tick};

/// Writes a run's MCAP file.
#[derive(Debug)]
pub struct Recorder {
    log: LogWriter,
    frame_dt_s: f64,
    lsb_arcsec: f64,
    temp_lsb_c: f64,
    /// A batch's other units' topics (slots after the first).
    slots: Vec<SlotTopics>,
    /// Device time the link figures were last written at, s (they are
    /// written once a minute of device time).
    last_link_s: f64,
    /// Device time of the tick whose link figures are being written (a
    /// batch's other units' follow the first unit's).
    links_at: Option<f64>,
    /// Whether the table angles of the states written are known (not for
    /// a run imported from another bench without them).
    table_angles_known: bool,
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

impl Tap for Live {
    fn publish(&self, topic: &str, log_time_ns: u64, json: &[u8]) {
        Live::publish(self, topic, log_time_ns, json);
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
        let log = LogWriter::create(path, &opening(meta, start_ns))?;
        Ok(Self::new(log, meta, scales))
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
        let log = LogWriter::from_file(file, path, &opening(meta, start_ns))?;
        Ok(Self::new(log, meta, scales))
    }

    fn new(log: LogWriter, meta: &RunMeta, scales: FrameScales) -> Self {
        Self {
            log,
            frame_dt_s: scales.dt_s,
            lsb_arcsec: scales.lsb_arcsec,
            temp_lsb_c: scales.temp_lsb_c,
            slots: meta
                .units
                .iter()
                .skip(1)
                .map(|u| SlotTopics::of(&u.slot))
                .collect(),
            last_link_s: 0.0,
            links_at: None,
            table_angles_known: true,
        }
    }

    /// Publish every message written from now on on `live` too.
    pub fn publish_live(&mut self, live: Arc<Live>) {
        self.log.tap(live);
    }

    /// Whether the table states written from now on carry table angles
    /// (an imported run knows its orientation, not always its table's).
    pub fn set_table_angles_known(&mut self, known: bool) {
        self.table_angles_known = known;
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        self.log.path()
    }

    /// Play a full disk from device time `t_s` on: every write from then
    /// fails as `No space left on device` would, and nothing more reaches
    /// the file (the simulated bench's `disk-full` fault).
    pub fn fill_disk_at(&mut self, t_s: f64) {
        let why = format!(
            "writing {}: {} (simulated: --inject disk-full)",
            self.log.path().display(),
            std::io::Error::from_raw_os_error(28)
        );
        self.log.fail_from(t_s, why);
    }

    /// The first write failure, if any ("writing FILE: cause").
    pub fn failure(&self) -> Option<&str> {
        self.log.failure()
    }

    fn write_json(
        &mut self,
        topic: &str,
        t_s: f64,
        value: &impl serde::Serialize,
    ) -> std::io::Result<()> {
        self.log.write(topic, t_s, value)
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

    /// Messages written per topic.
    pub fn message_counts(&self) -> &BTreeMap<String, u64> {
        self.log.message_counts()
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
        let report = format!("{}.json", crate::unit::report_name(serial));
        self.log
            .unit_result(slot, result.to_entries(), report, report_json, end_s)
    }

    /// End the log of a run: the `result` metadata, the report (when there
    /// is one) as an attachment, the summary, indexes and footer. After a
    /// write failure, returns that failure; what reached the disk is kept.
    pub fn finish_run(
        self,
        result: &ResultMeta,
        report_json: Option<&str>,
        end_s: f64,
    ) -> std::io::Result<()> {
        self.log
            .finish(result.to_entries(), report_json, end_s)
            .map(|_| ())
    }
}

/// What a run's log starts with: its `run` metadata, its procedure, its
/// batch's other units' slots.
fn opening(meta: &RunMeta, start_ns: u64) -> Opening<'_> {
    Opening {
        library: format!("gyrobench {}", env!("CARGO_PKG_VERSION")),
        run: meta.to_entries(),
        procedure_toml: &meta.procedure_toml,
        slots: meta.units.iter().skip(1).map(|u| u.slot.clone()).collect(),
        start_ns,
    }
}

/// The `result` record of a run's result.
impl From<&RunResult> for ResultMeta {
    fn from(r: &RunResult) -> Self {
        Self {
            end_time_utc: None,
            outcome: r.outcome,
            cleanup_completed: r.cleanup_completed,
            device_time_s: Some(r.device_time_s),
            frames: r.frames,
            error: r.error.clone(),
            measurements: r.measurements.iter().map(ResultMeasurement::from).collect(),
            bench_left: r.bench_left.clone(),
        }
    }
}

/// A measurement as the `result` record lists it.
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
        let ns = self.log.ns(t_s);
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
