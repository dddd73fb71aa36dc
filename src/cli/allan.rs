//! `gyrobench allan FILE [--taus octave|dense] [--json]`: overlapping Allan
//! deviation with confidence intervals and the fitted noise terms, of one
//! record of a run's MCAP log (at the frame rate) or of an interchange CSV.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use serde::Serialize;

use super::Outcome;
use crate::analysis::allan::{Allan, Taus, analyse};
use crate::analysis::figures::bias_stability;
use crate::runlog::interchange;
use crate::runlog::replay::record_rates;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum TauSet {
    Octave,
    Dense,
}

#[derive(Debug, Args)]
pub struct AllanArgs {
    /// A run's log (.mcap) or an interchange CSV (.csv).
    file: PathBuf,
    /// Averaging times: octave (1, 2, 4, ... samples) or dense (10 per decade).
    #[arg(long, value_enum, default_value = "octave")]
    taus: TauSet,
    /// Record of the log to analyse (default: its longest record); for a
    /// CSV, the step label (default: the longest evenly spaced stretch).
    #[arg(long)]
    record: Option<String>,
    /// Print JSON (tau_s, adev_dph, lo_dph, hi_dph, noise, ...) instead of a table.
    #[arg(long)]
    json: bool,
}

/// `--json` output.
#[derive(Debug, Serialize)]
struct Output<'a> {
    file: String,
    record: &'a str,
    samples: usize,
    tau0_s: f64,
    tau_s: Vec<f64>,
    adev_dph: Vec<f64>,
    lo_dph: Vec<f64>,
    hi_dph: Vec<f64>,
    edf: Vec<f64>,
    alpha: Vec<i32>,
    noise: &'a crate::analysis::allan::NoiseTerms,
    bias_instability: BiasInstability,
}

#[derive(Debug, Serialize)]
struct BiasInstability {
    ieee_b_dph: f64,
    adev_min_dph: f64,
    adev_min_tau_s: f64,
    bias_stability_100s_dph: f64,
}

fn load(args: &AllanArgs) -> Result<(String, Vec<f64>, f64)> {
    let is_csv = args
        .file
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if !is_csv {
        let r = record_rates(&args.file, args.record.as_deref())?;
        super::warn_incomplete(
            &args.file,
            &r.read,
            &format!(
                "analysing the {} frames of `{}` it holds",
                r.rate_dph.len(),
                r.record
            ),
        );
        return Ok((r.record, r.rate_dph, r.dt_s));
    }
    let rows = interchange::read(&args.file)?;
    let rows: Vec<interchange::Row> = match &args.record {
        Some(step) => rows.into_iter().filter(|r| &r.step == step).collect(),
        None => rows,
    };
    anyhow::ensure!(
        !rows.is_empty(),
        "{}: no rows with step `{}`",
        args.file.display(),
        args.record.as_deref().unwrap_or_default()
    );
    let (start, len, dt) = interchange::longest_even_run(&rows);
    let label = args.record.clone().unwrap_or_else(|| {
        format!(
            "rows {}..{} (longest evenly spaced stretch)",
            start + 2,
            start + len + 1
        )
    });
    let rate = rows[start..start + len]
        .iter()
        .map(|r| r.rate_dph)
        .collect();
    Ok((label, rate, dt))
}

pub fn run(args: AllanArgs) -> Result<Outcome> {
    let (record, rate, tau0) =
        load(&args).with_context(|| format!("reading {}", args.file.display()))?;
    anyhow::ensure!(
        rate.len() >= 9,
        "{}: {} samples in `{record}`; the Allan deviation needs at least 9",
        args.file.display(),
        rate.len()
    );
    let taus = match args.taus {
        TauSet::Octave => Taus::Octave,
        TauSet::Dense => Taus::Dense,
    };
    let a: Allan = analyse(&rate, tau0, taus);
    let per_100s = ((100.0 / tau0).round() as usize).max(1);
    let bi = BiasInstability {
        ieee_b_dph: a.bias_instability.ieee_b_dph,
        adev_min_dph: a.bias_instability.adev_min_dph,
        adev_min_tau_s: a.bias_instability.adev_min_tau_s,
        bias_stability_100s_dph: bias_stability(&rate, per_100s),
    };
    if args.json {
        let out = Output {
            file: args.file.display().to_string(),
            record: &record,
            samples: a.samples,
            tau0_s: a.tau0_s,
            tau_s: a.points.iter().map(|p| p.tau_s).collect(),
            adev_dph: a.points.iter().map(|p| p.adev).collect(),
            lo_dph: a.points.iter().map(|p| p.lo).collect(),
            hi_dph: a.points.iter().map(|p| p.hi).collect(),
            edf: a.points.iter().map(|p| p.edf).collect(),
            alpha: a.points.iter().map(|p| p.alpha).collect(),
            noise: &a.noise,
            bias_instability: bi,
        };
        outln!("{}", serde_json::to_string_pretty(&out)?)?;
    } else {
        outf!(
            "{}",
            render_text(&args.file.display().to_string(), &record, &a, &bi)
        )?;
    }
    Ok(Outcome::Success)
}

fn render_text(file: &str, record: &str, a: &Allan, bi: &BiasInstability) -> String {
    let mut s = format!(
        "{file}, {record}: {} samples every {} s\n\n  {:>12} {:>12} {:>12} {:>12} {:>9} {:>6}\n",
        a.samples, a.tau0_s, "tau s", "ADEV deg/h", "lo (1-sig)", "hi (1-sig)", "EDF", "alpha"
    );
    for p in &a.points {
        s.push_str(&format!(
            "  {:>12.4} {:>12.6} {:>12.6} {:>12.6} {:>9.1} {:>6}\n",
            p.tau_s, p.adev, p.lo, p.hi, p.edf, p.alpha
        ));
    }
    let n = &a.noise;
    s.push_str(&format!(
        "\nnoise terms (weighted fit, rms misfit {:.1} %):\n  quantization      {:.4} arcsec\n  angle random walk {:.6} deg/sqrt(h)\n  bias instability  {:.5} deg/h (IEEE B = floor / 0.664)\n  rate random walk  {:.5} deg/h/sqrt(h)\n",
        100.0 * n.fit_rms_relative,
        n.quantization_arcsec,
        n.arw_deg_per_rt_h,
        n.bias_instability_dph,
        n.rate_random_walk_dph_per_rt_h
    ));
    s.push_str(&format!(
        "\n\"bias instability\", three figures:\n  IEEE coefficient B         {:.5} deg/h\n  raw ADEV minimum           {:.5} deg/h at {:.0} s\n  bias stability (100 s avg) {:.5} deg/h (1-sigma, GJB 2426A; what acceptance limits judge)\n",
        bi.ieee_b_dph, bi.adev_min_dph, bi.adev_min_tau_s, bi.bias_stability_100s_dph
    ));
    s
}
