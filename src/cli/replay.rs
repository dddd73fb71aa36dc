//! `gyrobench replay RUN.mcap [--coeffs FILE] [--out DIR]`: every
//! measurement and the verdict recomputed from a run's log alone.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::{Outcome, Usage};
use crate::clock::Stopwatch;
use crate::coeffs::Chosen;
use crate::report::{Report, render_html};
use crate::runlog::replay::replay_unit;

#[derive(Debug, Args)]
#[command(after_help = after_help!(
    "gyrobench replay runs/smoke/run.mcap",
    "0 the run passed, 3 it failed its limits, 1 error (an unreadable log, a run that ended in \
     error or was cut short), 2 usage (an --out that is a run directory, or inside another run's \
     directory without --force), 130 the run was interrupted"
))]
pub struct ReplayArgs {
    /// The run's log (live, recovered, truncated or imported).
    log: PathBuf,
    /// Model-4 coefficients to compensate with instead of the run's.
    #[arg(long)]
    coeffs: Option<PathBuf>,
    /// Where to write report.json and report.html (default: beside the log,
    /// in <log dir>/replay, the replay's own place in its run directory).
    /// Never a run directory itself; inside one (other than the default),
    /// only with --force.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write into an --out inside a run directory.
    #[arg(long)]
    force: bool,
    /// Also index the run in the results store (idempotent), and show in
    /// the report who reviewed and approved it there (`results sign`).
    #[arg(long)]
    store: bool,
    /// The results store (with --store): a SQLite file, a postgres:// URL
    /// (default: $GYROBENCH_DB, else ~/.local/share/gyrobench/results.sqlite).
    #[arg(long, value_name = "STORE", requires = "store")]
    db: Option<String>,
    /// A batch's unit to replay, by serial (default: every unit of a
    /// batch, each to report-SERIAL.json and .html).
    #[arg(long, value_name = "SERIAL")]
    unit: Option<String>,
}

pub fn run(args: ReplayArgs) -> Result<Outcome> {
    let out = out_dir(&args)?;
    let coeffs = match &args.coeffs {
        Some(p) => {
            let chosen = Chosen::from_file(p).context("loading the coefficient set")?;
            if chosen.compensation().is_none() {
                return Err(Usage(format!(
                    "{} holds no [model4]: a set of the scale factor alone compensates nothing",
                    p.display()
                ))
                .into());
            }
            Some(chosen)
        }
        None => None,
    };
    // A log that cannot be read says why in the replay itself.
    let units = crate::runlog::view::log_units(&args.log).unwrap_or_default();
    let batch = crate::runlog::view::is_batch(&units);
    if batch && args.unit.is_none() && coeffs.is_some() {
        return Err(Usage(
            "--coeffs is one unit's set: give the batch's unit it is for with --unit SERIAL".into(),
        )
        .into());
    }
    let serials: Vec<Option<String>> = match (&args.unit, batch) {
        (Some(u), _) => vec![Some(u.clone())],
        (None, true) => units.into_iter().map(|(_, serial)| Some(serial)).collect(),
        (None, false) => vec![None],
    };
    // The log's exit code is its worst unit's.
    let rank = |o: &Outcome| match o {
        Outcome::Success => 0,
        Outcome::ConditionalPass => 1,
        Outcome::Fail => 2,
        Outcome::Error => 3,
        _ => 4,
    };
    let mut worst = Outcome::Success;
    for serial in &serials {
        let o = replay_one(&args, &out, coeffs.as_ref(), serial.as_deref(), batch)?;
        if rank(&o) > rank(&worst) {
            worst = o;
        }
    }
    if args.store {
        let loc = crate::results::Location::resolve(args.db.as_deref(), None);
        if let Some(mut s) = crate::results::Store::open(&loc)? {
            let done = s.index_log(&args.log)?;
            errln!("{done:?} in the results store {}", s.name());
        }
    }
    Ok(worst)
}

/// Where the reports go: `--out`, or `<log dir>/replay`, the replay's own
/// place in the run's directory. A run directory itself never (it keeps
/// the run's own report); inside one, the default or with `--force`.
fn out_dir(args: &ReplayArgs) -> Result<PathBuf> {
    let own = args
        .log
        .parent()
        .map_or_else(|| PathBuf::from("replay"), |d| d.join("replay"));
    let out = args.out.clone().unwrap_or_else(|| own.clone());
    if crate::session::rundir::is_run_dir(&out) {
        return Err(Usage(format!(
            "{} is a run directory (it holds run.mcap or run.lock): replay writes its report \
             elsewhere; choose another --out",
            out.display()
        ))
        .into());
    }
    crate::fsutil::check_output(
        &out,
        crate::fsutil::OutputRule {
            inputs: &[],
            force: args.force,
            own: Some(&own),
        },
    )?;
    Ok(out)
}

/// Replay one unit (`serial`; none: the log as written) and write its
/// report into `out`: `report.json` and `.html`, or for a batch's unit
/// `report-SERIAL.json` and `.html`, the names its run wrote.
fn replay_one(
    args: &ReplayArgs,
    out: &std::path::Path,
    coeffs: Option<&crate::coeffs::Chosen>,
    serial: Option<&str>,
    batch: bool,
) -> Result<Outcome> {
    let coeffs = coeffs.and_then(Chosen::compensation);
    let watch = Stopwatch::start();
    let r = replay_unit(&args.log, coeffs.as_ref(), serial)?;
    let secs = watch.elapsed_s();
    super::warn_incomplete(
        &args.log,
        &r.read,
        &format!("read up to {:.0} s of device time", r.last_state_s),
    );
    if let Some(d) = r.read.damage(r.meta.part_start_ns()) {
        errln!(
            "error: {}: {d}; the report says so, and its figures lack these",
            args.log.display()
        );
    }
    if r.result.frames == 0 {
        errln!(
            "replayed {} intervals in {secs:.2} s (no frames: an imported run)",
            r.result.records.intervals()
        );
    } else {
        errln!(
            "replayed {} frames in {secs:.2} s ({:.1} M frames/s)",
            r.result.frames,
            r.result.frames as f64 / secs.max(1e-9) / 1e6
        );
    }
    let mut report = Report::new(&r.procedure, &r.result, &r.meta, r.link);
    if r.meta.imported_from.is_some() {
        // No moves in an imported run's procedure: its records' poses are
        // the orientations the file gave.
        report.positions = crate::report::Position::logged(&r.procedure, &r.poses);
    }
    if let Some(c) = &coeffs {
        report.coefficients = c.used.clone();
    }
    if args.store {
        let loc = crate::results::Location::resolve(args.db.as_deref(), None);
        if let Some(mut s) = crate::results::Store::open(&loc)? {
            report.signatures = s.signatures(&format!("{}.{}", r.meta.run_id, r.meta.part))?;
        }
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let name = match serial.filter(|_| batch) {
        Some(s) => crate::unit::report_name(s),
        None => "report".to_owned(),
    };
    for (name, bytes) in [
        (format!("{name}.json"), report.to_json()),
        (
            format!("{name}.html"),
            render_html(&report, &r.result.records),
        ),
    ] {
        let path = out.join(name);
        crate::fsutil::write_atomic(&path, bytes.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    outf!("{}", report.render_text())?;
    errln!("report in {}", out.display());
    Ok(Outcome::of_run(r.result.outcome, 130))
}
