//! Nonlinear least squares within box bounds: Levenberg-Marquardt with
//! projected steps, its Jacobian by forward differences and, once the
//! search turns out long, kept up to date by secant (Broyden) updates. The
//! thermal layer's searches end with it (a Nelder-Mead simplex finds the
//! basin, this settles in it): on the network's residuals it reaches in a
//! few hundred evaluations the optimum the simplex crawled to in
//! thousands.
//!
//! Written here rather than taken from a crate: the network's quantities
//! have physical bounds the fit must never leave (a time constant, a
//! rise, a capacity ratio of zero), and the Levenberg-Marquardt crates
//! for nalgebra take no bounds (and `levenberg-marquardt` pins an older
//! nalgebra than ours).

use nalgebra::{DMatrix, DVector};

/// Relative step of the forward differences (ours: the square root of
/// f64's epsilon, scaled by the quantity; the residuals are smooth).
const FD_STEP: f64 = 1.5e-8;
/// A step that lowers the sum of squares by less than this fraction ends
/// the search.
const REL_TOL: f64 = 1e-10;
/// Iterations with a whole forward-difference Jacobian at every point
/// before the secant updates take over (ours: the study's runs settle in
/// 4 to 40, most under 20, so a search that converges this soon is the
/// plain Levenberg-Marquardt's, number for number).
const FD_ITERS: usize = 20;
/// Accepted secant steps over which the sum of squares must fall by more
/// than [`STALL_TOL`] of itself, or the Jacobian is taken afresh (and the
/// search ends when a fresh one gains no more): ours.
const STALL_STEPS: usize = 10;
const STALL_TOL: f64 = 1e-6;
/// Failed steps in a row (the damping doubled each time) after which a
/// secant Jacobian is taken afresh by forward differences (ours).
const REFRESH_AFTER_FAILS: u32 = 5;

/// The minimum of `sum(residuals(p)^2)` over `lo <= p <= hi` from `start`
/// (clamped into the box), with at most the evaluations `iters`
/// forward-difference Jacobians take (`iters * (n + 1)`): the point and
/// its sum of squares. A quantity on a bound whose gradient points out of
/// the box is held there for the step; the others move by the damped
/// Gauss-Newton step, clamped into the box. Non-finite residuals count
/// as a worse point.
///
/// The first [`FD_ITERS`] iterations take a forward-difference Jacobian
/// at every point ([`plain`]). A search still going after them is in a
/// long curved valley (a network pressed against a bound by a unit its
/// form does not hold crawled there for 100 iterations of 12
/// evaluations each); it goes on with the secant version of
/// Levenberg-Marquardt ([`secant`]), one or two evaluations an iteration.
pub fn minimize(
    residuals: impl Fn(&[f64]) -> Vec<f64>,
    start: &[f64],
    lo: &[f64],
    hi: &[f64],
    iters: usize,
) -> (Vec<f64>, f64) {
    let evals = std::cell::Cell::new(0usize);
    let counted = |p: &[f64]| {
        evals.set(evals.get() + 1);
        residuals(p)
    };
    let first = plain(&counted, start, lo, hi, FD_ITERS.min(iters));
    if first.converged || iters <= FD_ITERS {
        return (first.p, first.f);
    }
    let budget = (iters * (start.len() + 1)).saturating_sub(evals.get());
    secant(&counted, &first.p, lo, hi, budget)
}

/// Where a search ended.
struct Ended {
    p: Vec<f64>,
    f: f64,
    /// It stopped on its own (no step gained), not at its iteration cap.
    converged: bool,
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

/// One forward-difference column of the Jacobian at `p` (residuals `r`),
/// stepping into the box.
fn column(
    residuals: &impl Fn(&[f64]) -> Vec<f64>,
    p: &[f64],
    r: &[f64],
    i: usize,
    hi: &[f64],
) -> Vec<f64> {
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
}

/// The whole forward-difference Jacobian, by columns.
fn jacobian(
    residuals: &impl Fn(&[f64]) -> Vec<f64>,
    p: &[f64],
    r: &[f64],
    hi: &[f64],
) -> Vec<Vec<f64>> {
    (0..p.len())
        .map(|i| column(residuals, p, r, i, hi))
        .collect()
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

/// The normal matrix of the free columns, the negative gradient on them,
/// and the largest diagonal element (for a floor on the damping).
fn normal(cols: &[Vec<f64>], g: &[f64], free: &[usize]) -> (DMatrix<f64>, DVector<f64>, f64) {
    let k = free.len();
    let h = DMatrix::from_fn(k, k, |a, b| dot(&cols[free[a]], &cols[free[b]]));
    let rhs = DVector::from_fn(k, |a, _| -g[free[a]]);
    let scale = (0..k).map(|a| h[(a, a)]).fold(0.0, f64::max).max(1e-300);
    (h, rhs, scale)
}

/// The damped step `(H + lambda diag H) s = rhs` taken from `p` on the
/// free quantities and clamped into the box; none when the damped matrix
/// is not positive definite.
fn damped_step(
    p: &[f64],
    free: &[usize],
    normal: &(DMatrix<f64>, DVector<f64>, f64),
    lambda: f64,
    lo: &[f64],
    hi: &[f64],
) -> Option<Vec<f64>> {
    let (h, rhs, scale) = normal;
    let mut a = h.clone();
    for d in 0..free.len() {
        a[(d, d)] += lambda * (h[(d, d)] + 1e-12 * scale);
    }
    let step = a.cholesky()?.solve(rhs);
    let mut q = p.to_vec();
    for (a, &i) in free.iter().enumerate() {
        q[i] += step[a];
    }
    clamp(&mut q, lo, hi);
    Some(q)
}

/// Levenberg-Marquardt with a forward-difference Jacobian at every
/// accepted point, at most `iters` Jacobians.
fn plain(
    residuals: &impl Fn(&[f64]) -> Vec<f64>,
    start: &[f64],
    lo: &[f64],
    hi: &[f64],
    iters: usize,
) -> Ended {
    let mut p = start.to_vec();
    clamp(&mut p, lo, hi);
    let mut r = residuals(&p);
    let mut f = sse(&r);
    let stop = |p, f| Ended {
        p,
        f,
        converged: true,
    };
    if f == f64::MAX {
        return stop(p, f);
    }
    let mut lambda = 1e-3;
    for _ in 0..iters {
        let cols = jacobian(residuals, &p, &r, hi);
        let g: Vec<f64> = cols.iter().map(|c| dot(c, &r)).collect();
        let free = free_set(&p, &g, lo, hi);
        if free.is_empty() {
            return stop(p, f);
        }
        let normal = normal(&cols, &g, &free);
        let mut moved = None;
        for _ in 0..12 {
            let Some(q) = damped_step(&p, &free, &normal, lambda, lo, hi) else {
                lambda *= 10.0;
                continue;
            };
            if q == p {
                break;
            }
            let rq = residuals(&q);
            let fq = sse(&rq);
            if fq < f {
                moved = Some((q, rq, fq));
                lambda = (lambda * 0.3).max(1e-12);
                break;
            }
            lambda *= 10.0;
        }
        let Some((q, rq, fq)) = moved else {
            return stop(p, f);
        };
        let gained = f - fq;
        (p, r, f) = (q, rq, fq);
        if gained <= REL_TOL * f {
            return stop(p, f);
        }
    }
    Ended {
        p,
        f,
        converged: false,
    }
}

/// The secant version of Levenberg-Marquardt (Madsen, Nielsen and
/// Tingleff, "Methods for non-linear least squares problems", 2004,
/// sec. 3.4) within the box, from `start`, at most `budget` evaluations:
/// the Jacobian starts by forward differences and is then updated along
/// every step tried (Broyden's rank-one update), one coordinate a
/// iteration taken afresh by a forward difference when the step hardly
/// moved along it (so the Jacobian stays honest in every direction); the
/// damping follows the gain ratio (Nielsen's rule). A stall (the sum of
/// squares falling by less than [`STALL_TOL`] over [`STALL_STEPS`]
/// steps), a step that gains nothing or repeated failures take the
/// Jacobian afresh; the search ends when a fresh one gains nothing more.
fn secant(
    residuals: &impl Fn(&[f64]) -> Vec<f64>,
    start: &[f64],
    lo: &[f64],
    hi: &[f64],
    budget: usize,
) -> (Vec<f64>, f64) {
    let evals = std::cell::Cell::new(0usize);
    let residuals = |p: &[f64]| {
        evals.set(evals.get() + 1);
        residuals(p)
    };
    let n = start.len();
    let mut p = start.to_vec();
    clamp(&mut p, lo, hi);
    let mut r = residuals(&p);
    let mut f = sse(&r);
    if f == f64::MAX {
        return (p, f);
    }
    let mut cols = jacobian(&residuals, &p, &r, hi);
    let mut fresh = true;
    let (mut lambda, mut nu, mut fails) = (1e-3, 2.0, 0u32);
    let mut coord = 0;
    let mut history = std::collections::VecDeque::with_capacity(STALL_STEPS);
    while evals.get() < budget {
        let g: Vec<f64> = cols.iter().map(|c| dot(c, &r)).collect();
        let free = free_set(&p, &g, lo, hi);
        let normal = normal(&cols, &g, &free);
        let step = if free.is_empty() {
            None
        } else {
            damped_step(&p, &free, &normal, lambda, lo, hi)
        };
        let q = match step {
            Some(q) if q != p => q,
            // A damped matrix that is not positive definite: more damping.
            None if !free.is_empty() && fails < REFRESH_AFTER_FAILS => {
                (lambda, nu, fails) = (lambda * nu, nu * 2.0, fails + 1);
                continue;
            }
            // Nothing to move, or no step: with a fresh Jacobian that is
            // the end; a stale one is taken afresh first.
            _ if fresh => break,
            _ => {
                cols = jacobian(&residuals, &p, &r, hi);
                (fresh, fails) = (true, 0);
                continue;
            }
        };
        let s: Vec<f64> = q.iter().zip(&p).map(|(a, b)| a - b).collect();
        coord = (coord + 1) % n;
        if s[coord].abs() < 0.8 * dot(&s, &s).sqrt() {
            cols[coord] = column(&residuals, &p, &r, coord, hi);
        }
        let rq = residuals(&q);
        let fq = sse(&rq);
        if fq < f64::MAX {
            broyden(&mut cols, &s, &r, &rq);
            fresh = false;
        }
        if fq < f {
            let sf: Vec<f64> = free.iter().map(|&i| s[i]).collect();
            let gf: Vec<f64> = free.iter().map(|&i| g[i]).collect();
            let hs = &normal.0 * DVector::from_column_slice(&sf);
            let predicted = -2.0 * dot(&gf, &sf) - dot(&sf, hs.as_slice());
            let rho = if predicted > 0.0 {
                (f - fq) / predicted
            } else {
                1.0
            };
            lambda = (lambda * (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3))).max(1e-12);
            (nu, fails) = (2.0, 0);
            if history.len() == STALL_STEPS {
                history.pop_front();
            }
            history.push_back(fq);
            let stalled = history.len() == STALL_STEPS && history[0] - fq <= STALL_TOL * fq;
            let gained = f - fq;
            (p, r, f) = (q, rq, fq);
            if gained <= REL_TOL * f || stalled {
                if fresh {
                    break;
                }
                cols = jacobian(&residuals, &p, &r, hi);
                fresh = true;
                history.clear();
            }
        } else {
            (lambda, nu, fails) = (lambda * nu, nu * 2.0, fails + 1);
            if fails >= REFRESH_AFTER_FAILS {
                if fresh {
                    break;
                }
                cols = jacobian(&residuals, &p, &r, hi);
                (fresh, fails, nu) = (true, 0, 2.0);
            }
        }
    }
    (p, f)
}

/// Broyden's rank-one update of the Jacobian (by columns) along the step
/// `s` that took the residuals from `r` to `rq`.
fn broyden(cols: &mut [Vec<f64>], s: &[f64], r: &[f64], rq: &[f64]) {
    let ss = dot(s, s);
    if ss <= 0.0 {
        return;
    }
    let u: Vec<f64> = (0..r.len())
        .map(|j| {
            let js: f64 = cols.iter().zip(s).map(|(c, si)| c[j] * si).sum();
            (rq[j] - r[j] - js) / ss
        })
        .collect();
    for (c, &si) in cols.iter_mut().zip(s) {
        if si != 0.0 {
            for (cj, uj) in c.iter_mut().zip(&u) {
                *cj += uj * si;
            }
        }
    }
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

    /// Four Rosenbrock valleys side by side as residuals (10 (y - x^2),
    /// 1 - x for each pair): the minimum (1, ..., 1) at the end of long
    /// curved valleys in eight quantities, the kind of search the secant
    /// updates take over. Within the budget of 100 forward-difference
    /// Jacobians it ends there, in fewer evaluations than forward
    /// differences alone take.
    #[test]
    fn a_long_curved_valley_is_followed_to_its_end_with_secant_updates() {
        let evals = std::cell::Cell::new(0usize);
        let res = |p: &[f64]| {
            evals.set(evals.get() + 1);
            p.chunks(2)
                .flat_map(|c| [10.0 * (c[1] - c[0] * c[0]), 1.0 - c[0]])
                .collect::<Vec<f64>>()
        };
        let start = [-1.9, 3.0, -1.2, 1.0, 0.5, -2.0, -1.5, 4.0];
        let (lo, hi) = ([-5.0; 8], [5.0; 8]);
        // The valleys outlast the forward-difference phase.
        assert!(!plain(&res, &start, &lo, &hi, FD_ITERS).converged);
        evals.set(0);
        let (p, f) = minimize(res, &start, &lo, &hi, 100);
        assert!(f < 1e-14, "{f} at {p:?}");
        assert!(p.iter().all(|v| (v - 1.0).abs() < 1e-6), "{p:?}");
        let with_secant = evals.replace(0);
        let fd = plain(&res, &start, &lo, &hi, 100);
        assert!(fd.f < 1e-14);
        assert!(
            with_secant < evals.get(),
            "{with_secant} evaluations against {} with forward differences alone",
            evals.get()
        );
    }

    /// The minimum lies on a bound and is reached by the secant phase
    /// (the search is still going after [`FD_ITERS`]): it ends on the
    /// bound, never past it.
    #[test]
    fn the_secant_phase_keeps_to_the_box() {
        // Rosenbrock with x held to at most 0.5: the minimum along the
        // bound is at (0.5, 0.25).
        let res = |p: &[f64]| vec![10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]];
        let (p, _) = secant(&res, &[-1.9, 3.0], &[-5.0, -5.0], &[0.5, 5.0], 10_000);
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
