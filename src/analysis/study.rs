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
    let window = |lo: f64, hi: f64| -> Option<f64> {
        let v: Vec<f64> = series
            .iter()
            .filter(|s| s.time_s >= lo && s.time_s < hi)
            .map(Interval::bias_dph)
            .collect();
        (v.len() as f64 >= 0.9 * (hi - lo)).then(|| mean(&v))
    };
    let first = window(0.0, SELF_HEATING_WINDOW_S)?;
    let last = window(
        SELF_HEATING_SPAN_S - SELF_HEATING_WINDOW_S,
        SELF_HEATING_SPAN_S,
    )?;
    Some(first - last)
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
