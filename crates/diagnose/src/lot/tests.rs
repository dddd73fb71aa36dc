//! Lots made up in code: every unit a thermal cycle and nine positions at
//! 1 Hz, model-4 bias of its own, white noise, and library effects added
//! as the library's own columns (the lot's split is under test here, not
//! the library's forms: the controller's self-check draws units from the
//! twin).

use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

use super::*;
use crate::analysis::series::Interval;
use crate::data::Sample;
use crate::geometry::Orientation;
use crate::twin::TwinConfig;

/// White rate noise at 1 Hz, deg/h (its 60 s means: 0.0052 deg/h).
const NOISE_DPH: f64 = 0.04;

/// An effect added to a unit's runs: the library's columns times these
/// coefficients.
#[derive(Debug, Clone)]
struct Added {
    effect: Effect,
    coefficients: Vec<f64>,
}

fn added(effect: Effect, coefficients: &[f64]) -> Added {
    Added {
        effect,
        coefficients: coefficients.to_vec(),
    }
}

/// The nine positions of the study's orientation run, az/el/roll.
const POSITIONS: [(f64, f64, f64); 9] = [
    (0.0, 90.0, 0.0),
    (90.0, 90.0, 0.0),
    (180.0, 90.0, 0.0),
    (270.0, 90.0, 0.0),
    (90.0, 0.0, 0.0),
    (90.0, 0.0, 90.0),
    (90.0, 0.0, 180.0),
    (90.0, 0.0, 270.0),
    (0.0, 35.0, 0.0),
];

/// Seconds at each position.
const POSE_S: u32 = 1200;

/// One run of a unit: a 3 h thermal cycle at one position, or the nine
/// positions 20 min each at 20 degC; the unit's model-4 coefficients
/// `k` (K1 on dT, K4 on TK), its `effects` and noise from `seed`.
fn run(positions: bool, k: (f64, f64), effects: &[Added], seed: u64) -> RunData {
    let site = TwinConfig::default_rl16().site;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let len = if positions { 9 * POSE_S } else { 3 * 3600 };
    let (mut tcase, tau) = (20.0_f64, 1200.0);
    let samples: Vec<Sample> = (0..len)
        .map(|i| {
            let t = f64::from(i) + 0.5;
            let (air, pose, record) = if positions {
                let p = (i / POSE_S) as usize;
                (20.0, POSITIONS[p], format!("pos{p}"))
            } else {
                let air = 20.0 + 25.0 * (std::f64::consts::TAU * t / 10_800.0).sin();
                (air, POSITIONS[0], format!("seg{}", i / 1800))
            };
            tcase += (air + 2.0 * (1.0 - (-t / 600.0).exp()) - tcase) / tau;
            let t1 = tcase + 0.8 + 0.3 * (t / 900.0).sin();
            let orientation = Orientation::new(pose.0, pose.1, pose.2);
            let reference_dph = orientation.earth_rate_dph(&site);
            Sample {
                iv: Interval {
                    time_s: t,
                    rate_dph: reference_dph,
                    reference_dph,
                    t1_c: t1,
                    t2_c: tcase + 0.5,
                    tcase_c: tcase,
                    chamber_c: air,
                    frames: 400,
                },
                orientation,
                record: record.clone(),
                step: record.into(),
                table_rate_body_dph: nalgebra::Vector3::zeros(),
            }
        })
        .collect();
    let mut run = RunData {
        name: format!(
            "{} (seed {seed})",
            if positions { "positions" } else { "cycle" }
        ),
        site,
        samples,
    };
    let offset = 0.3 * rng.sample::<f64, _>(StandardNormal);
    let mut bias: Vec<f64> = run
        .samples
        .iter()
        .map(|s| {
            offset
                + k.0 * s.iv.gradient_c()
                + k.1 * s.iv.tcase_c
                + 0.5 * (-s.iv.time_s / 600.0).exp()
                + NOISE_DPH * rng.sample::<f64, _>(StandardNormal)
        })
        .collect();
    for a in effects {
        let p = a.effect.grid()[0];
        for (c, coeff) in a.effect.columns(&run, p).iter().zip(&a.coefficients) {
            for (b, v) in bias.iter_mut().zip(c) {
                *b += coeff * v;
            }
        }
    }
    for (s, b) in run.samples.iter_mut().zip(bias) {
        s.iv.rate_dph += b;
    }
    run
}

/// A unit of serial `serial`, its two runs with `effects`.
fn unit(serial: &str, k: (f64, f64), effects: &[Added], seed: u64) -> LotUnit {
    LotUnit {
        serial: serial.into(),
        dut_type: "RL-16".into(),
        slot: String::new(),
        runs: vec![
            run(false, k, effects, seed),
            run(true, k, effects, seed + 1),
        ],
    }
}

/// The twin's terms as each unit's reference, its own thermal network
/// for the thermal layer (nothing to fit: the split is under test).
fn opts() -> Options {
    Options {
        twin: Some(TwinConfig::default_rl16()),
        fit_thermal: false,
        power_replications: 0,
    }
}

/// Model-4 coefficients unit by unit: each unit of a lot is its own.
const K: [(f64, f64); 4] = [(0.08, 0.004), (0.05, 0.006), (0.11, 0.003), (0.07, 0.005)];

/// A misalignment of (theta_z, -theta_y) = (+8, -6) arcmin, in rad.
fn fixture_tilt(scale: f64) -> Added {
    let arcmin = (1.0_f64 / 60.0).to_radians();
    added(
        Effect::AxisMisalignment,
        &[8.0 * arcmin * scale, -6.0 * arcmin * scale],
    )
}

fn shared_names(lot: &Lot) -> Vec<(&str, Vec<&str>)> {
    lot.shared_effects
        .iter()
        .map(|s| {
            (
                s.name.as_str(),
                s.units.iter().map(String::as_str).collect(),
            )
        })
        .collect()
}

fn own_names(lot: &Lot, serial: &str) -> Vec<String> {
    lot.units
        .iter()
        .find(|u| u.serial == serial)
        .map(|u| u.effects.iter().map(|a| a.name.clone()).collect())
        .unwrap_or_default()
}

/// Four units on one fixture that tilts them alike, one of them with a
/// g-sensitivity of its own: the tilt is the lot's (the fixture's), listed
/// once with every unit, near the injected angles; the g-sensitivity is
/// that unit's alone, and it is the outlier.
#[test]
fn a_fixture_tilt_is_shared_and_a_units_own_effect_sets_it_apart() {
    let g = added(Effect::GSensitivity, &[0.0, 0.03, 0.025]);
    let units: Vec<LotUnit> = (0..4)
        .map(|u| {
            let mut fx = vec![fixture_tilt(1.0)];
            if u == 2 {
                fx.push(g.clone());
            }
            unit(&format!("U{u}"), K[u], &fx, 100 + 10 * u as u64)
        })
        .collect();
    let lot = diagnose_lot(units, &opts()).expect("a lot");
    assert_eq!(
        shared_names(&lot),
        vec![("axis_misalignment", vec!["U0", "U1", "U2", "U3"])],
        "{:#?}",
        lot.considered
    );
    let tilt = &lot.shared_effects[0];
    let arcmin = (1.0_f64 / 60.0).to_radians();
    let ey = tilt.parameters["earth_y"] / arcmin;
    let ez = tilt.parameters["earth_z"] / arcmin;
    assert!(
        (ey - 8.0).abs() < 0.5 && (ez + 6.0).abs() < 0.5,
        "{ey} {ez}"
    );
    assert_eq!(tilt.seat, "fixture");
    assert!(tilt.agreement_p >= LOT_THRESHOLDS.agree_alpha);
    assert!(tilt.shrink > 0.3, "{}", tilt.shrink);
    // Listed once: under no unit.
    for u in &lot.units {
        assert!(
            !u.effects.iter().any(|a| a.name == "axis_misalignment"),
            "{}: {:?}",
            u.serial,
            u.effects
        );
    }
    assert_eq!(own_names(&lot, "U2"), vec!["g_sensitivity".to_owned()]);
    for s in ["U0", "U1", "U3"] {
        assert!(
            own_names(&lot, s).is_empty(),
            "{s}: {:?}",
            own_names(&lot, s)
        );
    }
    assert_eq!(lot.outliers, vec!["U2".to_owned()]);
    let u2 = &lot.units[2];
    assert!(u2.outlier);
    let kinds: Vec<&str> = u2.evidence.iter().map(|e| e.kind.as_str()).collect();
    assert!(kinds.contains(&"own_effect"), "{kinds:?}");
    assert!(kinds.contains(&"gap"), "{kinds:?}");
    // The lot's gap shrinks with the bench's share, and further with U2's.
    let g = &lot.gap;
    assert!(
        g.after_shared_dph < 0.8 * g.gap_dph && g.after_dph < g.after_shared_dph,
        "{g:?}"
    );
    assert!(
        u2.gap_after_dph < 0.7 * u2.gap_after_shared_dph,
        "{}",
        serde_json_like(u2)
    );
    // The bench's correction holds the tilt alone; U2's own twin its
    // g-sensitivity alone, and on this bench the tilt as well.
    let bench = lot.bench_effects();
    assert!(bench.axis_misalignment.is_some_and(|m| m.enabled));
    assert!(bench.g_sensitivity.is_none());
    let base = TwinConfig::default_rl16();
    let own = lot.unit_twin(2, &base, false).expect("U2");
    assert!(own.effects.g_sensitivity.is_some_and(|g| g.enabled));
    assert!(own.effects.axis_misalignment.is_none_or(|m| !m.enabled));
    let here = lot.unit_twin(2, &base, true).expect("U2");
    let m = here
        .effects
        .axis_misalignment
        .expect("the tilt on this bench");
    assert!((m.about_z_arcmin - 8.0).abs() < 0.5, "{m:?}");
    assert!(lot.unit_twin(4, &base, true).is_none());
}

/// Every unit's runs with the Earth rate the units sense turned from the
/// one the bench states (`latitude_deg`: the runs' latitude minus the one
/// the units sense; `north_deg`: the table's azimuths as stated minus as
/// they are), as the library's columns at those coefficients.
fn stated_wrong(latitude_deg: f64, north_deg: f64) -> Added {
    let phi = TwinConfig::default_rl16().site.latitude_deg.to_radians();
    let w = crate::geometry::EARTH_RATE_DPH;
    added(
        Effect::EarthRateError,
        &[
            -w * latitude_deg.to_radians(),
            w * phi.cos() * north_deg.to_radians(),
        ],
    )
}

/// A lot of `n` units (`U0`, ...) that all carry `bench` and nothing else,
/// their noise from seeds `seed`, `seed + 1`, ...
fn on_one_bench(n: usize, bench: &Added, seed: u64) -> Lot {
    let units: Vec<LotUnit> = (0..n)
        .map(|u| {
            unit(
                &format!("U{u}"),
                K[u],
                std::slice::from_ref(bench),
                seed + u as u64,
            )
        })
        .collect();
    diagnose_lot(units, &opts()).expect("a lot")
}

#[test]
fn a_latitude_stated_wrong_is_the_sites_and_no_units_own() {
    let lot = on_one_bench(4, &stated_wrong(0.1, 0.0), 300);
    assert_eq!(
        shared_names(&lot),
        vec![("earth_rate_error", vec!["U0", "U1", "U2", "U3"])],
        "{:#?}",
        lot.considered
    );
    let e = &lot.shared_effects[0];
    assert_eq!(e.seat, "site", "{}", e.seat_why);
    let x = evidence::EarthRateError::of(&e.parameters, lot.site.latitude_deg);
    assert!((x.latitude_deg - 0.1).abs() < 0.01, "{x:?}");
    assert!(x.north_deg.abs() < 0.02, "{x:?}");
    assert!(
        e.seat_why.contains("latitude 0.10 deg off"),
        "{}",
        e.seat_why
    );
    for u in &lot.units {
        assert!(u.effects.is_empty(), "{}: {:?}", u.serial, u.effects);
        // Nothing of its own: its gap with the bench's share is its gap
        // in the final fit (both read from the same reference).
        assert!(
            (u.gap_after_shared_dph - u.gap_after_dph).abs() < 1e-9,
            "{}",
            serde_json_like(u)
        );
    }
    assert!(lot.outliers.is_empty(), "{:?}", lot.outliers);
    // The bench's correction carries it; a unit's own twin does not.
    let bench = lot.bench_effects();
    let b = bench
        .earth_rate_error
        .expect("the bench's Earth-rate error");
    assert!((b.latitude_dph - e.parameters["latitude_dph"]).abs() < 1e-12);
    let base = TwinConfig::default_rl16();
    let own = lot.unit_twin(0, &base, false).expect("U0");
    assert!(own.effects.earth_rate_error.is_none());
}

#[test]
fn a_north_stated_wrong_is_the_tables() {
    let lot = on_one_bench(3, &stated_wrong(0.0, 0.25), 400);
    assert_eq!(
        shared_names(&lot),
        vec![("earth_rate_error", vec!["U0", "U1", "U2"])],
        "{:#?}",
        lot.considered
    );
    let e = &lot.shared_effects[0];
    assert_eq!(e.seat, "table", "{}", e.seat_why);
    let x = evidence::EarthRateError::of(&e.parameters, lot.site.latitude_deg);
    assert!((x.north_deg - 0.25).abs() < 0.03, "{x:?}");
    assert!(x.latitude_deg.abs() < 0.01, "{x:?}");
}

fn serde_json_like(u: &UnitResult) -> String {
    format!(
        "{}: {:.5} -> {:.5} -> {:.5} (noise {:.5})",
        u.serial, u.gap_dph, u.gap_after_shared_dph, u.gap_after_dph, u.noise_dph
    )
}

/// Three units share a tilt; the fourth's is less than half of it (it
/// sits differently in its slot): one shared tilt for all four still
/// removes most of the gap, but the units' values disagree, so the tilt
/// is shared by the three and the fourth is the outlier with its own
/// value beside the lot's.
#[test]
fn a_unit_whose_tilt_differs_from_the_lots_is_the_outlier() {
    let units: Vec<LotUnit> = (0..4)
        .map(|u| {
            let tilt = fixture_tilt(if u == 1 { 0.4 } else { 1.0 });
            unit(&format!("U{u}"), K[u], &[tilt], 200 + 10 * u as u64)
        })
        .collect();
    let lot = diagnose_lot(units, &opts()).expect("a lot");
    assert_eq!(
        shared_names(&lot),
        vec![("axis_misalignment", vec!["U0", "U2", "U3"])],
        "{:#?}",
        lot.considered
    );
    assert_eq!(lot.outliers, vec!["U1".to_owned()]);
    let e = lot.units[1]
        .evidence
        .iter()
        .find(|e| e.kind == "shared_effect_differs")
        .expect("its tilt differs");
    assert_eq!(e.effect.as_deref(), Some("axis_misalignment"));
    assert!(e.p_value.is_some_and(|p| p < 0.001), "{e:?}");
    assert!(e.value > 5.0, "{e:?}");
}

/// Three units with nothing but their own model 4 and noise: nothing
/// shared, nothing own, no outlier.
#[test]
fn a_lot_of_plain_units_shares_nothing_and_has_no_outlier() {
    let units: Vec<LotUnit> = (0..3)
        .map(|u| unit(&format!("U{u}"), K[u], &[], 300 + 10 * u as u64))
        .collect();
    let lot = diagnose_lot(units, &opts()).expect("a lot");
    assert!(lot.shared_effects.is_empty(), "{:#?}", lot.shared_effects);
    assert!(lot.units.iter().all(|u| u.effects.is_empty()));
    assert!(lot.outliers.is_empty(), "{:?}", lot.units);
    assert!(lot.no_outlier_because.is_none());
}

/// Two units that differ: a lot of two names what differs, never which
/// of them is the outlier.
#[test]
fn a_lot_of_two_says_what_differs_not_which_is_odd() {
    let g = added(Effect::GSensitivity, &[0.0, 0.03, 0.025]);
    let units = vec![unit("A", K[0], &[], 400), unit("B", K[1], &[g], 410)];
    let lot = diagnose_lot(units, &opts()).expect("a lot");
    assert!(lot.outliers.is_empty());
    assert_eq!(own_names(&lot, "B"), vec!["g_sensitivity".to_owned()]);
    let why = lot.no_outlier_because.as_deref().unwrap_or_default();
    assert!(why.contains("a lot of two"), "{why}");
    assert!(lot.lot_size.starts_with("A lot of two"));
}

/// What is not a lot is refused, saying why.
#[test]
fn units_of_several_types_or_sites_are_not_a_lot() {
    let one = |serial: &str, dut_type: &str| LotUnit {
        serial: serial.into(),
        dut_type: dut_type.into(),
        slot: String::new(),
        runs: vec![run(true, K[0], &[], 7)],
    };
    let err = |units: Vec<LotUnit>| diagnose_lot(units, &opts()).expect_err("refused");
    assert_eq!(err(vec![one("A", "RL-16")]), LotError::TooFew { units: 1 });
    let e = err(vec![
        one("A", "RL-16"),
        one("B", "RL-20"),
        one("C", "RL-16"),
    ]);
    assert_eq!(
        e,
        LotError::SeveralTypes {
            types: vec!["RL-16: A, C".into(), "RL-20: B".into()]
        }
    );
    assert!(e.to_string().contains("a lot is of one type"), "{e}");
    let mut far = one("B", "RL-16");
    far.runs[0].site.latitude_deg += 1.0;
    let e = err(vec![one("A", "RL-16"), far]);
    assert!(
        matches!(&e, LotError::SeveralSites { sites } if sites.len() == 2 && sites[1].contains("of B")),
        "{e}"
    );
    // A site stated to the metre either way is one site.
    let mut near = one("B", "RL-16");
    near.runs[0].site.latitude_deg += 0.001;
    assert!(check(&[one("A", "RL-16"), near]).is_ok());
    assert_eq!(
        err(vec![one("A", "RL-16"), one("A", "RL-16")]),
        LotError::Twice { serial: "A".into() }
    );
    let mut empty = one("B", "RL-16");
    empty.runs.clear();
    assert_eq!(
        err(vec![one("A", "RL-16"), empty]),
        LotError::NoRuns { serial: "B".into() }
    );
}
