//! `gyrobench diagnose`: a withheld effect is found in recorded runs, the
//! updated twin closes the gap, and the quick self-check holds its targets.

use std::path::{Path, PathBuf};

use crate::cli::{gyrobench, gyrobench_ok, temp_dir};
use crate::common::{figure, json, s};

#[test]
fn a_withheld_effect_is_found_and_the_updated_twin_closes_the_gap() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("diagnose");
    let default = String::from_utf8(gyrobench(&["twin", "default-config"]).stdout).expect("utf-8");
    let with = default.replacen(
        "[effects.hysteresis]\nenabled = false\namplitude_dph = 0.05",
        "[effects.hysteresis]\nenabled = true\namplitude_dph = 0.05",
        1,
    );
    assert_ne!(with, default);
    let twin = dir.join("hysteresis.toml");
    std::fs::write(&twin, with).expect("twin");
    // The study's two procedures on the unit with the effect.
    let mut logs = Vec::new();
    for p in ["thermal_cycle", "orientation"] {
        let procedure = format!("{}/procedures/{p}.toml", env!("CARGO_MANIFEST_DIR"));
        let run = dir.join(p);
        gyrobench(&["run", &procedure, "--twin", s(&twin), "--out", s(&run)]);
        logs.push(run.join("run.mcap"));
    }
    let (a, b) = (s(&logs[0]), s(&logs[1]));

    let out = dir.join("d1");
    let r = gyrobench(&["diagnose", a, b, "--out", s(&out)]);
    assert_eq!(
        r.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    let gap = hysteresis_is_named(&out);
    updated_twin_closes_the_gap(&dir, &logs, &out, gap);
    a_wrong_network_is_fitted_again(&dir, &twin, &logs);
    the_interchange_csv_finds_it_again(&dir, &twin, &logs, gap);

    // Bad input: a clear error.
    std::fs::write(dir.join("junk.mcap"), b"junk").expect("junk");
    let r = gyrobench(&[
        "diagnose",
        s(&dir.join("junk.mcap")),
        "--out",
        s(&dir.join("d4")),
    ]);
    assert_eq!(r.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&r.stderr).contains("not an MCAP log"));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The first diagnosis (no twin given) of the hysteresis unit's runs, in
/// `out`: the contract's keys, the thermal network fitted, hysteresis
/// named with its play width, and the page. Returns the rate layer's gap.
fn hysteresis_is_named(out: &Path) -> f64 {
    let d = json(&out.join("diagnosis.json"));
    // The contract.
    assert!(
        d["layers"]["thermal"]["gap_c"].as_f64().is_some(),
        "{}",
        d["layers"]
    );
    // Without a twin the thermal network is fitted: on the twin's own runs
    // nothing is left but the sensors' resolution, and the fit finds the
    // twin's time constants.
    let thermal = &d["layers"]["thermal"];
    assert!(
        thermal["gap_c"].as_f64().expect("gap_c") < 0.05,
        "{thermal}"
    );
    let case_tau = thermal["fitted"]["case_tau_s"].as_f64().expect("fitted");
    assert!((case_tau / 1200.0 - 1.0).abs() < 0.05, "{thermal}");
    let gap = d["layers"]["rate"]["gap_dph"].as_f64().expect("gap_dph");
    let segs = d["where"].as_array().expect("where");
    assert!(!segs.is_empty());
    for k in ["run", "step", "start_s", "end_s", "regime", "share"] {
        assert!(!segs[0][k].is_null(), "where[0].{k}");
    }
    assert!(d["confounded"].is_array());
    assert!(d["unexplained"]["gap_dph"].as_f64().is_some());
    let e = &d["effects"][0];
    assert_eq!(e["name"], "hysteresis", "{}", d["effects"]);
    for k in [
        "parameters",
        "held_out_gap_before_dph",
        "held_out_gap_after_dph",
        "shrink",
        "p_value",
    ] {
        assert!(!e[k].is_null(), "effects[0].{k}");
    }
    assert!(e["shrink"].as_f64().expect("shrink") > 0.35, "{e}");
    assert!(e["p_value"].as_f64().expect("p") < 0.01, "{e}");
    let width = e["parameters"]["width_c"].as_f64().expect("width");
    assert!((1.0..=4.0).contains(&width), "play width {width} (twin: 2)");
    let html = std::fs::read_to_string(out.join("diagnosis.html")).expect("html");
    for part in [
        "Rate residual, held out",
        "Thermal residual",
        "Residual per position",
        "Residual Allan deviation",
    ] {
        assert!(html.contains(part), "diagnosis.html lacks {part}");
    }
    // The page answers first: the layer, the effect and how far it shrinks.
    let headline = html
        .split("<p class=headline>")
        .nth(1)
        .and_then(|h| h.split("</p>").next())
        .expect("a headline");
    assert!(
        headline.contains("Hysteresis explains it") && headline.contains("% smaller"),
        "{headline}"
    );
    assert!(!html.contains("0.0e0"), "p-values read as zero");
    if d["confounded"].as_array().is_some_and(Vec::is_empty) {
        assert!(!html.contains("<h2>Confounded</h2>"), "an empty heading");
    }
    // A row per position: the orientation run's nine (the thermal cycle
    // sits at one of them).
    let rows = html.matches("<tr><td class=num>").count();
    assert!(rows >= 9, "{rows} position rows");
    gap
}

/// The updated twin (from the diagnosis in `out`) as the reference: the
/// rate layer's gap closes below 0.7 of `gap` and nothing more is named.
fn updated_twin_closes_the_gap(dir: &Path, logs: &[PathBuf], out: &Path, gap: f64) {
    let (a, b) = (s(&logs[0]), s(&logs[1]));
    let updated = out.join("twin-updated.toml");
    let text = std::fs::read_to_string(&updated).expect("twin-updated.toml");
    assert!(
        text.contains("[effects.hysteresis]\nenabled = true"),
        "{text}"
    );
    let again = dir.join("d2");
    let r = gyrobench(&["diagnose", a, b, "--twin", s(&updated), "--out", s(&again)]);
    assert_eq!(
        r.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    let d2 = json(&again.join("diagnosis.json"));
    let gap2 = d2["layers"]["rate"]["gap_dph"].as_f64().expect("gap_dph");
    assert!(gap2 < 0.7 * gap, "{gap} -> {gap2}");
    assert_eq!(
        d2["effects"].as_array().map(Vec::len),
        Some(0),
        "{}",
        d2["effects"]
    );
    // The twin's own thermal network reproduces the sensors it made.
    assert!(d2["layers"]["thermal"]["gap_c"].as_f64().expect("gap_c") < 0.05);
}

/// A twin whose thermal network is wrong: its gap shows, and the network
/// fitted from the runs is the unit's and is written to the updated twin.
fn a_wrong_network_is_fitted_again(dir: &Path, twin: &Path, logs: &[PathBuf]) {
    let (a, b) = (s(&logs[0]), s(&logs[1]));
    // A twin whose thermal network is wrong (case time constant 1800 s,
    // the unit's is 1200 s): the thermal layer carries the gap, and the
    // network fitted from the twin's values closes it in twin-updated.toml.
    let slow = dir.join("slow-case.toml");
    let wrong = std::fs::read_to_string(twin).expect("twin").replacen(
        "case_tau_s = 1200.0",
        "case_tau_s = 1800.0",
        1,
    );
    assert!(wrong.contains("case_tau_s = 1800.0"));
    std::fs::write(&slow, wrong).expect("twin");
    let third = dir.join("d3");
    let r = gyrobench(&["diagnose", a, b, "--twin", s(&slow), "--out", s(&third)]);
    assert_eq!(
        r.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    let t3 = json(&third.join("diagnosis.json"))["layers"]["thermal"].clone();
    assert!(t3["gap_c"].as_f64().expect("gap_c") > 0.3, "{t3}");
    assert!(
        t3["fitted_gap_c"].as_f64().expect("fitted_gap_c") < 0.05,
        "{t3}"
    );
    let fitted_tau = t3["fitted"]["case_tau_s"].as_f64().expect("fitted");
    assert!((fitted_tau / 1200.0 - 1.0).abs() < 0.05, "{t3}");
    let updated: toml::Table = std::fs::read_to_string(third.join("twin-updated.toml"))
        .expect("twin-updated.toml")
        .parse()
        .expect("toml");
    let tau = updated["thermal"]["case_tau_s"].as_float().expect("tau");
    assert!((tau - fitted_tau).abs() < 1e-6, "{tau}");
}

/// The runs exported to the interchange CSV and imported at the twin's
/// site: the diagnosis names hysteresis again, its gap within twice `gap`.
fn the_interchange_csv_finds_it_again(dir: &Path, twin: &Path, logs: &[PathBuf], gap: f64) {
    // The same runs through the interchange CSV (a lab's own recording):
    // exported, imported at the twin's site and diagnosed, the effect is
    // found again. The CSV carries the table's moves inside the steps that
    // made them; the diagnosis leaves them out.
    let site_toml = {
        let text = std::fs::read_to_string(twin).expect("twin");
        let start = text.find("[site]").expect("a site");
        let end = text[start + 1..]
            .find("\n[")
            .map_or(text.len(), |k| start + 1 + k);
        text[start..end].to_owned()
    };
    let site = dir.join("site.toml");
    std::fs::write(&site, site_toml).expect("site");
    let mut imported = Vec::new();
    for (k, log) in logs.iter().enumerate() {
        let csv = dir.join(format!("run{k}.csv"));
        let back = dir.join(format!("run{k}-imported.mcap"));
        assert_eq!(
            gyrobench(&["export", s(log), "-o", s(&csv)]).status.code(),
            Some(0)
        );
        let r = gyrobench(&[
            "import",
            s(&csv),
            "--site",
            s(&site),
            "--dut",
            "RL16-0042",
            "-o",
            s(&back),
        ]);
        assert!(
            r.status.code() == Some(0),
            "{}",
            String::from_utf8_lossy(&r.stderr)
        );
        imported.push(back);
    }
    let fifth = dir.join("d5");
    let r = gyrobench(&[
        "diagnose",
        s(&imported[0]),
        s(&imported[1]),
        "--out",
        s(&fifth),
    ]);
    assert_eq!(r.status.code(), Some(0));
    let d5 = json(&fifth.join("diagnosis.json"));
    let gap5 = d5["layers"]["rate"]["gap_dph"].as_f64().expect("gap_dph");
    assert!(gap5 < 2.0 * gap, "imported: {gap5} deg/h against {gap}");
    assert_eq!(d5["effects"][0]["name"], "hysteresis", "{}", d5["effects"]);
}

/// `diagnose selfcheck --runs 1 --effects EFFECTS [extra] --out DIR`:
/// its selfcheck.json, after checking it ran and found nothing in null runs.
fn quick_selfcheck(dir: &std::path::Path, effects: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "diagnose",
        "selfcheck",
        "--runs",
        "1",
        "--effects",
        effects,
        "--out",
        s(dir),
    ];
    args.extend_from_slice(extra);
    let r = gyrobench(&args);
    assert_eq!(
        r.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    // Progress on stderr, one line a trial counted "n of N" in words a
    // person reads; stdout holds the results only.
    let err = String::from_utf8_lossy(&r.stderr);
    let out = String::from_utf8_lossy(&r.stdout);
    let total = 2 + 2 * effects.split(',').count();
    for n in 1..=total {
        let want = format!("[{n:>w$}/{total}] ", w = total.to_string().len());
        assert_eq!(err.matches(&want).count(), 1, "{want}: {err}");
    }
    assert!(
        err.contains("null (nothing injected), seed 1: nothing named"),
        "{err}"
    );
    assert!(!err.contains("Some(") && !err.contains("None"), "{err}");
    assert!(
        !out.contains("seed") && out.starts_with("noise unit"),
        "{out}"
    );
    let sc = json(&dir.join("selfcheck.json"));
    assert_eq!(sc["false_positive_rate"], 0.0, "{}", sc["trials"]);
    sc
}

/// The 3x row of `effect` in a self-check's power table.
fn power_at_3x(sc: &serde_json::Value, effect: &str) -> serde_json::Value {
    sc["power"]
        .as_array()
        .expect("power")
        .iter()
        .find(|p| p["amplitude"] == 3.0 && p["effect"] == effect)
        .expect("3x row")
        .clone()
}

/// The quick version of the self-check: one run per case, one effect.
#[test]
fn the_quick_selfcheck_finds_the_effect_and_nothing_in_null_or_outside_runs() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("selfcheck");
    let sc = quick_selfcheck(&dir, "hysteresis,case_temperature", &[]);
    assert_eq!(sc["periodic_attributed"], 0.0, "{}", sc["trials"]);
    assert_eq!(sc["periodic_period_found"], 1.0, "{}", sc["trials"]);
    for effect in ["hysteresis", "case_temperature"] {
        let p3 = power_at_3x(&sc, effect);
        assert_eq!(p3["named_first"], 1.0, "{p3}");
        assert!(p3["excess_closed"].as_f64().expect("closed") >= 0.5, "{p3}");
    }
    assert!(sc["confusion"]["hysteresis@3"]["hysteresis"].as_u64() == Some(1));
    // Axis up, a case-temperature term and a short lag of it explain the
    // same thing: the simpler is named, the pair reported as confounded;
    // hysteresis is told apart from everything.
    let trial = |label: &str| {
        sc["trials"]
            .as_array()
            .expect("trials")
            .iter()
            .find(|t| t["injected"] == label)
            .expect("trial")
            .clone()
    };
    let case = trial("case_temperature@3");
    assert!(
        case["confounded"]
            .as_array()
            .expect("pairs")
            .iter()
            .any(|p| p[0] == "case_temperature" && p[1] == "thermal_lag"),
        "{case}"
    );
    assert_eq!(trial("hysteresis@3")["confounded"], serde_json::json!([]));
    assert!(
        std::fs::read_to_string(dir.join("selfcheck.html"))
            .expect("html")
            .contains("Confusion matrix")
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The shipped `procedures` run on `twin` (seed 7) into `dir`; their logs.
/// A run may end with the unit beyond its limits (exit 3): the log is
/// whole either way, and the diagnosis reads the log.
fn runs_on(
    dir: &std::path::Path,
    twin: &std::path::Path,
    procedures: &[&str],
) -> Vec<std::path::PathBuf> {
    procedures
        .iter()
        .map(|p| {
            let procedure = format!("{}/procedures/{p}.toml", env!("CARGO_MANIFEST_DIR"));
            let run = dir.join(p);
            let r = gyrobench(&[
                "run",
                &procedure,
                "--twin",
                s(twin),
                "--seed",
                "7",
                "--out",
                s(&run),
            ]);
            assert!(
                matches!(r.status.code(), Some(0 | 3)),
                "{p}: {:?} {}",
                r.status.code(),
                String::from_utf8_lossy(&r.stderr)
            );
            run.join("run.mcap")
        })
        .collect()
}

/// A misalignment with a magnetic sensitivity: the study's two runs cannot
/// tell the misalignment from a mix of g- and magnetic sensitivity (Earth
/// rate lies in the plane of gravity and the field) and say so, naming
/// `procedures/misalignment.toml`; with that run diagnosed too, both are
/// named and the misalignment comes out at the twin's angles.
#[test]
fn the_misalignment_run_tells_a_misalignment_from_magnetic_sensitivity() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("diagnose-misalignment");
    let default = String::from_utf8(gyrobench(&["twin", "default-config"]).stdout).expect("utf-8");
    let with = default
        .replacen(
            "[effects.magnetic_sensitivity]\nenabled = false\ncoeff_dph_per_ut = [0.0, 0.001, 0.001]",
            "[effects.magnetic_sensitivity]\nenabled = true\ncoeff_dph_per_ut = [0.0, 0.003, 0.0025]",
            1,
        )
        .replacen(
            "[effects.axis_misalignment]\nenabled = false\nabout_y_arcmin = 2.0\nabout_z_arcmin = 2.0",
            "[effects.axis_misalignment]\nenabled = true\nabout_y_arcmin = 25.0\nabout_z_arcmin = 20.0",
            1,
        );
    assert_eq!(
        with.matches("enabled = true").count(),
        default.matches("enabled = true").count() + 2
    );
    let twin = dir.join("twin.toml");
    std::fs::write(&twin, with).expect("twin");
    let logs = runs_on(
        &dir,
        &twin,
        &["thermal_cycle", "orientation", "misalignment"],
    );
    // The run measures the tilts itself (roll 0 about z, roll 90 about
    // y), with the magnetic sensitivity beside them; 20-25 arcmin is
    // beyond its 10 arcmin limits.
    let report = json(&dir.join("misalignment").join("report.json"));
    assert_eq!(report["outcome"], "fail", "{report}");
    for (name, truth) in [
        ("misalignment_roll000_arcsec", 20.0 * 60.0),
        ("misalignment_roll090_arcsec", 25.0 * 60.0),
    ] {
        let (v, se) = figure(&report, name);
        assert!(
            (v - truth).abs() <= 3.0 * se + 1.0,
            "{name}: {v} +- {se}, the twin's {truth}"
        );
    }
    let diagnosed = |n: usize| {
        let out = dir.join(format!("d{n}"));
        let mut args = vec!["diagnose"];
        args.extend(logs[..n].iter().map(|l| s(l)));
        args.extend(["--out", s(&out)]);
        let r = gyrobench(&args);
        assert_eq!(
            r.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&r.stderr)
        );
        (json(&out.join("diagnosis.json")), out)
    };
    let names = |d: &serde_json::Value| -> Vec<String> {
        d["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .map(|e| e["name"].as_str().expect("name").to_owned())
            .collect()
    };

    let (two, _) = diagnosed(2);
    let told = two["confounded"]
        .as_array()
        .expect("confounded")
        .iter()
        .find(|c| {
            c["effects"]
                .as_array()
                .is_some_and(|e| e.iter().any(|x| x == "axis_misalignment"))
        })
        .unwrap_or_else(|| panic!("no confound with the misalignment: {two}"));
    assert!(
        told["separate_with"]
            .as_str()
            .is_some_and(|w| w.contains("procedures/misalignment.toml")),
        "{told}"
    );

    let (three, out) = diagnosed(3);
    let named = names(&three);
    assert!(
        named.contains(&"axis_misalignment".to_owned())
            && named.contains(&"magnetic_sensitivity".to_owned()),
        "{named:?}: {}",
        three["confounded"]
    );
    let updated = std::fs::read_to_string(out.join("twin-updated.toml")).expect("twin-updated");
    let table: toml::Table = updated.parse().expect("toml");
    let m = &table["effects"]["axis_misalignment"];
    for (k, truth) in [("about_y_arcmin", 25.0), ("about_z_arcmin", 20.0)] {
        let v = m[k].as_float().expect(k);
        assert!(
            (v - truth).abs() < 0.5,
            "{k}: {v} arcmin, the twin's {truth}"
        );
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// With the study's runs a scale-factor drift hides in the temperature
/// terms; the axis-down run of `procedures/separating.toml` shows it.
#[test]
fn the_separating_run_shows_a_scale_factor_drift() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("selfcheck-separating");
    let mut shown = Vec::new();
    for extra in [&[][..], &["--separating"][..]] {
        let out = dir.join(format!("sc{}", extra.len()));
        let sc = quick_selfcheck(&out, "scale_factor_temperature", extra);
        let p3 = power_at_3x(&sc, "scale_factor_temperature");
        assert_eq!(p3["named_first"], 1.0, "{p3}");
        shown.push((
            sc["sizes"][0]["gap_per_rms"].as_f64().expect("gap_per_rms"),
            p3["coefficient"].as_f64().expect("coefficient"),
        ));
    }
    let ((study, c_study), (separating, c_separating)) = (shown[0], shown[1]);
    assert!(study < 0.3, "axis up only: {study} of the drift shows");
    assert!(separating > 0.8, "with the axis-down run: {separating}");
    // The smallest drift found at 3x the noise is several times smaller.
    assert!(c_separating < 0.25 * c_study, "{c_study} -> {c_separating}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_small_effect_is_inconclusive_and_the_deciding_run_decides_it() {
    let _busy = crate::common::busy_turn();
    // An axis misalignment of 3 arcmin (about 0.6 of the noise of 60 s
    // means between positions): with the study's runs it improves the
    // held-out gap but misses a bar.
    let dir = temp_dir("inconclusive");
    let default = String::from_utf8(gyrobench(&["twin", "default-config"]).stdout).expect("utf-8");
    let with = default.replacen(
        "[effects.axis_misalignment]\nenabled = false\nabout_y_arcmin = 2.0\nabout_z_arcmin = 2.0",
        "[effects.axis_misalignment]\nenabled = true\nabout_y_arcmin = 3.0\nabout_z_arcmin = 3.0",
        1,
    );
    assert_ne!(with, default);
    let twin = dir.join("misaligned.toml");
    std::fs::write(&twin, with).expect("twin");
    let logs = runs_on(&dir, &twin, &["thermal_cycle", "orientation"]);
    let out = dir.join("d");
    let r = gyrobench(&[
        "diagnose",
        s(&logs[0]),
        s(&logs[1]),
        "--power-replications",
        "20",
        "--out",
        s(&out),
    ]);
    assert_eq!(r.status.code(), Some(0));
    let stdout = String::from_utf8_lossy(&r.stdout).to_string();
    let d = json(&out.join("diagnosis.json"));
    assert!(d["effects"].as_array().expect("effects").is_empty(), "{d}");
    let inc = &d["inconclusive"];
    assert_eq!(inc["candidates"][0]["name"], "axis_misalignment", "{inc}");
    let c = &inc["candidates"][0];
    // It misses a bar: significance, or the held-out share (min_gain).
    assert!(
        c["p_value"].as_f64().expect("p") >= c["level"].as_f64().expect("level")
            || c["improvement"].as_f64().expect("improvement")
                < gyrobench::diagnose::THRESHOLDS.min_gain,
        "{c}"
    );
    let run = &inc["deciding_run"];
    // Its power simulated on the fitted unit, the estimate beside it.
    assert!(run["power"].as_f64().expect("power") >= 0.8, "{run}");
    assert_eq!(run["replications"], 20, "{run}");
    assert!(run["estimated_power"].as_f64().is_some(), "{run}");
    assert!(stdout.contains("simulated replications"), "{stdout}");
    assert!(
        stdout.contains("deciding run for axis_misalignment"),
        "{stdout}"
    );
    let page = std::fs::read_to_string(out.join("diagnosis.html")).expect("page");
    assert!(page.contains("<h2>Inconclusive</h2>") && page.contains("deciding-run.toml"));
    // The procedure is ready for run, and run on the unit it decides: the
    // effect is named.
    let deciding = out.join("deciding-run.toml");
    assert_eq!(gyrobench(&["check", s(&deciding)]).status.code(), Some(0));
    let more = dir.join("deciding");
    let r = gyrobench(&[
        "run",
        s(&deciding),
        "--twin",
        s(&twin),
        "--seed",
        "21",
        "--out",
        s(&more),
    ]);
    assert_eq!(r.status.code(), Some(0));
    let out2 = dir.join("d2");
    let r = gyrobench(&[
        "diagnose",
        s(&logs[1]),
        s(&more.join("run.mcap")),
        "--out",
        s(&out2),
    ]);
    assert_eq!(r.status.code(), Some(0));
    let d2 = json(&out2.join("diagnosis.json"));
    // The run decides at the simulated power (80 % or more), not always:
    // the effect is named, or an effect these positions cannot tell from
    // it is, and the diagnosis says the two are confounded.
    let named = d2["effects"][0]["name"].as_str().expect("an effect named");
    let told_confounded = d2["confounded"]
        .as_array()
        .expect("confounded")
        .iter()
        .any(|c| {
            let pair = c["effects"].to_string();
            pair.contains(named) && pair.contains("axis_misalignment")
        });
    assert!(named == "axis_misalignment" || told_confounded, "{d2}");
    // ...and says so where it is read first.
    if named != "axis_misalignment" {
        let stdout = String::from_utf8_lossy(&r.stdout).to_string();
        let first = stdout.lines().next().unwrap_or_default();
        assert!(
            first.contains("cannot tell it from") && first.contains("axis_misalignment"),
            "{first}"
        );
    }
    // A diagnosis that is not inconclusive leaves no deciding run behind.
    assert!(d2["inconclusive"].is_null());
    assert!(!out2.join("deciding-run.toml").exists());
}

#[test]
fn the_randomized_selfcheck_diagnoses_units_that_are_not_the_twin() {
    let _busy = crate::common::busy_turn();
    // Two units drawn far from the twin: a null one and one with a
    // hysteresis at its own noise, each diagnosed without a twin.
    let dir = temp_dir("randomized");
    let out = dir.join("sc");
    gyrobench_ok(&[
        "diagnose",
        "selfcheck",
        "--randomize",
        "--units",
        "2",
        "--seed",
        "1",
        "--out",
        s(&out),
    ]);
    let sc = json(&out.join("randomized.json"));
    let trials = sc["trials"].as_array().expect("trials");
    assert_eq!(
        trials.len() + sc["skipped"].as_array().expect("skipped").len(),
        2
    );
    for t in trials {
        // Each unit is its own: a noise of its own, a thermal layer that
        // follows it.
        assert!(t["noise_dph"].as_f64().expect("noise") > 0.0, "{t}");
        assert!(t["thermal_gap_c"].as_f64().expect("thermal") < 0.05, "{t}");
        if t["case"]["kind"] == "null" {
            assert!(
                t["accepted"].as_array().expect("accepted").is_empty(),
                "{t}"
            );
        }
    }
    for k in [
        "named_at_2x",
        "named_at_1_5x",
        "pairs_both_named",
        "false_attribution",
        "thermal_within_0_05",
        "median_excess_closed",
    ] {
        assert!(sc.get(k).is_some(), "{k}");
    }
}
