//! A run from its start to its report, as `run` and `run --resume` drive
//! it: the run directory (new, locked), the log's metadata, the bench
//! (embedded or real drivers, behind the limits guard), the sequencer,
//! the end of the log and the report. `import` and `twin study` share the
//! pieces they need (the run id, the embedded bench).

pub mod benchlock;
pub mod rundir;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::bench::{BenchConfig, open_bench};
use crate::clock::{Pacing, VirtualClock, utc_now};
use crate::coeffs::Chosen;
use crate::procedure::Procedure;
use crate::procedure::estimate::min_total_s;
use crate::protocol::frame::LinkStats;
use crate::report::{Report, render_html};
use crate::runlog::meta::{ResultMeta, RunMeta};
use crate::runlog::replay::{
    ReplayError, add_link, logged, replay, replay_unit, resume_batch_from,
};
use crate::runlog::schema::FORMAT;
use crate::runlog::writer::{FrameScales, Recorder};
use crate::sequencer::device::DeviceBench;
use crate::sequencer::guard::Guarded;
use crate::sequencer::{
    self, BenchIo, Event, Interrupt, Observer, Operator, Options, Resume, RunResult,
};
use crate::sim::embedded::{EmbeddedBench, Fault};
use crate::twin::TwinConfig;
use rundir::{RunDir, RunDirError};

/// Why a run could not start or end properly.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The run directory cannot be used.
    #[error(transparent)]
    RunDir(#[from] RunDirError),
    /// The bench is in use by another run (or cannot be locked).
    #[error(transparent)]
    BenchLock(#[from] benchlock::BenchLockError),
    /// The run to resume cannot be read.
    #[error("reading the run to resume")]
    Replay(#[from] ReplayError),
    /// The run to resume cannot be resumed.
    #[error("{0}")]
    NotResumable(String),
    /// The bench is not usable for this plan.
    #[error("{0}")]
    Bench(String),
    /// A device failed before the run started.
    #[error("bringing up the bench of {bench}")]
    Device {
        /// The bench file, as the operator named it.
        bench: String,
        /// What the device did.
        #[source]
        source: crate::driver::DeviceError,
    },
    /// An instrument is past its calibration due date and the bench
    /// refuses such runs.
    #[error(
        "{instruments} past the calibration due date in {bench}; the bench's overdue_calibration = \"refuse\" does not start a run (calibrate the instrument and update calibration_due)"
    )]
    CalibrationOverdue {
        /// The instruments with their due dates.
        instruments: String,
        /// The bench file.
        bench: String,
    },
    /// A file could not be written.
    #[error("{what} {path}: {cause}")]
    Io {
        /// What was being done.
        what: &'static str,
        /// The file.
        path: String,
        /// Cause.
        #[source]
        cause: std::io::Error,
    },
}

/// A fresh run id: 16 random bytes in hex, the same in every part.
pub fn new_run_id() -> String {
    let bytes: [u8; 16] = rand::random();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// What a run (or a resumed part of one) works with.
#[derive(Debug)]
pub struct Plan {
    /// The validated procedure.
    procedure: Procedure,
    /// Where it was read from.
    procedure_path: String,
    /// The bench.
    bench_cfg: BenchConfig,
    /// The bench as named to the operator (`embedded` or the file).
    bench_label: String,
    /// Twin of the embedded bench.
    twin: TwinConfig,
    /// Coefficients to compensate with (none: model 4 fitted on the run's
    /// own records).
    coeffs: Option<Chosen>,
    /// The run's seed; a resumed part seeds its twin with
    /// `seed + part - 1` (a new power-on, fresh noise).
    seed: u64,
    /// Serial number of the unit.
    dut: String,
    /// Who runs it.
    operator: String,
    /// The bench PC it runs on (its host name, or `[results] station`).
    station: String,
    /// Where its results are recorded.
    store: crate::results::Location,
    /// `max` or a factor (logged as given).
    speed: String,
    /// Pacing of the embedded bench.
    pacing: Pacing,
    /// Faults the embedded bench plays.
    faults: Vec<(f64, Fault)>,
    /// The earlier parts, when this continues a run.
    resume: Option<Resumed>,
    /// Where the run's channels are also published live (`run --live`,
    /// the station).
    live: Option<Arc<crate::runlog::live::Live>>,
    /// A batch's units, in the bench's slot order (empty: the one unit
    /// `dut` of a bench without slots). The first is `dut`.
    batch: Vec<BatchUnit>,
}

/// One unit of a batch: the slot it sits in and its serial.
#[derive(Debug, Clone)]
pub struct BatchUnit {
    /// Its slot on the bench.
    pub slot: crate::bench::Slot,
    /// The slot's place in the bench's `[[slots]]` (its default seed is
    /// the run's plus this).
    pub index: usize,
    /// Its serial.
    pub serial: String,
    /// The embedded bench: the slot's own twin (none: the run's).
    pub twin: Option<TwinConfig>,
}

impl BatchUnit {
    /// Its twin's seed on the embedded bench in a run seeded `run_seed`:
    /// its slot's, or the run's plus the slot's index.
    pub fn seed(&self, run_seed: u64) -> u64 {
        self.slot
            .seed
            .unwrap_or_else(|| run_seed.wrapping_add(self.index as u64))
    }
}

/// A batch's units on `bench` (its file at `bench_path`, whose directory
/// slot twin files are read from) from `(slot, serial)` pairs, in the
/// bench's slot order; the error names the pair at fault (its index in
/// `given`) and what is wrong. Slots not given stay empty.
pub fn batch_units(
    bench: &BenchConfig,
    bench_path: Option<&Path>,
    given: &[(String, String)],
) -> Result<Vec<BatchUnit>, (usize, String)> {
    let names = bench.slot_names();
    let mut taken: Vec<(usize, usize)> = Vec::new();
    for (at, (slot, serial)) in given.iter().enumerate() {
        let Some(index) = bench.slots.iter().position(|s| s.name == *slot) else {
            return Err((
                at,
                format!("the bench has no slot {slot:?} (its slots: {names})"),
            ));
        };
        crate::unit::check_serial(serial).map_err(|e| (at, e.to_string()))?;
        if taken.iter().any(|(i, _)| *i == index) {
            return Err((at, format!("slot {slot} is given twice")));
        }
        if taken.iter().any(|(_, g)| given[*g].1 == *serial) {
            return Err((at, format!("unit {serial} is given for two slots")));
        }
        // Each unit's report is named by its serial as a file name.
        if let Some((_, g)) = taken
            .iter()
            .find(|(_, g)| crate::unit::same_report_file(&given[*g].1, serial))
        {
            return Err((
                at,
                format!(
                    "units {} and {serial} would share one report file ({}.html): their serials differ only in letter case or in characters a file name cannot hold; give each unit its own serial",
                    given[*g].1,
                    crate::unit::report_name(serial)
                ),
            ));
        }
        taken.push((index, at));
    }
    taken.sort_by_key(|(i, _)| *i);
    let dir = bench_path
        .and_then(Path::parent)
        .unwrap_or_else(|| Path::new("."));
    taken
        .into_iter()
        .map(|(index, at)| {
            let slot = bench.slots[index].clone();
            let twin = match &slot.twin {
                Some(t) => Some(TwinConfig::load(&dir.join(t)).map_err(|e| {
                    (
                        at,
                        format!("loading the twin file of slot {}: {e}", slot.name),
                    )
                })?),
                None => None,
            };
            Ok(BatchUnit {
                slot,
                index,
                serial: given[at].1.clone(),
                twin,
            })
        })
        .collect()
}

impl Plan {
    /// A new run of `procedure` (read from `procedure_path`) on the bench
    /// `bench_cfg`: named `embedded` to the operator, for the simulated
    /// bench's unnamed unit, no operator, its results recorded nowhere, on
    /// the embedded twin, seed 1, no coefficients (model 4 fitted on the
    /// run's own records), at full speed, no faults, not published live.
    /// The CLI and the station both start here; the `with_` methods set
    /// the rest by name.
    pub fn new(
        procedure: Procedure,
        procedure_path: impl Into<String>,
        bench_cfg: BenchConfig,
    ) -> Self {
        Self {
            station: station(&bench_cfg),
            procedure,
            procedure_path: procedure_path.into(),
            bench_cfg,
            bench_label: "embedded".into(),
            twin: TwinConfig::default_rl16(),
            coeffs: None,
            seed: 1,
            dut: crate::unit::SIMULATED_SERIAL.into(),
            operator: String::new(),
            store: crate::results::Location::Off,
            speed: "max".into(),
            pacing: Pacing::Max,
            faults: Vec::new(),
            resume: None,
            live: None,
            batch: Vec::new(),
        }
    }

    /// The bench as named to the operator (`embedded`, or its file).
    #[must_use]
    pub fn with_bench_label(self, bench_label: impl Into<String>) -> Self {
        Self {
            bench_label: bench_label.into(),
            ..self
        }
    }

    /// Where its results are recorded.
    #[must_use]
    pub fn with_store(self, store: crate::results::Location) -> Self {
        Self { store, ..self }
    }

    /// The unit's serial number (a batch: [`Plan::with_batch`]).
    #[must_use]
    pub fn with_dut(self, dut: impl Into<String>) -> Self {
        Self {
            dut: dut.into(),
            ..self
        }
    }

    /// Who runs it.
    #[must_use]
    pub fn with_operator(self, operator: impl Into<String>) -> Self {
        Self {
            operator: operator.into(),
            ..self
        }
    }

    /// The validated procedure.
    pub fn procedure(&self) -> &Procedure {
        &self.procedure
    }

    /// Where the procedure was read from.
    pub fn procedure_path(&self) -> &str {
        &self.procedure_path
    }

    /// The bench.
    pub fn bench(&self) -> &BenchConfig {
        &self.bench_cfg
    }

    /// The unit's serial (a batch: its first unit's).
    pub fn dut(&self) -> &str {
        &self.dut
    }

    /// Who runs it.
    pub fn operator(&self) -> &str {
        &self.operator
    }

    /// A batch's units, in the bench's slot order (empty: one unit).
    pub fn batch(&self) -> &[BatchUnit] {
        &self.batch
    }

    /// The earlier parts, when this continues a run.
    pub fn resumed(&self) -> Option<&Resumed> {
        self.resume.as_ref()
    }

    /// Run `units` as a batch (the first is the plan's `dut`).
    #[must_use]
    pub fn with_batch(mut self, units: Vec<BatchUnit>) -> Self {
        if let Some(first) = units.first() {
            self.dut = first.serial.clone();
        }
        self.batch = units;
        self
    }

    /// Unit `k`'s twin on the embedded bench, standing at the bench's site
    /// in its slot, and its seed for `part`.
    fn unit_twin(&self, k: usize, part: u32) -> (TwinConfig, u64) {
        let u = self.batch.get(k);
        // The bench is one: a slot's own twin gives its unit; the
        // chamber, the table and the gyro links are the run's.
        let mut twin = u
            .and_then(|u| u.twin.clone())
            .unwrap_or_else(|| self.twin.clone())
            .on_bench_of(&self.twin);
        twin.site = self.bench_cfg.site;
        twin.table.geometry = match u {
            Some(u) => self.bench_cfg.slot_geometry(&u.slot),
            None => self.bench_cfg.table.geometry,
        };
        let seed = u.map_or(self.seed, |u| u.seed(self.seed));
        (twin, seed.wrapping_add(u64::from(part) - 1))
    }

    /// The embedded bench's twin.
    #[must_use]
    pub fn with_twin(self, twin: TwinConfig) -> Self {
        Self { twin, ..self }
    }

    /// The coefficients to compensate with (none: fitted on the run).
    #[must_use]
    pub fn with_coeffs(self, coeffs: Option<Chosen>) -> Self {
        Self { coeffs, ..self }
    }

    /// The run's seed.
    #[must_use]
    pub fn with_seed(self, seed: u64) -> Self {
        Self { seed, ..self }
    }

    /// The pace of the embedded bench, and the `speed` as given (logged).
    #[must_use]
    pub fn with_speed(self, speed: impl Into<String>, pacing: Pacing) -> Self {
        Self {
            speed: speed.into(),
            pacing,
            ..self
        }
    }

    /// Faults the embedded bench plays, at device times.
    #[must_use]
    pub fn with_faults(self, faults: Vec<(f64, Fault)>) -> Self {
        Self { faults, ..self }
    }

    /// Publish the run's channels live too.
    #[must_use]
    pub fn with_live(self, live: Option<Arc<crate::runlog::live::Live>>) -> Self {
        Self { live, ..self }
    }
}

/// What the earlier parts of a resumed run leave.
#[derive(Debug)]
pub struct Resumed {
    /// The run's id (empty for a format 1 run).
    pub run_id: String,
    /// UTC start of the first part.
    pub start_time_utc: String,
    /// Where to pick up and what the parts made.
    pub state: Resume,
    /// File name of the last part.
    pub previous_file: String,
    /// Link figures of the earlier parts.
    pub link: LinkStats,
    /// A batch's other units' link figures of the earlier parts (in unit
    /// order).
    pub unit_links: Vec<LinkStats>,
    /// A summary line for the operator.
    pub summary: String,
}

/// Where the run's directory goes.
#[derive(Debug)]
pub enum Place {
    /// `base/<procedure>-<UTC time>`, made unique.
    Auto {
        /// The directory runs go in (`runs`).
        base: PathBuf,
    },
    /// A directory the operator chose.
    At {
        /// The directory.
        path: PathBuf,
        /// Move a run already there aside instead of refusing.
        force: bool,
    },
    /// The directory of the run being resumed, locked before its log was
    /// read ([`lock_for_resume`]).
    Resume(RunDir),
}

/// Lock the run directory `dir` to resume the run in it: taken before its
/// log is read, so two resumes of one run cannot both go on.
pub fn lock_for_resume(dir: &Path) -> Result<RunDir, SessionError> {
    Ok(RunDir::open_existing(dir, &utc_now().to_rfc3339())?)
}

/// The newest part of the run in `dir`: `run.mcap`, `run.part2.mcap`, ...
pub fn last_part(dir: &Path) -> Result<PathBuf, SessionError> {
    let first = dir.join("run.mcap");
    if !first.exists() {
        return Err(SessionError::NotResumable(format!(
            "{} holds no run.mcap: not a run directory",
            dir.display()
        )));
    }
    let mut n = 1;
    while dir.join(format!("run.part{}.mcap", n + 1)).exists() {
        n += 1;
    }
    Ok(if n == 1 {
        first
    } else {
        dir.join(format!("run.part{n}.mcap"))
    })
}

/// The station name a bench records its runs under.
pub fn station(bench: &BenchConfig) -> String {
    bench
        .results
        .as_ref()
        .and_then(|r| r.station.clone())
        .unwrap_or_else(rundir::hostname)
}

/// The plan that continues the interrupted run in `dir` from its last
/// completed step, everything (procedure, bench, twin, coefficients, seed,
/// unit) as its log says; its results go to `store` (resolved against the
/// logged bench's `[results]` when not given).
pub fn plan_resume(
    dir: &Path,
    pacing: Pacing,
    speed: &str,
    store: Option<&str>,
) -> Result<Plan, SessionError> {
    let last = last_part(dir)?;
    let prev = replay(&last, None)?;
    // A batch: each other unit as its own view of the log replays it, and
    // the batch resumes when any unit of it was cut short.
    let others = prev
        .meta
        .units
        .iter()
        .skip(1)
        .map(|u| replay_unit(&last, None, Some(&u.serial)))
        .collect::<Result<Vec<_>, _>>()?;
    let units = || std::iter::once(&prev).chain(&others);
    if !units().any(|u| {
        matches!(
            u.result.outcome,
            sequencer::Outcome::Error | sequencer::Outcome::Aborted
        )
    }) {
        return Err(SessionError::NotResumable(format!(
            "the run in {} finished (outcome {}); there is nothing to resume",
            dir.display(),
            prev.result.outcome.as_str()
        )));
    }
    let config = logged(&prev.meta)
        .map_err(|e| SessionError::NotResumable(format!("{}: {e}", last.display())))?;
    let completed = steps_to_keep(dir, &prev, &others)?;
    let state = resume_batch_from(&prev, &others, completed);
    let summary = resume_summary(dir, &last, &prev, completed);
    let meta = &prev.meta;
    let seed = match (meta.seed, config.bench.is_embedded()) {
        (Some(s), _) => s,
        (None, false) => 0,
        (None, true) => {
            return Err(SessionError::NotResumable(format!(
                "{}: the log of a simulated run names no seed; it cannot be continued with the same unit",
                last.display()
            )));
        }
    };
    let store = crate::results::Location::resolve(
        store,
        config.bench.results.as_ref().and_then(|r| r.db.as_deref()),
    );
    // The coefficients the run compensated with, as its log holds them.
    let coeffs = match (&meta.coeffs_toml, config.coeffs) {
        (Some(text), Some(set)) => Some(Chosen {
            set,
            text: text.clone(),
            used: meta
                .unit()
                .map_or_else(crate::coeffs::CoeffsUsed::fitted, |u| {
                    u.coefficients.clone()
                }),
        }),
        _ => None,
    };
    let mut plan = Plan::new(
        prev.procedure.clone(),
        meta.procedure_path.clone(),
        config.bench,
    )
    .with_bench_label(meta.bench.clone())
    .with_store(store)
    .with_dut(meta.dut_serial.clone())
    .with_operator(meta.operator.clone())
    .with_twin(config.twin.unwrap_or_else(TwinConfig::default_rl16))
    .with_coeffs(coeffs)
    .with_seed(seed)
    .with_speed(speed, pacing);
    // The run stays on the bench PC its log names.
    if !meta.station.is_empty() {
        plan.station = meta.station.clone();
    }
    if meta.is_batch() {
        let batch = logged_batch(&plan.bench_cfg, meta, &last)?;
        plan = plan.with_batch(batch);
    }
    plan.resume = Some(Resumed {
        run_id: meta.run_id.clone(),
        start_time_utc: meta.start_time_utc.clone(),
        state,
        previous_file: last
            .file_name()
            .map_or(String::new(), |f| f.to_string_lossy().into_owned()),
        link: prev.link,
        unit_links: others.iter().map(|o| o.link).collect(),
        summary,
    });
    Ok(plan)
}

/// `resuming DIR (its last part LOG ended: WHY): what is taken again`.
fn resume_summary(
    dir: &Path,
    last: &Path,
    prev: &crate::runlog::replay::Replayed,
    completed: usize,
) -> String {
    format!(
        "resuming {} (its last part {} ended: {}): {}",
        dir.display(),
        last.display(),
        prev.result
            .error
            .as_ref()
            .map_or("-".to_owned(), |e| format!(
                "{} in step {}",
                e.message, e.step
            )),
        crate::sequencer::resume::describe_resume(&prev.procedure, completed)
    )
}

/// How many of the run's steps a resume keeps: those its last part
/// completed, or, when every step ran, those before the first record that
/// must be taken again.
fn steps_to_keep(
    dir: &Path,
    prev: &crate::runlog::replay::Replayed,
    others: &[crate::runlog::replay::Replayed],
) -> Result<usize, SessionError> {
    let units = || std::iter::once(prev).chain(others);
    let steps = prev.procedure.setup.len() + prev.procedure.main.len();
    if prev.completed_steps < steps {
        return Ok(prev.completed_steps);
    }
    // Every step ran but a record could not be judged (a link that lost
    // frames, a stuck output): take it again, from its thermal segment as
    // after any break. A log cut short after its last step (the disk
    // filled, or the process ended, before the end record) cannot stand as
    // the run's record: its last record is taken again, so the run ends on
    // a log that says how it ended.
    units()
        .filter_map(first_unsound_record)
        .min()
        .or_else(|| (!prev.ended).then(|| last_record(&prev.procedure)).flatten())
        .ok_or_else(|| {
            SessionError::NotResumable(format!(
                "every step of the run in {} completed; it ended in error ({}), which no step taken again would change",
                dir.display(),
                units()
                    .find_map(|u| u.result.error.as_ref())
                    .map_or("-".to_owned(), |e| e.message.clone())
            ))
        })
}

/// A logged batch's units again, on the logged bench: each in its slot
/// (by name), with its own twin as logged.
fn logged_batch(
    bench: &BenchConfig,
    meta: &RunMeta,
    log: &Path,
) -> Result<Vec<BatchUnit>, SessionError> {
    let bad = |why: String| SessionError::NotResumable(format!("{}: {why}", log.display()));
    meta.units
        .iter()
        .map(|u| {
            let index = bench
                .slots
                .iter()
                .position(|s| s.name == u.slot)
                .ok_or_else(|| bad(format!("its bench has no slot {:?}", u.slot)))?;
            if bench.slots[index].twin.is_some() && u.twin_toml.is_none() {
                return Err(bad(format!(
                    "slot {} has its own twin file, and the log does not hold it: the same unit cannot be simulated again",
                    u.slot
                )));
            }
            let twin = match &u.twin_toml {
                Some(text) => Some(
                    TwinConfig::from_source(&crate::config::Source::from_text(
                        &format!("the logged twin of slot {}", u.slot),
                        text,
                    ))
                    .map_err(|e| bad(e.to_string()))?,
                ),
                None => None,
            };
            Ok(BatchUnit {
                slot: bench.slots[index].clone(),
                index,
                serial: u.serial.clone(),
                twin,
            })
        })
        .collect()
}

/// Run-order index of the procedure's last record step.
fn last_record(procedure: &crate::procedure::Procedure) -> Option<usize> {
    procedure
        .setup
        .iter()
        .chain(&procedure.main)
        .enumerate()
        .filter(|(_, s)| matches!(s.kind, crate::procedure::StepKind::Record { .. }))
        .map(|(i, _)| i)
        .last()
}

/// Run-order index of the first record whose data could not be judged.
fn first_unsound_record(prev: &crate::runlog::replay::Replayed) -> Option<usize> {
    prev.procedure
        .setup
        .iter()
        .chain(&prev.procedure.main)
        .position(|s| match &s.kind {
            crate::procedure::StepKind::Record { label, .. } => prev
                .result
                .records
                .health(label)
                .and_then(crate::sequencer::health::RecordHealth::problem)
                .is_some(),
            _ => false,
        })
}

/// How a run ended, with where its files are.
#[derive(Debug)]
pub struct Finished {
    /// The run directory.
    pub dir: PathBuf,
    /// The log of this part.
    pub log: PathBuf,
    /// The report (also written as report.json and report.html unless
    /// `report_error` says why not).
    pub report: Report,
    /// The run's result.
    pub result: RunResult,
    /// Why the report files could not be written, if they could not.
    pub report_error: Option<String>,
    /// Things the operator should know (a stale lock taken over, a run
    /// moved aside, an incomplete log).
    pub notes: Vec<String>,
    /// How many of `notes` were given with [`Event::Begin`] already.
    pub notes_at_begin: usize,
    /// A batch's units, each with its report (empty: one unit, `report`).
    pub units: Vec<FinishedUnit>,
}

/// One unit of a batch at the end of its run.
#[derive(Debug, Clone)]
pub struct FinishedUnit {
    /// Its slot.
    pub slot: String,
    /// Its serial.
    pub serial: String,
    /// Its report.
    pub report: Report,
    /// Its report files' name without the extension (`report-SERIAL`).
    pub file: String,
}

/// Longest a table move may take before it is a failure, s.
pub const MOVE_TIMEOUT_S: f64 = 600.0;

/// The sequencer's options for a run on `bench`.
pub fn options(
    procedure: &Procedure,
    bench: &BenchConfig,
    coeffs: Option<crate::coeffs::Compensation>,
    interrupt: Arc<Interrupt>,
    resume: Option<Resume>,
) -> Options {
    Options {
        judging: crate::sequencer::measure::Judging::new(
            procedure,
            bench,
            crate::runlog::schema::FORMAT,
        ),
        coeffs,
        interrupt,
        dut_max_c: bench.limits.dut_max_c,
        in_position: (
            bench.devices.table.in_position_deg,
            bench.devices.table.settle_s,
        ),
        move_timeout_s: MOVE_TIMEOUT_S,
        resume,
        supply_safe_on: bench
            .devices
            .supply
            .as_ref()
            .is_some_and(|p| p.safe_state == crate::bench::SupplySafe::On),
        units: Vec::new(),
        stop_on_unit_error: bench.on_unit_error == crate::bench::OnUnitError::Stop,
        supply: bench.devices.supply.as_ref().map(|p| (p.volts, p.limit_a)),
        part_start_utc: None,
    }
}

/// The embedded simulated bench for `twin` (guarded by `limits`).
pub fn embedded_bench(
    twin: &TwinConfig,
    seed: u64,
    pacing: Pacing,
    faults: &[(f64, Fault)],
    limits: crate::bench::Limits,
    supply: Option<&crate::bench::SupplyDevice>,
) -> Guarded<EmbeddedBench> {
    let clock = Arc::new(VirtualClock::new(pacing));
    let mut b = EmbeddedBench::new(twin.clone(), seed, clock);
    if let Some(p) = supply {
        b = b.with_supply(p);
    }
    for (at, f) in faults {
        b.schedule(*at, *f);
    }
    Guarded::new(b, limits).with_supply(supply)
}

fn io_err(what: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> SessionError {
    let path = path.display().to_string();
    move |cause| SessionError::Io { what, path, cause }
}

/// Refuse to start when the bench says so (`overdue_calibration =
/// "refuse"`) and an instrument is past its calibration due date on
/// `today`.
pub fn check_calibration(
    bench: &BenchConfig,
    bench_label: &str,
    today: chrono::NaiveDate,
) -> Result<(), SessionError> {
    if bench.overdue_calibration != crate::bench::OverduePolicy::Refuse {
        return Ok(());
    }
    let d = &bench.devices;
    let overdue: Vec<String> = [
        ("the chamber", d.chamber.calibration_due),
        ("the table", d.table.calibration_due),
    ]
    .iter()
    .filter_map(|(who, due)| {
        due.filter(|due| today > due.0)
            .map(|due| format!("{who} (due {due})"))
    })
    .collect();
    if overdue.is_empty() {
        return Ok(());
    }
    Err(SessionError::CalibrationOverdue {
        instruments: overdue.join(" and "),
        bench: bench_label.to_owned(),
    })
}

/// Run `plan` in `place` on the async runtime `rt`; `interrupt` stops it
/// (cleanup still runs).
pub fn execute(
    plan: Plan,
    place: Place,
    rt: &tokio::runtime::Runtime,
    progress: &mut dyn Operator,
    interrupt: Arc<Interrupt>,
) -> Result<Finished, SessionError> {
    let today = utc_now().date_naive();
    check_plan(&plan, today)?;
    let part = plan.resume.as_ref().map_or(1, |r| r.state.part);
    let start = utc_now();
    let run_start = plan
        .resume
        .as_ref()
        .map_or_else(|| start.to_rfc3339(), |r| r.start_time_utc.clone());
    // The bench before its run directory: a run refused for a bench in
    // use leaves nothing behind.
    let mut bench_lock = lock_bench(&plan, &run_start)?;
    let (dir, mut notes) = open_run_dir(place, &plan.procedure.meta.name, &start)?;
    bench_lock.set_run_dir(&dir.path);

    let mut bench = bench_for(&plan, part, rt)?;
    let (meta, log, mut recorder) = open_log(
        &plan,
        (part, &run_start, &start, today),
        &dir.path,
        bench.as_mut(),
        rt,
    )?;

    let mut store = StoreLink::open(&plan.store, &meta, &log, &mut notes);
    let _ = progress.observe(&Event::Begin {
        dir: &dir.path,
        notes: &notes,
    });
    let notes_at_begin = notes.len();
    let mut opts = options(
        &plan.procedure,
        &plan.bench_cfg,
        plan.coeffs.as_ref().and_then(Chosen::compensation),
        interrupt,
        plan.resume.as_ref().map(|r| r.state.clone()),
    );
    opts.part_start_utc = Some(start);
    opts.units = plan
        .batch
        .iter()
        .map(|u| format!("slot {} ({})", u.slot.name, u.serial))
        .collect();
    let result = run_guarded(&plan, rt, bench.as_mut(), &mut recorder, progress, &opts);
    let (part_link, part_slot_links) = part_links(bench.as_ref(), meta.units.len());
    let unit_links = unit_links(plan.resume.as_ref(), &part_link, &part_slot_links);
    let link = unit_links.first().copied().unwrap_or_default();
    let finish = |result: &RunResult, k: usize| {
        let link = unit_links.get(k).copied().unwrap_or_default();
        Report::new(&plan.procedure, &result.unit(k), &meta.for_unit(k), link)
    };
    let end_s = bench.now_s();
    // One end time, stated in the log and recorded in the store alike.
    let ended_utc = utc_now().to_rfc3339();
    let (result, reports) = close_log(
        recorder,
        &log,
        result,
        &meta,
        finish,
        (end_s, &ended_utc, &part_link, &part_slot_links),
        &mut notes,
    );
    let (report_error, units) = write_reports(&dir.path, &meta, &result, &reports);
    let report = reports
        .into_iter()
        .next()
        .unwrap_or_else(|| finish(&result, 0));
    store.finish(&log, &result, link, &ended_utc, &mut notes);
    Ok(Finished {
        dir: dir.path.clone(),
        log,
        report,
        result,
        report_error,
        notes,
        notes_at_begin,
        units,
    })
}

/// The run's log, created: its metadata (`part` of the run started at
/// `run_start`, this part at `start`, instruments due on `today`) with
/// the bench's identities and the run's twin as the bench stands it, its
/// path in `dir`, and its recorder (live stream and disk faults set).
fn open_log(
    plan: &Plan,
    (part, run_start, start, today): (u32, &str, &chrono::DateTime<chrono::Utc>, chrono::NaiveDate),
    dir: &Path,
    bench: &mut dyn BenchIo,
    rt: &tokio::runtime::Runtime,
) -> Result<(RunMeta, PathBuf, Recorder), SessionError> {
    // The embedded bench simulates the bench its file describes: the twin
    // stands at the bench's site on the bench's table (a lab's simulated
    // bench near the equator has its own latitude and its table turned).
    // The run's twin as the bench stands it (a batch's units' own twins
    // are logged with each unit).
    let mut twin = plan.twin.clone();
    twin.site = plan.bench_cfg.site;
    twin.table.geometry = plan.bench_cfg.table.geometry;
    let identities = rt.block_on(bench.identify());
    let instruments = plan.bench_cfg.instruments(
        identities.chamber,
        identities.table,
        identities.supply,
        today,
    );
    let meta = run_meta(plan, &twin, part, run_start, start, instruments)?;
    let log = if part == 1 {
        dir.join("run.mcap")
    } else {
        dir.join(format!("run.part{part}.mcap"))
    };
    let start_ns = start.timestamp_nanos_opt().unwrap_or(0).max(0) as u64;
    let scales = FrameScales {
        dt_s: bench.frame_dt_s(),
        lsb_arcsec: bench.lsb_arcsec(),
        temp_lsb_c: bench.temp_lsb_c(),
    };
    let mut recorder = Recorder::create(&log, &meta, start_ns, scales)
        .map_err(io_err("creating the log", &log))?;
    if let Some(live) = &plan.live {
        recorder.publish_live(live.clone());
    }
    for (at, f) in &plan.faults {
        if *f == Fault::DiskFull {
            recorder.fill_disk_at(*at);
        }
    }
    Ok((meta, log, recorder))
}

/// Run the procedure on `bench` into `recorder`. A bug that panics
/// mid-run must not leave the bench where it was: the panic is caught,
/// the bench brought to its safe state and read back, and the run ends as
/// an error with everything logged kept.
fn run_guarded(
    plan: &Plan,
    rt: &tokio::runtime::Runtime,
    bench: &mut dyn BenchIo,
    recorder: &mut Recorder,
    progress: &mut dyn Operator,
    opts: &sequencer::Options,
) -> RunResult {
    let ran = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        rt.block_on(sequencer::run(
            &plan.procedure,
            &mut *bench,
            &mut *recorder,
            progress,
            opts,
        ))
    }));
    match ran {
        Ok(r) => r,
        Err(panic) => rt.block_on(after_panic(
            bench,
            recorder,
            &panic_text(panic.as_ref()),
            plan.bench_cfg.devices.table.in_position_deg,
            opts.supply_safe_on,
        )),
    }
}

/// Every unit's link figures of this part (the first unit's, then a
/// batch's others'), read once: a real link goes on counting the frames
/// that still come, and the log and the reports must give the same.
fn part_links(bench: &dyn BenchIo, units: usize) -> (LinkStats, Vec<LinkStats>) {
    (
        bench.link_stats(),
        (1..units).map(|k| bench.slot_link_stats(k)).collect(),
    )
}

/// Every unit's link figures over the whole run: this part's, with the
/// earlier parts' of a resumed run (what the reports give).
fn unit_links(resume: Option<&Resumed>, first: &LinkStats, others: &[LinkStats]) -> Vec<LinkStats> {
    let whole = |earlier: Option<LinkStats>, part: &LinkStats| match resume {
        Some(_) => add_link(&earlier.unwrap_or_default(), part),
        None => *part,
    };
    std::iter::once(whole(resume.map(|r| r.link), first))
        .chain(
            others
                .iter()
                .enumerate()
                .map(|(i, part)| whole(resume.and_then(|r| r.unit_links.get(i).copied()), part)),
        )
        .collect()
}

/// Write the link's last figures and the result into the log and close
/// it; every unit's report (one for a run of one unit). A log that cannot
/// be completed keeps what reached
/// the disk, makes the run an error and tells how to recover it.
fn close_log(
    mut recorder: Recorder,
    log: &std::path::Path,
    mut result: RunResult,
    meta: &RunMeta,
    report_of: impl Fn(&RunResult, usize) -> Report,
    (end_s, ended_utc, part_link, slot_links): (f64, &str, &LinkStats, &[LinkStats]),
    notes: &mut Vec<String>,
) -> (RunResult, Vec<Report>) {
    let reports_of = |result: &RunResult| {
        (0..result.units())
            .map(|k| report_of(result, k))
            .collect::<Vec<_>>()
    };
    let reports = reports_of(&result);
    let log_end = recorder
        .link(end_s, part_link)
        .and_then(|()| {
            slot_links
                .iter()
                .enumerate()
                .try_for_each(|(i, l)| recorder.slot_link(i + 1, end_s, l))
        })
        .and_then(|()| {
            // A batch's other units: each one's result and report.
            meta.units
                .iter()
                .zip(&reports)
                .enumerate()
                .skip(1)
                .try_for_each(|(k, (u, r))| {
                    recorder.unit_result(
                        &u.slot,
                        &u.serial,
                        &ResultMeta::from(&result.unit(k)).ended_at(ended_utc),
                        &r.to_json(),
                        end_s,
                    )
                })
        })
        .and_then(|()| {
            let first = reports.first().map(Report::to_json);
            recorder.finish_run(
                &ResultMeta::from(&result).ended_at(ended_utc),
                first.as_deref(),
                end_s,
            )
        });
    let Err(e) = log_end else {
        return (result, reports);
    };
    if result.error.is_none() {
        result.outcome = sequencer::Outcome::Error;
        result.error = Some(sequencer::RunError {
            device: None,
            step: "end of run".into(),
            message: format!("the log could not be completed: {e}"),
        });
    }
    // Every unit of a batch ends in error: its log is cut.
    let cut = sequencer::RunError {
        device: None,
        step: "end of run".into(),
        message: format!("the log could not be completed: {e}"),
    };
    for u in &mut result.others {
        if u.outcome != Some(sequencer::Outcome::Error) {
            u.outcome = Some(sequencer::Outcome::Error);
            u.error = Some(cut.clone());
        }
    }
    notes.push(format!(
        "the log {} is incomplete ({e}); `gyrobench recover {}` rewrites what it holds as a complete log",
        log.display(),
        log.display()
    ));
    let reports = reports_of(&result);
    (result, reports)
}

/// What stops a plan before anything is opened: an instrument past its
/// calibration, a bench file mixing simulated and real devices, faults
/// asked of a real bench.
fn check_plan(plan: &Plan, today: chrono::NaiveDate) -> Result<(), SessionError> {
    let embedded = plan.bench_cfg.is_embedded();
    check_calibration(&plan.bench_cfg, &plan.bench_label, today)?;
    let specs = [
        &plan.bench_cfg.devices.chamber.spec,
        &plan.bench_cfg.devices.table.spec,
        &plan.bench_cfg.devices.gyro.spec,
    ];
    if !embedded && specs.iter().any(|s| s.starts_with("sim://")) {
        return Err(SessionError::Bench(
            "the bench file mixes sim:// and real devices; use all sim:// (the embedded bench) or none".into(),
        ));
    }
    if !plan.bench_cfg.slots.is_empty() && plan.batch.is_empty() {
        return Err(SessionError::Bench(format!(
            "the bench {} holds slots: name the unit in each (`run --dut SLOT=SERIAL`, repeated)",
            plan.bench_label
        )));
    }
    if !embedded && !plan.faults.is_empty() {
        return Err(SessionError::Bench(
            "--inject applies to the embedded simulated bench only".into(),
        ));
    }
    Ok(())
}

/// The run's directory as `place` says, and what the operator is told
/// about it (a stale lock taken over, an earlier run moved aside).
fn open_run_dir(
    place: Place,
    name: &str,
    start: &chrono::DateTime<chrono::Utc>,
) -> Result<(RunDir, Vec<String>), SessionError> {
    let dir = match place {
        Place::Auto { base } => RunDir::create_unique(
            &base,
            name,
            &start.format("%Y%m%dT%H%M%SZ").to_string(),
            &start.to_rfc3339(),
        )?,
        Place::At { path, force } => RunDir::create_at(&path, &start.to_rfc3339(), force)?,
        Place::Resume(dir) => dir,
    };
    let mut notes = Vec::new();
    if let Some(holder) = &dir.lock.stale {
        notes.push(format!(
            "took over the lock of {holder}, which no longer runs (killed or crashed)"
        ));
    }
    if let Some(aside) = &dir.moved_aside {
        notes.push(format!(
            "the run that was in {} is now in {}",
            dir.path.display(),
            aside.display()
        ));
    }
    Ok((dir, notes))
}

/// Every device the plan drives, locked for the run's life (the embedded
/// bench's, none).
fn lock_bench(plan: &Plan, started: &str) -> Result<benchlock::BenchLock, SessionError> {
    let units = if plan.batch.is_empty() {
        plan.dut.clone()
    } else {
        plan.batch
            .iter()
            .map(|u| u.serial.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let holder = benchlock::Holder {
        procedure: plan.procedure.meta.name.clone(),
        units,
        bench: plan.bench_label.clone(),
        started_utc: started.to_owned(),
    };
    Ok(benchlock::BenchLock::acquire(&filled_slots(plan), &holder)?)
}

/// The bench file as the run opens it: a batch's filled slots alone (an
/// empty slot's link is not opened: nothing may be behind it), in the
/// run's order.
fn filled_slots(plan: &Plan) -> BenchConfig {
    let mut cfg = plan.bench_cfg.clone();
    cfg.slots
        .retain(|s| plan.batch.iter().any(|u| u.slot.name == s.name));
    cfg
}

/// The bench the plan runs on: the embedded twin (seeded for the part),
/// or the bench file's devices opened behind the bench's limits.
fn bench_for(
    plan: &Plan,
    part: u32,
    rt: &tokio::runtime::Runtime,
) -> Result<Box<dyn BenchIo>, SessionError> {
    let limits = plan.bench_cfg.limits.clone();
    let bench: Box<dyn BenchIo> = if plan.bench_cfg.is_embedded() {
        let (twin, seed) = plan.unit_twin(0, part);
        let others = (1..plan.batch.len())
            .map(|k| plan.unit_twin(k, part))
            .collect::<Vec<_>>();
        Box::new(
            embedded_bench(
                &twin,
                seed,
                plan.pacing,
                &plan.faults,
                limits,
                plan.bench_cfg.devices.supply.as_ref(),
            )
            .map_inner(|b| {
                others
                    .into_iter()
                    .fold(b, |b, (twin, seed)| b.with_slot(twin, seed))
            }),
        )
    } else {
        let bench_err = |source| SessionError::Device {
            bench: plan.bench_label.clone(),
            source,
        };
        let cfg = filled_slots(plan);
        let open = rt.block_on(open_bench(&cfg)).map_err(bench_err)?;
        let device = rt
            .block_on(DeviceBench::start(&cfg, open))
            .map_err(bench_err)?;
        Box::new(Guarded::new(device, limits).with_supply(plan.bench_cfg.devices.supply.as_ref()))
    };
    Ok(bench)
}

/// The run's metadata, as the log's `run` record holds it.
fn run_meta(
    plan: &Plan,
    twin: &TwinConfig,
    part: u32,
    run_start: &str,
    start: &chrono::DateTime<chrono::Utc>,
    instruments: Vec<crate::bench::Instrument>,
) -> Result<RunMeta, SessionError> {
    let embedded = plan.bench_cfg.is_embedded();
    // A store URL's password never goes into a log.
    let mut logged_bench = plan.bench_cfg.clone();
    if let Some(r) = logged_bench.results.as_mut() {
        r.db = r.db.as_deref().map(crate::results::pg::redact);
    }
    let bench_toml = toml::to_string_pretty(&logged_bench).map_err(|e| {
        SessionError::Bench(format!("the bench configuration cannot be logged: {e}"))
    })?;
    let site_json = serde_json::to_string(&plan.bench_cfg.site)
        .map_err(|e| SessionError::Bench(format!("the site cannot be logged: {e}")))?;
    let twin_toml = if embedded {
        Some(twin.to_toml().map_err(|e| {
            SessionError::Bench(format!("the twin configuration cannot be logged: {e}"))
        })?)
    } else {
        None
    };
    Ok(RunMeta {
        format: FORMAT,
        run_id: plan
            .resume
            .as_ref()
            .map(|r| r.run_id.clone())
            .filter(|id| !id.is_empty())
            .unwrap_or_else(new_run_id),
        procedure_toml: plan.procedure.text.clone(),
        procedure_path: plan.procedure_path.clone(),
        bench_toml,
        bench: plan.bench_label.clone(),
        twin_toml,
        coeffs_toml: plan.coeffs.as_ref().map(|c| c.text.clone()),
        site_json,
        dut_serial: plan.dut.clone(),
        dut_type: plan.procedure.meta.dut_type.clone(),
        operator: plan.operator.clone(),
        station: plan.station.clone(),
        software_version: crate::version::VERSION.to_owned(),
        start_time_utc: run_start.to_owned(),
        part_start_time_utc: start.to_rfc3339(),
        seed: embedded.then_some(plan.seed),
        part,
        previous_part: plan.resume.as_ref().map(|r| r.previous_file.clone()),
        resume_completed_steps: plan.resume.as_ref().map(|r| r.state.completed),
        speed: plan.speed.clone(),
        imported_from: None,
        bench_id: plan.bench_cfg.bench_id(&plan.bench_label),
        host: rundir::hostname(),
        software_revision: crate::version::REVISION.to_owned(),
        instruments,
        units: if plan.batch.is_empty() {
            vec![crate::runlog::meta::RunUnit {
                slot: String::new(),
                serial: plan.dut.clone(),
                dut_type: plan.procedure.meta.dut_type.clone(),
                coefficients: plan
                    .coeffs
                    .as_ref()
                    .map_or_else(crate::coeffs::CoeffsUsed::fitted, |c| c.used.clone()),
                mount: None,
                twin_toml: None,
                seed: None,
            }]
        } else {
            batch_meta_units(plan)?
        },
        other: Default::default(),
    })
}

/// A batch's units as its log's `run` record names them: each compensated
/// with the model fitted on its own records, its slot's mount, and its
/// own twin when its slot has one (a resume simulates the same unit).
fn batch_meta_units(plan: &Plan) -> Result<Vec<crate::runlog::meta::RunUnit>, SessionError> {
    plan.batch
        .iter()
        .map(|u| {
            let twin_toml = match &u.twin {
                Some(t) => Some(t.to_toml().map_err(|e| {
                    SessionError::Bench(format!(
                        "the twin of slot {} cannot be logged: {e}",
                        u.slot.name
                    ))
                })?),
                None => None,
            };
            Ok(crate::runlog::meta::RunUnit {
                slot: u.slot.name.clone(),
                serial: u.serial.clone(),
                dut_type: plan.procedure.meta.dut_type.clone(),
                coefficients: crate::coeffs::CoeffsUsed::fitted(),
                mount: Some(plan.bench_cfg.slot_geometry(&u.slot).mount),
                twin_toml,
                seed: plan.bench_cfg.is_embedded().then(|| u.seed(plan.seed)),
            })
        })
        .collect()
}

/// The run's link to the results store: recorded when it starts and when
/// it ends; a store that cannot be reached is said once, and the run is
/// queued to be written the next time a command opens the store.
struct StoreLink {
    store: Option<crate::results::Store>,
    key: Option<String>,
    location: crate::results::Location,
    /// The run's units' slots, in order.
    slots: Vec<String>,
}

impl StoreLink {
    fn open(
        loc: &crate::results::Location,
        meta: &RunMeta,
        log: &Path,
        notes: &mut Vec<String>,
    ) -> Self {
        let mut link = Self {
            store: None,
            key: None,
            location: loc.clone(),
            slots: meta.units.iter().map(|u| u.slot.clone()).collect(),
        };
        match crate::results::Store::open(loc) {
            Ok(Some(mut s)) => {
                let flushed = s.flush_pending();
                if flushed > 0 {
                    notes.push(format!(
                        "{flushed} queued run(s) written to the results store"
                    ));
                }
                match s.begin_part(meta, log) {
                    Ok(k) => link.key = Some(k),
                    Err(e) => notes.push(format!(
                        "{e}; the run goes on and will be recorded when it ends"
                    )),
                }
                link.store = Some(s);
            }
            Ok(None) => {}
            Err(e) => notes.push(format!(
                "{e}; the run goes on (its log is the record) and is queued for the store"
            )),
        }
        link
    }

    fn finish(
        &mut self,
        log: &Path,
        result: &RunResult,
        link: LinkStats,
        ended_utc: &str,
        notes: &mut Vec<String>,
    ) {
        if self.location == crate::results::Location::Off {
            return;
        }
        let done = match (&mut self.store, &self.key) {
            (Some(s), Some(key)) => s
                .finish_part(
                    key,
                    log,
                    &crate::results::record::PartEnd {
                        result,
                        link,
                        ended_utc: ended_utc.to_owned(),
                        slots: self.slots.clone(),
                    },
                )
                .map(|()| s.name().to_owned()),
            // Not recorded at the start: the log has it all now.
            _ => crate::results::Store::open(&self.location).and_then(|s| match s {
                Some(mut s) => s.index_log(log).map(|_| s.name().to_owned()),
                None => Ok(String::new()),
            }),
        };
        match done {
            Ok(name) => notes.push(format!("recorded in the results store {name}")),
            Err(e) => {
                let queued = crate::results::record::part_key_of_log(log).and_then(|k| {
                    crate::results::pending::push(&self.location.describe(), &k, log).ok()
                });
                notes.push(format!(
                    "{e}; {}",
                    match queued {
                        Some(q) => format!(
                            "the run is queued ({}) and will be written the next time a command opens the store, or by `gyrobench results sync`",
                            q.display()
                        ),
                        None => "run `gyrobench results sync` on its directory once the store is back".into(),
                    }
                ));
            }
        }
    }
}

/// What a panic said.
fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

/// The end of a run that panicked: the bench to its safe state and read
/// back, the failure logged; the result says what is known.
async fn after_panic(
    bench: &mut dyn BenchIo,
    log: &mut dyn Observer,
    what: &str,
    in_position_deg: f64,
    supply_safe_on: bool,
) -> RunResult {
    use sequencer::{Level, finish};
    let now = bench.now_s();
    let mut expected = finish::Expected {
        supply_safe_on,
        ..finish::Expected::default()
    };
    let safe = bench.safe_state().await;
    if safe.is_ok() {
        expected.safe();
    }
    let left = finish::bench_left(bench, &expected, in_position_deg).await;
    let message = format!(
        "internal error (please report it): {what}; the bench was brought to its safe state{}",
        safe.err()
            .map_or(String::new(), |e| format!(" but that failed: {e}"))
    );
    for (level, text) in [
        (Level::Error, message.as_str()),
        (Level::Info, &format!("bench left: {}", left.summary)),
    ] {
        // The log may be what failed; the report still says it all.
        let _logged = log.observe(&Event::Line {
            t_s: now,
            level,
            message: text,
        });
    }
    RunResult {
        outcome: sequencer::Outcome::Error,
        measurements: Vec::new(),
        error: Some(sequencer::RunError {
            device: None,
            step: "unknown".into(),
            message,
        }),
        cleanup_completed: false,
        device_time_s: bench.now_s(),
        frames: bench.link_stats().frames,
        records: Default::default(),
        bench_left: Some(left),
        // Every unit of a batch ends with the run.
        others: (1..bench.units())
            .map(|k| sequencer::UnitResult {
                frames: bench.slot_link_stats(k).frames,
                ..sequencer::UnitResult::default()
            })
            .collect(),
    }
}

/// The run's reports in `dir`: `report.json` and `report.html`, or for a
/// batch each unit's `report-SERIAL.json` and `.html`; the first write
/// that failed, and a batch's units with their reports.
fn write_reports(
    dir: &Path,
    meta: &RunMeta,
    result: &RunResult,
    reports: &[Report],
) -> (Option<String>, Vec<FinishedUnit>) {
    if !meta.is_batch() {
        let error = reports
            .first()
            .and_then(|r| write_report_as(dir, "report", r, result.unit_records(0)).err());
        return (error, Vec::new());
    }
    let mut error = None;
    let mut units = Vec::new();
    for (k, (u, r)) in meta.units.iter().zip(reports).enumerate() {
        let name = crate::unit::report_name(&u.serial);
        if let Err(e) = write_report_as(dir, &name, r, result.unit_records(k)) {
            error.get_or_insert(e);
        }
        units.push(FinishedUnit {
            slot: u.slot.clone(),
            serial: u.serial.clone(),
            report: r.clone(),
            file: name,
        });
    }
    (error, units)
}

/// `NAME.json` and `NAME.html` in `dir`.
fn write_report_as(
    dir: &Path,
    name: &str,
    report: &Report,
    records: &crate::sequencer::measure::Records,
) -> Result<(), String> {
    for (name, bytes) in [
        (format!("{name}.json"), report.to_json()),
        (format!("{name}.html"), render_html(report, records)),
    ] {
        let path = dir.join(name);
        crate::fsutil::write_atomic(&path, bytes.as_bytes())
            .map_err(|e| format!("writing {}: {e}", path.display()))?;
    }
    Ok(())
}

/// Device time the procedure needs at least, s (for progress bars).
pub fn estimated_s(plan: &Plan) -> f64 {
    min_total_s(&plan.procedure, &plan.bench_cfg.procedure_limits())
}
