//! Tests that catch a broken twin: kinematics, quantization, determinism,
//! and each extra effect acting only where its physics says.

use super::*;
use gyrobench_model::geometry::EARTH_RATE_DPH;

/// A twin whose output is exactly the kinematic rate: no bias, no noise.
fn quiet() -> TwinConfig {
    let mut c = TwinConfig::default_rl16();
    c.bias.turn_on_sigma_dph = 0.0;
    let b = &mut c.bias.model4;
    b.offset_dph = 0.0;
    (b.k1_dph_per_c, b.k2_dph_per_c2, b.k3_dph_per_c_per_s) = (0.0, 0.0, 0.0);
    (b.k4_dph_per_c, b.k5_dph) = (0.0, 0.0);
    c.noise.arw_deg_per_rt_h = 0.0;
    c.noise.bias_instability_dph = 0.0;
    c.thermal.sensor_noise_c = 0.0;
    c
}

fn at(mut c: TwinConfig, outer: f64, inner: f64) -> TwinConfig {
    c.table.initial = TableAngles {
        outer_deg: outer,
        inner_deg: inner,
    };
    c
}

/// Mean output rate over `[from_s, to_s)` from the counts, deg/h.
fn mean_rate(twin: &mut Twin, from_s: f64, to_s: f64) -> f64 {
    twin.run_until(from_s, |_, _| {});
    let lsb = twin.config().gyro.lsb_arcsec;
    let mut counts: i64 = 0;
    twin.run_until(to_s, |_, g| counts += i64::from(g.delta_counts));
    counts as f64 * lsb / (to_s - from_s)
}

const NINE: [(f64, f64); 9] = [
    (90.0, 0.0),
    (90.0, 90.0),
    (90.0, 180.0),
    (90.0, 270.0),
    (0.0, 0.0),
    (0.0, 90.0),
    (0.0, 180.0),
    (0.0, 270.0),
    (35.0, 0.0),
];

#[test]
fn earth_rate_in_each_of_the_nine_positions_matches_the_closed_form() {
    let site = TwinConfig::default_rl16().site;
    let phi = site.latitude_deg.to_radians();
    for (outer, inner) in NINE {
        let mut twin = Twin::new(at(quiet(), outer, inner), 1);
        let o = twin.orientation();
        let (e, psi) = (o.elevation_deg.to_radians(), o.azimuth_deg.to_radians());
        let want = EARTH_RATE_DPH * (e.sin() * phi.sin() + e.cos() * psi.cos() * phi.cos());
        let got = mean_rate(&mut twin, 0.0, 200.0);
        // One LSB over 200 s is 0.00125 deg/h.
        assert!(
            (got - want).abs() < 0.002,
            "outer {outer} inner {inner}: {got} vs {want}"
        );
    }
}

#[test]
fn table_rotation_adds_its_rate_on_the_sensitive_axis() {
    let mut twin = Twin::new(at(quiet(), 90.0, 0.0), 1);
    twin.demand_table(None, Some(AxisDemand::Rate(10.0)));
    let earth = EARTH_RATE_DPH
        * TwinConfig::default_rl16()
            .site
            .latitude_deg
            .to_radians()
            .sin();
    // After the 1 s acceleration the inner axis turns at 10 deg/s = 36000 deg/h.
    let got = mean_rate(&mut twin, 5.0, 65.0);
    assert!((got - (36_000.0 + earth)).abs() < 0.01, "{got}");
}

#[test]
fn no_angle_is_lost_to_quantization_over_ten_million_frames() {
    let mut c = TwinConfig::default_rl16();
    c.gyro.lsb_arcsec = 1.7; // coarse, so that every frame leaves a residual
    let mut twin = Twin::new(c, 3);
    twin.demand_table(Some(AxisDemand::Rate(1.3)), Some(AxisDemand::Rate(-7.1)));
    let mut counts: i64 = 0;
    let mut frames = 0u64;
    let end_s = 10_000_000.0 / 400.0;
    twin.run_until(end_s, |_, g| {
        counts += i64::from(g.delta_counts);
        frames += 1;
    });
    assert_eq!(frames, 10_000_000);
    let fed = twin.truth().angle_arcsec;
    let out = counts as f64 * 1.7;
    assert!(fed.abs() > 1e8, "the test must move a large angle: {fed}");
    assert!((out - fed).abs() < 1.7, "counts {out} vs fed {fed} arcsec");
}

/// A frame clock off nominal: more (or fewer) frames in the same device
/// time, each covering that much less (more) of it, and the same angle
/// in all of them; the frames' own clock reads the rate off by the error.
#[test]
fn a_frame_clock_error_changes_the_frames_not_the_angle() {
    let frames = |ppm: f64| {
        let mut c = TwinConfig::default_rl16();
        c.gyro.frame_clock_error_ppm = ppm;
        let mut twin = Twin::new(c, 5);
        twin.demand_table(None, Some(AxisDemand::Rate(50.0)));
        let mut v = Vec::new();
        twin.run_until(1000.0, |_, g| v.push(*g));
        (v, twin.truth().angle_arcsec)
    };
    let counts = |v: &[GyroSample]| v.iter().map(|g| i64::from(g.delta_counts)).sum::<i64>();
    let (nominal, fed) = frames(0.0);
    assert_eq!(nominal.len(), 400_000);
    for ppm in [50.0, -50.0, 1000.0, -1000.0] {
        let (v, fed_here) = frames(ppm);
        // 400 000 (1 + e) frames, one either way for where the last fell.
        let want = 400_000.0 * (1.0 + ppm * 1e-6);
        assert!(
            (v.len() as f64 - want).abs() <= 1.0,
            "{ppm} ppm: {} frames",
            v.len()
        );
        // Numbered without a gap, each later than the one before.
        assert!(
            v.windows(2).all(|w| w[1].index == w[0].index + 1),
            "{ppm} ppm"
        );
        assert!(v.windows(2).all(|w| w[1].time_s > w[0].time_s), "{ppm} ppm");
        // The same physics (seed, noise) fed the same angle; the counts
        // hold it to within the part of a frame not yet sent.
        assert_eq!(fed_here, fed, "{ppm} ppm");
        let lsb = 0.25;
        let per_frame = 50.0 * 3600.0 / 400.0;
        let lag = fed - counts(&v) as f64 * lsb;
        assert!(
            lag > -lsb && lag < per_frame + lsb,
            "{ppm} ppm: {lag} arcsec behind"
        );
        // Counts over frames taken at the nominal period read the rate
        // off by the error: -e for a fast clock.
        let naive = counts(&v) as f64 * lsb / (v.len() as f64 / 400.0);
        let truth = counts(&nominal) as f64 * lsb / 1000.0;
        let err_ppm = (naive / truth - 1.0) * 1e6;
        assert!(
            (err_ppm + ppm).abs() < 0.5 + 1e-3 * ppm.abs(),
            "{ppm} ppm reads {err_ppm}"
        );
    }
}

#[test]
fn same_seed_same_frames_other_seed_other_frames() {
    let frames = |seed| {
        let mut twin = Twin::new(TwinConfig::default_rl16(), seed);
        twin.set_chamber(40.0, 2.0).expect("within limits");
        twin.move_table(TableAngles {
            outer_deg: 0.0,
            inner_deg: 90.0,
        });
        let mut v = Vec::new();
        twin.run_until(300.0, |_, g| v.push(*g));
        v
    };
    let a = frames(11);
    assert_eq!(a.len(), 120_000);
    assert!(a == frames(11), "same seed must reproduce every frame");
    assert!(a != frames(12), "another seed must give other noise");
}

#[test]
fn turn_on_bias_differs_from_power_on_to_power_on() {
    let mut c = quiet();
    c.bias.turn_on_sigma_dph = 0.05;
    let mut twin = Twin::new(c, 5);
    let earth = twin.truth().kinematic_dph;
    let first = twin.truth().bias_dph;
    twin.power_off();
    twin.run_until(10.0, |_, _| {});
    twin.power_on();
    let second = twin.truth().bias_dph;
    assert!((first - second).abs() > 1e-4, "{first} vs {second}");
    assert!((twin.truth().kinematic_dph - earth).abs() < 1e-12);
}

#[test]
fn self_heating_term_decays_with_the_warmup_time_constant() {
    let mut c = quiet();
    c.bias.model4.k5_dph = 0.5;
    let tau_w = c.bias.model4.warmup_tau_s;
    let mut twin = Twin::new(c.clone(), 1);
    let b0 = twin.truth().bias_dph;
    twin.run_until(tau_w, |_, _| {});
    let b1 = twin.truth().bias_dph;
    assert!((b0 - 0.5).abs() < 1e-9);
    assert!((b1 - 0.5 / std::f64::consts::E).abs() < 1e-3, "{b1}");
    // Switched off, the same K5 does nothing.
    c.bias.terms.self_heating = false;
    assert_eq!(Twin::new(c, 1).truth().bias_dph, 0.0);
}

#[test]
fn gradient_moves_at_constant_chamber_temperature_after_power_on() {
    let mut twin = Twin::new(TwinConfig::default_rl16(), 1);
    let dt0 = twin.truth().t1_c - twin.truth().t2_c;
    twin.run_until(1800.0, |_, _| {});
    let tr = twin.truth();
    assert!((tr.air_c - 20.0).abs() < 1e-9, "chamber stays at +20 degC");
    assert!(
        tr.t1_c - tr.t2_c - dt0 > 0.3,
        "self-heating must open a gradient"
    );
}

/// Mean rate in each of the nine positions with `effect` on, minus off.
fn effect_deltas(enable: impl Fn(&mut TwinConfig)) -> Vec<f64> {
    NINE.iter()
        .map(|&(outer, inner)| {
            let base = at(TwinConfig::default_rl16(), outer, inner);
            let mut with = base.clone();
            enable(&mut with);
            // Same seed: the noise cancels and the difference is the effect.
            let off = mean_rate(&mut Twin::new(base, 9), 0.0, 120.0);
            let on = mean_rate(&mut Twin::new(with, 9), 0.0, 120.0);
            on - off
        })
        .collect()
}

fn spread(x: &[f64]) -> f64 {
    gyrobench_analysis::figures::peak_to_peak(x)
}

#[test]
fn g_sensitivity_moves_bias_between_rolls_not_between_azimuths() {
    let d = effect_deltas(|c| {
        let g = c.effects.g_sensitivity.as_mut().expect("fixture section");
        g.enabled = true;
        g.coeff_dph_per_g = [0.0, 0.05, 0.03];
    });
    assert!(spread(&d[0..4]) < 0.005, "azimuths, axis up: {d:?}");
    assert!(spread(&d[4..8]) > 0.09, "rolls, axis horizontal: {d:?}");
}

#[test]
fn magnetic_sensitivity_moves_bias_between_azimuths_with_axis_up() {
    let d = effect_deltas(|c| {
        let m = c
            .effects
            .magnetic_sensitivity
            .as_mut()
            .expect("fixture section");
        m.enabled = true;
        m.coeff_dph_per_ut = [0.0, 0.002, 0.002];
    });
    // Horizontal field 19.7 uT turns around the housing: +-0.039 deg/h.
    assert!(spread(&d[0..4]) > 0.06, "azimuths: {d:?}");
}

#[test]
fn axis_misalignment_changes_the_earth_rate_projection() {
    let d = effect_deltas(|c| {
        let a = c
            .effects
            .axis_misalignment
            .as_mut()
            .expect("fixture section");
        a.enabled = true;
        (a.about_y_arcmin, a.about_z_arcmin) = (0.0, -20.0);
    });
    // Axis east, tilted 20' towards north: W cos(phi) * 5.8e-3 = 0.056 deg/h.
    let want = EARTH_RATE_DPH * 50.45f64.to_radians().cos() * (20.0 / 60.0f64).to_radians();
    for &k in &[4usize, 6] {
        assert!(
            (d[k].abs() - want).abs() < 0.01,
            "position {k}: {d:?} vs {want}"
        );
    }
}

#[test]
fn an_earth_rate_error_is_read_along_the_axis_as_a_vector_fixed_on_the_bench() {
    let d = effect_deltas(|c| {
        c.effects.earth_rate_error = Some(crate::twin::config::EarthRateError {
            enabled: true,
            latitude_dph: 0.1,
            east_dph: 0.05,
        });
    });
    // Axis up: the turned part (-sin lat, 0, -cos lat) reads 0.1 cos lat
    // at every azimuth; axis east or west: the east part, +-0.05, at
    // every roll.
    let up = 0.1 * 50.45f64.to_radians().cos();
    for (k, x) in d[0..4].iter().enumerate() {
        assert!((x - up).abs() < 0.003, "azimuth {k}: {d:?} vs {up}");
    }
    for (k, x) in d[4..8].iter().enumerate() {
        assert!((x.abs() - 0.05).abs() < 0.003, "roll {k}: {d:?}");
    }
    assert!(spread(&d[4..8]) < 0.003, "rolls: {d:?}");
}

#[test]
fn scale_factor_temperature_shows_under_rotation_not_at_rest() {
    let run = |enabled: bool, rotate: bool| {
        let mut c = at(TwinConfig::default_rl16(), 90.0, 0.0);
        c.chamber.initial_c = 50.0;
        let s = c
            .effects
            .scale_factor_temperature
            .as_mut()
            .expect("fixture section");
        (s.enabled, s.ppm_per_c) = (enabled, 10.0);
        let mut twin = Twin::new(c, 4);
        if rotate {
            twin.demand_table(None, Some(AxisDemand::Rate(10.0)));
        }
        mean_rate(&mut twin, 5.0, 65.0)
    };
    let at_rest = run(true, false) - run(false, false);
    let rotating = run(true, true) - run(false, true);
    // ~35 degC above reference * 10 ppm * 36000 deg/h = ~12 deg/h.
    assert!(rotating > 10.0, "{rotating}");
    assert!(at_rest.abs() < 0.01, "{at_rest}");
}

#[test]
fn hysteresis_separates_heating_from_cooling() {
    let bias_after = |enabled: bool, set_c: f64| {
        let mut c = TwinConfig::default_rl16();
        let h = c.effects.hysteresis.as_mut().expect("fixture section");
        h.enabled = enabled;
        let mut twin = Twin::new(c, 2);
        twin.set_chamber(set_c, 1.0).expect("within limits");
        twin.run_until(3600.0, |_, _| {});
        twin.truth().bias_dph
    };
    let heating = bias_after(true, 50.0) - bias_after(false, 50.0);
    let cooling = bias_after(true, -10.0) - bias_after(false, -10.0);
    let amp = TwinConfig::default_rl16()
        .effects
        .hysteresis
        .expect("fixture section")
        .amplitude_dph;
    assert!((heating + amp).abs() < 1e-9, "{heating}");
    assert!((cooling - amp).abs() < 1e-9, "{cooling}");
}

#[test]
fn thermal_lag_trails_the_case_temperature() {
    let mut c = TwinConfig::default_rl16();
    let l = c.effects.thermal_lag.as_mut().expect("fixture section");
    l.enabled = true;
    let (coeff, reference) = (l.coeff_dph_per_c, l.reference_c);
    let mut on = Twin::new(c, 2);
    let mut off = Twin::new(TwinConfig::default_rl16(), 2);
    for twin in [&mut on, &mut off] {
        twin.set_chamber(50.0, 1.0).expect("within limits");
        twin.run_until(3600.0, |_, _| {});
    }
    let delta = on.truth().bias_dph - off.truth().bias_dph;
    let lagged = delta / coeff + reference;
    let case = on.truth().case_c;
    assert!(
        lagged > reference + 1.0,
        "the lag must have moved: {lagged}"
    );
    assert!(lagged < case - 1.0, "and trail the case ({case}): {lagged}");
}

/// Non-overlapping Allan deviation of a 1 Hz series at `m` samples.
fn adev(x: &[f64], m: usize) -> f64 {
    let means = gyrobench_analysis::figures::block_means(x, m);
    let d: Vec<f64> = means.windows(2).map(|w| w[1] - w[0]).collect();
    (0.5 * d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt()
}

/// 1 Hz output rates of a quiet twin with the given noise, deg/h.
fn noise_series(arw: f64, bi: f64, hours: f64) -> Vec<f64> {
    let mut c = quiet();
    c.noise.arw_deg_per_rt_h = arw;
    c.noise.bias_instability_dph = bi;
    c.gyro.lsb_arcsec = 1e-4; // keep quantization far below the noise
    let lsb = c.gyro.lsb_arcsec;
    let mut twin = Twin::new(c, 21);
    let mut out = Vec::new();
    let mut acc: i64 = 0;
    twin.run_until(hours * 3600.0, |_, g| {
        acc += i64::from(g.delta_counts);
        if g.index % 400 == 0 {
            out.push(acc as f64 * lsb);
            acc = 0;
        }
    });
    out
}

#[test]
fn angle_random_walk_has_the_configured_coefficient() {
    // ADEV(tau) = N * 60 / sqrt(tau) for white rate noise.
    let x = noise_series(0.003, 0.0, 3.0);
    for tau in [1usize, 10] {
        let want = 0.003 * 60.0 / (tau as f64).sqrt();
        let got = adev(&x, tau);
        assert!((got / want - 1.0).abs() < 0.1, "tau {tau}: {got} vs {want}");
    }
}

#[test]
fn bias_instability_sets_the_allan_floor() {
    // Flicker: flat ADEV at 0.664 B over the middle of its band.
    let b = 0.01;
    let x = noise_series(0.0, b, 60.0);
    for tau in [30usize, 300] {
        let got = adev(&x, tau);
        assert!((got / (0.664 * b) - 1.0).abs() < 0.25, "tau {tau}: {got}");
    }
}

/// The path-length control resets each time the blocks have moved
/// `reset_span_c` since the last reset: out of lock for `relock_s` (the
/// status word's lock bit clear, the other bits set), and the bias steps
/// by `mode_bias_dph` onto the other mode and back at the next reset.
#[test]
fn the_path_length_control_resets_on_the_blocks_span_and_hops_mode() {
    let mut c = quiet();
    c.path_length_control.reset_span_c = 10.0;
    c.path_length_control.relock_s = 0.5;
    c.path_length_control.mode_bias_dph = 0.2;
    let mut twin = Twin::new(c, 3);
    twin.set_chamber(50.0, 3.0).expect("within the chamber");
    let mut resets: Vec<(f64, f64)> = Vec::new();
    let mut out_of_lock = 0u64;
    // Before the first frame: no lock to lose (the acquisition is not a reset).
    let mut last = 0;
    let mut bias = Vec::new();
    twin.run_until(4.0 * 3600.0, |t, g| {
        let lost = g.status & status::PATH_LENGTH_LOCK == 0;
        if lost {
            out_of_lock += 1;
            assert_eq!(g.status, status::NOMINAL & !status::PATH_LENGTH_LOCK);
        }
        if lost && last & status::PATH_LENGTH_LOCK != 0 {
            let tr = t.truth();
            resets.push((g.time_s, 0.5 * (tr.t1_c + tr.t2_c)));
            bias.push(tr.bias_dph);
        }
        last = g.status;
    });
    // From about +20 to +50 degC: three resets 10 degC apart.
    assert_eq!(resets.len(), 3, "{resets:?}");
    for w in resets.windows(2) {
        assert!((w[1].1 - w[0].1 - 10.0).abs() < 0.05, "{resets:?}");
    }
    // The acquisition at power-on and each reset, 0.5 s at 400 Hz.
    assert_eq!(out_of_lock, 4 * 200);
    // The bias alternates between the two modes (the rest of it is the
    // quiet twin's zero).
    assert!(
        (bias[0] - 0.2).abs() < 1e-9 && bias[1].abs() < 1e-9,
        "{bias:?}"
    );
    assert!((bias[2] - 0.2).abs() < 1e-9, "{bias:?}");
}
