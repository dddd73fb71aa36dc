//! Rate-table figures of a laser gyro (IEEE Std 647 names where it has
//! them; definitions in `docs/figures.md`): scale factor, its
//! nonlinearity, asymmetry and temperature coefficient, and the dead band
//! and threshold near zero input. Each record of a rate procedure is one
//! point: its mean input rate (Earth and table rate on the sensitive axis,
//! from the table's angles and rates), its mean output rate and the
//! standard error of that mean. For the scale-factor figures a record
//! over whole revolutions is taken in the angle domain ([`angle`]).

pub mod angle;

use nalgebra::{DMatrix, DVector};

use super::series::Interval;

/// One record as a point of the rate transfer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RatePoint {
    /// Mean input rate on the sensitive axis, deg/h.
    pub input_dph: f64,
    /// Mean output rate, deg/h.
    pub output_dph: f64,
    /// Standard error of the output mean, deg/h (the scatter of its 1 s
    /// means about the input, over their number).
    pub se_dph: f64,
    /// Mean block temperature, degC.
    pub block_c: f64,
}

impl RatePoint {
    /// The point of one record's 1 Hz intervals (none when empty).
    pub fn of(record: &[Interval]) -> Option<Self> {
        let n = record.len();
        if n == 0 {
            return None;
        }
        let nf = n as f64;
        let mean = |f: &dyn Fn(&Interval) -> f64| record.iter().map(f).sum::<f64>() / nf;
        let input = mean(&|i| i.reference_dph);
        let output = mean(&|i| i.rate_dph);
        let bias = output - input;
        let var = if n > 1 {
            record
                .iter()
                .map(|i| (i.bias_dph() - bias).powi(2))
                .sum::<f64>()
                / (nf - 1.0)
        } else {
            0.0
        };
        Some(Self {
            input_dph: input,
            output_dph: output,
            se_dph: (var / nf).sqrt(),
            block_c: mean(&|i| 0.5 * (i.t1_c + i.t2_c)),
        })
    }

    /// The point in the angle domain: its input and output over the
    /// record's whole revolutions ([`angle::AngleSpan`]), its standard
    /// error and block temperature from its 1 Hz means as before.
    pub fn over_revolutions(self, span: &angle::AngleSpan) -> Self {
        Self {
            input_dph: span.input_dph,
            output_dph: span.output_dph(),
            ..self
        }
    }
}

/// A figure with its standard error (none when it cannot be estimated).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figure {
    /// Value.
    pub value: f64,
    /// One standard error.
    pub std_error: Option<f64>,
}

/// Least squares `y = X b`: the coefficients and their covariance (from
/// the residual variance); none when underdetermined or singular.
fn least_squares(x: &DMatrix<f64>, y: &DVector<f64>) -> Option<(DVector<f64>, DMatrix<f64>)> {
    let (n, p) = x.shape();
    if n <= p {
        return None;
    }
    let xtx = x.transpose() * x;
    let inv = xtx.try_inverse()?;
    let b = &inv * x.transpose() * y;
    let r = y - x * &b;
    let s2 = r.norm_squared() / (n - p) as f64;
    Some((b, inv * s2))
}

/// The transfer fit `output = K+ input (input > 0) + K- input (input < 0) + B`:
/// one slope per direction and a common bias (one slope when the records
/// turn one way only). The slopes, the bias and their covariance.
#[derive(Debug, Clone)]
pub struct Transfer {
    /// Slope for positive inputs.
    pub k_pos: f64,
    /// Slope for negative inputs.
    pub k_neg: f64,
    /// Bias, deg/h.
    pub bias_dph: f64,
    /// Covariance of (K+, K-, B); with one direction, (K, K, B) share it.
    cov: DMatrix<f64>,
    /// Both directions were fitted.
    both: bool,
}

impl Transfer {
    /// The fit over `points`; none with fewer than four points (three in
    /// one direction) or a singular design.
    pub fn fit(points: &[RatePoint]) -> Option<Self> {
        let pos = points.iter().any(|p| p.input_dph > 0.0);
        let neg = points.iter().any(|p| p.input_dph < 0.0);
        let y = DVector::from_iterator(points.len(), points.iter().map(|p| p.output_dph));
        if pos && neg {
            let x = DMatrix::from_fn(points.len(), 3, |i, j| {
                let v = points[i].input_dph;
                match j {
                    0 => v.max(0.0),
                    1 => v.min(0.0),
                    _ => 1.0,
                }
            });
            let (b, cov) = least_squares(&x, &y)?;
            Some(Self {
                k_pos: b[0],
                k_neg: b[1],
                bias_dph: b[2],
                cov,
                both: true,
            })
        } else {
            let x = DMatrix::from_fn(points.len(), 2, |i, j| {
                if j == 0 { points[i].input_dph } else { 1.0 }
            });
            let (b, c) = least_squares(&x, &y)?;
            let cov = DMatrix::from_row_slice(
                3,
                3,
                &[
                    c[(0, 0)],
                    c[(0, 0)],
                    c[(0, 1)],
                    c[(0, 0)],
                    c[(0, 0)],
                    c[(0, 1)],
                    c[(1, 0)],
                    c[(1, 0)],
                    c[(1, 1)],
                ],
            );
            Some(Self {
                k_pos: b[0],
                k_neg: b[0],
                bias_dph: b[1],
                cov,
                both: false,
            })
        }
    }

    /// The mean scale factor `(K+ + K-) / 2`.
    pub fn k(&self) -> f64 {
        0.5 * (self.k_pos + self.k_neg)
    }

    /// Its standard error.
    fn k_se(&self) -> f64 {
        let c = &self.cov;
        let v = if self.both {
            0.25 * (c[(0, 0)] + c[(1, 1)] + 2.0 * c[(0, 1)])
        } else {
            c[(0, 0)]
        };
        v.max(0.0).sqrt()
    }

    /// The fitted output at `input`.
    pub fn output_dph(&self, input: f64) -> f64 {
        let k = if input >= 0.0 { self.k_pos } else { self.k_neg };
        k * input + self.bias_dph
    }
}

/// Scale factor error against nominal, ppm: `(K - 1) 1e6` with `K` the
/// mean of the two directions' slopes, with its standard error.
pub fn scale_factor_ppm(points: &[RatePoint]) -> Option<Figure> {
    let t = Transfer::fit(points)?;
    Some(Figure {
        value: (t.k() - 1.0) * 1e6,
        std_error: Some(t.k_se() * 1e6),
    })
}

/// Scale-factor nonlinearity, ppm: the largest residual of the transfer
/// fit (asymmetry is its own figure), relative to the fitted output at that
/// point. Its standard error is that point's, relative the same way.
pub fn nonlinearity_ppm(points: &[RatePoint]) -> Option<Figure> {
    let t = Transfer::fit(points)?;
    points
        .iter()
        .filter_map(|p| {
            let net = t.output_dph(p.input_dph) - t.bias_dph;
            (net != 0.0).then(|| {
                let r = (p.output_dph - t.output_dph(p.input_dph)) / net.abs();
                (r.abs() * 1e6, p.se_dph / net.abs() * 1e6)
            })
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(value, se)| Figure {
            value,
            std_error: Some(se),
        })
}

/// Scale-factor asymmetry, ppm: `(K+ - K-) / K` of the transfer fit.
pub fn asymmetry_ppm(points: &[RatePoint]) -> Option<Figure> {
    let t = Transfer::fit(points)?;
    if !t.both {
        return None;
    }
    let k = t.k();
    let c = &t.cov;
    let var = c[(0, 0)] + c[(1, 1)] - 2.0 * c[(0, 1)];
    Some(Figure {
        value: (t.k_pos - t.k_neg) / k * 1e6,
        std_error: Some(var.max(0.0).sqrt() / k.abs() * 1e6),
    })
}

/// Arcseconds in a radian.
const ARCSEC_PER_RAD: f64 = 180.0 * 3600.0 / std::f64::consts::PI;

/// A table rate under this, deg/h, is no turn (ours: a thousandth of a
/// deg/s).
const MIN_TURN_DPH: f64 = 3.6;

/// Input axis misalignment, arcsec: the slope of the Earth-removed rate
/// against the rate of a table axis turning across the sensitive axis
/// (`(turn deg/h, record)` pairs), fitted with a common bias. A sensitive
/// axis tilted by a small angle towards the turning axis reads that share
/// of its rate, which changes sign with the direction; gravity, the field
/// and Earth rate average the same over whole revolutions either way. None
/// without three records, or without turns both ways.
pub fn misalignment_arcsec(points: &[(f64, RatePoint)]) -> Option<Figure> {
    let both_ways = points.iter().any(|(w, _)| *w > MIN_TURN_DPH)
        && points.iter().any(|(w, _)| *w < -MIN_TURN_DPH);
    if points.len() < 3 || !both_ways {
        return None;
    }
    let x = DMatrix::from_fn(
        points.len(),
        2,
        |i, j| if j == 0 { points[i].0 } else { 1.0 },
    );
    let y = DVector::from_iterator(
        points.len(),
        points.iter().map(|(_, p)| p.output_dph - p.input_dph),
    );
    let (b, cov) = least_squares(&x, &y)?;
    Some(Figure {
        value: b[0] * ARCSEC_PER_RAD,
        std_error: Some(cov[(0, 0)].max(0.0).sqrt() * ARCSEC_PER_RAD),
    })
}

/// Scale factor change per degC of the block, ppm/degC: the fit
/// `output = K0 input + c input (T - Tm) + B`, `c / K0`. None when the
/// records span less than 1 degC.
pub fn temperature_coefficient_ppm_per_c(points: &[RatePoint]) -> Option<Figure> {
    let n = points.len() as f64;
    let tm = points.iter().map(|p| p.block_c).sum::<f64>() / n;
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.block_c), b.max(p.block_c))
        });
    if hi - lo < 1.0 {
        return None;
    }
    let x = DMatrix::from_fn(points.len(), 3, |i, j| {
        let p = points[i];
        match j {
            0 => p.input_dph,
            1 => p.input_dph * (p.block_c - tm),
            _ => 1.0,
        }
    });
    let y = DVector::from_iterator(points.len(), points.iter().map(|p| p.output_dph));
    let (b, cov) = least_squares(&x, &y)?;
    Some(Figure {
        value: b[1] / b[0] * 1e6,
        std_error: Some(cov[(1, 1)].max(0.0).sqrt() / b[0].abs() * 1e6),
    })
}

/// Output of a gyro with lock-in threshold `l` and bias `b` at input `x`
/// (nominal scale factor): none inside the lock-in band, the Adler
/// equation's `sign(u) sqrt(u^2 - l^2)` outside, `u = x + b`.
pub fn locked_output(x: f64, b: f64, l: f64) -> f64 {
    let u = x + b;
    if u.abs() <= l {
        0.0
    } else {
        u.signum() * (u * u - l * l).sqrt()
    }
}

fn ssr(points: &[RatePoint], b: f64, l: f64) -> f64 {
    points
        .iter()
        .map(|p| (p.output_dph - locked_output(p.input_dph, b, l)).powi(2))
        .sum()
}

/// Golden-section minimum of `f` on `[lo, hi]`.
fn golden(mut lo: f64, mut hi: f64, f: impl Fn(f64) -> f64) -> f64 {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..80 {
        if fc < fd {
            hi = d;
            d = c;
            fd = fc;
            c = hi - g * (hi - lo);
            fc = f(c);
        } else {
            lo = c;
            c = d;
            fc = fd;
            d = lo + g * (hi - lo);
            fd = f(d);
        }
    }
    0.5 * (lo + hi)
}

/// The lock-in fit of records around zero input: (bias, lock-in
/// threshold, its standard error), deg/h. The threshold is searched on a
/// grid up to the largest input, refined, and the bias fitted for each.
pub fn lock_in(points: &[RatePoint]) -> Option<(f64, f64, Option<f64>)> {
    if points.len() < 4 {
        return None;
    }
    let span = points.iter().map(|p| p.input_dph.abs()).fold(0.0, f64::max);
    if span <= 0.0 {
        return None;
    }
    // The bias from the points farthest from zero, where lock-in matters
    // least.
    let mut far: Vec<&RatePoint> = points.iter().collect();
    far.sort_by(|a, b| b.input_dph.abs().total_cmp(&a.input_dph.abs()));
    let far = &far[..far.len().div_ceil(3)];
    let b0 = far.iter().map(|p| p.output_dph - p.input_dph).sum::<f64>() / far.len() as f64;
    let best_b = |l: f64| golden(b0 - span / 2.0, b0 + span / 2.0, |b| ssr(points, b, l));
    let cost = |l: f64| ssr(points, best_b(l), l);
    let grid = 200;
    let step = span / f64::from(grid);
    let l_grid = (0..=grid)
        .map(|i| f64::from(i) * step)
        .min_by(|a, b| cost(*a).total_cmp(&cost(*b)))?;
    let l = golden((l_grid - step).max(0.0), l_grid + step, cost);
    let b = best_b(l);
    // Standard error from the Jacobian at the optimum.
    let n = points.len();
    let h = 1e-4 * span.max(1.0);
    let jac = DMatrix::from_fn(n, 2, |i, j| {
        let x = points[i].input_dph;
        if j == 0 {
            (locked_output(x, b + h, l) - locked_output(x, b - h, l)) / (2.0 * h)
        } else {
            (locked_output(x, b, l + h) - locked_output(x, b, (l - h).max(0.0)))
                / (l + h - (l - h).max(0.0))
        }
    });
    let s2 = ssr(points, b, l) / (n - 2) as f64;
    let linear = (jac.transpose() * &jac)
        .try_inverse()
        .map(|inv| (inv[(1, 1)] * s2).max(0.0).sqrt())
        .filter(|v| v.is_finite());
    // Near zero the output hardly depends on the lock-in (its first
    // derivative vanishes at 0), so the linearized error blows up; the
    // profile of the cost is what the data say: the lock-in above the fit
    // at which the least squares rise by one residual variance.
    let profile = {
        let rise = |x: f64| cost(x) - cost(l) - s2;
        (rise(span) > 0.0).then(|| {
            let (mut lo, mut hi) = (l, span);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if rise(mid) > 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            hi - l
        })
    };
    let se = match (linear, profile) {
        (Some(a), Some(p)) => Some(a.min(p)),
        (a, p) => a.or(p),
    };
    Some((b, l, se))
}

/// Output under this share of the expected marks the dead band (IEEE).
pub const DEAD_BAND_SHARE: f64 = 0.1;
/// Output at least this share of the expected marks the threshold (IEEE).
pub const THRESHOLD_SHARE: f64 = 0.5;

/// The input (bias removed) at which a gyro with lock-in `l` gives
/// `share` of the expected output: `l / sqrt(1 - share^2)`.
pub fn input_for_share(l: f64, share: f64) -> f64 {
    l / (1.0 - share * share).sqrt()
}

/// Dead band (`share` 0.1) or threshold (0.5), deg/h, from the lock-in fit.
pub fn band_dph(points: &[RatePoint], share: f64) -> Option<Figure> {
    let (_, l, se) = lock_in(points)?;
    let f = input_for_share(1.0, share);
    Some(Figure {
        value: l * f,
        std_error: se.map(|s| s * f),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pt(input: f64, output: f64) -> RatePoint {
        RatePoint {
            input_dph: input,
            output_dph: output,
            se_dph: 0.001,
            block_c: 20.0,
        }
    }

    #[test]
    fn misalignment_is_the_slope_against_the_turn_and_needs_both_ways() {
        // 100 arcsec of tilt, a bias of 0.3 deg/h, Earth rate 7 deg/h on
        // the axis; +-5 deg/s ABBA with a little noise.
        let tilt = 100.0 / ARCSEC_PER_RAD;
        let at = |w: f64, noise: f64| (w, pt(7.0, 7.0 + 0.3 + tilt * w + noise));
        let abba = [
            at(18_000.0, 0.002),
            at(-18_000.0, -0.001),
            at(-18_000.0, 0.001),
            at(18_000.0, -0.002),
        ];
        let f = misalignment_arcsec(&abba).expect("figure");
        assert!((f.value - 100.0).abs() < 0.1, "{f:?}");
        assert!(f.std_error.is_some_and(|se| se > 0.0 && se < 0.1), "{f:?}");
        assert!(misalignment_arcsec(&abba[..2]).is_none(), "two records");
        let one_way = [abba[0], abba[3], at(9_000.0, 0.0)];
        assert!(misalignment_arcsec(&one_way).is_none(), "one direction");
    }

    const LADDER_DPS: [f64; 8] = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0];

    fn ladder(f: impl Fn(f64) -> f64) -> Vec<RatePoint> {
        LADDER_DPS
            .iter()
            .flat_map(|r| [*r, -*r])
            .map(|r| {
                let x = r * 3600.0 + 10.6;
                pt(x, f(x))
            })
            .collect()
    }

    #[test]
    fn a_scale_factor_error_and_a_bias_are_separated() {
        let pts = ladder(|x| x * (1.0 + 120e-6) + 0.8);
        let sf = scale_factor_ppm(&pts).expect("fit");
        assert!((sf.value - 120.0).abs() < 1e-6, "{sf:?}");
        let nl = nonlinearity_ppm(&pts).expect("fit");
        assert!(nl.value < 1e-6, "a straight line has none: {nl:?}");
        let a = asymmetry_ppm(&pts).expect("fit");
        assert!(a.value.abs() < 1e-6, "{a:?}");
    }

    #[test]
    fn asymmetry_is_the_difference_of_the_two_slopes() {
        let pts = ladder(|x| x * (1.0 + 0.5e-6 * 40.0 * x.signum()) - 0.3);
        let a = asymmetry_ppm(&pts).expect("fit");
        assert!((a.value - 40.0).abs() < 1e-3, "{a:?}");
    }

    #[test]
    fn a_quadratic_output_error_shows_as_nonlinearity() {
        let fs = 400.0 * 3600.0;
        let pts = ladder(|x| x * (1.0 + 50e-6 * x.abs() / fs));
        let nl = nonlinearity_ppm(&pts).expect("fit");
        assert!(nl.value > 5.0 && nl.value < 50.0, "{nl:?}");
    }

    #[test]
    fn the_lock_in_fit_finds_threshold_and_bias() {
        let (b, l) = (0.8, 6.0);
        let pts: Vec<RatePoint> = (-30..=30)
            .map(|i| {
                let x = f64::from(i);
                pt(x, locked_output(x, b, l))
            })
            .collect();
        let (fb, fl, _) = lock_in(&pts).expect("fit");
        assert!((fb - b).abs() < 1e-3 && (fl - l).abs() < 1e-3, "{fb} {fl}");
        let d = band_dph(&pts, DEAD_BAND_SHARE).expect("fit");
        assert!((d.value - l / 0.99f64.sqrt()).abs() < 1e-2, "{d:?}");
    }
}
