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
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/allan");
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
    assert!(f.arw_deg_per_rt_h < 1e-9 && f.quantization_arcsec < 1e-9);
}
