//! `gyrobench diagnose --lot`: a batch's log of three units on a fixture
//! that tilts them alike, one with a g-sensitivity of its own: the tilt is
//! the lot's (the fixture's), the g-sensitivity the unit's, that unit the
//! outlier; each unit's twin on this bench closes its gap; units of
//! several types or sites are refused.

use crate::cli::{gyrobench, gyrobench_ok, temp_dir};
use crate::common::{json, s};

const SERIALS: [&str; 3] = ["LOT-A", "LOT-B", "LOT-C"];

/// The default twin with a tilt of 20 and 15 arcmin about z and y (the
/// fixture's), and with `g` a g-sensitivity of its own.
fn twin_text(default: &str, g: bool) -> String {
    let tilted = default.replacen(
        "[effects.axis_misalignment]\nenabled = false\nabout_y_arcmin = 2.0\nabout_z_arcmin = 2.0",
        "[effects.axis_misalignment]\nenabled = true\nabout_y_arcmin = 15.0\nabout_z_arcmin = 20.0",
        1,
    );
    assert_ne!(tilted, default, "the default twin's misalignment moved");
    if !g {
        return tilted;
    }
    let with_g = tilted.replacen(
        "[effects.g_sensitivity]\nenabled = false\ncoeff_dph_per_g = [0.0, 0.03, 0.02]",
        "[effects.g_sensitivity]\nenabled = true\ncoeff_dph_per_g = [0.0, 0.15, 0.1]",
        1,
    );
    assert_ne!(with_g, tilted, "the default twin's g-sensitivity moved");
    with_g
}

/// The orientation run of the three units as one batch (slots A-C of a
/// copy of `fixtures/bench/quad.toml`, C with the g-sensitivity).
fn batch(dir: &std::path::Path) -> std::path::PathBuf {
    let default = String::from_utf8(gyrobench(&["twin", "default-config"]).stdout).expect("utf-8");
    std::fs::write(dir.join("tilt.toml"), twin_text(&default, false)).expect("twin");
    std::fs::write(dir.join("tilt-g.toml"), twin_text(&default, true)).expect("twin");
    let quad = std::fs::read_to_string(format!(
        "{}/fixtures/bench/quad.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .expect("quad.toml");
    let bench = quad
        .replacen(
            "[[slots]]\nname = \"A\"\n",
            "[[slots]]\nname = \"A\"\ntwin = \"tilt.toml\"\n",
            1,
        )
        .replacen(
            "[[slots]]\nname = \"B\"\n",
            "[[slots]]\nname = \"B\"\ntwin = \"tilt.toml\"\n",
            1,
        )
        .replacen(
            "[[slots]]\nname = \"C\"\n",
            "[[slots]]\nname = \"C\"\ntwin = \"tilt-g.toml\"\n",
            1,
        );
    assert_eq!(bench.matches("twin = ").count(), 3, "{bench}");
    let path = dir.join("quad-tilted.toml");
    std::fs::write(&path, bench).expect("bench");
    let procedure = format!("{}/procedures/orientation.toml", env!("CARGO_MANIFEST_DIR"));
    let run = dir.join("batch");
    let duts: Vec<String> = ["A", "B", "C"]
        .iter()
        .zip(SERIALS)
        .map(|(slot, serial)| format!("{slot}={serial}"))
        .collect();
    let mut args = vec!["run", &procedure, "--bench", s(&path), "--out", s(&run)];
    for d in &duts {
        args.extend(["--dut", d.as_str()]);
    }
    let r = gyrobench(&args);
    assert_eq!(
        r.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    run.join("run.mcap")
}

#[test]
fn a_lots_shared_tilt_is_the_benchs_and_the_odd_unit_is_named() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("diagnose-lot");
    let log = batch(&dir);
    let out = dir.join("lot");
    let r = gyrobench(&["diagnose", "--lot", s(&log), "--out", s(&out)]);
    assert_eq!(
        r.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&r.stderr)
    );
    let lot = json(&out.join("lot.json"));
    // The contract: shared effects with name, parameters, units, seat,
    // shrink; units with serial, effects (as diagnosis.json lists them),
    // outlier.
    let shared = lot["shared_effects"].as_array().expect("shared_effects");
    assert_eq!(shared.len(), 1, "{}", lot["considered"]);
    let tilt = &shared[0];
    assert_eq!(tilt["name"], "axis_misalignment", "{}", lot["considered"]);
    assert_eq!(tilt["units"], serde_json::json!(SERIALS), "{tilt}");
    assert_eq!(tilt["seat"], "fixture");
    assert!(tilt["shrink"].as_f64().expect("shrink") > 0.3, "{tilt}");
    // theta_z = 20 arcmin, in rad.
    let theta_z = tilt["parameters"]["earth_y"].as_f64().expect("earth_y");
    assert!(
        (theta_z.to_degrees() * 60.0 - 20.0).abs() < 2.0,
        "{theta_z} rad"
    );
    let units = lot["units"].as_array().expect("units");
    assert_eq!(units.len(), 3);
    for (u, serial) in units.iter().zip(SERIALS) {
        assert_eq!(u["serial"], serial);
        let own: Vec<&str> = u["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .filter_map(|e| e["name"].as_str())
            .collect();
        // The tilt is listed once, not again under a unit.
        assert!(!own.contains(&"axis_misalignment"), "{serial}: {own:?}");
        let c = serial == "LOT-C";
        assert_eq!(own == ["g_sensitivity"], c, "{serial}: {own:?}");
        assert_eq!(u["outlier"], c, "{serial}: {}", u["evidence"]);
        if c {
            let e = &u["effects"][0];
            for k in ["name", "parameters", "shrink"] {
                assert!(!e[k].is_null(), "effects[0].{k}");
            }
            assert!(!u["evidence"].as_array().expect("evidence").is_empty());
        }
    }
    assert_eq!(lot["outliers"], serde_json::json!(["LOT-C"]));
    let g = &lot["gap"];
    let f = |k: &str| g[k].as_f64().expect("gap");
    assert!(
        f("after_shared_dph") < f("gap_dph") && f("after_dph") < f("after_shared_dph"),
        "{g}"
    );

    // The page and the headline say it first.
    let html = std::fs::read_to_string(out.join("lot.html")).expect("lot.html");
    let headline = html
        .split("<p class=headline>")
        .nth(1)
        .and_then(|h| h.split("</p>").next())
        .expect("a headline");
    assert!(
        headline.contains("The bench&#39;s: axis_misalignment (fixture")
            && headline.contains("LOT-C is unlike the lot"),
        "{headline}"
    );
    for part in [
        "Shared effects: the bench",
        // A chart's title, as plotters escapes it.
        "each unit&apos;s own against the lot",
        "Held-out rate gap, unit by unit",
        "Every effect weighed",
    ] {
        assert!(html.contains(part), "lot.html lacks {part}");
    }
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(stdout.starts_with("Lot of 3 RL-16 units"), "{stdout}");

    // Acting on it: the bench's correction holds the tilt; each unit's
    // twin on this bench closes its gap, its own twin leaves the tilt to
    // the bench.
    let correction =
        std::fs::read_to_string(out.join("bench-correction.toml")).expect("correction");
    let table: toml::Table = correction.parse().expect("TOML");
    assert_eq!(table["shared"][0]["seat"].as_str(), Some("fixture"));
    assert_eq!(
        table["effects"]["axis_misalignment"]["enabled"].as_bool(),
        Some(true),
        "{correction}"
    );
    let unit_dir = out.join("units").join("LOT-C");
    assert!(unit_dir.join("diagnosis.json").is_file());
    for (twin, named) in [
        ("twin-on-this-bench.toml", vec![]),
        ("twin-updated.toml", vec!["axis_misalignment"]),
    ] {
        let again = dir.join(twin);
        let r = gyrobench(&[
            "diagnose",
            s(&log),
            "--unit",
            "LOT-C",
            "--twin",
            s(&unit_dir.join(twin)),
            "--out",
            s(&again),
        ]);
        assert_eq!(
            r.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&r.stderr)
        );
        let d = json(&again.join("diagnosis.json"));
        let got: Vec<&str> = d["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .filter_map(|e| e["name"].as_str())
            .collect();
        assert_eq!(got, named, "{twin}: {}", d["effects"]);
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Units of several types, or runs at several sites, or one unit, are not
/// a lot: refused as a usage error that says why.
#[test]
fn units_of_several_types_or_sites_are_refused_as_a_lot() {
    let dir = temp_dir("diagnose-lot-refused");
    let root = env!("CARGO_MANIFEST_DIR");
    let smoke = format!("{root}/procedures/smoke.toml");
    let other_type = dir.join("smoke-rl20.toml");
    let text = std::fs::read_to_string(&smoke).expect("smoke");
    std::fs::write(
        &other_type,
        text.replacen("dut_type = \"RL-16\"", "dut_type = \"RL-20\"", 1),
    )
    .expect("procedure");
    // The embedded bench moved to another site (Paris): the smoke test's
    // poses stay in reach, only the site differs.
    let embedded =
        std::fs::read_to_string(format!("{root}/fixtures/bench/embedded.toml")).expect("bench");
    let moved = embedded.replacen(
        "latitude_deg = 50.45\nlongitude_deg = 30.52\nheight_m = 180.0",
        "latitude_deg = 48.85\nlongitude_deg = 2.35\nheight_m = 35.0",
        1,
    );
    assert_ne!(moved, embedded, "the embedded bench's site moved");
    let elsewhere = dir.join("elsewhere.toml");
    std::fs::write(&elsewhere, moved).expect("bench");
    let runs: [(&str, &str, Vec<&str>); 3] = [
        ("a", "S-1", vec![smoke.as_str()]),
        ("b", "S-2", vec![s(&other_type)]),
        ("c", "S-3", vec![smoke.as_str(), "--bench", s(&elsewhere)]),
    ];
    for (name, serial, args) in &runs {
        let out = dir.join(name);
        let mut a = vec!["run"];
        a.extend(args.iter().copied());
        a.extend(["--dut", serial, "--out", s(&out)]);
        let r = gyrobench(&a);
        assert_eq!(
            r.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&r.stderr)
        );
    }
    let log = |n: &str| dir.join(n).join("run.mcap");
    let refused = |logs: &[&std::path::Path], says: &str| {
        let mut a = vec!["diagnose", "--lot"];
        a.extend(logs.iter().map(|p| s(p)));
        let out = dir.join("d");
        a.extend(["--out", s(&out)]);
        let r = gyrobench(&a);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{logs:?}: {err}");
        assert!(err.contains(says), "{logs:?}: {err}");
        assert!(!out.join("lot.json").exists());
    };
    refused(&[&log("a"), &log("b")], "a lot is of one type");
    refused(&[&log("a"), &log("b")], "RL-20: S-2");
    refused(&[&log("a"), &log("c")], "made at 2 sites");
    refused(&[&log("a")], "two or more units");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// `diagnose selfcheck --lots N`: N lots diagnosed, their figures in
/// `lots.json` and on stdout; no lots is a usage error.
#[test]
fn the_lot_selfcheck_writes_its_figures() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("lot-selfcheck");
    let out = dir.join("sc");
    let r = gyrobench_ok(&["diagnose", "selfcheck", "--lots", "1", "--out", s(&out)]);
    let sc = json(&out.join("lots.json"));
    assert_eq!(sc["lots"], 1);
    let trials = sc["trials"].as_array().expect("trials");
    assert_eq!(trials.len(), 1, "{sc}");
    // The first lot is a shared lot: counted there, no other kind run.
    assert_eq!(trials[0]["case"]["kind"], "shared");
    assert_eq!(sc["shared_named_right"]["of"], 1);
    assert!(sc["null_false_attribution"]["rate"].is_null(), "{sc}");
    assert!(sc["outlier_flagged_right"]["rate"].is_null(), "{sc}");
    let stdout = String::from_utf8_lossy(&r.stdout);
    assert!(
        stdout.contains("shared fault named right (effect, every unit, seat): "),
        "{stdout}"
    );
    assert!(stdout.contains("null lots with anything attributed: no lot of its kind"));

    let r = gyrobench(&["diagnose", "selfcheck", "--lots", "0", "--out", s(&out)]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("--lots must be 1 or more"));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
