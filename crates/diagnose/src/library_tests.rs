//! The candidate effects' regressors against their definitions on made-up
//! inputs: the play and the lag on known temperature histories, the
//! positional effects at known orientations, and the names and pairs the
//! report gives.

use super::*;
use crate::selection_tests::runs::run;

/// A run at one position (axis up) whose case temperature is `case(t)`.
fn with_case(len: usize, case: impl Fn(f64) -> f64) -> RunData {
    let mut r = run(
        "case",
        &vec![20.0; len],
        &[(0.0, 90.0, 0.0)],
        900,
        0.0,
        0.0,
        1,
    );
    for s in &mut r.samples {
        s.iv.tcase_c = case(s.iv.time_s);
    }
    r
}

#[test]
fn every_effect_is_found_by_its_library_name_and_no_other() {
    let named: Vec<Effect> = LIBRARY.iter().chain(&[Effect::Gradient]).copied().collect();
    for &e in &named {
        assert_eq!(Effect::from_name(e.name()), Some(e));
    }
    let mut names: Vec<&str> = named.iter().map(|e| e.name()).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), named.len());
    // Outside disturbances are never taken by name (never an effect).
    for e in [Effect::BiasStep, Effect::BiasDrift, Effect::Periodic] {
        assert!(e.is_outside());
        assert_eq!(Effect::from_name(e.name()), None);
    }
    assert!(LIBRARY.iter().all(|e| !e.is_outside()));
    assert_eq!(Effect::from_name("nonsense"), None);
}

/// Each effect gives one column per named term, one value per sample;
/// its complexity counts them and its nonlinear parameter.
#[test]
fn every_effect_has_one_column_per_term_and_sample() {
    let r = run("r", &[20.0; 500], &[(0.0, 90.0, 0.0)], 900, 0.0, 0.0, 1);
    let all = LIBRARY.iter().chain(&[
        Effect::Gradient,
        Effect::BiasStep,
        Effect::BiasDrift,
        Effect::Periodic,
    ]);
    for &e in all {
        let cols = e.columns(&r, e.grid()[0]);
        assert_eq!(cols.len(), e.terms().len(), "{e:?}");
        assert!(cols.iter().all(|c| c.len() == r.samples.len()), "{e:?}");
        assert_eq!(
            e.complexity(),
            e.terms().len() + usize::from(e.parameter().is_some())
        );
        assert_eq!(e.grid().len() > 1, e.parameter().is_some(), "{e:?}");
    }
}

/// The play on a case temperature that rises 10 degC and falls back: once
/// it has moved a width, the output sits at -1 rising and +1 falling;
/// after the turn it crosses over linearly, one width per two; never
/// outside -1..1.
#[test]
fn the_play_follows_its_width_and_remembers_the_direction() {
    let w = 2.0;
    let r = with_case(2000, |t| 20.0 + 10.0 * (1.0 - (t / 1000.0 - 1.0).abs()));
    let p = Param::Memory {
        on: EffectTemperature::Case,
        value: w,
    };
    let col = &Effect::Hysteresis.columns(&r, p)[0];
    assert!(col.iter().all(|v| (-1.0..=1.0).contains(v)));
    let at = |t: usize| col[t];
    // Rising, past the width (0.01 degC per s: 200 s).
    assert!((at(500) + 1.0).abs() < 1e-9, "{}", at(500));
    // Falling, past the width again.
    assert!((at(1500) - 1.0).abs() < 1e-9, "{}", at(1500));
    // Half-way through the turn: the temperature fell one width from its
    // top (0.01 degC per s: 200 s), the output crosses zero.
    assert!(at(1200).abs() < 0.01, "{}", at(1200));
    assert!((at(1100) + 0.5).abs() < 0.01, "{}", at(1100));
    // A narrower play has turned over by then.
    let narrow = Param::Memory {
        on: EffectTemperature::Case,
        value: 0.25,
    };
    assert!((Effect::Hysteresis.columns(&r, narrow)[0][1100] - 1.0).abs() < 1e-9);
}

/// The lag of a step of the case temperature: the exponential approach of
/// its time constant.
#[test]
fn the_lag_is_a_first_order_approach_of_its_time_constant() {
    let tau = 300.0;
    let r = with_case(2000, |t| if t < 1.0 { 20.0 } else { 30.0 });
    let p = Param::Memory {
        on: EffectTemperature::Case,
        value: tau,
    };
    let col = &Effect::ThermalLag.columns(&r, p)[0];
    assert_eq!(col[0], 20.0);
    for k in [1usize, 100, 300, 1000] {
        let want = 30.0 - 10.0 * (-(k as f64) / tau).exp();
        assert!(
            (col[k] - want).abs() < 1e-9,
            "{k}: {} against {want}",
            col[k]
        );
    }
    // On the block (the mean of T1 and T2), it starts from those.
    let block = Param::Memory {
        on: EffectTemperature::Block,
        value: tau,
    };
    let b = &Effect::ThermalLag.columns(&r, block)[0];
    let s = &r.samples[0];
    assert_eq!(b[0], 0.5 * (s.iv.t1_c + s.iv.t2_c));
    assert!((b[1000] - col[1000]).abs() > 1.0);
}

/// The positional regressors at known orientations: gravity along the
/// sensitive axis is -1 g axis up and +1 g axis down; the misalignment's
/// terms are the Earth rate across the axis; the scale-factor drift is
/// the reference times the block above 20 degC.
#[test]
fn positional_regressors_are_the_fields_in_the_body_frame() {
    let poses = [(0.0, 90.0, 0.0), (0.0, -90.0, 0.0), (90.0, 0.0, 0.0)];
    let r = run("p", &[20.0; 30], &poses, 10, 0.0, 0.0, 1);
    let g = Effect::GSensitivity.columns(&r, Param::None);
    assert!((g[0][0] + 1.0).abs() < 1e-12 && (g[0][10] - 1.0).abs() < 1e-12);
    assert!(g[0][20].abs() < 1e-12 && (g[2][20] - 1.0).abs() < 1e-12);
    let site = &r.site;
    let m = Effect::AxisMisalignment.columns(&r, Param::None);
    for i in [0, 10, 20] {
        let w = r.samples[i].earth_rate_body(site);
        assert!((m[0][i] - w[1]).abs() < 1e-12 && (m[1][i] - w[2]).abs() < 1e-12);
        // The axis's own share is the reference, not a misalignment.
        assert!((w[0] - r.samples[i].iv.reference_dph).abs() < 1e-9);
    }
    let sf = Effect::ScaleFactorTemperature.columns(&r, Param::None);
    let s = &r.samples[5];
    let want = s.iv.reference_dph * (0.5 * (s.iv.t1_c + s.iv.t2_c) - 20.0);
    assert!((sf[0][5] - want).abs() < 1e-12);
    let warm = Effect::SelfHeating.columns(&r, Param::TauS(150.0));
    assert!((warm[0][5] - (-r.samples[5].iv.time_s / 150.0).exp()).abs() < 1e-15);
}

/// model 4's gradient rate of a block gradient that ramps at a known
/// rate is that rate.
#[test]
fn the_gradient_rate_of_a_ramp_is_its_slope() {
    let mut r = run("g", &[20.0; 600], &[(0.0, 90.0, 0.0)], 900, 0.0, 0.0, 1);
    for s in &mut r.samples {
        s.iv.t1_c = s.iv.t2_c + 0.002 * s.iv.time_s;
    }
    let col = &Effect::GradientRate.columns(&r, Param::None)[0];
    assert!(
        col.iter().all(|v| (v - 0.002).abs() < 1e-9),
        "{:?}",
        &col[..3]
    );
}

/// Which run separates a pair does not depend on the pair's order, and
/// the pairs the documentation names get their runs.
#[test]
fn the_separating_run_is_the_pairs_whatever_its_order() {
    for &a in &LIBRARY {
        for &b in &LIBRARY {
            assert_eq!(separate_with(a, b), separate_with(b, a), "{a:?} {b:?}");
            assert_eq!(separating_procedure(a, b), separating_procedure(b, a));
        }
    }
    use Effect::*;
    assert_eq!(
        separating_procedure(GSensitivity, AxisMisalignment),
        Some("procedures/misalignment.toml")
    );
    assert_eq!(
        separating_procedure(ScaleFactorTemperature, ThermalLag),
        Some("procedures/separating.toml")
    );
    assert_eq!(separating_procedure(Hysteresis, ThermalLag), None);
    assert!(separate_with(Hysteresis, ThermalLag).contains("long soak"));
}

/// The grids span what the documentation gives, increasing, on each of
/// the three temperatures for a memory effect.
#[test]
fn the_grids_span_their_documented_ranges() {
    let values = |e: Effect| -> Vec<f64> { e.grid().iter().map(|p| p.value()).collect() };
    let heat = values(Effect::SelfHeating);
    assert_eq!((heat[0], heat[heat.len() - 1]), (150.0, 4800.0));
    assert!(heat.windows(2).all(|w| w[0] < w[1]));
    for (e, lo, hi) in [
        (Effect::Hysteresis, 0.5, 16.0),
        (Effect::ThermalLag, 300.0, 14_400.0),
    ] {
        for on in EffectTemperature::ALL {
            let v: Vec<f64> = e
                .grid()
                .iter()
                .filter(|p| p.temperature() == Some(on))
                .map(|p| p.value())
                .collect();
            assert_eq!((v[0], v[v.len() - 1]), (lo, hi), "{e:?} on {on:?}");
            assert!(v.windows(2).all(|w| w[0] < w[1]));
        }
    }
}
