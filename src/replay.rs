//! Replay: every measurement and the verdict of a run, recomputed from its
//! MCAP log alone.
//!
//! The procedure, bench and coefficients come from the log's `run`
//! metadata; the 1 Hz intervals are rebuilt from the gyro frames and the
//! 1 Hz bench state through the same reduction the live run uses
//! ([`TickSums`]), and each measure step is computed where its start event
//! sits in the log, on the records recorded up to then. How the run ended
//! (error, interrupt) is a fact of the run, read from the `result` record.
//! The log streams through: memory holds the 1 Hz intervals, never frames.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;
use serde::de::{IgnoredAny, SeqAccess, Visitor};

use crate::analysis::model::Fit;
use crate::bench::BenchConfig;
use crate::coeffs::CoeffsFile;
use crate::config::Source;
use crate::procedure::{Procedure, StepKind};
use crate::protocol::frame::LinkStats;
use crate::recorder::{Rate1Hz, topics};
use crate::runlog::{self, Item, ReadSummary};
use crate::sequencer::measure::{self, IntervalState, MeasureOutcome, Records, TickSums};
use crate::sequencer::{Outcome, Resume, RunError, RunResult, resume_plan};
use crate::twin::TwinConfig;

/// Name of the metadata record with the run's configuration.
pub const RUN_META: &str = "run";
/// Name of the metadata record that says how the run ended.
pub const RESULT_META: &str = "result";

/// What a replay rebuilt.
#[derive(Debug)]
pub struct Replayed {
    /// The run's metadata (`procedure_toml`, `dut_serial`, ...).
    pub meta: BTreeMap<String, String>,
    /// The procedure read from the log.
    pub procedure: Procedure,
    /// Measurements, records and verdict.
    pub result: RunResult,
    /// The last link figures in the log.
    pub link: LinkStats,
    /// How the read went (complete or truncated).
    pub read: ReadSummary,
    /// Device time of the last state in the log, s.
    pub last_state_s: f64,
    /// Steps completed, counted in setup + main run order over every part
    /// (where a resume picks up).
    pub completed_steps: usize,
    /// Which part of the run this file is (1 for a run never resumed).
    pub part: u32,
}

/// Why a log cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The file could not be read.
    #[error(transparent)]
    Read(#[from] runlog::ReadError),
    /// Something the replay needs is not in the log.
    #[error("{path}: {message}")]
    Log {
        /// File.
        path: String,
        /// What is wrong.
        message: String,
    },
}

/// A JSON array of integers reduced to its sum and length while parsing
/// (no allocation per frame).
#[derive(Debug, Default, Clone, Copy)]
struct Sum {
    n: u64,
    sum: i64,
}

impl<'de> Deserialize<'de> for Sum {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Sum;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("an array of integers")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<Sum, A::Error> {
                let mut s = Sum::default();
                while let Some(v) = a.next_element::<i64>()? {
                    s.n += 1;
                    s.sum = s.sum.saturating_add(v);
                }
                Ok(s)
            }
        }
        d.deserialize_seq(V)
    }
}

#[derive(Deserialize)]
struct FramesMsg {
    dt_s: f64,
    lsb_arcsec: f64,
    temp_lsb_c: f64,
    #[serde(rename = "seq")]
    _seq: IgnoredAny,
    counts: Sum,
    t1_raw: Sum,
    t2_raw: Sum,
    tcase_raw: Sum,
    #[serde(rename = "status")]
    _status: IgnoredAny,
}

#[derive(Deserialize)]
struct TableMsg {
    t_s: f64,
    earth_rate_dph: f64,
}

#[derive(Deserialize)]
struct ChamberMsg {
    air_c: f64,
}

#[derive(Deserialize)]
struct LogMsg {
    level: u8,
    message: String,
}

/// Scale factors of the frames seen so far.
#[derive(Debug, Clone, Copy)]
struct Scales {
    dt_s: f64,
    lsb_arcsec: f64,
    temp_lsb_c: f64,
}

struct State<'a> {
    path: &'a Path,
    coeffs_override: Option<&'a Fit>,
    meta: BTreeMap<String, String>,
    result_meta: Option<BTreeMap<String, String>>,
    procedure: Option<Procedure>,
    coeffs: Option<Fit>,
    records: Records,
    measurements: Vec<measure::Measurement>,
    pending: Option<(TickSums, Scales)>,
    chamber_c: f64,
    table: Option<(f64, f64)>,
    link: LinkStats,
    frames: u64,
    last_step: Option<String>,
    /// Index of the next step in run order.
    cursor: usize,
    /// Steps completed ("end of step" seen), in run order.
    completed: usize,
    /// What earlier parts of the run left (a resumed run's later part).
    earlier: Option<Box<Replayed>>,
}

/// The configuration a run logged in its `run` metadata.
#[derive(Debug, Clone)]
pub struct Logged {
    /// Bench (`bench_toml`; the embedded bench when empty).
    pub bench: BenchConfig,
    /// Procedure (`procedure_toml`), checked against that bench.
    pub procedure: Procedure,
    /// Coefficients the run compensated with (`coeffs_toml`).
    pub coeffs: Option<CoeffsFile>,
    /// Twin of a simulated run (`twin_toml`).
    pub twin: Option<TwinConfig>,
}

/// Parse the `run` metadata's configuration; errors say which part.
pub fn logged(entries: &BTreeMap<String, String>) -> Result<Logged, String> {
    let text = |k: &str| entries.get(k).filter(|t| !t.trim().is_empty());
    let src = |k: &str, t: &str| Source::from_text(&format!("{k} (in the log)"), t);
    let bench = match text("bench_toml") {
        Some(t) => BenchConfig::from_source(&src("bench_toml", t))
            .map_err(|e| format!("the logged bench configuration: {e}"))?,
        None => BenchConfig::embedded(),
    };
    let procedure_text = text("procedure_toml")
        .ok_or_else(|| "no procedure in the log's run metadata".to_owned())?;
    let name = entries
        .get("procedure_path")
        .map_or("procedure (in the log)".to_owned(), |p| {
            format!("{p} (in the log)")
        });
    let procedure = Procedure::from_source(&Source::from_text(&name, procedure_text), &bench)
        .map_err(|e| format!("the logged procedure: {e}"))?;
    let coeffs = text("coeffs_toml")
        .map(|t| CoeffsFile::from_source(&src("coeffs_toml", t)))
        .transpose()
        .map_err(|e| format!("the logged coefficients: {e}"))?;
    let twin = text("twin_toml")
        .map(|t| TwinConfig::from_source(&src("twin_toml", t)))
        .transpose()
        .map_err(|e| format!("the logged twin: {e}"))?;
    Ok(Logged {
        bench,
        procedure,
        coeffs,
        twin,
    })
}

/// Where a resume of the run `prev` picks up after `completed` steps, with
/// what its parts leave (records and measurements trimmed).
pub fn resume_from(prev: &Replayed, completed: usize) -> Resume {
    let (start_at, _) = resume_plan(&prev.procedure, completed);
    let mut records = prev.result.records.clone();
    let mut measurements = prev.result.measurements.clone();
    Resume::trim(&prev.procedure, start_at, &mut records, &mut measurements);
    Resume {
        start_at,
        completed,
        part: prev.part + 1,
        records,
        measurements,
        frames: prev.result.frames,
        device_time_s: prev.result.device_time_s,
    }
}

impl State<'_> {
    fn log_err(&self, message: impl Into<String>) -> String {
        format!("{}: {}", self.path.display(), message.into())
    }

    fn meta(&mut self, name: &str, entries: &BTreeMap<String, String>) -> Result<(), String> {
        match name {
            RUN_META => {
                self.meta = entries.clone();
                let l = logged(entries).map_err(|e| self.log_err(e))?;
                self.coeffs = l.coeffs.as_ref().map(CoeffsFile::fit);
                self.procedure = Some(l.procedure);
                if let Some(prev) = entries.get("previous_part").filter(|p| !p.is_empty()) {
                    let prev_path = self.path.with_file_name(prev);
                    let earlier = replay(&prev_path, self.coeffs_override)
                        .map_err(|e| self.log_err(format!("its earlier part {prev}: {e}")))?;
                    let completed = entries
                        .get("resume_completed_steps")
                        .and_then(|v| v.parse().ok())
                        .unwrap_or(earlier.completed_steps);
                    let r = resume_from(&earlier, completed);
                    self.records = r.records;
                    self.measurements = r.measurements;
                    self.frames = r.frames;
                    self.cursor = r.start_at;
                    self.completed = r.start_at;
                    self.earlier = Some(Box::new(earlier));
                }
            }
            RESULT_META => self.result_meta = Some(entries.clone()),
            _ => {}
        }
        Ok(())
    }

    fn message(&mut self, topic: &str, data: &[u8]) -> Result<(), String> {
        let bad =
            |what: &str, e: serde_json::Error| format!("a {what} message does not parse: {e}");
        match topic {
            topics::FRAMES => {
                let m: FramesMsg = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                if [m.t1_raw.n, m.t2_raw.n, m.tcase_raw.n] != [m.counts.n; 3] {
                    return Err(self.log_err("a /gyro/frames message has arrays of unequal length"));
                }
                self.frames += m.counts.n;
                let sums = TickSums {
                    n: m.counts.n,
                    counts: m.counts.sum,
                    temps: [m.t1_raw.sum, m.t2_raw.sum, m.tcase_raw.sum],
                };
                let scales = Scales {
                    dt_s: m.dt_s,
                    lsb_arcsec: m.lsb_arcsec,
                    temp_lsb_c: m.temp_lsb_c,
                };
                self.pending = Some((sums, scales));
            }
            topics::CHAMBER => {
                let m: ChamberMsg = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.chamber_c = m.air_c;
            }
            topics::TABLE => {
                let m: TableMsg = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.table = Some((m.t_s, m.earth_rate_dph));
            }
            topics::RATE_1HZ => {
                // The live run wrote this interval from the tick just logged.
                let m: Rate1Hz = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                let Some((sums, sc)) = self.pending.take() else {
                    // No frames before it: an imported run; take the interval as logged.
                    self.records.push(m.interval(), m.record.as_deref());
                    return Ok(());
                };
                let Some((t_s, reference_dph)) = self.table else {
                    return Err(self.log_err("a 1 Hz interval without the state before it"));
                };
                let at = IntervalState {
                    t_s,
                    reference_dph,
                    chamber_c: self.chamber_c,
                };
                if let Some(iv) = sums.interval(&at, sc.dt_s, sc.lsb_arcsec, sc.temp_lsb_c) {
                    self.records.push(iv, m.record.as_deref());
                }
            }
            topics::LINK => {
                self.link = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
            }
            topics::EVENTS => {
                let m: LogMsg = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                if m.level == 1 {
                    self.step_event(&m.message);
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// `step KEY (line N): ...` or `cleanup KEY (line N): ...`: a step
    /// started; a measure step is computed here, as in the live run.
    fn step_event(&mut self, message: &str) {
        if let Some(key) = message.strip_prefix("end of step ") {
            let done = self
                .procedure
                .as_ref()
                .and_then(|p| p.steps().nth(self.cursor.checked_sub(1)?))
                .is_some_and(|s| s.key == key);
            if done {
                self.completed = self.cursor;
            }
            return;
        }
        let Some(rest) = message
            .strip_prefix("step ")
            .or_else(|| message.strip_prefix("cleanup "))
        else {
            return;
        };
        let Some((key, _)) = rest.split_once(" (line ") else {
            return;
        };
        self.last_step = Some(key.to_owned());
        // Steps of a repeat share a key: match the next one in run order.
        let Some((at, step)) = self.procedure.as_ref().and_then(|p| {
            p.steps()
                .enumerate()
                .skip(self.cursor)
                .find(|(_, s)| s.key == key)
        }) else {
            return;
        };
        self.cursor = at + 1;
        match &step.kind {
            StepKind::Record { label, .. } => self.records.start(label),
            StepKind::Measure(m) => {
                let coeffs = self.coeffs_override.or(self.coeffs.as_ref());
                self.measurements
                    .push(measure::compute(m, &self.records, coeffs, key));
            }
            _ => {}
        }
    }
}

/// Replay the log at `path`; `coeffs` replace the coefficients the run used.
pub fn replay(path: &Path, coeffs: Option<&Fit>) -> Result<Replayed, ReplayError> {
    let mut st = State {
        path,
        coeffs_override: coeffs,
        meta: BTreeMap::new(),
        result_meta: None,
        procedure: None,
        coeffs: None,
        records: Records::default(),
        measurements: Vec::new(),
        pending: None,
        chamber_c: f64::NAN,
        table: None,
        link: LinkStats::default(),
        frames: 0,
        last_step: None,
        cursor: 0,
        completed: 0,
        earlier: None,
    };
    let read = runlog::read(path, |item| match item {
        Item::Meta { name, entries } => st.meta(name, entries),
        Item::Message { topic, data, .. } => {
            if st.procedure.is_none() && topic != topics::EVENTS {
                return Err(
                    st.log_err("messages before the run metadata; is this a gyrobench log?")
                );
            }
            st.message(topic, data)
        }
    })?;
    let log_err = |message: String| ReplayError::Log {
        path: path.display().to_string(),
        message,
    };
    if let Some(why) = read.stopped.as_ref().filter(|_| read.complete) {
        return Err(log_err(why.clone()));
    }
    let procedure = st.procedure.take().ok_or_else(|| {
        log_err("no run metadata (procedure, bench) in the log; is this a gyrobench log?".into())
    })?;
    let last_state_s = st.table.map_or(0.0, |(t, _)| t);
    let earlier_s = st.earlier.as_ref().map_or(0.0, |e| e.result.device_time_s);
    let failed = st
        .measurements
        .iter()
        .any(|m| m.outcome != MeasureOutcome::Pass);
    let verdict = if failed { Outcome::Fail } else { Outcome::Pass };
    let (outcome, error, cleanup_completed, device_time_s) = match &st.result_meta {
        Some(r) => {
            let outcome = match r.get("outcome").map(String::as_str) {
                Some("error") => Outcome::Error,
                Some("aborted") => Outcome::Aborted,
                // pass or fail: the verdict is the recomputed one.
                _ => verdict,
            };
            let error = r.get("error_step").map(|step| RunError {
                device: r.get("error_device").cloned(),
                step: step.clone(),
                message: r.get("error_message").cloned().unwrap_or_default(),
            });
            (
                outcome,
                error,
                r.get("cleanup_completed").is_some_and(|v| v == "true"),
                r.get("device_time_s")
                    .and_then(|v| v.parse().ok())
                    .unwrap_or(earlier_s + last_state_s),
            )
        }
        None => (
            Outcome::Error,
            Some(RunError {
                device: None,
                step: st.last_step.clone().unwrap_or_default(),
                message: format!(
                    "the log ends at {:.0} s of device time without its end record ({}); {} bytes after the last complete chunk were lost",
                    last_state_s,
                    read.stopped.as_deref().unwrap_or("the run did not finish"),
                    read.bytes_lost
                ),
            }),
            false,
            earlier_s + last_state_s,
        ),
    };
    let link = match &st.earlier {
        Some(e) => add_link(&e.link, &st.link),
        None => st.link,
    };
    let part = st.earlier.as_ref().map_or(1, |e| e.part + 1);
    Ok(Replayed {
        meta: st.meta,
        procedure,
        result: RunResult {
            outcome,
            measurements: st.measurements,
            error,
            cleanup_completed,
            device_time_s,
            frames: st.frames,
            records: st.records,
        },
        link,
        read,
        last_state_s,
        completed_steps: st.completed,
        part,
    })
}

/// Link figures of two parts of a run, added.
pub fn add_link(a: &LinkStats, b: &LinkStats) -> LinkStats {
    LinkStats {
        bytes: a.bytes + b.bytes,
        frames: a.frames + b.frames,
        resyncs: a.resyncs + b.resyncs,
        skipped_bytes: a.skipped_bytes + b.skipped_bytes,
        crc_errors: a.crc_errors + b.crc_errors,
        lost_frames: a.lost_frames + b.lost_frames,
        duplicates: a.duplicates + b.duplicates,
    }
}

/// The `result` metadata record of a run.
pub fn result_entries(r: &RunResult) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    let outcome = serde_json::to_value(r.outcome)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default();
    m.insert("outcome".into(), outcome);
    m.insert("cleanup_completed".into(), r.cleanup_completed.to_string());
    m.insert("device_time_s".into(), format!("{:?}", r.device_time_s));
    m.insert("frames".into(), r.frames.to_string());
    if let Some(e) = &r.error {
        m.insert("error_step".into(), e.step.clone());
        m.insert("error_message".into(), e.message.clone());
        if let Some(d) = &e.device {
            m.insert("error_device".into(), d.clone());
        }
    }
    m
}

/// Per-frame rates of one record of a log, deg/h (Earth rate included).
#[derive(Debug, Clone)]
pub struct RecordRates {
    /// Record label.
    pub record: String,
    /// Frame period, s.
    pub dt_s: f64,
    /// Rate of each frame, deg/h.
    pub rate_dph: Vec<f64>,
}

#[derive(Deserialize)]
struct FrameCounts {
    dt_s: f64,
    lsb_arcsec: f64,
    counts: Vec<i32>,
}

/// The frames of record `label` (default: the longest record of the
/// logged procedure) as a rate series at the frame rate; for an imported
/// run (no frames), its 1 Hz means.
pub fn record_rates(path: &Path, label: Option<&str>) -> Result<RecordRates, ReplayError> {
    let log_err = |message: String| ReplayError::Log {
        path: path.display().to_string(),
        message,
    };
    let mut want: Option<String> = label.map(str::to_owned);
    let mut labels: Vec<String> = Vec::new();
    let mut pending: Option<FrameCounts> = None;
    let mut out = RecordRates {
        record: String::new(),
        dt_s: f64::NAN,
        rate_dph: Vec::new(),
    };
    runlog::read(path, |item| {
        match item {
            Item::Meta { name, entries } if name == RUN_META => {
                // The procedure as logged, checked against the logged bench.
                if let Ok(Logged { procedure: p, .. }) = logged(entries) {
                    let records = p.steps().filter_map(|s| match &s.kind {
                        StepKind::Record { label, duration_s } => {
                            Some((label.clone(), *duration_s))
                        }
                        _ => None,
                    });
                    let mut longest: Option<(String, f64)> = None;
                    for (l, d) in records {
                        labels.push(l.clone());
                        if longest.as_ref().is_none_or(|(_, best)| d > *best) {
                            longest = Some((l, d));
                        }
                    }
                    if want.is_none() {
                        want = longest.map(|(l, _)| l);
                    }
                }
            }
            Item::Message { topic, data, .. } if topic == topics::FRAMES => {
                pending = serde_json::from_slice(data).ok();
            }
            Item::Message { topic, data, .. } if topic == topics::RATE_1HZ => {
                let m: Rate1Hz = serde_json::from_slice(data)
                    .map_err(|e| format!("a {topic} message does not parse: {e}"))?;
                let mine = want
                    .as_deref()
                    .is_some_and(|w| m.record.as_deref() == Some(w));
                match pending.take() {
                    Some(f) if mine => {
                        out.dt_s = f.dt_s;
                        let k = f.lsb_arcsec / f.dt_s;
                        out.rate_dph
                            .extend(f.counts.iter().map(|&c| f64::from(c) * k));
                    }
                    // No frames (an imported run): the 1 Hz means.
                    None if mine => {
                        out.dt_s = 1.0;
                        out.rate_dph.push(m.rate_dph);
                    }
                    _ => {}
                }
            }
            _ => {}
        }
        Ok(())
    })?;
    let Some(want) = want else {
        return Err(log_err("the log has no record steps to analyse".into()));
    };
    if out.rate_dph.is_empty() {
        return Err(log_err(format!(
            "no frames recorded under `{want}`; records in this log: {}",
            if labels.is_empty() {
                "none".to_owned()
            } else {
                labels.join(", ")
            }
        )));
    }
    out.record = want;
    Ok(out)
}
