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

/// The smoothed series a drift figure is the peak-to-peak of, as a person
/// checks it: each stretch's centred moving average against time (thinned
/// to a tenth of the window, which loses nothing a 600 s smoothing shows),
/// and the exact highest and lowest points.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DriftTrace {
    /// Per stretch: (time at the window's centre, s; smoothed value).
    pub parts: Vec<Vec<(f64, f64)>>,
    /// Where the highest smoothed value lies: (s, value).
    pub max: (f64, f64),
    /// Where the lowest lies.
    pub min: (f64, f64),
}

impl DriftTrace {
    /// The drift: highest minus lowest smoothed value.
    pub fn pp(&self) -> f64 {
        self.max.1 - self.min.1
    }
}

/// [`drift_pp`] over several stretches (parts of a resumed run), each
/// given as (times, values): each is smoothed on its own, never across the
/// break, and the peak-to-peak is taken over all of them. None when no
/// stretch is as long as `window`.
pub fn drift_trace(parts: &[(Vec<f64>, Vec<f64>)], window: usize) -> Option<DriftTrace> {
    let thin = (window / 10).max(1);
    let mut trace = DriftTrace {
        max: (f64::NAN, f64::NEG_INFINITY),
        min: (f64::NAN, f64::INFINITY),
        ..DriftTrace::default()
    };
    for (t, x) in parts {
        let smoothed = moving_average(x, window);
        let centre = |i: usize| (t[i] + t[i + window - 1]) / 2.0;
        let (mut hi, mut lo) = (None, None);
        for (i, &v) in smoothed.iter().enumerate() {
            if v > trace.max.1 {
                trace.max = (centre(i), v);
                hi = Some(i);
            }
            if v < trace.min.1 {
                trace.min = (centre(i), v);
                lo = Some(i);
            }
        }
        if !smoothed.is_empty() {
            // Thinned, but the extremes kept: the line passes through the
            // points the figure is taken between.
            trace.parts.push(
                smoothed
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| {
                        i % thin == 0
                            || *i == smoothed.len() - 1
                            || Some(*i) == hi
                            || Some(*i) == lo
                    })
                    .map(|(i, &v)| (centre(i), v))
                    .collect(),
            );
        }
    }
    (!trace.parts.is_empty()).then_some(trace)
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

/// Turn-on to turn-on bias repeatability (IEEE Std 647): the sample
/// standard deviation of the mean biases of `n` turn-ons, with its one
/// standard error for `n` samples, `s / sqrt(2 (n - 1))` (the chi
/// distribution's, normal turn-on biases); none below two turn-ons.
pub fn repeatability(turn_on_means: &[f64]) -> Option<(f64, f64)> {
    let n = turn_on_means.len();
    if n < 2 || turn_on_means.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let s = std_dev(turn_on_means);
    Some((s, s / (2.0 * (n as f64 - 1.0)).sqrt()))
}

/// Warm-up time (IEEE Std 647: the time from turn-on to the specified
/// performance), on a series of 1-per-`dt_s` samples starting at turn-on:
/// the end of the first `window`-sample mean after which every such mean
/// stays within `band` of the settled value; s from the series' start.
/// The settled value is the mean of the series' last quarter (ours: a
/// single last window would carry its own noise into every comparison).
/// None when the series holds fewer than four windows, or its last mean
/// is still outside the band (not warm within the series).
pub fn warm_up_time(x: &[f64], dt_s: f64, window: usize, band: f64) -> Option<f64> {
    if window == 0 || x.len() < 4 * window {
        return None;
    }
    let settled = mean(&x[x.len() - x.len() / 4..]);
    let means = moving_average(x, window);
    // The last mean outside the band; warm once past it.
    let last_out = means.iter().rposition(|m| (m - settled).abs() > band);
    let first_in = last_out.map_or(0, |i| i + 1);
    // Mean i covers samples i..i + window: it ends window samples in. The
    // last mean itself outside the band: not settled within the series.
    (first_in < means.len()).then(|| (first_in + window) as f64 * dt_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeatability_is_the_spread_of_the_turn_on_biases_with_its_error() {
        let (s, e) = repeatability(&[1.0, 2.0, 3.0, 4.0, 5.0]).expect("five turn-ons");
        assert!((s - 2.5_f64.sqrt()).abs() < 1e-12);
        assert!((e - s / 8.0_f64.sqrt()).abs() < 1e-12);
        assert_eq!(repeatability(&[1.0]), None);
        assert_eq!(repeatability(&[1.0, f64::NAN]), None);
    }

    #[test]
    fn warm_up_ends_when_the_mean_stays_in_its_band() {
        // A transient of 0.5 decaying in 600 s, on a flat 0.1: within
        // 0.01 of the end once 0.5 exp(-t/600) < 0.01, t = 2347 s; a
        // 100 s mean lags by about half a window.
        let x: Vec<f64> = (0..10_000)
            .map(|i| 0.1 + 0.5 * (-(f64::from(i) + 0.5) / 600.0).exp())
            .collect();
        let t = warm_up_time(&x, 1.0, 100, 0.01).expect("settles");
        assert!((t - 2397.0).abs() < 5.0, "{t}");
        // Already warm: one window.
        assert_eq!(warm_up_time(&[0.2; 500], 1.0, 100, 0.01), Some(100.0));
        assert_eq!(warm_up_time(&[0.2; 399], 1.0, 100, 0.01), None);
        // Still drifting at the end: not warm within the record.
        let ramp: Vec<f64> = (0..1000).map(|i| f64::from(i) * 0.001).collect();
        assert_eq!(warm_up_time(&ramp, 1.0, 100, 0.01), None);
    }

    #[test]
    fn a_drift_trace_is_the_drift_and_shows_where_it_is_taken() {
        // A ramp then a step down, in two stretches.
        let t1: Vec<f64> = (0..100).map(f64::from).collect();
        let x1: Vec<f64> = (0..100).map(|i| f64::from(i) * 0.01).collect();
        let t2: Vec<f64> = (200..300).map(f64::from).collect();
        let x2 = vec![-0.5; 100];
        let tr = drift_trace(&[(t1, x1.clone()), (t2, x2.clone())], 20).expect("trace");
        let all: Vec<f64> = moving_average(&x1, 20)
            .into_iter()
            .chain(moving_average(&x2, 20))
            .collect();
        assert_eq!(tr.pp(), peak_to_peak(&all));
        assert_eq!(tr.max.0, 89.5);
        assert!((tr.max.1 - 0.895).abs() < 1e-12);
        assert_eq!(tr.min.1, -0.5);
        assert_eq!(tr.parts.len(), 2, "never smoothed across the break");
        assert!(tr.parts[0].len() < 81, "thinned");
        assert!(
            tr.parts[0].contains(&tr.max),
            "the highest point is on the line"
        );
        assert!(drift_trace(&[(vec![0.0], vec![1.0])], 10).is_none());
    }

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
