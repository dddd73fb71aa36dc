//! `gyrobench import` and `export`: runs recorded elsewhere, in the
//! interchange CSV, in and out, and the commands that take the result.

use std::path::Path;

use crate::cli::{gyrobench, temp_dir};
use crate::common::s;

const SITE: &str = "[site]
latitude_deg = 50.45
longitude_deg = 30.52
height_m = 180.0
magnetic_field_ned_ut = [19.5, 2.7, 46.5]
";

/// `gyrobench import CSV --site SITE -o LOG --db none`.
fn import(csv: &Path, site: &Path, log: &Path) -> std::process::Output {
    gyrobench(&[
        "import",
        s(csv),
        "--site",
        s(site),
        "-o",
        s(log),
        "--db",
        "none",
    ])
}

fn rows(p: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(p)
        .expect("csv")
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

#[test]
fn a_csv_run_imports_replays_calibrates_and_exports_back() {
    let dir = temp_dir("import");
    let csv = dir.join("cycle.csv");
    let site = dir.join("site.toml");
    std::fs::write(&site, SITE).expect("site");
    let out = gyrobench(&["twin", "study", "--csv", s(&csv), "--json"]);
    assert!(out.status.success());
    let study: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");

    let log = dir.join("cycle.mcap");
    let out = gyrobench(&["import", s(&csv), "--site", s(&site), "-o", s(&log)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!dir.join("cycle.mcap.partial").exists());

    // replay judges it like a live run; the figures are the study's own.
    let rep = dir.join("replay");
    let out = gyrobench(&["replay", s(&log), "--out", s(&rep)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rep.join("report.json")).expect("report"))
            .expect("JSON");
    let value = |name: &str| {
        r["measurements"]
            .as_array()
            .expect("list")
            .iter()
            .find(|m| m["name"] == name)
            .and_then(|m| m["value"].as_f64())
            .unwrap_or_else(|| panic!("{name} measured"))
    };
    let fig = |k: &str| {
        study["thermal"][k]
            .as_f64()
            .unwrap_or_else(|| panic!("{k}: {study}"))
    };
    assert!((value("raw_drift_pp_dph") - fig("raw_drift_pp_dph")).abs() < 1e-4);
    // The study's compensated drift is model 4 fitted to its own records:
    // the imported run's fit residual; its judged figure is held out.
    assert!(
        (value("compensated_drift_fit_residual_pp_dph") - fig("compensated_drift_pp_dph")).abs()
            < 1e-4
    );
    assert!(
        value("compensated_drift_pp_dph") >= value("compensated_drift_fit_residual_pp_dph") - 0.01
    );

    // calibrate and allan take it too.
    let out = gyrobench(&["calibrate", s(&log), "-o", s(&dir.join("c.toml"))]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = gyrobench(&["allan", s(&log), "--record", "soak_end", "--json"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // export gives the same rows back.
    let back = dir.join("back.csv");
    let out = gyrobench(&["export", s(&log), "-o", s(&back)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (a, b) = (rows(&csv), rows(&back));
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x[9], y[9], "step label");
        for c in 0..9 {
            let (u, v): (f64, f64) = (x[c].parse().expect("number"), y[c].parse().expect("number"));
            assert!((u - v).abs() < 1e-9, "column {c}: {u} vs {v}");
        }
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_live_log_exports_at_1_hz_with_its_orientation() {
    let dir = temp_dir("export");
    let run = dir.join("run");
    let smoke = concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/smoke.toml");
    gyrobench(&["run", smoke, "--out", s(&run)]);
    let csv = dir.join("smoke.csv");
    let out = gyrobench(&["export", s(&run.join("run.mcap")), "-o", s(&csv)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows = rows(&csv);
    let east: Vec<&Vec<String>> = rows.iter().filter(|r| r[9] == "east").collect();
    assert_eq!(east.len(), 180, "the 180 s record at 1 Hz");
    assert!(
        east.iter()
            .all(|r| r[7].parse::<f64>().expect("el").abs() < 1e-6
                && (r[6].parse::<f64>().expect("az") - 90.0).abs() < 1e-6)
    );
    // Not a log: an error, and no file left behind.
    let bad = dir.join("bad.csv");
    let out = gyrobench(&["export", s(&csv), "-o", s(&bad)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(!bad.exists() && !dir.join("bad.csv.partial").exists());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_bad_row_is_refused_with_its_line_and_leaves_no_file() {
    let dir = temp_dir("import-bad");
    let site = dir.join("site.toml");
    std::fs::write(&site, SITE).expect("site");
    let csv = dir.join("bad.csv");
    let mut text = String::from(
        "time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n",
    );
    for i in 0..100 {
        text.push_str(&format!("{i}.5,12.0,20,20,20,20,0,90,0,a\n"));
    }
    text.push_str("100.5,12.0,20,twenty,20,20,0,90,0,a\n");
    std::fs::write(&csv, text).expect("csv");
    let log = dir.join("bad.mcap");
    let out = gyrobench(&["import", s(&csv), "--site", s(&site), "-o", s(&log)]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.csv:102: field t2_c"), "{err}");
    assert!(!log.exists() && !dir.join("bad.mcap.partial").exists());
    // A bad site file is refused with its key.
    std::fs::write(&site, SITE.replace("50.45", "95.0")).expect("site");
    let out = gyrobench(&["import", s(&csv), "--site", s(&site), "-o", s(&log)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("site.latitude_deg"));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// `import` prints the figures it can compute at the acceptance's limits
/// as what they are, for reference: no PASS or FAIL for a run that was
/// never an acceptance, and exit 0 whatever they are; `replay` gives the
/// verdict (0 pass, 3 fail).
#[test]
fn import_gives_figures_for_reference_and_leaves_the_verdict_to_replay() {
    let dir = temp_dir("import-reference");
    let fixture = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/lab-run.csv");
    let site = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/site.toml");
    // The shipped lab run, and the same run with a drift of 1.8 deg/h per
    // hour added: beyond the acceptance's raw-drift limit.
    let text = std::fs::read_to_string(fixture).expect("fixture");
    let mut drifting = String::new();
    for (i, line) in text.lines().enumerate() {
        let mut f: Vec<String> = line.split(',').map(str::to_owned).collect();
        if i > 0 {
            let t: f64 = f[0].parse().expect("time_s");
            let rate: f64 = f[1].parse().expect("rate_dph");
            f[1] = format!("{:.6}", rate + 0.0005 * t);
        }
        drifting.push_str(&f.join(","));
        drifting.push('\n');
    }
    let drifting_csv = dir.join("drifting.csv");
    std::fs::write(&drifting_csv, drifting).expect("csv");
    for (csv, against, verdict) in [(fixture, "within", 0), (s(&drifting_csv), "beyond", 3)] {
        let log = dir.join(format!("{against}.mcap"));
        let out = gyrobench(&["import", csv, "--site", site, "-o", s(&log)]);
        let text = String::from_utf8_lossy(&out.stdout);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            text.contains("figures judged at the acceptance's limits, for reference")
                && text.contains("this run was not an acceptance")
                && text.contains(&format!("gyrobench replay {}", s(&log))),
            "{text}"
        );
        assert!(!text.contains("PASS") && !text.contains("FAIL"), "{text}");
        let raw = text
            .lines()
            .find(|l| l.trim_start().starts_with("raw_drift_pp_dph"))
            .unwrap_or_else(|| panic!("raw drift in {text}"));
        assert!(raw.ends_with(against), "{raw}");
        let out = gyrobench(&["replay", s(&log), "--out", s(&dir.join(against))]);
        assert_eq!(out.status.code(), Some(verdict), "{against}");
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// `export -o` and `import -o` never write over a run's log or a file of a
/// run directory unless told to: the report beside it would describe
/// another run.
#[test]
fn export_and_import_refuse_to_write_over_a_runs_record() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    let dir = crate::cli::temp_dir("import-overwrite");
    let p = crate::common::write(&dir, "tiny.toml", crate::common::TINY);
    let run = |name: &str| {
        let out = dir.join(name);
        let o = crate::cli::gyrobench(&["run", s(&p), "--db", "none", "--out", s(&out)]);
        assert_eq!(o.status.code(), Some(0), "{}", crate::common::stderr(&o));
        out
    };
    let (a, b) = (run("a"), run("b"));
    let before = std::fs::read(b.join("run.mcap")).expect("log");
    let fixtures = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/import");
    let import = |out: &std::path::Path, force: bool| {
        let mut args = vec![
            "import".to_owned(),
            fixtures.join("lab-run.csv").display().to_string(),
            "--site".to_owned(),
            fixtures.join("site.toml").display().to_string(),
            "--db".to_owned(),
            "none".to_owned(),
            "-o".to_owned(),
            out.display().to_string(),
        ];
        if force {
            args.push("--force".to_owned());
        }
        crate::cli::command().args(&args).output().expect("runs")
    };
    for o in [
        crate::cli::gyrobench(&[
            "export",
            s(&a.join("run.mcap")),
            "-o",
            s(&b.join("run.mcap")),
        ]),
        crate::cli::gyrobench(&[
            "export",
            s(&a.join("run.mcap")),
            "-o",
            s(&b.join("report.json")),
        ]),
        import(&b.join("run.mcap"), false),
    ] {
        assert_eq!(o.status.code(), Some(2), "{}", crate::common::stderr(&o));
        assert!(
            crate::common::stderr(&o).contains("--force"),
            "{}",
            crate::common::stderr(&o)
        );
    }
    assert_eq!(
        std::fs::read(b.join("run.mcap")).expect("log"),
        before,
        "untouched"
    );
    // A new file, or --force: written.
    let csv = dir.join("a.csv");
    let o = crate::cli::gyrobench(&["export", s(&a.join("run.mcap")), "-o", s(&csv)]);
    assert_eq!(o.status.code(), Some(0));
    let o = crate::cli::gyrobench(&["export", s(&a.join("run.mcap")), "-o", s(&csv)]);
    assert_eq!(
        o.status.code(),
        Some(0),
        "a CSV outside a run directory is the user's to replace"
    );
    let o = import(&b.join("run.mcap"), true);
    assert_eq!(o.status.code(), Some(0), "{}", crate::common::stderr(&o));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Earth rate on a sensitive axis at azimuth `az` and elevation `el`
/// (deg) at latitude `lat`, deg/h: `W (sin e sin phi + cos e cos psi cos phi)`
/// (docs/physics.md), written out here rather than taken from the crate.
fn earth_rate_dph(lat: f64, az: f64, el: f64) -> f64 {
    let w = 7.292_115e-5_f64.to_degrees() * 3600.0;
    let (phi, psi, e) = (lat.to_radians(), az.to_radians(), el.to_radians());
    w * (e.sin() * phi.sin() + e.cos() * psi.cos() * phi.cos())
}

/// Orientations spread over the whole sphere of axis directions (a
/// Fibonacci lattice, with the poles, the horizontal axis pointing north
/// a low-latitude lab reverses about, and the 55 deg tilt made toward
/// north), each at every roll in 45 deg steps.
fn poses_on_the_sphere() -> Vec<(f64, f64, f64)> {
    let mut axes = vec![
        (0.0, 90.0),
        (0.0, -90.0),
        (0.0, 0.0),
        (180.0, 0.0),
        (0.0, 35.0),
    ];
    let n = 24;
    for i in 0..n {
        let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
        let az = (i as f64 * 137.507_764_05).rem_euclid(360.0);
        axes.push((az, z.asin().to_degrees()));
    }
    let mut out = Vec::new();
    for (az, el) in axes {
        for k in 0..8 {
            out.push((az, el, -180.0 + 45.0 * k as f64));
        }
    }
    out
}

#[test]
fn any_orientation_on_the_sphere_imports_judges_and_exports_back() {
    let dir = temp_dir("import-sphere");
    let site = dir.join("site.toml");
    std::fs::write(&site, SITE).expect("site");
    // Seven 1 Hz rows per pose: the rate is the Earth rate the pose sees
    // plus a constant bias, so every figure of the drift is zero exactly
    // when the importer takes the pose as given. The first row of each
    // pose after the first is the second the table turned in: outside the
    // records (the other six, 1392 s in all, give the drift figures).
    let bias = 3.25;
    let mut csv = String::from(
        "time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n",
    );
    let poses = poses_on_the_sphere();
    let mut t = 0.5;
    for (i, (az, el, roll)) in poses.iter().enumerate() {
        for _ in 0..7 {
            let rate = earth_rate_dph(50.45, *az, *el) + bias;
            csv.push_str(&format!(
                "{t:.3},{rate},20.5,20.4,20.1,20,{az},{el},{roll},pose_{i}\n"
            ));
            t += 1.0;
        }
    }
    let file = dir.join("sphere.csv");
    std::fs::write(&file, &csv).expect("csv");
    let log = dir.join("sphere.mcap");
    let out = import(&file, &site, &log);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(&format!("({} s outside records", poses.len() - 1)),
        "{text}"
    );

    // Export gives the very rows back.
    let back = dir.join("back.csv");
    let out = gyrobench(&["export", s(&log), "-o", s(&back)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (a, b) = (rows(&file), rows(&back));
    assert_eq!(a.len(), poses.len() * 7);
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x[9], y[9], "step label");
        for c in 0..9 {
            let (u, v): (f64, f64) = (x[c].parse().expect("number"), y[c].parse().expect("number"));
            assert!((u - v).abs() < 1e-9, "{}: column {c}: {u} vs {v}", x[9]);
        }
    }

    // Replay judges it from the orientations: the Earth rate of every pose
    // is taken out (no drift left), and each record's position is its pose,
    // with no table angles (none were given).
    let rep = dir.join("replay");
    let out = gyrobench(&["replay", s(&log), "--out", s(&rep)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rep.join("report.json")).expect("report"))
            .expect("JSON");
    let raw = r["measurements"]
        .as_array()
        .expect("list")
        .iter()
        .find(|m| m["name"] == "raw_drift_pp_dph")
        .and_then(|m| m["value"].as_f64())
        .expect("raw drift judged");
    assert!(
        raw.abs() < 1e-6,
        "the drift left by the reference: {raw} deg/h"
    );
    let positions = r["positions"].as_array().expect("positions");
    assert_eq!(positions.len(), poses.len());
    for (p, (az, el, roll)) in positions.iter().zip(&poses) {
        let o = &p["orientation"];
        assert_eq!(o["azimuth_deg"].as_f64(), Some(*az), "{p}");
        assert_eq!(o["elevation_deg"].as_f64(), Some(*el), "{p}");
        assert_eq!(o["roll_deg"].as_f64(), Some(*roll), "{p}");
        assert!(p["table"].is_null(), "{p}");
    }
    // The pose a low-latitude lab reverses about is named for what it is.
    assert_eq!(
        positions[2 * 8]["description"].as_str(),
        Some("axis horizontal toward azimuth 0 deg, roll 180 deg"),
        "{}",
        positions[2 * 8]
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_table_geometry_with_the_site_gives_table_angles_or_names_the_rows_it_cannot_reach() {
    let dir = temp_dir("import-geometry");
    // The study's table: its outer axis on the north-south line, the unit
    // along the inner axis; it reaches axis up and the tilts toward east,
    // never the axis horizontal pointing north.
    let site = dir.join("site.toml");
    std::fs::write(
        &site,
        format!(
            "{SITE}\n[table.geometry]\nouter_axis_ned = [-1.0, 0.0, 0.0]\ninner_axis_ned = [0.0, 1.0, 0.0]\nmount = {{ azimuth_deg = 90.0, elevation_deg = 0.0, roll_deg = 0.0 }}\n"
        ),
    )
    .expect("site");
    let head =
        "time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n";
    let mut reachable = String::from(head);
    for i in 0..10 {
        reachable.push_str(&format!("{}.5,12,20,20,20,20,0,90,-90,up\n", i));
    }
    let good = dir.join("up.csv");
    std::fs::write(&good, &reachable).expect("csv");
    let log = dir.join("up.mcap");
    let out = import(&good, &site, &log);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rep = dir.join("replay-up");
    // The log's table states carry the angles the geometry gives.
    let out = gyrobench(&["replay", s(&log), "--out", s(&rep)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let mut north = String::from(head);
    for i in 0..10 {
        north.push_str(&format!("{}.5,9,20,20,20,20,0,0,0,north\n", i));
    }
    let bad = dir.join("north.csv");
    std::fs::write(&bad, &north).expect("csv");
    let log = dir.join("north.mcap");
    let out = import(&bad, &site, &log);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("10 row(s) do not fit the site file's [table.geometry]"),
        "{err}"
    );
    assert!(err.contains("time_s = 0.5 (step \"north\")"), "{err}");
    assert!(!log.exists());
    // Without the geometry the same rows are taken as they are.
    let plain = dir.join("plain-site.toml");
    std::fs::write(&plain, SITE).expect("site");
    let out = import(&bad, &plain, &log);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // Table-angle columns: taken as given, and checked against the geometry.
    let mut with_angles = String::from(head.trim_end());
    with_angles.push_str(",outer_deg,inner_deg\n");
    for i in 0..10 {
        with_angles.push_str(&format!(
            "{}.5,12,20,20,20,20,0,90,-90,up,90,{}\n",
            i,
            if i < 5 { 0 } else { 30 }
        ));
    }
    let cols = dir.join("cols.csv");
    std::fs::write(&cols, &with_angles).expect("csv");
    let log = dir.join("cols.mcap");
    let out = import(&cols, &plain, &log);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_file(&log).expect("rm");
    // The unit lies along the inner axis: the inner angle turns it about
    // its own axis, and 30 deg of it contradicts the roll the rows give, so
    // the geometry refuses the last five rows.
    let out = import(&cols, &site, &log);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("5 row(s) do not fit"), "{err}");
    assert!(
        err.contains("its table angles (outer 90 deg, inner 30 deg)"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The two example lab files were written from lab-run.csv's rows in
/// other units and layouts (fixtures/import/make_examples.py): read
/// through their maps, they give those rows back.
#[test]
fn the_example_maps_read_their_lab_files_back_to_the_interchange_rows() {
    let dir = temp_dir("import-maps");
    let reference = rows(Path::new("fixtures/import/lab-run.csv"));
    for (name, n, rate_tol, temp_tol) in [
        ("iso-dps-kelvin", 2400, 1e-9, 1e-9),
        // Counts of 0.01 arcsec: each 1 s mean is within one count a
        // second (0.01 deg/h); temperatures quantised to 1/16 degC.
        ("counts-10ms", 120, 0.0101, 1.0 / 32.0 + 1e-9),
    ] {
        let log = dir.join(format!("{name}.mcap"));
        let out = gyrobench(&[
            "import",
            &format!("fixtures/import/{name}.csv"),
            "--map",
            &format!("fixtures/import/{name}.map.toml"),
            "--site",
            "fixtures/import/site.toml",
            "--dut",
            "RL16-0417",
            "-o",
            s(&log),
            "--db",
            "none",
        ]);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let back = dir.join(format!("{name}.csv"));
        let out = gyrobench(&["export", s(&log), "-o", s(&back)]);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let got = rows(&back);
        assert_eq!(got.len(), n, "{name}");
        for (x, y) in reference.iter().zip(&got) {
            let f = |r: &Vec<String>, c: usize| -> f64 { r[c].parse().expect("number") };
            assert!(
                (f(x, 0) - f(y, 0)).abs() < 1e-9,
                "{name}: time {} vs {}",
                x[0],
                y[0]
            );
            assert!(
                (f(x, 1) - f(y, 1)).abs() <= rate_tol,
                "{name} at {}: rate {} vs {}",
                x[0],
                x[1],
                y[1]
            );
            for c in 2..6 {
                assert!(
                    (f(x, c) - f(y, c)).abs() <= temp_tol,
                    "{name} at {}: column {c}: {} vs {}",
                    x[0],
                    x[c],
                    y[c]
                );
            }
            for c in 6..9 {
                assert_eq!(f(x, c), f(y, c), "{name}: orientation");
            }
        }
        if name == "iso-dps-kelvin" {
            assert!(
                reference.iter().zip(&got).all(|(x, y)| x[9] == y[9]),
                "step labels"
            );
        } else {
            assert_eq!(got[59][9], "warm_up");
            assert_eq!(
                got[60][9], "hold",
                "the boundary at 63 s: the row of 63..64 s"
            );
        }
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// An imported run's report lists the pose of each record it judges, in
/// the operator's words, with no table angles it was not given, and no
/// column for a figure it does not judge (an import judges no mean bias).
#[test]
fn an_imported_runs_report_shows_each_records_pose_without_table_angles() {
    let dir = temp_dir("import-positions");
    let site = dir.join("site.toml");
    std::fs::write(&site, SITE).expect("site");
    let mut csv = String::from(
        "time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n",
    );
    let mut t = 0.5;
    for (label, az, el, n) in [
        ("warm", 0.0, 90.0, 1800),
        ("north", 0.0, 0.0, 1200),
        ("down", 0.0, -90.0, 1200),
    ] {
        for i in 0..n {
            let wobble = if i % 2 == 0 { 0.01 } else { -0.01 };
            let rate = earth_rate_dph(50.45, az, el) + 2.0 + wobble;
            csv.push_str(&format!(
                "{t},{rate},20.5,20.4,20.1,20,{az},{el},0,{label}\n"
            ));
            t += 1.0;
        }
    }
    let file = dir.join("two.csv");
    std::fs::write(&file, &csv).expect("csv");
    let log = dir.join("two.mcap");
    let out = import(&file, &site, &log);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rep = dir.join("replay");
    let out = gyrobench(&["replay", s(&log), "--out", s(&rep)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(rep.join("report.html")).expect("html");
    let at = html
        .find("<h2>Positions</h2>")
        .expect("a Positions section");
    let section = &html[at..at + html[at..].find("</table>").expect("its table")];
    assert!(
        section.contains("<td>north</td><td>axis horizontal toward azimuth 0 deg, roll 0 deg</td><td class=num>-</td><td class=num>-</td>"),
        "{section}"
    );
    assert!(
        section.contains("<td>down</td><td>axis down, azimuth 0 deg</td>"),
        "{section}"
    );
    assert!(
        section.contains("<th>bias stability, deg/h</th>"),
        "{section}"
    );
    assert!(
        !section.contains("<th>bias, "),
        "no empty bias column: {section}"
    );
    assert!(
        html[at..].contains("Limits: bias stability ..0.05 deg/h."),
        "{section}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Each measurement of a report.json, by name.
fn figures(report: &Path) -> std::collections::BTreeMap<String, Option<f64>> {
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report).expect("report")).expect("JSON");
    r["measurements"]
        .as_array()
        .expect("measurements")
        .iter()
        .map(|m| {
            (
                m["name"].as_str().expect("name").to_owned(),
                m["value"].as_f64(),
            )
        })
        .collect()
}

/// `gyrobench ARGS`, which must exit 0; its stdout.
fn ok(args: &[&str]) -> String {
    let out = gyrobench(args);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The same figures, within what 1 Hz data carries: the import takes the
/// log's own 1 Hz means (rate, temperatures, times to the millisecond)
/// and computes the Earth rate from the orientation rather than from the
/// table angles, which differ by rounding alone (1e-12 deg/h); 1e-9
/// deg/h is far below the 1e-4 a report prints.
fn assert_same_figures(
    live: &std::collections::BTreeMap<String, Option<f64>>,
    got: &std::collections::BTreeMap<String, Option<f64>>,
) {
    assert_eq!(
        live.keys().collect::<Vec<_>>(),
        got.keys().collect::<Vec<_>>(),
        "the same figures"
    );
    for (name, v) in live {
        let (a, b) = (v.expect("live value"), got[name].expect("imported value"));
        assert!((a - b).abs() < 1e-9, "{name}: {a} live, {b} imported");
    }
}

/// The nine-position run (README: runs/orientation, here without
/// --speed) exported, imported and replayed gives its own figures: the
/// sidecar carries the procedure, unit and site; moves and waits are no
/// records. Without the sidecar (through a map, or a CSV of the ten
/// columns an older export wrote) no move or wait becomes a record either.
#[test]
fn the_nine_positions_exported_and_imported_give_their_own_figures() {
    let dir = temp_dir("import-orientation");
    let procedure = concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/orientation.toml");
    let run = dir.join("orientation");
    ok(&[
        "run",
        procedure,
        "--dut",
        "RL16-0042",
        "--out",
        s(&run),
        "--db",
        "none",
    ]);
    let live = figures(&run.join("report.json"));
    assert_eq!(live.len(), 18);
    let csv = dir.join("orientation.csv");
    let text = ok(&["export", s(&run.join("run.mcap")), "-o", s(&csv)]);
    assert!(text.contains("orientation.export.toml"), "{text}");
    assert!(dir.join("orientation.export.toml").is_file());

    // No --site, --dut or --type: the sidecar gives them.
    let back = dir.join("back.mcap");
    let text = ok(&["import", s(&csv), "-o", s(&back), "--db", "none"]);
    assert!(text.contains("in 9 record(s)"), "{text}");
    assert!(text.contains("unit: RL-16 RL16-0042"), "{text}");
    let rep = dir.join("back-report");
    ok(&["replay", s(&back), "--out", s(&rep)]);
    assert_same_figures(&live, &figures(&rep.join("report.json")));
    let unit = |p: &Path| -> serde_json::Value {
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(p).expect("report"))
            .expect("JSON")["dut"]
            .clone()
    };
    assert_eq!(
        unit(&rep.join("report.json")),
        unit(&run.join("report.json")),
        "one unit: its own run and its import"
    );
    // Export of the import gives the rows back.
    let again = dir.join("again.csv");
    ok(&["export", s(&back), "-o", s(&again)]);
    assert_eq!(
        std::fs::read_to_string(&csv).expect("csv"),
        std::fs::read_to_string(&again).expect("csv")
    );

    // Without the sidecar: the CSV alone, through a map naming the record
    // column, and cut to the ten columns of an older export.
    let alone = dir.join("alone");
    std::fs::create_dir_all(&alone).expect("dir");
    std::fs::copy(&csv, alone.join("o.csv")).expect("copy");
    let ten: String = std::fs::read_to_string(&csv)
        .expect("csv")
        .lines()
        .map(|l| format!("{}\n", l.split(',').take(10).collect::<Vec<_>>().join(",")))
        .collect();
    std::fs::write(alone.join("ten.csv"), ten).expect("ten");
    let map = alone.join("o.map.toml");
    std::fs::write(
        &map,
        "[time]\ncolumn = \"time_s\"\nform = \"seconds\"\n[rate]\ncolumn = \"rate_dph\"\nunit = \"deg/h\"\n\
         [temperatures]\nt1 = \"t1_c\"\nt2 = \"t2_c\"\ntcase = \"tcase_c\"\nchamber = \"chamber_c\"\n\
         [orientation]\ncolumns = { azimuth = \"azimuth_deg\", elevation = \"elevation_deg\", roll = \"roll_deg\" }\n\
         [step]\ncolumn = \"step\"\nrecord = \"record\"\n",
    )
    .expect("map");
    let site = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/site.toml");
    for (name, extra) in [("mapped", vec!["--map", s(&map)]), ("ten", vec![])] {
        let file = if name == "ten" {
            alone.join("ten.csv")
        } else {
            alone.join("o.csv")
        };
        let log = alone.join(format!("{name}.mcap"));
        let mut args = vec![
            "import",
            s(&file),
            "--site",
            site,
            "-o",
            s(&log),
            "--db",
            "none",
        ];
        args.extend(extra);
        let text = ok(&args);
        assert!(text.contains("in 9 record(s)"), "{name}: {text}");
        let rep = alone.join(format!("{name}-report"));
        let out = gyrobench(&["replay", s(&log), "--out", s(&rep)]);
        assert_eq!(
            out.status.code(),
            Some(0),
            "{name}: the drift of records alone"
        );
        let got = figures(&rep.join("report.json"));
        assert!(
            got.keys().all(|k| !k.contains("main.")),
            "{name}: no figure of a wait or a move: {got:?}"
        );
        assert!(
            got["raw_drift_pp_dph"].expect("raw drift") < 0.1,
            "{name}: {got:?}"
        );
        for (k, v) in live.iter().filter(|(k, _)| k.starts_with("bias_stability")) {
            let g = got[k].expect("imported");
            assert!((v.expect("live") - g).abs() < 1e-9, "{name}: {k}");
        }
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The thermal cycle's start, as `procedures/thermal_cycle.toml` makes it
/// (the table moved in setup, then the self-heating record from
/// power-on), without the six hours after it: the figures' fits on the
/// whole cycle cost seconds a run.
const HEATING: &str = r#"
[procedure]
name = "heating"
description = "the thermal cycle's self-heating record"
dut_type = "RL-16"
spec = "test"

[[setup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }

[[setup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 1.0

[[main]]
action = "record"
label = "self_heating"
duration_s = 1800.0

[[main]]
action = "measure"
name = "self_heating_dph"
metric = "self_heating"
records = ["self_heating"]
high = 1.0
unit = "deg/h"

[[cleanup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 1.0
"#;

/// A thermal cycle's export keeps its self-heating on import, with its
/// sidecar and without it (setup's move is no record, so the first record
/// starts at power-on). Measured on the whole `thermal_cycle.toml` too
/// (0.4889 deg/h both ways); here on its first half hour.
#[test]
fn a_thermal_cycle_keeps_its_self_heating_through_export_and_import() {
    let dir = temp_dir("import-cycle");
    let procedure = crate::common::write(&dir, "heating.toml", HEATING);
    let run = dir.join("cycle");
    ok(&[
        "run",
        s(&procedure),
        "--dut",
        "RL16-0042",
        "--out",
        s(&run),
        "--db",
        "none",
    ]);
    let live = figures(&run.join("report.json"));
    let csv = dir.join("cycle.csv");
    ok(&["export", s(&run.join("run.mcap")), "-o", s(&csv)]);
    let back = dir.join("back.mcap");
    ok(&["import", s(&csv), "-o", s(&back), "--db", "none"]);
    let rep = dir.join("back-report");
    ok(&["replay", s(&back), "--out", s(&rep)]);
    assert_same_figures(&live, &figures(&rep.join("report.json")));
    // The CSV alone: judged by a procedure made from its rows.
    let alone = dir.join("alone");
    std::fs::create_dir_all(&alone).expect("dir");
    std::fs::copy(&csv, alone.join("cycle.csv")).expect("copy");
    let log = alone.join("cycle.mcap");
    let site = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/site.toml");
    let text = ok(&[
        "import",
        s(&alone.join("cycle.csv")),
        "--site",
        site,
        "-o",
        s(&log),
        "--db",
        "none",
    ]);
    let heating = text
        .lines()
        .find(|l| l.trim_start().starts_with("self_heating_dph"))
        .unwrap_or_else(|| panic!("self-heating in {text}"));
    let v: f64 = heating
        .split_whitespace()
        .nth(1)
        .expect("value")
        .parse()
        .expect("number");
    assert!(
        (v - live["self_heating_dph"].expect("live")).abs() < 1e-4,
        "{heating}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Without --dut or a sidecar, the run names no unit (UNNAMED), never
/// the file's name; --type records the type given (default gyro); a
/// --type against the sidecar's procedure is refused; no --site and no
/// sidecar is a usage error.
#[test]
fn an_import_names_the_unit_it_is_told_of_or_none() {
    let dir = temp_dir("import-unit");
    let fixture = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/lab-run.csv");
    let site = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/site.toml");
    let dut = |log: &Path| -> serde_json::Value {
        let rep = dir.join(format!(
            "{}-report",
            log.file_stem().expect("stem").to_string_lossy()
        ));
        ok(&["replay", s(log), "--out", s(&rep)]);
        serde_json::from_str::<serde_json::Value>(
            &std::fs::read_to_string(rep.join("report.json")).expect("report"),
        )
        .expect("JSON")["dut"]
            .clone()
    };
    let plain = dir.join("plain.mcap");
    let text = ok(&[
        "import",
        fixture,
        "--site",
        site,
        "-o",
        s(&plain),
        "--db",
        "none",
    ]);
    assert!(text.contains("unit: gyro UNNAMED (names no unit"), "{text}");
    assert_eq!(
        dut(&plain),
        serde_json::json!({"type": "gyro", "serial": "UNNAMED"})
    );
    let typed = dir.join("typed.mcap");
    ok(&[
        "import",
        fixture,
        "--site",
        site,
        "--dut",
        "RL16-0417",
        "--type",
        "RL-16",
        "-o",
        s(&typed),
        "--db",
        "none",
    ]);
    assert_eq!(
        dut(&typed),
        serde_json::json!({"type": "RL-16", "serial": "RL16-0417"})
    );
    // A sidecar whose procedure tests RL-16 units refuses another type.
    let smoke = concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/smoke.toml");
    let run = dir.join("smoke");
    ok(&["run", smoke, "--out", s(&run), "--db", "none"]);
    let csv = dir.join("smoke.csv");
    ok(&["export", s(&run.join("run.mcap")), "-o", s(&csv)]);
    let out = gyrobench(&[
        "import",
        s(&csv),
        "--type",
        "FOG-9",
        "-o",
        s(&dir.join("x.mcap")),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("--type \"FOG-9\": the procedure in")
            && err.contains("tests units of type \"RL-16\""),
        "{err}"
    );
    // No site anywhere: usage.
    let out = gyrobench(&["import", fixture, "-o", s(&dir.join("y.mcap"))]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("give --site SITE.toml"), "{err}");
    let out = gyrobench(&[
        "import",
        fixture,
        "--site",
        site,
        "--type",
        "",
        "-o",
        s(&dir.join("z.mcap")),
    ]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// An import map whose power-on lies a year before its lab file's data
/// is refused naming both times, not as a number that is not finite.
#[test]
fn a_map_with_a_power_on_far_from_the_data_is_refused_in_words() {
    let dir = temp_dir("import-power-on");
    let map = std::fs::read_to_string("fixtures/import/iso-dps-kelvin.map.toml").expect("map");
    let far = map.replace(
        "power_on = \"2026-03-02T08:00:00+07:00\"",
        "power_on = \"2025-03-02T08:00:00+07:00\"",
    );
    assert_ne!(far, map, "the map's power-on moved a year back");
    let bad = dir.join("far.map.toml");
    std::fs::write(&bad, far).expect("map");
    let out = gyrobench(&[
        "import",
        "fixtures/import/iso-dps-kelvin.csv",
        "--map",
        s(&bad),
        "--site",
        "fixtures/import/site.toml",
        "-o",
        s(&dir.join("far.mcap")),
        "--db",
        "none",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("after the power-on 2025-03-02T08:00:00+07:00 (`time.power_on`, ")
            && err.contains("the data's first time is 2026-"),
        "{err}"
    );
    assert!(!err.contains("NaN"), "{err}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
