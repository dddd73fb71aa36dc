//! Figures of merit on evenly spaced series. Pure functions.

/// Centred moving average over `window` samples, kept only where the window
/// is full (the output is `window - 1` shorter than the input).
pub fn moving_average(x: &[f64], window: usize) -> Vec<f64> {
    if window == 0 || x.len() < window {
        return Vec::new();
    }
    let mut out = Vec::with_capacity(x.len() - window + 1);
    let mut sum: f64 = x[..window].iter().sum();
    out.push(sum / window as f64);
    for i in window..x.len() {
        sum += x[i] - x[i - window];
        out.push(sum / window as f64);
    }
    out
}

/// Means of consecutive non-overlapping blocks of `block` samples (a
/// trailing partial block is dropped).
pub fn block_means(x: &[f64], block: usize) -> Vec<f64> {
    if block == 0 {
        return Vec::new();
    }
    x.chunks_exact(block)
        .map(|c| c.iter().sum::<f64>() / block as f64)
        .collect()
}

/// Largest minus smallest value (0 for an empty slice).
pub fn peak_to_peak(x: &[f64]) -> f64 {
    let (lo, hi) = x
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    if x.is_empty() { 0.0 } else { hi - lo }
}

/// Arithmetic mean (NaN for an empty slice).
pub fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// Sample standard deviation, n - 1 (NaN below two samples).
pub fn std_dev(x: &[f64]) -> f64 {
    if x.len() < 2 {
        return f64::NAN;
    }
    let m = mean(x);
    (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64).sqrt()
}

/// Root mean square.
pub fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// Bias stability (GJB 2426A convention): 1-sigma of the output averaged
/// over `avg_samples` consecutive samples.
pub fn bias_stability(x: &[f64], avg_samples: usize) -> f64 {
    std_dev(&block_means(x, avg_samples))
}

/// Drift: peak-to-peak of the series smoothed by a centred moving average of
/// `window` samples.
pub fn drift_pp(x: &[f64], window: usize) -> f64 {
    peak_to_peak(&moving_average(x, window))
}

/// Slope by local linear regression over `±half` samples (edges use what
/// is there), per sample spacing `dt`. Far less noisy than a plain
/// difference on quantized temperatures.
pub fn smoothed_derivative(x: &[f64], dt: f64, half: usize) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|i| {
            let lo = i.saturating_sub(half);
            let hi = (i + half).min(n.saturating_sub(1));
            if hi <= lo {
                return 0.0;
            }
            let m = (hi - lo + 1) as f64;
            let tm = (lo + hi) as f64 / 2.0;
            let xm = x[lo..=hi].iter().sum::<f64>() / m;
            let (mut sxy, mut sxx) = (0.0, 0.0);
            for (j, v) in x[lo..=hi].iter().enumerate() {
                let t = (lo + j) as f64 - tm;
                sxy += t * (v - xm);
                sxx += t * t;
            }
            sxy / sxx / dt
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_average_keeps_full_windows_only() {
        let y = moving_average(&[1.0, 2.0, 3.0, 4.0, 5.0], 3);
        assert_eq!(y, vec![2.0, 3.0, 4.0]);
        assert!(moving_average(&[1.0], 3).is_empty());
    }

    #[test]
    fn drift_and_stability_of_a_known_signal() {
        // A 1 Hz ramp of 0.001 deg/h per sample: pp after a 11-sample average
        // is the ramp over the kept span.
        let x: Vec<f64> = (0..1000).map(|i| f64::from(i) * 0.001).collect();
        assert!((drift_pp(&x, 11) - 0.989).abs() < 1e-9);
        let blocks = block_means(&x, 100);
        assert_eq!(blocks.len(), 10);
        assert!((bias_stability(&x, 100) - std_dev(&blocks)).abs() < 1e-15);
        assert!((std_dev(&[1.0, 3.0]) - 2f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn smoothed_derivative_recovers_a_slope() {
        let x: Vec<f64> = (0..200).map(|i| 3.0 + 0.25 * f64::from(i)).collect();
        for d in smoothed_derivative(&x, 2.0, 10) {
            assert!((d - 0.125).abs() < 1e-12);
        }
    }
}
