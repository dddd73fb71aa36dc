//! The searches: Nelder-Mead from a grid of starts, settled by
//! Levenberg-Marquardt (`lsq`), the folds started from the fit on all the
//! runs and from each other's optima, two threads.

use super::*;

/// Nelder-Mead from `start` (a step of 0.3 along each quantity: a third
/// of a log time constant), at most `iters` iterations: the best point
/// found and its cost.
pub(super) fn search<C>(cost: C, start: &[f64], iters: u64) -> (Vec<f64>, f64)
where
    C: CostFunction<Param = Vec<f64>, Output = f64> + Clone,
{
    let mut simplex = vec![start.to_vec()];
    for i in 0..start.len() {
        let mut v = start.to_vec();
        v[i] += 0.3;
        simplex.push(v);
    }
    let fallback = || {
        (
            start.to_vec(),
            cost.cost(&start.to_vec()).unwrap_or(f64::MAX),
        )
    };
    let Ok(solver) = NelderMead::new(simplex).with_sd_tolerance(1e-12) else {
        return fallback();
    };
    Executor::new(cost.clone(), solver)
        .configure(|s| s.max_iters(iters))
        .run()
        .ok()
        .and_then(|r| {
            Some((
                r.state().get_best_param()?.clone(),
                r.state().get_best_cost(),
            ))
        })
        .unwrap_or_else(fallback)
}

/// A cost that is a sum of squares of residuals, its searched quantities
/// within box bounds: searched by the simplex, settled by
/// [`lsq::minimize`].
pub(super) trait Squares:
    CostFunction<Param = Vec<f64>, Output = f64> + Clone + Sync
{
    /// The residuals the cost sums the squares of, at `p` (within bounds).
    fn residuals(&self, p: &[f64]) -> Vec<f64>;
    /// The searched quantities' lower and upper bounds.
    fn bounds(&self) -> (Vec<f64>, Vec<f64>);
}

/// Every start scored, the best `keep` searched by the simplex for
/// `iters` iterations (with none, the best start as it is), the best of
/// them settled by Levenberg-Marquardt within the bounds (at most the
/// evaluations of [`SETTLE_ITERS`] Jacobians).
pub(super) fn multistart<C: Squares>(
    cost: C,
    starts: &[Vec<f64>],
    keep: usize,
    iters: u64,
) -> Vec<f64> {
    multistart_settled(cost, starts, keep, iters, SETTLE_ITERS)
}

/// [`multistart`] with a settling search of at most `settle` Jacobians.
pub(super) fn multistart_settled<C: Squares>(
    cost: C,
    starts: &[Vec<f64>],
    keep: usize,
    iters: u64,
    settle: usize,
) -> Vec<f64> {
    let mut scored: Vec<(&Vec<f64>, f64)> = starts
        .iter()
        .map(|q| (q, cost.cost(q).unwrap_or(f64::MAX)))
        .collect();
    scored.sort_by(|a, b| a.1.total_cmp(&b.1));
    // No simplex iterations: the best start as it is.
    let keep = if iters == 0 { 0 } else { keep };
    let best = scored
        .iter()
        .take(keep)
        .map(|(q, _)| search(cost.clone(), q, iters))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .or_else(|| scored.first().map(|(q, c)| ((*q).clone(), *c)))
        .unwrap_or_else(|| (starts[0].clone(), f64::MAX));
    let (lo, hi) = cost.bounds();
    let settled = lsq::minimize(|p| cost.residuals(p), &best.0, &lo, &hi, settle);
    if settled.1 <= best.1 {
        settled.0
    } else {
        best.0
    }
}

/// The settling search's budget, in forward-difference Jacobians (one
/// evaluation per searched quantity each, and two per step tried; ours:
/// the study's runs settle in 4 to 40).
pub(super) const SETTLE_ITERS: usize = 100;

/// The starts: a coarse grid over the shapes a unit can have, not the
/// RL-16 defaults (ours: case 600-5000 s, blocks 150-2000 s, weak and
/// strong exchange, with and without a mount node, blocks that do and do
/// not load the case).
pub(super) fn grid() -> Vec<Shape> {
    let mut out = Vec::new();
    for mount in [1.0f64, 900.0] {
        for case in [600.0f64, 1600.0, 5000.0] {
            for block in [150.0f64, 600.0, 2000.0] {
                for coupling in [300.0f64, 5000.0] {
                    for ratio in [0.0, 0.5] {
                        let mut q = off();
                        q[..SIMPLE_LEN].copy_from_slice(&[
                            mount.ln(),
                            case.ln(),
                            block.ln(),
                            (block * 1.1).ln(),
                            coupling.ln(),
                            0.5,
                            ratio,
                            ratio,
                        ]);
                        out.push(q);
                    }
                }
            }
        }
    }
    out
}

/// Identify the network on the blocks outside `held_out` from the grid of
/// starts (and `prior`, a twin's network, as one more; the prior's form
/// is searched when there is one: its full form's quantities and its
/// effects).
pub(super) fn identify(
    runs: &[Vec<Block>],
    held_out: Option<usize>,
    prior: Option<(&Shape, Form)>,
) -> Shape {
    let form = prior.map_or_else(Form::default, |p| p.1);
    let starts: Vec<Shape> = grid().into_iter().chain(prior.map(|p| *p.0)).collect();
    search_shape(runs, held_out, form, &starts, 6, 150)
}

/// The network's shape searched from `starts` ([`multistart`]) on the
/// blocks outside `held_out`, within bounds, in `form` (which quantities
/// move, which effects act).
pub(super) fn search_shape(
    runs: &[Vec<Block>],
    held_out: Option<usize>,
    form: Form,
    starts: &[Shape],
    keep: usize,
    iters: u64,
) -> Shape {
    shape_settled(runs, held_out, form, starts, (keep, iters), SETTLE_ITERS)
}

/// [`search_shape`] from the best of `starts`, its settling search cut
/// at `settle` Jacobians: a screening fit, which [`settle_shape`] may
/// carry on.
pub(super) fn screen_shape(
    runs: &[Vec<Block>],
    held_out: Option<usize>,
    form: Form,
    starts: &[Shape],
    iters: u64,
    settle: usize,
) -> Shape {
    shape_settled(runs, held_out, form, starts, (1, iters), settle)
}

/// [`multistart_settled`] on the network's shape in `form`, the `keep`
/// best starts searched by the simplex for `iters` iterations each.
fn shape_settled(
    runs: &[Vec<Block>],
    held_out: Option<usize>,
    form: Form,
    starts: &[Shape],
    (keep, iters): (usize, u64),
    settle: usize,
) -> Shape {
    let cost = Cost {
        runs,
        held_out,
        form,
    };
    let starts: Vec<Vec<f64>> = starts.iter().map(|q| cost.searched(q)).collect();
    let p = multistart_settled(cost, &starts, keep, iters, settle);
    cost.shape(&p).0
}

/// The settling search carried on from `start` for at most `settle`
/// Jacobians (the start kept where it does not gain).
pub(super) fn settle_shape(
    runs: &[Vec<Block>],
    held_out: Option<usize>,
    form: Form,
    start: &Shape,
    settle: usize,
) -> Shape {
    let cost = Cost {
        runs,
        held_out,
        form,
    };
    let (lo, hi) = cost.bounds();
    let p = cost.searched(start);
    let (q, f) = lsq::minimize(|x| cost.residuals(x), &p, &lo, &hi, settle);
    if f <= cost.cost(&p).unwrap_or(f64::MAX) {
        cost.shape(&q).0
    } else {
        *start
    }
}

/// Starts of the full form's search around a fit of the simpler one: a
/// heat sink's time constant, s, and capacity ratio, and block 1's
/// capacity over block 2's (ours: sinks of 300 s to 6000 s, light and
/// heavy, since a baseplate can weigh many times the case; blocks three
/// times apart either way).
pub(super) const FULL_STARTS: [(f64, f64, f64); 8] = [
    (300.0, 0.5, 1.0),
    (1500.0, 0.5, 1.0),
    (6000.0, 0.5, 1.0),
    (300.0, 3.0, 1.0),
    (1500.0, 3.0, 1.0),
    (6000.0, 3.0, 1.0),
    (SINK_START_S, 0.0, 3.0),
    (SINK_START_S, 0.0, 1.0 / 3.0),
];

/// The fits searched again in the full form (of `form`'s effects): the
/// one on all the runs from its own optimum with each of
/// [`FULL_STARTS`], each fold from that ([`warm_shape`]), then started
/// again from the others' optima as in the simpler form
/// ([`cross_started`]).
pub(super) fn in_full_form(data: &[Vec<Block>], shapes: &[Shape], form: Form) -> Vec<Shape> {
    let form = Form { full: true, ..form };
    let Some(first) = shapes.first() else {
        return Vec::new();
    };
    let starts: Vec<Shape> = FULL_STARTS
        .iter()
        .map(|&(tau, ratio, blocks)| {
            let mut q = *first;
            q[at::SINK_TAU] = tau.ln();
            q[at::SINK_RATIO] = ratio;
            q[at::BLOCKS_1_OVER_2] = blocks.ln();
            q
        })
        .collect();
    let all = search_shape(data, None, form, &starts, 2, 150);
    let folds: Vec<usize> = (0..shapes.len() - 1).collect();
    let searched = std::iter::once(all)
        .chain(on_two_threads(&folds, |&k| {
            warm_shape(data, Some(k), form, &all)
        }))
        .collect();
    cross_started(data, searched, form)
}

/// Simplex iterations of a fold's search from the fit on all the runs
/// before it is settled by Levenberg-Marquardt (ours: the fold's optimum
/// lies near, three quarters of its blocks being the same).
pub(super) const WARM_ITERS: u64 = 30;

/// A fold's network, searched from `start` (the fit on all the runs).
///
/// A fold sees three quarters of the blocks the fit on all the runs saw,
/// so its optimum lies near that fit's: searched from there, it is spared
/// the grid's six simplex searches, which on a unit unlike the twin were
/// most of the diagnosis's time. It still minimises its
/// own training cost alone (a start is not a fit to the held-out
/// quarter), and [`cross_started`] still searches again any fit another
/// one's optimum beats.
pub(super) fn warm_shape(
    runs: &[Vec<Block>],
    held_out: Option<usize>,
    form: Form,
    start: &Shape,
) -> Shape {
    search_shape(runs, held_out, form, &[*start], 1, WARM_ITERS)
}

/// A fold's modes, searched from `start` (the modes on all the runs), as
/// [`warm_shape`].
pub(super) fn warm_modes(
    runs: &[Vec<Block>],
    held_out: Option<usize>,
    axis: usize,
    start: &[f64; MODES],
) -> [f64; MODES] {
    let cost = ModalCost {
        runs,
        held_out,
        axis,
    };
    let p = multistart(cost, &[start.map(f64::ln).to_vec()], 1, WARM_ITERS);
    clamp_modes(&p).0
}

/// `f` over `jobs` on two threads (the jobs dealt alternately), the
/// results in the jobs' order. A worker's panic is raised again here: a
/// lost worker would otherwise drop half the results and shift the rest.
pub(super) fn on_two_threads<J: Sync, R: Send>(jobs: &[J], f: impl Fn(&J) -> R + Sync) -> Vec<R> {
    let f = &f;
    let mut out: Vec<(usize, R)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..2)
            .map(|w| {
                s.spawn(move || {
                    jobs.iter()
                        .enumerate()
                        .filter(|(i, _)| i % 2 == w)
                        .map(|(i, j)| (i, f(j)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    });
    out.sort_by_key(|o| o.0);
    out.into_iter().map(|o| o.1).collect()
}

/// Another fit's optimum must cost this fraction of a fit's own or less
/// to be searched from (ours: a basin 10 % better; the lost fits were 2 to
/// 600 times worse).
pub(super) const CROSS_BETTER: f64 = 0.9;
/// Simplex iterations of the search from another fit's optimum before it
/// is settled (ours: it starts in the right basin).
pub(super) const CROSS_ITERS: u64 = 150;

/// The network fits (on all the runs, then with each fold held out) each
/// searched again from whichever of the others' optima fits its own
/// training blocks better than its own optimum does, by [`CROSS_BETTER`].
/// A fit that leaves out the first quarter of a run (the warm-up, where
/// the rises show) starts from a grid far from the unit and could end in
/// a basin 2 to 600 times worse than the network the other fits found:
/// on randomised units of the network's own form that made one unit in
/// eight say `form_misfit`. Each fit still
/// minimises only its own training cost (a start from a fit that saw the
/// held-out quarter is a start, not a fit to it).
pub(super) fn cross_started(data: &[Vec<Block>], shapes: Vec<Shape>, form: Form) -> Vec<Shape> {
    let fold = |i: usize| (i > 0).then(|| i - 1);
    let better: Vec<(usize, Option<Shape>)> = (0..shapes.len())
        .map(|i| {
            let cost = Cost {
                runs: data,
                held_out: fold(i),
                form,
            };
            let at = |q: &Shape| cost.cost(&cost.searched(q)).unwrap_or(f64::MAX);
            let own = at(&shapes[i]);
            let other = shapes
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, q)| (*q, at(q)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            (i, other.filter(|o| o.1 < CROSS_BETTER * own).map(|o| o.0))
        })
        .collect();
    let jobs: Vec<(usize, Shape)> = better
        .into_iter()
        .filter_map(|(i, q)| Some((i, q?)))
        .collect();
    let searched = on_two_threads(&jobs, |&(i, q)| {
        search_shape(data, fold(i), form, &[q], 1, CROSS_ITERS)
    });
    let mut out = shapes;
    for (&(i, _), q) in jobs.iter().zip(searched) {
        out[i] = q;
    }
    out
}
