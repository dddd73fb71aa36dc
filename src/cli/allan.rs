//! `gyrobench allan FILE [--taus octave|dense] [--json]`: overlapping Allan
//! deviation with confidence intervals and the fitted noise terms, of one
//! record of a run's MCAP log (at the frame rate) or of an interchange CSV.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde::Serialize;

use super::Outcome;
use gyrobench::analysis::allan::{Allan, NoiseTerms, TERM_KEYS, Taus, analyse};
use gyrobench::analysis::figures::bias_stability;
use gyrobench::runlog::interchange;
use gyrobench::runlog::replay::record_rates_unit;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum TauSet {
    Octave,
    Dense,
}

#[derive(Debug, Args)]
#[command(after_help = after_help!("gyrobench allan runs/smoke/run.mcap --record up", plain))]
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
    /// A batch's unit, by serial (default: the batch's first unit).
    #[arg(long, value_name = "SERIAL")]
    unit: Option<String>,
}

/// `--json` output. Field names are a contract (other tools read them):
/// new fields are added, none renamed.
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
    noise: NoiseJson,
    bias_instability: BiasInstability,
}

/// The fitted noise terms; a term the curve does not resolve is `null`,
/// with the reason and the fitted value under `not_resolved`.
#[derive(Debug, Serialize)]
struct NoiseJson {
    quantization_arcsec: Option<f64>,
    arw_deg_per_rt_h: Option<f64>,
    bias_instability_dph: Option<f64>,
    rate_random_walk_dph_per_rt_h: Option<f64>,
    fit_rms_relative: f64,
    not_resolved: std::collections::BTreeMap<&'static str, NotResolved>,
}

#[derive(Debug, Serialize)]
struct NotResolved {
    reason: String,
    fitted: f64,
}

impl NoiseJson {
    fn new(n: &NoiseTerms) -> Self {
        let v = terms(n);
        let shown = |i: usize| n.resolved[i].is_resolved().then_some(v[i]);
        Self {
            quantization_arcsec: shown(0),
            arw_deg_per_rt_h: shown(1),
            bias_instability_dph: shown(2),
            rate_random_walk_dph_per_rt_h: shown(3),
            fit_rms_relative: n.fit_rms_relative,
            not_resolved: (0..4)
                .filter_map(|i| {
                    let reason = n.resolved[i].reason()?;
                    Some((
                        TERM_KEYS[i],
                        NotResolved {
                            reason,
                            fitted: v[i],
                        },
                    ))
                })
                .collect(),
        }
    }
}

/// The four terms' values in the order of [`TERM_KEYS`].
fn terms(n: &NoiseTerms) -> [f64; 4] {
    [
        n.quantization_arcsec,
        n.arw_deg_per_rt_h,
        n.bias_instability_dph,
        n.rate_random_walk_dph_per_rt_h,
    ]
}

#[derive(Debug, Serialize)]
struct BiasInstability {
    /// `null` when the fit does not resolve B (see `noise.not_resolved`).
    ieee_b_dph: Option<f64>,
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
        let r = record_rates_unit(&args.file, args.record.as_deref(), args.unit.as_deref())?;
        if let Some(d) = r.read.damage(r.start_ns) {
            anyhow::bail!(
                "{}: {d}; an Allan deviation across the missing frames would be wrong \
                 (the run's figures in `replay` say what its records hold)",
                args.file.display()
            );
        }
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
    // Every error of the load names the file.
    let (record, rate, tau0) = load(&args)?;
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
        ieee_b_dph: a.noise.resolved[2]
            .is_resolved()
            .then_some(a.bias_instability.ieee_b_dph),
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
            noise: NoiseJson::new(&a.noise),
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
    let v = terms(n);
    let term = |i: usize, value: String| match n.resolved[i].reason() {
        None => value,
        Some(why) => format!("not resolved ({why})"),
    };
    s.push_str(&format!(
        "\nnoise terms (weighted fit, rms misfit {:.1} %):\n  quantization      {}\n  angle random walk {}\n  bias instability  {}\n  rate random walk  {}\n",
        100.0 * n.fit_rms_relative,
        term(0, format!("{:.4} arcsec", v[0])),
        term(1, format!("{:.6} deg/sqrt(h)", v[1])),
        term(2, format!("{:.5} deg/h (IEEE B = floor / 0.664)", v[2])),
        term(3, format!("{:.5} deg/h/sqrt(h)", v[3])),
    ));
    let b = bi
        .ieee_b_dph
        .map_or("not resolved (see the noise terms)".to_owned(), |b| {
            format!("{b:.5} deg/h")
        });
    let stability = if bi.bias_stability_100s_dph.is_finite() {
        format!(
            "{:.5} deg/h (1-sigma, GJB 2426A; what acceptance limits judge)",
            bi.bias_stability_100s_dph
        )
    } else {
        "n/a (the record holds fewer than two 100 s averages)".to_owned()
    };
    s.push_str(&format!(
        "\n\"bias instability\", three figures:\n  IEEE coefficient B         {b}\n  raw ADEV minimum           {:.5} deg/h at {:.0} s\n  bias stability (100 s avg) {stability}\n",
        bi.adev_min_dph, bi.adev_min_tau_s
    ));
    s
}
