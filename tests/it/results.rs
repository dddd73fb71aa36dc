//! The results store, on SQLite and on a real PostgreSQL server: runs
//! record themselves, `results` answers from them, exports parse, sync is
//! idempotent, bad stores are refused by name, a store that goes away
//! never loses a run, and eight benches write one store at once.
//!
//! PostgreSQL comes from `GYROBENCH_TEST_POSTGRES` (a URL; `.ci/run` starts
//! a server and sets it). Without it these tests say so and pass, except
//! under CI (`CI` set), where a missing server fails them.

use std::path::{Path, PathBuf};
use std::process::Stdio;

use crate::cli::{command, temp_dir};
use crate::common::{MINI, TINY, json, s, stderr, wait_for, write};

/// The PostgreSQL URL to test against, if any.
fn postgres() -> Option<String> {
    match std::env::var("GYROBENCH_TEST_POSTGRES") {
        Ok(url) if !url.is_empty() => Some(url),
        _ => {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI needs a PostgreSQL server: set GYROBENCH_TEST_POSTGRES (tests/conformance/postgres.sh starts one)"
            );
            eprintln!(
                "skipped: no PostgreSQL server (set GYROBENCH_TEST_POSTGRES to test against one)"
            );
            None
        }
    }
}

/// gyrobench against the store `db`.
fn with_db(db: &str, args: &[&str]) -> std::process::Output {
    command()
        .env("GYROBENCH_DB", db)
        .args(args)
        .output()
        .expect("runs")
}

fn stdout(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Two runs of two units, a resumed run, and every question of the issue:
/// list, show, unit, trend, exports, and a sync that adds nothing.
fn lifecycle(db: &str, tag: &str) {
    let dir = temp_dir(&format!("results-{tag}"));
    let (a, b) = (format!("{tag}-A-1"), format!("{tag}-B-2"));
    let resumed = record_runs(db, &dir, &a, &b);
    let unit = list_show_and_unit(db, &a, &resumed);
    trend_of_the_store(db, &dir, &b);

    let xml = dir.join("results.xml");
    let csv = dir.join("results.csv");
    let r = with_db(
        db,
        &[
            "results",
            "export",
            "--serial",
            &a,
            "--junit",
            s(&xml),
            "--csv",
            s(&csv),
        ],
    );
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    check_junit(&xml, 2);
    let rows = std::fs::read_to_string(&csv).expect("csv").lines().count();
    assert_eq!(
        rows,
        1 + unit["measurements"].as_array().map_or(0, Vec::len)
    );

    // The logs are the truth: a sync of them adds nothing, twice.
    for _ in 0..2 {
        let r = with_db(db, &["results", "sync", s(&dir)]);
        assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
        assert!(
            stdout(&r).contains(": 0 part(s) indexed, 4 already in"),
            "{}",
            stdout(&r)
        );
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Two units' runs and a run of `a` that stops and is resumed, each
/// recorded in the store `db`; returns the resumed run's folder.
fn record_runs(db: &str, dir: &Path, a: &str, b: &str) -> PathBuf {
    let p = write(dir, "tiny.toml", TINY);
    let mini = write(dir, "mini.toml", MINI);
    for (serial, seed) in [(a, "1"), (b, "2")] {
        let r = with_db(
            db,
            &[
                "run",
                s(&p),
                "--dut",
                serial,
                "--seed",
                seed,
                "--out",
                s(&dir.join(serial)),
                "--operator",
                "ana",
            ],
        );
        assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
        assert!(
            stderr(&r).contains("recorded in the results store"),
            "{}",
            stderr(&r)
        );
    }
    // A run that stops and is resumed: two parts, the second the latest.
    let resumed = dir.join("resumed");
    let r = with_db(
        db,
        &[
            "run",
            s(&mini),
            "--dut",
            a,
            "--out",
            s(&resumed),
            "--inject",
            "chamber-alarm@2500",
        ],
    );
    assert_eq!(r.status.code(), Some(1));
    let r = with_db(db, &["run", "--resume", s(&resumed)]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    resumed
}

/// The store's list (latest parts, all parts, by outcome), one run's
/// record and one unit's: each as the runs recorded by `record_runs`
/// left them. Returns the unit's record.
fn list_show_and_unit(db: &str, a: &str, resumed: &Path) -> serde_json::Value {
    let list = with_db(db, &["results", "list", "--serial", a, "--json"]);
    assert_eq!(list.status.code(), Some(0), "{}", stderr(&list));
    let runs: serde_json::Value = serde_json::from_slice(&list.stdout).expect("JSON");
    let runs = runs.as_array().expect("list");
    assert_eq!(runs.len(), 2, "latest parts only: {runs:?}");
    assert!(
        runs.iter()
            .all(|r| r["operator"] == "ana" || r["part"] == 2),
        "{runs:?}"
    );
    assert_eq!(runs[0]["part"], 2, "the resumed run, newest first");
    assert_eq!(runs[0]["outcome"], "pass");
    let all = with_db(
        db,
        &["results", "list", "--serial", a, "--all-parts", "--json"],
    );
    let all: serde_json::Value = serde_json::from_slice(&all.stdout).expect("JSON");
    assert_eq!(all.as_array().map(Vec::len), Some(3));
    let errors = with_db(
        db,
        &[
            "results",
            "list",
            "--serial",
            a,
            "--all-parts",
            "--outcome",
            "error",
            "--json",
        ],
    );
    let errors: serde_json::Value = serde_json::from_slice(&errors.stdout).expect("JSON");
    assert_eq!(errors[0]["part"], 1, "{errors}");

    let id = runs[0]["id"].as_str().expect("id");
    let show = with_db(db, &["results", "show", &id[..12]]);
    assert_eq!(show.status.code(), Some(0), "{}", stderr(&show));
    let text = stdout(&show);
    assert!(
        text.contains("PASS: mini on RL-16") && text.contains("parts:"),
        "{text}"
    );
    assert!(
        text.contains("log_sha256: ") && text.contains("procedure_sha256: "),
        "{text}"
    );
    let report = json(&resumed.join("report.json"));
    for m in report["measurements"].as_array().expect("measurements") {
        assert!(text.contains(m["name"].as_str().expect("name")), "{text}");
    }

    let unit = with_db(db, &["results", "unit", a, "--json"]);
    let unit: serde_json::Value = serde_json::from_slice(&unit.stdout).expect("JSON");
    assert_eq!(unit["runs"].as_array().map(Vec::len), Some(2));
    assert_eq!(
        unit["measurements"].as_array().map(Vec::len),
        Some(2 + report["measurements"].as_array().map_or(0, Vec::len))
    );
    unit
}

/// The store's trend of one figure: withheld below 25 values, Cpk and
/// Ppk once allowed, the same mean, sigma and extremes as the rows the
/// store exports, and a page for unit `b`.
fn trend_of_the_store(db: &str, dir: &Path, b: &str) {
    let trend = with_db(
        db,
        &[
            "results",
            "trend",
            "bias_dph:up",
            "--type",
            "RL-16",
            "--since",
            "2000-01-01",
            "--json",
        ],
    );
    assert_eq!(trend.status.code(), Some(0), "{}", stderr(&trend));
    let t: serde_json::Value = serde_json::from_slice(&trend.stdout).expect("JSON");
    // Below 25 values no index is shown, and the trend says why.
    assert!(
        t["within"]["k"].is_null() && t["overall"]["k"].is_null(),
        "{t}"
    );
    assert!(
        t["within"]["withheld"]
            .as_str()
            .is_some_and(|w| w.contains("fewer than 25")),
        "{t}"
    );
    let trend = with_db(
        db,
        &[
            "results",
            "trend",
            "bias_dph:up",
            "--type",
            "RL-16",
            "--since",
            "2000-01-01",
            "--min-values",
            "3",
            "--json",
        ],
    );
    assert_eq!(trend.status.code(), Some(0), "{}", stderr(&trend));
    let t: serde_json::Value = serde_json::from_slice(&trend.stdout).expect("JSON");
    assert!(t["count"].as_i64().expect("count") >= 3, "{t}");
    assert_eq!(t["low"], -5.0);
    assert!(
        t["within"]["k"].as_f64().expect("both limits: a Cpk") > 1.0,
        "{t}"
    );
    let k = &t["overall"];
    assert_eq!(
        k["k"].as_f64(),
        k["upper"]
            .as_f64()
            .zip(k["lower"].as_f64())
            .map(|(u, l)| u.min(l)),
        "Ppk is the smaller side: {t}"
    );
    // The same figures from the rows the store exports.
    let csv = dir.join("trend-rows.csv");
    let r = with_db(
        db,
        &[
            "results",
            "export",
            "--type",
            "RL-16",
            "--since",
            "2000-01-01",
            "--csv",
            s(&csv),
        ],
    );
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    let text = std::fs::read_to_string(&csv).expect("csv");
    let values: Vec<f64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|c| c[9] == "bias_dph:up" && !c[10].is_empty())
        .map(|c| c[10].parse().expect("value"))
        .collect();
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let sigma = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1e-6);
    assert_eq!(t["count"].as_f64(), Some(n), "{t}");
    assert!(
        close(t["mean"].as_f64().expect("mean"), mean),
        "{t} vs {mean}"
    );
    assert!(
        close(t["sigma"].as_f64().expect("sigma"), sigma),
        "{t} vs {sigma}"
    );
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert!(
        close(t["min"].as_f64().expect("min"), lo) && close(t["max"].as_f64().expect("max"), hi),
        "{t}"
    );
    let page = dir.join("trend.html");
    let r = with_db(
        db,
        &[
            "results",
            "trend",
            "bias_dph:up",
            "--serial",
            b,
            "--html",
            s(&page),
        ],
    );
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    assert!(
        std::fs::read_to_string(&page)
            .expect("page")
            .contains("<svg")
    );
}

/// The JUnit file parses with a third-party parser (Python's junitparser,
/// when CI's virtualenv is there) and has `suites` testsuites.
fn check_junit(xml: &Path, suites: usize) {
    let text = std::fs::read_to_string(xml).expect("junit");
    assert_eq!(text.matches("<testsuite ").count(), suites, "{text}");
    if let Some(python) = crate::common::python("the JUnit check by junitparser") {
        crate::common::conformance(&python, "check_junit.py", &[s(xml)]);
    }
}

#[test]
fn sqlite_records_every_run_and_answers_the_lab_questions() {
    let dir = temp_dir("results-sqlite-store");
    lifecycle(s(&dir.join("results.sqlite")), "sqlite");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn postgres_records_every_run_and_answers_the_lab_questions() {
    if let Some(url) = postgres() {
        lifecycle(&url, &format!("pg{}", std::process::id()));
    }
}

#[test]
fn a_bad_store_is_refused_by_name_and_the_run_goes_on() {
    let dir = temp_dir("results-bad");
    let p = write(&dir, "tiny.toml", TINY);
    // A file that is not SQLite.
    let corrupt = write(&dir, "corrupt.sqlite", &"not a database ".repeat(400));
    let r = with_db(s(&corrupt), &["results", "list"]);
    assert_eq!(r.status.code(), Some(1));
    assert!(
        stderr(&r).contains(&format!("results store {}", corrupt.display())),
        "{}",
        stderr(&r)
    );
    let out = dir.join("run");
    let r = with_db(s(&corrupt), &["run", s(&p), "--out", s(&out)]);
    assert_eq!(r.status.code(), Some(0), "the run goes on: {}", stderr(&r));
    assert!(stderr(&r).contains("queued"), "{}", stderr(&r));
    assert_eq!(json(&out.join("report.json"))["outcome"], "pass");
    // A schema from a newer gyrobench.
    let newer = dir.join("newer.sqlite");
    assert_eq!(
        with_db(s(&newer), &["results", "list"]).status.code(),
        Some(0)
    );
    let conn = std::process::Command::new("python3")
        .args([
            "-c",
            "import sqlite3,sys; c=sqlite3.connect(sys.argv[1]); c.execute('UPDATE gyrobench_schema SET version = 99'); c.commit()",
            s(&newer),
        ])
        .status()
        .expect("python3");
    assert!(conn.success());
    let r = with_db(s(&newer), &["results", "list"]);
    assert_eq!(r.status.code(), Some(1));
    assert!(
        stderr(&r).contains("schema is version 99, newer than this gyrobench"),
        "{}",
        stderr(&r)
    );
    // A wrong URL, and (with a server) a wrong password: the password
    // never printed.
    let r = with_db(
        "postgres://gyrobench:secret@127.0.0.1:1/nowhere",
        &["results", "list"],
    );
    assert_eq!(r.status.code(), Some(1));
    assert!(
        stderr(&r).contains("results store postgres://gyrobench@127.0.0.1:1/nowhere"),
        "{}",
        stderr(&r)
    );
    assert!(!stderr(&r).contains("secret"));
    if let Some(url) = postgres() {
        let wrong = url.replacen("gyrobench:gyrobench@", "gyrobench:not-it@", 1);
        let r = with_db(&wrong, &["results", "list"]);
        assert_eq!(r.status.code(), Some(1));
        assert!(
            stderr(&r).contains("password authentication failed"),
            "{}",
            stderr(&r)
        );
        assert!(!stderr(&r).contains("not-it"));
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A PostgreSQL server of this test's own, to stop mid-run.
struct OwnServer {
    dir: std::path::PathBuf,
}

impl OwnServer {
    fn start(dir: &Path, port: u16) -> Option<(Self, String)> {
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/conformance/postgres.sh");
        let out = std::process::Command::new(script)
            .args(["start", s(dir), &port.to_string()])
            .output()
            .ok()?;
        out.status.success().then(|| {
            (
                Self {
                    dir: dir.to_owned(),
                },
                String::from_utf8_lossy(&out.stdout).trim().to_owned(),
            )
        })
    }

    fn stop(&self) {
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/conformance/postgres.sh");
        let _stopped = std::process::Command::new(script)
            .args(["stop", s(&self.dir)])
            .status();
    }
}

impl Drop for OwnServer {
    fn drop(&mut self) {
        self.stop();
    }
}

#[test]
fn a_server_that_goes_away_mid_run_loses_nothing_and_the_run_is_written_later() {
    if postgres().is_none() {
        return;
    }
    let dir = temp_dir("results-away");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let port = 20_000 + (std::process::id() % 20_000) as u16;
    let Some((server, url)) = OwnServer::start(&dir.join("pg"), port) else {
        panic!("a PostgreSQL server of the test's own must start (tests/conformance/postgres.sh)");
    };
    let p = write(&dir, "mini.toml", MINI);
    let out = dir.join("run");
    let child = command()
        .env("GYROBENCH_DB", &url)
        .args([
            "run",
            s(&p),
            "--out",
            s(&out),
            "--speed",
            "400",
            "--dut",
            "AWAY-1",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run starts");
    wait_for(&out.join("run.mcap"));
    server.stop();
    let done = child.wait_with_output().expect("ends");
    assert_eq!(done.status.code(), Some(0), "{}", stderr(&done));
    assert!(stderr(&done).contains("is queued"), "{}", stderr(&done));
    assert_eq!(json(&out.join("report.json"))["outcome"], "pass");
    // Back: the first command that opens the store writes the run.
    let (again, url2) = OwnServer::start(&dir.join("pg"), port).expect("the server starts again");
    let r = with_db(&url2, &["results", "list", "--serial", "AWAY-1", "--json"]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    assert!(
        stderr(&r).contains("queued run(s) written"),
        "{}",
        stderr(&r)
    );
    let rows: serde_json::Value = serde_json::from_slice(&r.stdout).expect("JSON");
    assert_eq!(rows[0]["outcome"], "pass", "{rows}");
    drop(again);
    drop(server);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn eight_benches_write_one_postgres_store_at_once_and_lose_nothing() {
    let _busy = crate::common::busy_turn();
    let Some(url) = postgres() else { return };
    let dir = temp_dir("results-eight");
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("procedures/smoke.toml");
    let tag = format!("EIGHT-{}", std::process::id());
    let children: Vec<_> = (0..8)
        .map(|i| {
            command()
                .env("GYROBENCH_DB", &url)
                .args([
                    "run",
                    s(&p),
                    "--out",
                    s(&dir.join(format!("bench{i}"))),
                    "--dut",
                    &format!("{tag}-{i}"),
                    "--seed",
                    &(i + 1).to_string(),
                ])
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .expect("bench starts")
        })
        .collect();
    for c in children {
        let o = c.wait_with_output().expect("ends");
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    }
    let xml = dir.join("eight.xml");
    let mut total = 0;
    for i in 0..8 {
        let r = with_db(&url, &["results", "unit", &format!("{tag}-{i}"), "--json"]);
        assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
        let u: serde_json::Value = serde_json::from_slice(&r.stdout).expect("JSON");
        assert_eq!(u["runs"].as_array().map(Vec::len), Some(1), "bench {i}");
        let report = json(&dir.join(format!("bench{i}/report.json")));
        assert_eq!(u["measurements"], {
            let ms: Vec<serde_json::Value> = report["measurements"]
                .as_array()
                .expect("measurements")
                .iter()
                .map(|m| m["value"].clone())
                .collect();
            let stored: Vec<serde_json::Value> = u["measurements"]
                .as_array()
                .expect("stored")
                .iter()
                .map(|m| m["value"].clone())
                .collect();
            assert_eq!(stored, ms, "bench {i}: every measurement, as reported");
            u["measurements"].clone()
        });
        total += 1;
    }
    assert_eq!(total, 8);
    let r = with_db(
        &url,
        &[
            "results",
            "export",
            "--junit",
            s(&xml),
            "--since",
            "2000-01-01",
            "--procedure",
            "smoke",
        ],
    );
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A run queued because its store could not be reached waits for that
/// store: another store opened meanwhile does not take it; the store it
/// was meant for does, once it is back.
#[test]
fn a_queued_run_goes_only_to_the_store_it_was_meant_for() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("results-queue");
    let home = dir.join("home");
    let at = |db: &Path, args: &[&str]| {
        command()
            .env("XDG_DATA_HOME", &home)
            .env("GYROBENCH_DB", db)
            .args(args)
            .output()
            .expect("runs")
    };
    let p = write(&dir, "tiny.toml", TINY);
    let broken = write(&dir, "broken.sqlite", &"not a database ".repeat(400));
    let other = dir.join("other.sqlite");
    let r = at(
        &broken,
        &["run", s(&p), "--dut", "Q-1", "--out", s(&dir.join("run"))],
    );
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    assert!(stderr(&r).contains("queued"), "{}", stderr(&r));
    // Another store: the queued run is not its.
    let list = at(&other, &["results", "list", "--json"]);
    assert_eq!(list.status.code(), Some(0), "{}", stderr(&list));
    assert_eq!(stdout(&list).trim(), "[]", "{}", stdout(&list));
    // The store it was meant for, repaired: it takes it.
    std::fs::remove_file(&broken).expect("repair");
    let list = at(&broken, &["results", "list", "--json"]);
    assert!(
        stderr(&list).contains("1 queued run(s) written"),
        "{}",
        stderr(&list)
    );
    let rows: serde_json::Value = serde_json::from_slice(&list.stdout).expect("JSON");
    assert_eq!(rows[0]["serial"], "Q-1", "{rows}");
    assert_eq!(
        std::fs::read_dir(home.join("gyrobench/pending"))
            .map(|d| d.count())
            .ok(),
        Some(0)
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Run `sql` on the store `db` (a SQLite file or a PostgreSQL URL), as
/// someone with write access to it would.
fn edit_store(db: &str, sql: &str) {
    if db.starts_with("postgres") {
        let mut c = postgres::Client::connect(db, postgres::NoTls).expect("the server");
        c.batch_execute(sql).expect("the edit");
    } else {
        let c = rusqlite::Connection::open(db).expect("the file");
        c.execute_batch(sql).expect("the edit");
    }
}

/// A coefficient set of unit `serial` (type RL-16V) that no store holds.
fn set_of(serial: &str) -> String {
    format!(
        "[unit]\nserial = \"{serial}\"\ntype = \"RL-16V\"\n\n[set]\ncreated_utc = \"2026-12-03T10:00:00+00:00\"\n\
         software = \"gyrobench 0.1.0\"\nmodels = [\"model4\"]\n\n[model4]\nk1_dph_per_c = -0.12\n\
         k2_dph_per_c2 = -0.01\nk3_dph_per_c_per_s = 20.0\nk4_dph_per_c = -0.007\nk5_dph = 0.36\n\
         warmup_tau_s = 600.0\noffset_dph = 0.0\n"
    )
}

/// A run of unit `TAG-A` (with a coefficient set and an operator) and a
/// batch of two in `runs`, stored in `db`; verify agrees with them (and
/// with --replay). Their parts' keys, the single run's first.
fn stored_runs(db: &str, dir: &Path, runs: &Path, tag: &str) -> (String, String) {
    // A type of their own: the lab questions of `lifecycle`, asked of the
    // same server, are about RL-16s.
    let p = write(
        dir,
        "tiny.toml",
        &TINY.replace("dut_type = \"RL-16\"", "dut_type = \"RL-16V\""),
    );
    let unit = format!("{tag}-A");
    let set = write(dir, "set.toml", &set_of(&unit));
    let one = runs.join("one");
    let mut args = vec!["run", s(&p), "--dut", &unit, "--operator", "ana"];
    args.extend(["--coeffs", s(&set), "--out", s(&one)]);
    let r = with_db(db, &args);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    let quad = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/quad.toml");
    let (a, c) = (format!("A={tag}-Q1"), format!("C={tag}-Q3"));
    let batch = runs.join("batch");
    let mut args = vec!["run", s(&p), "--bench", s(&quad), "--dut", &a, "--dut", &c];
    args.extend(["--out", s(&batch)]);
    let r = with_db(db, &args);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    for more in [&[][..], &["--replay"][..]] {
        let mut args = vec!["results", "verify", s(runs)];
        args.extend(more);
        let v = with_db(db, &args);
        assert_eq!(v.status.code(), Some(0), "{}", stdout(&v));
    }
    let key = |report: std::path::PathBuf| {
        let id = json(&report)["run_id"].clone();
        format!("{}.1", id.as_str().expect("run id"))
    };
    (
        key(one.join("report.json")),
        key(batch.join(format!("report-{tag}-Q1.json"))),
    )
}

/// The record differences verify's JSON `v` names for the part `run`:
/// (field, the store's value, the log's).
fn named(v: &serde_json::Value, run: &str) -> Vec<(String, serde_json::Value, serde_json::Value)> {
    v["findings"]
        .as_array()
        .expect("findings")
        .iter()
        .filter(|f| f["run"] == run && f["problem"] == "record_differs")
        .flat_map(|f| f["differences"].as_array().cloned().unwrap_or_default())
        .map(|d| {
            let field = d["field"].as_str().unwrap_or("").to_owned();
            (field, d["store"].clone(), d["log"].clone())
        })
        .collect()
}

/// Runs stored in `db` ([`stored_runs`]), then their rows edited as the
/// issue's attacker did: each edit is named by field with the store's
/// value and the log's.
fn verify_names_every_field_edited(db: &str, tag: &str) {
    let dir = temp_dir(&format!("results-verify-fields-{tag}"));
    let runs = dir.join("runs");
    let (one, batch) = stored_runs(db, &dir, &runs, tag);
    let log = json(&runs.join("one/report.json"));
    let moved = format!("{tag}-MOVED");
    edit_store(
        db,
        &format!(
            "INSERT INTO units (dut_type, serial) VALUES ('RL-16V', '{moved}');
             UPDATE runs SET outcome = 'fail', operator = 'mallory', started_utc = '2020-01-01T00:00:00+00:00',
               bench_id = 'bench-9', software_revision = 'deadbeef',
               unit_id = (SELECT id FROM units WHERE serial = '{moved}') WHERE id = '{one}';
             UPDATE run_units SET outcome = 'fail', coeffs_sha256 = '00ff',
               unit_id = (SELECT id FROM units WHERE serial = '{moved}') WHERE run = '{one}';
             UPDATE run_units SET outcome = 'fail' WHERE run = '{batch}' AND slot = 'C';"
        ),
    );
    let v = with_db(db, &["results", "verify", s(&runs), "--json"]);
    assert_eq!(v.status.code(), Some(3), "{}", stdout(&v));
    let v: serde_json::Value = serde_json::from_slice(&v.stdout).expect("JSON");
    let j = serde_json::Value::from;
    let unit = format!("{tag}-A");
    let (moved, unit) = (j(moved.as_str()), j(unit.as_str()));
    assert_eq!(
        named(&v, &one),
        [
            ("operator".into(), j("mallory"), j("ana")),
            (
                "started_utc".into(),
                j("2020-01-01T00:00:00+00:00"),
                log["start_time_utc"].clone()
            ),
            ("bench_id".into(), j("bench-9"), j("embedded")),
            (
                "software_revision".into(),
                j("deadbeef"),
                log["software_revision"].clone()
            ),
            ("serial".into(), moved.clone(), unit.clone()),
            ("outcome".into(), j("fail"), j("pass")),
            ("unit.serial".into(), moved, unit),
            ("unit.outcome".into(), j("fail"), j("pass")),
            (
                "unit.coeffs_sha256".into(),
                j("00ff"),
                log["coefficients"]["sha256"].clone()
            ),
        ]
    );
    assert_eq!(
        named(&v, &batch),
        [("unit[C].outcome".into(), j("fail"), j("pass"))]
    );
    // The terminal says the same, one line per field.
    let text = stdout(&with_db(db, &["results", "verify", s(&runs)]));
    assert!(
        text.contains("RECORD DIFFERS")
            && text.contains("operator: the store has \"mallory\", the log \"ana\""),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn sqlite_verify_names_every_field_edited_away_from_the_log() {
    let dir = temp_dir("results-sqlite-verify-fields");
    verify_names_every_field_edited(s(&dir.join("results.sqlite")), "sqlite");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn postgres_verify_names_every_field_edited_away_from_the_log() {
    if let Some(url) = postgres() {
        verify_names_every_field_edited(&url, &format!("pg{}", std::process::id()));
    }
}

/// A run reviewed, then approved by someone else, in store `db`; each sign
/// out of turn refused; `show` lists both; an edited figure breaks them.
fn signing(db: &str, tag: &str) {
    let dir = temp_dir(&format!("results-sign-{tag}"));
    let p = write(
        &dir,
        "tiny.toml",
        &TINY.replace("dut_type = \"RL-16\"", "dut_type = \"RL-16S\""),
    );
    let unit = format!("{tag}-S1");
    let out = dir.join("run");
    let r = with_db(db, &["run", s(&p), "--dut", &unit, "--out", s(&out)]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    let run = json(&out.join("report.json"))["run_id"]
        .as_str()
        .expect("run id")
        .to_owned();
    let sign =
        |role: &str, by: &str| with_db(db, &["results", "sign", &run, "--role", role, "--by", by]);
    let refused = sign("approved", "Bo");
    assert_eq!(refused.status.code(), Some(2), "{}", stderr(&refused));
    assert!(
        stderr(&refused).contains("not reviewed yet"),
        "{}",
        stderr(&refused)
    );
    let r = sign("reviewed", "Al");
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    let again = sign("reviewed", "Al");
    assert_eq!(again.status.code(), Some(2), "{}", stderr(&again));
    let own = sign("approved", "Al");
    assert_eq!(own.status.code(), Some(2), "{}", stderr(&own));
    assert!(
        stderr(&own).contains("another person approves it"),
        "{}",
        stderr(&own)
    );
    let r = sign("approved", "Bo");
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));

    let shown = with_db(db, &["results", "show", &run, "--json"]);
    assert_eq!(shown.status.code(), Some(0), "{}", stderr(&shown));
    let d: serde_json::Value = serde_json::from_slice(&shown.stdout).expect("JSON");
    let signed: Vec<(String, String)> = d["signatures"]
        .as_array()
        .expect("signatures")
        .iter()
        .map(|g| {
            (
                g["role"].as_str().unwrap_or("").to_owned(),
                g["by"].as_str().unwrap_or("").to_owned(),
            )
        })
        .collect();
    assert_eq!(
        signed,
        [
            ("reviewed".into(), "Al".into()),
            ("approved".into(), "Bo".into())
        ]
    );
    let text = stdout(&with_db(db, &["results", "show", &run]));
    assert!(
        text.contains("reviewed  by Al") && text.contains("approved  by Bo"),
        "{text}"
    );

    // The report rendered again from the log with the store shows them.
    let again = dir.join("again");
    let r = with_db(
        db,
        &[
            "replay",
            s(&out.join("run.mcap")),
            "--store",
            "--out",
            s(&again),
        ],
    );
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    let html = std::fs::read_to_string(again.join("report.html")).expect("page");
    for (role, by) in [("reviewed by", "Al"), ("approved by", "Bo")] {
        let row = html.split(&format!("<th>{role}</th>")).nth(1).unwrap_or("");
        let cell = row.split("</td>").next().unwrap_or("");
        assert!(cell.contains(by), "{role}: {cell}");
    }
    assert_eq!(
        json(&again.join("report.json"))["signatures"]
            .as_array()
            .map(Vec::len),
        Some(2)
    );

    let v = with_db(db, &["results", "verify", s(&dir)]);
    assert_eq!(v.status.code(), Some(0), "{}", stdout(&v));
    // A figure edited in the store: both signatures no longer hold.
    edit_store(
        db,
        &format!("UPDATE measurements SET value = value + 1 WHERE run = '{run}.1' AND seq = 0"),
    );
    let v = with_db(db, &["results", "verify", s(&dir), "--json"]);
    assert_eq!(v.status.code(), Some(3), "{}", stdout(&v));
    let j: serde_json::Value = serde_json::from_slice(&v.stdout).expect("JSON");
    let broken: Vec<&str> = j["findings"]
        .as_array()
        .expect("findings")
        .iter()
        .filter(|f| f["problem"] == "signature_broken")
        .filter_map(|f| f["detail"].as_str())
        .collect();
    assert_eq!(broken.len(), 2, "{j}");
    assert!(
        broken
            .iter()
            .all(|d| d.contains("stored verdict or figures")),
        "{broken:?}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn sqlite_signing_reviews_then_approves_and_verify_names_an_edit_since() {
    let dir = temp_dir("results-sqlite-sign");
    signing(s(&dir.join("results.sqlite")), "sqlite");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn postgres_signing_reviews_then_approves_and_verify_names_an_edit_since() {
    if let Some(url) = postgres() {
        signing(&url, &format!("pg{}", std::process::id()));
    }
}
