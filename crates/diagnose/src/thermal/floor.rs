//! The sensors' noise floor: what their own noise and resolution leave
//! in a held-out gap of 60 s means.

use super::*;

/// What the sensors' own noise and resolution leave in the held-out gap
/// of 60 s means, however good the model: per sensor, from the runs alone.
///
/// The 1 Hz white noise is read from second differences of consecutive
/// samples (1.4826 MAD / sqrt 6: robust to the few where the temperature
/// bends), and the resolution from the smallest step between samples when
/// most steps are whole multiples of it (a quantised sensor). A 60 s mean
/// keeps the white noise over sqrt 60; a quantisation the noise does not
/// dither (noise under half a step) stays whole, as uniform error of
/// step / sqrt 12. Returns (per sensor, RMS over them), degC.
pub fn noise_floor(runs: &[RunData]) -> (BTreeMap<String, f64>, f64) {
    let mut per_sensor = BTreeMap::new();
    for (name, j) in [("t1_c", 0), ("t2_c", 1), ("tcase_c", 2)] {
        let value = |s: &crate::data::Sample| [s.iv.t1_c, s.iv.t2_c, s.iv.tcase_c][j];
        let mut second = Vec::new();
        let mut steps = Vec::new();
        for run in runs {
            for w in run.samples.windows(3) {
                let even = (w[1].iv.time_s - w[0].iv.time_s - 1.0).abs() < 0.5
                    && (w[2].iv.time_s - w[1].iv.time_s - 1.0).abs() < 0.5;
                if even {
                    second.push(value(&w[0]) - 2.0 * value(&w[1]) + value(&w[2]));
                }
            }
            for w in run.samples.windows(2) {
                let d = (value(&w[1]) - value(&w[0])).abs();
                if d > 1e-9 {
                    steps.push(d);
                }
            }
        }
        let sigma_1hz = median_abs(&mut second).map_or(0.0, |m| 1.4826 * m / 6f64.sqrt());
        let q = resolution(&steps);
        let undithered = q > 0.0 && sigma_1hz < 0.5 * q;
        let var = sigma_1hz * sigma_1hz / AVERAGING_S as f64
            + if undithered { q * q / 12.0 } else { 0.0 };
        per_sensor.insert(name.to_owned(), var.sqrt());
    }
    let rms = quadratic_mean(&per_sensor);
    (per_sensor, rms)
}

/// Median of |v|, none when empty.
pub(super) fn median_abs(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    for x in v.iter_mut() {
        *x = x.abs();
    }
    v.sort_by(f64::total_cmp);
    Some(v[v.len() / 2])
}

/// A sensor's resolution from the steps between its samples: the smallest
/// step, when at least 90 % of the steps are whole multiples of it (to a
/// tenth of it); 0 for a sensor that is not quantised (or whose values are
/// means over many readings).
pub(super) fn resolution(steps: &[f64]) -> f64 {
    let Some(q) = steps.iter().copied().min_by(f64::total_cmp) else {
        return 0.0;
    };
    let whole = steps
        .iter()
        .filter(|d| {
            let k = *d / q;
            (k - k.round()).abs() < 0.1
        })
        .count();
    if q > 1e-6 && whole as f64 >= 0.9 * steps.len() as f64 {
        q
    } else {
        0.0
    }
}
