//! `gyrobench station` across the process boundary: its HTTP API as the
//! page uses it, the run it makes (a normal run directory that `replay`
//! reproduces), and the page itself in a real browser when CI has one.

use std::io::{BufRead, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};

use crate::cli::{command, gyrobench, temp_dir};
use crate::common::{json, s};

/// A station on an ephemeral loopback port, stopped (SIGTERM) when
/// dropped.
struct Served {
    child: Child,
    base: String,
    token: String,
}

impl Served {
    /// `extra` arguments after the usual ones (the embedded bench at full
    /// speed, a live stream on a free loopback port).
    fn start(dir: &Path, extra: &[&str]) -> Self {
        Self::offering(
            dir,
            concat!(env!("CARGO_MANIFEST_DIR"), "/procedures"),
            extra,
        )
    }

    /// As [`Served::start`], offering the procedures of `procedures`.
    fn offering(dir: &Path, procedures: &str, extra: &[&str]) -> Self {
        Self::serving(dir, procedures, s(&dir.join("results.sqlite")), extra)
    }

    /// As [`Served::offering`], keeping its results in `db` (`none`: no
    /// store).
    fn serving(dir: &Path, procedures: &str, db: &str, extra: &[&str]) -> Self {
        let mut child = command()
            .args([
                "station",
                "--listen",
                "127.0.0.1:0",
                "--live",
                "127.0.0.1:0",
                "--procedures",
                procedures,
                "--runs",
                s(&dir.join("runs")),
                "--db",
                db,
            ])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("station starts");
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().expect("stdout"))
            .read_line(&mut line)
            .expect("the URL");
        let url = line
            .trim()
            .strip_prefix("station ")
            .expect("station URL")
            .to_owned();
        let (base, token) = url.split_once("/?token=").expect("a token in the URL");
        Self {
            child,
            base: base.to_owned(),
            token: token.to_owned(),
        }
    }

    fn url(&self) -> String {
        format!("{}/?token={}", self.base, self.token)
    }

    /// One HTTP/1.1 request: (status, body).
    fn request(&self, method: &str, path: &str, token: bool, body: &str) -> (u16, String) {
        let host = self.base.trim_start_matches("http://");
        crate::http::request(
            host,
            token.then_some(self.token.as_str()),
            method,
            path,
            body,
        )
        .expect("an HTTP response")
    }

    fn state(&self) -> serde_json::Value {
        let (code, body) = self.request("GET", "/api/state", true, "");
        assert_eq!(code, 200, "{body}");
        serde_json::from_str(&body).expect("state JSON")
    }

    /// Poll the state until `f` holds (at most 60 s).
    fn until(&self, what: &str, f: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
        for _ in 0..600 {
            let st = self.state();
            if f(&st) {
                return st;
            }
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        panic!("{what}: not within 60 s: {}", self.state());
    }

    fn stop(mut self) -> std::process::ExitStatus {
        let _sent = std::process::Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        for _ in 0..200 {
            if let Some(status) = self.child.try_wait().expect("station") {
                return status;
            }
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        panic!("the station did not stop within 20 s of SIGTERM");
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _killed = self.child.kill();
        let _reaped = self.child.wait();
    }
}

const SMOKE: &str = r#"{"procedure":"smoke.toml","serial":"RL16-0042","operator":"ann"}"#;

#[test]
fn the_station_runs_a_procedure_from_start_to_report_and_refuses_what_it_must() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("station");
    let st = Served::start(&dir, &[]);
    refusals_and_offers(&st);
    a_run_to_its_verdict_and_its_files(&st, &dir);
    abort_at_the_prompt_and_resume(&st);

    // The page itself, in a browser, when there is one.
    browser_check(&st);
    // A browser left open on the page (its event stream streaming) must
    // not hold the stop: the stream ends and the station exits.
    let host = st.base.trim_start_matches("http://").to_owned();
    let mut open = TcpStream::connect(&host).expect("connect");
    write!(
        open,
        "GET /api/events?token={} HTTP/1.1\r\nHost: {host}\r\n\r\n",
        st.token
    )
    .expect("send");
    let mut first = [0u8; 256];
    let n = open.read(&mut first).expect("the stream starts");
    assert!(
        String::from_utf8_lossy(&first[..n]).starts_with("HTTP/1.1 200"),
        "{}",
        String::from_utf8_lossy(&first[..n])
    );
    assert_eq!(
        st.stop().code(),
        Some(0),
        "SIGTERM stops the station cleanly, an event stream open"
    );
    drop(open);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The station's refusals, each with its reason (no token, a blank
/// serial, a path out of the procedures, the unit named two ways or by
/// slot on a bench of one), and the procedures it offers.
fn refusals_and_offers(st: &Served) {
    let (code, body) = st.request("POST", "/api/start", false, SMOKE);
    assert_eq!(code, 403, "no token: {body}");
    let (code, body) = st.request(
        "POST",
        "/api/start",
        true,
        r#"{"procedure":"smoke.toml","serial":"  "}"#,
    );
    assert_eq!(code, 400, "{body}");
    assert!(body.contains("serial"), "{body}");
    let (code, body) = st.request(
        "POST",
        "/api/start",
        true,
        r#"{"procedure":"../x.toml","serial":"A1"}"#,
    );
    assert_eq!(code, 404, "{body}");
    // Both ways of naming the unit: refused, naming both, none ignored;
    // slots on a bench of one unit: refused, naming `serial`.
    for (req, says) in [
        (
            r#"{"procedure":"smoke.toml","serial":"A1","serials":{"A":"A2"}}"#,
            ["`serial` and `serials`", "not both"],
        ),
        (
            r#"{"procedure":"smoke.toml","serials":{"A":"A2"}}"#,
            ["one unit", "`serial`"],
        ),
    ] {
        let (code, body) = st.request("POST", "/api/start", true, req);
        assert_eq!(code, 400, "{req}: {body}");
        assert!(says.iter().all(|w| body.contains(w)), "{req}: {body}");
    }
    let (code, body) = st.request("GET", "/api/procedures", false, "");
    assert_eq!(code, 403, "{body}");
    let (code, body) = st.request("GET", "/api/procedures", true, "");
    assert_eq!(code, 200, "{body}");
    let offers: serde_json::Value = serde_json::from_str(&body).expect("JSON");
    let smoke = offers
        .as_array()
        .expect("list")
        .iter()
        .find(|o| o["file"] == "smoke.toml")
        .expect("smoke offered");
    assert!(smoke["device_s"].as_f64().expect("device time") > 300.0);
    assert!(!smoke["prompts"].as_array().expect("prompts").is_empty());
}

/// A run from the page: it waits at its prompt (the bench busy
/// meanwhile), ends in a verdict, and its files are served; its log
/// replays to its report, and its operator is the report's and the store's.
fn a_run_to_its_verdict_and_its_files(st: &Served, dir: &Path) {
    let (code, body) = st.request("POST", "/api/start", true, SMOKE);
    assert_eq!(code, 200, "{body}");
    let waiting = st.until("the prompt", |s| !s["run"]["prompt"].is_null());
    let id = waiting["run"]["prompt"]["id"].as_u64().expect("prompt id");
    let (code, body) = st.request("POST", "/api/start", true, SMOKE);
    assert_eq!(code, 409, "busy: {body}");
    let (code, body) = st.request("POST", "/api/answer", true, &format!(r#"{{"id":{id}}}"#));
    assert_eq!(code, 200, "{body}");
    let done = st.until("the verdict", |s| s["run"]["phase"] == "finished");
    let run = &done["run"];
    assert_eq!(run["outcome"], "pass", "{run}");
    assert_eq!(run["measurements"].as_array().map(Vec::len), Some(2));
    assert!(!done["samples"].as_array().expect("samples").is_empty());
    assert!(
        run["bench_left"]
            .as_str()
            .is_some_and(|b| b.contains("read back")),
        "{run}"
    );

    // Its files: the report, the log; a normal run directory that replay
    // reproduces byte for byte.
    let (code, page) = st.request("GET", "/runs/1/report.html", true, "");
    assert_eq!(code, 200);
    assert!(page.contains("PASS"));
    let (code, _) = st.request("GET", "/runs/1/run.mcap", true, "");
    assert_eq!(code, 200);
    let (code, _) = st.request("GET", "/runs/1/../../etc/passwd", true, "");
    assert_ne!(code, 200);
    let run_dir = PathBuf::from(run["dir"].as_str().expect("dir"));
    let replay = dir.join("replay");
    let r = gyrobench(&["replay", s(&run_dir.join("run.mcap")), "--out", s(&replay)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(
        std::fs::read(replay.join("report.json")).expect("replayed"),
        std::fs::read(run_dir.join("report.json")).expect("run's"),
        "replay reproduces the station's run"
    );
    // The operator typed in the page is the report's and the store's.
    let report = json(&run_dir.join("report.json"));
    assert_eq!(report["operator"], "ann", "{report}");
    assert_eq!(report["dut"]["serial"], "RL16-0042");
    let (code, body) = st.request("GET", "/api/history?serial=RL16-0042", true, "");
    assert_eq!(code, 200, "{body}");
    assert!(body.contains("\"outcome\":\"pass\""), "{body}");
}

/// Abort at the prompt: cleanup runs, the verdict is aborted and the
/// bench left safe; then resumed from the page, a new part in the same
/// directory, to a verdict.
fn abort_at_the_prompt_and_resume(st: &Served) {
    let (code, body) = st.request("POST", "/api/start", true, SMOKE);
    assert_eq!(code, 200, "{body}");
    st.until("the second prompt", |s| {
        s["run"]["number"] == 2 && !s["run"]["prompt"].is_null()
    });
    let (code, body) = st.request("POST", "/api/abort", true, "{}");
    assert_eq!(code, 200, "{body}");
    let done = st.until("the abort", |s| s["run"]["phase"] == "finished");
    assert_eq!(done["run"]["outcome"], "aborted", "{}", done["run"]);
    let aborted_dir = PathBuf::from(done["run"]["dir"].as_str().expect("dir"));
    let report = json(&aborted_dir.join("report.json"));
    assert_eq!(
        report["bench_left"]["verified"], true,
        "{}",
        report["bench_left"]
    );

    // Resumed from the page: a new part in the same directory, to a verdict.
    let (code, body) = st.request("POST", "/api/resume", true, r#"{"run":1}"#);
    assert_eq!(code, 404, "only the run on the page resumes: {body}");
    let (code, body) = st.request("POST", "/api/resume", true, r#"{"run":2}"#);
    assert_eq!(code, 200, "{body}");
    let resumed = st.until("the resumed run's end or prompt", |s| {
        s["run"]["number"] == 3
            && (s["run"]["phase"] == "finished" || !s["run"]["prompt"].is_null())
    });
    if let Some(id) = resumed["run"]["prompt"]["id"].as_u64() {
        let (code, body) = st.request("POST", "/api/answer", true, &format!(r#"{{"id":{id}}}"#));
        assert_eq!(code, 200, "{body}");
    }
    let done = st.until("the resumed verdict", |s| {
        s["run"]["number"] == 3 && s["run"]["phase"] == "finished"
    });
    assert_eq!(done["run"]["outcome"], "pass", "{}", done["run"]);
    assert_eq!(
        done["run"]["dir"].as_str().map(PathBuf::from),
        Some(aborted_dir.clone())
    );
    assert!(aborted_dir.join("run.part2.mcap").is_file());
}

/// A station on a bench with slots: a serial per slot (blank ones empty),
/// one tile per unit with its live rate and verdict, each unit's report
/// served; the page driven in Chromium when CI has it.
#[test]
fn the_station_runs_a_batch_with_a_tile_and_a_report_per_unit() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("station-batch");
    let quad = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/bench/quad.toml");
    let st = Served::start(&dir, &["--bench", quad]);
    assert_eq!(
        st.state()["slots"],
        serde_json::json!(["A", "B", "C", "D"]),
        "the page is told the bench's slots"
    );
    // No serial in any slot: refused with its reason; a slot the bench
    // lacks, and `serial` beside or instead of `serials`, too.
    for (body, says) in [
        (
            r#"{"procedure":"smoke.toml","serials":{"A":" ","B":""}}"#,
            "each slot",
        ),
        (
            r#"{"procedure":"smoke.toml","serials":{"E":"RL16-1"}}"#,
            "its slots: A, B, C, D",
        ),
        (
            r#"{"procedure":"smoke.toml","serial":"RL16-1","serials":{"A":"RL16-2"}}"#,
            "`serial` and `serials` given together",
        ),
        (
            r#"{"procedure":"smoke.toml","serial":"RL16-1"}"#,
            "slots (A, B, C, D): give each unit's serial by slot in `serials`",
        ),
    ] {
        let (code, text) = st.request("POST", "/api/start", true, body);
        assert_eq!(code, 400, "{text}");
        assert!(text.contains(says), "{text}");
    }
    let (code, body) = st.request(
        "POST",
        "/api/start",
        true,
        r#"{"procedure":"smoke.toml","serials":{"A":"RL16-0101","B":"","C":" RL16-0103 "},"operator":"ann"}"#,
    );
    assert_eq!(code, 200, "{body}");
    let waiting = st.until("the prompt", |s| !s["run"]["prompt"].is_null());
    let units = waiting["run"]["units"].as_array().expect("units").clone();
    assert_eq!(units.len(), 2, "{units:?}");
    assert_eq!(
        (&units[0]["slot"], &units[1]["slot"]),
        (&"A".into(), &"C".into())
    );
    assert_eq!(units[1]["serial"], "RL16-0103", "trimmed as scanned");
    let id = waiting["run"]["prompt"]["id"].as_u64().expect("prompt id");
    let (code, body) = st.request("POST", "/api/answer", true, &format!(r#"{{"id":{id}}}"#));
    assert_eq!(code, 200, "{body}");
    let done = st.until("the verdicts", |s| s["run"]["phase"] == "finished");
    // Each tile had its own unit's rate, to its last second.
    let rates: Vec<f64> = done["run"]["units"]
        .as_array()
        .expect("units")
        .iter()
        .map(|u| u["bias_dph"].as_f64().expect("a live rate"))
        .collect();
    assert_ne!(rates[0], rates[1], "each tile has its own unit's rate");
    // And its drift over a named minute of its last record.
    for u in done["run"]["units"].as_array().expect("units") {
        assert_eq!(u["drift"]["seconds"], 60, "{u}");
        assert_eq!(u["drift"]["record"], "east", "{u}");
    }
    let run = &done["run"];
    assert_eq!(run["outcome"], "pass", "{run}");
    for (u, serial) in run["units"]
        .as_array()
        .expect("units")
        .iter()
        .zip(["RL16-0101", "RL16-0103"])
    {
        assert_eq!(u["outcome"], "pass", "{u}");
        let file = u["report"].as_str().expect("report file");
        assert_eq!(file, format!("report-{serial}.html"));
        let (code, page) = st.request("GET", &format!("/runs/1/{file}"), true, "");
        assert_eq!(code, 200);
        assert!(page.contains(serial) && page.contains("PASS"));
        // And from the unit's history (the store's row, its own report).
        let (code, body) = st.request("GET", &format!("/api/history?serial={serial}"), true, "");
        assert_eq!(code, 200, "{body}");
        let h: serde_json::Value = serde_json::from_str(&body).expect("history");
        let run_id = h["runs"][0]["id"]
            .as_str()
            .expect("a stored run")
            .to_owned();
        let (code, page) = st.request(
            "GET",
            &format!("/api/report?run={run_id}&unit={serial}"),
            true,
            "",
        );
        assert_eq!(code, 200);
        assert!(
            page.contains(serial),
            "the history's report is the unit's own"
        );
    }
    let (code, _) = st.request("GET", "/runs/1/report-..%2Fx.html", true, "");
    assert_ne!(code, 200);
    // The page, as an operator uses it.
    if let Some(python) = crate::common::python("the station page driven in Chromium")
        && let Some(driver) = ["/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver"]
            .into_iter()
            .find(|p| Path::new(p).is_file())
    {
        let shot = std::env::var("GYROBENCH_STATION_SHOT").unwrap_or_default();
        let url = st.url();
        let mut args = vec!["--batch", url.as_str(), driver];
        if !shot.is_empty() {
            args.push(&shot);
        }
        crate::common::conformance(&python, "station_browser.py", &args);
    }
    assert!(st.stop().success());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Two records with the inner axis turned half a turn between them: the
/// 1 s rate of the turn reads hundreds of deg/h, which on a chart of every
/// second flattens the drift to a line. The drift chart's series (sample
/// columns 8 and 9) hold the records' seconds alone, the read-out gives
/// the bench and the unit in numbers, the drift named by its window.
#[test]
fn the_drift_chart_and_read_out_leave_the_slews_out() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("station-drift");
    let procedures = dir.join("procedures");
    std::fs::create_dir_all(&procedures).expect("procedures");
    crate::common::write(
        &procedures,
        "turn.toml",
        r#"[procedure]
name = "turn"
description = "Two short records, the inner axis turned half a turn between them."
dut_type = "RL-16"

[[main]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }

[[main]]
action = "record"
label = "before"
duration_s = 90.0

[[main]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 180.0 }

[[main]]
action = "record"
label = "after"
duration_s = 90.0
"#,
    );
    let st = Served::offering(&dir, s(&procedures), &[]);
    let (code, body) = st.request(
        "POST",
        "/api/start",
        true,
        r#"{"procedure":"turn.toml","serial":"RL16-0042"}"#,
    );
    assert_eq!(code, 200, "{body}");
    let done = st.until("the verdict", |s| s["run"]["phase"] == "finished");
    let samples = done["samples"].as_array().expect("samples");
    assert!(
        samples
            .iter()
            .all(|s| s.as_array().map(Vec::len) == Some(10)),
        "ten columns: {:?}",
        samples.first()
    );
    let column = |k: usize| -> Vec<f64> { samples.iter().filter_map(|s| s[k].as_f64()).collect() };
    let widest = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(
        widest(&column(1)) > 100.0,
        "the turn in the 1 s rate: {}",
        widest(&column(1))
    );
    let (drift, means) = (column(8), column(9));
    assert!(
        (170..=182).contains(&drift.len()),
        "the records' seconds: {}",
        drift.len()
    );
    assert!(widest(&drift) < 5.0, "the turn in the drift: {drift:?}");
    assert!(
        (50..=64).contains(&means.len()) && widest(&means) < 2.0,
        "a mean once each record has lasted a minute: {means:?}"
    );
    let now = &done["run"]["now"];
    assert!(
        (now["chamber_c"].as_f64().expect("chamber") - 20.0).abs() < 0.5,
        "{now}"
    );
    assert_eq!(
        now["inner_deg"].as_f64().map(f64::round),
        Some(180.0),
        "{now}"
    );
    for sensor in ["tcase_c", "t1_c", "t2_c"] {
        assert!(now[sensor].as_f64().is_some_and(|t| t > 15.0), "{now}");
    }
    assert_eq!(now["drift"]["seconds"], 60, "{now}");
    assert_eq!(
        now["drift"]["window"], "mean of the last 60 s of record after (ended)",
        "{now}"
    );
    assert!(
        now["drift"]["mean_dph"].as_f64().expect("drift").abs() < 2.0,
        "{now}"
    );
    assert!(st.stop().success());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// `tests/conformance/station_browser.py` against the station: required
/// in CI, skipped (said) elsewhere without selenium and chromedriver.
fn browser_check(st: &Served) {
    if let Some((python, driver)) = chromium("the station page driven in Chromium") {
        crate::common::conformance(&python, "station_browser.py", &[&st.url(), driver]);
    }
}

/// The Python with selenium and the chromedriver that drive the page:
/// required in CI, none (said) elsewhere without them.
fn chromium(what: &str) -> Option<(String, &'static str)> {
    let python = crate::common::python(what)?;
    let driver = ["/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver"]
        .into_iter()
        .find(|p| Path::new(p).is_file());
    let Some(driver) = driver else {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI drives the station page in Chromium: install chromium-driver"
        );
        eprintln!("skipped: {what} (no chromedriver)");
        return None;
    };
    Some((python, driver))
}

/// A finished run of the station is signed from it, by the rules and in
/// the words of `results sign` (the same code): reviewed through the API
/// (the store, `results show` and the history list it), approved by the
/// reviewer refused, each other refusal with its reason, nothing signed
/// without the token; then approved by someone else from the page in
/// Chromium (when CI has it), the list updated.
#[test]
fn a_run_is_signed_from_the_station_by_the_rules_of_results_sign() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("station-sign");
    let db = dir.join("results.sqlite");
    let st = Served::start(&dir, &[]);
    let (code, body) = st.request("POST", "/api/start", true, SMOKE);
    assert_eq!(code, 200, "{body}");
    let waiting = st.until("the prompt", |s| !s["run"]["prompt"].is_null());
    let id = waiting["run"]["prompt"]["id"].as_u64().expect("prompt id");
    let (code, body) = st.request("POST", "/api/answer", true, &format!(r#"{{"id":{id}}}"#));
    assert_eq!(code, 200, "{body}");
    let done = st.until("the verdict", |s| s["run"]["phase"] == "finished");
    assert_eq!(done["run"]["outcome"], "pass", "{}", done["run"]);
    let history = || {
        let (code, body) = st.request("GET", "/api/history?serial=RL16-0042", true, "");
        assert_eq!(code, 200, "{body}");
        serde_json::from_str::<serde_json::Value>(&body).expect("history")
    };
    let h = history();
    let run = h["runs"][0]["id"]
        .as_str()
        .expect("a stored run")
        .to_owned();
    assert_eq!(h["signatures"][&run], serde_json::json!([]), "{h}");
    let sign = |token: bool, role: &str, by: &str| {
        let body = serde_json::json!({ "run": run, "role": role, "by": by, "note": "QP-12 rev C" });
        st.request("POST", "/api/sign", token, &body.to_string())
    };
    let signed = |run: &str| -> Vec<(String, String)> {
        let shown = gyrobench(&["results", "--db", s(&db), "show", run, "--json"]);
        assert!(
            shown.status.success(),
            "{}",
            String::from_utf8_lossy(&shown.stderr)
        );
        let d: serde_json::Value = serde_json::from_slice(&shown.stdout).expect("JSON");
        d["signatures"]
            .as_array()
            .expect("signatures")
            .iter()
            .map(|g| (s_of(&g["role"]), s_of(&g["by"])))
            .collect()
    };

    // Refused, each with the words `results sign` says it in.
    let (code, body) = sign(false, "reviewed", "A. Quality");
    assert_eq!(code, 403, "no token: {body}");
    assert!(body.contains("token"), "{body}");
    for (role, by, want, says) in [
        ("approved", "B. Lead", 400, "not reviewed yet"),
        ("reviewer", "A. Quality", 400, "reviewed or approved"),
        (
            "reviewed",
            " ",
            400,
            "a name of 1 to 200 printable characters",
        ),
    ] {
        let (code, body) = sign(true, role, by);
        assert_eq!(code, want, "{role} by {by:?}: {body}");
        assert!(body.contains(says), "{role} by {by:?}: {body}");
    }
    for unknown in ["ffffffff", ""] {
        let body = serde_json::json!({ "run": unknown, "role": "reviewed", "by": "A. Quality" });
        let (code, body) = st.request("POST", "/api/sign", true, &body.to_string());
        assert_eq!(code, 404, "run {unknown:?}: {body}");
        assert!(body.contains("results list"), "{body}");
    }
    assert!(signed(&run).is_empty(), "a refusal signed something");

    // Reviewed: the store and the history hold it.
    let (code, body) = sign(true, "reviewed", "A. Quality");
    assert_eq!(code, 200, "{body}");
    let g: serde_json::Value = serde_json::from_str(&body).expect("signature");
    assert_eq!(
        (&g["run"], &g["role"], &g["by"]),
        (
            &run.as_str().into(),
            &"reviewed".into(),
            &"A. Quality".into()
        )
    );
    assert!(
        g["signed_utc"].as_str().is_some_and(|t| t.ends_with('Z')),
        "{g}"
    );
    assert_eq!(
        signed(&run),
        [("reviewed".to_owned(), "A. Quality".to_owned())]
    );
    let shown = gyrobench(&["results", "--db", s(&db), "show", &run]);
    let text = String::from_utf8_lossy(&shown.stdout);
    assert!(
        text.contains("reviewed  by A. Quality") && text.contains("QP-12 rev C"),
        "{text}"
    );
    let h = history();
    assert_eq!(h["signatures"][&run][0]["by"], "A. Quality", "{h}");
    assert_eq!(
        h["runs"][0]["id"],
        run.as_str(),
        "the history's keys stay: {h}"
    );

    // Approved by the reviewer: refused; nothing added.
    let (code, body) = sign(true, "approved", "A. Quality");
    assert_eq!(code, 400, "{body}");
    assert!(
        body.contains("A. Quality reviewed it; another person approves it"),
        "{body}"
    );
    assert_eq!(signed(&run).len(), 1);

    // From the page: the reviewer's approval refused in words, another
    // person's accepted, the list updated.
    if let Some((python, driver)) = chromium("the station page's signing form driven in Chromium") {
        let shot = std::env::var("GYROBENCH_SIGN_SHOT").unwrap_or_default();
        let url = st.url();
        let mut args = vec!["--sign", url.as_str(), driver];
        if !shot.is_empty() {
            args.push(&shot);
        }
        crate::common::conformance(&python, "station_browser.py", &args);
        assert_eq!(
            signed(&run),
            [
                ("reviewed".to_owned(), "A. Quality".to_owned()),
                ("approved".to_owned(), "B. Lead".to_owned())
            ]
        );
    }
    assert!(st.stop().success());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

fn s_of(v: &serde_json::Value) -> String {
    v.as_str().unwrap_or_default().to_owned()
}

/// A station without a results store says so when asked to sign (and
/// still asks for the token first).
#[test]
fn a_station_without_a_results_store_says_so_when_asked_to_sign() {
    let dir = temp_dir("station-sign-none");
    let st = Served::serving(
        &dir,
        concat!(env!("CARGO_MANIFEST_DIR"), "/procedures"),
        "none",
        &[],
    );
    let body = r#"{"run":"0968c2e6","role":"reviewed","by":"A. Quality"}"#;
    let (code, text) = st.request("POST", "/api/sign", false, body);
    assert_eq!(code, 403, "{text}");
    let (code, text) = st.request("POST", "/api/sign", true, body);
    assert_eq!(code, 409, "{text}");
    assert!(
        text.contains("no results store") && text.contains("--db"),
        "{text}"
    );
    assert!(st.stop().success());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The live Foxglove stream, from `run --live` and from the station, to a
/// third-party client (`tests/conformance/live_foxglove.py`: the Python
/// `websockets` package speaking the protocol): every channel of the log
/// advertised with its schema, and messages that validate against it and
/// are the log's own. Runs at 60x so that the client sees them live.
#[test]
fn the_live_foxglove_stream_carries_the_logs_channels_to_a_third_party_client() {
    let Some(python) = crate::common::python("the live Foxglove stream checked by websockets")
    else {
        return;
    };
    let dir = temp_dir("live");
    for mode in ["run", "batch"] {
        crate::common::conformance(
            &python,
            "live_foxglove.py",
            &[mode, env!("CARGO_BIN_EXE_gyrobench"), s(&dir)],
        );
    }
    let st = Served::start(&dir, &["--speed", "60"]);
    let state = st.state();
    let live = state["live_url"]
        .as_str()
        .expect("the station says its live URL");
    assert!(live.starts_with("ws://127.0.0.1:"), "{live}");
    crate::common::conformance(
        &python,
        "live_foxglove.py",
        &["station", &st.base, &st.token],
    );
    assert!(st.stop().success());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Closing the terminal or SSH session that started the station (SIGHUP),
/// or Ctrl-\ (SIGQUIT), mid-run: the run is aborted, its cleanup runs, its
/// report is written and the bench is read back at rest, as for SIGTERM.
#[test]
fn sighup_and_sigquit_stop_the_station_as_sigterm_does() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    for signal in ["HUP", "QUIT"] {
        let dir = temp_dir(&format!("station-sig{signal}"));
        let mut st = Served::start(&dir, &[]);
        let (code, body) = st.request("POST", "/api/start", true, SMOKE);
        assert_eq!(code, 200, "{body}");
        // At the prompt: the run is under way (its log open, the bench set).
        let waiting = st.until("the prompt", |s| !s["run"]["prompt"].is_null());
        let run_dir = PathBuf::from(waiting["run"]["dir"].as_str().expect("dir"));
        let _sent = std::process::Command::new("kill")
            .args([&format!("-{signal}"), &st.child.id().to_string()])
            .status();
        let status = (0..300)
            .find_map(|_| {
                let s = st.child.try_wait().expect("station");
                if s.is_none() {
                    std::thread::sleep(std::time::Duration::from_millis(100));
                }
                s
            })
            .unwrap_or_else(|| panic!("SIG{signal}: the station did not stop within 30 s"));
        assert_eq!(status.code(), Some(0), "SIG{signal}: {status}");
        let report = json(&run_dir.join("report.json"));
        assert_eq!(report["outcome"], "aborted", "SIG{signal}");
        assert_eq!(
            report["bench_left"]["verified"], true,
            "SIG{signal}: {}",
            report["bench_left"]
        );
        assert_eq!(report["cleanup_completed"], true, "SIG{signal}");
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}

/// A flood of connections that send nothing (no token needed to open
/// them) never keeps the page or Abort out: the oldest of them are closed
/// to make room, and a request sent at once is answered.
#[test]
fn a_flood_of_half_open_connections_leaves_the_page_reachable() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("station-flood");
    let st = Served::start(&dir, &[]);
    let host = st.base.trim_start_matches("http://").to_owned();
    let flood: Vec<TcpStream> = (0..600)
        .map(|_| TcpStream::connect(&host).expect("a connection"))
        .collect();
    // Answered while the flood is held open.
    let (code, body) = st.request("GET", "/api/state", true, "");
    assert_eq!(code, 200, "{body}");
    let (code, body) = st.request("POST", "/api/abort", true, "{}");
    assert_ne!(code, 403, "{body}");
    // The oldest of the flood were closed by the station.
    let mut first = &flood[0];
    // A guard against a station that would never close it (the station's
    // own limit is 10 s); not a measure of speed.
    first
        .set_read_timeout(Some(std::time::Duration::from_secs(120)))
        .expect("timeout");
    let mut byte = [0u8; 1];
    let read = first.read(&mut byte);
    let closed = match &read {
        Ok(0) => true,
        Err(e) => !matches!(
            e.kind(),
            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
        ),
        Ok(_) => false,
    };
    assert!(closed, "the oldest idle connection is still open: {read:?}");
    drop(flood);
    assert_eq!(st.stop().code(), Some(0));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Everything `conn` receives until the station closes it (a guard of
/// 60 s against a station that never would; not a measure of speed).
fn answer_of(mut conn: &TcpStream) -> String {
    conn.set_read_timeout(Some(std::time::Duration::from_secs(60)))
        .expect("timeout");
    let mut got = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        match conn.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&chunk[..n]),
            Err(e) => {
                assert!(
                    !matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ),
                    "still open after 60 s; received {:?}",
                    String::from_utf8_lossy(&got)
                );
                break;
            }
        }
    }
    String::from_utf8_lossy(&got).into_owned()
}

/// A request head and the start of a body of 1000 bytes, the rest never
/// sent.
fn half_sent(host: &str, method: &str, path: &str, token: Option<&str>) -> TcpStream {
    let mut c = TcpStream::connect(host).expect("a connection");
    let auth = token.map_or(String::new(), |t| format!("X-Gyrobench-Token: {t}\r\n"));
    write!(
        c,
        "{method} {path} HTTP/1.1\r\nHost: {host}\r\n{auth}Content-Type: application/json\r\nContent-Length: 1000\r\n\r\n{{\"procedure\":"
    )
    .expect("a half-sent request");
    c
}

/// A connection that asked for the page's head (no token), was answered
/// and stays open.
fn page_kept_open(host: &str) -> TcpStream {
    let mut c = TcpStream::connect(host).expect("a connection");
    write!(c, "HEAD / HTTP/1.1\r\nHost: {host}\r\n\r\n").expect("a request");
    c.set_read_timeout(Some(std::time::Duration::from_secs(60)))
        .expect("timeout");
    let mut got = Vec::new();
    let mut byte = [0u8; 1];
    while !got.ends_with(b"\r\n\r\n") {
        let n = c.read(&mut byte).expect("the page's head");
        assert_eq!(n, 1, "closed: {:?}", String::from_utf8_lossy(&got));
        got.push(byte[0]);
    }
    assert!(
        got.starts_with(b"HTTP/1.1 200"),
        "{:?}",
        String::from_utf8_lossy(&got)
    );
    c
}

/// 600 connections sending a request head without the token and a body
/// they never finish, held open: the token holder is still answered (the
/// page, the state, Abort). Sent to the API, each is refused on its head
/// (403, the connection closed) without its body being waited for. 600
/// connections kept open after asking for the page (which needs no
/// token) never take the last slots: the oldest of them make room. SIGTERM then stops the
/// station with the flood still open, and closes a token holder's own
/// half-sent request rather than wait for its body's deadline.
#[test]
fn the_station_stays_reachable_for_its_token_holder_under_600_half_sent_requests() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("station-half-sent");
    let st = Served::start(&dir, &[]);
    let host = st.base.trim_start_matches("http://").to_owned();
    // One alone: refused on its head, its body never waited for.
    let answer = answer_of(&half_sent(&host, "POST", "/api/start", None));
    assert!(
        answer.starts_with("HTTP/1.1 403") && answer.contains("token"),
        "a half-sent request without the token: {answer:?}"
    );
    let paths = ["/api/start", "/api/abort", "/api/answer", "/api/resume"];
    let flood: Vec<TcpStream> = (0..600)
        .map(|i| half_sent(&host, "POST", paths[i % paths.len()], None))
        .collect();
    let (code, body) = st.request("GET", "/api/state", true, "");
    assert_eq!(code, 200, "{body}");
    let (code, body) = st.request("POST", "/api/abort", true, "{}");
    assert_eq!(code, 400, "answered (nothing to abort): {body}");
    assert!(body.contains("no run"), "{body}");
    // Every one of them closed by the station: refused, or closed unread
    // to make room when they came faster than their heads were read.
    for (i, c) in flood.iter().enumerate() {
        let answer = answer_of(c);
        assert!(
            answer.is_empty() || answer.starts_with("HTTP/1.1 403"),
            "half-sent request {i} without the token: {answer:?}"
        );
    }
    drop(flood);

    // The page needs no token: connections that asked for it stay open
    // (kept alive), but never in the token holder's slots.
    let idle: Vec<TcpStream> = (0..600).map(|_| page_kept_open(&host)).collect();
    let (code, page) = st.request("GET", &format!("/?token={}", st.token), false, "");
    assert_eq!(code, 200);
    assert!(page.contains("gyrobench station"));
    let (code, body) = st.request("GET", "/api/state", true, "");
    assert_eq!(code, 200, "{body}");
    let evicted = answer_of(&idle[0]);
    assert!(
        evicted.is_empty(),
        "the oldest is closed to make room: {evicted:?}"
    );

    // Stopped with all of it open.
    let mine = half_sent(&host, "POST", "/api/start", Some(&st.token));
    assert_eq!(
        st.stop().code(),
        Some(0),
        "SIGTERM stops the station, the flood open"
    );
    let closed = answer_of(&mine);
    assert!(
        !closed.contains("408"),
        "the stop waited for the body's deadline: {closed:?}"
    );
    drop(idle);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A link planted in a run directory is never followed by the download
/// route: only the run directory's own regular files are served.
#[test]
fn a_link_in_a_run_directory_is_not_served() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("station-link");
    let st = Served::start(&dir, &[]);
    let (code, body) = st.request("POST", "/api/start", true, SMOKE);
    assert_eq!(code, 200, "{body}");
    let waiting = st.until("the prompt", |s| !s["run"]["prompt"].is_null());
    let id = waiting["run"]["prompt"]["id"].as_u64().expect("prompt id");
    let (code, body) = st.request("POST", "/api/answer", true, &format!(r#"{{"id":{id}}}"#));
    assert_eq!(code, 200, "{body}");
    let done = st.until("the verdict", |s| s["run"]["phase"] == "finished");
    let run_dir = PathBuf::from(done["run"]["dir"].as_str().expect("dir"));
    let (code, _) = st.request("GET", "/runs/1/report.html", true, "");
    assert_eq!(code, 200);
    let secret = dir.join("secret.txt");
    std::fs::write(&secret, "not the bench's to give").expect("secret");
    std::fs::remove_file(run_dir.join("report.html")).expect("remove");
    std::os::unix::fs::symlink(&secret, run_dir.join("report.html")).expect("link");
    let (code, body) = st.request("GET", "/runs/1/report.html", true, "");
    assert_eq!(code, 404, "{body}");
    assert!(!body.contains("not the bench's to give"));
    assert_eq!(st.stop().code(), Some(0));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
