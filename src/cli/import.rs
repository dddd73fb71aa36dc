//! `gyrobench import RUN.csv --site SITE.toml -o RUN.mcap` and
//! `gyrobench export RUN.mcap -o RUN.csv`: runs recorded elsewhere, in the
//! interchange CSV, in and out.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::{Outcome, Usage};
use crate::fsutil::{OutputRule, check_output};
use crate::runlog::exchange::{export_unit, import, import_mapped, load_site};

#[derive(Debug, Args)]
#[command(after_help = after_help!(
    "gyrobench import fixtures/import/lab-run.csv --site fixtures/import/site.toml -o lab-run.mcap\n  \
     gyrobench import fixtures/import/iso-dps-kelvin.csv --map fixtures/import/iso-dps-kelvin.map.toml \
     --site fixtures/import/site.toml -o iso.mcap",
    "0 the log is written, whatever its figures (they are for reference: `replay` of the log \
     gives the verdict), 1 error (a bad row or site file, I/O), 2 usage (an output that is an \
     input, or a run's log or in a run directory without --force)"
))]
pub struct ImportArgs {
    /// Interchange CSV (docs/analysis.md, "Interchange CSV"), or a lab's
    /// own file with --map.
    csv: PathBuf,
    /// An import map (TOML) saying how to read a lab's own file: which
    /// column is time, rate, temperatures, orientation and step, in which
    /// units (docs/analysis.md, "Import maps"; examples in fixtures/import/).
    #[arg(long)]
    map: Option<PathBuf>,
    /// Where the run stood: a TOML file with a `[site]` table.
    #[arg(long)]
    site: PathBuf,
    /// Serial number of the unit (default: the CSV's file name without
    /// its extension).
    #[arg(long)]
    dut: Option<String>,
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
    /// directory, is refused without --force).
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
        crate::unit::check_serial(d).map_err(|e| Usage(format!("--dut {d:?}: {e}")))?;
    }
    let mut inputs = vec![args.csv.as_path(), args.site.as_path()];
    inputs.extend(args.map.as_deref());
    check_output(
        &args.out,
        OutputRule {
            inputs: &inputs,
            force: args.force,
            own: None,
        },
    )?;
    let site = load_site(&args.site).context("reading the site file")?;
    let r = match &args.map {
        Some(m) => {
            let map = crate::runlog::import_map::load(m).context("reading the import map")?;
            import_mapped(&args.csv, &map, &site, args.dut.as_deref(), &args.out)?
        }
        None => import(&args.csv, &site, args.dut.as_deref(), &args.out)?,
    };
    let loc = crate::results::Location::resolve(args.db.as_deref(), None);
    match crate::results::Store::open(&loc).and_then(|s| match s {
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
    let done = export_unit(&args.log, &args.out, args.unit.as_deref())?;
    super::warn_incomplete(&args.log, &done.read, "exported what it holds");
    outln!(
        "exported {} rows (1 Hz) to {}",
        done.rows,
        args.out.display()
    )?;
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
pub fn render_import(r: &crate::runlog::exchange::Imported, out: &std::path::Path) -> String {
    use crate::sequencer::measure::MeasureOutcome;
    let mut s = format!(
        "imported {} s of 1 Hz data in {} record(s) into {}\n",
        r.intervals,
        r.records.len(),
        out.display()
    );
    if r.measurements.is_empty() {
        s.push_str("no figure of the acceptance can be computed from these data\n");
        return s;
    }
    s.push_str(&format!(
        "figures judged at the acceptance's limits, for reference (this run was not an acceptance; \
         `gyrobench replay {}` judges the log as a run):\n",
        out.display()
    ));
    for m in &r.measurements {
        let against = match (m.outcome, m.value) {
            (MeasureOutcome::Pass, _) => "within",
            (MeasureOutcome::Fail, Some(_)) => "beyond",
            (MeasureOutcome::Fail, None) => "not computable",
            (MeasureOutcome::Error, _) => "not judged (unsound data)",
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
