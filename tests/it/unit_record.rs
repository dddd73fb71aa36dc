//! The record of a unit, as quality signs it: whose coefficients, which
//! unit, who ran it where with which instruments, and a store that tells
//! the truth about the logs. Each test runs the binary as a user would,
//! against a store of its own.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::calibrate::CYCLE;
use crate::cli::{command, temp_dir};
use crate::common::{MINI, json, s, stderr, write};

/// `gyrobench ARGS` with the results store `db`.
fn with(db: &Path, args: &[&str]) -> Output {
    command()
        .env("GYROBENCH_DB", db)
        .args(args)
        .output()
        .expect("the gyrobench binary runs")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A run that must end with a verdict (pass or fail).
fn judged(db: &Path, args: &[&str]) -> Output {
    let o = with(db, args);
    assert!(
        matches!(o.status.code(), Some(0 | 3)),
        "{args:?}: {}",
        stderr(&o)
    );
    o
}

/// Two runs of unit RL16-0042 and its coefficient set, in `dir`.
fn calibrated(dir: &Path, db: &Path) -> (PathBuf, PathBuf, [PathBuf; 2]) {
    let p = write(dir, "cycle.toml", CYCLE);
    let runs = ["1", "2"].map(|seed| {
        let out = dir.join(format!("c{seed}"));
        judged(
            db,
            &[
                "run",
                s(&p),
                "--seed",
                seed,
                "--dut",
                "RL16-0042",
                "--out",
                s(&out),
            ],
        );
        out.join("run.mcap")
    });
    let set = dir.join("unit.toml");
    let o = with(db, &["calibrate", s(&runs[0]), s(&runs[1]), "-o", s(&set)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    (p, set, runs)
}

fn sha256(path: &Path) -> String {
    gyrobench::fsutil::sha256_file(path).expect("readable")
}

#[test]
fn a_coefficient_set_names_its_unit_and_another_unit_is_refused_unless_a_reason_is_given() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("unit-set");
    let db = dir.join("results.sqlite");
    let (p, set, runs) = calibrated(&dir, &db);

    // The file names the unit, its version in the store and the runs it was
    // fitted on with their logs' SHA-256; so do the JSON and the page.
    let text = std::fs::read_to_string(&set).expect("set");
    let parsed: toml::Table = toml::from_str(&text).expect("TOML");
    assert_eq!(
        parsed["unit"]["serial"].as_str(),
        Some("RL16-0042"),
        "{text}"
    );
    assert_eq!(parsed["unit"]["type"].as_str(), Some("RL-16"));
    assert_eq!(parsed["set"]["version"].as_integer(), Some(1));
    assert!(
        parsed["set"]["software"]
            .as_str()
            .is_some_and(|v| v.starts_with("gyrobench "))
    );
    let fitted = parsed["set"]["fitted_on"].as_array().expect("fitted_on");
    for (f, log) in fitted.iter().zip(&runs) {
        assert_eq!(f["log_sha256"].as_str(), Some(sha256(log).as_str()));
        let run_id = json(&log.with_file_name("report.json"))["run_id"].clone();
        assert_eq!(f["run_id"].as_str(), run_id.as_str());
    }
    let cal = json(&dir.join("unit.calibration.json"));
    assert_eq!(cal["unit"]["serial"], "RL16-0042");
    assert_eq!(cal["set"]["version"], 1);
    let page = std::fs::read_to_string(dir.join("unit.calibration.html")).expect("page");
    assert!(page.contains("RL16-0042") && page.contains(&sha256(&runs[0])));

    // Another unit: refused with exit 2, naming both.
    let other = dir.join("other");
    let o = with(
        &db,
        &[
            "run",
            s(&p),
            "--coeffs",
            s(&set),
            "--dut",
            "RL16-0099",
            "--out",
            s(&other),
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("RL16-0042") && e.contains("RL16-0099"), "{e}");
    assert!(!other.exists(), "nothing ran");

    // With a reason: used, and the reason is in the report and the store.
    let o = judged(
        &db,
        &[
            "run",
            s(&p),
            "--coeffs",
            s(&set),
            "--dut",
            "RL16-0099",
            "--coeffs-override",
            "sister unit of the same batch",
            "--out",
            s(&other),
        ],
    );
    let r = json(&other.join("report.json"));
    assert_eq!(
        r["coefficients"]["override_reason"],
        "sister unit of the same batch"
    );
    assert_eq!(r["coefficients"]["serial"], "RL16-0042");
    assert_eq!(r["coefficients"]["sha256"], sha256(&set));
    assert!(
        stdout(&o).contains("used for another unit: sister unit"),
        "{}",
        stdout(&o)
    );
    let h = with(&db, &["results", "unit", "RL16-0099", "--json"]);
    let h: serde_json::Value = serde_json::from_slice(&h.stdout).expect("JSON");
    assert_eq!(
        h["runs"][0]["coefficients"]["override_reason"],
        "sister unit of the same batch"
    );

    // --coeffs latest: the unit's newest set from the store, named by its
    // unit, version and the SHA-256 of the file calibrate wrote.
    let latest = dir.join("latest");
    judged(
        &db,
        &[
            "run",
            s(&p),
            "--coeffs",
            "latest",
            "--dut",
            "RL16-0042",
            "--out",
            s(&latest),
        ],
    );
    let r = json(&latest.join("report.json"));
    let c = &r["coefficients"];
    assert_eq!(
        (
            c["source"].as_str(),
            c["serial"].as_str(),
            c["version"].as_i64()
        ),
        (Some("store"), Some("RL16-0042"), Some(1))
    );
    assert_eq!(c["sha256"], sha256(&set));
    let note = r["measurements"][0]["note"].as_str().expect("note");
    assert!(note.contains("set 1 of RL-16 RL16-0042"), "{note}");
    let html = std::fs::read_to_string(latest.join("report.html")).expect("html");
    assert!(
        html.contains("set 1 of RL-16 RL16-0042"),
        "the page names the set"
    );
    // A unit with no set in the store: refused, saying so.
    let o = with(
        &db,
        &["run", s(&p), "--coeffs", "latest", "--dut", "RL16-0100"],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("holds no coefficient set of RL-16 RL16-0100"));

    // A set of an earlier version names no unit: refused the same way.
    let old = dir.join("old.toml");
    let without_unit: String = text
        .split("\n[model4]")
        .nth(1)
        .map(|rest| format!("[model4]{rest}"))
        .expect("model4");
    std::fs::write(&old, without_unit).expect("old set");
    let o = with(
        &db,
        &["run", s(&p), "--coeffs", s(&old), "--dut", "RL16-0042"],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("names no unit"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_bench_file_needs_the_units_serial_and_serials_follow_one_rule() {
    let dir = temp_dir("unit-serial");
    let db = dir.join("results.sqlite");
    let p = write(&dir, "mini.toml", MINI);
    let bench = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/sim-serve.toml");
    // Refused before any device is opened (nothing serves these ports).
    for (dut, says) in [
        (None, "give the unit's serial number with --dut"),
        (Some("SIMULATED"), "names no unit"),
    ] {
        let mut args = vec!["run", s(&p), "--bench", s(&bench)];
        if let Some(d) = dut {
            args.extend(["--dut", d]);
        }
        let o = with(&db, &args);
        assert_eq!(o.status.code(), Some(2), "{dut:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{}", stderr(&o));
    }
    for bad in [
        "",
        "RL16\u{1b}[31m",
        "RL16\u{202E}2400",
        &"X".repeat(10_000),
    ] {
        let o = with(&db, &["run", s(&p), "--dut", bad, "--db", "none"]);
        assert_eq!(o.status.code(), Some(2), "{bad:?}: {}", stderr(&o));
        assert!(stderr(&o).contains("--dut"), "{}", stderr(&o));
    }
    let o = with(&db, &["run", s(&p), "--operator", &"o".repeat(100_000)]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn the_report_and_the_store_say_who_ran_it_where_with_which_instruments() {
    let dir = temp_dir("unit-who");
    let db = dir.join("results.sqlite");
    let p = write(&dir, "mini.toml", MINI);
    let run = dir.join("run");
    let o = judged(
        &db,
        &[
            "run",
            s(&p),
            "--dut",
            "RL16-0042",
            "--operator",
            "J. Doe",
            "--out",
            s(&run),
        ],
    );
    // The run directory is printed with the verdict.
    assert!(
        stdout(&o).contains(&format!("run directory: {}", run.display())),
        "{}",
        stdout(&o)
    );
    let r = json(&run.join("report.json"));
    assert_eq!(r["operator"], "J. Doe");
    assert_eq!(r["bench_id"], "embedded");
    assert_eq!(r["run_id"].as_str().map(str::len), Some(32));
    assert!(!r["host"].as_str().expect("host").is_empty());
    assert!(
        !r["software_revision"]
            .as_str()
            .expect("revision")
            .is_empty()
    );
    // The simulated instruments identify themselves as their instruments do.
    let inst = r["instruments"].as_array().expect("instruments");
    assert_eq!(inst[0]["role"], "chamber");
    assert_eq!(inst[0]["identity"]["manufacturer"], "Espec");
    assert_eq!(inst[0]["identity"]["model"], "SCP-220,TEMP");
    assert_eq!(inst[1]["identity"]["serial"], "SIM-TABLE");
    assert_eq!(r["coefficients"]["source"], "fitted");
    let html = std::fs::read_to_string(run.join("report.html")).expect("html");
    for text in [
        "J. Doe",
        r["run_id"].as_str().expect("id"),
        "SCP-220,TEMP",
        "SIM-TABLE",
    ] {
        assert!(html.contains(text), "report.html lacks {text}");
    }
    // The store has the same record.
    let show = with(
        &db,
        &[
            "results",
            "show",
            r["run_id"].as_str().expect("id"),
            "--json",
        ],
    );
    let show: serde_json::Value = serde_json::from_slice(&show.stdout).expect("JSON");
    assert_eq!(show["run"]["operator"], "J. Doe");
    assert_eq!(show["run"]["bench_id"], "embedded");
    let fields: Vec<(String, String)> =
        serde_json::from_value(show["fields"].clone()).expect("fields");
    let field = |k: &str| fields.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
    assert!(field("instruments").is_some_and(|v| v.contains("SIM-TABLE")));
    assert!(field("host").is_some_and(|v| !v.is_empty()));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The embedded bench as a bench file, with the chamber's calibration due
/// `due` and the bench's policy `policy`.
fn bench_with_due(dir: &Path, due: &str, policy: &str) -> PathBuf {
    let text = gyrobench::bench::EMBEDDED_BENCH_TOML.replace(
        "[devices.chamber]\n",
        &format!("[devices.chamber]\ncalibration_due = {due}\n"),
    );
    write(
        dir,
        "bench.toml",
        &format!("overdue_calibration = \"{policy}\"\n{text}"),
    )
}

#[test]
fn an_instrument_past_its_calibration_due_date_is_flagged_or_refused() {
    let dir = temp_dir("unit-due");
    let db = dir.join("results.sqlite");
    let p = write(&dir, "mini.toml", MINI);
    let run = dir.join("overdue");
    let bench = bench_with_due(&dir, "2020-01-31", "warn");
    let o = judged(
        &db,
        &[
            "run",
            s(&p),
            "--bench",
            s(&bench),
            "--dut",
            "RL16-0042",
            "--out",
            s(&run),
        ],
    );
    let first = stdout(&o).lines().next().unwrap_or_default().to_owned();
    assert!(first.contains("(chamber calibration OVERDUE)"), "{first}");
    let r = json(&run.join("report.json"));
    assert_eq!(r["calibration_overdue"], serde_json::json!(["chamber"]));
    assert_eq!(r["instruments"][0]["calibration_due"], "2020-01-31");
    let html = std::fs::read_to_string(run.join("report.html")).expect("html");
    assert!(html.contains("CALIBRATION OVERDUE"));
    let list = with(&db, &["results", "unit", "RL16-0042"]);
    assert!(
        stdout(&list).contains("chamber calibration OVERDUE"),
        "{}",
        stdout(&list)
    );

    // Not yet due: nothing flagged.
    let fine = bench_with_due(&dir, "2999-01-31", "refuse");
    let o = judged(
        &db,
        &["run", s(&p), "--bench", s(&fine), "--dut", "RL16-0042"],
    );
    assert!(!stdout(&o).contains("OVERDUE"), "{}", stdout(&o));
    // A bench that refuses: exit 2 before anything runs.
    let refusing = bench_with_due(&dir, "2020-01-31", "refuse");
    let o = with(
        &db,
        &["run", s(&p), "--bench", s(&refusing), "--dut", "RL16-0042"],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("due 2020-01-31"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn an_imported_run_is_a_reference_and_stays_out_of_trends_and_yields() {
    let dir = temp_dir("unit-reference");
    let db = dir.join("results.sqlite");
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/import");
    let log = dir.join("lab.mcap");
    let o = with(
        &db,
        &[
            "import",
            s(&fixtures.join("lab-run.csv")),
            "--site",
            s(&fixtures.join("site.toml")),
            "--dut",
            "LAB-7",
            "-o",
            s(&log),
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let list = with(&db, &["results", "list", "--json"]);
    let rows: serde_json::Value = serde_json::from_slice(&list.stdout).expect("JSON");
    assert_eq!(rows[0]["outcome"], "reference", "{rows}");
    // A judged run beside it: the trend counts it alone.
    let p = write(&dir, "cycle.toml", CYCLE);
    judged(&db, &["run", s(&p), "--dut", "RL16-0042"]);
    let trend = |extra: &[&str]| {
        let mut args = vec!["results", "trend", "compensated_drift_pp_dph", "--json"];
        args.extend(extra);
        let o = with(&db, &args);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).expect("JSON")
    };
    assert_eq!(trend(&[])["judged"], 1);
    assert_eq!(trend(&["--include-reference"])["judged"], 2);
    // The page's axis names real dates even with the import in it.
    let page = dir.join("trend.html");
    let o = with(
        &db,
        &[
            "results",
            "trend",
            "compensated_drift_pp_dph",
            "--include-reference",
            "--html",
            s(&page),
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let html = std::fs::read_to_string(&page).expect("page");
    assert!(!html.contains("( to"), "an undated axis");
    assert!(html.contains("LAB-7") && html.contains("RL16-0042"));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_trend_gives_one_sided_indices_and_every_point_names_its_unit_run_and_report() {
    let dir = temp_dir("unit-trend");
    let db = dir.join("results.sqlite");
    let p = write(&dir, "cycle.toml", CYCLE);
    let mut ids = Vec::new();
    for (seed, serial) in [("1", "RL16-0001"), ("2", "RL16-0002"), ("3", "RL16-0003")] {
        let out = dir.join(serial);
        judged(
            &db,
            &[
                "run",
                s(&p),
                "--seed",
                seed,
                "--dut",
                serial,
                "--out",
                s(&out),
            ],
        );
        ids.push(
            json(&out.join("report.json"))["run_id"]
                .as_str()
                .expect("id")
                .to_owned(),
        );
    }
    let page = dir.join("trend.html");
    let o = with(
        &db,
        &[
            "results",
            "trend",
            "compensated_drift_pp_dph",
            "--html",
            s(&page),
            "--min-values",
            "3",
            "--json",
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let t: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    // One limit (high): Cpk is Cpu and Ppk is Ppu; no lower index.
    assert!(t["low"].is_null() && t["high"].as_f64().is_some(), "{t}");
    let (cpu, cpk) = (&t["within"]["upper"], &t["within"]["k"]);
    assert!(cpu.as_f64().is_some() && cpu == cpk, "{t}");
    assert!(t["within"]["lower"].is_null());
    assert!(t["overall"]["k"].as_f64().is_some() && t["overall"]["k"] == t["overall"]["upper"]);
    let mean = t["mean"].as_f64().expect("mean");
    let sigma = t["sigma"].as_f64().expect("sigma");
    let high = t["high"].as_f64().expect("high");
    let ppk = t["overall"]["k"].as_f64().expect("ppk");
    assert!((ppk - (high - mean) / (3.0 * sigma)).abs() < 1e-9, "{t}");
    // A peak-to-peak is non-negative with an upper limit alone: its
    // performance by percentiles of a lognormal fit is the one to read.
    let p = &t["percentile"];
    assert_eq!(p["preferred"], true, "{t}");
    let (x50, x99) = (
        p["x_50"].as_f64().expect("median"),
        p["x_99865"].as_f64().expect("percentile"),
    );
    // The median of a lognormal fit lies among the values; its tail above.
    let (lo, hi) = (
        t["min"].as_f64().expect("min"),
        t["max"].as_f64().expect("max"),
    );
    assert!(lo <= x50 && x50 <= hi && x99 > hi, "{t}");
    let ppk_pct = p["k"].as_f64().expect("Ppk by percentiles");
    assert!((ppk_pct - (high - x50) / (x99 - x50)).abs() < 1e-9, "{t}");
    let text = with(&db, &["results", "trend", "compensated_drift_pp_dph"]);
    assert!(stdout(&text).contains("Cpk ") && !stdout(&text).contains("needs both limits"));
    let html = std::fs::read_to_string(&page).expect("page");
    for (id, serial) in ids.iter().zip(["RL16-0001", "RL16-0002", "RL16-0003"]) {
        // The hover title over the dot, and the table row with its report.
        assert!(
            html.contains(&format!("{serial} run {}", &id[..12])),
            "{serial}"
        );
        let report = dir.join(serial).join("report.html");
        assert!(html.contains(&format!(
            "{}",
            report.strip_prefix(&dir).expect("below").display()
        )));
    }
    assert_eq!(
        html.matches("<title>#").count(),
        3,
        "one named target per point"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn sync_reads_only_new_or_changed_logs_and_verify_finds_what_differs() {
    let dir = temp_dir("unit-verify");
    let db = dir.join("results.sqlite");
    let runs = dir.join("runs");
    let p = write(&dir, "mini.toml", MINI);
    for n in ["a", "b", "c"] {
        judged(
            &db,
            &[
                "run",
                s(&p),
                "--dut",
                "RL16-0042",
                "--out",
                s(&runs.join(n)),
            ],
        );
    }
    // A run the store never saw.
    judged(
        &db,
        &["run", s(&p), "--db", "none", "--out", s(&runs.join("d"))],
    );

    let o = with(&db, &["results", "verify", s(&runs)]);
    assert_eq!(o.status.code(), Some(3), "{}", stdout(&o));
    assert!(stdout(&o).contains("NOT INDEXED"), "{}", stdout(&o));
    assert!(stdout(&o).contains("3 agree"), "{}", stdout(&o));

    let sync = |want: &str| {
        let o = with(&db, &["results", "sync", s(&runs)]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        assert!(stdout(&o).contains(want), "want {want}: {}", stdout(&o));
    };
    sync("1 part(s) indexed, 3 already in");
    sync("0 part(s) indexed, 4 already in");
    // The third sync reads nothing: every log is as the store last saw it.
    sync("(4 of them unchanged since the last sync, not read)");
    let o = with(&db, &["results", "verify", s(&runs), "--replay"]);
    assert_eq!(o.status.code(), Some(0), "{}", stdout(&o));
    assert!(
        stdout(&o).contains("4 stored part(s) checked, 4 agree"),
        "{}",
        stdout(&o)
    );

    // One byte changed in a log: changed, found by its SHA-256; sync reads it again.
    let a = runs.join("a/run.mcap");
    let mut bytes = std::fs::read(&a).expect("log");
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x01;
    std::fs::write(&a, &bytes).expect("tamper");
    // One log gone.
    std::fs::remove_file(runs.join("b/run.mcap")).expect("remove");
    let o = with(&db, &["results", "verify", s(&runs)]);
    assert_eq!(o.status.code(), Some(3));
    let out = stdout(&o);
    assert!(
        out.contains("CHANGED") && out.contains("a/run.mcap"),
        "{out}"
    );
    assert!(
        out.contains("MISSING") && out.contains("b/run.mcap"),
        "{out}"
    );
    let o = with(&db, &["results", "sync", s(&runs)]);
    assert!(
        stdout(&o).contains("(2 of them unchanged"),
        "{}",
        stdout(&o)
    );
    let json_out = with(&db, &["results", "verify", s(&runs), "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&json_out.stdout).expect("JSON");
    assert_eq!(v["findings"].as_array().map(Vec::len), Some(2), "{v}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn diagnose_refuses_runs_of_two_units_unless_asked_and_then_says_so() {
    let dir = temp_dir("unit-diagnose");
    let db = dir.join("results.sqlite");
    let p = write(&dir, "cycle.toml", CYCLE);
    let logs = [("1", "RL16-0042"), ("2", "RL16-0043")].map(|(seed, serial)| {
        let out = dir.join(serial);
        judged(
            &db,
            &[
                "run",
                s(&p),
                "--seed",
                seed,
                "--dut",
                serial,
                "--out",
                s(&out),
            ],
        );
        out.join("run.mcap")
    });
    let o = with(
        &db,
        &[
            "diagnose",
            s(&logs[0]),
            s(&logs[1]),
            "--out",
            s(&dir.join("d")),
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("RL16-0042") && e.contains("RL16-0043"), "{e}");
    assert!(!dir.join("d").exists());
    let o = with(
        &db,
        &[
            "diagnose",
            s(&logs[0]),
            s(&logs[1]),
            "--allow-mixed-units",
            "--power-replications",
            "0",
            "--out",
            s(&dir.join("d")),
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stdout(&o).starts_with("Runs of several units diagnosed as one"),
        "{}",
        stdout(&o)
    );
    let d = json(&dir.join("d/diagnosis.json"));
    assert_eq!(d["mixed_units"].as_array().map(Vec::len), Some(2));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
