//! Held-out fitting of the rate layer: a model is a set of library effects
//! (each with its nonlinear parameter) plus one offset per run, fitted by
//! least squares and scored by blocked cross-validation, one fold per
//! block of a record of at most [`FOLD_MAX_S`] (contiguous, never random
//! samples). Scores are
//! the residual's 60 s means, so white noise does not drown the slow
//! effects and neighbouring samples do not count as independent.
//!
//! Each fold's sums (Gram matrix, right-hand side, block means) are made
//! once, so leaving a fold out costs one small solve.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use gyrobench_model::procedure::StepKeyBuf;
use nalgebra::{DMatrix, DVector};

use super::data::RunData;
use super::library::{Effect, Param, Term, Units};

/// Averaging time of the scores, s (samples are 1 Hz).
pub const AVERAGING_S: usize = 60;

/// Longest fold, s (ours): records are cut into blocks of at most 15 min,
/// so that leaving one out still leaves its neighbours in the same regime
/// (a warm-up or a cold soak held out whole would have to be extrapolated).
pub const FOLD_MAX_S: usize = 900;

/// Longest fold in the warm-up (the first [`WARMUP_S`] after power-on), s
/// (ours): the warm-up transient lives almost only there, and a 15 min
/// block held out whole leaves its exponential to be extrapolated from
/// its tail; measured on the self-check, 15 min warm-up folds made a
/// missing hysteresis look like a worse fit.
pub const WARMUP_FOLD_MAX_S: usize = 300;

/// Time since power-on the warm-up folds cover, s.
pub const WARMUP_S: f64 = 1800.0;

/// One fold: a record of one run.
#[derive(Debug, Clone)]
pub struct Fold {
    /// Run index.
    pub run: usize,
    /// Record label.
    pub record: String,
    /// Step key.
    pub step: StepKeyBuf,
    /// Rows `start..end` of the stacked design.
    pub start: usize,
    /// End row (exclusive).
    pub end: usize,
}

/// The stacked data of all runs.
#[derive(Debug)]
pub struct Data<'a> {
    /// The runs.
    pub runs: &'a [RunData],
    /// Earth-removed bias, deg/h, all runs stacked (another signal only
    /// through [`Data::with_data`]: sums of it are kept).
    y: Vec<f64>,
    /// Run of each row.
    pub run_of: Vec<usize>,
    /// Unit of each run (a lot's runs of several units stacked,
    /// [`Data::with_units`]; else every run unit 0): a term acts in the
    /// runs of its [`Units`].
    pub unit_of_run: Vec<usize>,
    /// The folds, in row order.
    pub folds: Vec<Fold>,
    /// Rows of records taken while the table turned (rate runs), by the
    /// index of their run in [`Data::turning_runs`]: each such run gets a
    /// scale factor of its own, a nuisance as its offset is.
    pub turning_of: Vec<Option<usize>>,
    /// Runs with records taken while turning, in run order.
    pub turning_runs: Vec<usize>,
    /// Kinematic reference of each row, deg/h.
    pub reference: Vec<f64>,
    /// Stacked columns built so far, by effect and parameter (bits).
    cache: ColumnCache,
    /// Sums of the columns every model has (run offsets, scale factors).
    fixed: FixedSums,
    /// Each effect column's sums against those and the data, and the
    /// cross products of effect columns, as they are asked for.
    stats: Mutex<ColumnStats>,
}

/// Stacked columns by effect, parameter and units.
type ColumnCache = Mutex<HashMap<(Effect, ParamKey, Units), Vec<Arc<Vec<f64>>>>>;

/// A parameter told apart bit for bit ([`Param::key`]).
type ParamKey = (u8, u64, u64);

/// One stacked effect column: effect, parameter, units, term.
type ColumnKey = (Effect, ParamKey, Units, usize);

/// What the Gram matrix needs of the columns every model has: per run its
/// rows and the sum of its data; per rate run (as [`Data::turning_runs`])
/// the sums of its scale-factor column, of its square and of its product
/// with the data.
#[derive(Debug, Default)]
struct FixedSums {
    rows: Vec<f64>,
    y: Vec<f64>,
    turn: Vec<f64>,
    turn_sq: Vec<f64>,
    turn_y: Vec<f64>,
}

/// One effect column's spread (its scale in the design) and sums: per run,
/// against each rate run's scale-factor column, against the data, and of
/// its square.
#[derive(Debug)]
struct ColumnSums {
    scale: f64,
    run: Vec<f64>,
    turn: Vec<f64>,
    y: f64,
    sq: f64,
}

#[derive(Debug, Default)]
struct ColumnStats {
    single: HashMap<ColumnKey, Arc<ColumnSums>>,
    pair: HashMap<(ColumnKey, ColumnKey), f64>,
}

/// The scale-factor column's value at a rate record's row: the kinematic
/// reference, scaled to sit near the others.
fn turn_value(reference_dph: f64) -> f64 {
    reference_dph * 1e-5
}

impl<'a> Data<'a> {
    /// Stack the recorded samples of `runs`.
    pub fn new(runs: &'a [RunData]) -> Self {
        let mut y = Vec::new();
        let mut run_of = Vec::new();
        let mut folds: Vec<Fold> = Vec::new();
        let mut turning_of = Vec::new();
        let mut turning_runs: Vec<usize> = Vec::new();
        let mut reference = Vec::new();
        for (r, run) in runs.iter().enumerate() {
            for s in &run.samples {
                let row = y.len();
                y.push(s.iv.bias_dph());
                run_of.push(r);
                reference.push(s.iv.reference_dph);
                turning_of.push(if s.step.as_key().is_rate_record() {
                    if turning_runs.last() != Some(&r) {
                        turning_runs.push(r);
                    }
                    Some(turning_runs.len() - 1)
                } else {
                    None
                });
                match folds.last_mut() {
                    Some(f)
                        if f.run == r
                            && f.record == s.record
                            && f.end - f.start
                                < if s.iv.time_s < WARMUP_S {
                                    WARMUP_FOLD_MAX_S
                                } else {
                                    FOLD_MAX_S
                                } =>
                    {
                        f.end = row + 1;
                    }
                    _ => folds.push(Fold {
                        run: r,
                        record: s.record.clone(),
                        step: s.step.clone(),
                        start: row,
                        end: row + 1,
                    }),
                }
            }
        }
        Self {
            runs,
            y,
            run_of,
            unit_of_run: vec![0; runs.len()],
            folds,
            turning_of,
            turning_runs,
            reference,
            cache: Mutex::default(),
            fixed: FixedSums::default(),
            stats: Mutex::default(),
        }
        .with_fixed_sums()
    }

    /// The same runs with `y` as the data (one value per row): a signal
    /// fitted as if it were the data. `None` when its length is not the
    /// rows'.
    pub fn with_data(self, y: Vec<f64>) -> Option<Self> {
        (y.len() == self.y.len()).then(|| {
            Self {
                y,
                stats: Mutex::default(),
                ..self
            }
            .with_fixed_sums()
        })
    }

    /// The same runs as a lot's: `unit_of_run[r]` the unit (below
    /// [`Units::MAX`]) of run `r`, so a term in some [`Units`] acts in
    /// their runs alone. `None` when there is not one unit per run.
    pub fn with_units(self, unit_of_run: Vec<usize>) -> Option<Self> {
        (unit_of_run.len() == self.runs.len() && unit_of_run.iter().all(|&u| u < Units::MAX)).then(
            || Self {
                unit_of_run,
                cache: Mutex::default(),
                stats: Mutex::default(),
                ..self
            },
        )
    }

    /// Whether a term in `units` acts in the rows of run `run`.
    fn acts_in(&self, units: Units, run: usize) -> bool {
        units.holds(self.unit_of_run.get(run).copied().unwrap_or(0))
    }

    fn with_fixed_sums(mut self) -> Self {
        let (nruns, nturn) = (self.runs.len(), self.turning_runs.len());
        let mut fixed = FixedSums {
            rows: vec![0.0; nruns],
            y: vec![0.0; nruns],
            turn: vec![0.0; nturn],
            turn_sq: vec![0.0; nturn],
            turn_y: vec![0.0; nturn],
        };
        for (i, &v) in self.y.iter().enumerate() {
            let r = self.run_of[i];
            fixed.rows[r] += 1.0;
            fixed.y[r] += v;
            if let Some(t) = self.turning_of[i] {
                let x = turn_value(self.reference[i]);
                fixed.turn[t] += x;
                fixed.turn_sq[t] += x * x;
                fixed.turn_y[t] += x * v;
            }
        }
        self.fixed = fixed;
        self
    }

    /// The data, one value per row (runs stacked).
    pub fn y(&self) -> &[f64] {
        &self.y
    }

    /// Stacked regressor columns of a model, each with its key. Each
    /// effect's columns at a parameter are built once per [`Data`] and
    /// shared (the selection fits the same effects at the same parameters
    /// many times over).
    fn columns(&self, model: &[Term]) -> Vec<(ColumnKey, Arc<Vec<f64>>)> {
        let mut cols = Vec::new();
        for &Term {
            effect: e,
            param: p,
            units,
        } in model
        {
            let key = (e, p.key(), units);
            let cached = self
                .cache
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .get(&key)
                .cloned();
            let built = cached.unwrap_or_else(|| {
                let built: Vec<Arc<Vec<f64>>> = if e.is_outside() {
                    self.outside_columns(e, p)
                        .into_iter()
                        .map(Arc::new)
                        .collect()
                } else {
                    // A unit's own term is zero in the other units' runs.
                    let per_run: Vec<Vec<Vec<f64>>> = self
                        .runs
                        .iter()
                        .enumerate()
                        .map(|(k, r)| {
                            if self.acts_in(units, k) {
                                e.columns(r, p)
                            } else {
                                vec![vec![0.0; r.samples.len()]; e.terms().len()]
                            }
                        })
                        .collect();
                    (0..e.terms().len())
                        .map(|c| {
                            Arc::new(
                                per_run
                                    .iter()
                                    .flat_map(|cs| cs[c].iter().copied())
                                    .collect(),
                            )
                        })
                        .collect()
                };
                self.cache
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .insert(key, built.clone());
                built
            });
            cols.extend(
                built
                    .into_iter()
                    .enumerate()
                    .map(|(t, c)| ((e, p.key(), units, t), c)),
            );
        }
        cols
    }

    fn lock_stats(&self) -> std::sync::MutexGuard<'_, ColumnStats> {
        self.stats
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// A column's spread and sums, made once per [`Data`].
    fn column_sums(&self, key: ColumnKey, c: &[f64]) -> Arc<ColumnSums> {
        if let Some(s) = self.lock_stats().single.get(&key) {
            return Arc::clone(s);
        }
        let n = self.y.len().max(1) as f64;
        let mean = c.iter().sum::<f64>() / n;
        let spread = (c.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n).sqrt();
        let mut sums = ColumnSums {
            scale: if spread > 1e-300 && spread.is_finite() {
                spread
            } else {
                1.0
            },
            run: vec![0.0; self.runs.len()],
            turn: vec![0.0; self.turning_runs.len()],
            y: 0.0,
            sq: 0.0,
        };
        for (i, &v) in c.iter().enumerate() {
            sums.run[self.run_of[i]] += v;
            sums.y += v * self.y[i];
            sums.sq += v * v;
            if let Some(t) = self.turning_of[i] {
                sums.turn[t] += v * turn_value(self.reference[i]);
            }
        }
        let sums = Arc::new(sums);
        self.lock_stats().single.insert(key, Arc::clone(&sums));
        sums
    }

    /// The cross product of two effect columns, made once per [`Data`].
    fn cross(&self, a: (ColumnKey, &[f64]), b: (ColumnKey, &[f64])) -> f64 {
        // Two units' own columns never meet in a row.
        if a.0.2.apart(b.0.2) {
            return 0.0;
        }
        let key = if a.0 <= b.0 { (a.0, b.0) } else { (b.0, a.0) };
        if let Some(&v) = self.lock_stats().pair.get(&key) {
            return v;
        }
        let v = if a.0.0.is_outside() || b.0.0.is_outside() {
            a.1.iter().zip(b.1).map(|(x, y)| x * y).sum()
        } else {
            // A unit's own column is zero in the other units' runs: only
            // the runs where both act are summed, in row order (the same
            // sum, without a lot's other units' rows).
            let both = |k: usize| self.acts_in(a.0.2, k) && self.acts_in(b.0.2, k);
            self.run_rows()
                .filter(|(k, _)| both(*k))
                .flat_map(|(_, rows)| a.1[rows.clone()].iter().zip(&b.1[rows]))
                .map(|(x, y)| x * y)
                .sum()
        };
        self.lock_stats().pair.insert(key, v);
        v
    }

    /// Each run with its rows (a run's samples are stacked together).
    fn run_rows(&self) -> impl Iterator<Item = (usize, std::ops::Range<usize>)> + '_ {
        let mut start = 0;
        self.runs.iter().enumerate().map(move |(k, r)| {
            let rows = start..start + r.samples.len();
            start = rows.end;
            (k, rows)
        })
    }
}

impl Data<'_> {
    /// The columns of a disturbance outside the library: a step from its
    /// row to the end of its run ([`Effect::BiasStep`]), the time from the
    /// middle of its run, in hours ([`Effect::BiasDrift`]), or the sine and
    /// cosine of the time through one run at a period
    /// ([`Effect::Periodic`]). One zero column per term when the parameter
    /// is not the effect's kind.
    fn outside_columns(&self, e: Effect, p: Param) -> Vec<Vec<f64>> {
        let n = self.y.len();
        let in_run = |run: usize, f: &dyn Fn(f64) -> f64| -> Vec<f64> {
            let mut t = self
                .runs
                .get(run)
                .into_iter()
                .flat_map(|r| r.samples.iter().map(|s| s.iv.time_s));
            (0..n)
                .map(|i| {
                    if self.run_of[i] == run {
                        t.next().map_or(0.0, f)
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        match (e, p) {
            (Effect::BiasStep, Param::Row(at)) => {
                let at = at.min(n.saturating_sub(1));
                vec![
                    (0..n)
                        .map(|i| f64::from(u8::from(i >= at && self.run_of[i] == self.run_of[at])))
                        .collect(),
                ]
            }
            (Effect::Periodic, Param::Periodic { run, period_s }) => {
                let w = std::f64::consts::TAU / period_s;
                vec![
                    in_run(run, &|t| (w * t).sin()),
                    in_run(run, &|t| (w * t).cos()),
                ]
            }
            (Effect::BiasDrift, Param::Run(run)) => {
                let (lo, hi) = self
                    .runs
                    .get(run)
                    .into_iter()
                    .flat_map(|r| r.samples.iter().map(|s| s.iv.time_s))
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| {
                        (a.min(t), b.max(t))
                    });
                let mid = 0.5 * (lo + hi);
                vec![in_run(run, &|t| (t - mid) / 3600.0)]
            }
            _ => vec![vec![0.0; n]; e.terms().len()],
        }
    }
}

/// A model scored and fitted.
#[derive(Debug, Clone)]
pub struct Scored {
    /// The effects and their parameters.
    pub model: Vec<Term>,
    /// Held-out sum of squares of the 60 s means, per fold.
    pub fold_sse: Vec<f64>,
    /// 60 s means per fold.
    pub fold_blocks: Vec<usize>,
    /// Coefficients on all data: effect terms in order, then run offsets.
    pub coeffs: Vec<f64>,
    /// Their standard errors (autocorrelation-inflated).
    pub stderr: Vec<f64>,
    /// In-sample residual, per row.
    pub residual: Vec<f64>,
    /// Held-out residual, per row (each fold predicted without itself).
    pub held_out: Vec<f64>,
    /// In-sample residual's 60 s means, fold by fold, with the run of each.
    pub block_residual: Vec<(usize, f64)>,
    /// Parameters fitted (terms and run offsets).
    pub parameters: usize,
    /// Degrees of freedom the fit spends on the record means (see
    /// [`between_spent`]).
    pub between_spent: f64,
    /// Record of each fold (folds cut from one record share it).
    pub fold_record: Vec<usize>,
}

impl Scored {
    /// Held-out gap: RMS of the held-out residual's 60 s means, deg/h.
    pub fn gap(&self) -> f64 {
        let n: usize = self.fold_blocks.iter().sum();
        (self.fold_sse.iter().sum::<f64>() / n.max(1) as f64).sqrt()
    }

    /// Total held-out sum of squares.
    pub fn sse(&self) -> f64 {
        self.fold_sse.iter().sum()
    }
}

fn solve(g: &DMatrix<f64>, h: &DVector<f64>) -> DVector<f64> {
    let p = g.nrows();
    let ridge = 1e-10 * (0..p).map(|i| g[(i, i)]).sum::<f64>() / p.max(1) as f64;
    let gr = g + DMatrix::identity(p, p) * ridge;
    match gr.clone().cholesky() {
        Some(c) => c.solve(h),
        None => gr
            .svd(true, true)
            .solve(h, 1e-12)
            .unwrap_or_else(|_| DVector::zeros(p)),
    }
}

/// A model's design matrix, row by row: the effects' columns (scaled to
/// unit spread), one offset per run, one scale factor per rate run.
struct Design<'d> {
    data: &'d Data<'d>,
    /// Each effect column's key (for its kept sums).
    keys: Vec<ColumnKey>,
    cols: Vec<Arc<Vec<f64>>>,
    scales: Vec<f64>,
    /// Effect columns.
    q: usize,
    /// All columns.
    p: usize,
    /// Per run: its effect columns that can be non-zero (a lot's unit's:
    /// its own and the shared ones; a single unit's: all).
    effect_cols_of_run: Vec<Vec<usize>>,
}

impl<'d> Design<'d> {
    fn new(data: &'d Data<'d>, model: &[Term]) -> Self {
        let keyed = data.columns(model);
        let scales = keyed
            .iter()
            .map(|(k, c)| data.column_sums(*k, c).scale)
            .collect();
        let (keys, cols): (Vec<ColumnKey>, Vec<Arc<Vec<f64>>>) = keyed.into_iter().unzip();
        let q = cols.len();
        // A rate run's scale factor is the unit's, known from its
        // calibration, not an effect: one per run with turning records, a
        // nuisance (a misaligned axis, for one, reads every turn short by
        // its cosine).
        let p = q + data.runs.len() + data.turning_runs.len();
        let effect_cols_of_run = (0..data.runs.len())
            .map(|run| {
                (0..q)
                    .filter(|&j| {
                        let (e, _, units, _) = keys[j];
                        e.is_outside() || data.acts_in(units, run)
                    })
                    .collect()
            })
            .collect();
        Self {
            data,
            keys,
            cols,
            scales,
            q,
            p,
            effect_cols_of_run,
        }
    }

    /// The columns that can be non-zero in the rows of run `run`, in
    /// order: the effect columns of the terms acting in its unit (a
    /// disturbance outside the library, built per run, always), its
    /// offset, its scale factor when it turns. A lot's unit's rows meet
    /// only its own and the shared columns: its Gram sums need no more.
    fn active_in(&self, run: usize) -> Vec<usize> {
        let data = self.data;
        let nruns = data.runs.len();
        let turn = data.turning_runs.iter().position(|&r| r == run);
        self.effect_cols_of_run[run]
            .iter()
            .copied()
            .chain([self.q + run])
            .chain(turn.map(|t| self.q + nruns + t))
            .collect()
    }

    /// The fitted value of row `i` for coefficients `beta` (the tests'
    /// reference for [`Design::fitted`]).
    #[cfg(test)]
    fn predict(&self, i: usize, beta: &DVector<f64>) -> f64 {
        let (data, q, nruns) = (self.data, self.q, self.data.runs.len());
        let mut v = beta[q + data.run_of[i]];
        // The columns zero in this row's unit add nothing.
        for &j in &self.effect_cols_of_run[data.run_of[i]] {
            v += self.cols[j][i] / self.scales[j] * beta[j];
        }
        if let Some(t) = data.turning_of[i] {
            v += turn_value(data.reference[i]) * beta[q + nruns + t];
        }
        v
    }

    /// The fitted values of rows `rows` for coefficients `beta`, column
    /// by column over each run's stretch of rows (each row's sum taken in
    /// the same order as row by row: its run's offset, the effect columns
    /// acting in its unit, its turn; the same values to the bit, in a
    /// loop the compiler vectorises).
    fn fitted(&self, rows: std::ops::Range<usize>, beta: &DVector<f64>) -> Vec<f64> {
        let (data, q, nruns) = (self.data, self.q, self.data.runs.len());
        let mut out = Vec::with_capacity(rows.len());
        let mut start = rows.start;
        while start < rows.end {
            let run = data.run_of[start];
            let end = (start..rows.end)
                .find(|&i| data.run_of[i] != run)
                .unwrap_or(rows.end);
            let base = out.len();
            out.resize(base + (end - start), beta[q + run]);
            let v = &mut out[base..];
            for &j in &self.effect_cols_of_run[run] {
                let (col, scale, b) = (&self.cols[j][start..end], self.scales[j], beta[j]);
                for (vi, ci) in v.iter_mut().zip(col) {
                    *vi += ci / scale * b;
                }
            }
            for (vi, i) in v.iter_mut().zip(start..end) {
                if let Some(t) = data.turning_of[i] {
                    *vi += turn_value(data.reference[i]) * beta[q + nruns + t];
                }
            }
            start = end;
        }
        out
    }

    /// Row `i` whole, every column (the tests' reference for the sums
    /// over the active columns alone).
    #[cfg(test)]
    fn row_into(&self, i: usize, x: &mut DVector<f64>) {
        let (data, q, nruns) = (self.data, self.q, self.data.runs.len());
        for j in 0..q {
            x[j] = self.cols[j][i] / self.scales[j];
        }
        for j in q..self.p {
            x[j] = 0.0;
        }
        x[q + data.run_of[i]] = 1.0;
        if let Some(t) = data.turning_of[i] {
            x[q + nruns + t] = turn_value(data.reference[i]);
        }
    }

    /// Row `i`'s values in the columns `active` (those of its run,
    /// [`Design::active_in`]); every other column is zero in it.
    fn active_row_into(&self, i: usize, active: &[usize], xa: &mut DVector<f64>) {
        let (data, q, nruns) = (self.data, self.q, self.data.runs.len());
        for (k, &j) in active.iter().enumerate() {
            xa[k] = if j < q {
                self.cols[j][i] / self.scales[j]
            } else if j < q + nruns {
                // The run's own offset (no other run's is active).
                1.0
            } else {
                match data.turning_of[i] {
                    Some(t) if j == q + nruns + t => turn_value(data.reference[i]),
                    _ => 0.0,
                }
            };
        }
    }
}

/// Fit `model` on all data and score it fold by fold.
pub fn score(data: &Data<'_>, model: &[Term]) -> Scored {
    let design = Design::new(data, model);
    let (q, p, scales) = (design.q, design.p, &design.scales);
    let n = data.y.len();
    let FoldSums {
        grams,
        blocks,
        g_all,
        h_all,
    } = fold_sums(data, &design);
    let beta_all = solve(&g_all, &h_all);
    let (fold_sse, fold_blocks, held_out) =
        held_out_by_fold(data, &design, &grams, &blocks, &g_all, &h_all);
    let residual: Vec<f64> = design
        .fitted(0..n, &beta_all)
        .iter()
        .zip(&data.y)
        .map(|(f, y)| y - f)
        .collect();
    let rss: f64 = residual.iter().map(|v| v * v).sum();
    let r1 = {
        let num: f64 = residual.windows(2).map(|w| w[0] * w[1]).sum();
        (num / rss.max(f64::MIN_POSITIVE)).clamp(0.0, 0.99)
    };
    let sigma2 = rss / (n.saturating_sub(p)).max(1) as f64 * (1.0 + r1) / (1.0 - r1);
    let inv = g_all.clone().try_inverse();
    let stderr = (0..p)
        .map(|j| {
            let s = if j < q { scales[j] } else { 1.0 };
            inv.as_ref()
                .map_or(f64::NAN, |m| (sigma2 * m[(j, j)]).sqrt() / s)
        })
        .collect();
    let coeffs = (0..p)
        .map(|j| beta_all[j] / if j < q { scales[j] } else { 1.0 })
        .collect();
    let fold_record = record_ids(data);
    let between_spent = inv.as_ref().map_or(p as f64, |g_inv| {
        between_spent(&blocks, &fold_record, g_inv)
    });
    let block_residual = data
        .folds
        .iter()
        .flat_map(|f| {
            residual[f.start..f.end]
                .chunks_exact(AVERAGING_S)
                .map(move |c| (f.run, c.iter().sum::<f64>() / c.len() as f64))
                .collect::<Vec<_>>()
        })
        .collect();
    Scored {
        model: model.to_vec(),
        fold_sse,
        fold_blocks,
        coeffs,
        stderr,
        residual,
        held_out,
        block_residual,
        parameters: p,
        between_spent,
        fold_record,
    }
}

/// A design's sums fold by fold ([`fold_sums`]).
struct FoldSums {
    /// Per fold: the Gram matrix and the right-hand side.
    grams: Vec<(DMatrix<f64>, DVector<f64>)>,
    /// Per fold: the 60 s block means of the regressor rows and the data.
    blocks: Vec<Vec<(DVector<f64>, f64)>>,
    /// The Gram matrix over every fold.
    g_all: DMatrix<f64>,
    /// The right-hand side over every fold.
    h_all: DVector<f64>,
}

/// Per fold: Gram matrix, right-hand side, and the 60 s block means of
/// `design`; and their sums over the folds.
fn fold_sums(data: &Data<'_>, design: &Design<'_>) -> FoldSums {
    let p = design.p;
    let mut grams = Vec::with_capacity(data.folds.len());
    let mut blocks = Vec::with_capacity(data.folds.len());
    let mut g_all = DMatrix::zeros(p, p);
    let mut h_all = DVector::zeros(p);
    for f in &data.folds {
        // The Gram sums over the columns the fold's rows can reach (a
        // lot's unit: its own and the shared ones), put in place after.
        let active = design.active_in(f.run);
        let na = active.len();
        let mut ga = DMatrix::zeros(na, na);
        let mut xa = DVector::zeros(na);
        let mut ha = DVector::zeros(na);
        let mut means: Vec<(DVector<f64>, f64)> = Vec::new();
        let mut acc = (DVector::zeros(na), 0.0, 0usize);
        // The active columns of a 60 s block's mean row, put in place.
        let placed = |sums: &DVector<f64>, k: f64| {
            let mut m = DVector::zeros(p);
            for (ka, &j) in active.iter().enumerate() {
                m[j] = sums[ka] / k;
            }
            m
        };
        for i in f.start..f.end {
            design.active_row_into(i, &active, &mut xa);
            ga.syger(1.0, &xa, &xa, 1.0);
            ha.axpy(data.y[i], &xa, 1.0);
            acc.0 += &xa;
            acc.1 += data.y[i];
            acc.2 += 1;
            if acc.2 == AVERAGING_S {
                let k = AVERAGING_S as f64;
                means.push((placed(&acc.0, k), acc.1 / k));
                acc = (DVector::zeros(na), 0.0, 0);
            }
        }
        let mut h = DVector::zeros(p);
        for (ka, &j) in active.iter().enumerate() {
            h[j] = ha[ka];
        }
        ga.fill_upper_triangle_with_lower_triangle();
        let mut g = DMatrix::zeros(p, p);
        for (ka, &ja) in active.iter().enumerate() {
            for (kb, &jb) in active.iter().enumerate() {
                g[(ja, jb)] = ga[(ka, kb)];
            }
        }
        g_all += &g;
        h_all += &h;
        grams.push((g, h));
        blocks.push(means);
    }
    FoldSums {
        grams,
        blocks,
        g_all,
        h_all,
    }
}

/// Each fold predicted by the fit on the other folds (their sums, the
/// whole less the fold's): per fold, the sum of squares of its 60 s block
/// residuals and their count; and every row's held-out residual. Runs
/// with a single fold: their offset cannot come from other folds; the
/// held-out residual then has its own mean removed (a nuisance).
fn held_out_by_fold(
    data: &Data<'_>,
    design: &Design<'_>,
    grams: &[(DMatrix<f64>, DVector<f64>)],
    blocks: &[Vec<(DVector<f64>, f64)>],
    g_all: &DMatrix<f64>,
    h_all: &DVector<f64>,
) -> (Vec<f64>, Vec<usize>, Vec<f64>) {
    let folds_of_run = |r: usize| data.folds.iter().filter(|f| f.run == r).count();
    let mut fold_sse = Vec::with_capacity(data.folds.len());
    let mut fold_blocks = Vec::with_capacity(data.folds.len());
    let mut held_out = vec![0.0; data.y.len()];
    for (k, f) in data.folds.iter().enumerate() {
        let beta = solve(&(g_all - &grams[k].0), &(h_all - &grams[k].1));
        let alone = folds_of_run(f.run) < 2;
        let mut r: Vec<f64> = blocks[k].iter().map(|(x, y)| y - x.dot(&beta)).collect();
        let mut rows: Vec<f64> = design
            .fitted(f.start..f.end, &beta)
            .iter()
            .zip(&data.y[f.start..f.end])
            .map(|(f, y)| y - f)
            .collect();
        if alone {
            let m = rows.iter().sum::<f64>() / rows.len().max(1) as f64;
            rows.iter_mut().for_each(|v| *v -= m);
            let mb = r.iter().sum::<f64>() / r.len().max(1) as f64;
            r.iter_mut().for_each(|v| *v -= mb);
        }
        held_out[f.start..f.end].copy_from_slice(&rows);
        fold_sse.push(r.iter().map(|v| v * v).sum());
        fold_blocks.push(r.len());
    }
    (fold_sse, fold_blocks, held_out)
}

/// Record of each fold (folds cut from one record share it).
fn record_ids(data: &Data<'_>) -> Vec<usize> {
    let mut id = 0;
    data.folds
        .iter()
        .enumerate()
        .map(|(k, f)| {
            if k > 0 && (data.folds[k - 1].run != f.run || data.folds[k - 1].record != f.record) {
                id += 1;
            }
            id
        })
        .collect()
}

/// Degrees of freedom a model spends on the record means: the summed
/// leverage of the fitted record means, `sum_r N_r m_r' G^-1 m_r` (`m_r`
/// the record's mean regressor row, `N_r` its rows, `G` the Gram matrix of
/// every row). A per-run offset spends one; a term that varies only
/// within records (a thermal term at a steady temperature) spends next to
/// nothing, a term that varies only between records spends up to one per
/// parameter. Counting every parameter against the record means instead
/// leaves an effect between nine positions a handful of degrees of
/// freedom, most of them taken by terms that do not live there.
fn between_spent(
    blocks: &[Vec<(DVector<f64>, f64)>],
    fold_record: &[usize],
    g_inv: &DMatrix<f64>,
) -> f64 {
    let mut spent = 0.0;
    let mut k = 0;
    while k < blocks.len() {
        let record = fold_record[k];
        let mut sum: Option<DVector<f64>> = None;
        let mut n = 0usize;
        while k < blocks.len() && fold_record[k] == record {
            for (x, _) in &blocks[k] {
                match sum.as_mut() {
                    Some(s) => *s += x,
                    None => sum = Some(x.clone()),
                }
                n += 1;
            }
            k += 1;
        }
        if let Some(s) = sum {
            let m = s / n as f64;
            spent += (n * AVERAGING_S) as f64 * m.dot(&(g_inv * &m));
        }
    }
    spent
}

/// In-sample sum of squares of a model (to choose nonlinear parameters):
/// one solve on all rows, none of the held-out folds. The Gram matrix is
/// put together from sums kept per column and per pair of columns (the
/// selection asks for the same base model with each candidate many
/// times: only the candidate's products with the others are new).
pub fn in_sample_sse(data: &Data<'_>, model: &[Term]) -> f64 {
    let design = Design::new(data, model);
    let (keys, cols) = (&design.keys, &design.cols);
    let sums: Vec<Arc<ColumnSums>> = keys
        .iter()
        .zip(cols)
        .map(|(k, c)| data.column_sums(*k, c))
        .collect();
    let (q, p, nruns, fx) = (design.q, design.p, data.runs.len(), &data.fixed);
    let mut g = DMatrix::zeros(p, p);
    let mut h = DVector::zeros(p);
    for a in 0..q {
        let sa = &sums[a];
        for b in 0..a {
            let d = data.cross((keys[a], &cols[a]), (keys[b], &cols[b]));
            g[(a, b)] = d / (sa.scale * sums[b].scale);
        }
        g[(a, a)] = sa.sq / (sa.scale * sa.scale);
        for r in 0..nruns {
            g[(q + r, a)] = sa.run[r] / sa.scale;
        }
        for (t, v) in sa.turn.iter().enumerate() {
            g[(q + nruns + t, a)] = v / sa.scale;
        }
        h[a] = sa.y / sa.scale;
    }
    for r in 0..nruns {
        g[(q + r, q + r)] = fx.rows[r];
        h[q + r] = fx.y[r];
    }
    for (t, &r) in data.turning_runs.iter().enumerate() {
        let k = q + nruns + t;
        g[(k, q + r)] = fx.turn[t];
        g[(k, k)] = fx.turn_sq[t];
        h[k] = fx.turn_y[t];
    }
    g.fill_upper_triangle_with_lower_triangle();
    let beta = solve(&g, &h);
    // The residuals row by row: `y'y - 2 b'h + b'G b` cancels to noise
    // on these columns (uncentred, with an offset per run).
    design
        .fitted(0..data.y.len(), &beta)
        .iter()
        .zip(&data.y)
        .map(|(f, y)| (y - f).powi(2))
        .sum()
}

/// `model` plus `effect`, its parameter chosen on the in-sample fit
/// jointly with the parameters of the model's `free` effects (those the
/// reference chose from the data, such as model 4's warm-up time constant:
/// a joint refit, so a warm-up time constant bent to stand in for a missing
/// effect is set right once the effect is there). The parameters the
/// reference fixed stay (a twin's; re-choosing them with every candidate
/// let a lag and a long warm-up fit a slow periodic disturbance outside
/// the library, measured by the self-check).
pub fn with_best_parameter(
    data: &Data<'_>,
    model: &[Term],
    effect: Effect,
    free: &[Effect],
) -> Vec<Term> {
    with_best_parameter_in(data, model, effect, Units::ALL, free)
}

/// [`with_best_parameter`] with the effect in `units` alone (a lot's:
/// shared by some of its units, or one unit's own), its parameter chosen
/// on the in-sample fit of every row.
pub fn with_best_parameter_in(
    data: &Data<'_>,
    model: &[Term],
    effect: Effect,
    units: Units,
    free: &[Effect],
) -> Vec<Term> {
    let mut bases = vec![model.to_vec()];
    for &f in free {
        if let Some(i) = model.iter().position(|m| m.effect == f) {
            bases = bases
                .iter()
                .flat_map(|b| {
                    f.grid().iter().map(move |&p| {
                        let mut v = b.clone();
                        v[i].param = p;
                        v
                    })
                })
                .collect();
        }
    }
    // A memory effect's temperature (case, block, mean) is chosen first,
    // with the free parameters as they are: each temperature's best value,
    // refined; its width or time constant then jointly with them (every
    // form against every free value would triple the cost for a choice the
    // first pass makes as well).
    let mut grid: Vec<Param> = effect.grid().to_vec();
    if effect.has_forms() {
        let mut best: Option<(f64, Vec<Term>)> = None;
        for form in crate::twin::config::EffectTemperature::ALL {
            let g: Vec<Param> = grid
                .iter()
                .copied()
                .filter(|p| p.temperature() == Some(form))
                .collect();
            let found = best_on_grid(data, &[model.to_vec()], (effect, units), &g, true)
                .map(|(sse, m)| refine(data, sse, m, &g));
            if let Some((sse, m)) = found
                && best.as_ref().is_none_or(|(x, _)| sse < *x)
            {
                best = Some((sse, m));
            }
        }
        let Some((_, first)) = best else {
            return model.to_vec();
        };
        if bases.len() == 1 {
            return first;
        }
        let form = first.last().and_then(|m| m.param.temperature());
        grid.retain(|p| p.temperature() == form);
    }
    let choose = bases.len() > 1 || grid.len() > 1;
    match best_on_grid(data, &bases, (effect, units), &grid, choose) {
        Some((sse, m)) if grid.len() > 1 => refine(data, sse, m, &grid).1,
        Some((_, m)) => m,
        None => model.to_vec(),
    }
}

/// The best of `bases` x `grid` by the in-sample fit (the first when
/// there is nothing to `choose`).
fn best_on_grid(
    data: &Data<'_>,
    bases: &[Vec<Term>],
    (effect, units): (Effect, Units),
    grid: &[Param],
    choose: bool,
) -> Option<(f64, Vec<Term>)> {
    let mut best: Option<(f64, Vec<Term>)> = None;
    for b in bases {
        for &p in grid {
            let mut m = b.clone();
            m.push(Term::in_units(effect, p, units));
            let sse = if choose { in_sample_sse(data, &m) } else { 0.0 };
            if best.as_ref().is_none_or(|(x, _)| sse < *x) {
                best = Some((sse, m));
            }
        }
    }
    best
}

/// `model` (the effect last, at a value of `grid`) with the effect's value
/// moved to the geometric middle toward either neighbour on the grid when
/// that fits better: the grid's steps of 2-3x halved, so a play of 12
/// degC is not taken for 8 or 16.
fn refine(data: &Data<'_>, sse: f64, model: Vec<Term>, grid: &[Param]) -> (f64, Vec<Term>) {
    let Some(&Term { param: p, .. }) = model.last() else {
        return (sse, model);
    };
    let value = p.value();
    let mut values: Vec<f64> = grid.iter().map(|g| g.value()).collect();
    values.sort_by(f64::total_cmp);
    let Some(i) = values.iter().position(|&v| v == value) else {
        return (sse, model);
    };
    let mut best = (sse, model);
    for j in [i.checked_sub(1), Some(i + 1)].into_iter().flatten() {
        let Some(&other) = values.get(j) else {
            continue;
        };
        let mut m = best.1.clone();
        if let Some(last) = m.last_mut() {
            last.param = p.with_value((value * other).sqrt());
        }
        let sse = in_sample_sse(data, &m);
        if sse < best.0 {
            best = (sse, m);
        }
    }
    best
}

/// `model` with the parameters of its `free` effects chosen again on the
/// in-sample fit (as [`with_best_parameter`] does with a candidate): for a
/// model that gained a term with no parameter grid of its own (an outside
/// disturbance).
pub fn refit_free(data: &Data<'_>, model: &[Term], free: &[Effect]) -> Vec<Term> {
    let mut best = model.to_vec();
    for &f in free {
        let Some(i) = model.iter().position(|m| m.effect == f) else {
            continue;
        };
        let mut best_sse = f64::INFINITY;
        for &p in f.grid() {
            let mut m = best.clone();
            m[i].param = p;
            let sse = in_sample_sse(data, &m);
            if sse < best_sse {
                best_sse = sse;
                best = m;
            }
        }
    }
    best
}

/// Whether an effect's regressors vary within a run at all (relative to
/// their size): a regressor constant in every run is the run offset again,
/// and the runs cannot say anything about it.
pub fn identifiable(data: &Data<'_>, effect: Effect, p: Param) -> bool {
    data.runs.iter().any(|run| {
        effect.columns(run, p).iter().any(|c| {
            let n = c.len().max(1) as f64;
            let m = c.iter().sum::<f64>() / n;
            let var = c.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n;
            let size = c.iter().map(|v| v * v).sum::<f64>() / n;
            var > 1e-12 * size.max(1e-300)
        })
    })
}

/// Long-run variance factor of a residual series (runs kept apart):
/// 1 + 2 sum_l (1 - l/(L+1)) r_l, Bartlett weights (Newey-West), L lags.
fn long_run_factor(r: &[(usize, f64)], lags: usize) -> f64 {
    let g0: f64 = r.iter().map(|(_, v)| v * v).sum();
    if g0 <= 0.0 {
        return 1.0;
    }
    let mut f = 1.0;
    for l in 1..=lags {
        let gl: f64 = r
            .iter()
            .zip(r.iter().skip(l))
            .filter(|(a, b)| a.0 == b.0)
            .map(|(a, b)| a.1 * b.1)
            .sum();
        f += 2.0 * (1.0 - l as f64 / (lags as f64 + 1.0)) * gl / g0;
    }
    f.max(1.0)
}

/// Upper tail of a nested F-test of `q` more parameters.
fn f_test(rss0: f64, rss1: f64, q: f64, dof: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, FisherSnedecor};
    if dof < 1.0 || rss1 <= 0.0 || rss0 <= rss1 {
        return 1.0;
    }
    let f = ((rss0 - rss1) / q) / (rss1 / dof);
    FisherSnedecor::new(q, dof).map_or(1.0, |d| 1.0 - d.cdf(f))
}

/// Lags of the long-run variance, in 60 s means (ours: 20 min).
pub const NEWEY_WEST_LAGS: usize = 20;
/// Lags of the long-run variance of the record means (ours: 2 records: a
/// slow disturbance moves neighbouring records together).
pub const BETWEEN_LAGS: usize = 2;

/// Does `better` (base plus a candidate) beat `base`? Returns the held-out
/// improvement (reduction of the held-out sum of squares of 60 s means)
/// and a p-value that respects autocorrelated residuals. The in-sample 60 s
/// means are split into their record (fold) means and the deviations from
/// them; each part gets a nested F-test and the smaller p-value, doubled
/// (Bonferroni over the two), is returned:
/// - between records: one value per record (a position's or a thermal
///   segment's mean: the slow part of the noise, flicker, moves whole
///   records), their number cut by the record means' own long-run
///   variance ([`BETWEEN_LAGS`]); the degrees of freedom are those each
///   model spends on the record means ([`between_spent`]), not its
///   parameter count;
/// - within records: the sample size cut by the deviations' long-run
///   variance (Newey-West, Bartlett weights, [`NEWEY_WEST_LAGS`]).
pub fn improvement(base: &Scored, better: &Scored) -> (f64, f64) {
    let gain = base.sse() - better.sse();
    let q = better.parameters.saturating_sub(base.parameters).max(1) as f64;
    let rss = |r: &[(usize, f64)]| r.iter().map(|(_, v)| v * v).sum::<f64>();
    let (f0, f1) = (fold_means(base), fold_means(better));
    let (w0, w1) = (within(base, &f0), within(better, &f1));
    let n_eff = (w1.len() as f64 - f1.len() as f64) / long_run_factor(&w1, NEWEY_WEST_LAGS);
    let p_within = f_test(rss(&w0), rss(&w1), q, n_eff - q);
    let (g0, g1) = (record_means(base), record_means(better));
    let n_records = g1.len() as f64 / long_run_factor(&g1, BETWEEN_LAGS);
    let q_between = better.between_spent - base.between_spent;
    let p_between = if q_between < super::THRESHOLDS.min_between_dof {
        1.0
    } else {
        f_test(
            rss(&g0),
            rss(&g1),
            q_between,
            n_records - better.between_spent,
        )
    };
    (gain, (2.0 * p_within.min(p_between)).min(1.0))
}

/// Block residuals minus their fold's mean.
fn within(s: &Scored, means: &[(usize, f64)]) -> Vec<(usize, f64)> {
    let mut out = Vec::with_capacity(s.block_residual.len());
    let mut at = 0;
    for (k, &n) in s.fold_blocks.iter().enumerate() {
        let m = means.get(k).map_or(0.0, |x| x.1);
        out.extend(
            s.block_residual[at..at + n]
                .iter()
                .map(|&(r, v)| (r, v - m)),
        );
        at += n;
    }
    out
}

/// Mean of the in-sample block residual of each fold.
fn fold_means(s: &Scored) -> Vec<(usize, f64)> {
    let mut out = Vec::new();
    let mut at = 0;
    for &n in &s.fold_blocks {
        let part = &s.block_residual[at..at + n];
        let run = part.first().map_or(usize::MAX, |x| x.0);
        out.push((run, part.iter().map(|x| x.1).sum::<f64>() / n.max(1) as f64));
        at += n;
    }
    out
}

/// Mean of the in-sample block residual of each record (its folds together).
fn record_means(s: &Scored) -> Vec<(usize, f64)> {
    let mut out: Vec<(usize, f64, usize)> = Vec::new();
    let mut at = 0;
    for (k, &n) in s.fold_blocks.iter().enumerate() {
        let part = &s.block_residual[at..at + n];
        at += n;
        let Some(first) = part.first() else { continue };
        let sum: f64 = part.iter().map(|x| x.1).sum();
        match out.last_mut() {
            Some(last) if k > 0 && s.fold_record[k - 1] == s.fold_record[k] => {
                last.1 += sum;
                last.2 += n;
            }
            _ => out.push((first.0, sum, n)),
        }
    }
    out.into_iter()
        .map(|(r, sum, n)| (r, sum / n as f64))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The in-sample sum of squares row by row: the Gram matrix of every
    /// row and the residual of every row.
    fn in_sample_sse_by_rows(data: &Data<'_>, model: &[Term]) -> f64 {
        let design = Design::new(data, model);
        let mut g = DMatrix::zeros(design.p, design.p);
        let mut h = DVector::zeros(design.p);
        let mut x = DVector::zeros(design.p);
        for i in 0..data.y.len() {
            design.row_into(i, &mut x);
            g.syger(1.0, &x, &x, 1.0);
            h.axpy(data.y[i], &x, 1.0);
        }
        g.fill_upper_triangle_with_lower_triangle();
        let beta = solve(&g, &h);
        (0..data.y.len())
            .map(|i| (data.y[i] - design.predict(i, &beta)).powi(2))
            .sum()
    }

    /// Three runs a thermal cycle, positions and a rate record would give,
    /// made up: temperatures that swing and lag, the axis in five poses,
    /// and in the last run a record taken while the table turns (its step
    /// `KEY.record`, its reference the table's rate).
    fn synthetic_runs() -> Vec<RunData> {
        use super::super::data::Sample;
        use crate::analysis::series::Interval;
        use crate::geometry::Orientation;
        let site = crate::twin::TwinConfig::default_rl16().site;
        let poses = [
            (0.0, 90.0, 0.0),
            (90.0, 0.0, 0.0),
            (270.0, 0.0, 0.0),
            (0.0, -90.0, 0.0),
            (90.0, 0.0, 90.0),
        ];
        (0..3_u32)
            .map(|r| {
                let samples = (0..3000_u32)
                    .map(|k| {
                        let t = f64::from(k);
                        let phase = f64::from(r);
                        let tcase = 20.0 + 15.0 * (t / 700.0 + phase).sin();
                        let t1 = tcase + 0.5 + 0.3 * (t / 300.0).sin();
                        let (az, el, roll) = poses[(k as usize / 300 + r as usize) % poses.len()];
                        let orientation = Orientation::new(az, el, roll);
                        let turning = r == 2 && (1000..1600).contains(&k);
                        let reference_dph = if turning {
                            3600.0
                        } else {
                            orientation.earth_rate_dph(&site)
                        };
                        Sample {
                            iv: Interval {
                                time_s: t,
                                rate_dph: reference_dph + 0.01 * (t / 50.0).sin() + 0.002 * tcase,
                                reference_dph,
                                t1_c: t1,
                                t2_c: t1 - 0.2,
                                tcase_c: tcase,
                                chamber_c: tcase - 1.0,
                                frames: 400,
                            },
                            orientation,
                            record: format!("r{}", k / 300),
                            step: if turning {
                                "main.2.record".into()
                            } else {
                                format!("main.{}", k / 300).into()
                            },
                            table_rate_body_dph: if turning {
                                nalgebra::Vector3::new(3600.0, 0.0, 0.0)
                            } else {
                                nalgebra::Vector3::zeros()
                            },
                        }
                    })
                    .collect();
                RunData {
                    name: format!("synthetic {r}"),
                    site,
                    samples,
                }
            })
            .collect()
    }

    /// The sums kept per column and pair give the sum of squares the rows
    /// give, for models of thermal, orientation and rate terms (a rate run
    /// brings its scale factor), asked for in any order, on the runs' data
    /// and on another signal fitted as if it were the data.
    #[test]
    fn the_in_sample_fit_from_kept_sums_is_the_fit_from_the_rows() {
        use super::super::library::{LIBRARY, MODEL4};
        let runs = synthetic_runs();
        let data = Data::new(&runs);
        assert!(!data.turning_runs.is_empty());
        let signal: Vec<f64> = (0..data.y.len()).map(|i| (i as f64 * 1e-3).sin()).collect();
        let other = Data::new(&runs)
            .with_data(signal)
            .expect("one value per row");
        assert!(Data::new(&runs).with_data(vec![0.0; 3]).is_none());
        let base: Vec<Term> = MODEL4.iter().map(|&e| Term::new(e, e.grid()[0])).collect();
        let mut models = vec![Vec::new(), base.clone()];
        for e in LIBRARY {
            for &p in e.grid().iter().take(2) {
                let mut m = base.clone();
                m.push(Term::new(e, p));
                models.push(m);
            }
        }
        // Twice: the second pass reads every sum from what was kept.
        for data in [&data, &other] {
            for _ in 0..2 {
                for m in models.iter().rev() {
                    let (kept, rows) = (in_sample_sse(data, m), in_sample_sse_by_rows(data, m));
                    assert!(
                        (kept - rows).abs() <= 1e-9 * rows,
                        "{m:?}: {kept} against {rows}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_sums_and_fits_over_a_runs_columns_are_those_of_its_whole_rows() {
        use super::super::library::{LIBRARY, MODEL4, Units};
        // A lot of two units (the first run the first unit's, the others
        // the second's): terms shared by both, and one of each unit's own,
        // whose columns are zero in the other unit's rows.
        let runs = synthetic_runs();
        let lot = Data::new(&runs).with_units(vec![0, 1, 1]).expect("units");
        let mut model: Vec<Term> = MODEL4.iter().map(|&e| Term::new(e, e.grid()[0])).collect();
        model.push(Term::in_units(
            LIBRARY[0],
            LIBRARY[0].grid()[0],
            Units::one(0),
        ));
        model.push(Term::in_units(
            LIBRARY[1],
            LIBRARY[1].grid()[0],
            Units::one(1),
        ));
        let single = Data::new(&runs);
        for (data, model) in [
            (&lot, &model),
            (&single, &model[..MODEL4.len() + 1].to_vec()),
        ] {
            let design = Design::new(data, model);
            let sums = fold_sums(data, &design);
            let (mut g, mut h) = (DMatrix::zeros(design.p, design.p), DVector::zeros(design.p));
            let mut x = DVector::zeros(design.p);
            for (k, f) in data.folds.iter().enumerate() {
                let mut block = (DVector::zeros(design.p), 0.0);
                let mut means = Vec::new();
                for (n, i) in (f.start..f.end).enumerate() {
                    design.row_into(i, &mut x);
                    g.syger(1.0, &x, &x, 1.0);
                    h.axpy(data.y[i], &x, 1.0);
                    block.0 += &x;
                    block.1 += data.y[i];
                    if (n + 1) % AVERAGING_S == 0 {
                        let a = AVERAGING_S as f64;
                        means.push((&block.0 / a, block.1 / a));
                        block = (DVector::zeros(design.p), 0.0);
                    }
                }
                assert_eq!(sums.blocks[k], means, "fold {k}'s 60 s means");
                let beta = DVector::from_fn(design.p, |j, _| 0.3 - 0.1 * j as f64);
                let rows: Vec<f64> = (f.start..f.end).map(|i| design.predict(i, &beta)).collect();
                assert_eq!(design.fitted(f.start..f.end, &beta), rows, "fold {k}'s fit");
            }
            let beta = DVector::from_fn(design.p, |j, _| 0.1 * j as f64 - 0.2);
            let n = data.y.len();
            let rows: Vec<f64> = (0..n).map(|i| design.predict(i, &beta)).collect();
            assert_eq!(design.fitted(0..n, &beta), rows, "every run's rows");
            g.fill_upper_triangle_with_lower_triangle();
            let scale = g.amax();
            assert!(
                (&sums.g_all - &g).amax() <= 1e-12 * scale,
                "the Gram matrix of every row"
            );
            assert!(
                (&sums.h_all - &h).amax() <= 1e-12 * h.amax(),
                "the right-hand side of every row"
            );
        }
    }

    /// Degrees of freedom spent on the record means by the columns of
    /// `cols` (each a function of record and row), three records of two
    /// 60 s blocks each, one fold per record.
    fn spent(cols: &[&dyn Fn(usize, usize) -> f64]) -> f64 {
        let p = cols.len();
        let mut g = DMatrix::zeros(p, p);
        let mut blocks = Vec::new();
        for r in 0..3 {
            let mut means = Vec::new();
            for b in 0..2 {
                let mut sum = DVector::zeros(p);
                for i in b * AVERAGING_S..(b + 1) * AVERAGING_S {
                    let x = DVector::from_iterator(p, cols.iter().map(|c| c(r, i)));
                    g += &x * x.transpose();
                    sum += x;
                }
                means.push((sum / AVERAGING_S as f64, 0.0));
            }
            blocks.push(means);
        }
        let g_inv = g.try_inverse().expect("columns apart");
        between_spent(&blocks, &[0, 1, 2], &g_inv)
    }

    #[test]
    fn only_what_varies_between_records_spends_their_degrees_of_freedom() {
        let offset = |_: usize, _: usize| 1.0;
        let between = |r: usize, _: usize| r as f64 - 1.0;
        let within = |_: usize, i: usize| if i.is_multiple_of(2) { 1.0 } else { -1.0 };
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
        assert!(close(spent(&[&offset]), 1.0));
        assert!(close(spent(&[&offset, &between]), 2.0));
        // A term that moves within records only spends nothing there,
        // although it is a parameter of the model.
        assert!(close(spent(&[&offset, &within]), 1.0));
        assert!(close(spent(&[&offset, &between, &within]), 2.0));
    }
}

#[cfg(test)]
#[path = "engine_tests.rs"]
mod more_tests;
