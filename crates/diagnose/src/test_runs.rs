//! Runs made up for the tests, with a known answer: the sensor
//! temperatures are the twin's own thermal network driven by a chamber
//! profile, each position is held for whole records, and the rate is the
//! kinematic reference plus model 4's terms at known coefficients, a
//! per-run offset, white noise of a known sigma, and whatever a test
//! injects on top ([`inject`]).

use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::analysis::series::Interval;
use crate::data::{RunData, Sample};
use crate::geometry::Orientation;
use crate::library::{Effect, Param};
use crate::twin::TwinConfig;
use crate::twin::thermal::ThermalNetwork;

/// Model 4's terms in every made-up run: block gradient, deg/h/degC.
pub const K1_DPH_PER_C: f64 = 0.05;
/// Case temperature, deg/h/degC (above 20 degC).
pub const K4_DPH_PER_C: f64 = 0.002;
/// The warm-up transient's size, deg/h.
pub const K5_DPH: f64 = 0.03;
/// The warm-up transient's time constant, s (on the self-heating grid).
pub const WARMUP_TAU_S: f64 = 600.0;

/// The axis up at four azimuths, horizontal east at four rolls, horizontal
/// north, and down: positions that tell gravity, the Earth rate and the
/// magnetic field apart.
pub const POSES: [(f64, f64, f64); 10] = [
    (0.0, 90.0, 0.0),
    (90.0, 90.0, 0.0),
    (180.0, 90.0, 0.0),
    (270.0, 90.0, 0.0),
    (90.0, 0.0, 0.0),
    (90.0, 0.0, 90.0),
    (90.0, 0.0, 180.0),
    (90.0, 0.0, 270.0),
    (0.0, 0.0, 0.0),
    (0.0, -90.0, 0.0),
];

/// The axis horizontal east at eight rolls: gravity, the Earth rate and the
/// magnetic field all turn in the body's y-z plane (the north-down plane),
/// so a g-sensitivity, a magnetic sensitivity and a misalignment are one
/// sinusoid of the roll.
pub const ROLLS_EAST: [(f64, f64, f64); 8] = [
    (90.0, 0.0, 0.0),
    (90.0, 0.0, 45.0),
    (90.0, 0.0, 90.0),
    (90.0, 0.0, 135.0),
    (90.0, 0.0, 180.0),
    (90.0, 0.0, 225.0),
    (90.0, 0.0, 270.0),
    (90.0, 0.0, 315.0),
];

/// Chamber air of a thermal cycle, degC per second: 30 min at +20, up to
/// +45 at 0.5 degC/min, 40 min there, down to +5, 40 min there, back to
/// +20 (4.2 h).
pub fn cycle_air() -> Vec<f64> {
    let mut air = vec![20.0; 1800];
    let mut at: f64 = 20.0;
    for (target, hold_s) in [(45.0, 2400), (5.0, 2400), (20.0, 0)] {
        while (at - target).abs() > 1e-9 {
            at += (target - at).clamp(-1.0 / 120.0, 1.0 / 120.0);
            air.push(at);
        }
        air.extend(std::iter::repeat_n(at, hold_s));
    }
    air
}

/// A run of `air.len()` seconds on the twin's RL-16 network, powered at
/// t = 0: each of `poses` (azimuth, elevation, roll, deg) in turn for a
/// record of `record_s`, the rate the reference plus model 4's terms, an
/// offset of `offset_dph` and white noise of `noise_dph` at 1 Hz.
pub fn run(
    name: &str,
    air: &[f64],
    poses: &[(f64, f64, f64)],
    record_s: usize,
    offset_dph: f64,
    noise_dph: f64,
    seed: u64,
) -> RunData {
    let cfg = TwinConfig::default_rl16();
    let site = cfg.site;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut net = ThermalNetwork::soaked(&cfg.thermal, air.first().copied().unwrap_or(20.0));
    let samples = air
        .iter()
        .enumerate()
        .map(|(t, &air_c)| {
            net.step(1.0, air_c, true, 1.0);
            let record = t / record_s;
            let (az, el, roll) = poses[record % poses.len()];
            let orientation = Orientation::new(az, el, roll);
            let reference_dph = orientation.earth_rate_dph(&site);
            let time_s = t as f64 + 0.5;
            let bias = K1_DPH_PER_C * net.gradient_c()
                + K4_DPH_PER_C * (net.case_c - 20.0)
                + K5_DPH * (-time_s / WARMUP_TAU_S).exp()
                + offset_dph
                + noise_dph * rng.sample::<f64, _>(StandardNormal);
            Sample {
                iv: Interval {
                    time_s,
                    rate_dph: reference_dph + bias,
                    reference_dph,
                    t1_c: net.t1_c,
                    t2_c: net.t2_c,
                    tcase_c: net.case_c,
                    chamber_c: air_c,
                    frames: 400,
                },
                orientation,
                record: format!("r{record}"),
                step: format!("main.{record}").into(),
                table_rate_body_dph: nalgebra::Vector3::zeros(),
            }
        })
        .collect();
    RunData {
        name: name.to_owned(),
        site,
        samples,
    }
}

/// Two runs of one unit as a study makes them: a thermal cycle axis up
/// and [`POSES`] at +20 degC, a quarter of an hour each (6.7 h), with
/// white noise of `noise_dph` at 1 Hz.
pub fn study(noise_dph: f64, seed: u64) -> Vec<RunData> {
    vec![
        run(
            "cycle",
            &cycle_air(),
            &[(0.0, 90.0, 0.0)],
            900,
            0.02,
            noise_dph,
            seed,
        ),
        run(
            "positions",
            &vec![20.0; POSES.len() * 900],
            &POSES,
            900,
            -0.01,
            noise_dph,
            seed + 1,
        ),
    ]
}

/// `effect` at `param` added to the rate of every run, its terms weighted
/// by `coeffs` (as the library builds its regressors, so the fitted
/// coefficients are `coeffs`).
pub fn inject(runs: &mut [RunData], effect: Effect, param: Param, coeffs: &[f64]) {
    for run in runs.iter_mut() {
        let cols = effect.columns(run, param);
        for (i, s) in run.samples.iter_mut().enumerate() {
            s.iv.rate_dph += cols.iter().zip(coeffs).map(|(c, k)| c[i] * k).sum::<f64>();
        }
    }
}

/// A value per stacked row of `runs` (runs in order), from each sample.
pub fn per_row(runs: &[RunData], f: impl Fn(&Sample) -> f64) -> Vec<f64> {
    runs.iter().flat_map(|r| r.samples.iter().map(&f)).collect()
}
