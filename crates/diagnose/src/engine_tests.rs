//! Blocked cross-validation on made-up runs: how the records are cut into
//! folds, that a fold is predicted without its own data, what a fit
//! recovers, and how the paired test scores a regressor that explains the
//! data against one that does not.

use super::*;
use crate::library::{Effect, LIBRARY, MODEL4, Param, Term};
use crate::selection_tests::runs::{POSES, WARMUP_TAU_S, inject, per_row, run, study};

/// Model 4 with the made-up runs' own warm-up time constant.
fn model4() -> Vec<Term> {
    MODEL4
        .iter()
        .map(|&e| match e {
            Effect::SelfHeating => Term::new(e, Param::TauS(WARMUP_TAU_S)),
            _ => Term::new(e, Param::None),
        })
        .collect()
}

/// `model` with `effect` (no parameter) added.
fn with(model: &[Term], effect: Effect) -> Vec<Term> {
    let mut m = model.to_vec();
    m.push(Term::new(effect, Param::None));
    m
}

#[test]
fn folds_are_whole_blocks_of_one_record_of_at_most_15_min_5_in_the_warm_up() {
    let runs = study(0.0, 1);
    let data = Data::new(&runs);
    let rows: Vec<_> = runs.iter().flat_map(|r| &r.samples).collect();
    // The folds tile the rows in order.
    assert_eq!(data.folds[0].start, 0);
    assert_eq!(data.folds.last().map(|f| f.end), Some(rows.len()));
    for w in data.folds.windows(2) {
        assert_eq!(w[0].end, w[1].start);
    }
    for f in &data.folds {
        let len = f.end - f.start;
        let first = rows[f.start];
        let limit = if first.iv.time_s < WARMUP_S {
            WARMUP_FOLD_MAX_S
        } else {
            FOLD_MAX_S
        };
        assert!(len > 0 && len <= limit, "{f:?}");
        assert!(
            (f.start..f.end).all(|i| data.run_of[i] == f.run && rows[i].record == f.record),
            "{f:?}"
        );
    }
    // The made-up records are 15 min long: after the warm-up, one fold
    // each; in it, three.
    let warm = data
        .folds
        .iter()
        .filter(|f| f.run == 0 && f.record == "r0")
        .count();
    assert_eq!(warm, 3);
    assert_eq!(record_ids(&data).last().copied(), Some(18 + 10 - 1));
}

/// Whatever is added to one fold's data moves its held-out residual by
/// exactly that (its prediction comes from the other folds alone), and
/// moves the other folds' predictions (they were fitted with it).
#[test]
fn a_fold_is_predicted_without_its_own_data() {
    let runs = study(0.05, 2);
    let model = with(&model4(), Effect::GSensitivity);
    let before = score(&Data::new(&runs), &model);
    let k = 7;
    let base = Data::new(&runs);
    let f = base.folds[k].clone();
    let mut y = base.y().to_vec();
    let bump = |i: usize| 0.3 * (i as f64 * 0.01).sin() + 0.1;
    for (i, v) in y.iter_mut().enumerate().take(f.end).skip(f.start) {
        *v += bump(i);
    }
    let data = base.with_data(y).expect("one value per row");
    let after = score(&data, &model);
    for i in f.start..f.end {
        let moved = after.held_out[i] - before.held_out[i];
        assert!((moved - bump(i)).abs() < 1e-9, "row {i}: {moved}");
    }
    let other = &data.folds[k + 1];
    assert!(
        (other.start..other.end).any(|i| (after.held_out[i] - before.held_out[i]).abs() > 1e-6)
    );
}

/// A signal made of a g-sensitivity and an offset per run: the fit gives
/// back the coefficients (in the effect's own units, not the scaled
/// design's) and the offsets, and leaves nothing.
#[test]
fn the_fit_gives_back_known_coefficients_and_run_offsets() {
    let runs = study(0.0, 3);
    let signal: Vec<f64> = runs
        .iter()
        .zip([0.5, -0.25])
        .flat_map(|(r, offset)| {
            r.samples
                .iter()
                .map(move |s| offset + 0.2 * s.gravity_body()[1] - 0.1 * s.gravity_body()[2])
        })
        .collect();
    let data = Data::new(&runs).with_data(signal).expect("one per row");
    let s = score(&data, &[Term::new(Effect::GSensitivity, Param::None)]);
    let want = [0.0, 0.2, -0.1, 0.5, -0.25];
    assert_eq!(s.coeffs.len(), want.len());
    for (got, want) in s.coeffs.iter().zip(want) {
        assert!((got - want).abs() < 1e-8, "{:?}", s.coeffs);
    }
    assert!(s.residual.iter().all(|r| r.abs() < 1e-8));
    assert!(s.gap() < 1e-8);
}

/// The standard errors scale with the noise: the same noise twice as large
/// gives the same coefficients' errors twice as large.
#[test]
fn standard_errors_scale_with_the_noise() {
    let runs = study(0.05, 4);
    let noise: Vec<f64> = {
        let quiet = study(0.0, 4);
        per_row(&runs, |s| s.iv.bias_dph())
            .iter()
            .zip(per_row(&quiet, |s| s.iv.bias_dph()))
            .map(|(a, b)| a - b)
            .collect()
    };
    let g = per_row(&runs, |s| 0.2 * s.gravity_body()[1]);
    let model = [Term::new(Effect::GSensitivity, Param::None)];
    let fit = |k: f64| {
        let y = g.iter().zip(&noise).map(|(a, n)| a + k * n).collect();
        score(&Data::new(&runs).with_data(y).expect("one per row"), &model)
    };
    let (one, two) = (fit(1.0), fit(2.0));
    for j in 0..3 {
        let ratio = two.stderr[j] / one.stderr[j];
        assert!((ratio - 2.0).abs() < 1e-6, "term {j}: {ratio}");
    }
    // About the noise's size: 0.05 deg/h at 1 Hz over thousands of rows
    // at each position leaves errors of a few 1e-3 deg/h/g at most.
    assert!(
        one.stderr[1] > 1e-5 && one.stderr[1] < 5e-3,
        "{}",
        one.stderr[1]
    );
    assert!((one.coeffs[1] - 0.2).abs() < 4.0 * one.stderr[1]);
}

/// The held-out gap is the RMS of the held-out 60 s means: their count
/// is each fold's whole minutes.
#[test]
fn the_gap_is_the_rms_of_whole_minutes_held_out() {
    let runs = study(0.05, 5);
    let data = Data::new(&runs);
    let s = score(&data, &model4());
    for (f, &n) in data.folds.iter().zip(&s.fold_blocks) {
        assert_eq!(n, (f.end - f.start) / AVERAGING_S);
    }
    let blocks: usize = s.fold_blocks.iter().sum();
    assert!((s.gap().powi(2) * blocks as f64 - s.sse()).abs() < 1e-12 * s.sse().max(1.0));
    // White noise of 0.05 deg/h at 1 Hz: 60 s means of about 0.05 / sqrt 60.
    let want = 0.05 / (AVERAGING_S as f64).sqrt();
    assert!(
        (s.gap() / want - 1.0).abs() < 0.2,
        "{} against {want}",
        s.gap()
    );
}

/// A regressor that truly explains the data lowers the held-out error by
/// most of the gap, significantly; the same regressor on data it does not
/// explain (model 4 and white noise) gains nothing worth naming and is
/// not significant.
#[test]
fn a_true_regressor_lowers_the_held_out_error_and_a_spurious_one_does_not() {
    let mut runs = study(0.05, 6);
    let quiet = runs.clone();
    inject(
        &mut runs,
        Effect::GSensitivity,
        Param::None,
        &[0.0, 0.05, 0.0],
    );
    for (runs, explains) in [(&runs, true), (&quiet, false)] {
        let data = Data::new(runs);
        let base = score(&data, &model4());
        let better = score(&data, &with(&model4(), Effect::GSensitivity));
        let (gain, p) = improvement(&base, &better);
        assert!((gain - (base.sse() - better.sse())).abs() < 1e-12);
        if explains {
            assert!(gain > 0.8 * base.sse() && p < 1e-6, "{gain} {p}");
        } else {
            assert!(gain < crate::THRESHOLDS.min_gain * base.sse(), "{gain}");
            assert!(p > 0.01, "{p}");
        }
    }
}

/// Degrees of freedom spent on the record means, on the made-up runs: one
/// per run offset; a term constant within every record (gravity, at
/// positions held for whole records) one per parameter; a term that lives
/// within records (the warm-up) less than one.
#[test]
fn record_means_are_spent_by_what_varies_between_records() {
    let runs = study(0.0, 7);
    let data = Data::new(&runs);
    let offsets = score(&data, &[]).between_spent;
    assert!((offsets - 2.0).abs() < 1e-6, "{offsets}");
    let g = score(&data, &with(&[], Effect::GSensitivity)).between_spent;
    assert!((g - 5.0).abs() < 1e-6, "{g}");
    let warm = score(&data, &[Term::new(Effect::SelfHeating, Param::TauS(150.0))]);
    assert!(warm.between_spent > 2.0 && warm.between_spent < 3.0);
}

/// The warm-up's time constant is chosen on the grid, and moved to the
/// geometric middle toward a neighbour when the truth lies there.
#[test]
fn a_parameter_is_chosen_on_its_grid_and_refined_between_its_values() {
    let runs = study(0.0, 8);
    for tau in [1200.0, (1200.0f64 * 2400.0).sqrt()] {
        let y = per_row(&runs, |s| 0.05 * (-s.iv.time_s / tau).exp());
        let data = Data::new(&runs).with_data(y).expect("one per row");
        let m = with_best_parameter(&data, &[], Effect::SelfHeating, &[]);
        assert_eq!(m, [Term::new(Effect::SelfHeating, Param::TauS(tau))]);
    }
}

/// An effect whose regressors are constant in every run is the run offset
/// again: gravity in runs at one position is not identifiable, at several
/// it is.
#[test]
fn only_effects_that_vary_within_a_run_are_identifiable() {
    let still = [run(
        "up",
        &[20.0; 3600],
        &[(0.0, 90.0, 0.0)],
        900,
        0.0,
        0.0,
        1,
    )];
    let turned = [run("turned", &[20.0; 3600], &POSES, 300, 0.0, 0.0, 1)];
    for e in [Effect::GSensitivity, Effect::MagneticSensitivity] {
        assert!(!identifiable(&Data::new(&still), e, Param::None), "{e:?}");
        assert!(identifiable(&Data::new(&turned), e, Param::None), "{e:?}");
    }
    // Time is not: the warm-up varies in any run.
    let tau = Effect::SelfHeating.grid()[0];
    assert!(identifiable(&Data::new(&still), Effect::SelfHeating, tau));
}

/// The outside disturbances' columns: a step from its row to the end of
/// its run only, a drift through one run in hours about its middle, a
/// sine and cosine through one run; zero elsewhere.
#[test]
fn outside_disturbances_act_in_their_own_run_only() {
    let runs = study(0.0, 9);
    let data = Data::new(&runs);
    let n0 = runs[0].samples.len();
    let n = data.y().len();
    let k = 1000;
    let step = data.outside_columns(Effect::BiasStep, Param::Row(k));
    assert!(step[0][..k].iter().all(|&v| v == 0.0));
    assert!(step[0][k..n0].iter().all(|&v| v == 1.0));
    assert!(step[0][n0..].iter().all(|&v| v == 0.0));
    let drift = data.outside_columns(Effect::BiasDrift, Param::Run(1));
    assert!(drift[0][..n0].iter().all(|&v| v == 0.0));
    let mean = drift[0][n0..].iter().sum::<f64>() / (n - n0) as f64;
    assert!(mean.abs() < 1e-9, "{mean}");
    let slope = (drift[0][n - 1] - drift[0][n0]) / (runs[1].samples.len() - 1) as f64;
    assert!((slope - 1.0 / 3600.0).abs() < 1e-12, "{slope}");
    let sine = data.outside_columns(
        Effect::Periodic,
        Param::Periodic {
            run: 0,
            period_s: 3600.0,
        },
    );
    assert_eq!(sine.len(), 2);
    assert!(sine.iter().all(|c| c[n0..].iter().all(|&v| v == 0.0)));
    let t = runs[0].samples[10].iv.time_s;
    assert!((sine[0][10] - (std::f64::consts::TAU * t / 3600.0).sin()).abs() < 1e-12);
    // A parameter of another kind gives zero columns, never a panic.
    let wrong = data.outside_columns(Effect::BiasStep, Param::Run(0));
    assert!(wrong[0].iter().all(|&v| v == 0.0));
}

/// The nested F-test: no improvement, no evidence; a large one, strong
/// evidence. The long-run variance factor: one for white noise (and never
/// below one), above one for a slow wander, and lags never reach across
/// runs.
#[test]
fn the_tests_statistics_behave_at_their_edges() {
    assert_eq!(f_test(1.0, 1.0, 1.0, 100.0), 1.0);
    assert_eq!(f_test(1.0, 2.0, 1.0, 100.0), 1.0);
    assert_eq!(f_test(2.0, 1.0, 1.0, 0.5), 1.0);
    let strong = f_test(10.0, 1.0, 1.0, 100.0);
    let weak = f_test(1.005, 1.0, 1.0, 100.0);
    assert!(
        strong < 1e-10 && weak > 0.1 && weak < 1.0,
        "{strong} {weak}"
    );
    let alternating: Vec<(usize, f64)> = (0..100)
        .map(|i| (0, if i % 2 == 0 { 1.0 } else { -1.0 }))
        .collect();
    assert_eq!(long_run_factor(&alternating, 5), 1.0);
    let wander: Vec<(usize, f64)> = (0..200).map(|i| (0, (i as f64 / 30.0).sin())).collect();
    assert!(long_run_factor(&wander, 5) > 4.0);
    // The same values, each in a run of its own: no lag pairs them.
    let apart: Vec<(usize, f64)> = wander.iter().enumerate().map(|(i, x)| (i, x.1)).collect();
    assert_eq!(long_run_factor(&apart, 5), 1.0);
}

/// Every library effect scores on the made-up runs without a panic and
/// with finite figures (the grid's first parameter).
#[test]
fn every_library_effect_scores_finitely() {
    let runs = study(0.05, 10);
    let data = Data::new(&runs);
    let base = score(&data, &model4());
    for e in LIBRARY {
        let mut m = model4();
        if !m.iter().any(|t| t.effect == e) {
            m.push(Term::new(e, e.grid()[0]));
        }
        let s = score(&data, &m);
        let (gain, p) = improvement(&base, &s);
        assert!(s.gap().is_finite() && gain.is_finite(), "{e:?}");
        assert!((0.0..=1.0).contains(&p), "{e:?}: {p}");
    }
}
