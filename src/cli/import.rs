//! `gyrobench import RUN.csv --site SITE.toml -o RUN.mcap` and
//! `gyrobench export RUN.mcap -o RUN.csv`: runs recorded elsewhere, in the
//! interchange CSV, in and out.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::{Outcome, Usage};
use gyrobench::fsutil::{OutputRule, check_output};
use gyrobench::runlog::exchange::{ImportOptions, export_unit, import, load_site, sidecar};

#[derive(Debug, Args)]
#[command(after_help = after_help!(
    "gyrobench import fixtures/import/lab-run.csv --site fixtures/import/site.toml -o lab-run.mcap\n  \
     gyrobench import fixtures/import/iso-dps-kelvin.csv --map fixtures/import/iso-dps-kelvin.map.toml \
     --site fixtures/import/site.toml -o iso.mcap\n  \
     gyrobench import run.csv -o back.mcap   (an export: run.export.toml beside it gives the procedure, unit and site)",
    "0 the log is written, whatever its figures (they are for reference: `replay` of the log \
     gives the verdict), 1 error (a bad row, site file or sidecar, a sidecar of another run, I/O), \
     2 usage (no --site and no sidecar, a bad --dut or --type, an output that is an input, or a \
     run's log or in a run directory without --force)"
))]
pub struct ImportArgs {
    /// Interchange CSV (docs/analysis.md, "Interchange CSV"), or a lab's
    /// own file with --map. The sidecar `export` wrote beside it
    /// (RUN.export.toml beside RUN.csv) is read when it is there: its
    /// procedure judges the rows, its unit, site and coefficients are the
    /// run's unless the flags below say otherwise.
    csv: PathBuf,
    /// An import map (TOML) saying how to read a lab's own file: which
    /// column is time, rate, temperatures, orientation and step, in which
    /// units (docs/analysis.md, "Import maps"; examples in fixtures/import/).
    #[arg(long)]
    map: Option<PathBuf>,
    /// Where the run stood: a TOML file with a `[site]` table (and
    /// optionally the table's `[table.geometry]`). Required unless a
    /// sidecar gives it; given with one, it replaces the sidecar's.
    #[arg(long)]
    site: Option<PathBuf>,
    /// Serial number of the unit (default: the sidecar's; without one,
    /// UNNAMED, which names no unit: give the serial to file the run under
    /// its unit).
    #[arg(long)]
    dut: Option<String>,
    /// Type of the unit (default: the sidecar's; without one, `gyro`). A
    /// unit's runs are one unit's only with one type: give the type its
    /// own runs record (`RL-16`) to diagnose or calibrate them together.
    #[arg(long = "type", value_name = "TYPE")]
    dut_type: Option<String>,
    /// The log to write (an existing log, or a path inside a run
    /// directory, is refused without --force).
    #[arg(short, long)]
    out: PathBuf,
    /// Write the --out even if it is a run's log or inside a run
    /// directory.
    #[arg(long)]
    force: bool,
    /// The results store the imported run is recorded in: a SQLite file,
    /// a postgres:// URL or `none` (default: $GYROBENCH_DB, else
    /// ~/.local/share/gyrobench/results.sqlite).
    #[arg(long, value_name = "STORE")]
    db: Option<String>,
}

#[derive(Debug, Args)]
#[command(after_help = after_help!("gyrobench export runs/smoke/run.mcap -o run.csv", plain))]
pub struct ExportArgs {
    /// Any run log (live, simulated or imported).
    log: PathBuf,
    /// The CSV to write (an existing log, or a path inside a run
    /// directory, is refused without --force). Its sidecar, RUN.export.toml beside
    /// RUN.csv, is written with it: the run's procedure, unit, site and
    /// coefficients, which `import` reads back.
    #[arg(short, long)]
    out: PathBuf,
    /// Write the --out even if it is a run's log or inside a run
    /// directory.
    #[arg(long)]
    force: bool,
    /// A batch's unit, by serial (default: the batch's first unit).
    #[arg(long, value_name = "SERIAL")]
    unit: Option<String>,
}

pub fn run_import(args: ImportArgs) -> Result<Outcome> {
    if let Some(d) = &args.dut {
        gyrobench::unit::check_serial(d).map_err(|e| Usage(format!("--dut {d:?}: {e}")))?;
    }
    if let Some(t) = &args.dut_type {
        gyrobench::unit::check_type(t).map_err(|e| Usage(format!("--type {t:?}: {e}")))?;
    }
    let side = sidecar::path_for(&args.csv);
    if args.site.is_none() && !side.is_file() {
        return Err(Usage(format!(
            "give --site SITE.toml, where the run stood: no sidecar {} beside {} gives it",
            side.display(),
            args.csv.display()
        ))
        .into());
    }
    let mut inputs = vec![args.csv.as_path()];
    inputs.extend(args.site.as_deref());
    inputs.extend(args.map.as_deref());
    inputs.extend(side.is_file().then_some(side.as_path()));
    check_output(
        &args.out,
        OutputRule {
            inputs: &inputs,
            force: args.force,
            own: None,
        },
    )?;
    let site = match &args.site {
        Some(p) => Some(load_site(p).context("reading the site file")?),
        None => None,
    };
    let map = match &args.map {
        Some(m) => Some(gyrobench::runlog::import_map::load(m).context("reading the import map")?),
        None => None,
    };
    let opts = ImportOptions {
        site: site.as_ref(),
        dut: args.dut.as_deref(),
        dut_type: args.dut_type.as_deref(),
        map: map.as_ref(),
    };
    let r = import(&args.csv, &opts, &args.out)?;
    let loc = gyrobench::results::Location::resolve(args.db.as_deref(), None);
    match gyrobench::results::Store::open(&loc).and_then(|s| match s {
        Some(mut s) => s.index_log(&args.out).map(|_| Some(s.name().to_owned())),
        None => Ok(None),
    }) {
        Ok(Some(name)) => errln!("recorded in the results store {name}"),
        Ok(None) => {}
        Err(e) => {
            errln!("warning: {e}; the log is written; `gyrobench results sync` indexes it later")
        }
    }
    outf!("{}", render_import(&r, &args.out))?;
    // The import did its job whatever the figures are: they are for
    // reference, and `replay` gives the run's verdict.
    Ok(Outcome::Success)
}

pub fn run_export(args: ExportArgs) -> Result<Outcome> {
    check_output(
        &args.out,
        OutputRule {
            inputs: &[&args.log],
            force: args.force,
            own: None,
        },
    )?;
    // The sidecar written beside the CSV is an output too.
    let side = sidecar::path_for(&args.out);
    check_output(
        &side,
        OutputRule {
            inputs: &[&args.log],
            force: args.force,
            own: None,
        },
    )?;
    let done = export_unit(&args.log, &args.out, args.unit.as_deref())?;
    super::warn_incomplete(&args.log, &done.read, "exported what it holds");
    outln!(
        "exported {} rows (1 Hz) to {}",
        done.rows,
        args.out.display()
    )?;
    match &done.sidecar {
        Ok(p) => outln!(
            "with its sidecar {} (the run's procedure, unit, site and coefficients, for import)",
            p.display()
        )?,
        Err(why) => errln!(
            "warning: no sidecar beside {} ({why}): an import of it is judged by a procedure made from its rows",
            args.out.display()
        ),
    }
    if let Some(d) = &done.damage {
        errln!(
            "error: {}: {d}; the CSV holds every other row, and lacks these",
            args.log.display()
        );
        return Ok(Outcome::Error);
    }
    Ok(Outcome::Success)
}

/// What `import` made, and the figures it could compute at the
/// acceptance's limits: for reference, never a verdict (the run was not an
/// acceptance; `replay` judges the log as a run).
pub fn render_import(r: &gyrobench::runlog::exchange::Imported, out: &std::path::Path) -> String {
    use gyrobench::sequencer::measure::MeasureOutcome;
    let mut s = format!(
        "imported {} s of 1 Hz data in {} record(s) into {}{}\n",
        r.intervals,
        r.records.len(),
        out.display(),
        if r.unrecorded > 0 {
            format!(" ({} s outside records: moves, waits, soaks)", r.unrecorded)
        } else {
            String::new()
        }
    );
    s.push_str(&match &r.sidecar {
        Some(p) => format!(
            "judged by the run's own procedure, from its sidecar {}\n",
            p.display()
        ),
        None => "judged by a procedure made from its rows\n".to_owned(),
    });
    s.push_str(&if r.serial == gyrobench::unit::UNNAMED_SERIAL {
        format!(
            "unit: {} {} (names no unit: give --dut SERIAL to file the run under its unit)\n",
            r.dut_type, r.serial
        )
    } else {
        format!("unit: {} {}\n", r.dut_type, r.serial)
    });
    if r.measurements.is_empty() {
        s.push_str("no figure of the acceptance can be computed from these data\n");
        return s;
    }
    s.push_str(&if r.sidecar.is_some() {
        format!(
            "figures judged at its procedure's limits, for reference (an import gives no verdict; \
             `gyrobench replay {}` judges the log as a run):\n",
            out.display()
        )
    } else {
        format!(
            "figures judged at the acceptance's limits, for reference (this run was not an acceptance; \
             `gyrobench replay {}` judges the log as a run):\n",
            out.display()
        )
    });
    for m in &r.measurements {
        let against = match (m.outcome, m.value) {
            (MeasureOutcome::Pass, _) => "within",
            (MeasureOutcome::Fail, Some(_)) => "beyond",
            (MeasureOutcome::Fail, None) => "not computable",
            (MeasureOutcome::Error, _) => "not judged (unsound data)",
            (MeasureOutcome::ConditionalPass, _) => "within, by less than its uncertainty",
            (MeasureOutcome::ConditionalFail, _) => "beyond, by less than its uncertainty",
        };
        s.push_str(&format!(
            "  {:<32} {:>10} {:<6} [{}]  {against}\n",
            m.name,
            m.value.map_or("n/a".to_owned(), |v| format!("{v:.4}")),
            m.unit,
            m.limits_text(),
        ));
        if !m.note.is_empty() {
            s.push_str(&format!("    {}\n", m.note));
        }
    }
    s
}
