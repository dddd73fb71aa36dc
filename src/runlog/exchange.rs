//! Runs recorded elsewhere, in and out: the interchange CSV becomes a log
//! with the channels of a live run (`import`), and any log becomes the
//! interchange CSV at 1 Hz (`export`). Both write to a temporary name and
//! rename when complete.
//!
//! An imported log has no `/gyro/frames` (the CSV holds interval means,
//! not frames); its `/gyro/rate_1hz`, `/chamber/state`, `/table/state`,
//! `/events` and `run` metadata are those of a live run, with a procedure
//! made from the CSV's steps: one `record` step per stretch of rows with
//! the same step label, then the figures the shipped acceptance judges, at
//! its limits. `replay`, `calibrate`, `allan` and `diagnose` take it.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use super::interchange::{self, CsvError, Row};
use super::meta::{ResultMeta, RunMeta};
use super::reader::{self, Item, ReadSummary};
use super::schema::{FORMAT, Level, RUN_META, Rate1Hz, StepPhase, TableState, topics};
use super::writer::{FrameScales, Recorder};
use crate::analysis::series::Interval;
use crate::bench::BenchConfig;
use crate::config::{Checker, ConfigError, Source};
use crate::driver::{ChamberMode, ChamberReading, TableReading};
use crate::fsutil::{Pending, ensure_distinct};
use crate::geometry::{Site, TableAngles, TableGeometry};
use crate::procedure::{Procedure, Step, StepKind};
use crate::sequencer::measure::{self, MeasureOutcome, Records};
use crate::sequencer::{BenchState, Outcome, RunResult, Tick};

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
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
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
    /// Something else, with its file.
    #[error("{0}")]
    Other(String),
}

/// What an import made.
#[derive(Debug, Clone)]
pub struct Imported {
    /// 1 Hz intervals written.
    pub intervals: usize,
    /// Records (stretches of one step label).
    pub records: Vec<String>,
    /// The verdict of the generated procedure on the data.
    pub outcome: Outcome,
    /// The measurements behind it.
    pub measurements: Vec<measure::Measurement>,
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

/// Stretches of rows with one step label: (label made unique, first, end).
fn stretches(rows: &[Row]) -> Vec<(String, usize, usize)> {
    let mut out: Vec<(String, usize, usize)> = Vec::new();
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut start = 0;
    for i in 1..=rows.len() {
        if i == rows.len() || rows[i].step != rows[start].step {
            let base = if rows[start].step.is_empty() {
                "unlabelled".to_owned()
            } else {
                rows[start].step.clone()
            };
            let n = seen.entry(base.clone()).or_insert(0);
            *n += 1;
            let label = if *n == 1 { base } else { format!("{base}#{n}") };
            out.push((label, start, i));
            start = i;
        }
    }
    out
}

fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_owned()).to_string()
}

/// The procedure an imported run is judged by: its records, then the
/// acceptance's figures where the data allow them.
fn procedure_text(name: &str, parts: &[(String, usize, usize)], rows: &[Row]) -> String {
    let mut t = format!(
        "# Made by gyrobench import from {name}: one record per stretch of rows with\n# one step label, judged with the limits of procedures/acceptance.toml.\n\n[procedure]\nname = {}\ndescription = {}\ndut_type = \"gyro\"\nspec = \"model-4 compensated drift 0.05 deg/h (p-p of 600 s averages); bias stability 0.05 deg/h (1-sigma of 100 s averages)\"\n",
        toml_str("imported"),
        toml_str(&format!("run imported from {name}"))
    );
    let measure = |t: &mut String,
                   name: &str,
                   metric: &str,
                   records: &[&str],
                   avg: Option<f64>,
                   lim: &str| {
        let recs: Vec<String> = records.iter().map(|r| toml_str(r)).collect();
        t.push_str(&format!(
            "\n[[main]]\naction = \"measure\"\nname = {}\nmetric = \"{metric}\"\nrecords = [{}]\n{}{lim}\nunit = \"deg/h\"\n",
            toml_str(name),
            recs.join(", "),
            avg.map_or(String::new(), |a| format!("averaging_s = {a:.1}\n"))
        ));
    };
    for (label, a, b) in parts {
        t.push_str(&format!(
            "\n[[main]]\naction = \"record\"\nlabel = {}\nduration_s = {:.1}\n",
            toml_str(label),
            (b - a) as f64
        ));
    }
    let all: Vec<&str> = parts.iter().map(|p| p.0.as_str()).collect();
    if let Some((first, a, b)) = parts.first()
        && rows[*a].time_s < 60.0
        && rows[b - 1].time_s >= 1800.0
    {
        measure(
            &mut t,
            "self_heating_dph",
            "self_heating",
            &[first],
            None,
            "high = 1.0",
        );
    }
    if rows.len() >= 1200 {
        measure(
            &mut t,
            "raw_drift_pp_dph",
            "drift_pp",
            &all,
            Some(600.0),
            "high = 1.0",
        );
        measure(
            &mut t,
            "compensated_drift_pp_dph",
            "compensated_drift_pp",
            &all,
            Some(600.0),
            "high = 0.05",
        );
    }
    // Bias stability where it means something: records after the warm-up
    // with the chamber steady (within 1 degC), as the acceptance's positions.
    for (label, a, b) in parts {
        let air = rows[*a..*b].iter().map(|r| r.chamber_c);
        let spread =
            air.clone().fold(f64::NEG_INFINITY, f64::max) - air.fold(f64::INFINITY, f64::min);
        if b - a >= 300 && rows[*a].time_s >= 1800.0 && spread <= 1.0 {
            measure(
                &mut t,
                &format!("bias_stability_dph:{label}"),
                "bias_stability",
                &[label],
                Some(100.0),
                "high = 0.05",
            );
        }
    }
    t
}

/// Import the interchange CSV at `csv` (site from `site`) as a log at
/// `out`; `dut` is the unit's serial (default: the CSV's file stem).
pub fn import(
    csv: &Path,
    site: &SiteFile,
    dut: Option<&str>,
    out: &Path,
) -> Result<Imported, ImportError> {
    ensure_distinct(out, &[csv])?;
    let serial = serial_of(csv, dut)?;
    let rows = interchange::read(csv)?;
    import_rows(csv, rows, None, site, &serial, out)
}

/// Import a lab's own file at `file` read through `map` (see
/// [`import_map`](super::import_map)), as [`import`] does the interchange CSV.
pub fn import_mapped(
    file: &Path,
    map: &super::import_map::ImportMap,
    site: &SiteFile,
    dut: Option<&str>,
    out: &Path,
) -> Result<Imported, ImportError> {
    ensure_distinct(out, &[file])?;
    let serial = serial_of(file, dut)?;
    let mapped = map.read(file).map_err(|e| match e {
        super::import_map::MapError::Map(e) => ImportError::Config(e),
        super::import_map::MapError::Csv(e) => ImportError::Csv(e),
    })?;
    import_rows(file, mapped.rows, mapped.power_on_utc, site, &serial, out)
}

/// The unit's serial: `dut`, else the file's stem (checked either way).
fn serial_of(file: &Path, dut: Option<&str>) -> Result<String, ImportError> {
    let name = file.display().to_string();
    let serial = match dut {
        Some(d) => d.to_owned(),
        None => file
            .file_stem()
            .map_or(String::new(), |s| s.to_string_lossy().into_owned()),
    };
    crate::unit::check_serial(&serial).map_err(|e| {
        ImportError::Other(match dut {
            Some(_) => format!("--dut {serial:?}: {e}"),
            None => format!(
                "{name}: its file name {serial:?} stands for the unit's serial and is not one ({e}); give --dut SERIAL"
            ),
        })
    })?;
    Ok(serial)
}

/// Write `rows` read from `file` as a log at `out`; `power_on_utc` dates
/// the run when the file gave dates (else the import dates it).
fn import_rows(
    file: &Path,
    rows: Vec<Row>,
    power_on_utc: Option<String>,
    site: &SiteFile,
    serial: &str,
    out: &Path,
) -> Result<Imported, ImportError> {
    let name = file.display().to_string();
    let serial = serial.to_owned();
    let imported_at = power_on_utc.unwrap_or_else(|| crate::clock::utc_now().to_rfc3339());
    let rows = to_one_hz(&rows, &name)?;
    let geometry = site.table.as_ref().map(|t| t.geometry);
    let angles = table_angles(&rows, geometry.as_ref(), &name)?;
    let parts = stretches(&rows);
    let mut bench = BenchConfig::embedded();
    // Another lab's bench: its own uncertainties are not known here.
    bench.uncertainty = crate::typeb::TypeB::default();
    let site = site.site;
    bench.site = site;
    if let Some(g) = geometry {
        bench.table.geometry = g;
    }
    let text = procedure_text(&name, &parts, &rows);
    let procedure = Procedure::from_source(&Source::from_text("imported procedure", &text), &bench)
        .map_err(|e| {
            ImportError::Other(format!("{name}: the procedure made from its steps: {e}"))
        })?;
    let other = |what: &str, e: &dyn std::fmt::Display| {
        ImportError::Other(format!("{name}: writing the {what} into the log: {e}"))
    };
    let meta = RunMeta {
        format: FORMAT,
        run_id: crate::session::new_run_id(),
        procedure_toml: text.clone(),
        procedure_path: format!("{name} (imported)"),
        bench_toml: toml::to_string_pretty(&bench).map_err(|e| other("bench", &e))?,
        bench: format!("imported from {name}"),
        site_json: serde_json::to_string(&site).map_err(|e| other("site", &e))?,
        dut_serial: serial.clone(),
        dut_type: "gyro".into(),
        software_version: crate::version::VERSION.to_owned(),
        software_revision: crate::version::REVISION.to_owned(),
        // Dated by the file's power-on where it gives dates, else by the
        // import.
        start_time_utc: imported_at.clone(),
        part_start_time_utc: imported_at,
        part: 1,
        imported_from: Some(name.clone()),
        bench_id: "imported".into(),
        host: crate::session::rundir::hostname(),
        units: vec![crate::runlog::meta::RunUnit {
            slot: String::new(),
            serial,
            dut_type: "gyro".into(),
            coefficients: crate::coeffs::CoeffsUsed::fitted(),
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
        site,
        &procedure,
        &parts,
        &rows,
        &angles,
    )?;
    pending
        .commit()
        .map_err(|e| ImportError::Other(format!("writing {}: {e}", out.display())))?;
    Ok(Imported {
        intervals: rows.len(),
        records: parts.into_iter().map(|p| p.0).collect(),
        outcome,
        measurements,
    })
}

/// Write the imported run's log to `tmp`; returns the verdict.
fn write_log(
    tmp: &mut Pending,
    meta: &RunMeta,
    site: Site,
    procedure: &Procedure,
    parts: &[(String, usize, usize)],
    rows: &[Row],
    angles: &[Option<TableAngles>],
) -> Result<(Outcome, Vec<measure::Measurement>), ImportError> {
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
    let mut rec = Recorder::from_file(file, &tmp_path, meta, 0, scales).map_err(io)?;
    let mut records = Records::default();
    let steps: Vec<_> = procedure.main.iter().collect();
    let mut step_at = 0;
    let setup = procedure.setup.len();
    for (label, a, b) in parts {
        let Some(step) = steps.get(step_at) else {
            break;
        };
        let index = setup + step_at;
        step_at += 1;
        let t0 = rows[*a].time_s - 0.5;
        rec.step(&crate::sequencer::events::step_event(
            t0,
            StepPhase::Start,
            index,
            step,
        ))
        .map_err(io)?;
        rec.event(t0, Level::Debug, &step.start_message())
            .map_err(io)?;
        records.start(label);
        for (r, known) in rows[*a..*b].iter().zip(&angles[*a..*b]) {
            write_row(&mut rec, &mut records, (label, &step.key), r, *known, &site).map_err(io)?;
        }
        let t1 = rows[b - 1].time_s + 0.5;
        rec.step(&crate::sequencer::events::step_event(
            t1,
            StepPhase::End,
            index,
            step,
        ))
        .map_err(io)?;
        rec.event(t1, Level::Debug, &format!("end of step {}", step.key))
            .map_err(io)?;
    }
    let end_s = rows.last().map_or(0.0, |r| r.time_s + 0.5);
    // Judged as its replay judges it: the procedure's rule, no declared
    // uncertainties of the bench it came from.
    let judging = measure::Judging {
        rule: procedure.meta.decision_rule,
        ..measure::Judging::default()
    };
    let measurements = write_measures(
        &mut rec,
        &steps[step_at..],
        setup + step_at,
        &records,
        (end_s, &judging),
    )
    .map_err(io)?;
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
    rec.finish_run(&ResultMeta::new(&result), None, end_s)
        .map_err(io)?;
    Ok((outcome, measurements))
}

/// One imported row as the tick and 1 Hz interval a run logs, in record
/// `label` of step `step_key`, filed in `records` too.
fn write_row(
    rec: &mut Recorder,
    records: &mut Records,
    (label, step_key): (&str, &str),
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
    rec.tick(&tick, Some(label), step_key)?;
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
    records.push(iv, Some(label));
    rec.interval(&iv, Some(label))
}

/// The measure steps of `steps` (the first at index `first`), computed on
/// `records` and logged at `end_s` as a run logs them.
fn write_measures(
    rec: &mut Recorder,
    steps: &[&Step],
    first: usize,
    records: &Records,
    (end_s, judging): (f64, &measure::Judging),
) -> std::io::Result<Vec<measure::Measurement>> {
    let mut measurements = Vec::new();
    for (i, step) in steps.iter().enumerate() {
        if let StepKind::Measure(m) = &step.kind {
            let index = first + i;
            rec.step(&crate::sequencer::events::step_event(
                end_s,
                StepPhase::Start,
                index,
                step,
            ))?;
            rec.event(end_s, Level::Debug, &step.start_message())?;
            let meas = measure::compute(m, records, None, &step.key, judging);
            rec.event(
                end_s,
                if meas.outcome == MeasureOutcome::Pass {
                    Level::Info
                } else {
                    Level::Warning
                },
                &format!(
                    "{} = {}",
                    meas.name,
                    meas.value.map_or("n/a".into(), |v| format!("{v:.4}"))
                ),
            )?;
            rec.step(&crate::sequencer::events::step_event(
                end_s,
                StepPhase::End,
                index,
                step,
            ))?;
            rec.event(end_s, Level::Debug, &format!("end of step {}", step.key))?;
            measurements.push(meas);
        }
    }
    Ok(measurements)
}

/// What an export wrote.
#[derive(Debug, Clone)]
pub struct Exported {
    /// Rows written.
    pub rows: usize,
    /// How the read of the log went (complete or truncated).
    pub read: ReadSummary,
    /// Damaged parts of the log skipped (rows missing), in words.
    pub damage: Option<String>,
}

/// Write every 1 Hz interval of the log at `log` as interchange CSV at
/// `out`; `step` is the record label, or the procedure step while not
/// recording. A log with no interval at all is an error, and leaves no file.
pub fn export(log: &Path, out: &Path) -> Result<Exported, ImportError> {
    export_unit(log, out, None)
}

/// [`export`] of unit `unit` (a serial) of a batch's log (`super::view`).
pub fn export_unit(log: &Path, out: &Path, unit: Option<&str>) -> Result<Exported, ImportError> {
    ensure_distinct(out, &[log])?;
    let mut pending =
        Pending::output(out).map_err(|e| ImportError::Other(format!("{}: {e}", out.display())))?;
    let tmp = pending.path().to_owned();
    let err = |e: &dyn std::fmt::Display| format!("writing {}: {e}", tmp.display());
    let file = pending
        .take_file()
        .map_err(|e| ImportError::Other(err(&e)))?;
    let mut w = csv::Writer::from_writer(std::io::BufWriter::new(file));
    w.write_record(interchange::HEADER)
        .map_err(|e| ImportError::Other(err(&e)))?;
    let mut table: Option<TableState> = None;
    let mut rows = 0usize;
    let mut saw_run = false;
    let mut start_ns = None;
    let read = super::view::read_unit(log, unit, |item| {
        match item {
            Item::Meta { name, entries } if name == RUN_META => {
                saw_run = true;
                start_ns = start_ns.or_else(|| super::recover::part_start_ns(entries));
            }
            Item::Message { topic, data, .. } if topic == topics::TABLE => {
                table = Some(serde_json::from_slice(data).map_err(|e| format!("{topic}: {e}"))?);
            }
            Item::Message { topic, data, .. } if topic == topics::RATE_1HZ => {
                let r: Rate1Hz =
                    serde_json::from_slice(data).map_err(|e| format!("{topic}: {e}"))?;
                let Some(t) = &table else {
                    return Err("a 1 Hz interval before any table state".into());
                };
                let step = r.record.clone().unwrap_or_else(|| t.step.clone());
                w.write_record([
                    format!("{:.3}", r.t_s),
                    format!("{}", r.rate_dph),
                    format!("{}", r.t1_c),
                    format!("{}", r.t2_c),
                    format!("{}", r.tcase_c),
                    format!("{}", r.chamber_c),
                    format!("{}", t.azimuth_deg),
                    format!("{}", t.elevation_deg),
                    format!("{}", t.roll_deg),
                    step,
                ])
                .map_err(|e| err(&e))?;
                rows += 1;
            }
            _ => {}
        }
        Ok(())
    })?;
    let fail = |m: String| ImportError::Other(m);
    // `--unit` naming a unit the log lacks stopped the read: say so.
    if let (false, Some(why), Some(_)) = (saw_run, &read.stopped, unit) {
        return Err(fail(format!("{}: {why}", log.display())));
    }
    if !saw_run {
        return Err(fail(format!(
            "{}: not a gyrobench log (no run metadata){}",
            log.display(),
            read.trouble()
        )));
    }
    if let Some(why) = read.stopped.as_ref().filter(|_| read.complete) {
        return Err(fail(format!("{}: {why}", log.display())));
    }
    if rows == 0 {
        return Err(fail(format!(
            "{}: no 1 Hz interval in the log{}; nothing to export",
            log.display(),
            read.trouble()
        )));
    }
    w.flush().map_err(|e| fail(err(&e)))?;
    drop(w);
    pending.commit().map_err(|e| fail(err(&e)))?;
    let damage = read.damage(start_ns);
    Ok(Exported { rows, read, damage })
}
