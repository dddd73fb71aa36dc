//! Nonlinear least squares within box bounds: Levenberg-Marquardt with
//! projected steps, its Jacobian by forward differences, each step
//! corrected by geodesic acceleration. The thermal layer's searches end
//! with it (a Nelder-Mead simplex finds the basin, this settles in it).
//!
//! Written here rather than taken from a crate: the network's quantities
//! have physical bounds the fit must never leave (a time constant, a
//! rise, a capacity ratio of zero), and the Levenberg-Marquardt crates
//! for nalgebra take no bounds (and `levenberg-marquardt` pins an older
//! nalgebra than ours).
//!
//! What makes it fast on the network's residuals, where a plain
//! projected Levenberg-Marquardt crawled (a unit the simple form does not
//! hold spent its whole budget of 100 Jacobians and ended at three times
//! the sum of squares this reaches in a fifth of the evaluations):
//!
//! - **Quantities on a bound sit the step out when it fails.** A quantity
//!   on its bound whose gradient points into the box is free to move, but
//!   the step clamped back into the box is then not the step the normal
//!   equations chose; near a form's edge (a heat sink of no capacity,
//!   whose time constant then does nothing) that failed again and again,
//!   and every failure raised the damping. A failed step is tried again
//!   with the quantities on a bound held where they are, before the
//!   damping is raised.
//! - **Geodesic acceleration** (Transtrum and Sethna, "Improvements to
//!   the Levenberg-Marquardt algorithm for nonlinear least-squares
//!   minimization", 2012): along a long curved valley (the capacity ratio
//!   of the blocks trading against their time constants) the step is
//!   bent by the residuals' second directional derivative, taken by one
//!   more evaluation, instead of being damped to a crawl.
//! - **A search that has stopped gaining ends.** The network's fits
//!   spent a third to a half of their Jacobians on steps that each
//!   gained a few 1e-7 of the sum of squares or less: once five steps
//!   together gain less than a millionth, the search ends. A search
//!   creeping along a valley could have gone on gaining (the tests show
//!   one: under a tenth of a percent in a thousand more evaluations);
//!   no held-out score, test or named effect turns on that much (the
//!   twelve units of docs/diagnosis.md name the same effects with it).
//! - **A quantity held on its bound is not differenced every step.** A
//!   form that misses drives some of its quantities onto their bounds
//!   and holds them there (the conductance unit's settle had four of its
//!   twelve on bounds for most of its 80 Jacobians), yet each Jacobian
//!   took their columns only to learn their gradients still point out
//!   of the box. A quantity held at a whole Jacobian stays held for the
//!   next [`REFRESH`] - 1, its column not taken; a failed step takes a
//!   whole Jacobian at once (a search ends on a failed step only at a
//!   whole one), so a quantity the search needs back is released before
//!   it gives up.

use nalgebra::{DMatrix, DVector};

/// Relative step of the forward differences (ours: the square root of
/// f64's epsilon, scaled by the quantity; the residuals are smooth).
const FD_STEP: f64 = 1.5e-8;
/// A step that lowers the sum of squares by less than this fraction ends
/// the search.
const REL_TOL: f64 = 1e-10;
/// The finite-difference step of the second directional derivative, as
/// a fraction of the step (Transtrum and Sethna's 0.1).
const ACCEL_PROBE: f64 = 0.1;
/// The acceleration is used only while at most this fraction of the step
/// (twice its norm over the step's; Transtrum and Sethna's 0.75): a
/// larger one means the quadratic model is not to be trusted there.
const ACCEL_RATIO: f64 = 0.75;
/// Damping raises tried from one point before the search ends there.
const TRIES: usize = 12;
/// A search whose last [`STALL_STEPS`] steps together lowered the sum of
/// squares by less than this fraction of it has settled (ours: on the
/// conductance unit of docs/benchmarks.md the full form's fit on all the
/// runs spent 24 of its 38 Jacobians on steps that each gained under
/// 3e-7, the trace's resolution, most of them far less; a fit crossing a
/// plateau there gains 1e-6 to 1e-5 a step and goes on, five times
/// above the bar: a flatter plateau would be ended on it).
const STALL_TOL: f64 = 1e-6;
/// The steps [`STALL_TOL`] is summed over (ours).
const STALL_STEPS: usize = 5;
/// A quantity held on its bound (its gradient pointing out of the box) at
/// a whole Jacobian stays held, its column not taken, until the next
/// whole one, every this many Jacobians or when a step fails (ours: on
/// the conductance unit's settle four of its twelve quantities sat on
/// bounds for most of its 80 Jacobians).
const REFRESH: usize = 5;

/// What a search does beyond the plain damped steps.
#[derive(Debug, Clone, Copy)]
struct Rules {
    /// Each step bent by its geodesic acceleration.
    accelerate: bool,
    /// The stall rule's bar ([`STALL_TOL`]).
    stall: f64,
    /// Jacobians between whole ones ([`REFRESH`]; 1: every one whole).
    refresh: usize,
}

/// The rules [`minimize`] searches by.
const RULES: Rules = Rules {
    accelerate: true,
    stall: STALL_TOL,
    refresh: REFRESH,
};

/// The minimum of `sum(residuals(p)^2)` over `lo <= p <= hi` from `start`
/// (clamped into the box), with at most `iters` forward-difference
/// Jacobians: the point and its sum of squares. A quantity on a bound
/// whose gradient points out of the box is held there for the step; the
/// others move by the damped Gauss-Newton step with its geodesic
/// acceleration, clamped into the box (a failed step is tried again with
/// every quantity on a bound held). Non-finite residuals count as a worse
/// point.
pub fn minimize(
    residuals: impl Fn(&[f64]) -> Vec<f64> + Sync,
    start: &[f64],
    lo: &[f64],
    hi: &[f64],
    iters: usize,
) -> (Vec<f64>, f64) {
    levenberg_marquardt(&residuals, start, (lo, hi), iters, RULES)
}

/// Sum of squares, `f64::MAX` when not finite.
fn sse(r: &[f64]) -> f64 {
    let s: f64 = r.iter().map(|x| x * x).sum();
    if s.is_finite() { s } else { f64::MAX }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn clamp(p: &mut [f64], lo: &[f64], hi: &[f64]) {
    for (i, v) in p.iter_mut().enumerate() {
        *v = v.clamp(lo[i], hi[i]);
    }
}

/// The forward-difference Jacobian at `p` (residuals `r`), by columns,
/// each stepping into the box, but for the `held` quantities' (left
/// empty); the columns on two threads (each column is the same
/// arithmetic wherever it runs, so the search's path does not depend on
/// it). A search that runs alone, the first fit on all the runs or the
/// one candidate left to settle, then has both cores; two searches side
/// by side share them.
fn jacobian(
    residuals: &(impl Fn(&[f64]) -> Vec<f64> + Sync),
    p: &[f64],
    r: &[f64],
    (hi, held): (&[f64], &[bool]),
) -> Vec<Vec<f64>> {
    let column = |i: usize| -> Vec<f64> {
        if held[i] {
            return Vec::new();
        }
        let mut h = FD_STEP * p[i].abs().max(1.0);
        if p[i] + h > hi[i] {
            h = -h;
        }
        let mut q = p.to_vec();
        q[i] += h;
        residuals(&q)
            .iter()
            .zip(r)
            .map(|(a, b)| (a - b) / h)
            .collect()
    };
    // The first half of the columns computed on a second thread, the
    // rest here.
    let computed: Vec<usize> = (0..p.len()).filter(|&i| !held[i]).collect();
    let half = computed.len() / 2;
    if half == 0 {
        return (0..p.len()).map(column).collect();
    }
    let split = computed[half];
    std::thread::scope(|s| {
        let first = s.spawn(|| (0..split).map(column).collect::<Vec<_>>());
        let rest: Vec<Vec<f64>> = (split..p.len()).map(column).collect();
        let mut cols = first
            .join()
            .unwrap_or_else(|e| std::panic::resume_unwind(e));
        cols.extend(rest);
        cols
    })
}

/// The quantities free to move: not on a bound their gradient `g`
/// points out of.
fn free_set(p: &[f64], g: &[f64], lo: &[f64], hi: &[f64]) -> Vec<usize> {
    (0..p.len())
        .filter(|&i| {
            g[i].is_finite() && !(p[i] <= lo[i] && g[i] > 0.0) && !(p[i] >= hi[i] && g[i] < 0.0)
        })
        .collect()
}

/// The Gauss-Newton system on a set of free quantities: the Jacobian's
/// columns' products (the upper triangle, mirrored), the gradient on them,
/// and the largest diagonal element (for a floor on the damping).
struct Normal {
    free: Vec<usize>,
    h: DMatrix<f64>,
    g: DVector<f64>,
    scale: f64,
}

impl Normal {
    fn new(cols: &[Vec<f64>], g: &[f64], free: Vec<usize>) -> Self {
        let k = free.len();
        let mut h = DMatrix::zeros(k, k);
        for a in 0..k {
            for b in a..k {
                let v = dot(&cols[free[a]], &cols[free[b]]);
                (h[(a, b)], h[(b, a)]) = (v, v);
            }
        }
        let g = DVector::from_fn(k, |a, _| g[free[a]]);
        let scale = (0..k).map(|a| h[(a, a)]).fold(0.0, f64::max).max(1e-300);
        Self { free, h, g, scale }
    }

    /// `(H + lambda diag H)^-1 (-J^T v)` for the gradient-like `jv`
    /// (`J^T v` on the free quantities); none when the damped matrix is
    /// not positive definite.
    fn solve(&self, lambda: f64, jv: &DVector<f64>) -> Option<DVector<f64>> {
        let mut a = self.h.clone();
        for d in 0..self.free.len() {
            a[(d, d)] += lambda * (self.h[(d, d)] + 1e-12 * self.scale);
        }
        Some(a.cholesky()?.solve(&(-jv)))
    }

    /// `p` moved by `step` on the free quantities (not clamped).
    fn moved(&self, p: &[f64], step: &DVector<f64>) -> Vec<f64> {
        let mut q = p.to_vec();
        for (a, &i) in self.free.iter().enumerate() {
            q[i] += step[a];
        }
        q
    }
}

/// A point of the search: where, its residuals, and the Jacobian there
/// by columns.
#[derive(Clone, Copy)]
struct At<'a> {
    p: &'a [f64],
    r: &'a [f64],
    cols: &'a [Vec<f64>],
}

/// The damped step from `p` on `normal`'s free quantities, with its
/// geodesic acceleration when `accelerate` and the acceleration is small
/// beside it ([`ACCEL_RATIO`]; one more evaluation of the residuals):
/// the new point, clamped into the box; none when the damped matrix is
/// not positive definite.
fn step(
    residuals: &impl Fn(&[f64]) -> Vec<f64>,
    at: &At<'_>,
    normal: &Normal,
    lambda: f64,
    bounds: (&[f64], &[f64]),
    accelerate: bool,
) -> Option<Vec<f64>> {
    let At { p, r, cols } = *at;
    let (lo, hi) = bounds;
    let inside = |x: &[f64]| (0..x.len()).all(|i| lo[i] <= x[i] && x[i] <= hi[i]);
    let v = normal.solve(lambda, &normal.g)?;
    let mut q = normal.moved(p, &v);
    clamp(&mut q, lo, hi);
    // The second directional derivative along v, by a finite difference
    // (Transtrum and Sethna's eq. 15), from a probe inside the box.
    let probe = normal.moved(p, &(&v * ACCEL_PROBE));
    if !accelerate || q == p || !inside(&probe) {
        return Some(q);
    }
    let rp = residuals(&probe);
    let rpp: Vec<f64> = (0..r.len())
        .map(|j| {
            let jv: f64 = normal
                .free
                .iter()
                .zip(v.iter())
                .map(|(&i, vi)| cols[i][j] * vi)
                .sum();
            2.0 / ACCEL_PROBE * ((rp[j] - r[j]) / ACCEL_PROBE - jv)
        })
        .collect();
    let jt_rpp = DVector::from_fn(normal.free.len(), |a, _| dot(&cols[normal.free[a]], &rpp));
    let Some(acc) = normal.solve(lambda, &jt_rpp) else {
        return Some(q);
    };
    let small = 2.0 * acc.norm() <= ACCEL_RATIO * v.norm();
    if !small || !acc.iter().all(|a| a.is_finite()) {
        return Some(q);
    }
    let mut accelerated = normal.moved(p, &(v + acc * 0.5));
    clamp(&mut accelerated, lo, hi);
    Some(accelerated)
}

/// The quantities held on a bound at the last whole Jacobian, whose
/// columns are not taken until the next whole one.
struct Pins {
    held: Vec<bool>,
    since_whole: usize,
    refresh: usize,
}

impl Pins {
    /// None held; the first Jacobian whole.
    fn new(n: usize, refresh: usize) -> Self {
        Self {
            held: vec![false; n],
            since_whole: refresh,
            refresh,
        }
    }

    /// Whether the next Jacobian is whole (every `refresh`, or after
    /// [`Pins::release`]); a whole one holds nothing.
    fn next(&mut self) -> bool {
        let whole = self.since_whole >= self.refresh;
        if whole {
            self.held.fill(false);
            self.since_whole = 0;
        }
        self.since_whole += 1;
        whole
    }

    /// At a whole Jacobian: hold the quantities on a bound that are not
    /// `free` to move (their gradients point out of the box).
    fn hold(&mut self, p: &[f64], free: &[usize], (lo, hi): (&[f64], &[f64])) {
        for (i, h) in self.held.iter_mut().enumerate() {
            *h = (p[i] <= lo[i] || p[i] >= hi[i]) && !free.contains(&i);
        }
    }

    /// The next Jacobian whole: a step failed with quantities held.
    fn release(&mut self) {
        self.since_whole = self.refresh;
    }
}

/// Levenberg-Marquardt with a forward-difference Jacobian at every
/// accepted point, at most `iters` Jacobians; the damping falls by 0.3
/// on a step that gains and rises tenfold on one that does not. Each
/// damping is tried with the free quantities, then (when some sit on a
/// bound) with those on a bound held; a quantity held on its bound at a
/// whole Jacobian stays held, its column not taken, until the next whole
/// one (every `refresh` Jacobians, or at once when a step fails). With
/// `accelerate` each step carries its geodesic acceleration; the search
/// ends when a step gains less than [`REL_TOL`] or its last
/// [`STALL_STEPS`] less than `stall` of the sum of squares together.
fn levenberg_marquardt(
    residuals: &(impl Fn(&[f64]) -> Vec<f64> + Sync),
    start: &[f64],
    (lo, hi): (&[f64], &[f64]),
    iters: usize,
    rules: Rules,
) -> (Vec<f64>, f64) {
    let Rules {
        accelerate,
        stall,
        refresh,
    } = rules;
    let mut p = start.to_vec();
    clamp(&mut p, lo, hi);
    let mut r = residuals(&p);
    let mut f = sse(&r);
    if f == f64::MAX {
        return (p, f);
    }
    let mut lambda = 1e-3;
    // The last steps' gains (none yet: no stall).
    let mut recent = [f64::INFINITY; STALL_STEPS];
    let mut pins = Pins::new(p.len(), refresh);
    for _ in 0..iters {
        let whole = pins.next();
        let cols = jacobian(residuals, &p, &r, (hi, &pins.held));
        let g: Vec<f64> = cols
            .iter()
            .map(|c| if c.is_empty() { 0.0 } else { dot(c, &r) })
            .collect();
        let free: Vec<usize> = free_set(&p, &g, lo, hi)
            .into_iter()
            .filter(|&i| !pins.held[i])
            .collect();
        if whole {
            pins.hold(&p, &free, (lo, hi));
        }
        if free.is_empty() {
            // Nothing to move: a whole Jacobian decides whether the
            // search has ended.
            if whole {
                break;
            }
            pins.release();
            continue;
        }
        // The free quantities, then (when some of them sit on a bound)
        // those off the bounds.
        let inside: Vec<usize> = free
            .iter()
            .copied()
            .filter(|&i| lo[i] < p[i] && p[i] < hi[i])
            .collect();
        let held = !inside.is_empty() && inside.len() < free.len();
        let mut systems = vec![Normal::new(&cols, &g, free)];
        if held {
            systems.push(Normal::new(&cols, &g, inside));
        }
        let at = At {
            p: &p,
            r: &r,
            cols: &cols,
        };
        let mut moved = None;
        'damping: for _ in 0..TRIES {
            // Every system's step leaves p where it is: nowhere to go.
            let mut stuck = true;
            for normal in &systems {
                let Some(q) = step(residuals, &at, normal, lambda, (lo, hi), accelerate) else {
                    stuck = false;
                    continue;
                };
                if q == p {
                    continue;
                }
                stuck = false;
                let rq = residuals(&q);
                let fq = sse(&rq);
                if fq < f {
                    moved = Some((q, rq, fq));
                    break 'damping;
                }
            }
            if stuck {
                break;
            }
            lambda *= 10.0;
        }
        let Some((q, rq, fq)) = moved else {
            if whole {
                break;
            }
            pins.release();
            continue;
        };
        lambda = (lambda * 0.3).max(1e-12);
        let gained = f - fq;
        recent.rotate_right(1);
        recent[0] = gained;
        (p, r, f) = (q, rq, fq);
        if gained <= REL_TOL * f {
            break;
        }
        // A search that has gained next to nothing over its last steps
        // has settled.
        if recent.iter().sum::<f64>() <= stall * f {
            break;
        }
    }
    (p, f)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sum of two decays fitted from a start far away: the time
    /// constants and amplitudes come back.
    #[test]
    fn two_decays_are_fitted_from_far_away() {
        let t: Vec<f64> = (0..200).map(|i| f64::from(i) * 5.0).collect();
        let model = |p: &[f64], t: f64| p[0] * (-t / p[1]).exp() + p[2] * (-t / p[3]).exp();
        let truth = [2.0, 40.0, 1.0, 400.0];
        let y: Vec<f64> = t.iter().map(|&t| model(&truth, t)).collect();
        let res =
            |p: &[f64]| -> Vec<f64> { t.iter().zip(&y).map(|(&t, y)| model(p, t) - y).collect() };
        let (p, f) = minimize(
            res,
            &[1.0, 10.0, 1.0, 1000.0],
            &[0.0, 1.0, 0.0, 1.0],
            &[10.0, 5000.0, 10.0, 5000.0],
            200,
        );
        assert!(f < 1e-12, "{f} at {p:?}");
        for (a, b) in p.iter().zip(truth) {
            assert!((a - b).abs() < 1e-4 * b, "{p:?}");
        }
    }

    /// Two decays fitted with a fifth quantity the residuals pull below
    /// its bound: it sits on the bound from the start, its column is
    /// taken at every fifth Jacobian only, and the search ends where the
    /// one taking every column does, in fewer evaluations.
    #[test]
    fn a_quantity_held_on_its_bound_is_not_differenced_every_step() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let evals = AtomicUsize::new(0);
        let t: Vec<f64> = (0..200).map(|i| f64::from(i) * 5.0).collect();
        let model = |p: &[f64], t: f64| p[0] * (-t / p[1]).exp() + p[2] * (-t / p[3]).exp();
        let truth = [2.0, 40.0, 1.0, 400.0];
        let y: Vec<f64> = t.iter().map(|&t| model(&truth, t)).collect();
        let res = |p: &[f64]| -> Vec<f64> {
            evals.fetch_add(1, Ordering::Relaxed);
            t.iter()
                .zip(&y)
                .map(|(&t, y)| model(p, t) - y)
                .chain([p[4] + 1.0])
                .collect()
        };
        let start = [1.0, 10.0, 1.0, 1000.0, 0.5];
        let (lo, hi) = ([0.0, 1.0, 0.0, 1.0, 0.0], [10.0, 5000.0, 10.0, 5000.0, 1.0]);
        let run = |refresh: usize| {
            evals.store(0, Ordering::Relaxed);
            let (p, f) =
                levenberg_marquardt(&res, &start, (&lo, &hi), 200, Rules { refresh, ..RULES });
            (p, f, evals.load(Ordering::Relaxed))
        };
        let (p, f, held) = run(REFRESH);
        let (p_every, f_every, every) = run(1);
        assert_eq!(p[4], 0.0, "{p:?}");
        assert!((f - 1.0).abs() < 1e-10, "{f} at {p:?}");
        for (a, b) in p.iter().zip(truth) {
            assert!((a - b).abs() < 1e-4 * b, "{p:?}");
        }
        assert!((f - f_every).abs() < 1e-12, "{f} against {f_every}");
        for (a, b) in p.iter().zip(&p_every) {
            assert!(
                (a - b).abs() < 1e-6 * b.abs().max(1.0),
                "{p:?} against {p_every:?}"
            );
        }
        assert!(
            held < every,
            "{held} evaluations against {every} with every column taken"
        );
    }

    /// Four Rosenbrock valleys side by side as residuals (10 (y - x^2),
    /// 1 - x for each pair): the minimum (1, ..., 1) at the end of long
    /// curved valleys in eight quantities. Within 100 Jacobians it ends
    /// there, and the geodesic acceleration gets there in fewer
    /// evaluations than the plain steps.
    #[test]
    fn a_long_curved_valley_is_followed_to_its_end() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let evals = AtomicUsize::new(0);
        let res = |p: &[f64]| {
            evals.fetch_add(1, Ordering::Relaxed);
            p.chunks(2)
                .flat_map(|c| [10.0 * (c[1] - c[0] * c[0]), 1.0 - c[0]])
                .collect::<Vec<f64>>()
        };
        let start = [-1.9, 3.0, -1.2, 1.0, 0.5, -2.0, -1.5, 4.0];
        let (lo, hi) = ([-5.0; 8], [5.0; 8]);
        let (p, f) = minimize(res, &start, &lo, &hi, 100);
        assert!(f < 1e-14, "{f} at {p:?}");
        assert!(p.iter().all(|v| (v - 1.0).abs() < 1e-6), "{p:?}");
        let accelerated = evals.swap(0, Ordering::Relaxed);
        let (_, f) = levenberg_marquardt(
            &res,
            &start,
            (&lo, &hi),
            100,
            Rules {
                accelerate: false,
                ..RULES
            },
        );
        assert!(f < 1e-14);
        assert!(
            accelerated < evals.load(Ordering::Relaxed),
            "{accelerated} evaluations against {} without the acceleration",
            evals.load(Ordering::Relaxed)
        );
    }

    /// A search creeping along a long, narrow, curved valley whose floor
    /// falls gently, each step gaining under a ten-millionth of a sum of
    /// squares the model cannot remove: the stall rule ends it at once,
    /// where the search without it spends its whole budget of Jacobians
    /// to gain under a tenth of a percent. That is the rule's trade,
    /// and the whole of what it costs here.
    #[test]
    fn a_search_that_stops_gaining_ends() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let evals = AtomicUsize::new(0);
        let res = |p: &[f64]| {
            evals.fetch_add(1, Ordering::Relaxed);
            vec![100.0 * (p[1] - p[0] * p[0]), 1e-3 * (p[0] - 100.0), 1.0]
        };
        let (lo, hi) = ([-200.0, -1e5], [200.0, 1e5]);
        let run = |stall: f64| {
            evals.store(0, Ordering::Relaxed);
            let (_, f) =
                levenberg_marquardt(&res, &[1.0, 1.0], (&lo, &hi), 200, Rules { stall, ..RULES });
            (f, evals.load(Ordering::Relaxed))
        };
        let (f_stall, n_stall) = run(STALL_TOL);
        let (f_whole, n_whole) = run(0.0);
        assert!(
            n_stall * 10 < n_whole,
            "{n_stall} evaluations against {n_whole} without the stall rule"
        );
        // It ends once its window of steps is full, not before: each step
        // costs a Jacobian (two evaluations here) and a trial at least.
        assert!(
            n_stall >= 3 * STALL_STEPS,
            "ended after {n_stall} evaluations"
        );
        // `minimize` is the search with the rule.
        evals.store(0, Ordering::Relaxed);
        let (_, f) = minimize(res, &[1.0, 1.0], &lo, &hi, 200);
        assert_eq!((f, evals.load(Ordering::Relaxed)), (f_stall, n_stall));
        assert!(
            f_whole <= f_stall && f_stall <= f_whole * 1.001,
            "{f_stall} against {f_whole}"
        );
    }

    /// The minimum lies on a bound at the end of a curved valley: the
    /// search ends on the bound, never past it.
    #[test]
    fn a_valley_that_ends_on_a_bound_is_followed_to_it() {
        // Rosenbrock with x held to at most 0.5: the minimum along the
        // bound is at (0.5, 0.25).
        let res = |p: &[f64]| vec![10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]];
        let (p, _) = minimize(res, &[-1.9, 3.0], &[-5.0, -5.0], &[0.5, 5.0], 200);
        assert_eq!(p[0], 0.5, "{p:?}");
        assert!((p[1] - 0.25).abs() < 1e-6, "{p:?}");
    }

    /// The unconstrained minimum lies outside the box: the fit ends on
    /// the bound, never past it, with the other quantity at its best.
    #[test]
    fn a_minimum_outside_the_box_ends_on_its_bound() {
        // Minimum at (-1, 2); the box keeps x >= 0.
        let res = |p: &[f64]| vec![p[0] + 1.0, 3.0 * (p[1] - 2.0), 0.1 * p[0] * p[1]];
        let (p, _) = minimize(res, &[3.0, 0.0], &[0.0, -5.0], &[5.0, 5.0], 100);
        assert_eq!(p[0], 0.0, "{p:?}");
        assert!((p[1] - 2.0).abs() < 1e-6, "{p:?}");
    }

    /// Residuals that turn non-finite away from the start leave the
    /// start's point, not a NaN.
    #[test]
    fn non_finite_residuals_are_a_worse_point() {
        let res = |p: &[f64]| vec![if p[0] > 1.0 { f64::NAN } else { p[0] - 2.0 }];
        let (p, f) = minimize(res, &[0.0], &[-10.0], &[10.0], 50);
        assert!(p[0] <= 1.0 && f.is_finite(), "{p:?} {f}");
    }

    /// A model linear in its parameters (a line) through noisy points:
    /// the minimum is the normal equations' solution, which the search
    /// must reach to rounding, noise or not.
    #[test]
    fn a_linear_model_ends_at_the_normal_equations_solution() {
        let t: Vec<f64> = (0..50).map(f64::from).collect();
        // A fixed, irregular "noise" of about 0.3.
        let y: Vec<f64> = t
            .iter()
            .map(|&t| 1.5 - 0.2 * t + 0.3 * (t * 1.7).sin())
            .collect();
        let n = t.len() as f64;
        let (st, sy) = (t.iter().sum::<f64>(), y.iter().sum::<f64>());
        let stt = t.iter().map(|t| t * t).sum::<f64>();
        let sty = t.iter().zip(&y).map(|(t, y)| t * y).sum::<f64>();
        let slope = (n * sty - st * sy) / (n * stt - st * st);
        let intercept = (sy - slope * st) / n;
        let res = |p: &[f64]| -> Vec<f64> {
            t.iter()
                .zip(&y)
                .map(|(&t, y)| p[0] + p[1] * t - y)
                .collect()
        };
        let (p, f) = minimize(res, &[0.0, 0.0], &[-10.0, -10.0], &[10.0, 10.0], 50);
        assert!((p[0] - intercept).abs() < 1e-6, "{p:?} against {intercept}");
        assert!((p[1] - slope).abs() < 1e-7, "{p:?} against {slope}");
        let best: f64 = res(&[intercept, slope]).iter().map(|r| r * r).sum();
        assert!(f <= best * (1.0 + 1e-9), "{f} against {best}");
    }

    /// An exponential decay under mild noise (1 % of its size): amplitude
    /// and time constant within a few percent, the sum of squares that of
    /// the noise.
    #[test]
    fn a_decay_under_mild_noise_is_recovered() {
        let t: Vec<f64> = (0..300).map(|i| f64::from(i) * 10.0).collect();
        // Deterministic noise of RMS about 0.01 (a sum of incommensurate
        // sines).
        let noise = |i: usize| 0.01 * ((i as f64 * 2.39).sin() + (i as f64 * 0.71).cos());
        let y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(i, &t)| 1.0 + 3.0 * (-t / 600.0).exp() + noise(i))
            .collect();
        let res = |p: &[f64]| -> Vec<f64> {
            t.iter()
                .zip(&y)
                .map(|(&t, y)| p[0] + p[1] * (-t / p[2]).exp() - y)
                .collect()
        };
        let (p, f) = minimize(
            res,
            &[0.0, 1.0, 100.0],
            &[-10.0, 0.0, 10.0],
            &[10.0, 10.0, 1e5],
            200,
        );
        assert!((p[0] - 1.0).abs() < 0.01, "{p:?}");
        assert!((p[1] - 3.0).abs() < 0.03, "{p:?}");
        assert!((p[2] / 600.0 - 1.0).abs() < 0.02, "{p:?}");
        let noise_sse: f64 = (0..t.len()).map(|i| noise(i).powi(2)).sum();
        assert!(f <= noise_sse, "{f} against the noise's {noise_sse}");
    }

    /// Rosenbrock's valley as residuals, from its classic start: the
    /// damping must turn the Gauss-Newton steps along the curved valley.
    #[test]
    fn rosenbrocks_valley_is_followed_to_its_minimum() {
        let res = |p: &[f64]| vec![10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]];
        let (p, f) = minimize(res, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], 200);
        assert!(f < 1e-16, "{f} at {p:?}");
        assert!(
            (p[0] - 1.0).abs() < 1e-7 && (p[1] - 1.0).abs() < 1e-7,
            "{p:?}"
        );
    }

    /// Every quantity's optimum outside the box, on either side: each ends
    /// on its bound; a start outside the box is taken into it first.
    #[test]
    fn optima_past_either_bound_end_on_the_bounds() {
        let res = |p: &[f64]| vec![p[0] - 7.0, p[1] + 7.0, 0.5 * (p[0] - p[1])];
        let (lo, hi) = ([-1.0, -2.0], [3.0, 4.0]);
        for start in [[0.0, 0.0], [100.0, -100.0], [-50.0, 50.0]] {
            let (p, _) = minimize(res, &start, &lo, &hi, 100);
            assert_eq!(p, [3.0, -2.0], "from {start:?}");
        }
        // No iterations: the start, clamped, and its sum of squares.
        let (p, f) = minimize(res, &[100.0, 0.0], &lo, &hi, 0);
        assert_eq!(p, [3.0, 0.0]);
        assert_eq!(f, 16.0 + 49.0 + 2.25);
    }

    /// A problem at its minimum stays there (no step lowers the sum).
    #[test]
    fn a_start_at_the_minimum_stays_there() {
        let res = |p: &[f64]| vec![p[0] - 2.0, 3.0 * (p[1] + 1.0), (p[0] - 2.0) * p[1]];
        let (p, f) = minimize(res, &[2.0, -1.0], &[-10.0, -10.0], &[10.0, 10.0], 100);
        assert_eq!(p, [2.0, -1.0]);
        assert_eq!(f, 0.0);
        // Nor does a noisy minimum move: the line's solution from the
        // solution itself.
        let res = |p: &[f64]| vec![p[0] - 1.0, p[0] - 3.0, p[1]];
        let (p, f) = minimize(res, &[2.0, 0.0], &[-10.0, -10.0], &[10.0, 10.0], 100);
        assert_eq!((p, f), (vec![2.0, 0.0], 2.0));
    }

    /// Residuals that see only the sum of two quantities: a direction of
    /// no information. The search ends at a point of the minimum's line,
    /// finite and near its start (the damping keeps the free direction
    /// from running off).
    #[test]
    fn a_rank_deficient_direction_does_not_blow_up() {
        let res = |p: &[f64]| vec![p[0] + p[1] - 3.0, 2.0 * (p[0] + p[1] - 3.0)];
        let (p, f) = minimize(res, &[0.5, 0.5], &[-1e6, -1e6], &[1e6, 1e6], 100);
        assert!(p.iter().all(|v| v.is_finite() && v.abs() < 10.0), "{p:?}");
        assert!(f < 1e-16 && (p[0] + p[1] - 3.0).abs() < 1e-8, "{f} {p:?}");
    }

    /// The Jacobian steps into the box: at the upper bound a quantity is
    /// differenced backwards, never past the bound (where these
    /// residuals are not defined), and still moves inward.
    #[test]
    fn the_jacobian_never_looks_past_the_upper_bound() {
        let res = |p: &[f64]| {
            assert!(p[0] <= 2.0, "evaluated past the bound at {p:?}");
            vec![p[0] - 0.5]
        };
        let (p, f) = minimize(res, &[2.0], &[0.0], &[2.0], 50);
        assert!((p[0] - 0.5).abs() < 1e-8 && f < 1e-16, "{p:?}");
    }
}
