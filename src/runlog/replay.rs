//! Replay: every measurement and the verdict of a run, recomputed from its
//! MCAP log alone.
//!
//! The procedure, bench and coefficients come from the log's `run`
//! metadata; the 1 Hz intervals are rebuilt from the gyro frames and the
//! 1 Hz bench state through the same reduction the live run uses
//! ([`TickSums`]), and each measure step is computed where its `/steps`
//! start sits in the log, on the records recorded up to then. How the run
//! ended (error, interrupt, the bench state) is a fact of the run, read
//! from the `result` record. The log streams through: memory holds the
//! 1 Hz intervals, never frames.
//!
//! Logs of format 1 (no `/steps`) are read by their `/events` lines, in
//! [`format1`], and give the same figures.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;
use serde::de::{IgnoredAny, SeqAccess, Visitor};

use super::meta::{ResultMeta, RunMeta};
use super::reader::{self, Item, ReadSummary};
use super::schema::{
    ChamberState, LinkSample, LogLine, RESULT_META, RUN_META, Rate1Hz, StepEvent, StepPhase,
    SupplyState, TableState, topics,
};

use crate::bench::BenchConfig;
use crate::coeffs::{CoefficientSet, Compensation};
use crate::config::Source;
use crate::geometry::{Orientation, TableAngles};
use crate::procedure::{Procedure, StepKind};
use crate::protocol::frame::LinkStats;
use crate::sequencer::measure::{self, IntervalState, Records, TickSums};
use crate::sequencer::{Outcome, Resume, RunError, RunResult, resume_plan};
use crate::twin::TwinConfig;
use gyrobench_model::measurement::Measurement;

/// What a replay rebuilt.
#[derive(Debug)]
pub struct Replayed {
    /// The run's metadata (of this part).
    pub meta: RunMeta,
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
    /// Whether the log holds its end record (the run's own outcome); a
    /// log without one was cut short (a kill, a full disk).
    pub ended: bool,
    /// When the part ended, as its end record states (none: a log without
    /// one, or written before the key).
    pub end_time_utc: Option<String>,
    /// The pose each record of an imported run was taken in, as logged
    /// (label, orientation, table angles where known), in run order; a
    /// live run's poses are its procedure's moves.
    pub poses: Vec<(String, Orientation, Option<TableAngles>)>,
}

/// Why a log cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The file could not be read.
    #[error(transparent)]
    Read(#[from] reader::ReadError),
    /// Something the replay needs is not in the log.
    #[error("{path}: {message}")]
    Log {
        /// File.
        path: String,
        /// What is wrong.
        message: String,
    },
}

impl From<crate::runlog::meta::RunMetaError> for ReplayError {
    fn from(e: crate::runlog::meta::RunMetaError) -> Self {
        use crate::runlog::meta::RunMetaError;
        match e {
            RunMetaError::Read(e) => Self::Read(e),
            RunMetaError::Invalid { ref path, .. } | RunMetaError::Missing { ref path } => {
                Self::Log {
                    path: path.clone(),
                    message: e.detail(),
                }
            }
        }
    }
}

/// A JSON array of integers reduced to its sum, length and extremes while
/// parsing (no allocation per frame).
#[derive(Debug, Default, Clone, Copy)]
struct Sum {
    n: u64,
    sum: i64,
    extremes: Option<(i64, i64)>,
    runs: crate::sequencer::health::Runs,
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
                    s.extremes = Some(s.extremes.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))));
                    s.runs.push(i32::try_from(v).unwrap_or(if v < 0 {
                        i32::MIN
                    } else {
                        i32::MAX
                    }));
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
    status: Vec<u16>,
}

/// Scale factors of the frames seen so far.
#[derive(Debug, Clone, Copy)]
struct Scales {
    dt_s: f64,
    lsb_arcsec: f64,
    temp_lsb_c: f64,
}

/// What an interval takes from the last `/table/state` before it.
#[derive(Debug, Clone, Copy)]
struct LoggedTable {
    t_s: f64,
    earth_rate_dph: f64,
    rates_dps: (f64, f64),
    orientation: Orientation,
    angles: Option<TableAngles>,
}

struct State<'a> {
    path: &'a Path,
    coeffs_override: Option<&'a Compensation>,
    /// The batch's unit replayed (its earlier parts are its too).
    unit: Option<&'a str>,
    meta: Option<RunMeta>,
    result_meta: Option<ResultMeta>,
    procedure: Option<Procedure>,
    coeffs: Option<Compensation>,
    records: Records,
    measurements: Vec<Measurement>,
    pending: Option<(TickSums, Scales)>,
    /// The tick's supply reading, filed with the record of the interval
    /// that follows it, or with none when the next message is not one.
    pending_power: Option<measure::PowerSample>,
    chamber_c: f64,
    table: Option<LoggedTable>,
    /// The pose of each record of an imported run, as logged.
    poses: Vec<(String, Orientation, Option<TableAngles>)>,
    /// How far a record's ends may fall off its frames on the logged bench.
    record_edge_s: f64,
    /// What the run's figures were judged by.
    judging: measure::Judging,
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
    pub coeffs: Option<CoefficientSet>,
    /// Twin of a simulated run (`twin_toml`).
    pub twin: Option<TwinConfig>,
}

/// Why the configuration a run logged in its `run` metadata cannot be
/// taken back from it.
#[derive(Debug, thiserror::Error)]
pub enum LoggedError {
    /// A log of format 2 or later, or of a real bench, without its bench.
    #[error("no bench configuration in the log's run metadata (bench {bench:?})")]
    NoBench {
        /// The bench the metadata names.
        bench: String,
    },
    /// No procedure text.
    #[error("no procedure in the log's run metadata")]
    NoProcedure,
    /// A logged text that does not load (file, line and field said by
    /// its source).
    #[error("the logged {part}: {source}")]
    Invalid {
        /// `bench configuration`, `procedure`, `coefficients` or `twin`.
        part: &'static str,
        /// Why.
        #[source]
        source: crate::config::ConfigError,
    },
}

/// A logged text that does not load, as a [`LoggedError`].
fn invalid(part: &'static str) -> impl Fn(crate::config::ConfigError) -> LoggedError {
    move |source| LoggedError::Invalid { part, source }
}

/// The bench a run logged in its `run` metadata (`bench_toml`; the
/// embedded bench for a format 1 log that left it empty).
pub fn logged_bench(meta: &RunMeta) -> Result<BenchConfig, LoggedError> {
    if meta.bench_toml.trim().is_empty() {
        if meta.format >= 2 || !meta.is_embedded() {
            return Err(LoggedError::NoBench {
                bench: meta.bench.clone(),
            });
        }
        return Ok(BenchConfig::embedded());
    }
    BenchConfig::from_source(&Source::from_text(
        "bench_toml (in the log)",
        &meta.bench_toml,
    ))
    .map_err(invalid("bench configuration"))
}

/// Parse the `run` metadata's configuration; errors say which part.
pub fn logged(meta: &RunMeta) -> Result<Logged, LoggedError> {
    let src = |k: &str, t: &str| Source::from_text(&format!("{k} (in the log)"), t);
    let bench = logged_bench(meta)?;
    if meta.procedure_toml.trim().is_empty() {
        return Err(LoggedError::NoProcedure);
    }
    let name = if meta.procedure_path.is_empty() {
        "procedure (in the log)".to_owned()
    } else {
        format!("{} (in the log)", meta.procedure_path)
    };
    let procedure = Procedure::from_source(
        &Source::from_text(&name, &meta.procedure_toml),
        &bench.procedure_limits(),
    )
    .map_err(invalid("procedure"))?;
    let coeffs = meta
        .coeffs_toml
        .as_deref()
        .map(|t| CoefficientSet::from_source(&src("coeffs_toml", t)))
        .transpose()
        .map_err(invalid("coefficients"))?;
    let twin = meta
        .twin_toml
        .as_deref()
        .map(|t| TwinConfig::from_source(&src("twin_toml", t)))
        .transpose()
        .map_err(invalid("twin"))?;
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
        others: Vec::new(),
    }
}

/// [`resume_from`] for a batch: the first unit's from `prev`, each other
/// unit's from its own replay of the same log (`others`, in unit order),
/// trimmed at the same step.
pub fn resume_batch_from(prev: &Replayed, others: &[Replayed], completed: usize) -> Resume {
    let mut r = resume_from(prev, completed);
    r.others = others
        .iter()
        .map(|o| {
            let u = resume_from(o, completed);
            crate::sequencer::resume::UnitResume {
                records: u.records,
                measurements: u.measurements,
                frames: u.frames,
            }
        })
        .collect();
    r
}

impl<'a> State<'a> {
    fn log_err(&self, message: impl Into<String>) -> String {
        format!("{}: {}", self.path.display(), message.into())
    }

    fn meta(&mut self, name: &str, entries: &BTreeMap<String, String>) -> Result<(), String> {
        match name {
            RUN_META => {
                let meta =
                    RunMeta::from_entries(entries).map_err(|e| self.log_err(e.to_string()))?;
                let l = logged(&meta).map_err(|e| self.log_err(e.to_string()))?;
                self.coeffs =
                    l.coeffs
                        .as_ref()
                        .and_then(CoefficientSet::fit)
                        .map(|fit| Compensation {
                            fit,
                            used: meta
                                .unit()
                                .map_or_else(crate::coeffs::CoeffsUsed::fitted, |u| {
                                    u.coefficients.clone()
                                }),
                        });
                self.record_edge_s = l.bench.record_edge_s();
                self.judging = measure::Judging::new(&l.procedure, &l.bench, meta.format);
                self.procedure = Some(l.procedure);
                if let Some(prev) = &meta.previous_part {
                    if prev.contains('/') || prev.contains('\\') || prev.starts_with('.') {
                        return Err(self.log_err(format!(
                            "previous_part {prev:?} is not a file name beside the log"
                        )));
                    }
                    let prev_path = self.path.with_file_name(prev);
                    let earlier = replay_unit(&prev_path, self.coeffs_override, self.unit)
                        .map_err(|e| self.log_err(format!("its earlier part {prev}: {e}")))?;
                    // A part of another run (a file copied in, a directory
                    // reused) is not this run's: its steps and figures
                    // would be mixed with another unit's.
                    let (mine, theirs) = (&meta.run_id, &earlier.meta.run_id);
                    if !mine.is_empty() && !theirs.is_empty() && mine != theirs {
                        return Err(self.log_err(format!(
                            "it is a part of run {mine}, but its earlier part {prev} is of run {theirs}: the parts are of two runs; move the foreign file out of the run directory"
                        )));
                    }
                    if earlier.meta.part + 1 != meta.part {
                        return Err(self.log_err(format!(
                            "it says it is part {} but its earlier part {prev} is part {}",
                            meta.part, earlier.meta.part
                        )));
                    }
                    let completed = meta
                        .resume_completed_steps
                        .unwrap_or(earlier.completed_steps);
                    let r = resume_from(&earlier, completed);
                    self.records = r.records;
                    self.records.set_part(r.part);
                    self.measurements = r.measurements;
                    self.frames = r.frames;
                    self.cursor = r.start_at;
                    self.completed = r.start_at;
                    self.earlier = Some(Box::new(earlier));
                }
                self.records.set_status_bits(
                    l.bench
                        .unit_status_bits(meta.unit().map_or("", |u| u.slot.as_str())),
                );
                self.meta = Some(meta);
            }
            RESULT_META => {
                self.result_meta = Some(
                    ResultMeta::from_entries(entries).map_err(|e| self.log_err(e.to_string()))?,
                );
            }
            _ => {}
        }
        Ok(())
    }

    /// A replay of `path` about to read it (`coeffs` replace the run's;
    /// `unit`: a batch's unit by serial).
    fn new(path: &'a Path, coeffs: Option<&'a Compensation>, unit: Option<&'a str>) -> Self {
        State {
            path,
            coeffs_override: coeffs,
            unit,
            meta: None,
            result_meta: None,
            procedure: None,
            judging: measure::Judging::default(),
            coeffs: None,
            records: Records::default(),
            measurements: Vec::new(),
            pending: None,
            pending_power: None,
            chamber_c: f64::NAN,
            table: None,
            poses: Vec::new(),
            record_edge_s: 0.0,
            link: LinkStats::default(),
            frames: 0,
            last_step: None,
            cursor: 0,
            completed: 0,
            earlier: None,
        }
    }

    /// How the run ended: as its end record says (a pass or fail judged
    /// again on the recomputed figures), or an error where the log stops
    /// without one, `last_state_s` into this part.
    fn ending(&mut self, read: &ReadSummary, last_state_s: f64) -> Ending {
        let earlier_s = self
            .earlier
            .as_ref()
            .map_or(0.0, |e| e.result.device_time_s);
        let (verdict, verdict_error) = crate::sequencer::verdict(&self.measurements);
        let (outcome, error, cleanup_completed, device_time_s, bench_left) = match self
            .result_meta
            .take()
        {
            Some(r) => {
                let (outcome, error) = match r.outcome {
                    Outcome::Error | Outcome::Aborted => (r.outcome, r.error),
                    // pass or fail: the verdict is the recomputed one.
                    Outcome::Pass
                    | Outcome::Fail
                    | Outcome::ConditionalPass
                    | Outcome::ConditionalFail => (verdict, verdict_error),
                };
                (
                    outcome,
                    error,
                    r.cleanup_completed,
                    r.device_time_s.unwrap_or(earlier_s + last_state_s),
                    r.bench_left,
                )
            }
            None => (
                Outcome::Error,
                Some(RunError {
                    device: None,
                    step: self.last_step.clone().unwrap_or_default(),
                    message: format!(
                        "the log ends at {:.0} s of device time without its end record ({}); {} bytes after the last complete chunk were lost",
                        last_state_s,
                        read.stopped.as_deref().unwrap_or("the run did not finish"),
                        read.bytes_lost
                    ),
                }),
                false,
                earlier_s + last_state_s,
                None,
            ),
        };
        Ending {
            outcome,
            error,
            cleanup_completed,
            device_time_s,
            bench_left,
        }
    }

    fn message(&mut self, topic: &str, data: &[u8]) -> Result<(), String> {
        let bad =
            |what: &str, e: serde_json::Error| format!("a {what} message does not parse: {e}");
        if topic != topics::RATE_1HZ
            && let Some(p) = self.pending_power.take()
        {
            self.records.push_power(p, None);
        }
        match topic {
            topics::SUPPLY => {
                let m: SupplyState = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.pending_power = Some(measure::PowerSample {
                    t_s: m.t_s,
                    v: m.v,
                    a: m.a,
                    on: m.on,
                });
            }
            topics::FRAMES => {
                let m: FramesMsg = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.on_frames(&m)?;
            }
            topics::CHAMBER => {
                let m: ChamberState = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.chamber_c = m.air_c;
            }
            topics::TABLE => {
                let m: TableState = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.on_table(&m);
            }
            topics::RATE_1HZ => {
                // The live run wrote this interval from the tick just logged.
                let m: Rate1Hz = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.on_interval(&m)?;
            }
            topics::LINK => {
                let m: LinkSample = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.link = m.stats;
            }
            topics::STEPS => {
                let e: StepEvent = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                self.step_event(&e)?;
            }
            topics::EVENTS if self.meta.as_ref().is_some_and(|m| m.format < 2) => {
                let m: LogLine = serde_json::from_slice(data).map_err(|e| bad(topic, e))?;
                if let Some(e) = format1::step_event(&m, self.procedure.as_ref(), self.cursor) {
                    self.step_event(&e)?;
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// A tick's frames, held until its 1 Hz interval comes.
    fn on_frames(&mut self, m: &FramesMsg) -> Result<(), String> {
        if [m.t1_raw.n, m.t2_raw.n, m.tcase_raw.n] != [m.counts.n; 3] {
            return Err(self.log_err("a /gyro/frames message has arrays of unequal length"));
        }
        self.frames += m.counts.n;
        let clamp = |v: i64| i32::try_from(v).unwrap_or(if v < 0 { i32::MIN } else { i32::MAX });
        if m.status.len() as u64 != m.counts.n {
            return Err(self.log_err("a /gyro/frames message has arrays of unequal length"));
        }
        let mut sums = TickSums {
            n: m.counts.n,
            counts: m.counts.sum,
            temps: [m.t1_raw.sum, m.t2_raw.sum, m.tcase_raw.sum],
            extremes: m.counts.extremes.map(|(lo, hi)| (clamp(lo), clamp(hi))),
            runs: m.counts.runs,
            ..TickSums::default()
        };
        let bits = self.records.status_bits();
        for &s in &m.status {
            sums.add_status(s, &bits);
        }
        let scales = Scales {
            dt_s: m.dt_s,
            lsb_arcsec: m.lsb_arcsec,
            temp_lsb_c: m.temp_lsb_c,
        };
        self.pending = Some((sums, scales));
        Ok(())
    }

    /// The table's state: the pose and rates the next interval is taken in.
    fn on_table(&mut self, m: &TableState) {
        self.table = Some(LoggedTable {
            t_s: m.t_s,
            earth_rate_dph: m.earth_rate_dph,
            rates_dps: (m.outer_rate_dps, m.inner_rate_dps),
            orientation: Orientation::new(m.azimuth_deg, m.elevation_deg, m.roll_deg),
            angles: m
                .outer_deg
                .zip(m.inner_deg)
                .map(|(outer_deg, inner_deg)| TableAngles {
                    outer_deg,
                    inner_deg,
                }),
        });
    }

    /// A 1 Hz interval: made again from the frames before it, as the live
    /// run made it; an imported run's (no frames) taken as logged.
    fn on_interval(&mut self, m: &Rate1Hz) -> Result<(), String> {
        let Some((sums, sc)) = self.pending.take() else {
            // No frames before it: an imported run; take the interval as logged,
            // and the pose its record was taken in.
            if let (Some(label), Some(t)) = (&m.record, &self.table)
                && !self.poses.iter().any(|p| &p.0 == label)
            {
                self.poses.push((label.clone(), t.orientation, t.angles));
            }
            self.records.push(m.interval(), m.record.as_deref());
            return Ok(());
        };
        let Some(table) = self.table else {
            return Err(self.log_err("a 1 Hz interval without the state before it"));
        };
        let at = IntervalState {
            t_s: table.t_s,
            reference_dph: table.earth_rate_dph,
            chamber_c: self.chamber_c,
            table_rates_dps: table.rates_dps,
            table_angles: table.angles,
            axis_gravity_g: -table.orientation.elevation_deg.to_radians().sin(),
        };
        self.records.push_sums(
            &sums,
            &at,
            m.record.as_deref(),
            sc.dt_s,
            sc.lsb_arcsec,
            sc.temp_lsb_c,
        );
        if let Some(p) = self.pending_power.take() {
            self.records.push_power(p, m.record.as_deref());
        }
        Ok(())
    }

    /// A step started or ended; a measure step is computed at its start,
    /// on the records so far, as in the live run.
    fn step_event(&mut self, e: &StepEvent) -> Result<(), String> {
        // A power-on, as the live run recorded it (a step's or the run's own).
        if let Some(on) = &e.power_on {
            self.records.power_on(on.clone());
        }
        if e.phase == StepPhase::Restore {
            return Ok(());
        }
        let Some(p) = self.procedure.as_ref() else {
            return Ok(());
        };
        let Some(step) = p.steps().nth(e.index).filter(|s| s.key == e.key) else {
            return Err(self.log_err(format!(
                "a /steps event names step {} ({}), which is not step {} of the logged procedure",
                e.key, e.description, e.index
            )));
        };
        let frames = self
            .meta
            .as_ref()
            .is_some_and(|m| m.imported_from.is_none());
        match e.phase {
            StepPhase::End => {
                // Steps completed count in setup + main run order.
                if e.index < p.setup.len() + p.main.len() {
                    self.completed = self.completed.max(e.index + 1);
                }
                if let (StepKind::Record { label, .. }, Some(link)) = (&step.kind, e.link) {
                    self.records.set_link(label, link);
                }
            }
            StepPhase::Start => {
                self.last_step = Some(e.key.clone());
                self.cursor = e.index + 1;
                match &step.kind {
                    // A run of frames has its records' health judged; an
                    // imported run (1 Hz means only) has none to judge.
                    StepKind::Record { label, duration_s } if frames => {
                        self.records
                            .start_frames(label, *duration_s, self.record_edge_s);
                    }
                    StepKind::Record { label, .. } => self.records.start(label),
                    StepKind::Measure(m) => {
                        let coeffs = self.coeffs_override.or(self.coeffs.as_ref());
                        self.measurements.push(measure::compute(
                            m,
                            &self.records,
                            coeffs,
                            &e.key,
                            &self.judging,
                        ));
                    }
                    _ => {}
                }
            }
            StepPhase::Restore => {}
        }
        Ok(())
    }
}

/// Format 1 logs: steps are known only by their `/events` lines,
/// `step KEY (line N): ...` / `cleanup KEY (line N): ...` at the start and
/// `end of step KEY` at the end (level 1).
mod format1 {
    use super::{LogLine, StepEvent, StepPhase};
    use crate::procedure::Procedure;
    use crate::runlog::schema::Level;

    /// The step event an `/events` line of a format 1 log stands for;
    /// `cursor` is the run-order position after the last step started
    /// (steps of a repeat share their key: the next one matches).
    pub(super) fn step_event(
        m: &LogLine,
        p: Option<&Procedure>,
        cursor: usize,
    ) -> Option<StepEvent> {
        if m.level != Level::Debug {
            return None;
        }
        let p = p?;
        let ev = |phase, index: usize| {
            let s = p.steps().nth(index)?;
            Some(crate::sequencer::events::step_event(0.0, phase, index, s))
        };
        if let Some(key) = m.message.strip_prefix("end of step ") {
            let index = cursor.checked_sub(1)?;
            return (p.steps().nth(index)?.key == key)
                .then(|| ev(StepPhase::End, index))
                .flatten();
        }
        let rest = m
            .message
            .strip_prefix("step ")
            .or_else(|| m.message.strip_prefix("cleanup "))?;
        let (key, _) = rest.split_once(" (line ")?;
        let (index, _) = p
            .steps()
            .enumerate()
            .skip(cursor)
            .find(|(_, s)| s.key == key)?;
        ev(StepPhase::Start, index)
    }
}

/// Replay the log at `path`; `coeffs` replace the coefficients the run used.
pub fn replay(path: &Path, coeffs: Option<&Compensation>) -> Result<Replayed, ReplayError> {
    replay_unit(path, coeffs, None)
}

/// Replay unit `unit` (a serial) of the log at `path` as the log of that
/// unit alone (`super::view`; none: the log as written, a batch's first
/// unit).
pub fn replay_unit(
    path: &Path,
    coeffs: Option<&Compensation>,
    unit: Option<&str>,
) -> Result<Replayed, ReplayError> {
    let mut st = State::new(path, coeffs, unit);
    let read = super::view::read_unit(
        path,
        unit,
        super::refusing(|item| match item {
            Item::Meta { name, entries } => st.meta(name, entries),
            Item::Message { topic, data, .. } => {
                if st.procedure.is_none() && topic != topics::EVENTS {
                    return Err(
                        st.log_err("messages before the run metadata; is this a gyrobench log?")
                    );
                }
                st.message(topic, data)
            }
            Item::Attachment { .. } => Ok(()),
        }),
    )?;
    if let Some(p) = st.pending_power.take() {
        st.records.push_power(p, None);
    }
    let log_err = |message: String| ReplayError::Log {
        path: path.display().to_string(),
        message,
    };
    if let Some(why) = read.stopped.as_ref().filter(|_| read.complete) {
        return Err(log_err(why.clone()));
    }
    let (Some(procedure), Some(meta)) = (st.procedure.take(), st.meta.take()) else {
        // `--unit` naming a unit the log lacks stopped the read: say so.
        if let (Some(why), Some(_)) = (&read.stopped, unit) {
            return Err(log_err(why.clone()));
        }
        return Err(log_err(format!(
            "no run metadata (procedure, bench) in the log{}; is this a gyrobench log?",
            read.trouble()
        )));
    };
    let last_state_s = st.table.map_or(0.0, |t| t.t_s);
    let ended = st.result_meta.is_some();
    let end_time_utc = st.result_meta.as_ref().and_then(|r| r.end_time_utc.clone());
    let end = st.ending(&read, last_state_s);
    // Damaged parts skipped: what the log still holds is replayed, but the
    // run cannot be judged on a log with holes.
    let (outcome, error) = with_damage(&read, meta.part_start_ns(), end.outcome, end.error);
    let (cleanup_completed, device_time_s, bench_left) =
        (end.cleanup_completed, end.device_time_s, end.bench_left);
    let link = match &st.earlier {
        Some(e) => add_link(&e.link, &st.link),
        None => st.link,
    };
    let part = st.earlier.as_ref().map_or(1, |e| e.part + 1);
    Ok(Replayed {
        meta,
        procedure,
        result: RunResult {
            outcome,
            measurements: st.measurements,
            error,
            cleanup_completed,
            device_time_s,
            frames: st.frames,
            records: st.records,
            bench_left,
            others: Vec::new(),
        },
        link,
        read,
        last_state_s,
        completed_steps: st.completed,
        part,
        ended,
        end_time_utc,
        poses: st.poses,
    })
}

/// How a replayed run ended, before the log's damage is weighed.
struct Ending {
    outcome: Outcome,
    error: Option<RunError>,
    cleanup_completed: bool,
    device_time_s: f64,
    bench_left: Option<crate::sequencer::BenchLeft>,
}

/// The outcome and error of a run whose log is damaged from `start_ns`
/// on: an error that says so (the damage comes first: the frames a record
/// misses are the log's holes, not the gyro's, whatever else the run said
/// of itself); else the run's own.
fn with_damage(
    read: &ReadSummary,
    start_ns: Option<u64>,
    outcome: Outcome,
    error: Option<RunError>,
) -> (Outcome, Option<RunError>) {
    match read.damage(start_ns) {
        Some(d) => (
            Outcome::Error,
            Some(RunError {
                device: None,
                step: "log".into(),
                message: format!(
                    "the log is damaged: {d}; its figures lack those messages{}",
                    error.map_or(String::new(), |e| format!(" (the run said: {})", e.message))
                ),
            }),
        ),
        None => (outcome, error),
    }
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
        reconnects: a.reconnects + b.reconnects,
        longest_gap_ms: a.longest_gap_ms.max(b.longest_gap_ms),
    }
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
    /// How the read of the log went (complete or truncated).
    pub read: ReadSummary,
    /// The run's start in log time, ns (to place damaged parts in it).
    pub start_ns: Option<u64>,
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
    record_rates_unit(path, label, None)
}

/// [`record_rates`] of unit `unit` (a serial) of a batch's log.
pub fn record_rates_unit(
    path: &Path,
    label: Option<&str>,
    unit: Option<&str>,
) -> Result<RecordRates, ReplayError> {
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
        read: ReadSummary::default(),
        start_ns: None,
    };
    let read = super::view::read_unit(
        path,
        unit,
        super::refusing(|item| {
            match item {
                Item::Meta { name, entries } if name == RUN_META => {
                    out.start_ns = out
                        .start_ns
                        .or_else(|| super::recover::part_start_ns(entries));
                    // The procedure as logged, checked against the logged bench.
                    let meta = RunMeta::from_entries(entries).map_err(|e| e.to_string())?;
                    if let Ok(Logged { procedure: p, .. }) = logged(&meta) {
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
                    pending = Some(
                        serde_json::from_slice(data)
                            .map_err(|e| format!("a {topic} message does not parse: {e}"))?,
                    );
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
            Ok::<(), String>(())
        }),
    )?;
    if let Some(why) = read.stopped.as_ref().filter(|_| read.complete) {
        return Err(log_err(why.clone()));
    }
    let stopped = read.trouble();
    out.read = read;
    let Some(want) = want else {
        return Err(log_err(format!(
            "the log has no record steps to analyse{stopped}"
        )));
    };
    if out.rate_dph.is_empty() {
        return Err(log_err(format!(
            "no frames recorded under `{want}`{stopped}; records in this log: {}",
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
