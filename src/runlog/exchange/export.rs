//! `export`: any log as the interchange CSV at 1 Hz, with its sidecar.

use std::path::{Path, PathBuf};

use super::super::interchange::{self, RECORD_COLUMN, TABLE_COLUMNS};
use super::super::meta::RunMeta;
use super::super::reader::{Item, ReadSummary};
use super::super::schema::{RUN_META, Rate1Hz, TableState, topics};
use super::ImportError;
use super::sidecar::{self, Sidecar};
use crate::fsutil::{Pending, ensure_distinct};

/// What an export wrote.
#[derive(Debug, Clone)]
pub struct Exported {
    /// Rows written.
    pub rows: usize,
    /// How the read of the log went (complete or truncated).
    pub read: ReadSummary,
    /// Damaged parts of the log skipped (rows missing), in words.
    pub damage: Option<String>,
    /// The sidecar written beside the CSV, or why there is none.
    pub sidecar: Result<PathBuf, String>,
}

/// Write every 1 Hz interval of the log at `log` as interchange CSV at
/// `out`, and its sidecar beside it (see [`export_unit`]).
pub fn export(log: &Path, out: &Path) -> Result<Exported, ImportError> {
    export_unit(log, out, None)
}

/// The CSV's columns: the ten, the table's angles where the log knows
/// them, and the record each row was recorded in (empty outside records).
fn header() -> Vec<&'static str> {
    interchange::HEADER
        .iter()
        .chain(&TABLE_COLUMNS)
        .chain(&[RECORD_COLUMN])
        .copied()
        .collect()
}

/// One interval as a CSV row, in the table state `t` before it.
fn row(r: &Rate1Hz, t: &TableState) -> [String; 13] {
    let opt = |v: Option<f64>| v.map_or_else(String::new, |v| format!("{v}"));
    let (outer, inner) = match (t.outer_deg, t.inner_deg) {
        (Some(o), Some(i)) => (Some(o), Some(i)),
        _ => (None, None),
    };
    [
        format!("{:.3}", r.t_s),
        format!("{}", r.rate_dph),
        format!("{}", r.t1_c),
        format!("{}", r.t2_c),
        format!("{}", r.tcase_c),
        format!("{}", r.chamber_c),
        format!("{}", t.azimuth_deg),
        format!("{}", t.elevation_deg),
        format!("{}", t.roll_deg),
        r.record.clone().unwrap_or_else(|| t.step.clone()),
        opt(outer),
        opt(inner),
        r.record.clone().unwrap_or_default(),
    ]
}

/// [`export`] of unit `unit` (a serial) of a batch's log (`super::view`):
/// `step` is the record label while recording, else the procedure step's
/// key; `record` the record label, empty outside records; the table's
/// angles where the log has them. Beside the CSV, its sidecar
/// (`RUN.export.toml`, [`sidecar`]) carries the run's procedure, unit,
/// site and coefficients; a log whose metadata cannot make one is
/// exported without it (`Exported::sidecar` says why). A log with no
/// interval at all is an error, and leaves no file.
pub fn export_unit(log: &Path, out: &Path, unit: Option<&str>) -> Result<Exported, ImportError> {
    let side_path = sidecar::path_for(out);
    ensure_distinct(out, &[log])?;
    ensure_distinct(&side_path, &[log])?;
    let mut pending =
        Pending::output(out).map_err(|e| ImportError::Other(format!("{}: {e}", out.display())))?;
    let tmp = pending.path().to_owned();
    let err = |e: &dyn std::fmt::Display| format!("writing {}: {e}", tmp.display());
    let file = pending
        .take_file()
        .map_err(|e| ImportError::Other(err(&e)))?;
    let mut w = csv::Writer::from_writer(std::io::BufWriter::new(file));
    w.write_record(header())
        .map_err(|e| ImportError::Other(err(&e)))?;
    let mut table: Option<TableState> = None;
    let mut rows = 0usize;
    // The run metadata, or why it does not read (the rows export anyway;
    // only the sidecar needs it).
    let mut meta: Option<Result<RunMeta, String>> = None;
    let mut angles_known = false;
    let mut start_ns = None;
    let read = super::super::view::read_unit(
        log,
        unit,
        crate::runlog::refusing(|item| {
            match item {
                Item::Meta { name, entries } if name == RUN_META => {
                    start_ns = start_ns.or_else(|| super::super::recover::part_start_ns(entries));
                    if meta.is_none() {
                        meta = Some(RunMeta::from_entries(entries).map_err(|e| e.to_string()));
                    }
                }
                Item::Message { topic, data, .. } if topic == topics::TABLE => {
                    let t: TableState =
                        serde_json::from_slice(data).map_err(|e| format!("{topic}: {e}"))?;
                    angles_known |= t.outer_deg.is_some() && t.inner_deg.is_some();
                    table = Some(t);
                }
                Item::Message { topic, data, .. } if topic == topics::RATE_1HZ => {
                    let r: Rate1Hz =
                        serde_json::from_slice(data).map_err(|e| format!("{topic}: {e}"))?;
                    let Some(t) = &table else {
                        return Err("a 1 Hz interval before any table state".into());
                    };
                    w.write_record(row(&r, t)).map_err(|e| err(&e))?;
                    rows += 1;
                }
                _ => {}
            }
            Ok::<(), String>(())
        }),
    )?;
    let fail = |m: String| ImportError::Other(m);
    // `--unit` naming a unit the log lacks stopped the read: say so.
    if let (None, Some(why), Some(_)) = (&meta, &read.stopped, unit) {
        return Err(fail(format!("{}: {why}", log.display())));
    }
    let Some(meta) = meta else {
        return Err(fail(format!(
            "{}: not a gyrobench log (no run metadata){}",
            log.display(),
            read.trouble()
        )));
    };
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
    // A CSV written to a pipe or a device has no place beside it.
    let to_file = match std::fs::metadata(out) {
        Ok(m) => m.is_file(),
        Err(_) => true,
    };
    let side = if to_file {
        meta.and_then(|m| side_text(&m, angles_known, out, log))
    } else {
        Err(format!("{} is not a file", out.display()))
    };
    let side_pending = match &side {
        Ok(text) => Some(write_side(&side_path, text)?),
        Err(_) => None,
    };
    pending.commit().map_err(|e| fail(err(&e)))?;
    if let Some(p) = side_pending {
        p.commit()
            .map_err(|e| fail(format!("writing {}: {e}", side_path.display())))?;
    }
    let damage = read.damage(start_ns);
    Ok(Exported {
        rows,
        read,
        damage,
        sidecar: side.map(|_| side_path),
    })
}

/// The sidecar's text for the run `meta` (the geometry of its logged
/// bench when its table states carry angles), or why there is none.
fn side_text(meta: &RunMeta, angles_known: bool, out: &Path, log: &Path) -> Result<String, String> {
    let geometry = if angles_known {
        Some(
            super::super::replay::logged_bench(meta)
                .map_err(|e| e.to_string())?
                .table
                .geometry,
        )
    } else {
        None
    };
    Sidecar::of_run(meta, geometry, out, log)
        .map_err(|e| e.to_string())?
        .to_toml()
        .map_err(|e| e.to_string())
}

/// The sidecar at `path`, written to its temporary, to be committed with
/// the CSV.
fn write_side(path: &Path, text: &str) -> Result<Pending, ImportError> {
    let io = |e: std::io::Error| ImportError::Other(format!("writing {}: {e}", path.display()));
    let mut p = Pending::output(path).map_err(io)?;
    let mut f = p.take_file().map_err(io)?;
    std::io::Write::write_all(&mut f, text.as_bytes()).map_err(io)?;
    f.sync_all().map_err(io)?;
    Ok(p)
}
