//! Runs recorded elsewhere, in and out: the interchange CSV (or a lab's
//! file read through an import map) becomes a log with the channels of a
//! live run (`import`), and any log becomes the interchange CSV at 1 Hz
//! with its sidecar (`export`). Both write to a temporary name and rename
//! when complete.
//!
//! An imported log has no `/gyro/frames` (the CSV holds interval means,
//! not frames); its `/gyro/rate_1hz`, `/chamber/state`, `/table/state`,
//! `/steps`, `/events` and `run` metadata are those of a live run. Rows
//! taken while the table turned, and rows outside records, are logged
//! outside any record ([`parts`]). The procedure is the one the export's
//! sidecar carries ([`sidecar`]), its steps matched to the rows in run
//! order, or else one made from the rows: a `record` step per stretch of
//! recorded rows with one step label, a `wait` per stretch outside
//! records, then the figures the shipped acceptance judges, at its
//! limits. `replay`, `calibrate`, `allan` and `diagnose` take it.

mod export;
pub mod parts;
pub mod sidecar;

pub use export::{Exported, export, export_unit};

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use self::parts::Part;
use self::sidecar::Sidecar;
use super::import_map::ImportMap;
use super::interchange::{self, CsvError, Row};
use super::meta::{ResultMeta, RunMeta};
use super::reader;
use super::schema::{FORMAT, Level, StepPhase};
use super::writer::{FrameScales, Recorder};
use crate::analysis::series::Interval;
use crate::bench::BenchConfig;
use crate::coeffs::{CoefficientSet, CoeffsUsed, Compensation};
use crate::config::{Checker, ConfigError, Source};
use crate::driver::{ChamberMode, ChamberReading, TableReading};
use crate::fsutil::{Pending, ensure_distinct};
use crate::geometry::{Site, TableAngles, TableGeometry};
use crate::procedure::{Procedure, Step, StepKind};
use crate::sequencer::measure::{self, MeasureOutcome, Records};
use crate::sequencer::{BenchState, Outcome, RunResult, Tick};
use gyrobench_model::measurement::Measurement;

/// `SITE.toml`: the `[site]` of a bench file alone, and, when the run was
/// made on a two-axis table whose geometry is known, its `[table.geometry]`
/// (the table angles of the rows then follow from their orientation).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteFile {
    /// Where the run stood.
    pub site: Site,
    /// The table the run was made on, if given.
    #[serde(default)]
    pub table: Option<SiteTable>,
}

/// `[table]` of a site file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteTable {
    /// Axes and mount of the table the run was made on.
    pub geometry: TableGeometry,
}

impl SiteFile {
    /// A site alone: no table geometry.
    pub fn of(site: Site) -> Self {
        Self { site, table: None }
    }
}

/// Read and check a site file.
pub fn load_site(path: &Path) -> Result<SiteFile, ConfigError> {
    site_from_source(&Source::read(path)?)
}

/// Parse and check a site file's text.
pub fn site_from_source(src: &Source) -> Result<SiteFile, ConfigError> {
    let f: SiteFile = src.parse()?;
    let c = Checker::new(src);
    f.site.validate(&c, "site")?;
    if let Some(t) = &f.table {
        t.geometry.validate(&c, "table.geometry")?;
    }
    Ok(f)
}

/// The table angles of every row: from its own columns, else from the
/// site file's table geometry, else not known. Rows whose angles
/// contradict their orientation under that geometry, or whose pose the
/// geometry cannot reach, are refused, a few of them named.
fn table_angles(
    rows: &[Row],
    geometry: Option<&TableGeometry>,
    name: &str,
) -> Result<Vec<Option<TableAngles>>, ImportError> {
    let Some(g) = geometry else {
        return Ok(rows.iter().map(Row::table_angles).collect());
    };
    let mut out = Vec::with_capacity(rows.len());
    let mut bad: Vec<String> = Vec::new();
    let mut count = 0usize;
    for r in rows {
        let o = r.orientation();
        let got = match r.table_angles() {
            Some(a) => {
                let off = crate::geometry::rotation_distance_deg(&g.rotation(a), &o.rotation());
                (off <= 0.1).then_some(a).ok_or_else(|| {
                    format!(
                        "its table angles (outer {} deg, inner {} deg) put the unit {off:.2} deg from its orientation",
                        a.outer_deg, a.inner_deg
                    )
                })
            }
            None => g.angles_for(o).map_err(|e| e.to_string()),
        };
        match got {
            Ok(a) => out.push(Some(a)),
            Err(why) => {
                count += 1;
                if bad.len() < 3 {
                    bad.push(format!("time_s = {} (step {:?}): {why}", r.time_s, r.step));
                }
            }
        }
    }
    if count > 0 {
        return Err(ImportError::Other(format!(
            "{name}: {count} row(s) do not fit the site file's [table.geometry]; {}{}; \
             correct the geometry, or leave it out (the orientation alone is enough)",
            bad.join("; "),
            if count > bad.len() { "; ..." } else { "" }
        )));
    }
    Ok(out)
}

/// Why an import or export failed.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// A bad CSV.
    #[error(transparent)]
    Csv(#[from] CsvError),
    /// A bad site file.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The log cannot be read.
    #[error(transparent)]
    Read(#[from] reader::ReadError),
    /// The output would destroy the input.
    #[error(transparent)]
    SamePath(#[from] crate::fsutil::SamePath),
    /// No site: neither `--site` nor a sidecar gives where the run stood.
    #[error(
        "{file}: give --site SITE.toml, where the run stood (no sidecar {sidecar} beside it gives it)"
    )]
    NoSite {
        /// The file imported.
        file: String,
        /// Where its sidecar would be.
        sidecar: String,
    },
    /// `--type` against the type the carried procedure tests.
    #[error(
        "--type {given:?}: the procedure in {sidecar} ({procedure}) tests units of type {carried:?}; leave --type out, or give {carried:?}"
    )]
    TypeConflict {
        /// `--type`.
        given: String,
        /// The procedure's `dut_type`.
        carried: String,
        /// The sidecar.
        sidecar: String,
        /// The procedure's file as the run named it.
        procedure: String,
    },
    /// The sidecar does not go with the file's rows.
    #[error(
        "{file}: {message}, in {sidecar}; the CSV and the sidecar beside it are not of one run: move the sidecar away to import the CSV alone"
    )]
    Mismatch {
        /// The file imported.
        file: String,
        /// Its sidecar.
        sidecar: String,
        /// What does not fit.
        message: String,
    },
    /// Something else, with its file.
    #[error("{0}")]
    Other(String),
}

/// What an import made.
#[derive(Debug, Clone)]
pub struct Imported {
    /// 1 Hz intervals written.
    pub intervals: usize,
    /// Records (stretches of recorded rows with one step label).
    pub records: Vec<String>,
    /// Rows logged outside any record (moves, waits, soaks).
    pub unrecorded: usize,
    /// The sidecar read beside the file, whose procedure judged the rows
    /// (none: a procedure made from the rows).
    pub sidecar: Option<PathBuf>,
    /// The unit's serial as recorded ([`crate::unit::UNNAMED_SERIAL`] when
    /// none was given).
    pub serial: String,
    /// The unit's type as recorded.
    pub dut_type: String,
    /// The verdict of the procedure on the data.
    pub outcome: Outcome,
    /// The measurements behind it.
    pub measurements: Vec<Measurement>,
}

/// Type of a unit an import is not told of (`--type`, a sidecar).
pub const DEFAULT_TYPE: &str = "gyro";

/// What `import` is given besides the file.
#[derive(Debug, Clone, Copy, Default)]
pub struct ImportOptions<'a> {
    /// `--site`: where the run stood (with a sidecar, it replaces the
    /// sidecar's site, and its table geometry when it gives one).
    pub site: Option<&'a SiteFile>,
    /// `--dut`: the unit's serial.
    pub dut: Option<&'a str>,
    /// `--type`: the unit's type.
    pub dut_type: Option<&'a str>,
    /// `--map`: how to read a lab's own file.
    pub map: Option<&'a ImportMap>,
}

/// Rows reduced to 1 s means (rows finer than 1 s are averaged per whole
/// second of `time_s` and step, as [`interchange::OneHz`] does; 1 s rows
/// pass through).
fn to_one_hz(rows: &[Row], name: &str) -> Result<Vec<Row>, ImportError> {
    let (_, _, dt) = interchange::longest_even_run(rows);
    if dt > 1.01 {
        return Err(ImportError::Other(format!(
            "{name}: samples every {dt} s; the importer needs 1 s or finer (the figures work on 1 s means)"
        )));
    }
    if dt > 0.99 {
        return Ok(rows.to_vec());
    }
    let mut out = interchange::OneHz::default();
    for r in rows {
        out.push(r.clone());
    }
    Ok(out.finish())
}

/// Import `file` (the interchange CSV, or a lab's file through
/// `opts.map`) as a log at `out`. The sidecar beside `file`
/// (`RUN.export.toml`, written by `export`) is read when it is there: its
/// procedure judges the rows, and its unit, site and coefficients are the
/// run's unless `opts` say otherwise.
pub fn import(file: &Path, opts: &ImportOptions<'_>, out: &Path) -> Result<Imported, ImportError> {
    let side_path = sidecar::path_for(file);
    let side = if side_path.is_file() {
        Some(Sidecar::load(&side_path)?)
    } else {
        None
    };
    let mut inputs = vec![file];
    if side.is_some() {
        inputs.push(&side_path);
    }
    ensure_distinct(out, &inputs)?;
    let name = file.display().to_string();
    let site = match (opts.site, &side) {
        (Some(s), Some(c)) => SiteFile {
            site: s.site,
            table: s.table.or(c.table),
        },
        (Some(s), None) => s.clone(),
        (None, Some(c)) => SiteFile {
            site: c.site,
            table: c.table,
        },
        (None, None) => {
            return Err(ImportError::NoSite {
                file: name,
                sidecar: side_path.display().to_string(),
            });
        }
    };
    let (rows, power_on_utc) = match opts.map {
        Some(map) => {
            let mapped = map.read(file).map_err(|e| match e {
                super::import_map::MapError::Map(e) => ImportError::Config(e),
                super::import_map::MapError::Csv(e) => ImportError::Csv(e),
            })?;
            (mapped.rows, mapped.power_on_utc)
        }
        None => (interchange::read(file)?, None),
    };
    let serial = match (opts.dut, &side) {
        (Some(d), _) => d.to_owned(),
        (None, Some(c)) => c.unit.serial.clone(),
        (None, None) => crate::unit::UNNAMED_SERIAL.to_owned(),
    };
    crate::unit::check_serial(&serial)
        .map_err(|e| ImportError::Other(format!("--dut {serial:?}: {e}")))?;
    let dut_type = match (opts.dut_type, &side) {
        (Some(t), _) => t.to_owned(),
        (None, Some(c)) => c.unit.dut_type.clone(),
        (None, None) => DEFAULT_TYPE.to_owned(),
    };
    crate::unit::check_type(&dut_type)
        .map_err(|e| ImportError::Other(format!("--type {dut_type:?}: {e}")))?;
    let dated = power_on_utc.or_else(|| side.as_ref().map(|c| c.export.started_utc.clone()));
    let unit = (serial, dut_type);
    let side = side.map(|c| (side_path, c));
    import_rows(file, rows, dated, &site, &unit, side.as_ref(), out)
}

/// The procedure the rows are judged by, with the step of each part: the
/// sidecar's (checked against the type the import records), or one made
/// from the rows.
struct Judged {
    text: String,
    path: String,
    procedure: Procedure,
    parts: Vec<Part>,
    /// Each part's step (its index in run order); none: between steps.
    at: Vec<Option<usize>>,
    carried: bool,
}

fn judged_by(
    name: &str,
    rows: &[Row],
    bench: &BenchConfig,
    dut_type: &str,
    side: Option<&(PathBuf, Sidecar)>,
) -> Result<Judged, ImportError> {
    let Some((side_path, c)) = side else {
        let parts = parts::parts(rows, true);
        let text = parts::procedure_text(name, dut_type, &parts, rows).map_err(|e| {
            ImportError::Other(format!(
                "{name}: writing the procedure made from its steps: {e}"
            ))
        })?;
        let procedure = Procedure::from_source(
            &Source::from_text("imported procedure", &text),
            &bench.procedure_limits(),
        )
        .map_err(|e| {
            ImportError::Other(format!("{name}: the procedure made from its steps: {e}"))
        })?;
        let at = (0..parts.len())
            .map(|i| Some(procedure.setup.len() + i))
            .collect();
        return Ok(Judged {
            text,
            path: format!("{name} (imported)"),
            procedure,
            parts,
            at,
            carried: false,
        });
    };
    let side_name = side_path.display().to_string();
    let mismatch = |message: String| ImportError::Mismatch {
        file: name.to_owned(),
        sidecar: side_name.clone(),
        message,
    };
    let procedure = Procedure::from_source(
        &Source::from_text(&format!("procedure.text in {side_name}"), &c.procedure.text),
        &bench.procedure_limits(),
    )
    .map_err(|e| {
        mismatch(format!(
            "its procedure does not fit the imported bench: {e}"
        ))
    })?;
    if procedure.meta.dut_type != dut_type {
        return Err(ImportError::TypeConflict {
            given: dut_type.to_owned(),
            carried: procedure.meta.dut_type.clone(),
            sidecar: side_name,
            procedure: c.procedure.path.clone(),
        });
    }
    let parts = parts::parts(rows, false);
    let at = parts::assign(&procedure, &parts, rows).map_err(mismatch)?;
    Ok(Judged {
        text: c.procedure.text.clone(),
        path: format!("{} (carried by {side_name})", c.procedure.path),
        procedure,
        parts,
        at,
        carried: true,
    })
}

/// Write `rows` read from `file` as a log at `out`; `dated` dates the run
/// (the file's power-on, or the exported run's start; else the import's
/// own time); `unit` is the serial and type recorded.
fn import_rows(
    file: &Path,
    rows: Vec<Row>,
    dated: Option<String>,
    site: &SiteFile,
    (serial, dut_type): &(String, String),
    side: Option<&(PathBuf, Sidecar)>,
    out: &Path,
) -> Result<Imported, ImportError> {
    let name = file.display().to_string();
    let imported_at = dated.unwrap_or_else(|| crate::clock::utc_now().to_rfc3339());
    let rows = to_one_hz(&rows, &name)?;
    let geometry = site.table.as_ref().map(|t| t.geometry);
    let angles = table_angles(&rows, geometry.as_ref(), &name)?;
    let mut bench = BenchConfig::embedded();
    // Another lab's bench: its own uncertainties are not known here.
    bench.uncertainty = crate::typeb::TypeB::default();
    bench.site = site.site;
    if let Some(g) = geometry {
        bench.table.geometry = g;
    }
    let judged = judged_by(&name, &rows, &bench, dut_type, side)?;
    let coeffs = side.and_then(|(_, c)| c.coefficients.as_ref());
    let compensation = coeffs
        .map(|k| {
            CoefficientSet::from_source(&Source::from_text("coefficients.text", &k.text)).map(
                |set| {
                    set.fit().map(|fit| Compensation {
                        fit,
                        used: k.used.clone(),
                    })
                },
            )
        })
        .transpose()?
        .flatten();
    let other = |what: &str, e: &dyn std::fmt::Display| {
        ImportError::Other(format!("{name}: writing the {what} into the log: {e}"))
    };
    let meta = RunMeta {
        format: FORMAT,
        run_id: crate::session::new_run_id(),
        procedure_toml: judged.text.clone(),
        procedure_path: judged.path.clone(),
        bench_toml: toml::to_string_pretty(&bench).map_err(|e| other("bench", &e))?,
        bench: format!("imported from {name}"),
        site_json: serde_json::to_string(&site.site).map_err(|e| other("site", &e))?,
        coeffs_toml: coeffs.map(|k| k.text.clone()),
        dut_serial: serial.clone(),
        dut_type: dut_type.clone(),
        software_version: crate::version::VERSION.to_owned(),
        software_revision: crate::version::REVISION.to_owned(),
        // Dated by the file's power-on where it gives dates (or the
        // exported run's start), else by the import.
        start_time_utc: imported_at.clone(),
        part_start_time_utc: imported_at,
        part: 1,
        imported_from: Some(name.clone()),
        bench_id: "imported".into(),
        host: crate::session::rundir::hostname(),
        units: vec![crate::runlog::meta::RunUnit {
            slot: String::new(),
            serial: serial.clone(),
            dut_type: dut_type.clone(),
            coefficients: coeffs.map_or_else(CoeffsUsed::fitted, |k| k.used.clone()),
            mount: None,
            twin_toml: None,
            seed: None,
        }],
        ..RunMeta::default()
    };
    let mut pending =
        Pending::output(out).map_err(|e| ImportError::Other(format!("{}: {e}", out.display())))?;
    let (outcome, measurements) = write_log(
        &mut pending,
        &meta,
        &judged,
        &rows,
        &angles,
        compensation.as_ref(),
    )?;
    pending
        .commit()
        .map_err(|e| ImportError::Other(format!("writing {}: {e}", out.display())))?;
    let recorded = judged.parts.iter().filter(|p| p.recorded);
    Ok(Imported {
        intervals: rows.len(),
        records: recorded.clone().map(|p| p.label.clone()).collect(),
        unrecorded: rows.len() - recorded.map(|p| p.b - p.a).sum::<usize>(),
        sidecar: side.map(|(p, _)| p.clone()),
        serial: serial.clone(),
        dut_type: dut_type.clone(),
        outcome,
        measurements,
    })
}

/// The log of an imported run as it is written: its recorder, records
/// and measurements so far.
struct Writing<'a> {
    rec: Recorder,
    records: Records,
    measurements: Vec<Measurement>,
    coeffs: Option<&'a Compensation>,
    /// Judged as its replay judges it: the procedure's rule, no declared
    /// uncertainties of the bench it came from.
    judging: measure::Judging,
}

impl Writing<'_> {
    /// Step `s` (at run-order `index`) starts at `t_s`: a record begins, a
    /// measure step is computed on the records so far, as a run does.
    fn start(&mut self, index: usize, s: &Step, t_s: f64) -> std::io::Result<()> {
        self.rec.step(&crate::sequencer::events::step_event(
            t_s,
            StepPhase::Start,
            index,
            s,
        ))?;
        self.rec.event(t_s, Level::Debug, &s.start_message())?;
        match &s.kind {
            StepKind::Record { label, .. } => self.records.start(label),
            StepKind::Measure(m) => {
                let meas = measure::compute(m, &self.records, self.coeffs, &s.key, &self.judging);
                let level = if meas.outcome == MeasureOutcome::Pass {
                    Level::Info
                } else {
                    Level::Warning
                };
                let value = meas.value.map_or("n/a".into(), |v| format!("{v:.4}"));
                self.rec
                    .event(t_s, level, &format!("{} = {value}", meas.name))?;
                self.measurements.push(meas);
            }
            _ => {}
        }
        Ok(())
    }

    /// Step `s` ends at `t_s`.
    fn end(&mut self, index: usize, s: &Step, t_s: f64) -> std::io::Result<()> {
        self.rec.step(&crate::sequencer::events::step_event(
            t_s,
            StepPhase::End,
            index,
            s,
        ))?;
        self.rec
            .event(t_s, Level::Debug, &format!("end of step {}", s.key))
    }
}

/// Write the imported run's log to `tmp`: each part's rows in its step,
/// the steps without rows (measures, notes, set points) started and ended
/// where they fall in run order; returns the verdict.
fn write_log(
    tmp: &mut Pending,
    meta: &RunMeta,
    judged: &Judged,
    rows: &[Row],
    angles: &[Option<TableAngles>],
    coeffs: Option<&Compensation>,
) -> Result<(Outcome, Vec<Measurement>), ImportError> {
    let scales = FrameScales {
        dt_s: 1.0,
        lsb_arcsec: 1.0,
        temp_lsb_c: 0.01,
    };
    let file = tmp
        .take_file()
        .map_err(|e| ImportError::Other(format!("writing {}: {e}", tmp.path().display())))?;
    let tmp_path = tmp.path().to_owned();
    let io = |e: std::io::Error| ImportError::Other(format!("writing {}: {e}", tmp_path.display()));
    let site: Site = serde_json::from_str(&meta.site_json)
        .map_err(|e| ImportError::Other(format!("the site: {e}")))?;
    let mut w = Writing {
        rec: Recorder::from_file(file, &tmp_path, meta, 0, scales).map_err(io)?,
        records: Records::default(),
        measurements: Vec::new(),
        coeffs,
        judging: measure::Judging {
            rule: judged.procedure.meta.decision_rule,
            ..measure::Judging::default()
        },
    };
    let steps: Vec<&Step> = judged.procedure.steps().collect();
    let (mut open, mut next): (Option<usize>, usize) = (None, 0);
    for (p, &at) in judged.parts.iter().zip(&judged.at) {
        let t0 = rows[p.a].time_s - 0.5;
        if open != at {
            if let Some(o) = open.take() {
                w.end(o, steps[o], t0).map_err(io)?;
            }
            if let Some(j) = at {
                for (k, s) in steps.iter().enumerate().take(j).skip(next) {
                    w.start(k, s, t0).map_err(io)?;
                    w.end(k, s, t0).map_err(io)?;
                }
                w.start(j, steps[j], t0).map_err(io)?;
                (open, next) = (Some(j), j + 1);
            }
        }
        // A row outside records keeps its own step label where the
        // procedure was made from the rows, or between a procedure's
        // steps (export gives it back).
        let key = match at {
            Some(j) if judged.carried || p.recorded => steps[j].key.as_str(),
            _ => p.step.as_str(),
        };
        let label = p.recorded.then_some(p.label.as_str());
        for (r, known) in rows[p.a..p.b].iter().zip(&angles[p.a..p.b]) {
            write_row(&mut w.rec, &mut w.records, (label, key), r, *known, &site).map_err(io)?;
        }
    }
    let end_s = rows.last().map_or(0.0, |r| r.time_s + 0.5);
    if let Some(o) = open {
        w.end(o, steps[o], end_s).map_err(io)?;
    }
    for (k, s) in steps.iter().enumerate().skip(next) {
        w.start(k, s, end_s).map_err(io)?;
        w.end(k, s, end_s).map_err(io)?;
    }
    let Writing {
        rec,
        records,
        measurements,
        ..
    } = w;
    let failed = measurements
        .iter()
        .any(|m| m.outcome != MeasureOutcome::Pass);
    let outcome = if failed { Outcome::Fail } else { Outcome::Pass };
    let result = RunResult {
        outcome,
        measurements: measurements.clone(),
        error: None,
        cleanup_completed: true,
        device_time_s: end_s,
        frames: 0,
        records,
        bench_left: None,
        others: Vec::new(),
    };
    rec.finish_run(&ResultMeta::from(&result), None, end_s)
        .map_err(io)?;
    Ok((outcome, measurements))
}

/// One imported row as the tick and 1 Hz interval a run logs, in record
/// `label` (none: outside any record) of step `step_key`, filed in
/// `records` too.
fn write_row(
    rec: &mut Recorder,
    records: &mut Records,
    (label, step_key): (Option<&str>, &str),
    r: &Row,
    known: Option<TableAngles>,
    site: &Site,
) -> std::io::Result<()> {
    // The orientation is the measured fact; the table angles are
    // written only where they are known.
    let o = r.orientation();
    rec.set_table_angles_known(known.is_some());
    let angles = known.unwrap_or_default();
    let state = BenchState {
        t_s: r.time_s + 0.5,
        chamber: ChamberReading {
            air_c: r.chamber_c,
            set_point_c: r.chamber_c,
            mode: ChamberMode::Constant,
            alarms: Vec::new(),
        },
        table: TableReading {
            angles,
            rates: TableAngles::default(),
        },
        commanded: angles,
        orientation: o,
        reference_dph: o.earth_rate_dph(site),
        in_position: true,
        power: None,
    };
    let tick = Tick {
        t0_s: r.time_s - 0.5,
        frames: Vec::new(),
        state: Some(state.clone()),
        slots: Vec::new(),
    };
    rec.tick(&tick, label, step_key)?;
    let iv = Interval {
        time_s: r.time_s,
        rate_dph: r.rate_dph,
        reference_dph: state.reference_dph,
        t1_c: r.t1_c,
        t2_c: r.t2_c,
        tcase_c: r.tcase_c,
        chamber_c: r.chamber_c,
        frames: 0,
    };
    records.push(iv, label);
    rec.interval(&iv, label)
}
