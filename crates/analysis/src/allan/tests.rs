use super::*;

fn xorshift_gauss(seed: u64, n: usize) -> Vec<f64> {
    let mut x = seed;
    (0..n)
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
        .collect()
}

#[test]
fn white_noise_falls_as_one_over_root_tau() {
    let rate = xorshift_gauss(0x2545_F491_4F6C_DD1D, 200_000);
    for (tau, dev) in oadev(&rate, 1.0, &[1, 4, 16, 64]) {
        let want = 1.0 / tau.sqrt();
        assert!((dev / want - 1.0).abs() < 0.1, "tau {tau}: {dev} vs {want}");
    }
}

#[test]
fn a_constant_rate_has_zero_deviation_and_taus_stop_at_a_third() {
    let dev = oadev(&[5.0; 100], 1.0, &octave_factors(100));
    assert!(dev.iter().all(|(_, d)| *d < 1e-12));
    assert_eq!(octave_factors(100), vec![1, 2, 4, 8, 16, 32]);
    let dense = factors(1000, Taus::Dense);
    assert_eq!(&dense[..6], &[1, 2, 3, 4, 5, 6]);
    assert_eq!(dense.last(), Some(&316));
    assert!(dense.windows(2).all(|w| w[0] < w[1]));
}

/// Reference values computed by allantools (fixtures/allan, made by
/// tests/conformance/make_allan_reference.py): ADEV to 1e-9 relative,
/// the same noise type at every tau, the same EDF and interval.
#[test]
fn agrees_with_allantools_on_adev_noise_type_edf_and_interval() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/allan");
    let reference: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root.join("reference.json")).expect("reference.json"),
    )
    .expect("JSON");
    let lsb = reference["lsb_dph"].as_f64().expect("lsb");
    let series = reference["series"].as_object().expect("series");
    assert_eq!(series.len(), 3);
    let mut alphas = std::collections::BTreeSet::new();
    for (name, points) in series {
        let rate: Vec<f64> = std::fs::read_to_string(root.join(format!("{name}.txt")))
            .expect("counts")
            .lines()
            .map(|l| l.trim().parse::<i64>().expect("integer") as f64 * lsb)
            .collect();
        let points = points.as_array().expect("points");
        let ms: Vec<usize> = points
            .iter()
            .map(|p| p["m"].as_u64().expect("m") as usize)
            .collect();
        let ours = oadev(&rate, 1.0, &ms);
        assert_eq!(ours.len(), points.len(), "{name}");
        for (p, (tau, dev)) in points.iter().zip(&ours) {
            let m = ms[ours.iter().position(|o| o.0 == *tau).expect("tau")];
            let want = p["oadev"].as_f64().expect("oadev");
            assert!(
                (dev / want - 1.0).abs() < 1e-9,
                "{name} m {m}: {dev} vs allantools {want}"
            );
            let alpha = noise_alpha(&rate, m);
            assert_eq!(
                alpha.map(i64::from),
                p["alpha"].as_i64(),
                "{name} m {m}: noise type"
            );
            let Some(want_edf) = p["edf"].as_f64() else {
                continue;
            };
            let alpha = alpha.expect("identified");
            alphas.insert(alpha);
            let edf = edf_oadev(alpha, m, rate.len() + 1);
            assert!(
                (edf / want_edf - 1.0).abs() < 1e-9,
                "{name} m {m} alpha {alpha}: edf {edf} vs {want_edf}"
            );
            let (lo, hi) = confidence_interval(*dev, edf, ONE_SIGMA);
            for (got, key) in [(lo, "lo"), (hi, "hi")] {
                let want = p[key].as_f64().expect("bound");
                assert!(
                    (got / want - 1.0).abs() < 1e-9,
                    "{name} m {m}: {key} {got} vs {want}"
                );
            }
        }
    }
    // The fixture exercises every branch of the EDF.
    assert_eq!(
        alphas.into_iter().collect::<Vec<_>>(),
        vec![-2, -1, 0, 1, 2]
    );
}

/// Series made from known terms give those terms back.
#[test]
fn the_noise_fit_recovers_known_arw_bias_instability_and_rrw() {
    let tau0: f64 = 0.01;
    let n = 2_000_000;
    let arw = 0.002; // deg/sqrt(h)
    let white = xorshift_gauss(7, n);
    let walk = xorshift_gauss(11, n);
    let k_rrw = 0.05; // deg/h/sqrt(h)
    // Rate random walk: increments of sigma K sqrt(tau0 / 3600) per sample.
    let mut w = 0.0;
    let rate: Vec<f64> = white
        .iter()
        .zip(&walk)
        .map(|(e, g)| {
            w += g * k_rrw * (tau0 / 3600.0).sqrt();
            e * arw * 60.0 / tau0.sqrt() + w
        })
        .collect();
    let a = analyse(&rate, tau0, Taus::Octave);
    let got = a.noise;
    assert!(
        (got.arw_deg_per_rt_h / arw - 1.0).abs() < 0.05,
        "ARW {}",
        got.arw_deg_per_rt_h
    );
    assert!(
        (got.rate_random_walk_dph_per_rt_h / k_rrw - 1.0).abs() < 0.35,
        "RRW {}",
        got.rate_random_walk_dph_per_rt_h
    );
    assert!(got.fit_rms_relative < 0.15, "{got:?}");
    // The two terms put in are resolved; quantization, absent, is not.
    assert!(got.resolved[1].is_resolved(), "{got:?}");
    assert!(got.resolved[3].is_resolved(), "{got:?}");
    assert!(!got.resolved[0].is_resolved(), "{got:?}");
    // Every interval brackets its deviation and narrows with more data.
    for p in &a.points {
        assert!(p.lo < p.adev && p.adev < p.hi, "{p:?}");
    }
    assert!(a.points[0].hi / a.points[0].lo < a.points[10].hi / a.points[10].lo);
}

#[test]
fn a_flicker_floor_reads_as_b_equal_floor_over_0_664() {
    // Pure flicker via the ADEV model: the fit reads B from the floor.
    let points: Vec<Point> = (0..12)
        .map(|k| {
            let tau = 2f64.powi(k);
            let adev = 0.664 * 0.01;
            Point {
                tau_s: tau,
                m: 1 << k,
                adev,
                lo: adev * 0.9,
                hi: adev * 1.1,
                edf: 100.0,
                alpha: -1,
            }
        })
        .collect();
    let f = fit_noise(&points);
    assert!((f.bias_instability_dph / 0.01 - 1.0).abs() < 1e-3, "{f:?}");
    assert!(f.resolved[2].is_resolved(), "{f:?}");
    assert!(f.arw_deg_per_rt_h < 1e-9 && f.quantization_arcsec < 1e-9);
}

/// White rate noise alone has no floor and no rise: bias instability and
/// rate random walk are not resolved (the CLI prints that, never a zero).
#[test]
fn white_noise_resolves_arw_only() {
    let rate: Vec<f64> = xorshift_gauss(3, 100_000)
        .iter()
        .map(|e| e * 0.002 * 60.0 / 0.1f64.sqrt())
        .collect();
    let n = analyse(&rate, 0.1, Taus::Octave).noise;
    assert!(n.resolved[1].is_resolved(), "{n:?}");
    for i in [2, 3] {
        assert!(!n.resolved[i].is_resolved(), "{}: {n:?}", TERM_KEYS[i]);
        assert!(n.resolved[i].reason().is_some());
    }
}

/// A term the fit keeps but the curve barely shows is weak, with the
/// misfit widening its error when the points stray from the model.
#[test]
fn a_term_lost_in_scatter_is_weak_not_resolved() {
    // A flicker floor of 0.001 under white noise of 0.1 at tau 1 s: at the
    // longest tau (1024 s) the floor is a few percent of the curve.
    let points: Vec<Point> = (0..11)
        .map(|k| {
            let tau = 2f64.powi(k);
            let floor = 0.664 * 0.001;
            let wobble = if k % 2 == 0 { 1.15 } else { 0.87 };
            let adev = (0.01 / tau + floor * floor).sqrt() * wobble;
            Point {
                tau_s: tau,
                m: 1 << k,
                adev,
                lo: adev * 0.9,
                hi: adev * 1.1,
                edf: 1000.0,
                alpha: 0,
            }
        })
        .collect();
    let n = fit_noise(&points);
    assert!(n.resolved[1].is_resolved(), "{n:?}");
    assert!(
        matches!(n.resolved[2], Resolved::Weak { misfit, .. } if misfit > 1.0)
            || n.resolved[2] == Resolved::AtZero,
        "{n:?}"
    );
}
