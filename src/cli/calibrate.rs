//! `gyrobench calibrate RUN.mcap... -o COEFFS.toml`: fit the compensation
//! models on recorded runs, validate on held-out runs, write coefficients;
//! rate-table runs among them give the scale factor and its temperature
//! coefficient (`[scale_factor]`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::{Outcome, Usage};
use crate::calibrate::{
    ABSURD_OVER_RAW, Calibration, calibrate, load_unit, mixed_serials, scale_factor,
};
use crate::coeffs::{CoefficientSet, FittedOn, SetSection, UnitSection};
use crate::fsutil::{OutputRule, check_output};

#[derive(Debug, Args)]
#[command(after_help = after_help!(
    "gyrobench calibrate runs/c1/run.mcap runs/c2/run.mcap -o unit.toml",
    "0 coefficients written, 1 error (unreadable runs, runs too short or of different units, a \
     fit that is not plausible), 2 usage (one run given twice, an output that is an input, a \
     run's log or in a run directory without --force)"
))]
pub struct CalibrateArgs {
    /// Run logs (.mcap) of one unit: thermal runs for the compensation
    /// (two or more for held-out validation), rate-table runs for the
    /// scale factor and its temperature coefficient.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// Coefficients file to write (the format `run --coeffs` reads);
    /// COEFFS.calibration.json and .html go beside it. None of them may
    /// be a run's log or inside a run directory (without --force).
    #[arg(short, long)]
    out: PathBuf,
    /// Write the outputs even if one is a run's log or inside a run
    /// directory.
    #[arg(long)]
    force: bool,
    /// Fit runs of units with different serial numbers together (refused
    /// otherwise: coefficients belong to one unit).
    #[arg(long)]
    allow_mixed_serials: bool,
    /// The results store the coefficient set is recorded in (one unit's
    /// runs only): a SQLite file, a postgres:// URL or `none` (default:
    /// $GYROBENCH_DB, else ~/.local/share/gyrobench/results.sqlite).
    #[arg(long, value_name = "STORE")]
    db: Option<String>,
    /// A batch's unit, by serial, in every log given (default: each log's
    /// first unit).
    #[arg(long, value_name = "SERIAL")]
    unit: Option<String>,
}

pub fn run(args: CalibrateArgs) -> Result<Outcome> {
    let json_path = args.out.with_extension("calibration.json");
    let html_path = args.out.with_extension("calibration.html");
    let inputs: Vec<&std::path::Path> = args.runs.iter().map(PathBuf::as_path).collect();
    for out in [&args.out, &json_path, &html_path] {
        check_output(
            out,
            OutputRule {
                inputs: &inputs,
                force: args.force,
                own: None,
            },
        )?;
    }
    let runs = args
        .runs
        .iter()
        .map(|p| load_unit(p, args.unit.as_deref()).map_err(anyhow::Error::from))
        .collect::<Result<Vec<_>>>()?;
    refuse_repeats(&runs)?;
    let mixed = mixed_serials(&runs);
    if !mixed.is_empty() && !args.allow_mixed_serials {
        anyhow::bail!(
            "the runs are of different units: {}; coefficients belong to one unit (give --allow-mixed-serials to fit them together anyway)",
            mixed.join(", ")
        );
    }
    // Rate runs give the scale factor; thermal runs the compensation.
    let sf = scale_factor(&runs);
    let thermal: Vec<crate::calibrate::RunSeries> = runs
        .iter()
        .filter(|r| !r.series.is_empty())
        .cloned()
        .collect();
    let mut cal = if thermal.is_empty() && sf.is_some() {
        None
    } else {
        let fitted = if thermal.is_empty() { &runs } else { &thermal };
        Some(fit(fitted)?)
    };
    let mut set = cal
        .as_ref()
        .map_or_else(CoefficientSet::default, Calibration::coefficient_set);
    set.scale_factor = sf;
    describe_set(&mut set, &args.runs, &runs, mixed.is_empty())?;
    // The store gives the set its version before the file is written, so
    // the file and the store hold the same text.
    let text = match (&set.unit, &cal) {
        (Some(_), Some(c)) => record(&args, &mut set, c)?,
        (Some(_), None) => record_scale_factor(&args, &mut set)?,
        (None, _) => set
            .to_toml()
            .context("writing the coefficient set as TOML")?,
    };
    crate::fsutil::write_output(&args.out, text.as_bytes())
        .with_context(|| format!("writing {}", args.out.display()))?;
    let Some(cal) = cal.as_mut() else {
        if let Some(sf) = &sf {
            outf!("{}", sf.render_text())?;
        }
        errln!(
            "scale factor in {} (rate runs only: give thermal runs too for compensation coefficients)",
            args.out.display()
        );
        return Ok(Outcome::Success);
    };
    cal.unit = set.unit.clone();
    cal.set = set.set.clone();
    crate::fsutil::write_output(&json_path, serde_json::to_string_pretty(&cal)?.as_bytes())
        .with_context(|| format!("writing {}", json_path.display()))?;
    crate::fsutil::write_output(&html_path, cal.render_html().as_bytes())
        .with_context(|| format!("writing {}", html_path.display()))?;
    outf!("{}", cal.render_text())?;
    if let Some(sf) = &sf {
        outf!("{}", sf.render_text())?;
    }
    errln!(
        "coefficients ({}) in {}, details in {} and {}",
        set.describe(),
        args.out.display(),
        json_path.display(),
        html_path.display()
    );
    Ok(Outcome::Success)
}

/// Each run once: one run given twice (or a copy of it) would validate the
/// fit on its own data, and held-out figures would be a lie.
fn refuse_repeats(runs: &[crate::calibrate::RunSeries]) -> Result<()> {
    for (i, a) in runs.iter().enumerate() {
        for b in &runs[..i] {
            let same_file =
                std::fs::canonicalize(&a.name).ok() == std::fs::canonicalize(&b.name).ok();
            let same_run = !a.run_id.is_empty() && a.run_id == b.run_id;
            if same_file || same_run {
                return Err(Usage(format!(
                    "{} and {} are the same run{}; give each run once (held-out validation needs different runs)",
                    b.name,
                    a.name,
                    if same_run {
                        format!(" (run id {})", a.run_id)
                    } else {
                        String::new()
                    }
                ))
                .into());
            }
        }
    }
    Ok(())
}

/// The set's unit (when the runs are of `one_unit`) and its provenance:
/// when, by what software, which models, fitted on which runs (`paths`).
fn describe_set(
    set: &mut CoefficientSet,
    paths: &[PathBuf],
    runs: &[crate::calibrate::RunSeries],
    one_unit: bool,
) -> Result<()> {
    set.unit = match (one_unit, runs.first()) {
        (true, Some(first)) => Some(UnitSection {
            serial: first.serial.clone(),
            dut_type: first.dut_type.clone(),
        }),
        _ => None,
    };
    set.set = Some(SetSection {
        version: None,
        created_utc: crate::clock::utc_now().to_rfc3339(),
        software: crate::version::software(),
        models: [
            ("model4", set.model4.is_some()),
            ("model3", set.model3.is_some()),
            ("model1", set.model1.is_some()),
            ("scale_factor", set.scale_factor.is_some()),
        ]
        .iter()
        .filter(|(_, has)| *has)
        .map(|(m, _)| (*m).to_owned())
        .collect(),
        fitted_on: fitted_on(paths, runs)?,
    });
    Ok(())
}

/// Fit the compensation models on the thermal runs, refusing fits that
/// cannot be scored or are not plausible.
fn fit(runs: &[crate::calibrate::RunSeries]) -> Result<Calibration> {
    let cal = calibrate(runs).context("fitting the compensation models")?;
    let scored = cal
        .table
        .iter()
        .find(|r| r.model == "model4")
        .is_some_and(|r| r.held_out.unwrap_or(r.in_sample).drift_pp_dph.is_finite());
    if !scored {
        let longest = runs.iter().map(|r| r.series.len()).max().unwrap_or(0);
        anyhow::bail!(
            "the runs are too short to score a drift: the longest holds {longest} s of recorded data, \
             and the drift is the p-p of the residual smoothed over {:.0} s; calibrate on thermal \
             runs (procedures/acceptance.toml); no coefficients written",
            crate::analysis::study::DRIFT_SMOOTHING_S
        );
    }
    let absurd = cal.absurd();
    if !absurd.is_empty() {
        anyhow::bail!(
            "the fit is not plausible: held out, it is more than {ABSURD_OVER_RAW}x worse than no compensation ({}); check that the runs are of one unit and cover its temperature range; no coefficients written",
            absurd.join("; ")
        );
    }
    Ok(cal)
}

/// Each run the set is fitted on: its id and its log's SHA-256.
fn fitted_on(paths: &[PathBuf], runs: &[crate::calibrate::RunSeries]) -> Result<Vec<FittedOn>> {
    paths
        .iter()
        .zip(runs)
        .map(|(p, r)| {
            Ok(FittedOn {
                run_id: r.run_id.clone(),
                log_sha256: crate::results::record::sha256_file(p)
                    .with_context(|| format!("reading {}", p.display()))?,
                log: p.display().to_string(),
            })
        })
        .collect()
}

/// Record the set for its unit in the results store, which numbers it;
/// the set's text with its version. A store that cannot be reached is a
/// warning (the file is the record, without a version).
fn record(args: &CalibrateArgs, set: &mut CoefficientSet, cal: &Calibration) -> Result<String> {
    let held = cal
        .table
        .iter()
        .find(|r| r.model == "model4")
        .and_then(|r| r.held_out)
        .map(|s| s.drift_pp_dph);
    store(args, set, &cal.validation, held)
}

/// [`record`] for a set of the scale factor alone.
fn record_scale_factor(args: &CalibrateArgs, set: &mut CoefficientSet) -> Result<String> {
    store(args, set, "rate-table runs (scale factor only)", None)
}

fn store(
    args: &CalibrateArgs,
    set: &mut CoefficientSet,
    validation: &str,
    held_out_drift_pp_dph: Option<f64>,
) -> Result<String> {
    use crate::results::record::{SetRecord, part_key_of_log};
    let sources = args
        .runs
        .iter()
        .map(|p| {
            let abs = std::path::absolute(p).unwrap_or_else(|_| p.clone());
            (
                part_key_of_log(p).unwrap_or_default(),
                abs.display().to_string(),
            )
        })
        .collect();
    let loc = crate::results::Location::resolve(args.db.as_deref(), None);
    let rec = SetRecord {
        validation,
        held_out_drift_pp_dph,
        sources,
    };
    match crate::results::Store::open(&loc).and_then(|s| match s {
        Some(mut s) => s
            .record_coefficients(set, &rec)
            .map(|text| Some((text, s.name().to_owned()))),
        None => Ok(None),
    }) {
        Ok(Some((text, name))) => {
            errln!("{} recorded in the results store {name}", set.describe());
            Ok(text)
        }
        Ok(None) => Ok(set
            .to_toml()
            .context("writing the coefficient set as TOML")?),
        Err(e) => {
            errln!("warning: {e}; the coefficients file is written without a store version");
            Ok(set
                .to_toml()
                .context("writing the coefficient set as TOML")?)
        }
    }
}
