//! The withheld-effect experiment: runs of the twin with one library effect
//! added (at amplitudes in units of the noise), diagnosed against a
//! reference without it; null runs with nothing added; runs with an effect
//! outside the library (a slow periodic disturbance). Says how often each
//! effect is named first, how much of its gap closes, how often a null run
//! gets an effect, and whether the outsider is ever attributed.

use std::collections::BTreeMap;

use serde::Serialize;

use super::data::{RunData, Sample};
use super::library::{Effect, LIBRARY, Param};
use super::{Options, diagnose};
use crate::geometry::TableGeometry;
use crate::study::{
    ORIENTATION_NORTH_TOML, ORIENTATION_TOML, RATE_TEMPERATURES_TOML, SEPARATING_TOML, StudyError,
    THERMAL_CYCLE_NORTH_TOML, THERMAL_CYCLE_TOML, simulate_samples,
};
use crate::twin::TwinConfig;
use crate::twin::config as tc;

/// Amplitudes, in units of the noise at the averaging time.
pub const AMPLITUDES: [f64; 2] = [1.5, 3.0];
/// Period of the out-of-library disturbance, s (ours).
pub const PERIODIC_PERIOD_S: f64 = 5400.0;
/// Its amplitude, in units of the noise.
pub const PERIODIC_AMPLITUDE: f64 = 3.0;

/// What one experiment injected.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Injected {
    /// Nothing.
    Null,
    /// A library effect at an amplitude (noise units).
    Effect(String, f64),
    /// The out-of-library periodic disturbance.
    Periodic,
}

impl Injected {
    fn label(&self) -> String {
        match self {
            Self::Null => "null".into(),
            Self::Effect(n, a) => format!("{n}@{a}"),
            Self::Periodic => "periodic (outside)".into(),
        }
    }
}

/// One experiment's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct Trial {
    /// What was injected.
    pub injected: String,
    /// Seed of its runs.
    pub seed: u64,
    /// The first accepted effect (none when nothing was significant).
    pub attributed: Option<String>,
    /// Every accepted effect.
    pub accepted: Vec<String>,
    /// Reference gap, deg/h.
    pub gap_before_dph: f64,
    /// Gap after the accepted effects, deg/h.
    pub gap_after_dph: f64,
    /// Fraction of the injected effect's excess gap (over the null runs'
    /// gap) closed: (before^2 - after^2) / (before^2 - null^2).
    pub excess_closed: Option<f64>,
    /// Period the diagnosis reports: of a periodic disturbance it held
    /// outside the library, else of the residual left unexplained, s.
    pub period_s: Option<f64>,
    /// Every candidate against the reference: name, held-out gap, p-value.
    pub candidates: Vec<(String, f64, f64)>,
    /// Pairs reported as confounded.
    pub confounded: Vec<[String; 2]>,
}

/// Per effect and amplitude.
#[derive(Debug, Clone, Serialize)]
pub struct Power {
    /// Library name.
    pub effect: String,
    /// Amplitude, noise units.
    pub amplitude: f64,
    /// The coefficient injected for it (the effect's own unit: deg/h per
    /// degC, per g, ..., along the self-check's direction).
    pub coefficient: f64,
    /// Runs.
    pub runs: usize,
    /// Fraction named first.
    pub named_first: f64,
    /// Mean fraction of the excess gap closed when named first.
    pub excess_closed: f64,
    /// Fraction of the runs where a confounded pair included it.
    pub confounded: f64,
}

/// How much of an effect the procedures let show, per unit coefficient
/// (the coefficient along [`DIRECTION`] for multi-term effects).
#[derive(Debug, Clone, Serialize)]
pub struct EffectSize {
    /// Library name.
    pub effect: String,
    /// RMS of its contribution's 60 s means (each run's mean removed),
    /// deg/h per unit coefficient.
    pub rms_dph: f64,
    /// The held-out gap the effect alone opens against the reference
    /// (noise-free), deg/h per unit coefficient: the unit its amplitudes
    /// are stated in. What the reference's refitted terms reproduce does
    /// not count.
    pub gap_dph: f64,
    /// `gap_dph / rms_dph`: near 0, the reference's terms reproduce the
    /// effect (it hides in them with these runs); about 1, none of it can
    /// be absorbed (above 1 when the reference's terms, refitted to it,
    /// extrapolate badly into the held-out blocks).
    pub gap_per_rms: f64,
}

/// The self-check's result.
#[derive(Debug, Clone, Serialize)]
pub struct SelfCheck {
    /// Runs per case.
    pub runs: usize,
    /// First seed.
    pub seed: u64,
    /// The procedures of each trial (names).
    pub procedures: Vec<String>,
    /// What an amplitude of 1 is.
    pub unit: Unit,
    /// Noise unit: the reference's held-out gap on null runs (RMS of the
    /// 60 s means), deg/h.
    pub noise_dph: f64,
    /// How much of each effect these procedures let show.
    pub sizes: Vec<EffectSize>,
    /// Detection power per effect and amplitude.
    pub power: Vec<Power>,
    /// Injected (rows) against attributed first (columns), counts.
    pub confusion: BTreeMap<String, BTreeMap<String, usize>>,
    /// Fraction of null runs with any effect accepted.
    pub false_positive_rate: f64,
    /// Fraction of periodic runs with any effect accepted.
    pub periodic_attributed: f64,
    /// Fraction of periodic runs whose unexplained part named a period
    /// within 20 % of the true one.
    pub periodic_period_found: f64,
    /// Every trial.
    pub trials: Vec<Trial>,
}

pub(crate) fn to_run(samples: Vec<crate::study::Sample>, name: &str, twin: &TwinConfig) -> RunData {
    RunData {
        name: name.into(),
        site: twin.site,
        samples: samples
            .into_iter()
            .map(|s| Sample {
                iv: s.interval,
                orientation: s.orientation,
                step: s.step.into(),
                record: s.record,
                table_rate_body_dph: s.table_rate_body_dph,
            })
            .collect(),
    }
}

/// The runs of one trial on `twin`: the study's thermal cycle and
/// orientation run (their `_north` versions on a table turned north),
/// and with `separating` also `procedures/separating.toml`
/// and the rate transfer at three temperatures
/// (`procedures/rate_transfer_temperatures.toml`).
pub(crate) fn runs_of(
    twin: &TwinConfig,
    seed: u64,
    separating: bool,
) -> Result<Vec<RunData>, StudyError> {
    // A table turned north (a lab near the equator) runs the cycle with
    // the axis north and rolls about north: the study's east-pointing
    // poses are out of its reach.
    let mut procedures = if twin.table.geometry == TableGeometry::north() {
        vec![
            (THERMAL_CYCLE_NORTH_TOML, "thermal_cycle_north"),
            (ORIENTATION_NORTH_TOML, "orientation_north"),
        ]
    } else {
        vec![
            (THERMAL_CYCLE_TOML, "thermal_cycle"),
            (ORIENTATION_TOML, "orientation"),
        ]
    };
    if separating {
        procedures.push((SEPARATING_TOML, "separating"));
        procedures.push((RATE_TEMPERATURES_TOML, "rate_transfer_temperatures"));
    }
    procedures
        .into_iter()
        .enumerate()
        .map(|(k, (text, name))| {
            let s = seed.wrapping_add(1_000_000 * k as u64);
            let samples = simulate_samples(text, name, twin, s)?;
            Ok(to_run(samples, &format!("{name} (seed {s})"), twin))
        })
        .collect()
}

/// Unit direction of the multi-term effects (ours).
const DIRECTION: [f64; 3] = [0.0, 0.8, 0.6];

/// An effect's contribution with coefficient 1 along [`DIRECTION`], per
/// sample, runs in order.
pub(crate) fn contribution(runs: &[RunData], e: Effect, p: Param) -> Vec<f64> {
    let mut out = Vec::new();
    for run in runs {
        let cols = e.columns(run, p);
        let dir: &[f64] = match cols.len() {
            3 => &DIRECTION,
            2 => &DIRECTION[1..],
            _ => &[1.0],
        };
        out.extend(
            (0..run.samples.len())
                .map(|i| cols.iter().zip(dir).map(|(c, d)| c[i] * d).sum::<f64>()),
        );
    }
    out
}

/// RMS over the runs' 60 s means (each run's mean removed) of `v`.
fn rms_of_means(runs: &[RunData], v: &[f64]) -> f64 {
    let (mut ss, mut n, mut at) = (0.0, 0usize, 0);
    for run in runs {
        let means: Vec<f64> = v[at..at + run.samples.len()]
            .chunks_exact(super::engine::AVERAGING_S)
            .map(|c| c.iter().sum::<f64>() / c.len() as f64)
            .collect();
        at += run.samples.len();
        let m = means.iter().sum::<f64>() / means.len().max(1) as f64;
        ss += means.iter().map(|x| (x - m).powi(2)).sum::<f64>();
        n += means.len();
    }
    (ss / n.max(1) as f64).sqrt()
}

/// How big an effect is, with coefficient 1: the held-out gap it opens
/// against `reference` (what the reference's refitted terms reproduce
/// does not count), and its plain RMS.
#[derive(Debug, Clone, Copy)]
struct Size {
    visible: f64,
    rms: f64,
}

fn size(runs: &[RunData], e: Effect, p: Param, reference: &TwinConfig) -> Size {
    let c = contribution(runs, e, p);
    let opts = Options {
        twin: Some(reference.clone()),
        fit_thermal: false,
        power_replications: 0,
    };
    Size {
        visible: super::visible_gap(runs, &opts, &c),
        rms: rms_of_means(runs, &c),
    }
}

/// The nonlinear parameter effect `e` has as [`inject`] puts it in `base`:
/// the warm-up's time constant, memory effects on the case.
pub(crate) fn injected_param(base: &TwinConfig, e: Effect) -> Param {
    match e {
        Effect::SelfHeating => Param::TauS(base.bias.model4.warmup_tau_s),
        Effect::Hysteresis => Param::Memory {
            on: tc::EffectTemperature::Case,
            value: 2.0,
        },
        Effect::ThermalLag => Param::Memory {
            on: tc::EffectTemperature::Case,
            value: 1800.0,
        },
        _ => Param::None,
    }
}

/// The twin with effect `e` added at coefficient `a` (along [`DIRECTION`]),
/// and the reference twin without it.
pub(crate) fn inject(base: &TwinConfig, e: Effect, a: f64) -> (TwinConfig, TwinConfig) {
    let mut data = base.clone();
    let mut reference = base.clone();
    let d = DIRECTION;
    match e {
        Effect::Hysteresis => {
            data.effects.hysteresis = Some(tc::Hysteresis {
                enabled: true,
                amplitude_dph: a,
                width_c: 2.0,
                temperature: tc::EffectTemperature::Case,
                shape: tc::HysteresisShape::Play,
            });
        }
        Effect::ThermalLag => {
            data.effects.thermal_lag = Some(tc::ThermalLag {
                enabled: true,
                coeff_dph_per_c: a,
                tau_s: 1800.0,
                reference_c: 20.0,
                temperature: tc::EffectTemperature::Case,
                order: 1,
            });
        }
        Effect::GSensitivity => {
            data.effects.g_sensitivity = Some(tc::GSensitivity {
                enabled: true,
                coeff_dph_per_g: d.map(|x| x * a),
            });
        }
        Effect::MagneticSensitivity => {
            data.effects.magnetic_sensitivity = Some(tc::MagneticSensitivity {
                enabled: true,
                coeff_dph_per_ut: d.map(|x| x * a),
            });
        }
        Effect::AxisMisalignment => {
            // Coefficients (theta_z, -theta_y) = a (0.8, 0.6), in rad.
            let arcmin = |rad: f64| rad.to_degrees() * 60.0;
            data.effects.axis_misalignment = Some(tc::AxisMisalignment {
                enabled: true,
                about_y_arcmin: arcmin(-a * d[2]),
                about_z_arcmin: arcmin(a * d[1]),
            });
        }
        Effect::ScaleFactorTemperature => {
            data.effects.scale_factor_temperature = Some(tc::ScaleFactorTemperature {
                enabled: true,
                ppm_per_c: a * 1e6,
                reference_c: 20.0,
            });
        }
        Effect::EarthRateError => {
            data.effects.earth_rate_error = Some(tc::EarthRateError {
                enabled: true,
                latitude_dph: a * d[1],
                east_dph: a * d[2],
            });
        }
        Effect::SelfHeating => {
            data.bias.model4.k5_dph = a;
            reference.bias.terms.self_heating = false;
        }
        Effect::GradientRate => {
            data.bias.model4.k3_dph_per_c_per_s = a;
            reference.bias.terms.gradient_rate = false;
        }
        Effect::GradientQuadratic => {
            data.bias.model4.k2_dph_per_c2 = a;
            reference.bias.terms.gradient_quadratic = false;
        }
        Effect::CaseTemperature => {
            data.bias.model4.k4_dph_per_c = a;
            reference.bias.terms.case_temperature = false;
        }
        // Not injectable: model 4's own first term, and the disturbances
        // outside the library (the randomised self-check adds those to
        // the rates).
        Effect::Gradient | Effect::BiasStep | Effect::BiasDrift | Effect::Periodic => {}
    }
    (data, reference)
}

fn trial(
    injected: &Injected,
    seed: u64,
    separating: bool,
    data_twin: &TwinConfig,
    reference: &TwinConfig,
    null_gap: f64,
) -> Result<Trial, StudyError> {
    let runs = runs_of(data_twin, seed, separating)?;
    let d = diagnose(
        &runs,
        &Options {
            // The self-check is about the rate layer.
            twin: Some(reference.clone()),
            fit_thermal: false,
            power_replications: 0,
        },
    );
    let accepted: Vec<String> = d.effects.iter().map(|e| e.name.clone()).collect();
    let (before, after) = (d.layers.rate.gap_dph, d.layers.rate.gap_after_dph);
    let excess_closed = match injected {
        Injected::Effect(..) if before * before > null_gap * null_gap => Some(
            ((before * before - after * after) / (before * before - null_gap * null_gap))
                .clamp(0.0, 1.0),
        ),
        _ => None,
    };
    Ok(Trial {
        injected: injected.label(),
        seed,
        attributed: accepted.first().cloned(),
        accepted,
        gap_before_dph: before,
        gap_after_dph: after,
        excess_closed,
        period_s: d
            .unexplained
            .outside
            .iter()
            .find_map(|o| o.period_s)
            .or(d.unexplained.period_s),
        candidates: d
            .candidates
            .iter()
            .map(|c| (c.name.clone(), c.held_out_gap_dph, c.p_value))
            .collect(),
        confounded: d.confounded.iter().map(|c| c.effects.clone()).collect(),
    })
}

/// What to run.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Runs per case.
    pub runs: usize,
    /// First seed.
    pub seed: u64,
    /// The library effects to inject.
    pub effects: Vec<Effect>,
    /// Add `procedures/separating.toml` to each trial's runs.
    pub separating: bool,
    /// What an amplitude of 1 is.
    pub unit: Unit,
}

/// How an effect's amplitude is stated in units of the noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Unit {
    /// The held-out gap the effect alone opens against the reference
    /// (what the reference's terms reproduce does not count).
    Gap,
    /// The plain RMS of its contribution's 60 s means.
    Rms,
}

/// One trial finished, as the self-check reports its progress.
#[derive(Debug, Clone, Copy)]
pub struct TrialDone<'a> {
    /// Trials finished so far, this one included.
    pub done: usize,
    /// Trials in the whole self-check.
    pub total: usize,
    /// What the trial's runs carried.
    pub injected: &'a Injected,
    /// Its outcome.
    pub trial: &'a Trial,
}

impl Plan {
    /// Trials the self-check makes: `runs` each of the null case, every
    /// effect at every amplitude, and the outside effect.
    pub fn trials(&self) -> usize {
        self.runs * (1 + self.effects.len() * AMPLITUDES.len() + 1)
    }
}

/// Run the self-check; `progress` hears of each trial as it ends (from
/// the worker threads, in the order they finish).
pub fn run(
    plan: &Plan,
    progress: &(dyn Fn(TrialDone<'_>) + Sync),
) -> Result<SelfCheck, StudyError> {
    let total = plan.trials();
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let report = |injected: &Injected, trial: &Trial| {
        let done = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress(TrialDone {
            done,
            total,
            injected,
            trial,
        });
    };
    let (runs, seed, separating) = (plan.runs, plan.seed, plan.separating);
    let base = TwinConfig::default_rl16();
    // Null runs first: they give the noise unit.
    let mut trials: Vec<(Injected, Trial)> = Vec::new();
    let mut null_gaps = Vec::new();
    let mut null_runs: Option<Vec<RunData>> = None;
    for k in 0..runs {
        let s = seed + k as u64;
        let t = trial(&Injected::Null, s, separating, &base, &base, 0.0)?;
        report(&Injected::Null, &t);
        null_gaps.push(t.gap_before_dph);
        trials.push((Injected::Null, t));
        if null_runs.is_none() {
            null_runs = Some(runs_of(&base, s, separating)?);
        }
    }
    let noise = null_gaps.iter().sum::<f64>() / null_gaps.len().max(1) as f64;
    let probe = null_runs.unwrap_or_default();
    let Cases {
        cases,
        sizes,
        coefficients,
    } = cases(plan, &base, &probe, noise);
    trials.extend(run_cases(plan, &cases, noise, &report)?);

    let mut confusion: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for (inj, t) in &trials {
        *confusion
            .entry(inj.label())
            .or_default()
            .entry(t.attributed.clone().unwrap_or_else(|| "none".into()))
            .or_default() += 1;
    }
    let power = power_of(&plan.effects, &trials, &coefficients);
    let rate = |label: &Injected, f: &dyn Fn(&Trial) -> bool| {
        let v: Vec<&Trial> = trials
            .iter()
            .filter(|(i, _)| i == label)
            .map(|(_, t)| t)
            .collect();
        v.iter().filter(|t| f(t)).count() as f64 / v.len().max(1) as f64
    };
    let mut procedures = vec!["thermal_cycle".to_owned(), "orientation".to_owned()];
    if separating {
        procedures.push("separating".into());
        procedures.push("rate_transfer_temperatures".into());
    }
    Ok(SelfCheck {
        runs,
        seed,
        procedures,
        unit: plan.unit,
        noise_dph: noise,
        sizes,
        power,
        confusion,
        false_positive_rate: rate(&Injected::Null, &|t| t.attributed.is_some()),
        periodic_attributed: rate(&Injected::Periodic, &|t| t.attributed.is_some()),
        periodic_period_found: rate(&Injected::Periodic, &|t| {
            t.period_s
                .is_some_and(|p| (p / PERIODIC_PERIOD_S - 1.0).abs() < 0.2)
        }),
        trials: trials.into_iter().map(|(_, t)| t).collect(),
    })
}

/// The injected cases of a self-check, each with the twin its runs are
/// made on and the reference it is diagnosed against; every effect's
/// size on the null runs; the coefficient each effect and amplitude got.
struct Cases {
    cases: Vec<(Injected, TwinConfig, TwinConfig)>,
    sizes: Vec<EffectSize>,
    coefficients: BTreeMap<(String, u64), f64>,
}

/// Every effect of `plan` at every amplitude (in units of `noise`, the
/// null runs' gap, sized on `probe`), and the outside periodic effect.
fn cases(plan: &Plan, base: &TwinConfig, probe: &[RunData], noise: f64) -> Cases {
    let mut cases: Vec<(Injected, TwinConfig, TwinConfig)> = Vec::new();
    let mut sizes = Vec::new();
    let mut coefficients: BTreeMap<(String, u64), f64> = BTreeMap::new();
    for &e in &plan.effects {
        let p = injected_param(base, e);
        let unit = size(probe, e, p, &inject(base, e, 1.0).1);
        sizes.push(EffectSize {
            effect: e.name().into(),
            rms_dph: unit.rms,
            gap_dph: unit.visible,
            gap_per_rms: unit.visible / unit.rms,
        });
        let per_unit = match plan.unit {
            Unit::Gap => unit.visible,
            Unit::Rms => unit.rms,
        };
        for &amp in &AMPLITUDES {
            let a = if per_unit > 0.0 {
                amp * noise / per_unit
            } else {
                0.0
            };
            coefficients.insert((e.name().to_owned(), amp.to_bits()), a);
            let (data, reference) = inject(base, e, a);
            cases.push((Injected::Effect(e.name().into(), amp), data, reference));
        }
    }
    let mut periodic = base.clone();
    periodic.effects.periodic = Some(tc::Periodic {
        enabled: true,
        // A sine of amplitude A has RMS A / sqrt(2).
        amplitude_dph: PERIODIC_AMPLITUDE * noise * std::f64::consts::SQRT_2,
        period_s: PERIODIC_PERIOD_S,
    });
    cases.push((Injected::Periodic, periodic, base.clone()));
    Cases {
        cases,
        sizes,
        coefficients,
    }
}

/// `plan.runs` trials of every case, on up to four worker threads over
/// the (case, seed) pairs, `report`ed as each ends; in the pairs' order.
fn run_cases(
    plan: &Plan,
    cases: &[(Injected, TwinConfig, TwinConfig)],
    noise: f64,
    report: &(dyn Fn(&Injected, &Trial) + Sync),
) -> Result<Vec<(Injected, Trial)>, StudyError> {
    let (runs, seed, separating) = (plan.runs, plan.seed, plan.separating);
    let jobs: Vec<(usize, u64)> = (0..cases.len())
        .flat_map(|c| (0..runs).map(move |k| (c, seed + 1000 * (c as u64 + 1) + k as u64)))
        .collect();
    let results = std::sync::Mutex::new(Vec::new());
    let next = std::sync::atomic::AtomicUsize::new(0);
    let workers = std::thread::available_parallelism()
        .map_or(1, usize::from)
        .min(4);
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(&(c, s)) = jobs.get(i) else { break };
                    let (inj, data, reference) = &cases[c];
                    let r = trial(inj, s, separating, data, reference, noise);
                    if let Ok(t) = &r {
                        report(inj, t);
                    }
                    // Pushing cannot panic, so the lock is never poisoned;
                    // were it, the results in it are still whole.
                    results
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .push((i, inj.clone(), r));
                }
            });
        }
    });
    let mut done = results
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    done.sort_by_key(|(i, _, _)| *i);
    done.into_iter()
        .map(|(_, inj, r)| r.map(|t| (inj, t)))
        .collect()
}

/// Each effect's power at each amplitude over `trials`: how often it was
/// named first, the excess it closed then, how often it was confounded.
fn power_of(
    effects: &[Effect],
    trials: &[(Injected, Trial)],
    coefficients: &BTreeMap<(String, u64), f64>,
) -> Vec<Power> {
    let mut power = Vec::new();
    for &e in effects {
        for &amp in &AMPLITUDES {
            let mine: Vec<&(Injected, Trial)> = trials
                .iter()
                .filter(|(i, _)| *i == Injected::Effect(e.name().into(), amp))
                .collect();
            let n = mine.len().max(1) as f64;
            let first: Vec<&Trial> = mine
                .iter()
                .filter(|(_, t)| t.attributed.as_deref() == Some(e.name()))
                .map(|(_, t)| t)
                .collect();
            power.push(Power {
                effect: e.name().into(),
                amplitude: amp,
                coefficient: coefficients
                    .get(&(e.name().to_owned(), amp.to_bits()))
                    .copied()
                    .unwrap_or(f64::NAN),
                runs: mine.len(),
                named_first: first.len() as f64 / n,
                excess_closed: if first.is_empty() {
                    0.0
                } else {
                    first.iter().filter_map(|t| t.excess_closed).sum::<f64>() / first.len() as f64
                },
                confounded: mine
                    .iter()
                    .filter(|(_, t)| {
                        t.confounded
                            .iter()
                            .any(|pair| pair.contains(&e.name().to_owned()))
                    })
                    .count() as f64
                    / n,
            });
        }
    }
    power
}

/// Every library effect.
pub fn all_effects() -> Vec<Effect> {
    LIBRARY.to_vec()
}

/// The page: power table, confusion matrix, rates.
pub fn render_html(s: &SelfCheck) -> String {
    let mut power = String::new();
    for p in &s.power {
        power.push_str(&format!(
            "<tr><td>{}</td><td class=num>{}</td><td class=num>{:.4e}</td><td class=num>{}</td><td class=num>{:.0} %</td><td class=num>{:.0} %</td><td class=num>{:.0} %</td></tr>\n",
            p.effect,
            p.amplitude,
            p.coefficient,
            p.runs,
            100.0 * p.named_first,
            100.0 * p.excess_closed,
            100.0 * p.confounded
        ));
    }
    let unit = match s.unit {
        Unit::Gap => "that gap (--unit gap)",
        Unit::Rms => "that RMS (--unit rms)",
    };
    let sizes: String = s
        .sizes
        .iter()
        .map(|z| {
            format!(
                "<tr><td>{}</td><td class=num>{:.4e}</td><td class=num>{:.4e}</td><td class=num>{:.2}</td></tr>\n",
                z.effect, z.rms_dph, z.gap_dph, z.gap_per_rms
            )
        })
        .collect();
    let cols: Vec<String> = {
        let mut c: Vec<String> = s
            .confusion
            .values()
            .flat_map(|m| m.keys().cloned())
            .collect();
        c.sort();
        c.dedup();
        c
    };
    let mut conf = format!(
        "<tr><th>injected \\ named first</th>{}</tr>\n",
        cols.iter()
            .map(|c| format!("<th>{c}</th>"))
            .collect::<String>()
    );
    for (row, m) in &s.confusion {
        conf.push_str(&format!(
            "<tr><td>{row}</td>{}</tr>\n",
            cols.iter()
                .map(|c| format!(
                    "<td class=num>{}</td>",
                    m.get(c).map_or(String::new(), |n| n.to_string())
                ))
                .collect::<String>()
        ));
    }
    let body = format!(
        "<h1>Diagnosis self-check</h1>\n<p>{} run(s) per case from seed {}, each case these procedures on the twin: {}. Noise unit: {:.5} deg/h (the reference's held-out gap on null runs, RMS of 60 s means).</p>\n<p>False-positive rate on null runs: <b>{:.0} %</b>. Out-of-library periodic disturbance ({} s, {}x noise): attributed in {:.0} % of runs; its period reported within 20 % in {:.0} %.</p>\n<h2>Detection power</h2>\n<table><tr><th>effect</th><th>amplitude (noise units)</th><th>coefficient</th><th>runs</th><th>named first</th><th>excess gap closed</th><th>in a confounded pair</th></tr>\n{power}</table>\n<h2>Confusion matrix</h2>\n<table>{conf}</table>\n<h2>How much of each effect these runs show</h2>\n<p>Per unit coefficient: the RMS of its contribution (60 s means) and the held-out gap it alone opens against the reference (what the reference's refitted terms reproduce does not count). Amplitudes are in units of {unit}; a small ratio means the effect hides in the reference's terms with these runs.</p>\n<table><tr><th>effect</th><th>RMS (deg/h per unit)</th><th>gap (deg/h per unit)</th><th>gap / RMS</th></tr>\n{sizes}</table>\n",
        s.runs,
        s.seed,
        crate::view::esc(&s.procedures.join(", ")),
        s.noise_dph,
        100.0 * s.false_positive_rate,
        PERIODIC_PERIOD_S,
        PERIODIC_AMPLITUDE,
        100.0 * s.periodic_attributed,
        100.0 * s.periodic_period_found,
    );
    crate::view::page("Diagnosis self-check", "", &body)
}
