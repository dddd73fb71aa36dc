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

/// [`drift_pp`] over several stretches (parts of a resumed run): each is
/// smoothed on its own, never across the break, and the peak-to-peak is
/// taken over all of them. None when no stretch is as long as `window`.
pub fn drift_pp_parts(parts: &[Vec<f64>], window: usize) -> Option<f64> {
    let smoothed: Vec<f64> = parts
        .iter()
        .flat_map(|p| moving_average(p, window))
        .collect();
    (!smoothed.is_empty()).then(|| peak_to_peak(&smoothed))
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

/// Slope by local linear regression over `±half_s` seconds at the
/// samples' times `t_s`, never across a gap: the series is cut where the
/// spacing exceeds 1.5 times its median (the moves between records), and
/// each piece is differentiated on its own. Records concatenated into one
/// series (a measure over several records, a run's recorded intervals)
/// would otherwise see each jump between records as a steep slope.
pub fn derivative_by_time(t_s: &[f64], x: &[f64], half_s: f64) -> Vec<f64> {
    let mut spacing: Vec<f64> = t_s.windows(2).map(|w| w[1] - w[0]).collect();
    if spacing.is_empty() {
        return vec![0.0; x.len()];
    }
    spacing.sort_by(f64::total_cmp);
    let dt = spacing[spacing.len() / 2].max(1e-6);
    let half = (half_s / dt).round().max(1.0) as usize;
    let mut out = Vec::with_capacity(x.len());
    let mut start = 0;
    for i in 1..=x.len() {
        if i == x.len() || t_s[i] - t_s[i - 1] > 1.5 * dt {
            out.extend(smoothed_derivative(&x[start..i], dt, half));
            start = i;
        }
    }
    out
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

    #[test]
    fn derivative_by_time_does_not_bridge_gaps() {
        // Two records of a slope 0.01 per s with a jump of 5 and a 120 s
        // gap between them: the jump must not show as a slope.
        let t: Vec<f64> = (0..100).chain(220..320).map(f64::from).collect();
        let x: Vec<f64> = t
            .iter()
            .map(|&t| 0.01 * t + if t > 200.0 { 5.0 } else { 0.0 })
            .collect();
        let d = derivative_by_time(&t, &x, 30.0);
        assert_eq!(d.len(), t.len());
        for v in d {
            assert!((v - 0.01).abs() < 1e-12, "{v}");
        }
        assert_eq!(derivative_by_time(&[1.0], &[2.0], 30.0), vec![0.0]);
    }
}
