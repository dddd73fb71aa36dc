//! Calibration of the thermal compensation from recorded runs: models 1, 3
//! and 4 of the study fitted jointly over the runs (one turn-on offset per
//! run, a nuisance), scored on held-out runs, written as a coefficients
//! file `run --coeffs` uses.
//!
//! Data: the 1 Hz intervals of each run rebuilt from its log (as replay
//! does), restricted to the records its compensated-drift measurements use
//! (the thermal records), or every recorded interval when it has none.
//! Records taken while the table turns (`rate` steps) are not thermal
//! data: they give the scale factor and its temperature coefficient
//! ([`scale_factor`]), pooled over the runs with one bias per run.

use std::path::Path;

use serde::Serialize;

use crate::analysis::figures::drift_pp;
use crate::analysis::model::{Fit, FitError, ModelKind, MultiFit, collinear, fit_runs};
use crate::analysis::rate::RatePoint;
use crate::analysis::series::Interval;
use crate::analysis::study::DRIFT_SMOOTHING_S;
use crate::coeffs::{CoefficientSet, ScaleFactorCoeffs};
use crate::procedure::{Metric, StepKind};
use crate::runlog::replay::{ReplayError, replay_unit};

/// Correlation above which two regressors are reported as collinear.
pub const COLLINEAR_ABOVE: f64 = 0.9;

/// One run's series.
#[derive(Debug, Clone)]
pub struct RunSeries {
    /// File name.
    pub name: String,
    /// Serial number of the unit the run tested.
    pub serial: String,
    /// Its type.
    pub dut_type: String,
    /// The run's id (empty in a log of the first format).
    pub run_id: String,
    /// 1 Hz intervals used for calibration.
    pub series: Vec<Interval>,
    /// Its records taken while the table turned, one point each.
    pub rate: Vec<RatePoint>,
}

/// Load the calibration series of a run from its log.
pub fn load(path: &Path) -> Result<RunSeries, ReplayError> {
    load_unit(path, None)
}

/// Load the calibration series of unit `unit` (a serial) of a batch's log
/// (`runlog::view`; none: the log as written).
pub fn load_unit(path: &Path, unit: Option<&str>) -> Result<RunSeries, ReplayError> {
    let r = replay_unit(path, None, unit)?;
    // Records of `rate` steps: a record right after a turn at a rate.
    let steps: Vec<&crate::procedure::Step> = r.procedure.steps().collect();
    let turning: Vec<String> = steps
        .windows(2)
        .filter_map(|w| match (&w[0].kind, &w[1].kind) {
            (StepKind::Turn { rate_dps, .. }, StepKind::Record { label, .. })
                if *rate_dps != 0.0 =>
            {
                Some(label.clone())
            }
            _ => None,
        })
        .collect();
    // As the scale-factor figures take them: over whole revolutions.
    let rate: Vec<RatePoint> = turning
        .iter()
        .filter_map(|l| r.result.records.rate_point(l).map(|(p, _)| p))
        .collect();
    let thermal: Vec<String> = r
        .procedure
        .steps()
        .filter_map(|s| match &s.kind {
            StepKind::Measure(m) if m.metric == Metric::CompensatedDriftPp => {
                Some(m.records.clone())
            }
            _ => None,
        })
        .flatten()
        .collect();
    let in_turns: std::collections::HashSet<u64> = turning
        .iter()
        .filter_map(|l| r.result.records.get(l))
        .flatten()
        .map(|iv| iv.time_s.to_bits())
        .collect();
    let series: Vec<Interval> = if thermal.is_empty() {
        r.result
            .records
            .all()
            .into_iter()
            .filter(|(rec, _)| *rec)
            .map(|(_, iv)| iv)
            // Not the rate records (their "bias" carries the scale factor
            // times the rate).
            .filter(|iv| !in_turns.contains(&iv.time_s.to_bits()))
            .collect()
    } else {
        let mut seen = Vec::new();
        thermal
            .iter()
            .filter(|l| {
                let new = !seen.contains(l);
                seen.push(l);
                new
            })
            .filter_map(|l| r.result.records.get(l))
            .flatten()
            .collect()
    };
    // A fit on part of a record would be a fit on other data than the log's.
    if let Some(why) = r.result.records.read_faults().any() {
        return Err(ReplayError::Log {
            path: path.display().to_string(),
            message: why,
        });
    }
    Ok(RunSeries {
        name: path.display().to_string(),
        serial: r.meta.dut_serial.clone(),
        dut_type: r.meta.dut_type.clone(),
        run_id: r.meta.run_id.clone(),
        series,
        rate,
    })
}

/// The scale factor pooled over the runs' rate records: `output = K0 x +
/// c x (T - Tref) + B_run` by least squares, one bias per run, `Tref` the
/// records' mean block temperature to 0.1 degC; `c` only when the records
/// span 1 degC or more. None without three rate records.
pub fn scale_factor(runs: &[RunSeries]) -> Option<ScaleFactorCoeffs> {
    use nalgebra::{DMatrix, DVector};
    let pts: Vec<(usize, &RatePoint)> = runs
        .iter()
        .enumerate()
        .flat_map(|(i, r)| r.rate.iter().map(move |p| (i, p)))
        .collect();
    let with: Vec<usize> = (0..runs.len())
        .filter(|i| !runs[*i].rate.is_empty())
        .collect();
    if pts.len() < 3 {
        return None;
    }
    let n = pts.len() as f64;
    let tref = (pts.iter().map(|(_, p)| p.block_c).sum::<f64>() / n * 10.0).round() / 10.0;
    let (lo, hi) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (_, p)| {
            (a.min(p.block_c), b.max(p.block_c))
        });
    let temp = hi - lo >= 1.0;
    let k = if temp { 2 } else { 1 };
    let cols = k + with.len();
    if pts.len() <= cols {
        return None;
    }
    let x = DMatrix::from_fn(pts.len(), cols, |i, j| {
        let (run, p) = pts[i];
        match j {
            0 => p.input_dph,
            1 if temp => p.input_dph * (p.block_c - tref),
            _ => f64::from(u8::from(with[j - k] == run)),
        }
    });
    let y = DVector::from_iterator(pts.len(), pts.iter().map(|(_, p)| p.output_dph));
    let inv = (x.transpose() * &x).try_inverse()?;
    let b = &inv * x.transpose() * &y;
    let s2 = (&y - &x * &b).norm_squared() / (pts.len() - cols) as f64;
    let se = |i: usize| (inv[(i, i)] * s2).max(0.0).sqrt();
    Some(ScaleFactorCoeffs {
        error_ppm: (b[0] - 1.0) * 1e6,
        error_ppm_stderr: se(0) * 1e6,
        ppm_per_c: temp.then(|| b[1] / b[0] * 1e6),
        ppm_per_c_stderr: temp.then(|| se(1) / b[0].abs() * 1e6),
        reference_c: tref,
        records: pts.len(),
    })
}

/// Residual figures of one model on one run (its own offset removed).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Score {
    /// Peak-to-peak of the residual smoothed over 600 s, deg/h.
    pub drift_pp_dph: f64,
    /// RMS of the 1 Hz residual, deg/h.
    pub rms_dph: f64,
}

fn score(residual: &[f64]) -> Score {
    let n = residual.len().max(1) as f64;
    let mean = residual.iter().sum::<f64>() / n;
    let centred: Vec<f64> = residual.iter().map(|r| r - mean).collect();
    let window = DRIFT_SMOOTHING_S as usize;
    Score {
        drift_pp_dph: if centred.len() >= window {
            drift_pp(&centred, window)
        } else {
            f64::NAN
        },
        rms_dph: (centred.iter().map(|r| r * r).sum::<f64>() / n).sqrt(),
    }
}

fn model_score(fit: Option<&Fit>, series: &[Interval]) -> Score {
    match fit {
        Some(f) => score(&f.residual(series)),
        None => score(&series.iter().map(Interval::bias_dph).collect::<Vec<_>>()),
    }
}

/// Mean of scores over folds.
fn mean_score(s: &[Score]) -> Score {
    let n = s.len().max(1) as f64;
    Score {
        drift_pp_dph: s.iter().map(|x| x.drift_pp_dph).sum::<f64>() / n,
        rms_dph: (s.iter().map(|x| x.rms_dph * x.rms_dph).sum::<f64>() / n).sqrt(),
    }
}

/// One line of the comparison table.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// `raw`, `model1`, `model3` or `model4`.
    pub model: &'static str,
    /// On runs it was not fitted to (leave one run out); none with one run.
    pub held_out: Option<Score>,
    /// On the runs it was fitted to.
    pub in_sample: Score,
}

/// One fitted model with its uncertainties.
#[derive(Debug, Clone, Serialize)]
pub struct Fitted {
    /// Which model.
    pub model: &'static str,
    /// Coefficient name, value and standard error.
    pub coefficients: Vec<(String, f64, f64)>,
    /// Warm-up time constant (model 4), s.
    pub warmup_tau_s: Option<f64>,
    /// Offset of each run, deg/h.
    pub run_offsets_dph: Vec<f64>,
}

/// Regressors the runs cannot separate.
#[derive(Debug, Clone, Serialize)]
pub struct Collinear {
    /// The two coefficients.
    pub terms: [&'static str; 2],
    /// Their correlation over the runs.
    pub correlation: f64,
    /// The extra run that would separate them.
    pub separate_with: String,
}

/// The whole calibration.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    /// The unit calibrated (none: runs of several units fitted together).
    pub unit: Option<crate::coeffs::UnitSection>,
    /// The set's version and provenance, once the caller knows them.
    pub set: Option<crate::coeffs::SetSection>,
    /// Runs used.
    pub runs: Vec<String>,
    /// How the held-out figures were obtained.
    pub validation: String,
    /// raw, model 1, model 3, model 4 (the study's progression).
    pub table: Vec<Row>,
    /// The models fitted on all runs.
    pub models: Vec<Fitted>,
    /// Collinear regressors (model 4).
    pub collinear: Vec<Collinear>,
    /// Warnings for the engineer.
    pub warnings: Vec<String>,
    #[serde(skip)]
    fits: Vec<MultiFit>,
}

const MODELS: [(ModelKind, &str); 3] = [
    (ModelKind::Model1, "model1"),
    (ModelKind::Model3, "model3"),
    (ModelKind::Model4, "model4"),
];

fn separate_with(a: &str, b: &str) -> String {
    let pair = |x: &str, y: &str| (a == x && b == y) || (a == y && b == x);
    if pair("k4_tk", "k5_f") {
        "a run powered on at another chamber temperature (a cold start after a soak at -20 degC, say), so the case temperature moves while the warm-up does not".into()
    } else if pair("k1_dt", "k2_dt2") {
        "a run that drives the block gradient over a wider range and through zero (faster ramps in both directions, or heating from one side)".into()
    } else if a.starts_with("k1_dt") || b.starts_with("k1_dt") || a.starts_with("k2_dt") {
        "a run with another ramp rate (0.5 or 2 degC/min), so the block gradient and its rate change apart".into()
    } else {
        "a run with another temperature profile (a different range or ramp rate)".into()
    }
}

/// A held-out figure this many times the raw drift (or not finite) is
/// not a fit of one unit's thermal behaviour but of something else
/// (runs of several units, a broken log): refused.
pub const ABSURD_OVER_RAW: f64 = 10.0;

/// Serials of runs that are not all of one unit, as `serial (run)` lines;
/// empty when they are.
pub fn mixed_serials(runs: &[RunSeries]) -> Vec<String> {
    let first = runs.first().map(|r| r.serial.as_str());
    if runs.iter().all(|r| Some(r.serial.as_str()) == first) {
        return Vec::new();
    }
    runs.iter()
        .map(|r| {
            format!(
                "{} ({})",
                if r.serial.is_empty() {
                    "no serial"
                } else {
                    &r.serial
                },
                r.name
            )
        })
        .collect()
}

impl Calibration {
    /// Models whose held-out figures are absurd against the raw drift, in
    /// words; empty when every held-out figure is plausible.
    pub fn absurd(&self) -> Vec<String> {
        absurd(&self.table)
    }
}

/// Rows of a comparison table (raw first) whose held-out figures are more
/// than [`ABSURD_OVER_RAW`] times the raw ones, or not finite.
fn absurd(table: &[Row]) -> Vec<String> {
    let Some(raw) = table.first().and_then(|r| r.held_out) else {
        return Vec::new();
    };
    let limit = |raw: f64| ABSURD_OVER_RAW * raw.abs().max(1e-3);
    table
        .iter()
        .skip(1)
        .filter_map(|row| {
            let h = row.held_out?;
            let bad = |v: f64, r: f64| !v.is_finite() || v > limit(r);
            (bad(h.drift_pp_dph, raw.drift_pp_dph) || bad(h.rms_dph, raw.rms_dph)).then(|| {
                format!(
                    "{}: held-out drift {:.4} deg/h p-p, rms {:.4} deg/h, against {:.4} / {:.4} deg/h raw",
                    row.model, h.drift_pp_dph, h.rms_dph, raw.drift_pp_dph, raw.rms_dph
                )
            })
        })
        .collect()
}

/// Fit every model on `runs` and validate by leaving one run out.
pub fn calibrate(runs: &[RunSeries]) -> Result<Calibration, FitError> {
    let all: Vec<&[Interval]> = runs.iter().map(|r| r.series.as_slice()).collect();
    let mut fits = Vec::new();
    for (kind, _) in MODELS {
        fits.push(fit_runs(kind, &all)?);
    }
    // In-sample: the joint fit, each run scored with its own offset removed.
    let in_sample = |fit: Option<&Fit>| {
        mean_score(&all.iter().map(|s| model_score(fit, s)).collect::<Vec<_>>())
    };
    let mut held: Vec<Option<Score>> = vec![None; 4];
    if runs.len() >= 2 {
        let mut folds: Vec<Vec<Score>> = vec![Vec::new(); 4];
        for k in 0..runs.len() {
            let train: Vec<&[Interval]> = all
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != k)
                .map(|(_, s)| *s)
                .collect();
            folds[0].push(model_score(None, all[k]));
            for (i, (kind, _)) in MODELS.iter().enumerate() {
                let f = fit_runs(*kind, &train)?;
                folds[i + 1].push(model_score(Some(&f.fit), all[k]));
            }
        }
        held = folds.iter().map(|f| Some(mean_score(f))).collect();
    }
    let mut table = vec![Row {
        model: "raw",
        held_out: held[0],
        in_sample: in_sample(None),
    }];
    for (i, (_, name)) in MODELS.iter().enumerate() {
        table.push(Row {
            model: name,
            held_out: held[i + 1],
            in_sample: in_sample(Some(&fits[i].fit)),
        });
    }
    let models = MODELS
        .iter()
        .zip(&fits)
        .map(|((kind, name), f)| Fitted {
            model: name,
            coefficients: kind
                .terms()
                .iter()
                .zip(
                    f.fit
                        .coeffs
                        .iter()
                        .zip(f.stderr.iter().chain([f64::NAN].iter())),
                )
                .map(|(t, (v, e))| ((*t).to_owned(), *v, *e))
                .collect(),
            warmup_tau_s: f.fit.warmup_tau_s,
            run_offsets_dph: f.offsets.clone(),
        })
        .collect();
    let tau_w = fits[2].fit.warmup_tau_s.unwrap_or(600.0);
    let collinear: Vec<Collinear> = collinear(ModelKind::Model4, &all, tau_w, COLLINEAR_ABOVE)
        .into_iter()
        .map(|(a, b, r)| Collinear {
            terms: [a, b],
            correlation: r,
            separate_with: separate_with(a, b),
        })
        .collect();
    let mut warnings = Vec::new();
    if runs.len() < 2 {
        warnings.push(
            "one run: the figures are in-sample only; calibrate on two or more runs to score the models on a run they were not fitted to".into(),
        );
    }
    for c in &collinear {
        warnings.push(format!(
            "{} and {} are collinear in these runs (r = {:.3}): their split is not determined; add {}",
            c.terms[0], c.terms[1], c.correlation, c.separate_with
        ));
    }
    Ok(Calibration {
        unit: None,
        set: None,
        runs: runs.iter().map(|r| r.name.clone()).collect(),
        validation: if runs.len() >= 2 {
            format!("leave one run out over {} runs", runs.len())
        } else {
            "in-sample only (one run)".into()
        },
        table,
        models,
        collinear,
        warnings,
        fits,
    })
}

impl Calibration {
    /// The coefficient set (without its unit and provenance, which the
    /// caller knows): model 4 for `run --coeffs`, models 3 and 1 beside
    /// it, and how they were validated.
    pub fn coefficient_set(&self) -> CoefficientSet {
        let mut info = toml::Table::new();
        info.insert(
            "runs".into(),
            toml::Value::Array(self.runs.iter().cloned().map(toml::Value::String).collect()),
        );
        info.insert("validation".into(), self.validation.clone().into());
        for (i, (_, name)) in MODELS.iter().enumerate() {
            let f = &self.fits[i];
            let mut se = toml::Table::new();
            for (t, e) in MODELS[i].0.terms().iter().zip(&f.stderr) {
                if e.is_finite() {
                    se.insert((*t).into(), (*e).into());
                }
            }
            info.insert(format!("{name}_stderr"), toml::Value::Table(se));
        }
        if let Some(r) = self.table.iter().find(|r| r.model == "model4") {
            let s = r.held_out.unwrap_or(r.in_sample);
            info.insert("model4_drift_pp_dph".into(), s.drift_pp_dph.into());
        }
        let fit = |kind: ModelKind| {
            self.fits
                .iter()
                .find(|f| f.fit.kind == kind)
                .map(|f| &f.fit)
        };
        CoefficientSet {
            unit: None,
            set: None,
            model4: fit(ModelKind::Model4).and_then(Fit::model4),
            model3: fit(ModelKind::Model3).and_then(Fit::model3),
            model1: fit(ModelKind::Model1).and_then(Fit::model1),
            scale_factor: None,
            calibration: Some(info),
        }
    }

    /// A self-contained page: the comparison table, every model's
    /// coefficients with their errors, the warnings.
    pub fn render_html(&self) -> String {
        use crate::view::{Chart, Marker, Series, esc, page};
        let f = |v: f64| {
            if v.is_finite() {
                format!("{v:.4}")
            } else {
                "n/a".into()
            }
        };
        let mut rows = String::new();
        for r in &self.table {
            let (hd, hr) = r.held_out.map_or(("-".into(), "-".into()), |h| {
                (f(h.drift_pp_dph), f(h.rms_dph))
            });
            rows.push_str(&format!(
                "<tr><td>{}</td><td class=num>{hd}</td><td class=num>{hr}</td><td class=num>{}</td><td class=num>{}</td></tr>\n",
                r.model,
                f(r.in_sample.drift_pp_dph),
                f(r.in_sample.rms_dph)
            ));
        }
        let mut coeffs = String::new();
        for m in &self.models {
            for (name, v, e) in &m.coefficients {
                coeffs.push_str(&format!(
                    "<tr><td>{}</td><td>{}</td><td class=num>{v:.6e}</td><td class=num>{}</td></tr>\n",
                    m.model,
                    esc(name),
                    if e.is_finite() { format!("{e:.2e}") } else { "(per-run mean)".into() }
                ));
            }
            if let Some(t) = m.warmup_tau_s {
                coeffs.push_str(&format!(
                    "<tr><td>{}</td><td>tau_w, s</td><td class=num>{t:.1}</td><td></td></tr>\n",
                    m.model
                ));
            }
        }
        let warnings: String = self
            .warnings
            .iter()
            .map(|w| format!("<p class=box>{}</p>\n", esc(w)))
            .collect();
        let runs: String = self
            .runs
            .iter()
            .map(|r| format!("<li>{}</li>", esc(r)))
            .collect();
        let names: Vec<String> = self.table.iter().map(|r| r.model.to_owned()).collect();
        // Side by side at each model, so neither hides the other.
        let at = |dx: f64, pick: &dyn Fn(&Row) -> Option<f64>| -> Vec<(f64, f64)> {
            self.table
                .iter()
                .enumerate()
                .filter_map(|(i, r)| {
                    Some((
                        i as f64 + dx,
                        pick(r).filter(|v| v.is_finite() && *v > 0.0)?,
                    ))
                })
                .collect()
        };
        let chart = Chart::new("Drift peak to peak left by each model", "model", "deg/h")
            .categories(names)
            .log_y()
            .height(280)
            .series(
                Series::points(
                    "held out (runs it was not fitted to)",
                    at(-0.08, &|r| r.held_out.map(|h| h.drift_pp_dph)),
                    Marker::Circle,
                )
                .marker(Marker::Circle, 6)
                .colour(0),
            )
            .series(
                Series::points(
                    "in sample",
                    at(0.08, &|r| Some(r.in_sample.drift_pp_dph)),
                    Marker::Square,
                )
                .marker(Marker::Square, 5)
                .colour(1),
            )
            .render();
        let body = format!(
            "<h1>Thermal compensation calibration{}</h1>\n<p class=headline>{}</p>\n{warnings}{}<p>Runs:</p><ul>{runs}</ul><p class=note>Validation: {}.</p>\n<h2>The study's progression</h2>\n<table><tr><th>model</th><th>held-out drift p-p, deg/h</th><th>held-out RMS</th><th>in-sample drift p-p</th><th>in-sample RMS</th></tr>\n{rows}</table>\n<p class=note>Drift = peak-to-peak of the residual smoothed over 600 s; each run's own offset (turn-on bias) removed.</p>\n{chart}<h2>Coefficients (all runs)</h2>\n<table><tr><th>model</th><th>term</th><th>value</th><th>standard error</th></tr>\n{coeffs}</table>\n",
            esc(&self.of_unit()),
            esc(&self.headline()),
            self.identity_html(),
            esc(&self.validation)
        );
        page(&format!("Calibration{}", self.of_unit()), "", &body)
    }

    /// ` of RL-16 RL16-0042` (empty when the runs are of several units).
    fn of_unit(&self) -> String {
        self.unit.as_ref().map_or(String::new(), |u| {
            format!(" of {} {}", u.dut_type, u.serial)
        })
    }

    /// The set's identity on the page: unit, version, when, by what, and
    /// each run with its log's SHA-256.
    fn identity_html(&self) -> String {
        use crate::view::esc;
        let unit = match &self.unit {
            Some(u) => format!("<b>{} {}</b>", esc(&u.dut_type), esc(&u.serial)),
            None => "<b>no unit</b> (runs of several units fitted together: the set cannot be used without --coeffs-override)".into(),
        };
        let Some(set) = &self.set else {
            return format!("<p class=note>Unit: {unit}.</p>\n");
        };
        let version = set.version.map_or_else(
            || "not recorded in a results store".to_owned(),
            |v| format!("set {v} in the results store"),
        );
        let runs: String = set
            .fitted_on
            .iter()
            .map(|r| {
                format!(
                    "<tr><td>{}</td><td><code>{}</code></td><td><code>{}</code></td></tr>",
                    esc(&r.log),
                    esc(if r.run_id.is_empty() { "-" } else { &r.run_id }),
                    esc(&r.log_sha256)
                )
            })
            .collect();
        format!(
            "<p class=note>Unit: {unit} &middot; {} &middot; fitted {} by {} &middot; models {}</p>\n<table><tr><th>log</th><th>run id</th><th>log SHA-256</th></tr>\n{runs}</table>\n",
            esc(&version),
            esc(&crate::view::utc_seconds(&set.created_utc)),
            esc(&set.software),
            esc(&set.models.join(", "))
        )
    }

    /// One sentence: what model 4 leaves, held out when it can be, against
    /// the raw drift; and whether there is a warning to read.
    pub fn headline(&self) -> String {
        let pick = |model: &str| self.table.iter().find(|r| r.model == model);
        let fig = |r: &Row| {
            r.held_out
                .map_or((r.in_sample.drift_pp_dph, "in sample"), |h| {
                    (h.drift_pp_dph, "held out")
                })
        };
        let mut s = match (pick("model4"), pick("raw")) {
            (Some(m4), Some(raw)) => {
                let (v, how) = fig(m4);
                let (r, _) = fig(raw);
                format!(
                    "Model 4 leaves a drift of {v:.4} deg/h peak to peak {how}, from {r:.4} deg/h uncompensated, on {} {}.",
                    self.runs.len(),
                    if self.runs.len() == 1 { "run" } else { "runs" }
                )
            }
            _ => format!("Calibrated on {} run(s).", self.runs.len()),
        };
        if !self.warnings.is_empty() {
            s.push_str(if self.warnings.len() == 1 {
                " A warning below: read it before using the coefficients."
            } else {
                " Warnings below: read them before using the coefficients."
            });
        }
        s
    }

    /// The comparison table and the model-4 coefficients as text.
    pub fn render_text(&self) -> String {
        let f = |v: f64| {
            if v.is_finite() {
                format!("{v:.4}")
            } else {
                "n/a".into()
            }
        };
        let mut s = format!(
            "calibration{} on {} run(s), validation: {}\n\n  {:<8} {:>18} {:>14} {:>18} {:>14}\n",
            self.of_unit(),
            self.runs.len(),
            self.validation,
            "model",
            "held-out drift pp",
            "held-out rms",
            "in-sample drift pp",
            "in-sample rms"
        );
        for r in &self.table {
            let h = r.held_out.map_or(("-".to_owned(), "-".to_owned()), |h| {
                (f(h.drift_pp_dph), f(h.rms_dph))
            });
            s.push_str(&format!(
                "  {:<8} {:>18} {:>14} {:>18} {:>14}\n",
                r.model,
                h.0,
                h.1,
                f(r.in_sample.drift_pp_dph),
                f(r.in_sample.rms_dph)
            ));
        }
        s.push_str("  (deg/h; drift = p-p of the residual smoothed over 600 s, each run's offset removed)\n\nmodel 4 on all runs:\n");
        if let Some(m) = self.models.iter().find(|m| m.model == "model4") {
            for (name, v, e) in &m.coefficients {
                if e.is_finite() {
                    s.push_str(&format!("  {name:<10} {v:>12.6} +- {e:.6}\n"));
                }
            }
            if let Some(t) = m.warmup_tau_s {
                s.push_str(&format!("  tau_w      {t:>12.1} s\n"));
            }
        }
        for w in &self.warnings {
            s.push_str(&format!("warning: {w}\n"));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(model: &'static str, drift: f64, rms: f64) -> Row {
        let s = Score {
            drift_pp_dph: drift,
            rms_dph: rms,
        };
        Row {
            model,
            held_out: Some(s),
            in_sample: s,
        }
    }

    #[test]
    fn a_held_out_fit_far_worse_than_no_compensation_is_absurd() {
        let fine = [
            row("raw", 0.66, 0.2),
            row("model1", 0.3, 0.1),
            row("model4", 0.03, 0.01),
        ];
        assert!(absurd(&fine).is_empty());
        let broken = [
            row("raw", 0.66, 0.2),
            row("model1", 2.4e6, 9.0e5),
            row("model4", f64::NAN, 0.01),
        ];
        let a = absurd(&broken);
        assert_eq!(a.len(), 2, "{a:?}");
        assert!(
            a[0].starts_with("model1") && a[1].starts_with("model4"),
            "{a:?}"
        );
    }
}
