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
}
