//! The thermal layer: sensor temperatures T1, T2, TK from the measured
//! chamber air. Without a twin, the case is a first-order lag of the air
//! and each block sensor a further lag of that, each plus a warm-up rise
//! `1 - exp(-t/tau)` (the powered gyro), the time constants chosen on all
//! data and the rest fitted per fold, scored held-out on 60 s means
//! like the rate layer. With a twin, its own thermal network is driven by
//! the measured air and orientation (nothing fitted).

use std::collections::BTreeMap;

use nalgebra::Vector3;

use super::ThermalLayer;
use super::data::RunData;
use super::engine::AVERAGING_S;
use crate::twin::TwinConfig;
use crate::twin::thermal::ThermalNetwork;

const TAU_GRID_S: [f64; 8] = [60.0, 120.0, 300.0, 600.0, 1200.0, 2400.0, 4800.0, 9600.0];

/// `input` (one value per sample) through a first-order lag of `tau` s.
fn lag_of(run: &RunData, input: &[f64], tau: f64) -> Vec<f64> {
    let mut y: Option<f64> = None;
    let mut last: Option<f64> = None;
    run.samples
        .iter()
        .zip(input)
        .map(|(s, &u)| {
            let dt = last.map_or(1.0, |l| (s.iv.time_s - l).max(0.0));
            last = Some(s.iv.time_s);
            let v = y.get_or_insert(u);
            *v += (u - *v) * (-(-dt / tau).exp_m1());
            *v
        })
        .collect()
}

/// The air through the case's lag `case_tau` (`None`: the air itself), then
/// through `tau`: one stage for the case, two for the blocks.
fn lagged(run: &RunData, case_tau: Option<f64>, tau: f64) -> Vec<f64> {
    let air: Vec<f64> = run.samples.iter().map(|s| s.iv.chamber_c).collect();
    match case_tau {
        Some(c) => lag_of(run, &lag_of(run, &air, c), tau),
        None => lag_of(run, &air, tau),
    }
}

/// Held-out RMS (60 s means) of `measured - (a + b lag(air) + c (1 -
/// exp(-t/tau)))`, one fold per record, a, b, c fitted on the other folds
/// of the same run; and the in-sample sum of squares (to choose tau).
fn fit_sensor(
    runs: &[RunData],
    get: fn(&crate::analysis::series::Interval) -> f64,
    case_tau: Option<f64>,
    tau: f64,
) -> (f64, f64, usize) {
    use nalgebra::{Matrix3, Vector3 as V3};
    let (mut sse, mut ins, mut nb) = (0.0, 0.0, 0usize);
    for run in runs {
        let x = lagged(run, case_tau, tau);
        let rows: Vec<(V3<f64>, f64)> = run
            .samples
            .iter()
            .zip(&x)
            .map(|(s, &l)| (V3::new(1.0, l, -(-s.iv.time_s / tau).exp_m1()), get(&s.iv)))
            .collect();
        let mut folds: Vec<(usize, usize)> = Vec::new();
        for (i, s) in run.samples.iter().enumerate() {
            match folds.last_mut() {
                Some(f) if run.samples[f.0].record == s.record => f.1 = i + 1,
                _ => folds.push((i, i + 1)),
            }
        }
        let sums = |lo: usize, hi: usize| {
            let mut g = Matrix3::zeros();
            let mut h = V3::zeros();
            for (r, y) in &rows[lo..hi] {
                g += r * r.transpose();
                h += r * *y;
            }
            (g, h)
        };
        let solve = |g: Matrix3<f64>, h: V3<f64>| {
            let ridge = 1e-9 * g.trace().max(1e-12);
            (g + Matrix3::identity() * ridge)
                .try_inverse()
                .map_or(V3::zeros(), |inv| inv * h)
        };
        let (ga, ha) = sums(0, rows.len());
        let beta = solve(ga, ha);
        ins += rows
            .iter()
            .map(|(r, y)| (y - r.dot(&beta)).powi(2))
            .sum::<f64>();
        for &(lo, hi) in &folds {
            let beta = if folds.len() > 1 {
                let (g, h) = sums(lo, hi);
                solve(ga - g, ha - h)
            } else {
                beta
            };
            for c in rows[lo..hi].chunks_exact(AVERAGING_S) {
                let r = c.iter().map(|(x, y)| y - x.dot(&beta)).sum::<f64>() / c.len() as f64;
                sse += r * r;
                nb += 1;
            }
        }
    }
    (sse, ins, nb)
}

/// The twin's network driven by the measured air: held-out is moot (nothing
/// is fitted); RMS of the 60 s means of measured minus simulated.
fn twin_sensor_rms(runs: &[RunData], twin: &TwinConfig) -> BTreeMap<String, f64> {
    let mut sums: BTreeMap<String, (f64, usize)> = BTreeMap::new();
    let axis = Vector3::from(twin.thermal.sensor_axis_body).normalize();
    for run in runs {
        let Some(first) = run.samples.first() else {
            continue;
        };
        let mut net = ThermalNetwork::soaked(&twin.thermal, first.iv.chamber_c);
        let mut t = 0.0;
        let mut sim = Vec::with_capacity(run.samples.len());
        for s in &run.samples {
            let convection = 1.0 + twin.thermal.convection_gain * s.gravity_body().dot(&axis).abs();
            while t < s.iv.time_s {
                let dt = (s.iv.time_s - t).min(1.0);
                net.step(dt, s.iv.chamber_c, true, convection);
                t += dt;
            }
            sim.push((net.t1_c, net.t2_c, net.case_c));
        }
        for (name, k) in [("t1_c", 0), ("t2_c", 1), ("tcase_c", 2)] {
            let e = sums.entry(name.into()).or_insert((0.0, 0));
            for c in (0..run.samples.len())
                .collect::<Vec<_>>()
                .chunks_exact(AVERAGING_S)
            {
                let r = c
                    .iter()
                    .map(|&i| {
                        let m = &run.samples[i].iv;
                        let (a, b, cc) = sim[i];
                        [m.t1_c - a, m.t2_c - b, m.tcase_c - cc][k]
                    })
                    .sum::<f64>()
                    / c.len() as f64;
                e.0 += r * r;
                e.1 += 1;
            }
        }
    }
    sums.into_iter()
        .map(|(k, (s, n))| (k, (s / n.max(1) as f64).sqrt()))
        .collect()
}

/// The thermal layer's gap.
pub fn layer(runs: &[RunData], twin: Option<&TwinConfig>) -> ThermalLayer {
    let (per_sensor_c, reference) = match twin {
        Some(t) => (
            twin_sensor_rms(runs, t),
            "the twin's thermal network driven by the measured chamber air and orientation"
                .to_owned(),
        ),
        None => {
            type Get = fn(&crate::analysis::series::Interval) -> f64;
            let best = |get: Get, case_tau: Option<f64>| {
                TAU_GRID_S
                    .iter()
                    .map(|&tau| (tau, fit_sensor(runs, get, case_tau, tau)))
                    .min_by(|a, b| a.1.1.total_cmp(&b.1.1))
                    .unwrap_or((600.0, (f64::NAN, f64::NAN, 1)))
            };
            let mut out = BTreeMap::new();
            // The case follows the air; each block follows the case.
            let (case_tau, (sse, _, nb)) = best(|iv| iv.tcase_c, None);
            out.insert("tcase_c".to_owned(), (sse / nb.max(1) as f64).sqrt());
            let sensors: [(&str, Get); 2] = [("t1_c", |iv| iv.t1_c), ("t2_c", |iv| iv.t2_c)];
            for (name, get) in sensors {
                let (_, (sse, _, nb)) = best(get, Some(case_tau));
                out.insert(name.to_owned(), (sse / nb.max(1) as f64).sqrt());
            }
            (
                out,
                "the case a first-order lag of the measured chamber air, each block sensor a further lag of that, each plus a warm-up rise with its time constant; fitted on the other records of the run".to_owned(),
            )
        }
    };
    let n = per_sensor_c.len().max(1) as f64;
    ThermalLayer {
        gap_c: (per_sensor_c.values().map(|v| v * v).sum::<f64>() / n).sqrt(),
        per_sensor_c,
        reference,
    }
}
