//! The thermal layer's effects: what a unit's thermal physics may hold
//! beyond the twin's network form (`[thermal.effects]` in the twin), each
//! a candidate the network is refitted with, jointly, when the network
//! alone cannot follow the runs; chosen on held-out evidence as the rate
//! layer chooses its effects (the same folds, a relevance bar, a test that
//! respects autocorrelated residuals, Bonferroni over the candidates, ties
//! to the simpler one), named with their parameters and how far the gap
//! shrinks (`docs/diagnosis.md`, "The thermal layer's effects").

use super::*;

/// A thermal effect of the library.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ThermalEffect {
    /// A sensor reads its node through a first-order lag of its own.
    SensorLag,
    /// A sensor reads `(1 + e) T`: a gain error.
    SensorGain,
    /// Each block's conductance to the case changes with gravity along a
    /// body axis (convection inside the housing).
    OrientationCoupling,
    /// A path from the air straight to one block: a gradient across the
    /// unit whenever the air moves away from the case.
    AirPath,
    /// The case's conductance to the air changes with the air
    /// temperature.
    ConductanceTemperature,
}

/// Every thermal effect, in the order candidates are listed.
pub const THERMAL_LIBRARY: [ThermalEffect; 5] = [
    ThermalEffect::SensorLag,
    ThermalEffect::SensorGain,
    ThermalEffect::OrientationCoupling,
    ThermalEffect::AirPath,
    ThermalEffect::ConductanceTemperature,
];

impl ThermalEffect {
    /// The name the output uses.
    pub fn name(self) -> &'static str {
        match self {
            Self::SensorLag => "sensor_lag",
            Self::SensorGain => "sensor_gain",
            Self::OrientationCoupling => "orientation_coupling",
            Self::AirPath => "air_path_to_block",
            Self::ConductanceTemperature => "conductance_temperature",
        }
    }

    /// Whether `form` holds it.
    fn in_form(self, form: &Form) -> bool {
        match self {
            Self::SensorLag => form.lag.is_some(),
            Self::SensorGain => form.gain.is_some(),
            Self::OrientationCoupling => form.coupling.is_some(),
            Self::AirPath => form.air_path.is_some(),
            Self::ConductanceTemperature => form.conductance,
        }
    }

    /// Its discrete choices: the sensor (T1, T2, TK), the body axis (x, y,
    /// z), the block (1, 2), or none.
    fn choices(self) -> usize {
        match self {
            Self::SensorLag | Self::SensorGain | Self::OrientationCoupling => 3,
            Self::AirPath => 2,
            Self::ConductanceTemperature => 1,
        }
    }

    /// `form` with this effect on `choice`.
    fn with(self, form: Form, choice: usize) -> Form {
        let mut f = form;
        match self {
            Self::SensorLag => f.lag = Some(choice),
            Self::SensorGain => f.gain = Some(choice),
            Self::OrientationCoupling => f.coupling = Some(choice),
            Self::AirPath => f.air_path = Some(choice),
            Self::ConductanceTemperature => f.conductance = true,
        }
        f
    }

    /// The starts of its quantities (ours: lags of 20 s to 10 min, gains
    /// of a percent either way, couplings a fifth up or down on either
    /// block, air paths of 1000 s to 30,000 s, a conductance 0.3 % per
    /// degC either way).
    fn starts(self) -> Vec<Vec<(usize, f64)>> {
        let one = |i: usize, vs: &[f64]| vs.iter().map(|&v| vec![(i, v)]).collect();
        match self {
            Self::SensorLag => one(
                at::LAG_TAU,
                &[20.0f64.ln(), 60.0f64.ln(), 200.0f64.ln(), 600.0f64.ln()],
            ),
            Self::SensorGain => one(at::SENSOR_GAIN, &[-0.01, 0.0, 0.01]),
            Self::OrientationCoupling => [(0.2, 0.2), (-0.2, -0.2), (0.2, 0.0), (0.0, 0.2)]
                .iter()
                .map(|&(a, b)| vec![(at::COUPLING1, a), (at::COUPLING2, b)])
                .collect(),
            Self::AirPath => one(
                at::AIR_PATH_TAU,
                &[1000.0f64.ln(), 5000.0f64.ln(), 30_000.0f64.ln()],
            ),
            Self::ConductanceTemperature => one(at::CONDUCTANCE, &[-0.003, 0.003]),
        }
    }

    /// What `choice` acts on, as the output names it.
    fn on(self, choice: usize) -> Option<String> {
        let name = match self {
            Self::SensorLag | Self::SensorGain => SENSORS[choice.min(2)],
            Self::OrientationCoupling => ["x", "y", "z"][choice.min(2)],
            Self::AirPath => ["block1", "block2"][choice.min(1)],
            Self::ConductanceTemperature => return None,
        };
        Some(name.to_owned())
    }

    /// Its fitted parameters, by the twin's `[thermal.effects]` keys.
    fn parameters(self, q: &Shape) -> BTreeMap<String, f64> {
        let tau = |i: usize| q[i].exp().clamp(SHAPE[i].1, SHAPE[i].2);
        let pairs: Vec<(&str, f64)> = match self {
            Self::SensorLag => vec![("sensor_lag_s", tau(at::LAG_TAU))],
            Self::SensorGain => vec![("sensor_gain_error", q[at::SENSOR_GAIN])],
            Self::OrientationCoupling => vec![
                ("orientation_coupling_block1", q[at::COUPLING1]),
                ("orientation_coupling_block2", q[at::COUPLING2]),
            ],
            Self::AirPath => vec![("air_path_tau_s", tau(at::AIR_PATH_TAU))],
            Self::ConductanceTemperature => {
                vec![("case_conductance_per_c", q[at::CONDUCTANCE])]
            }
        };
        pairs.into_iter().map(|(k, v)| (k.to_owned(), v)).collect()
    }
}

/// The bars the thermal effects are chosen by; `layers.thermal.thresholds`
/// in `diagnosis.json`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ThermalThresholds {
    /// Family-wise significance level: each step tests its candidate at
    /// `alpha` / the effects it weighed (Bonferroni; the conventional
    /// 0.05, as the rate layer).
    pub alpha: f64,
    /// Smallest share of the held-out sum of squares an effect must
    /// remove (the rate layer's `min_gain`).
    pub min_gain: f64,
    /// Candidates within this share of the best improvement are tied; the
    /// one with fewer quantities is named (the rate layer's `tie`).
    pub tie: f64,
    /// Lags of the Newey-West variance of the held-out loss differential,
    /// in 60 s blocks (ours: an hour; a misfit of a network lives on its
    /// time constants, tens of minutes to hours).
    pub newey_west_lags: usize,
    /// The effects best in sample (on all the runs) that are scored held
    /// out at each step (ours: each held-out score is five fits).
    pub scored: usize,
    /// A candidate after the best in sample is scored only when its
    /// training sum of squares is within this factor of the best's (ours:
    /// an effect of one or two quantities does not lose a lead of twice
    /// the sum of squares held out; on the twelve units of
    /// docs/diagnosis.md the candidates so far behind, 11 to 25 times,
    /// scored far below the best held out too, and their folds were a
    /// fifth of the layer's time on a unit whose conductance changes).
    pub scored_within: f64,
    /// At most this many effects are named (ours).
    pub max_effects: usize,
    /// Each candidate is first fitted with its settling search cut at
    /// this many Jacobians (a fifth of the whole budget), which ranks
    /// them. Ours: on the conductance unit of docs/benchmarks.md the
    /// leading candidate's sum of squares is about 2.5 after 20
    /// Jacobians and 2.28 after its whole settle, the next one's over a
    /// thousand times more; on the twelve units of docs/diagnosis.md the
    /// same effects are named as with every candidate settled whole, and
    /// the effect step takes a quarter less time.
    pub screen_jacobians: usize,
    /// Before that, each choice is glanced at: its best start settled for
    /// this many Jacobians, with no simplex search (a fifth of a
    /// screening's evaluations).
    pub glance_jacobians: usize,
    /// Only the choices whose glanced training sum of squares is within
    /// this factor of the best glance's are screened; the others keep
    /// their glance (ours: on the twelve units of docs/diagnosis.md the
    /// candidates that went on to contend were at most 3.2 times behind
    /// the best glance; at three Jacobians one was 15 times behind, at
    /// five none. A unit whose effect dominates, a conductance that
    /// changes with temperature, leaves one or two choices in sight; one
    /// whose effects are close, nearly all twelve).
    pub glance_within: f64,
    /// The candidates whose screened training sum of squares is within
    /// this factor of the best's settle on to the whole budget before
    /// they are ranked (ours: twice [`Self::scored_within`], room for a
    /// candidate's whole settle to gain more on the leader than the
    /// leader's own).
    pub contends_within: f64,
}

/// The thresholds every thermal selection is made with.
pub const THERMAL_THRESHOLDS: ThermalThresholds = ThermalThresholds {
    alpha: 0.05,
    min_gain: 0.25,
    tie: 0.03,
    newey_west_lags: 60,
    scored: 2,
    scored_within: 2.0,
    max_effects: 2,
    screen_jacobians: 20,
    glance_jacobians: 5,
    glance_within: 10.0,
    contends_within: 4.0,
};

/// An effect the thermal layer names (`layers.thermal.effects`).
#[derive(Debug, Clone, Serialize)]
pub struct FoundEffect {
    /// The library's name.
    pub name: String,
    /// What it acts on: the sensor (`t1_c`, `t2_c`, `tcase_c`), the body
    /// axis (`x`, `y`, `z`) or the block (`block1`, `block2`); none for
    /// the case's conductance.
    pub on: Option<String>,
    /// Its fitted quantities by the twin's `[thermal.effects]` keys (s,
    /// 1, 1/degC).
    pub parameters: BTreeMap<String, f64>,
    /// The network's held-out gap before and after it is added, degC.
    pub held_out_gap_before_c: f64,
    pub held_out_gap_after_c: f64,
    /// 1 - after / before.
    pub shrink: f64,
    /// Share of the held-out sum of squares it removes.
    pub improvement: f64,
    /// One-sided p-value of the held-out improvement (Diebold-Mariano,
    /// Newey-West variance).
    pub p_value: f64,
}

/// A candidate at the first step, against the network alone
/// (`layers.thermal.candidates`).
#[derive(Debug, Clone, Serialize)]
pub struct CandidateScore {
    /// The library's name.
    pub name: String,
    /// Its best choice in sample (as [`FoundEffect::on`]).
    pub on: Option<String>,
    /// Share of the sum of squares it removes fitted on all the runs.
    pub in_sample_improvement: f64,
    /// How far that fit went: `glance`, `screen` or `whole`
    /// ([`ThermalThresholds::glance_jacobians`],
    /// [`ThermalThresholds::screen_jacobians`], the whole budget).
    pub in_sample_fit: Fit,
    /// Its held-out gap, degC, when it was among the scored.
    pub held_out_gap_c: Option<f64>,
    /// Share of the held-out sum of squares it removes.
    pub improvement: Option<f64>,
    /// As [`FoundEffect::p_value`].
    pub p_value: Option<f64>,
}

/// How far a candidate's fit on all the runs went before it was ranked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Fit {
    /// Its best start settled for a few Jacobians: it was not in sight.
    Glance,
    /// Searched from its starts, its settling cut short: it was in sight
    /// but did not contend.
    Screen,
    /// Settled to the whole budget: a contender.
    Whole,
}

/// The selection's outcome: the network it ends with, the effects named,
/// the first step's candidates, and the gap the layer matches within.
pub(super) struct Selected {
    pub(super) net: NetworkHeldOut,
    pub(super) effects: Vec<FoundEffect>,
    pub(super) candidates: Vec<CandidateScore>,
}

/// The held-out gap (RMS over the sensors), degC.
pub(super) fn gap_of(net: &NetworkHeldOut) -> f64 {
    quadratic_mean(&net.held.per_sensor_c)
}

/// The gap a layer matches within: 0.05 degC or twice the sensors' noise
/// floor, whichever is more.
pub fn match_limit_c(floor_c: f64) -> f64 {
    FORM_MISFIT_C.max(2.0 * floor_c)
}

/// Effects added to `base` (the network in its form) while it misses
/// [`match_limit_c`]: at each step every effect not yet in the form is
/// fitted with the network on all the runs (each choice, from the
/// network's optimum and the effect's starts), the
/// [`ThermalThresholds::scored`] best in sample are scored held out (each
/// fold's fit started from the candidate's), and the best held-out one is
/// named when it removes [`ThermalThresholds::min_gain`] of the held-out
/// sum of squares and passes the test at `alpha` / the effects weighed.
pub(super) fn select(
    runs: &[RunData],
    data: &[Vec<Block>],
    base: NetworkHeldOut,
    floor_c: f64,
) -> Selected {
    let th = THERMAL_THRESHOLDS;
    let limit = match_limit_c(floor_c);
    let mut current = base;
    let mut effects = Vec::new();
    let mut candidates = Vec::new();
    // A NaN gap (no held-out block) is beyond any limit.
    let beyond = |g: f64| g.is_nan() || g > limit;
    while effects.len() < th.max_effects && beyond(gap_of(&current)) {
        let remaining: Vec<ThermalEffect> = THERMAL_LIBRARY
            .into_iter()
            .filter(|e| !e.in_form(&current.form))
            .collect();
        if remaining.is_empty() {
            break;
        }
        let step = weigh(runs, data, &current, &remaining);
        if effects.is_empty() {
            candidates = step.iter().map(|c| c.score.clone()).collect();
        }
        let level = th.alpha / remaining.len() as f64;
        let Some(best) = named(step, level) else {
            break;
        };
        let before = gap_of(&current);
        let after = gap_of(&best.net);
        effects.push(FoundEffect {
            name: best.effect.name().to_owned(),
            on: best.score.on.clone(),
            parameters: best.effect.parameters(&best.net.all),
            held_out_gap_before_c: before,
            held_out_gap_after_c: after,
            shrink: 1.0 - after / before,
            improvement: best.score.improvement.unwrap_or(0.0),
            p_value: best.score.p_value.unwrap_or(1.0),
        });
        current = best.net;
    }
    Selected {
        net: current,
        effects,
        candidates,
    }
}

/// A candidate weighed at one step.
struct Weighed {
    effect: ThermalEffect,
    score: CandidateScore,
    /// Its network and form on all the runs, and its training sum of
    /// squares.
    all: (Shape, Form, f64),
    /// Scored held out: the network with its folds.
    held: Option<NetworkHeldOut>,
}

/// The candidate named: its effect, score and network.
struct Named {
    effect: ThermalEffect,
    score: CandidateScore,
    net: NetworkHeldOut,
}

/// Every effect in `remaining` fitted with `current` on all the runs (its
/// best choice kept), the best in sample scored held out against
/// `current`. Each choice is glanced at
/// ([`ThermalThresholds::glance_jacobians`]), those within
/// [`ThermalThresholds::glance_within`] of the best glance are screened
/// ([`ThermalThresholds::screen_jacobians`]) and those within
/// [`ThermalThresholds::contends_within`] of the best screened settle
/// on, so the ranking and the named effect's parameters come from whole
/// fits and the others' `in_sample_improvement` from their screening or
/// their glance.
fn weigh(
    runs: &[RunData],
    data: &[Vec<Block>],
    current: &NetworkHeldOut,
    remaining: &[ThermalEffect],
) -> Vec<Weighed> {
    let th = THERMAL_THRESHOLDS;
    let base_sse = training_cost(data, &current.all, current.form);
    let jobs: Vec<(ThermalEffect, usize)> = remaining
        .iter()
        .flat_map(|&e| (0..e.choices()).map(move |c| (e, c)))
        .collect();
    let fits = fit_choices(data, current, &jobs);
    let mut weighed: Vec<Weighed> = remaining
        .iter()
        .map(|&e| {
            let best = jobs
                .iter()
                .zip(&fits)
                .filter(|((je, _), _)| *je == e)
                .min_by(|a, b| a.1.0.2.total_cmp(&b.1.0.2));
            let (choice, all, fit) = best.map_or(
                (0, (current.all, current.form, f64::MAX), Fit::Glance),
                |b| (b.0.1, b.1.0, b.1.1),
            );
            Weighed {
                effect: e,
                score: CandidateScore {
                    name: e.name().to_owned(),
                    on: e.on(choice),
                    in_sample_improvement: 1.0 - all.2 / base_sse,
                    in_sample_fit: fit,
                    held_out_gap_c: None,
                    improvement: None,
                    p_value: None,
                },
                all,
                held: None,
            }
        })
        .collect();
    weighed.sort_by(|a, b| a.all.2.total_cmp(&b.all.2));
    let best_sse = weighed.first().map_or(f64::MAX, |w| w.all.2);
    let close = |w: &&mut Weighed| w.all.2 <= th.scored_within * best_sse;
    for w in weighed.iter_mut().take(th.scored).filter(close) {
        // (Settling the candidate again here, 150 more iterations from
        // its weighing fit, changed no outcome on the twelve units of
        // docs/diagnosis.md and took a fifth of the layer's time.)
        let (q, form, _) = w.all;
        let folds = on_two_threads(&(0..FOLDS).collect::<Vec<_>>(), |&k| {
            warm_shape(data, Some(k), form, &q)
        });
        let shapes: Vec<Shape> = std::iter::once(q).chain(folds).collect();
        let net = network_held_out(runs, data, &shapes, form, q);
        let (improvement, p) = held_out_test(data, current, &net);
        w.score.held_out_gap_c = Some(gap_of(&net));
        w.score.improvement = Some(improvement);
        w.score.p_value = Some(p);
        w.held = Some(net);
    }
    weighed
}

/// A choice's fit on all the runs: its network and form, its training
/// sum of squares, and how far its search went.
type ChoiceFit = ((Shape, Form, f64), Fit);

/// Each (effect, choice) of `jobs` fitted with `current` on all the runs,
/// from the network's optimum and the effect's starts: glanced at, the
/// choices in sight screened, the contenders settled whole
/// ([`weigh`]).
fn fit_choices(
    data: &[Vec<Block>],
    current: &NetworkHeldOut,
    jobs: &[(ThermalEffect, usize)],
) -> Vec<ChoiceFit> {
    let th = THERMAL_THRESHOLDS;
    let starts_of = |e: ThermalEffect| -> Vec<Shape> {
        e.starts()
            .iter()
            .map(|s| {
                let mut q = current.all;
                for &(i, v) in s {
                    q[i] = v;
                }
                q
            })
            .collect()
    };
    // A glance at every choice: its best start settled a few Jacobians.
    let glanced = on_two_threads(jobs, |&(e, c)| {
        let form = e.with(current.form, c);
        let q = screen_shape(data, None, form, &starts_of(e), 0, th.glance_jacobians);
        (q, form, training_cost(data, &q, form))
    });
    let sight = glanced.iter().map(|f| f.2).fold(f64::MAX, f64::min);
    let mut fits: Vec<ChoiceFit> = glanced.into_iter().map(|f| (f, Fit::Glance)).collect();
    let in_sight: Vec<usize> = (0..jobs.len())
        .filter(|&i| fits[i].0.2 <= th.glance_within * sight)
        .collect();
    // Those in sight screened from their starts.
    let screened = on_two_threads(&in_sight, |&i| {
        let (e, c) = jobs[i];
        let form = e.with(current.form, c);
        let q = screen_shape(
            data,
            None,
            form,
            &starts_of(e),
            WARM_ITERS,
            th.screen_jacobians,
        );
        (q, form, training_cost(data, &q, form))
    });
    for (&i, f) in in_sight.iter().zip(screened) {
        fits[i] = (f, Fit::Screen);
    }
    // The contenders' settling searches carried on to the whole budget.
    let lead = in_sight
        .iter()
        .map(|&i| fits[i].0.2)
        .fold(f64::MAX, f64::min);
    let contenders: Vec<usize> = in_sight
        .iter()
        .copied()
        .filter(|&i| fits[i].0.2 <= th.contends_within * lead)
        .collect();
    let settled = on_two_threads(&contenders, |&i| {
        let (q, form, _) = fits[i].0;
        let rest = SETTLE_ITERS.saturating_sub(th.screen_jacobians);
        let q = settle_shape(data, None, form, &q, rest);
        (q, form, training_cost(data, &q, form))
    });
    for (&i, f) in contenders.iter().zip(settled) {
        fits[i] = (f, Fit::Whole);
    }
    fits
}

/// The training sum of squares of the network `q` in `form` on all the
/// runs.
fn training_cost(data: &[Vec<Block>], q: &Shape, form: Form) -> f64 {
    let cost = Cost {
        runs: data,
        held_out: None,
        form,
    };
    cost.cost(&cost.searched(q)).unwrap_or(f64::MAX)
}

/// The scored candidate to name, if any: the best held out (among those
/// tied with it, the one with the fewest searched quantities), when it
/// removes `min_gain` and passes `level`. A lesser candidate that passes
/// is not named in its place: where the best cannot be told from the
/// noise, a weaker one that can is most often taking up part of the best
/// one's misfit (a unit with an orientation coupling had an air path named
/// before its coupling when the next best was allowed in).
fn named(step: Vec<Weighed>, level: f64) -> Option<Named> {
    let th = THERMAL_THRESHOLDS;
    let scored: Vec<Weighed> = step.into_iter().filter(|w| w.held.is_some()).collect();
    let top = scored
        .iter()
        .filter_map(|w| w.score.improvement)
        .fold(f64::NEG_INFINITY, f64::max);
    let size = |w: &Weighed| w.all.1.searched().len();
    let chosen = scored
        .into_iter()
        .filter(|w| {
            w.score
                .improvement
                .is_some_and(|g| g >= top - th.tie * top.abs())
        })
        .min_by(|a, b| {
            size(a).cmp(&size(b)).then(
                b.score
                    .improvement
                    .unwrap_or(0.0)
                    .total_cmp(&a.score.improvement.unwrap_or(0.0)),
            )
        })?;
    let passes = chosen.score.p_value.is_some_and(|p| p < level)
        && chosen.score.improvement.is_some_and(|g| g >= th.min_gain);
    passes.then_some(())?;
    Some(Named {
        effect: chosen.effect,
        score: chosen.score,
        net: chosen.held?,
    })
}

/// How much of `before`'s held-out sum of squares `after` removes, and the
/// one-sided p-value of that improvement: the Diebold-Mariano test of the
/// held-out loss differential (each scored block's squared residuals
/// summed over the sensors, `before` minus `after`), its variance by
/// Newey-West over [`ThermalThresholds::newey_west_lags`] blocks within
/// each run.
fn held_out_test(
    data: &[Vec<Block>],
    before: &NetworkHeldOut,
    after: &NetworkHeldOut,
) -> (f64, f64) {
    let sq = |v: &[f64; 3]| v.iter().map(|x| x * x).sum::<f64>();
    let mut runs_d: Vec<Vec<f64>> = Vec::new();
    let (mut sse_before, mut sse_after) = (0.0, 0.0);
    for (r, run) in data.iter().enumerate() {
        let mut d = Vec::new();
        for (i, b) in run.iter().enumerate() {
            if b.fold >= FOLDS {
                continue;
            }
            let (x, y) = (
                sq(&before.fold_res[b.fold][r][i]),
                sq(&after.fold_res[b.fold][r][i]),
            );
            sse_before += x;
            sse_after += y;
            d.push(x - y);
        }
        runs_d.push(d);
    }
    let improvement = if sse_before > 0.0 {
        1.0 - sse_after / sse_before
    } else {
        0.0
    };
    (
        improvement,
        diebold_mariano(&runs_d, THERMAL_THRESHOLDS.newey_west_lags),
    )
}

/// One-sided p-value that the mean of the differentials `d` (one series
/// per run) is above zero, by their Newey-West (Bartlett) long-run
/// variance over `lags`, autocovariances taken within each run.
fn diebold_mariano(d: &[Vec<f64>], lags: usize) -> f64 {
    let n: usize = d.iter().map(Vec::len).sum();
    if n < 2 {
        return 1.0;
    }
    let mean = d.iter().flatten().sum::<f64>() / n as f64;
    let autocov = |l: usize| {
        d.iter()
            .map(|s| {
                s.iter()
                    .zip(s.iter().skip(l))
                    .map(|(a, b)| (a - mean) * (b - mean))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / n as f64
    };
    let lags = lags.min(n - 1);
    let var = autocov(0)
        + 2.0
            * (1..=lags)
                .map(|l| (1.0 - l as f64 / (lags + 1) as f64) * autocov(l))
                .sum::<f64>();
    if var.is_nan() || var <= 0.0 {
        return if mean > 0.0 { 0.0 } else { 1.0 };
    }
    let z = mean / (var / n as f64).sqrt();
    use statrs::distribution::{ContinuousCDF, Normal};
    Normal::standard().sf(z)
}
