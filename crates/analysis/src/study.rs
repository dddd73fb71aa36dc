//! The study's figures, defined once. `docs/figures.md` states the same
//! definitions for readers.
//!
//! All work on 1 Hz interval means with the kinematic (Earth + table) rate
//! removed using the logged orientation and the site latitude.

use serde::Serialize;

use super::figures::{bias_stability, drift_pp, mean};
use super::model::{self, Fit, FitError, ModelKind};
use super::series::Interval;

/// Length of the windows compared by the self-heating figure, s.
pub const SELF_HEATING_WINDOW_S: f64 = 120.0;
/// Span of the self-heating transient the study looks at, s (half an hour).
pub const SELF_HEATING_SPAN_S: f64 = 1800.0;
/// Smoothing of the drift figures (centred moving average), s.
pub const DRIFT_SMOOTHING_S: f64 = 600.0;
/// Averaging time of the bias-stability figure, s.
pub const STABILITY_AVERAGING_S: f64 = 100.0;

/// Self-heating transient: mean Earth-removed rate over the first
/// [`SELF_HEATING_WINDOW_S`] after power-on minus the mean over the last
/// [`SELF_HEATING_WINDOW_S`] of the first [`SELF_HEATING_SPAN_S`], deg/h
/// (signed; the study quotes its size). `None` if the run is shorter.
pub fn self_heating_dph(series: &[Interval]) -> Option<f64> {
    self_heating(series).ok()
}

/// Why the self-heating figure cannot be formed: a window the record
/// does not cover.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the {window} ({:.0} to {:.0} s after power-on) holds {covered_s:.0} s of data, \
     and the figure needs {:.0} s of it: {}; record from the power-on for \
     at least {SELF_HEATING_SPAN_S:.0} s",
    .span_s.0,
    .span_s.1,
    0.9 * (.span_s.1 - .span_s.0),
    held(*.record_s)
)]
pub struct SelfHeatingError {
    /// `first window` or `last window`.
    pub window: &'static str,
    /// Its span, s after power-on.
    pub span_s: (f64, f64),
    /// The device time the record covers inside it, s.
    pub covered_s: f64,
    /// Where the record runs, s after power-on (none: no data).
    pub record_s: Option<(f64, f64)>,
}

fn held(record_s: Option<(f64, f64)>) -> String {
    match record_s {
        Some((a, b)) => format!("the record runs from {a:.0} s to {b:.0} s after power-on"),
        None => "the record holds no data".to_owned(),
    }
}

/// [`self_heating_dph`], or why not in an operator's words. Each window
/// is judged by the device time its intervals cover (90 % of it at
/// least), whatever their cadence: a host that ticks every 1.2 s gives
/// fewer, longer intervals than one at 1 Hz, and the same figure.
/// `series` times count from power-on.
pub fn self_heating(series: &[Interval]) -> Result<f64, SelfHeatingError> {
    let window = |lo: f64, hi: f64, name: &'static str| -> Result<f64, SelfHeatingError> {
        let inside: Vec<&Interval> = series
            .iter()
            .filter(|s| s.time_s >= lo && s.time_s < hi)
            .collect();
        let times: Vec<f64> = inside.iter().map(|s| s.time_s).collect();
        let covered = covered_s(&times);
        if covered < 0.9 * (hi - lo) {
            return Err(SelfHeatingError {
                window: name,
                span_s: (lo, hi),
                covered_s: covered,
                record_s: series
                    .first()
                    .zip(series.last())
                    .map(|(a, b)| (a.time_s, b.time_s)),
            });
        }
        Ok(mean(
            &inside.iter().map(|s| s.bias_dph()).collect::<Vec<_>>(),
        ))
    };
    let first = window(0.0, SELF_HEATING_WINDOW_S, "first window")?;
    let last = window(
        SELF_HEATING_SPAN_S - SELF_HEATING_WINDOW_S,
        SELF_HEATING_SPAN_S,
        "last window",
    )?;
    Ok(first - last)
}

/// The device time one interval of `series` spans, s: the median spacing
/// of neighbours (1 s on a bench that ticks at 1 Hz; a host that polls
/// slower makes longer intervals). 1 s for fewer than two intervals. The
/// figures that average over seconds take that many seconds' intervals.
pub fn cadence_s(series: &[Interval]) -> f64 {
    let mut gaps: Vec<f64> = series
        .windows(2)
        .map(|w| w[1].time_s - w[0].time_s)
        .filter(|g| *g > 0.0)
        .collect();
    if gaps.is_empty() {
        return 1.0;
    }
    gaps.sort_by(f64::total_cmp);
    gaps[gaps.len() / 2]
}

/// The number of intervals of `cadence_s` that span `seconds` (at least 1).
pub fn intervals_for(seconds: f64, cadence_s: f64) -> usize {
    (seconds / cadence_s.max(1e-9)).round().max(1.0) as usize
}

/// Device time a run of interval centres covers, s: the spacings between
/// neighbours, a gap longer than twice the median spacing counted as one
/// spacing (the data it lacks), plus one spacing for the ends. A single
/// interval covers 1 s; none, nothing.
pub fn covered_s(times: &[f64]) -> f64 {
    let gaps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    if gaps.is_empty() {
        return times.len() as f64;
    }
    let mut sorted = gaps.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    gaps.iter()
        .map(|&g| if g <= 2.0 * median { g } else { median })
        .sum::<f64>()
        + median
}

/// Figures of a thermal run, raw and compensated.
#[derive(Debug, Clone, Serialize)]
pub struct ThermalFigures {
    /// Peak-to-peak of the Earth-removed rate, smoothed over
    /// [`DRIFT_SMOOTHING_S`], deg/h.
    pub raw_drift_pp_dph: f64,
    /// The same after model-4 compensation fitted on this run, deg/h.
    pub compensated_drift_pp_dph: f64,
    /// 1-sigma of [`STABILITY_AVERAGING_S`] averages, raw, deg/h.
    pub raw_bias_stability_dph: f64,
    /// The same, compensated, deg/h.
    pub compensated_bias_stability_dph: f64,
    /// Compensated drift with model 1 and model 3 fitted on the same run
    /// (the study's progression), deg/h.
    pub model1_drift_pp_dph: f64,
    /// Model 3, deg/h.
    pub model3_drift_pp_dph: f64,
    /// The model-4 fit used.
    pub model4: Fit,
}

/// Raw and compensated drift of a thermal run at 1 Hz.
pub fn thermal_figures(series: &[Interval]) -> Result<ThermalFigures, FitError> {
    let dt = spacing(series);
    let smooth = (DRIFT_SMOOTHING_S / dt).round() as usize;
    let avg = (STABILITY_AVERAGING_S / dt).round() as usize;
    let raw: Vec<f64> = series.iter().map(Interval::bias_dph).collect();
    let m4 = model::fit(ModelKind::Model4, series)?;
    let comp = m4.residual(series);
    let pp_of = |kind| -> Result<f64, FitError> {
        Ok(drift_pp(
            &model::fit(kind, series)?.residual(series),
            smooth,
        ))
    };
    Ok(ThermalFigures {
        raw_drift_pp_dph: drift_pp(&raw, smooth),
        compensated_drift_pp_dph: drift_pp(&comp, smooth),
        raw_bias_stability_dph: bias_stability(&raw, avg),
        compensated_bias_stability_dph: bias_stability(&comp, avg),
        model1_drift_pp_dph: pp_of(ModelKind::Model1)?,
        model3_drift_pp_dph: pp_of(ModelKind::Model3)?,
        model4: m4,
    })
}

fn spacing(series: &[Interval]) -> f64 {
    match series {
        [a, .., b] => (b.time_s - a.time_s) / (series.len() - 1) as f64,
        _ => 1.0,
    }
}

/// Temperature and temperature-rate sensitivity of the Earth-removed rate:
/// least squares of `bias = c + a TK + b dTK/dt` over the series (TK the
/// case temperature, dTK/dt by local regression over +-30 s), returning
/// (a deg/h per degC, b deg/h per degC/min). Fitted jointly so a ramp's
/// rate does not leak into the temperature slope. `None` when the
/// temperature does not move enough to tell (or too few samples).
pub fn temperature_sensitivity(series: &[Interval]) -> Option<(f64, f64)> {
    temperature_sensitivity_parts(&[series])
}

/// [`temperature_sensitivity`] over the parts of a resumed run: one
/// constant per part (each power-on has its own turn-on bias), the
/// temperature rate differentiated within each part, never across a break.
pub fn temperature_sensitivity_parts(parts: &[&[Interval]]) -> Option<(f64, f64)> {
    sensitivity_fit(parts).map(|f| (f.a, f.b))
}

/// The temperature and temperature-rate sensitivities with their standard
/// errors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensitivityFit {
    /// deg/h per degC.
    pub a: f64,
    /// deg/h per degC/min.
    pub b: f64,
    /// Standard error of `a`.
    pub se_a: f64,
    /// Standard error of `b`.
    pub se_b: f64,
    /// Degrees of freedom of the errors: the samples' effective number
    /// (their lag-1 autocorrelation taken into account) less the
    /// coefficients.
    pub dof: f64,
}

/// [`temperature_sensitivity_parts`] with the coefficients' standard
/// errors: `sigma^2 (X'X)^-1`, the residual variance inflated by
/// `(1 + r1) / (1 - r1)` for the lag-1 autocorrelation `r1` of the 1 Hz
/// residual (it is far from independent), the degrees of freedom the
/// sample count shrunk the same way less the coefficients.
pub fn sensitivity_fit(parts: &[&[Interval]]) -> Option<SensitivityFit> {
    let n: usize = parts.iter().map(|p| p.len()).sum();
    if n < 10 {
        return None;
    }
    let np = parts.len();
    let mut rows: Vec<(usize, f64, f64, f64)> = Vec::with_capacity(n);
    for (k, part) in parts.iter().enumerate() {
        let t: Vec<f64> = part.iter().map(|s| s.time_s).collect();
        let tk: Vec<f64> = part.iter().map(|s| s.tcase_c).collect();
        let rate = super::figures::derivative_by_time(&t, &tk, 30.0);
        for (i, s) in part.iter().enumerate() {
            rows.push((k, tk[i], rate[i], s.bias_dph()));
        }
    }
    let x = nalgebra::DMatrix::from_fn(n, np + 2, |i, j| {
        let (k, tk, rate, _) = rows[i];
        match j {
            j if j < np => f64::from(u8::from(j == k)),
            j if j == np => tk,
            _ => rate * 60.0,
        }
    });
    let (lo, hi) = rows
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| {
            (lo.min(r.1), hi.max(r.1))
        });
    if hi - lo < 0.5 {
        return None;
    }
    let y: Vec<f64> = rows.iter().map(|r| r.3).collect();
    let b = nalgebra::DVector::from_column_slice(&y);
    let beta = x.clone().svd(true, true).solve(&b, 1e-12).ok()?;
    if !(beta[np].is_finite() && beta[np + 1].is_finite()) {
        return None;
    }
    let resid = &b - &x * &beta;
    let rss = resid.norm_squared();
    let r1 = {
        let num: f64 = resid.as_slice().windows(2).map(|w| w[0] * w[1]).sum();
        (num / rss.max(f64::MIN_POSITIVE)).clamp(0.0, 0.99)
    };
    let p = np + 2;
    let n_eff = n as f64 * (1.0 - r1) / (1.0 + r1);
    let dof = (n_eff - p as f64).max(1.0);
    let sigma2 = rss / (n - p).max(1) as f64 * (1.0 + r1) / (1.0 - r1);
    let cov = (x.transpose() * &x).try_inverse()?;
    Some(SensitivityFit {
        a: beta[np],
        b: beta[np + 1],
        se_a: (sigma2 * cov[(np, np)]).sqrt(),
        se_b: (sigma2 * cov[(np + 1, np + 1)]).sqrt(),
        dof,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperature_and_its_rate_are_separated() {
        // A triangle in temperature with two ramp rates: the bias holds a
        // known slope in each.
        let series: Vec<Interval> = (0..20_000)
            .map(|i| {
                let t = f64::from(i);
                let tk = if t < 6000.0 {
                    20.0 + t / 200.0
                } else {
                    50.0 - (t - 6000.0) / 400.0
                };
                let rate_per_min = if t < 6000.0 { 0.3 } else { -0.15 };
                Interval {
                    time_s: t,
                    rate_dph: 0.5 - 0.007 * tk + 0.2 * rate_per_min + 9.0,
                    reference_dph: 9.0,
                    tcase_c: tk,
                    ..Interval::default()
                }
            })
            .collect();
        let (a, b) = temperature_sensitivity(&series).expect("computable");
        assert!((a + 0.007).abs() < 1e-5, "{a}");
        assert!((b - 0.2).abs() < 2e-3, "{b}");
        let flat: Vec<Interval> = series
            .iter()
            .map(|s| Interval {
                tcase_c: 20.0,
                ..*s
            })
            .collect();
        assert_eq!(temperature_sensitivity(&flat), None);
    }

    /// A transient `a exp(-t/300)`, sampled every `dt` from `t0` to 1800 s.
    fn transient(t0: f64, dt: f64) -> Vec<Interval> {
        let n = ((1800.0 - t0) / dt) as usize;
        (0..n)
            .map(|i| {
                let t = t0 + dt * i as f64 + dt / 2.0;
                Interval {
                    time_s: t,
                    rate_dph: 0.5 * (-t / 300.0).exp(),
                    ..Interval::default()
                }
            })
            .collect()
    }

    #[test]
    fn self_heating_is_the_same_at_any_tick_cadence() {
        let at_1hz = self_heating(&transient(0.0, 1.0)).expect("1 Hz");
        // A served bench ticking every 1.16 s, its record starting 2 s
        // after power-on: fewer intervals, the same device time covered.
        let served = self_heating(&transient(2.0, 1.16)).expect("1.16 s ticks");
        assert!((at_1hz - served).abs() < 0.01, "{at_1hz} {served}");
        assert!(at_1hz > 0.3, "{at_1hz}");
        // A record started 75 s late lacks most of the first window, and
        // says so in words.
        let late = self_heating(&transient(75.0, 1.0))
            .expect_err("late")
            .to_string();
        assert!(
            late.contains("first window") && late.contains("runs from 76 s"),
            "{late}"
        );
    }

    #[test]
    fn a_gap_is_not_covered_time() {
        let mut t: Vec<f64> = (0..120).map(f64::from).collect();
        t.retain(|x| !(30.0..80.0).contains(x));
        let c = covered_s(&t);
        assert!((c - 70.0).abs() < 1e-9, "{c}");
        assert_eq!(covered_s(&[]), 0.0);
    }
}
