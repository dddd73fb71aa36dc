//! Overlapping Allan deviation, O(N) per tau from the cumulative angle.

/// Octave averaging factors 1, 2, 4, ... up to a third of the series.
pub fn octave_factors(n: usize) -> Vec<usize> {
    std::iter::successors(Some(1usize), |m| m.checked_mul(2))
        .take_while(|m| 3 * m <= n)
        .collect()
}

/// Overlapping Allan deviation of a rate series sampled every `tau0_s`,
/// at each averaging factor `m` (tau = m tau0), in the rate's unit.
/// `theta_k` is the cumulative angle; the second difference
/// `theta_{k+2m} - 2 theta_{k+m} + theta_k` gives each term.
pub fn oadev(rate: &[f64], tau0_s: f64, factors: &[usize]) -> Vec<(f64, f64)> {
    let mut theta = Vec::with_capacity(rate.len() + 1);
    theta.push(0.0);
    let mut acc = 0.0;
    for r in rate {
        acc += r * tau0_s;
        theta.push(acc);
    }
    let n = theta.len();
    factors
        .iter()
        .filter(|&&m| m > 0 && n > 2 * m)
        .map(|&m| {
            let terms = n - 2 * m;
            let sum: f64 = (0..terms)
                .map(|k| {
                    let d = theta[k + 2 * m] - 2.0 * theta[k + m] + theta[k];
                    d * d
                })
                .sum();
            let tau = m as f64 * tau0_s;
            (tau, (sum / (2.0 * tau * tau * terms as f64)).sqrt())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_noise_falls_as_one_over_root_tau() {
        // Deterministic pseudo-noise with unit variance.
        let mut x = 0x2545_F491_4F6C_DD1Du64;
        let rate: Vec<f64> = (0..200_000)
            .map(|_| {
                let mut s = 0.0;
                for _ in 0..12 {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    s += (x >> 11) as f64 / (1u64 << 53) as f64;
                }
                s - 6.0
            })
            .collect();
        for (tau, dev) in oadev(&rate, 1.0, &[1, 4, 16, 64]) {
            let want = 1.0 / tau.sqrt();
            assert!((dev / want - 1.0).abs() < 0.1, "tau {tau}: {dev} vs {want}");
        }
    }

    #[test]
    fn a_constant_rate_has_zero_deviation_and_octaves_stop_at_a_third() {
        let dev = oadev(&[5.0; 100], 1.0, &octave_factors(100));
        assert!(dev.iter().all(|(_, d)| *d < 1e-12));
        assert_eq!(octave_factors(100), vec![1, 2, 4, 8, 16, 32]);
    }
}
