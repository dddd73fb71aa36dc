//! Rate-table tests on the embedded bench: the figures of
//! `procedures/rate_transfer.toml` and `procedures/dead_band.toml` against
//! the twin's configured rate response, a unit beyond its limit failing,
//! the figures replayed from the log, and the same `rate` steps run over
//! the real ACL command language to `sim serve`.

use std::path::{Path, PathBuf};

use gyrobench::analysis::rate::{
    self, DEAD_BAND_SHARE, RatePoint, THRESHOLD_SHARE, input_for_share,
};
use gyrobench::runlog::replay::replay;
use gyrobench::twin::config::{RateResponseConfig, TwinConfig};

use crate::cli::{gyrobench, temp_dir};
use crate::common::{figure, json, s, stderr, write};

const PROCEDURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/procedures");

/// A twin file: the RL-16 with `response` as its rate response.
fn twin_with(dir: &Path, name: &str, response: &RateResponseConfig) -> PathBuf {
    let mut twin = TwinConfig::default_rl16();
    twin.rate_response = response.clone();
    write(dir, name, &twin.to_toml().expect("twin TOML"))
}

/// Run `procedure` on the embedded bench with `twin` into `dir/out`.
fn run(procedure: &str, twin: &Path, out: &Path) -> std::process::Output {
    gyrobench(&[
        "run",
        &format!("{PROCEDURES}/{procedure}"),
        "--twin",
        s(twin),
        "--out",
        s(out),
        "--db",
        "none",
    ])
}

/// The records of the run's log as the twin's truth would give them: the
/// same input rates, the output the configured response gives without
/// noise or bias (a constant bias cancels in every figure).
fn truth_points(log: &Path, response: &RateResponseConfig, prefix: &str) -> Vec<RatePoint> {
    let replayed = replay(log, None).expect("the log replays");
    let records = &replayed.result.records;
    records
        .order
        .iter()
        .filter(|l| l.starts_with(prefix))
        .filter_map(|l| RatePoint::of(&records.get(l)?))
        .map(|p| RatePoint {
            output_dph: response.output_dph(p.input_dph, 1.0, 0.0),
            ..p
        })
        .collect()
}

fn assert_within_3_se(what: &str, (value, se): (f64, f64), truth: f64) {
    assert!(
        se > 0.0 && (value - truth).abs() <= 3.0 * se,
        "{what}: measured {value} +- {se}, the twin's value {truth}"
    );
}

#[test]
fn rate_transfer_figures_agree_with_the_twin_at_two_settings() {
    let dir = temp_dir("rate-transfer");
    let settings = [
        RateResponseConfig {
            scale_factor_error_ppm: 60.0,
            nonlinearity_ppm: 40.0,
            full_scale_dps: 400.0,
            asymmetry_ppm: 12.0,
            ..RateResponseConfig::default()
        },
        RateResponseConfig {
            scale_factor_error_ppm: -150.0,
            nonlinearity_ppm: 120.0,
            full_scale_dps: 400.0,
            asymmetry_ppm: -30.0,
            ..RateResponseConfig::default()
        },
    ];
    let mut seen = Vec::new();
    for (i, response) in settings.iter().enumerate() {
        let twin = twin_with(&dir, &format!("twin{i}.toml"), response);
        let out = dir.join(format!("run{i}"));
        let o = run("rate_transfer.toml", &twin, &out);
        assert!(
            matches!(o.status.code(), Some(0 | 3)),
            "setting {i}: {}",
            stderr(&o)
        );
        let report = json(&out.join("report.json"));
        let truth = truth_points(&out.join("run.mcap"), response, "rate_");
        assert_eq!(truth.len(), 16, "16 rate records");
        let sf = figure(&report, "scale_factor_ppm");
        let nl = figure(&report, "scale_factor_nonlinearity_ppm");
        let asym = figure(&report, "scale_factor_asymmetry_ppm");
        let t_sf = rate::scale_factor_ppm(&truth).expect("truth").value;
        let t_nl = rate::nonlinearity_ppm(&truth).expect("truth").value;
        let t_asym = rate::asymmetry_ppm(&truth).expect("truth").value;
        assert_within_3_se(&format!("setting {i} scale factor"), sf, t_sf);
        assert_within_3_se(&format!("setting {i} nonlinearity"), nl, t_nl);
        assert_within_3_se(&format!("setting {i} asymmetry"), asym, t_asym);
        // The asymmetry and scale factor are the configured ones (the
        // nonlinearity, odd in the rate, leaves both directions alike).
        assert!((t_asym - response.asymmetry_ppm).abs() < 0.5, "{t_asym}");
        seen.push((sf.0, nl.0, asym.0));
    }
    // The two settings are told apart by far more than their errors.
    assert!((seen[0].0 - seen[1].0).abs() > 100.0, "{seen:?}");
    assert!((seen[0].1 - seen[1].1).abs() > 20.0, "{seen:?}");
    assert!((seen[0].2 - seen[1].2).abs() > 20.0, "{seen:?}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn dead_band_and_threshold_agree_with_the_twin_at_two_settings() {
    let dir = temp_dir("dead-band");
    // Dithered (one count rms of stripping residual), and undithered: a
    // clean locked output, zero counts frame after frame inside the
    // lock-in, which is a measurement (exit 3, beyond the limit), not a
    // stuck gyro (exit 1).
    for (i, (lock_in, residual)) in [(3.0, 1.0), (8.0, 1.0), (3.0, 0.0)].into_iter().enumerate() {
        let response = RateResponseConfig {
            lock_in_dph: lock_in,
            dither_residual_counts: residual,
            ..RateResponseConfig::default()
        };
        let twin = twin_with(&dir, &format!("twin{i}.toml"), &response);
        let out = dir.join(format!("run{i}"));
        let o = run("dead_band.toml", &twin, &out);
        assert_eq!(o.status.code(), Some(3), "beyond 2 deg/h: {}", stderr(&o));
        let report = json(&out.join("report.json"));
        let lock_in = format!("lock-in {lock_in}, residual {residual} counts");
        let lock_in_dph = response.lock_in_dph;
        assert_within_3_se(
            &format!("{lock_in} dead band"),
            figure(&report, "dead_band_dph"),
            input_for_share(lock_in_dph, DEAD_BAND_SHARE),
        );
        assert_within_3_se(
            &format!("{lock_in} threshold"),
            figure(&report, "threshold_dph"),
            input_for_share(lock_in_dph, THRESHOLD_SHARE),
        );
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn the_rl16_passes_a_nonlinear_unit_fails_and_replay_gives_the_same_figures() {
    let dir = temp_dir("rate-verdicts");
    let nominal = twin_with(&dir, "nominal.toml", &RateResponseConfig::default());
    let out = dir.join("nominal");
    let o = run("rate_transfer.toml", &nominal, &out);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("scale_factor_nonlinearity_ppm") && text.contains(" ± "),
        "figures with their standard errors: {text}"
    );
    let bent = twin_with(
        &dir,
        "bent.toml",
        &RateResponseConfig {
            nonlinearity_ppm: 300.0,
            full_scale_dps: 400.0,
            ..RateResponseConfig::default()
        },
    );
    let out = dir.join("bent");
    let o = run("rate_transfer.toml", &bent, &out);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let report = json(&out.join("report.json"));
    let nl = report["measurements"]
        .as_array()
        .expect("measurements")
        .iter()
        .find(|m| m["name"] == "scale_factor_nonlinearity_ppm")
        .expect("nonlinearity");
    assert_eq!(nl["outcome"], "fail", "{nl}");
    let html = std::fs::read_to_string(out.join("report.html")).expect("page");
    assert!(
        html.contains("Scale-factor residuals"),
        "the residual chart"
    );
    // Replay recomputes every figure from the log alone.
    let replayed = dir.join("replayed");
    let r = gyrobench(&["replay", s(&out.join("run.mcap")), "--out", s(&replayed)]);
    assert_eq!(r.status.code(), Some(3), "{}", stderr(&r));
    assert_eq!(
        std::fs::read_to_string(out.join("report.json")).expect("live"),
        std::fs::read_to_string(replayed.join("report.json")).expect("replayed"),
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// `rate` steps are refused at `check` with their file, line and field when
/// the bench cannot turn that fast or has no rate mode.
#[test]
fn rate_steps_beyond_the_bench_are_refused_with_their_place() {
    let dir = temp_dir("rate-refused");
    let p = write(
        &dir,
        "fast.toml",
        "[procedure]\nname = \"fast\"\ndut_type = \"RL-16\"\n\n[[main]]\naction = \"rate\"\nlabel = \"a\"\nrate_dps = 900.0\nrevolutions = 1\n",
    );
    let o = gyrobench(&["check", s(&p)]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("main.0.rate_dps") && err.contains("rate-mode limit of 400"),
        "{err}"
    );
    let p = write(
        &dir,
        "half.toml",
        "[procedure]\nname = \"half\"\ndut_type = \"RL-16\"\n\n[[main]]\naction = \"rate\"\nlabel = \"a\"\nrate_dps = 10.0\nrevolutions = 1.5\n",
    );
    let o = gyrobench(&["check", s(&p)]);
    assert!(
        stderr(&o).contains("whole number of revolutions"),
        "{}",
        stderr(&o)
    );
    let p = write(
        &dir,
        "left.toml",
        "[procedure]\nname = \"left\"\ndut_type = \"RL-16\"\n\n[[main]]\naction = \"rate\"\nlabel = \"a\"\nrate_dps = 10.0\nrevolutions = 1\nkeep_turning = true\n\n[[main]]\naction = \"wait\"\nduration_s = 10.0\n",
    );
    let o = gyrobench(&["check", s(&p)]);
    let err = stderr(&o);
    assert!(
        err.contains("main.0.keep_turning") && err.contains("followed by another rate step"),
        "{err}"
    );
    let p = write(
        &dir,
        "jerk.toml",
        "[procedure]\nname = \"jerk\"\ndut_type = \"RL-16\"\n\n[[main]]\naction = \"rate\"\nlabel = \"a\"\nrate_dps = 10.0\nrevolutions = 1\nacc_dps2 = 500.0\n",
    );
    let o = gyrobench(&["check", s(&p)]);
    assert!(stderr(&o).contains("main.0.acc_dps2"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Ramps between rates: each step keeps turning and the next ramps from
/// its rate (from 10 to 40 deg/s at 1 deg/s^2, stepped by the host), and
/// the table is seen passing through the rates between them.
#[test]
fn a_ramp_between_rates_passes_through_the_rates_between() {
    let dir = temp_dir("rate-ramp");
    let p = write(
        &dir,
        "ramp.toml",
        r#"[procedure]
name = "ramp"
dut_type = "RL-16"

[[setup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }

[[main]]
action = "rate"
label = "r10"
rate_dps = 10.0
revolutions = 1
keep_turning = true

[[main]]
action = "rate"
label = "r40"
rate_dps = 40.0
revolutions = 4
acc_dps2 = 1.0
keep_turning = true

[[main]]
action = "rate"
label = "r-10"
rate_dps = -10.0
revolutions = 1
acc_dps2 = 5.0
keep_turning = true

[[main]]
action = "rate"
label = "r-40"
rate_dps = -40.0
revolutions = 4
acc_dps2 = 5.0

[[main]]
action = "measure"
name = "scale_factor_ppm"
metric = "scale_factor"
records = ["r*"]
low = -100.0
high = 100.0
unit = "ppm"

[[cleanup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }
"#,
    );
    let out = dir.join("run");
    let o = gyrobench(&["run", s(&p), "--out", s(&out), "--db", "none"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // The table's 1 Hz states between the two records: rates between 10
    // and 40 deg/s, rising about 1 deg/s each second.
    let replayed = replay(&out.join("run.mcap"), None).expect("replays");
    let between: Vec<f64> = replayed
        .result
        .records
        .all()
        .into_iter()
        .filter(|(rec, _)| !*rec)
        .map(|(_, iv)| iv.reference_dph / 3600.0)
        .filter(|r| *r > 11.0 && *r < 39.0)
        .collect();
    assert!(
        between.len() >= 25,
        "30 s of ramp at 1 deg/s^2, seen {} s: {between:?}",
        between.len()
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The same `rate` steps on `sim serve` over TCP and a pty: the driver
/// turns the table in the ACL command language and the figures come out.
/// Records of 3 min at 30x: a host's scheduling jitter of a millisecond or
/// two moves a few dozen frames across a record's ends, which a 36 s record
/// would count as lost (its allowance is 0.1 %).
#[test]
fn rate_steps_run_on_sim_serve_over_tcp_and_pty() {
    let _turn = crate::common::wall_clock_turn();
    let dir = temp_dir("rate-served");
    let served = crate::common::SimServe::start(&dir, 30.0);
    let p = write(
        &dir,
        "ladder.toml",
        r#"[procedure]
name = "ladder"
dut_type = "RL-16"

[[setup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }

[[main]]
action = "rate"
label = "r+20"
rate_dps = 20.0
revolutions = 10

[[main]]
action = "rate"
label = "r-20"
rate_dps = -20.0
revolutions = 10

[[main]]
action = "rate"
label = "r+50"
rate_dps = 50.0
revolutions = 25

[[main]]
action = "rate"
label = "r-50"
rate_dps = -50.0
revolutions = 25

[[main]]
action = "measure"
name = "scale_factor_ppm"
metric = "scale_factor"
records = ["r*"]
low = -100.0
high = 100.0
unit = "ppm"

[[cleanup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }
"#,
    );
    for scheme in ["tcp://", "pty://"] {
        let bench = served.bench_file(&dir, scheme, 30.0);
        let out = dir.join(format!("run-{}", scheme.trim_end_matches("://")));
        let o = gyrobench(&[
            "run",
            s(&p),
            "--bench",
            s(&bench),
            "--dut",
            "RL16-0042",
            "--out",
            s(&out),
            "--db",
            "none",
        ]);
        assert_eq!(
            o.status.code(),
            Some(0),
            "{scheme}: {}\n{}",
            stderr(&o),
            String::from_utf8_lossy(&o.stdout)
        );
        let report = json(&out.join("report.json"));
        let (sf, se) = figure(&report, "scale_factor_ppm");
        assert!(sf.abs() <= 3.0 * se + 1.0, "{scheme}: {sf} +- {se} ppm");
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The rate ladder at -40, +20 and +50 degC measures the scale factor's
/// temperature coefficient; `calibrate` fits it into `[scale_factor]`,
/// and `diagnose` names the library's `scale_factor_temperature` with it.
#[test]
fn the_scale_factor_temperature_coefficient_comes_from_rate_runs() {
    let dir = temp_dir("rate-temperature");
    let mut twin = TwinConfig::default_rl16();
    let sft = twin
        .effects
        .scale_factor_temperature
        .as_mut()
        .expect("the default file has the effect");
    sft.enabled = true;
    sft.ppm_per_c = 2.0;
    sft.reference_c = 20.0;
    let twin = write(&dir, "twin.toml", &twin.to_toml().expect("twin TOML"));
    let out = dir.join("run");
    let o = run("rate_transfer_temperatures.toml", &twin, &out);
    assert_eq!(
        o.status.code(),
        Some(3),
        "2 ppm/degC is beyond 1: {}",
        stderr(&o)
    );
    let report = json(&out.join("report.json"));
    assert_within_3_se(
        "scale factor temperature coefficient",
        figure(&report, "scale_factor_temperature_ppm_per_c"),
        2.0,
    );
    let log = out.join("run.mcap");
    let coeffs = dir.join("sf.toml");
    let o = gyrobench(&["calibrate", s(&log), "-o", s(&coeffs), "--db", "none"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let t: toml::Table =
        toml::from_str(&std::fs::read_to_string(&coeffs).expect("written")).expect("TOML");
    let sf = t["scale_factor"].as_table().expect("[scale_factor]");
    let f = |k: &str| sf[k].as_float().expect(k);
    assert_within_3_se(
        "calibrated ppm/degC",
        (f("ppm_per_c"), f("ppm_per_c_stderr")),
        2.0,
    );
    // At the reference (the records' mean block temperature) the error is
    // the coefficient times its distance from the twin's 20 degC.
    let at_ref = 2.0 * (f("reference_c") - 20.0);
    assert!(
        (f("error_ppm") - at_ref).abs() < 0.5,
        "{} ppm at {} degC, the twin's {at_ref}",
        f("error_ppm"),
        f("reference_c")
    );
    let diag = dir.join("diag");
    let o = gyrobench(&["diagnose", s(&log), "--out", s(&diag)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let d = json(&diag.join("diagnosis.json"));
    let named = &d["effects"][0];
    assert_eq!(named["name"], "scale_factor_temperature", "{d}");
    let per_c = named["parameters"]["per_c"].as_f64().expect("per_c");
    assert!((per_c - 2e-6).abs() < 0.05e-6, "{per_c}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The scale factor is counts per angle: a unit whose frame clock is 50
/// ppm fast (its frames read every rate 50 ppm low over time) gives the
/// scale factor of the same unit at 0 ppm to within 1 ppm, the figures
/// over whole revolutions of the table; the log replays to the same
/// report.
#[test]
fn a_frame_clock_error_does_not_reach_the_scale_factor() {
    let dir = temp_dir("rate-frame-clock");
    let mut figures = Vec::new();
    for ppm in [0.0, 50.0] {
        let mut twin = TwinConfig::default_rl16();
        twin.gyro.frame_clock_error_ppm = ppm;
        let twin = write(
            &dir,
            &format!("twin{ppm}.toml"),
            &twin.to_toml().expect("twin TOML"),
        );
        let out = dir.join(format!("run{ppm}"));
        let o = run("rate_transfer.toml", &twin, &out);
        assert_eq!(o.status.code(), Some(0), "{ppm} ppm: {}", stderr(&o));
        let report = json(&out.join("report.json"));
        let sf = report["measurements"]
            .as_array()
            .expect("measurements")
            .iter()
            .find(|m| m["name"] == "scale_factor_ppm")
            .expect("scale factor");
        assert_eq!(sf["note"], "", "every record over whole turns: {sf}");
        figures.push(figure(&report, "scale_factor_ppm").0);
        // Over time (counts over frames at the nominal period) the same
        // records read the clock's error.
        let log = out.join("run.mcap");
        let replayed = replay(&log, None).expect("the log replays");
        let records = &replayed.result.records;
        let by_time: Vec<RatePoint> = records
            .order
            .iter()
            .filter(|l| l.starts_with("rate_"))
            .filter_map(|l| RatePoint::of(&records.get(l)?))
            .collect();
        let over_time = rate::scale_factor_ppm(&by_time).expect("fit").value;
        assert!(
            (over_time - figures[0] + ppm).abs() < 1.0,
            "{ppm} ppm over time: {over_time}"
        );
        let again = dir.join(format!("replayed{ppm}"));
        let r = gyrobench(&["replay", s(&log), "--out", s(&again)]);
        assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
        assert_eq!(
            std::fs::read_to_string(out.join("report.json")).expect("live"),
            std::fs::read_to_string(again.join("report.json")).expect("replayed"),
        );
    }
    assert!(
        (figures[1] - figures[0]).abs() < 1.0,
        "50 ppm of frame clock moved the scale factor: {figures:?}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A rate run killed mid-record resumes with that record's turn: the
/// table is turned again before the record is retaken, and the run ends
/// with its figures.
#[test]
fn a_rate_run_killed_mid_record_resumes_with_the_turn() {
    let dir = temp_dir("rate-resume");
    let out = dir.join("run");
    // After the soak and the hour of warm-up, inside the +1 deg/s record.
    let o = gyrobench(&[
        "run",
        &format!("{PROCEDURES}/rate_transfer.toml"),
        "--out",
        s(&out),
        "--db",
        "none",
        "--inject",
        "process-kill@6200",
    ]);
    assert_eq!(o.status.code(), None, "killed: {}", stderr(&o));
    let o = gyrobench(&["run", "--resume", s(&out), "--db", "none"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(0), "{err}");
    let first = err
        .lines()
        .find(|l| l.starts_with('[') && !l.starts_with("[restore"))
        .unwrap_or_else(|| panic!("no step in {err}"));
    assert!(
        first.contains("turn the inner axis at +1 deg/s"),
        "the resumed part starts with the turn: {first}"
    );
    let report = json(&out.join("report.json"));
    let (sf, se) = figure(&report, "scale_factor_ppm");
    assert!(sf.abs() <= 3.0 * se + 0.1, "{sf} +- {se}");
    assert!(out.join("run.part2.mcap").is_file());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// `procedures/misalignment.toml` measures the tilt of the input axis:
/// the outer axis turning both ways at roll 0 reads the twin's tilt about
/// body z, at roll 90 its tilt about y; an aligned unit reads none, and
/// the replayed log gives the same figures.
#[test]
fn the_misalignment_run_measures_the_twins_axis_tilts() {
    let dir = temp_dir("rate-misalignment");
    for (y, z) in [(2.0, -1.0), (-0.5, 3.0), (0.0, 0.0)] {
        let mut twin = TwinConfig::default_rl16();
        let m = twin
            .effects
            .axis_misalignment
            .as_mut()
            .expect("the default file has the effect");
        m.enabled = y != 0.0 || z != 0.0;
        m.about_y_arcmin = y;
        m.about_z_arcmin = z;
        let twin = write(&dir, "twin.toml", &twin.to_toml().expect("twin TOML"));
        let out = dir.join(format!("run-{y}-{z}"));
        let o = run("misalignment.toml", &twin, &out);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let report = json(&out.join("report.json"));
        assert_within_3_se(
            "roll 0: tilt about z",
            figure(&report, "misalignment_roll000_arcsec"),
            60.0 * z,
        );
        assert_within_3_se(
            "roll 90: tilt about y",
            figure(&report, "misalignment_roll090_arcsec"),
            60.0 * y,
        );
        let replayed = replay(&out.join("run.mcap"), None).expect("replay");
        let live: Vec<Option<f64>> = report["measurements"]
            .as_array()
            .expect("measurements")
            .iter()
            .map(|m| m["value"].as_f64())
            .collect();
        let again: Vec<Option<f64>> = replayed
            .result
            .measurements
            .iter()
            .map(|m| m.value)
            .collect();
        assert_eq!(live, again, "replay of {}", out.display());
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Three positions (axis up, horizontal east, tilted 35 deg) on a twin
/// whose bias moves 0.2 deg/h per g of gravity along its axis: the
/// g-sensitivity figure finds it, and the spread of the bias between the
/// positions shows it; with the effect off both read near zero.
#[test]
fn the_g_sensitivity_and_the_positions_spread_find_the_twins_gravity_term() {
    let dir = temp_dir("g-sensitivity");
    let procedure = write(
        &dir,
        "g.toml",
        r#"[procedure]
name = "g_sensitivity"
dut_type = "RL-16"
decision_rule = "simple"

[[main]]
action = "wait"
duration_s = 1800.0

[[main]]
action = "repeat"
positions = [
  { label = "up", orientation = { azimuth_deg = 90.0, elevation_deg = 90.0, roll_deg = 0.0 } },
  { label = "east", orientation = { azimuth_deg = 90.0, elevation_deg = 0.0, roll_deg = 0.0 } },
  { label = "tilt", orientation = { azimuth_deg = 90.0, elevation_deg = 35.0, roll_deg = 0.0 } },
]

[[main.steps]]
action = "wait"
duration_s = 300.0

[[main.steps]]
action = "record"
label = "{label}"
duration_s = 1200.0

[[main]]
action = "measure"
name = "g_sensitivity_dph_per_g"
metric = "g_sensitivity"
records = ["up", "east", "tilt"]
low = -1.0
high = 1.0
unit = "deg/h/g"

[[main]]
action = "measure"
name = "bias_spread_dph"
metric = "bias_spread"
records = ["up", "east", "tilt"]
high = 1.0
unit = "deg/h"
"#,
    );
    for (k, want) in [(0.2, 0.2), (0.0, 0.0)] {
        let mut twin = TwinConfig::default_rl16();
        twin.effects.g_sensitivity = Some(gyrobench::twin::config::GSensitivity {
            enabled: k != 0.0,
            coeff_dph_per_g: [k, 0.0, 0.0],
        });
        let file = write(
            &dir,
            &format!("twin-{k}.toml"),
            &twin.to_toml().expect("TOML"),
        );
        let out = dir.join(format!("run-{k}"));
        let o = gyrobench(&[
            "run",
            s(&procedure),
            "--twin",
            s(&file),
            "--db",
            "none",
            "--out",
            s(&out),
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let report = json(&out.join("report.json"));
        assert_within_3_se(
            &format!("g-sensitivity {k}"),
            figure(&report, "g_sensitivity_dph_per_g"),
            want,
        );
        // Up to down the axis sees 1 g: the spread is the coefficient.
        let (spread, _) = figure(&report, "bias_spread_dph");
        assert!((spread - k).abs() < 0.05, "spread {spread} for {k}");
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// `procedures/noise.toml` judges the twin's noise terms: its angle random
/// walk found within three standard errors, a bias instability and rate
/// random walk the record does not resolve judged on their bounds (at or
/// above the truth); a unit four times noisier fails on its ARW.
#[test]
fn the_noise_procedure_judges_the_twins_noise_terms() {
    let dir = temp_dir("noise");
    for (arw, exit) in [(0.002, 0), (0.008, 3)] {
        let mut twin = TwinConfig::default_rl16();
        twin.noise.arw_deg_per_rt_h = arw;
        let file = write(
            &dir,
            &format!("twin-{arw}.toml"),
            &twin.to_toml().expect("TOML"),
        );
        let out = dir.join(format!("run-{arw}"));
        let o = run("noise.toml", &file, &out);
        assert_eq!(o.status.code(), Some(exit), "{}", stderr(&o));
        let report = json(&out.join("report.json"));
        assert_within_3_se(
            &format!("ARW {arw}"),
            figure(&report, "arw_deg_per_rt_h"),
            arw,
        );
        let m = |name: &str| {
            report["measurements"]
                .as_array()
                .expect("measurements")
                .iter()
                .find(|m| m["name"] == name)
                .cloned()
                .expect(name)
        };
        let b = m("bias_instability_dph");
        let bound = b["value"].as_f64().expect("a bound");
        let resolved = !b["note"]
            .as_str()
            .is_some_and(|n| n.contains("upper bound"));
        assert!(
            resolved || bound >= twin.noise.bias_instability_dph,
            "a bound at or above the truth: {b}"
        );
        let k = m("rate_random_walk_dph_per_rt_h");
        assert!(
            k["note"]
                .as_str()
                .is_some_and(|n| n.contains("upper bound")),
            "the twin has no rate random walk: {k}"
        );
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
