//! Overlapping Allan deviation of a rate series, its confidence intervals
//! and the noise terms it implies (`docs/physics.md`, "Allan deviation").
//!
//! - Each tau costs O(N): the second difference of the cumulative angle
//!   `theta_{k+2m} - 2 theta_{k+m} + theta_k`, summed in one pass; taus
//!   are spread over the available cores.
//! - Confidence intervals: chi-squared with the equivalent degrees of
//!   freedom of Greenhall & Riley (2004, "Uncertainty of stability variances
//!   based on finite differences", eqs. 7-13 and tables 1-3; NIST SP1065
//!   eq. 45), for the noise type found at each tau by the lag-1
//!   autocorrelation method (Riley & Greenhall 2004).
//! - Noise terms: a weighted least-squares fit of
//!   `AVAR = 3 Q^2/tau^2 + (60 N)^2/tau + (2 ln2/pi) B^2 + K^2 tau/(3 * 3600)`
//!   (Q arcsec, N deg/sqrt(h), B deg/h, K deg/h/sqrt(h), tau s), weights from
//!   the EDF (the variance of an AVAR estimate is 2 AVAR^2/EDF), all terms
//!   kept non-negative.

use serde::Serialize;
use statrs::distribution::ContinuousCDF;

/// One-sigma confidence level.
pub const ONE_SIGMA: f64 = 0.682_689_492_137_085_9;

/// IEEE Std 952 Annex C: the flicker floor of the ADEV is
/// sqrt(2 ln 2 / pi) B = 0.664 B.
pub fn floor_per_b() -> f64 {
    (2.0 * std::f64::consts::LN_2 / std::f64::consts::PI).sqrt()
}

/// Which averaging times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Taus {
    /// 1, 2, 4, ... samples.
    Octave,
    /// Ten per decade, log-spaced (distinct whole numbers of samples).
    Dense,
}

/// Averaging factors for `n` rate samples, up to a third of the series
/// (beyond, fewer than ~3 independent differences remain).
pub fn factors(n: usize, taus: Taus) -> Vec<usize> {
    let max = n / 3;
    let mut out: Vec<usize> = match taus {
        Taus::Octave => std::iter::successors(Some(1usize), |m| m.checked_mul(2))
            .take_while(|m| *m <= max)
            .collect(),
        Taus::Dense => (0..)
            .map(|k| 10f64.powf(f64::from(k) / 10.0).round() as usize)
            .take_while(|m| *m <= max)
            .collect(),
    };
    out.dedup();
    out
}

/// Octave averaging factors 1, 2, 4, ... up to a third of the series.
pub fn octave_factors(n: usize) -> Vec<usize> {
    factors(n, Taus::Octave)
}

/// Cumulative angle of `rate` (mean removed: the ADEV does not see a
/// constant, and a small angle keeps the second differences exact).
fn cumulative_angle(rate: &[f64], tau0_s: f64) -> Vec<f64> {
    let mean = rate.iter().sum::<f64>() / rate.len().max(1) as f64;
    let mut theta = Vec::with_capacity(rate.len() + 1);
    theta.push(0.0);
    let mut acc = 0.0;
    for r in rate {
        acc += (r - mean) * tau0_s;
        theta.push(acc);
    }
    theta
}

/// Sum of squared second differences `theta[k+2m] - 2 theta[k+m] + theta[k]`
/// for k in `lo..hi` (clipped to the terms that exist).
fn second_difference_sum(theta: &[f64], m: usize, lo: usize, hi: usize) -> f64 {
    let terms = theta.len().saturating_sub(2 * m);
    let hi = hi.min(terms);
    if m == 0 || lo >= hi {
        return 0.0;
    }
    let len = hi - lo;
    let a = &theta[lo..hi];
    let b = &theta[lo + m..lo + m + len];
    let c = &theta[lo + 2 * m..lo + 2 * m + len];
    // Eight independent lanes over exact chunks: no bounds checks, and
    // the compiler vectorises the loop.
    let mut acc = [0.0f64; 8];
    let (ac, bc, cc) = (a.chunks_exact(8), b.chunks_exact(8), c.chunks_exact(8));
    let tail = ac.remainder().len();
    for ((x, y), z) in ac.zip(bc).zip(cc) {
        for l in 0..8 {
            let d = z[l] - 2.0 * y[l] + x[l];
            acc[l] += d * d;
        }
    }
    let mut sum = acc.iter().sum::<f64>();
    for k in len - tail..len {
        let d = c[k] - 2.0 * b[k] + a[k];
        sum += d * d;
    }
    sum
}

/// Indices per cache block (ours: 8192 f64 = 64 KiB, so the block and its
/// neighbours stay in L2 while every tau takes its turn on it).
const BLOCK: usize = 8192;

/// Sums for every factor over k in `lo..hi`, block by block: all taus use
/// a block while it is in cache, so short taus cost one pass over memory
/// between them instead of one each.
fn blocked_sums(theta: &[f64], ms: &[usize], lo: usize, hi: usize) -> Vec<f64> {
    let mut sums = vec![0.0; ms.len()];
    let mut k = lo;
    while k < hi {
        let end = (k + BLOCK).min(hi);
        for (s, &m) in sums.iter_mut().zip(ms) {
            *s += second_difference_sum(theta, m, k, end);
        }
        k = end;
    }
    sums
}

/// Overlapping Allan deviation of a rate series sampled every `tau0_s`,
/// at each averaging factor `m` (tau = m tau0), in the rate's unit.
pub fn oadev(rate: &[f64], tau0_s: f64, factors: &[usize]) -> Vec<(f64, f64)> {
    let theta = cumulative_angle(rate, tau0_s);
    let n = theta.len();
    let ms: Vec<usize> = factors
        .iter()
        .copied()
        .filter(|&m| m > 0 && n > 2 * m)
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, usize::from);
    let sums = if threads < 2 || n < 100_000 {
        blocked_sums(&theta, &ms, 0, n)
    } else {
        // Contiguous ranges of k, one per core, each streaming its part.
        let per = n.div_ceil(threads);
        let mut total = vec![0.0; ms.len()];
        std::thread::scope(|s| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    let (theta, ms) = (&theta, &ms);
                    s.spawn(move || blocked_sums(theta, ms, t * per, ((t + 1) * per).min(n)))
                })
                .collect();
            for (t, h) in handles.into_iter().enumerate() {
                // A worker cannot panic on these bounds; if one did, redo its part here.
                let part = h
                    .join()
                    .unwrap_or_else(|_| blocked_sums(&theta, &ms, t * per, ((t + 1) * per).min(n)));
                for (acc, p) in total.iter_mut().zip(part) {
                    *acc += p;
                }
            }
        });
        total
    };
    ms.iter()
        .zip(sums)
        .map(|(&m, sum)| {
            let terms = n - 2 * m;
            let tau = m as f64 * tau0_s;
            (tau, (sum / (2.0 * tau * tau * terms as f64)).sqrt())
        })
        .collect()
}

/// Lag-1 autocorrelation (Riley & Greenhall 2004, eq. 2).
fn lag1_acf(x: &[f64]) -> f64 {
    let mu = x.iter().sum::<f64>() / x.len() as f64;
    let num: f64 = x.windows(2).map(|w| (w[0] - mu) * (w[1] - mu)).sum();
    let den: f64 = x.iter().map(|v| (v - mu).powi(2)).sum();
    num / den
}

/// Remove the least-squares line.
fn detrend_linear(x: &mut [f64]) {
    let n = x.len() as f64;
    let mt = (n - 1.0) / 2.0;
    let mx = x.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, v) in x.iter().enumerate() {
        let t = i as f64 - mt;
        sxy += t * (v - mx);
        sxx += t * t;
    }
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    for (i, v) in x.iter_mut().enumerate() {
        *v -= mx + slope * (i as f64 - mt);
    }
}

/// Power-law noise exponent alpha of the fractional-frequency (rate)
/// spectrum at averaging factor `m`, by the lag-1 autocorrelation of the
/// `m`-sample means: 2 white PM (quantization), 0 white FM (ARW), -1
/// flicker FM (bias instability), -2 random-walk FM (RRW), below -2
/// steeper still (a drift). `None` with fewer than 30 means (too few to
/// tell).
pub fn noise_alpha(rate: &[f64], m: usize) -> Option<i32> {
    let m = m.max(1);
    let mut x: Vec<f64> = rate
        .chunks_exact(m)
        .map(|c| c.iter().sum::<f64>() / m as f64)
        .collect();
    if x.len() < 30 {
        return None;
    }
    detrend_linear(&mut x);
    let dmax = 2;
    let mut d = 0;
    loop {
        let r1 = lag1_acf(&x);
        let rho = r1 / (1.0 + r1);
        if !rho.is_finite() {
            return None;
        }
        if rho < 0.25 || d >= dmax {
            let alpha = -(2.0 * rho).round_ties_even() - 2.0 * f64::from(d);
            return Some(alpha.clamp(-4.0, 2.0) as i32);
        }
        x = x.windows(2).map(|w| w[1] - w[0]).collect();
        d += 1;
    }
}

fn sw(t: f64, alpha: i32) -> f64 {
    let ln = |t: f64| if t == 0.0 { 0.0 } else { t.abs().ln() };
    match alpha {
        2 => -t.abs(),
        1 => t * t * ln(t),
        0 => t.abs().powi(3),
        -1 => t.powi(4) * ln(t),
        -2 => t.abs().powi(5),
        -3 => t.powi(6) * ln(t),
        _ => t.abs().powi(7),
    }
}

/// Eq. 8; `f = None` is F = infinity.
fn sx(t: f64, f: Option<f64>, alpha: i32) -> f64 {
    match f {
        None => sw(t, alpha + 2),
        Some(f) => f * f * (2.0 * sw(t, alpha) - sw(t - 1.0 / f, alpha) - sw(t + 1.0 / f, alpha)),
    }
}

/// Eq. 9 for d = 2 (the Allan variance).
fn sz(t: f64, f: Option<f64>, alpha: i32) -> f64 {
    6.0 * sx(t, f, alpha) - 4.0 * sx(t - 1.0, f, alpha) - 4.0 * sx(t + 1.0, f, alpha)
        + sx(t - 2.0, f, alpha)
        + sx(t + 2.0, f, alpha)
}

/// Eq. 10.
fn basic_sum(j: f64, big_m: f64, s: f64, f: Option<f64>, alpha: i32) -> f64 {
    let mut sum = sz(0.0, f, alpha).powi(2) + (1.0 - j / big_m) * sz(j / s, f, alpha).powi(2);
    let mut k = 1.0;
    while k < j {
        sum += 2.0 * (1.0 - k / big_m) * sz(k / s, f, alpha).powi(2);
        k += 1.0;
    }
    sum
}

/// Equivalent degrees of freedom of the overlapping ADEV at factor `m`
/// over `n_phase` angle samples (rate samples + 1) for noise `alpha`
/// (Greenhall & Riley 2004, unmodified overlapped estimator, d = 2).
pub fn edf_oadev(alpha: i32, m: usize, n_phase: usize) -> f64 {
    const D: f64 = 2.0;
    const J_MAX: f64 = 100.0;
    let alpha = alpha.clamp(-2, 2);
    let mf = m as f64;
    let (f, s) = (mf, mf);
    let l = mf / f + mf * D;
    let big_m = 1.0 + (s * (n_phase as f64 - l) / mf).floor();
    if big_m < 1.0 {
        return 1.0;
    }
    let j = big_m.min((D + 1.0) * s);
    let r = big_m / s;
    let inv = match alpha {
        2 => {
            // Case 4: binom(8,4)/binom(4,2)^2 = 70/36, a1 = d/2.
            (1.0 / big_m) * (70.0 / 36.0 - (D / 2.0) / r)
        }
        1 => {
            let (b0, b1) = (15.23, 12.0);
            if j <= J_MAX {
                basic_sum(j, big_m, s, Some(mf), 1) / (sz(0.0, Some(mf), 1).powi(2) * big_m)
            } else if r > D + 1.0 {
                let (a0, a1) = (790.0, 410.0);
                (a0 - a1 / r) / ((b0 + b1 * mf.ln()).powi(2) * r)
            } else {
                let mp = J_MAX / r;
                basic_sum(J_MAX, J_MAX, mp, Some(mp), 1) / ((b0 + b1 * mf.ln()).powi(2) * J_MAX)
            }
        }
        _ => {
            let (a0, a1) = match alpha {
                0 => (2.0 / 3.0, 1.0 / 3.0),
                -1 => (0.852, 0.375),
                _ => (1.079, 0.368),
            };
            if j <= J_MAX {
                let fp = (mf * (D + 1.0) <= J_MAX).then_some(mf);
                basic_sum(j, big_m, s, fp, alpha) / (sz(0.0, fp, alpha).powi(2) * big_m)
            } else if r > D + 1.0 {
                (a0 - a1 / r) / r
            } else {
                let mp = J_MAX / r;
                basic_sum(J_MAX, J_MAX, mp, None, alpha) / (sz(0.0, None, alpha).powi(2) * J_MAX)
            }
        }
    };
    let edf = 1.0 / inv;
    if edf.is_finite() && edf > 0.0 {
        edf
    } else {
        1.0
    }
}

/// Quantile of the chi-squared distribution with `k` degrees of freedom:
/// Wilson-Hilferty to start, then Newton on the regularized lower gamma
/// function (statrs' incomplete gamma is accurate where its quantile
/// search is not, at the tens of thousands of degrees of freedom long
/// gyro runs give).
pub fn chi2_quantile(p: f64, k: f64) -> f64 {
    use statrs::distribution::Normal;
    use statrs::function::gamma::{gamma_lr, ln_gamma};
    let Ok(normal) = Normal::new(0.0, 1.0) else {
        return f64::NAN;
    };
    let z = normal.inverse_cdf(p);
    let c = 2.0 / (9.0 * k);
    let mut x = (k * (1.0 - c + z * c.sqrt()).powi(3)).max(1e-8 * k.max(1.0));
    let h = k / 2.0;
    let ln_norm = h * std::f64::consts::LN_2 + ln_gamma(h);
    for _ in 0..100 {
        let f = gamma_lr(h, x / 2.0) - p;
        let pdf = ((h - 1.0) * x.ln() - x / 2.0 - ln_norm).exp();
        if pdf <= 0.0 || !pdf.is_finite() {
            break;
        }
        let step = f / pdf;
        let next = (x - step).max(x / 10.0);
        let done = (next - x).abs() <= 1e-15 * x;
        x = next;
        if done {
            break;
        }
    }
    x
}

/// Confidence interval of a deviation with `edf` degrees of freedom at
/// confidence `ci` (NIST SP1065 eq. 45).
pub fn confidence_interval(dev: f64, edf: f64, ci: f64) -> (f64, f64) {
    let lo_p = (1.0 - ci) / 2.0;
    let (chi_lo, chi_hi) = (chi2_quantile(lo_p, edf), chi2_quantile(1.0 - lo_p, edf));
    (dev * (edf / chi_hi).sqrt(), dev * (edf / chi_lo).sqrt())
}

/// One averaging time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Point {
    /// Averaging time, s.
    pub tau_s: f64,
    /// Averaging factor (tau / tau0).
    pub m: usize,
    /// Overlapping ADEV, in the rate's unit.
    pub adev: f64,
    /// One-sigma lower bound.
    pub lo: f64,
    /// One-sigma upper bound.
    pub hi: f64,
    /// Equivalent degrees of freedom.
    pub edf: f64,
    /// Noise exponent used for the EDF.
    pub alpha: i32,
}

/// Fitted noise terms (rate in deg/h).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NoiseTerms {
    /// Quantization noise Q, arcsec (sigma = sqrt(3) Q / tau).
    pub quantization_arcsec: f64,
    /// Angle random walk N, deg/sqrt(h) (sigma = 60 N / sqrt(tau s)).
    pub arw_deg_per_rt_h: f64,
    /// IEEE bias-instability coefficient B = floor / 0.664, deg/h.
    pub bias_instability_dph: f64,
    /// Rate random walk K, deg/h/sqrt(h).
    pub rate_random_walk_dph_per_rt_h: f64,
    /// RMS relative misfit of the fitted curve to the ADEV points.
    pub fit_rms_relative: f64,
    /// Whether the curve resolves each term, in the order Q, N, B, K.
    pub resolved: [Resolved; 4],
}

/// The noise terms' names as `--json` and reports key them, in the order
/// of [`NoiseTerms::resolved`].
pub const TERM_KEYS: [&str; 4] = [
    "quantization_arcsec",
    "arw_deg_per_rt_h",
    "bias_instability_dph",
    "rate_random_walk_dph_per_rt_h",
];

/// How many standard errors above zero a term's fitted AVAR coefficient
/// must lie to count as resolved by the curve.
pub const RESOLVED_SIGMAS: f64 = 2.0;

/// Whether the ADEV curve resolves one fitted noise term.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Resolved {
    /// The coefficient lies `z` standard errors above zero, at least
    /// [`RESOLVED_SIGMAS`].
    Yes {
        /// Coefficient over its standard error.
        z: f64,
    },
    /// The best fit puts the term at zero (its bound): the curve shows no
    /// part with this term's slope.
    AtZero,
    /// Fitted above zero, but fewer than [`RESOLVED_SIGMAS`] standard
    /// errors; the errors are scaled by `misfit` (the reduced chi-squared
    /// of the fit, when above 1: the curve departs from the model by more
    /// than its intervals allow).
    Weak {
        /// Coefficient over its standard error.
        z: f64,
        /// Factor on the variances from the fit's misfit (1 when it fits).
        misfit: f64,
    },
}

impl Resolved {
    /// The curve resolves the term.
    pub fn is_resolved(self) -> bool {
        matches!(self, Self::Yes { .. })
    }

    /// Why the term is not resolved, in words; `None` when it is.
    pub fn reason(self) -> Option<String> {
        match self {
            Self::Yes { .. } => None,
            Self::AtZero => {
                Some("the fit puts it at zero: no part of the curve has its slope".to_owned())
            }
            Self::Weak { z, misfit } if misfit > 1.0 => Some(format!(
                "{z:.1} standard errors from zero (needs {RESOLVED_SIGMAS}), the errors widened \
                 {:.1}x by the misfit of the curve to the model",
                misfit.sqrt()
            )),
            Self::Weak { z, .. } => Some(format!(
                "{z:.1} standard errors from zero (needs {RESOLVED_SIGMAS}): too little of the \
                 curve shows it"
            )),
        }
    }
}

/// The three figures called "bias instability" (`docs/physics.md`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BiasInstability {
    /// IEEE coefficient B = ADEV floor / 0.664 (from the fit), deg/h.
    pub ieee_b_dph: f64,
    /// The raw ADEV minimum, deg/h.
    pub adev_min_dph: f64,
    /// Where the minimum lies, s.
    pub adev_min_tau_s: f64,
}

/// The whole analysis of one series.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Allan {
    /// Sample time, s.
    pub tau0_s: f64,
    /// Rate samples.
    pub samples: usize,
    /// Per averaging time.
    pub points: Vec<Point>,
    /// Fitted noise terms.
    pub noise: NoiseTerms,
    /// The floor-based figures.
    pub bias_instability: BiasInstability,
}

/// ADEV with confidence intervals and the fitted noise terms.
pub fn analyse(rate: &[f64], tau0_s: f64, taus: Taus) -> Allan {
    let ms = factors(rate.len(), taus);
    let devs = oadev(rate, tau0_s, &ms);
    let mut last_alpha = 0;
    let points: Vec<Point> = ms
        .iter()
        .zip(devs)
        .map(|(&m, (tau_s, adev))| {
            // Too few means to identify the noise: keep the last type found.
            let alpha = noise_alpha(rate, m).unwrap_or(last_alpha);
            last_alpha = alpha;
            let edf = edf_oadev(alpha, m, rate.len() + 1);
            let (lo, hi) = confidence_interval(adev, edf, ONE_SIGMA);
            Point {
                tau_s,
                m,
                adev,
                lo,
                hi,
                edf,
                alpha,
            }
        })
        .collect();
    let noise = fit_noise(&points);
    let min = points
        .iter()
        .filter(|p| p.adev.is_finite())
        .min_by(|a, b| a.adev.total_cmp(&b.adev));
    Allan {
        tau0_s,
        samples: rate.len(),
        bias_instability: BiasInstability {
            ieee_b_dph: noise.bias_instability_dph,
            adev_min_dph: min.map_or(f64::NAN, |p| p.adev),
            adev_min_tau_s: min.map_or(f64::NAN, |p| p.tau_s),
        },
        points,
        noise,
    }
}

/// Relative error allowed for the four-term model itself (ours): with
/// millions of degrees of freedom at short taus, EDF weights alone would
/// let any small departure from the ideal slopes there outweigh the long
/// taus where bias instability and rate random walk live.
pub const MODEL_FLOOR: f64 = 0.05;

/// Regressors of the four terms at one tau (AVAR = sum c_i x_i).
fn term_columns(tau: f64) -> [f64; 4] {
    [1.0 / (tau * tau), 1.0 / tau, 1.0, tau]
}

/// Weighted non-negative least squares of the AVAR model: every subset of
/// the four terms is solved and the best non-negative solution kept.
pub fn fit_noise(points: &[Point]) -> NoiseTerms {
    let pts: Vec<&Point> = points
        .iter()
        .filter(|p| p.adev.is_finite() && p.adev > 0.0)
        .collect();
    let mut best: Option<([f64; 4], f64, [Resolved; 4])> = None;
    for mask in 1u8..16 {
        let idx: Vec<usize> = (0..4).filter(|i| mask & (1 << i) != 0).collect();
        if idx.len() > pts.len() {
            continue;
        }
        // Relative residuals over their standard error: sqrt(2/EDF) from
        // the estimate, MODEL_FLOOR from the model.
        let rows: Vec<(Vec<f64>, f64)> = pts
            .iter()
            .map(|p| {
                let avar = p.adev * p.adev;
                let w = 1.0 / (avar * (2.0 / p.edf + MODEL_FLOOR * MODEL_FLOOR).sqrt());
                let cols = term_columns(p.tau_s);
                (idx.iter().map(|&i| cols[i] * w).collect(), avar * w)
            })
            .collect();
        let x = nalgebra::DMatrix::from_fn(rows.len(), idx.len(), |r, c| rows[r].0[c]);
        let y = nalgebra::DVector::from_iterator(rows.len(), rows.iter().map(|r| r.1));
        let Ok(beta) = x.clone().svd(true, true).solve(&y, 1e-14) else {
            continue;
        };
        if beta.iter().any(|b| *b < 0.0 || !b.is_finite()) {
            continue;
        }
        let sse = (&y - &x * &beta).norm_squared();
        if best.as_ref().is_none_or(|(_, s, _)| sse < *s) {
            let mut c = [0.0; 4];
            let mut resolved = [Resolved::AtZero; 4];
            let z = significance(&x, &beta, sse);
            for (k, &i) in idx.iter().enumerate() {
                c[i] = beta[k];
                resolved[i] = z[k];
            }
            best = Some((c, sse, resolved));
        }
    }
    let (c, resolved) = best.map_or(([0.0; 4], [Resolved::AtZero; 4]), |(c, _, r)| (c, r));
    let model = |tau: f64| {
        term_columns(tau)
            .iter()
            .zip(&c)
            .map(|(x, k)| x * k)
            .sum::<f64>()
    };
    let rel: Vec<f64> = pts
        .iter()
        .map(|p| model(p.tau_s).sqrt() / p.adev - 1.0)
        .collect();
    NoiseTerms {
        quantization_arcsec: (c[0] / 3.0).sqrt(),
        arw_deg_per_rt_h: c[1].sqrt() / 60.0,
        bias_instability_dph: c[2].sqrt() / floor_per_b(),
        rate_random_walk_dph_per_rt_h: (c[3] * 3.0 * 3600.0).sqrt(),
        fit_rms_relative: (rel.iter().map(|r| r * r).sum::<f64>() / rel.len().max(1) as f64).sqrt(),
        resolved,
    }
}

/// How far each fitted coefficient lies from zero in standard errors, for
/// the weighted design `x` (rows already divided by their standard error)
/// and its residual sum of squares. The variances are scaled by the reduced
/// chi-squared when it exceeds 1, so a curve the model misfits resolves
/// less; a zero coefficient is [`Resolved::AtZero`].
fn significance(
    x: &nalgebra::DMatrix<f64>,
    beta: &nalgebra::DVector<f64>,
    sse: f64,
) -> Vec<Resolved> {
    let (n, p) = x.shape();
    let misfit = if n > p {
        (sse / (n - p) as f64).max(1.0)
    } else {
        1.0
    };
    let cov = (x.transpose() * x).try_inverse();
    (0..p)
        .map(|k| {
            if beta[k] <= 0.0 {
                return Resolved::AtZero;
            }
            let var = cov.as_ref().map_or(f64::INFINITY, |c| c[(k, k)] * misfit);
            let z = if var == 0.0 {
                f64::INFINITY
            } else if var.is_finite() && var > 0.0 {
                beta[k] / var.sqrt()
            } else {
                0.0
            };
            if z >= RESOLVED_SIGMAS {
                Resolved::Yes { z }
            } else {
                Resolved::Weak { z, misfit }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests;
