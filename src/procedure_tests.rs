//! The procedures checked against the shipped benches' limits (the
//! procedure types are `gyrobench-model`'s; the benches are the
//! controller's files).

use crate::bench::BenchConfig;
use crate::config::{ConfigError, Source};
use crate::geometry::{Orientation, TableAngles};
use crate::procedure::estimate::{min_total_s, travel_s};
use crate::procedure::*;

fn load(name: &str, text: &str) -> Result<Procedure, ConfigError> {
    Procedure::from_source(
        &Source::from_text(name, text),
        &BenchConfig::embedded().procedure_limits(),
    )
}

const SMOKE: &str = include_str!("../procedures/smoke.toml");

#[test]
fn shipped_procedures_validate_against_the_embedded_bench() {
    for (name, text) in [
        ("smoke.toml", SMOKE),
        (
            "thermal_cycle.toml",
            include_str!("../procedures/thermal_cycle.toml"),
        ),
        (
            "orientation.toml",
            include_str!("../procedures/orientation.toml"),
        ),
        (
            "acceptance.toml",
            include_str!("../procedures/acceptance.toml"),
        ),
    ] {
        let p = load(name, text).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(!p.main.is_empty(), "{name}");
    }
}

#[test]
fn the_north_procedures_run_on_a_table_turned_north_and_say_where_the_study_table_falls_short() {
    let north = BenchConfig::from_source(&Source::from_text(
        "embedded-north.toml",
        include_str!("../fixtures/bench/embedded-north.toml"),
    ))
    .expect("the north bench");
    assert_eq!(
        north.table.geometry,
        crate::geometry::TableGeometry::north()
    );
    for (name, text) in [
        (
            "thermal_cycle_north.toml",
            crate::study::THERMAL_CYCLE_NORTH_TOML,
        ),
        (
            "orientation_north.toml",
            crate::study::ORIENTATION_NORTH_TOML,
        ),
    ] {
        let p = Procedure::from_source(&Source::from_text(name, text), &north.procedure_limits())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(!p.main.is_empty(), "{name}");
    }
    // The study's table cannot roll about north: the error says where.
    let e = load(
        "orientation_north.toml",
        crate::study::ORIENTATION_NORTH_TOML,
    )
    .expect_err("the study's table cannot roll about north")
    .to_string();
    assert!(
        e.contains("orientation_north.toml") && e.contains("cannot reach"),
        "{e}"
    );
}

#[test]
fn orientation_run_reaches_the_nine_positions_of_the_study() {
    let p = load(
        "orientation.toml",
        include_str!("../procedures/orientation.toml"),
    )
    .expect("valid");
    let moves: Vec<(TableAngles, Orientation)> = p
        .main
        .iter()
        .filter_map(|s| match s.kind {
            StepKind::Move {
                angles,
                orientation,
            } => Some((angles, orientation)),
            _ => None,
        })
        .collect();
    assert_eq!(moves.len(), 9);
    for (a, o) in &moves[..4] {
        assert!(
            (a.outer_deg - 90.0).abs() < 1e-6 && (o.elevation_deg - 90.0).abs() < 1e-6,
            "{a:?}"
        );
    }
    for (a, o) in &moves[4..8] {
        assert!(
            a.outer_deg.abs() < 1e-6 && o.elevation_deg.abs() < 1e-6,
            "{a:?}"
        );
    }
    assert!((moves[8].0.outer_deg - 35.0).abs() < 1e-6);
    let inner: Vec<f64> = moves[4..8]
        .iter()
        .map(|(a, _)| a.inner_deg.rem_euclid(360.0).round())
        .collect();
    assert_eq!(inner, vec![0.0, 90.0, 180.0, 270.0], "four rolls");
    let measures: Vec<&str> = p.measures().map(|m| m.name.as_str()).collect();
    assert!(measures.contains(&"bias_stability_dph:az000"));
    assert!(measures.contains(&"bias_stability_dph:tilt55"));
    assert_eq!(
        measures
            .iter()
            .filter(|m| m.starts_with("bias_stability_dph:"))
            .count(),
        9
    );
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines()
        .position(|l| l.contains(needle))
        .expect("needle in text")
        + 1
}

fn refused(text: &str, needle: &str, want: &str) {
    let err = load("bad.toml", text).expect_err("must be refused");
    let msg = err.to_string();
    assert!(msg.contains(want), "{msg}");
    assert_eq!(err.line(), Some(line_of(text, needle)), "{msg}");
}

#[test]
fn set_point_beyond_the_chamber_limits_is_refused() {
    let t = SMOKE.replacen("set_c = 20.0", "set_c = 95.0", 1);
    refused(&t, "set_c = 95.0", "beyond the bench's chamber limits");
}

#[test]
fn ramp_beyond_capability_is_refused() {
    let t = SMOKE.replacen("ramp_c_per_min = 1.0", "ramp_c_per_min = 12.0", 1);
    refused(
        &t,
        "ramp_c_per_min = 12.0",
        "beyond the chamber's capability",
    );
}

#[test]
fn unreachable_orientation_is_refused() {
    let t = SMOKE.replacen(
        "azimuth_deg = 90.0, elevation_deg = 0.0",
        "azimuth_deg = 0.0, elevation_deg = 0.0",
        1,
    );
    refused(
        &t,
        "azimuth_deg = 0.0, elevation_deg = 0.0",
        "the table cannot reach",
    );
}

#[test]
fn unknown_key_is_refused_with_its_line() {
    let t = SMOKE.replacen("duration_s = 30.0", "duration_s = 30.0\nspeed = 2", 1);
    let err = load("bad.toml", &t).expect_err("unknown key");
    assert!(err.to_string().contains("unknown field `speed`"), "{err}");
}

#[test]
fn a_value_of_the_wrong_type_in_a_step_is_reported_at_its_own_line_with_its_key() {
    for (value, kind) in [("\"30\"", "string"), ("true", "boolean")] {
        let t = SMOKE.replacen("duration_s = 30.0", &format!("duration_s = {value}"), 1);
        let line = t
            .lines()
            .position(|l| l.starts_with("duration_s = ") && l.contains(value))
            .expect("the line")
            + 1;
        let err = load("bad.toml", &t).expect_err("wrong type");
        let msg = err.to_string();
        assert_eq!(err.line(), Some(line), "{msg}");
        assert!(
            msg.starts_with(&format!("bad.toml:{line}:")) && msg.contains("`duration_s`"),
            "{msg}"
        );
        assert!(msg.contains(kind), "{msg}");
    }
}

#[test]
fn measure_of_a_record_that_does_not_exist_is_refused() {
    let t = SMOKE.replacen("records = [\"{label}\"]", "records = [\"nowhere\"]", 1);
    refused(
        &t,
        "records = [\"nowhere\"]",
        "no earlier record step makes",
    );
}

#[test]
fn unknown_metric_and_missing_limits_are_refused() {
    let t = SMOKE.replacen("metric = \"bias_stability\"", "metric = \"vibes\"", 1);
    refused(&t, "metric = \"vibes\"", "is not a metric");
    let t = SMOKE.replacen("high = 0.2\n", "", 1);
    let err = load("bad.toml", &t).expect_err("no limit");
    assert!(err.to_string().contains("needs a limit"), "{err}");
}

#[test]
fn empty_and_binary_files_are_refused() {
    let err = load("empty.toml", "").expect_err("empty");
    assert!(
        err.to_string().contains("missing field `procedure`"),
        "{err}"
    );
    let err = load("bin.toml", "\u{0}\u{1}\u{2}garbage").expect_err("binary");
    assert_eq!(err.line(), Some(1));
}

/// A procedure of many steps loads with one parse of the file for all of
/// its error locations (it used to parse the file again for every step:
/// 4,000 steps took half a minute). The last step's line is still right.
#[test]
fn a_procedure_of_twenty_thousand_steps_loads_and_locates_its_last_step() {
    let mut text = String::from("[procedure]\nname = \"long\"\ndut_type = \"RL-16\"\n");
    for i in 0..20_000 {
        text.push_str(&format!(
            "\n[[main]]\naction = \"record\"\nlabel = \"r{i}\"\nduration_s = 1.0\n"
        ));
    }
    let p = load("long.toml", &text).expect("loads");
    assert_eq!(p.main.len(), 20_000);
    let last = p.main.last().expect("last");
    assert_eq!(last.line, 4 + 5 * 19_999 + 1, "{}", last.key);
    let bad = text.replace("label = \"r19999\"", "label = \"r0\"");
    let err = load("long.toml", &bad).expect_err("duplicate label");
    assert_eq!(err.line(), Some(4 + 5 * 19_999 + 3), "{err}");
}

/// Values outside physics are refused with their line, not run.
#[test]
fn absurd_durations_limits_and_ramps_are_refused() {
    for (from, to, want) in [
        (
            "duration_s = 30.0",
            "duration_s = 1e300",
            "main.0.steps.0.duration_s",
        ),
        (
            "duration_s = 30.0",
            "duration_s = 0.001",
            "main.0.steps.0.duration_s",
        ),
        ("high = 0.2", "high = nan", "main.0.steps.2.high"),
        ("high = 0.2", "high = inf", "main.0.steps.2.high"),
        (
            "ramp_c_per_min = 1.0",
            "ramp_c_per_min = 1e-300",
            "setup.0.ramp_c_per_min",
        ),
        (
            "averaging_s = 10.0",
            "averaging_s = 1e300",
            "main.0.steps.2.averaging_s",
        ),
    ] {
        let t = SMOKE.replacen(from, to, 1);
        let err = load("bad.toml", &t).expect_err(to);
        assert!(err.to_string().contains(want), "{to}: {err}");
        let line = t.lines().position(|l| l.contains(to)).map(|i| i + 1);
        assert_eq!(err.line(), line, "{to}: {err}");
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(512))]

    /// Arbitrary text, and the smoke procedure with arbitrary bytes spliced
    /// in, never panic the loader: every input is accepted or refused with
    /// a located error.
    #[test]
    fn the_loader_never_panics(text in "\\PC{0,400}", at in 0usize..2000, splice in "\\PC{0,40}") {
        let _ = load("fuzz.toml", &text);
        let mut s = SMOKE.to_owned();
        let mut i = at.min(s.len());
        while !s.is_char_boundary(i) {
            i -= 1;
        }
        s.insert_str(i, &splice);
        if let Err(e) = load("fuzz.toml", &s) {
            proptest::prop_assert!(e.line().is_some(), "{}", e);
        }
    }
}

#[test]
fn moves_follow_the_trapezoid_and_records_their_duration() {
    // 90 deg at 20 deg/s, 10 deg/s^2: 2 s + 2.5 s + 2 s = 6.5 s.
    assert!((travel_s(90.0, 20.0, 10.0) - 6.5).abs() < 1e-12);
    // Short moves never reach full rate: 2 sqrt(d/a).
    assert!((travel_s(10.0, 20.0, 10.0) - 2.0).abs() < 1e-12);
    let bench = BenchConfig::embedded();
    let p = Procedure::from_source(
        &Source::from_text("t.toml", include_str!("../procedures/thermal_cycle.toml")),
        &bench.procedure_limits(),
    )
    .expect("valid");
    let total = min_total_s(&p, &bench.procedure_limits());
    // 6.5 h of records plus the first move (90 deg outer from 0) and
    // settling, and the switch-on's second.
    assert!(
        (total - (23_400.0 + 6.5 + bench.devices.table.settle_s + 1.0)).abs() < 1e-6,
        "{total}"
    );
}

/// Every shipped procedure written from its raw value validates to the
/// same procedure on the bench it is for (the north ones on the table
/// turned north), step for step but for the lines the steps sit on.
#[test]
fn a_shipped_procedure_written_from_its_value_is_the_same_procedure() {
    let north = BenchConfig::from_source(&Source::from_text(
        "embedded-north.toml",
        include_str!("../fixtures/bench/embedded-north.toml"),
    ))
    .expect("the north bench")
    .procedure_limits();
    let embedded = BenchConfig::embedded().procedure_limits();
    for (name, text) in gyrobench_model::procedures::SHIPPED {
        let bench = if name.contains("_north") {
            &north
        } else {
            &embedded
        };
        let validated = |t: &str| {
            Procedure::from_source(&Source::from_text(name, t), bench)
                .unwrap_or_else(|e| panic!("{name}: {e}"))
        };
        let raw = raw::RawProcedure::from_toml(text).expect("a procedure");
        let written = raw.to_toml(&[]).expect("written");
        // Every step the same but for the line it sits on in its file.
        let json = |p: &Procedure| {
            let mut v = serde_json::to_value(p).expect("json");
            for group in ["setup", "main", "cleanup"] {
                if let Some(steps) = v[group].as_array_mut() {
                    for s in steps {
                        s.as_object_mut().map(|o| o.remove("line"));
                    }
                }
            }
            v
        };
        assert_eq!(json(&validated(&written)), json(&validated(text)), "{name}");
    }
}
