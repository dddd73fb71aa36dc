//! The compensated drift: the peak-to-peak of the 600 s moving mean of
//! the model-4 residual, judged on coefficients that did not see the
//! records it is taken on (the unit's set with `--coeffs`, else model 4
//! fitted held out within the run), and the fit's own residual beside it
//! (informative). With its noise floor: what a perfectly compensated unit
//! with the run's own noise would read.

use super::uncertainty::{noise_floor, noise_of_means};
use crate::analysis::figures::{DriftTrace, drift_trace, mean};
use crate::analysis::model::{self, HELD_OUT_BLOCK_S, HELD_OUT_FOLDS, ModelKind};
use crate::analysis::series::Interval;

/// Which residual a compensated drift is taken on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Residual {
    /// Coefficients that did not see the records: `--coeffs`, else held
    /// out within the run.
    HeldOut,
    /// Model 4 fitted to the records themselves (the fit's residual).
    InSample,
}

/// A compensated drift as computed.
#[derive(Debug, Default)]
pub struct Drift {
    /// Peak-to-peak, deg/h.
    pub value: Option<f64>,
    /// How it was obtained, or why it is missing.
    pub note: String,
    /// The smoothed residual the peak-to-peak was taken on.
    pub trace: Option<DriftTrace>,
    /// The residual (each part's constant removed), for its noise.
    pub residual: Vec<f64>,
    /// Its noise floor, deg/h.
    pub noise_floor: Option<f64>,
}

fn times(series: &[Interval]) -> Vec<f64> {
    series.iter().map(|i| i.time_s).collect()
}

/// The model-4 residual of each part: with `coeffs`, else fitted as
/// `which` says; with the words saying how.
fn residuals(
    coeffs: Option<&crate::coeffs::Compensation>,
    parts: &[&[Interval]],
    which: Residual,
) -> Result<(Vec<Vec<f64>>, String), String> {
    match (coeffs, which) {
        (Some(c), Residual::HeldOut) => Ok((
            parts.iter().map(|p| c.fit.residual(p)).collect(),
            format!("model 4 with {}", c.used.describe()),
        )),
        (_, Residual::InSample) => {
            let f = model::fit_runs(ModelKind::Model4, parts)
                .map_err(|e| format!("cannot compensate: {e}"))?;
            Ok((
                parts.iter().map(|p| f.fit.residual(p)).collect(),
                "model 4 fitted on these records: the fit's own residual, informative".to_owned(),
            ))
        }
        (None, Residual::HeldOut) => {
            let r = model::held_out_residual(
                ModelKind::Model4,
                parts,
                HELD_OUT_BLOCK_S,
                HELD_OUT_FOLDS,
            )
            .map_err(|e| format!("cannot compensate: {e}"))?;
            Ok((
                r,
                format!(
                    "model 4 fitted held out (no --coeffs given): {} s blocks dealt into {} folds, \
                     each predicted by the fit on the others",
                    HELD_OUT_BLOCK_S, HELD_OUT_FOLDS
                ),
            ))
        }
    }
}

/// The compensated drift over `parts` (one per power-on) smoothed over
/// `window` samples; over several parts each part's constant removed (a
/// peak-to-peak does not see a constant within one part).
pub fn compensated_drift(
    coeffs: Option<&crate::coeffs::Compensation>,
    parts: &[&[Interval]],
    window: usize,
    which: Residual,
) -> Drift {
    let samples: usize = parts.iter().map(|p| p.len()).sum();
    let (resid, note) = match residuals(coeffs, parts, which) {
        Ok(r) => r,
        Err(note) => {
            return Drift {
                note,
                ..Drift::default()
            };
        }
    };
    if samples < window {
        return Drift {
            note,
            ..Drift::default()
        };
    }
    let several = parts.len() > 1;
    let shifted: Vec<(Vec<f64>, Vec<f64>)> = parts
        .iter()
        .zip(resid)
        .map(|(p, r)| {
            let c = if several { mean(&r) } else { 0.0 };
            (times(p), r.iter().map(|v| v - c).collect())
        })
        .collect();
    let trace = drift_trace(&shifted, window);
    let residual: Vec<f64> = shifted
        .iter()
        .flat_map(|(_, r)| r.iter().copied())
        .collect();
    let floor = noise_of_means(&residual, window).map(|(s, _)| noise_floor(s, samples, window));
    Drift {
        value: trace.as_ref().map(DriftTrace::pp),
        note,
        trace,
        residual,
        noise_floor: floor,
    }
}
