//! The thermal layer: sensor temperatures T1, T2, TK from the measured
//! chamber air. With a twin, its own thermal network is driven by the
//! measured air and orientation (nothing fitted). Without, the same network
//! form (case node, two coupled block nodes, self-heating rises, convection
//! with the sensor axis vertical) with its parameters fitted to the runs by
//! Nelder-Mead (argmin), starting from the RL-16 defaults, and scored held
//! out: each run's 60 s blocks are cut into [`FOLDS`] contiguous stretches
//! and each stretch is predicted with parameters fitted on the others (the
//! network runs through every stretch on the measured air; only the fit
//! leaves the stretch out).

use std::collections::BTreeMap;

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::neldermead::NelderMead;
use nalgebra::Vector3;

use super::ThermalLayer;
use super::data::RunData;
use super::engine::AVERAGING_S;
use crate::twin::TwinConfig;
use crate::twin::config::ThermalConfig;
use crate::twin::thermal::ThermalNetwork;

/// A run's thermal residual: (time since power-on s, measured - simulated
/// T1, T2, TK) per 60 s block.
pub type Series = Vec<(f64, [f64; 3])>;

/// Held-out stretches per run (ours: contiguous, never random samples).
pub const FOLDS: usize = 4;
/// Integration step of the fitted network, s (ours: a tenth of the
/// shortest time constant the network is started from).
const STEP_S: f64 = 10.0;
/// Nelder-Mead iterations per fit (ours: the fit settles within ~600 on
/// the study's runs).
const MAX_ITERS: u64 = 1500;

/// One 60 s block of a run: its span, the mean air and convection factor
/// input, and the measured means of T1, T2, TK.
#[derive(Debug, Clone)]
struct Block {
    start_s: f64,
    end_s: f64,
    /// Air over each [`STEP_S`] of the block.
    air_c: Vec<f64>,
    gravity_along_axis: f64,
    measured: [f64; 3],
    fold: usize,
}

/// The runs as 60 s blocks (within each record), with their fold.
fn blocks(runs: &[RunData], axis: Vector3<f64>) -> Vec<Vec<Block>> {
    runs.iter()
        .map(|run| {
            let mut out = Vec::new();
            let mut i = 0;
            let s = &run.samples;
            while i + AVERAGING_S <= s.len() {
                let c = &s[i..i + AVERAGING_S];
                if c.iter().any(|x| x.record != c[0].record) {
                    i += c.iter().position(|x| x.record != c[0].record).unwrap_or(1);
                    continue;
                }
                let n = c.len() as f64;
                let mean =
                    |f: &dyn Fn(&super::data::Sample) -> f64| c.iter().map(f).sum::<f64>() / n;
                out.push(Block {
                    start_s: c[0].iv.time_s - 0.5,
                    end_s: c[c.len() - 1].iv.time_s + 0.5,
                    air_c: c
                        .chunks(STEP_S as usize)
                        .map(|p| p.iter().map(|x| x.iv.chamber_c).sum::<f64>() / p.len() as f64)
                        .collect(),
                    gravity_along_axis: mean(&|x| x.gravity_body().dot(&axis).abs()),
                    measured: [
                        mean(&|x| x.iv.t1_c),
                        mean(&|x| x.iv.t2_c),
                        mean(&|x| x.iv.tcase_c),
                    ],
                    fold: 0,
                });
                i += AVERAGING_S;
            }
            let n = out.len().max(1);
            for (k, b) in out.iter_mut().enumerate() {
                b.fold = k * FOLDS / n;
            }
            out
        })
        .collect()
}

/// Simulated means of (T1, T2, TK) over each block: the network soaked at
/// the first air temperature, powered from t = 0, driven by the blocks' air.
fn simulate(cfg: &ThermalConfig, run: &[Block]) -> Vec<[f64; 3]> {
    let Some(first) = run.first() else {
        return Vec::new();
    };
    let mut net = ThermalNetwork::soaked(cfg, first.air_c[0]);
    let mut t = 0.0;
    run.iter()
        .map(|b| {
            let convection = 1.0 + cfg.convection_gain * b.gravity_along_axis;
            // Up to the block (gaps between records) on its first air.
            while t < b.start_s - 1e-9 {
                let dt = (b.start_s - t).min(STEP_S);
                net.step(dt, b.air_c[0], true, convection);
                t += dt;
            }
            let (mut acc, mut n) = ([0.0; 3], 0.0);
            for &air in &b.air_c {
                let dt = STEP_S.min(b.end_s - t).max(0.0);
                let before = [net.t1_c, net.t2_c, net.case_c];
                net.step(dt, air, true, convection);
                let after = [net.t1_c, net.t2_c, net.case_c];
                for k in 0..3 {
                    acc[k] += 0.5 * (before[k] + after[k]) * dt;
                }
                n += dt;
                t += dt;
            }
            acc.map(|a| a / n.max(1e-9))
        })
        .collect()
}

/// The fitted quantities: log time constants, rises, convection gain.
fn to_config(base: &ThermalConfig, p: &[f64]) -> ThermalConfig {
    let mut c = base.clone();
    c.case_tau_s = p[0].exp();
    c.block1_tau_s = p[1].exp();
    c.block2_tau_s = p[2].exp();
    c.coupling_tau_s = p[3].exp();
    c.case_rise_c = p[4];
    c.block1_rise_c = p[5];
    c.block2_rise_c = p[6];
    c.convection_gain = p[7].abs();
    c
}

fn from_config(c: &ThermalConfig) -> Vec<f64> {
    vec![
        c.case_tau_s.ln(),
        c.block1_tau_s.ln(),
        c.block2_tau_s.ln(),
        c.coupling_tau_s.ln(),
        c.case_rise_c,
        c.block1_rise_c,
        c.block2_rise_c,
        c.convection_gain,
    ]
}

/// Sum of squares of the block residuals outside `held_out` (no sensor
/// offsets: the self-heating rises would trade against them, and a stretch
/// without the warm-up could not tell them apart).
#[derive(Clone, Copy)]
struct Cost<'a> {
    base: &'a ThermalConfig,
    runs: &'a [Vec<Block>],
    held_out: Option<usize>,
}

impl Cost<'_> {
    /// Residuals (measured - simulated) per block.
    fn residuals(&self, cfg: &ThermalConfig) -> Vec<Vec<[f64; 3]>> {
        self.runs
            .iter()
            .map(|run| {
                simulate(cfg, run)
                    .iter()
                    .zip(run)
                    .map(|(sim, b)| [0, 1, 2].map(|k| b.measured[k] - sim[k]))
                    .collect()
            })
            .collect()
    }
}

impl CostFunction for Cost<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, p: &Vec<f64>) -> Result<f64, Error> {
        let res = self.residuals(&to_config(self.base, p));
        let mut sse = 0.0;
        for (run, r) in self.runs.iter().zip(&res) {
            for (b, v) in run.iter().zip(r) {
                if Some(b.fold) != self.held_out {
                    sse += v.iter().map(|x| x * x).sum::<f64>();
                }
            }
        }
        Ok(if sse.is_finite() { sse } else { f64::MAX })
    }
}

/// Nelder-Mead from `start`; the start itself when the solver fails.
fn fit(cost: Cost<'_>, start: &[f64]) -> Vec<f64> {
    // Initial simplex: the start and one step along each quantity (a
    // fifth in each time constant, 0.5 degC in each rise, 0.2 in gain).
    let mut simplex = vec![start.to_vec()];
    for i in 0..start.len() {
        let mut v = start.to_vec();
        v[i] += if i < 4 {
            0.2
        } else if i < 7 {
            0.5
        } else {
            0.2
        };
        simplex.push(v);
    }
    let Ok(solver) = NelderMead::new(simplex).with_sd_tolerance(1e-10) else {
        return start.to_vec();
    };
    Executor::new(cost, solver)
        .configure(|s| s.max_iters(MAX_ITERS))
        .run()
        .ok()
        .and_then(|r| r.state().get_best_param().cloned())
        .unwrap_or_else(|| start.to_vec())
}

/// The network fitted to all the runs, and the held-out RMS of the 60 s
/// means per sensor (each stretch predicted with parameters fitted on the
/// others).
pub fn fitted_network(
    runs: &[RunData],
    base: &ThermalConfig,
) -> (ThermalConfig, BTreeMap<String, f64>, Vec<Series>) {
    let base = base.clone();
    let axis = Vector3::from(base.sensor_axis_body).normalize();
    let data = blocks(runs, axis);
    let start = from_config(&base);
    let cost = |held_out| Cost {
        base: &base,
        runs: &data,
        held_out,
    };
    let all = fit(cost(None), &start);
    let (mut sse, mut n) = ([0.0; 3], 0usize);
    let mut series: Vec<Series> = data
        .iter()
        .map(|r| vec![(0.0, [0.0; 3]); r.len()])
        .collect();
    for k in 0..FOLDS {
        // From the defaults, not from the fit on all data: a quantity the
        // other stretches cannot pin down must not keep the held-out
        // stretch's value.
        let cost = cost(Some(k));
        let p = fit(cost, &start);
        let res = cost.residuals(&to_config(&base, &p));
        for ((run, r), out) in data.iter().zip(&res).zip(&mut series) {
            for ((b, v), o) in run.iter().zip(r).zip(out.iter_mut()) {
                if b.fold == k {
                    *o = (0.5 * (b.start_s + b.end_s), *v);
                    for j in 0..3 {
                        sse[j] += v[j].powi(2);
                    }
                    n += 1;
                }
            }
        }
    }
    let rms = |j: usize| (sse[j] / n.max(1) as f64).sqrt();
    let per_sensor = [("t1_c", 0), ("t2_c", 1), ("tcase_c", 2)]
        .into_iter()
        .map(|(name, j)| (name.to_owned(), rms(j)))
        .collect();
    (to_config(&base, &all), per_sensor, series)
}

/// The twin's network driven by the measured air: held-out is moot (nothing
/// is fitted); RMS of the 60 s means of measured minus simulated, and the
/// residual series.
fn twin_sensor_rms(runs: &[RunData], twin: &TwinConfig) -> (BTreeMap<String, f64>, Vec<Series>) {
    let axis = Vector3::from(twin.thermal.sensor_axis_body).normalize();
    let mut series = Vec::new();
    let (mut sse, mut n) = ([0.0; 3], 0usize);
    for run in runs {
        let Some(first) = run.samples.first() else {
            series.push(Vec::new());
            continue;
        };
        let mut net = ThermalNetwork::soaked(&twin.thermal, first.iv.chamber_c);
        let mut t = 0.0;
        let mut res = Vec::with_capacity(run.samples.len());
        for s in &run.samples {
            let convection = 1.0 + twin.thermal.convection_gain * s.gravity_body().dot(&axis).abs();
            while t < s.iv.time_s {
                let dt = (s.iv.time_s - t).min(1.0);
                net.step(dt, s.iv.chamber_c, true, convection);
                t += dt;
            }
            res.push((
                s.iv.time_s,
                [
                    s.iv.t1_c - net.t1_c,
                    s.iv.t2_c - net.t2_c,
                    s.iv.tcase_c - net.case_c,
                ],
            ));
        }
        let blocks: Series = res
            .chunks_exact(AVERAGING_S)
            .map(|c| {
                let k = c.len() as f64;
                let t = c.iter().map(|p| p.0).sum::<f64>() / k;
                (
                    t,
                    [0, 1, 2].map(|j| c.iter().map(|p| p.1[j]).sum::<f64>() / k),
                )
            })
            .collect();
        for (_, v) in &blocks {
            for j in 0..3 {
                sse[j] += v[j] * v[j];
            }
            n += 1;
        }
        series.push(blocks);
    }
    let per_sensor = [("t1_c", 0), ("t2_c", 1), ("tcase_c", 2)]
        .into_iter()
        .map(|(name, j)| (name.to_owned(), (sse[j] / n.max(1) as f64).sqrt()))
        .collect();
    (per_sensor, series)
}

/// RMS over the sensors.
fn quadratic_mean(per_sensor: &BTreeMap<String, f64>) -> f64 {
    let n = per_sensor.len().max(1) as f64;
    (per_sensor.values().map(|v| v * v).sum::<f64>() / n).sqrt()
}

/// The thermal layer's gap.
pub fn layer(runs: &[RunData], twin: Option<&TwinConfig>, fit_with_twin: bool) -> ThermalLayer {
    let mut network = None;
    let mut fitted_gap_c = None;
    let (per_sensor_c, series, reference) = match twin {
        Some(t) => {
            let (per_sensor, series) = twin_sensor_rms(runs, t);
            if fit_with_twin {
                let (fitted, fitted_sensor, _) = fitted_network(runs, &t.thermal);
                network = Some(fitted);
                fitted_gap_c = Some(quadratic_mean(&fitted_sensor));
            }
            (
                per_sensor,
                series,
                "the twin's thermal network driven by the measured chamber air and orientation"
                    .to_owned(),
            )
        }
        None => {
            let (fitted, per_sensor, series) =
                fitted_network(runs, &TwinConfig::default_rl16().thermal);
            network = Some(fitted);
            (
                per_sensor,
                series,
                "the twin's thermal network form (case, two coupled blocks, self-heating rises, convection) with its time constants, rises and convection gain fitted to the runs (Nelder-Mead from the RL-16 defaults); each quarter of a run predicted with parameters fitted on the rest".to_owned(),
            )
        }
    };
    ThermalLayer {
        gap_c: quadratic_mean(&per_sensor_c),
        per_sensor_c,
        reference,
        fitted: network,
        fitted_gap_c,
        series,
    }
}
