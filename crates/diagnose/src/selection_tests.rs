//! The selection on made-up runs with a known answer: an effect injected
//! at a known size is named and fitted, nothing is named where nothing
//! was injected, and what the runs cannot tell apart is reported as such.

#[path = "test_runs.rs"]
pub(crate) mod runs;

use super::*;
use runs::{ROLLS_EAST, cycle_air, inject, per_row, run, study};

/// Model 4 as the reference, no simulated deciding run.
fn options() -> Options {
    Options {
        twin: None,
        fit_thermal: false,
        power_replications: 0,
    }
}

fn named(d: &Diagnosis) -> Vec<&str> {
    d.effects.iter().map(|a| a.name.as_str()).collect()
}

/// A g-sensitivity of (0, 0.08, -0.06) deg/h/g over noise of 0.05 deg/h at
/// 1 Hz: named alone, its coefficients within a few standard errors, most
/// of the gap closed, and the twin updated with it.
#[test]
fn an_injected_g_sensitivity_is_named_and_fitted() {
    let mut runs = study(0.05, 11);
    let truth = [0.0, 0.08, -0.06];
    inject(&mut runs, Effect::GSensitivity, Param::None, &truth);
    let d = diagnose_rate(&runs, &options());
    assert_eq!(named(&d), ["g_sensitivity"], "{:?}", d.candidates);
    let a = &d.effects[0];
    for (k, want) in ["x_dph_per_g", "y_dph_per_g", "z_dph_per_g"]
        .iter()
        .zip(truth)
    {
        let (got, err) = (a.parameters[*k], a.uncertainties[*k]);
        assert!(
            (got - want).abs() < 4.0 * err + 1e-3,
            "{k}: {got} +- {err} against {want}"
        );
    }
    let rate = &d.layers.rate;
    assert!(
        rate.gap_after_dph < 0.3 * rate.gap_dph,
        "{} -> {}",
        rate.gap_dph,
        rate.gap_after_dph
    );
    let twin = updated_twin(&TwinConfig::default_rl16(), &d);
    let g = twin.effects.g_sensitivity.expect("enabled");
    assert!(g.enabled);
    assert!((g.coeff_dph_per_g[1] - 0.08).abs() < 0.005, "{g:?}");
}

/// The same runs with nothing injected: only model 4 and white noise.
/// Nothing is named, held or said to be confounded.
#[test]
fn nothing_is_named_where_nothing_was_injected() {
    let runs = study(0.05, 11);
    let d = diagnose_rate(&runs, &options());
    assert!(d.effects.is_empty(), "{:?}", named(&d));
    assert!(d.confounded.is_empty(), "{:?}", d.confounded);
    assert!(d.unexplained.outside.is_empty());
    assert_eq!(d.layers.rate.gap_dph, d.layers.rate.gap_after_dph);
}

/// The thermal cycle axis up and the axis horizontal east at eight rolls:
/// gravity, the Earth rate and the magnetic field all turn in the body's
/// y-z plane, so a g-sensitivity is also a misalignment and a magnetic
/// sensitivity. The simplest of the tie (the misalignment's two terms) is
/// named and the other two reported confounded with it, with the run that
/// separates them.
#[test]
fn a_g_sensitivity_the_rolls_cannot_tell_from_a_misalignment_is_reported_confounded() {
    let mut runs = vec![
        run(
            "cycle",
            &cycle_air(),
            &[(0.0, 90.0, 0.0)],
            900,
            0.0,
            0.05,
            21,
        ),
        run(
            "rolls",
            &vec![20.0; 8 * 900],
            &ROLLS_EAST,
            900,
            0.0,
            0.05,
            22,
        ),
    ];
    inject(
        &mut runs,
        Effect::GSensitivity,
        Param::None,
        &[0.0, 0.08, -0.06],
    );
    let d = diagnose_rate(&runs, &options());
    assert_eq!(named(&d), ["axis_misalignment"], "{:?}", d.candidates);
    for other in ["g_sensitivity", "magnetic_sensitivity"] {
        let pair = d
            .confounded
            .iter()
            .find(|c| c.effects.contains(&other.to_owned()))
            .unwrap_or_else(|| panic!("{other} not reported: {:?}", d.confounded));
        assert!(pair.effects.contains(&"axis_misalignment".to_owned()));
        assert!(pair.separate_with.contains("procedures/misalignment.toml"));
    }
}

/// A play of 4 degC on the case temperature, 0.1 deg/h either way, through
/// the thermal cycle: named as a hysteresis on the case, its width on the
/// grid's step either side of the truth.
#[test]
fn an_injected_hysteresis_is_named_with_its_temperature_and_width() {
    let mut runs = study(0.05, 31);
    let on = crate::twin::config::EffectTemperature::Case;
    let p = Param::Memory { on, value: 4.0 };
    inject(&mut runs, Effect::Hysteresis, p, &[0.1]);
    let d = diagnose_rate(&runs, &options());
    assert_eq!(named(&d), ["hysteresis"], "{:?}", d.candidates);
    let a = &d.effects[0];
    assert_eq!(a.temperature.as_deref(), Some(on.name()));
    let width = a.parameters["width_c"];
    assert!((2.8..=5.7).contains(&width), "{width}");
    assert!((a.parameters["amplitude_dph"] - 0.1).abs() < 0.02, "{a:?}");
}

/// A jump of the bias by 0.05 deg/h in the middle of a record at one
/// temperature, outside the library: held as a bias step in the run it is
/// in, within 6 min and a tenth of its size, and nothing is named for it.
#[test]
fn a_bias_jump_outside_the_library_is_reported_not_attributed() {
    let mut runs = study(0.05, 41);
    let at_s = 4950.0;
    for s in &mut runs[1].samples {
        if s.iv.time_s > at_s {
            s.iv.rate_dph += 0.05;
        }
    }
    let d = diagnose_rate(&runs, &options());
    assert!(d.effects.is_empty(), "{:?}", named(&d));
    let [step] = d.unexplained.outside.as_slice() else {
        panic!("{:?}", d.unexplained.outside);
    };
    assert_eq!(
        (step.kind.as_str(), step.run.as_str()),
        ("bias_step", "positions")
    );
    let found = step.at_s.expect("a jump has a time");
    assert!((found - at_s).abs() <= 360.0, "{found}");
    assert!((step.size_dph - 0.05).abs() <= 0.005, "{}", step.size_dph);
}

/// What a signal alone opens against the reference: nothing for one model
/// 4 follows (a case-temperature term), its own size for one it cannot
/// (a g-sensitivity between positions).
#[test]
fn the_visible_gap_counts_only_what_the_reference_cannot_follow() {
    let runs = study(0.0, 1);
    let tcase = per_row(&runs, |s| 0.01 * s.iv.tcase_c);
    assert!(visible_gap(&runs, &options(), &tcase) < 1e-6);
    let g = per_row(&runs, |s| 0.1 * s.gravity_body()[1]);
    let gap = visible_gap(&runs, &options(), &g);
    assert!((0.02..0.1).contains(&gap), "{gap}");
    assert!(visible_gap(&runs, &options(), &[0.0; 3]).is_nan());
}

/// A slow sine in the residual is found at its period (on the 5 % grid)
/// with nearly all of the residual; white noise has no period worth
/// reporting.
#[test]
fn the_residuals_period_is_found() {
    let runs = study(0.0, 1);
    let data = Data::new(&runs);
    let sine = per_row(&runs, |s| {
        (std::f64::consts::TAU * s.iv.time_s / 3000.0).sin()
    });
    let (period, frac) = periodicity(&data, &sine);
    let period = period.expect("a period");
    assert!((period / 3000.0 - 1.0).abs() < 0.03, "{period}");
    assert!(frac > 0.95, "{frac}");
    let noise = run(
        "n",
        &vec![20.0; 20_000],
        &[(0.0, 90.0, 0.0)],
        900,
        0.0,
        1.0,
        5,
    );
    let noise_runs = [noise];
    let data = Data::new(&noise_runs);
    let e = per_row(&noise_runs, |s| s.iv.bias_dph());
    assert!(periodicity(&data, &e).1 < THRESHOLDS.periodic_above);
}

/// A bias jump is looked for only where it can be told from a position
/// change or a run's end: 10 min from the run's ends, 1 min from a
/// record's, on a whole minute from the run's end.
#[test]
fn bias_jumps_are_searched_only_away_from_record_and_run_ends() {
    let runs = study(0.0, 1);
    let data = Data::new(&runs);
    let e = vec![0.0; data.y().len()];
    let (jumps, drifts) = jumps_and_drifts(&data, &e);
    assert_eq!(drifts, [0, 1]);
    assert!(!jumps.is_empty());
    let first = |r: usize| data.run_of.iter().position(|&x| x == r).unwrap_or(0);
    for &(_, k) in &jumps {
        let r = data.run_of[k];
        let (start, end) = (first(r), first(r) + runs[r].samples.len());
        assert!(
            k - start >= STEP_SIDE_ROWS && end - k >= STEP_SIDE_ROWS,
            "{k}"
        );
        assert_eq!((end - k) % engine::AVERAGING_S, 0);
        let s = &runs[r].samples;
        let at = k - start;
        assert_eq!(
            s[at - STEP_CLEAR_ROWS].record,
            s[(at + STEP_CLEAR_ROWS).min(s.len() - 1)].record
        );
    }
}

/// The reference is model 4 without a twin, the twin's enabled terms and
/// effects with one; only what the reference leaves to the data (model
/// 4's warm-up time constant) is refitted with the candidates.
#[test]
fn the_reference_is_model4_or_the_twins_enabled_terms() {
    let spec = reference(None);
    assert_eq!(
        spec.iter().map(|s| s.0).collect::<Vec<_>>(),
        MODEL4.to_vec()
    );
    assert_eq!(free_parameters(&spec), [Effect::SelfHeating]);
    let mut twin = TwinConfig::default_rl16();
    twin.bias.terms.gradient_quadratic = false;
    twin.effects.g_sensitivity = Some(crate::twin::config::GSensitivity {
        enabled: true,
        coeff_dph_per_g: [0.0; 3],
    });
    let spec = reference(Some(&twin));
    let effects: Vec<Effect> = spec.iter().map(|s| s.0).collect();
    assert!(!effects.contains(&Effect::GradientQuadratic));
    assert!(effects.contains(&Effect::GSensitivity));
    // The twin's own warm-up time constant is kept: nothing is free.
    assert!(free_parameters(&spec).is_empty());
    assert!(
        spec.iter()
            .any(|s| s.1 == Some(Param::TauS(twin.bias.model4.warmup_tau_s)))
    );
}
