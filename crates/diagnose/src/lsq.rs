//! Nonlinear least squares within box bounds: Levenberg-Marquardt with a
//! forward-difference Jacobian and projected steps. The thermal layer's
//! searches end with it (a Nelder-Mead simplex finds the basin, this
//! settles in it): on the network's residuals it reaches in a few hundred
//! evaluations the optimum the simplex crawled to in thousands.
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

/// The minimum of `sum(residuals(p)^2)` over `lo <= p <= hi` from `start`
/// (clamped into the box), at most `iters` Jacobians: the point and its
/// sum of squares. A quantity on a bound whose gradient points out of
/// the box is held there for the step; the others move by the damped
/// Gauss-Newton step, clamped into the box. Non-finite residuals count
/// as a worse point.
pub fn minimize(
    residuals: impl Fn(&[f64]) -> Vec<f64>,
    start: &[f64],
    lo: &[f64],
    hi: &[f64],
    iters: usize,
) -> (Vec<f64>, f64) {
    let n = start.len();
    let clamp = |p: &mut [f64]| {
        for (i, v) in p.iter_mut().enumerate() {
            *v = v.clamp(lo[i], hi[i]);
        }
    };
    let sse = |r: &[f64]| {
        let s: f64 = r.iter().map(|x| x * x).sum();
        if s.is_finite() { s } else { f64::MAX }
    };
    let mut p = start.to_vec();
    clamp(&mut p);
    let mut r = residuals(&p);
    let mut f = sse(&r);
    if f == f64::MAX {
        return (p, f);
    }
    let mut lambda = 1e-3;
    for _ in 0..iters {
        // The Jacobian's columns, stepping into the box.
        let cols: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let mut h = FD_STEP * p[i].abs().max(1.0);
                if p[i] + h > hi[i] {
                    h = -h;
                }
                let mut q = p.clone();
                q[i] += h;
                residuals(&q)
                    .iter()
                    .zip(&r)
                    .map(|(a, b)| (a - b) / h)
                    .collect()
            })
            .collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let g: Vec<f64> = cols.iter().map(|c| dot(c, &r)).collect();
        let free: Vec<usize> = (0..n)
            .filter(|&i| {
                g[i].is_finite() && !(p[i] <= lo[i] && g[i] > 0.0) && !(p[i] >= hi[i] && g[i] < 0.0)
            })
            .collect();
        if free.is_empty() {
            break;
        }
        let k = free.len();
        let h = DMatrix::from_fn(k, k, |a, b| dot(&cols[free[a]], &cols[free[b]]));
        let rhs = DVector::from_fn(k, |a, _| -g[free[a]]);
        let scale = (0..k).map(|a| h[(a, a)]).fold(0.0, f64::max).max(1e-300);
        let mut moved = None;
        for _ in 0..12 {
            let mut a = h.clone();
            for d in 0..k {
                a[(d, d)] += lambda * (h[(d, d)] + 1e-12 * scale);
            }
            let Some(step) = a.cholesky().map(|c| c.solve(&rhs)) else {
                lambda *= 10.0;
                continue;
            };
            let mut q = p.clone();
            for (a, &i) in free.iter().enumerate() {
                q[i] += step[a];
            }
            clamp(&mut q);
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
            break;
        };
        let gained = f - fq;
        (p, r, f) = (q, rq, fq);
        if gained <= REL_TOL * f {
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
