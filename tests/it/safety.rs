//! Whatever ends a run, the bench is left in a known state, read back and
//! reported: a cleanup ramp the host steps reaches its set point, SIGTERM
//! and SIGHUP stop a run the way Ctrl-C does, a panic still brings the
//! bench to its safe state, and a run killed through `sim serve` resumes.

use std::path::Path;
use std::process::{Command, Stdio};

use crate::cli::{gyrobench, temp_dir};
use crate::common::{MINI, SimServe, Watched, json, s, stderr, write};

fn signal(pid: u32, sig: &str) {
    let ok = Command::new("kill")
        .args([&format!("-{sig}"), &pid.to_string()])
        .status()
        .expect("kill runs");
    assert!(ok.success(), "kill -{sig} {pid}");
}

/// The last `/chamber/state` message of a complete log.
fn last_chamber_state(log: &Path) -> serde_json::Value {
    let bytes = std::fs::read(log).expect("log");
    let mut last = serde_json::Value::Null;
    for m in mcap::MessageStream::new(&bytes).expect("a complete log") {
        let m = m.expect("message");
        if m.channel.topic == "/chamber/state" {
            last = serde_json::from_slice(&m.data).expect("JSON");
        }
    }
    last
}

/// Up to +30 degC, a minute recorded, and a cleanup ramp back to +20.
const RAMPED: &str = r#"
[procedure]
name = "ramped"
dut_type = "RL-16"

[[setup]]
action = "chamber"
set_c = 30.0
ramp_c_per_min = 3.0

[[main]]
action = "record"
label = "warm"
duration_s = 60.0

[[main]]
action = "measure"
name = "bias_dph:warm"
metric = "mean_bias"
records = ["warm"]
low = -5.0
high = 5.0
unit = "deg/h"

[[cleanup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 3.0
"#;

#[test]
fn a_cleanup_ramp_the_host_steps_reaches_its_set_point_and_is_read_back() {
    let dir = temp_dir("safety-ramp");
    let _turn = crate::common::wall_clock_turn();
    let served = SimServe::start(&dir, 100.0);
    let bench = served.bench_file(&dir, "tcp://", 100.0);
    let p = write(&dir, "ramped.toml", RAMPED);
    let out = dir.join("run");
    let r = gyrobench(&[
        "run",
        s(&p),
        "--bench",
        s(&bench),
        "--dut",
        "RL16-0042",
        "--out",
        s(&out),
    ]);
    // Both streams on failure: the summary (stdout) says how the run ended.
    assert_eq!(
        r.status.code(),
        Some(0),
        "{}\n{}",
        String::from_utf8_lossy(&r.stdout),
        stderr(&r)
    );
    let report = json(&out.join("report.json"));
    let left = &report["bench_left"];
    assert_eq!(left["verified"], true, "{left}");
    assert_eq!(left["intended"], "cleanup", "{left}");
    assert_eq!(left["chamber_mode"], "constant", "{left}");
    assert_eq!(left["chamber_set_point_c"], 20.0, "{left}");
    assert_eq!(report["cleanup_completed"], true);
    // The chamber's own reading at the end of the log agrees.
    let last = last_chamber_state(&out.join("run.mcap"));
    assert_eq!(last["set_point_c"], 20.0, "{last}");
    assert!(String::from_utf8_lossy(&r.stdout).contains("bench left: chamber holding +20.0 degC"));
    drop(served);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn sigterm_sighup_and_sigquit_stop_a_run_as_ctrl_c_does() {
    let dir = temp_dir("safety-signals");
    let p = write(&dir, "mini.toml", MINI);
    for (sig, code) in [("TERM", 143), ("HUP", 129), ("QUIT", 131)] {
        let out = dir.join(sig);
        let mut command = crate::cli::command();
        command
            .args(["run", s(&p), "--out", s(&out), "--speed", "300"])
            .stdout(Stdio::null());
        let mut run = Watched::spawn(command);
        // Mid-run: the first record has started.
        run.wait_for_line("] record warm for");
        signal(run.child.id(), sig);
        let (status, err) = run.finish();
        assert_eq!(status.code(), Some(code), "SIG{sig}: {err}");
        let report = json(&out.join("report.json"));
        assert_eq!(report["outcome"], "aborted", "SIG{sig}");
        let message = report["error"]["message"].as_str().expect("message");
        assert!(message.contains(&format!("SIG{sig}")), "{message}");
        assert_eq!(
            report["bench_left"]["verified"], true,
            "{}",
            report["bench_left"]
        );
        // The log is complete: its footer is there and replay reads it whole.
        let replayed = dir.join(format!("{sig}-replay"));
        let r = gyrobench(&["replay", s(&out.join("run.mcap")), "--out", s(&replayed)]);
        assert!(!stderr(&r).contains("incomplete"), "{}", stderr(&r));
        assert_eq!(json(&replayed.join("report.json"))["outcome"], "aborted");
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_panic_mid_run_still_brings_the_bench_to_its_safe_state() {
    let dir = temp_dir("safety-panic");
    let p = write(&dir, "mini.toml", MINI);
    let out = dir.join("run");
    let r = gyrobench(&["run", s(&p), "--out", s(&out), "--inject", "panic@900"]);
    assert_eq!(r.status.code(), Some(1), "{}", stderr(&r));
    let report = json(&out.join("report.json"));
    assert_eq!(report["outcome"], "error");
    let message = report["error"]["message"].as_str().expect("message");
    assert!(
        message.contains("internal error") && message.contains("safe state"),
        "{message}"
    );
    let left = &report["bench_left"];
    assert_eq!(left["intended"], "safe_state", "{left}");
    assert_eq!(left["chamber_mode"], "standby", "{left}");
    assert_eq!(left["verified"], true, "{left}");
    // What was logged before the panic is kept in a complete log.
    let r = gyrobench(&[
        "replay",
        s(&out.join("run.mcap")),
        "--out",
        s(&dir.join("replay")),
    ]);
    assert!(!stderr(&r).contains("incomplete"), "{}", stderr(&r));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_device_run_stopped_by_sigterm_or_killed_through_sim_serve_ends_safe_and_resumes() {
    let dir = temp_dir("safety-served");
    let _turn = crate::common::wall_clock_turn();
    let served = SimServe::start(&dir, 200.0);
    let bench = served.bench_file(&dir, "tcp://", 200.0);
    let p = write(&dir, "mini.toml", MINI);
    // SIGTERM: cleanup, the safe state read back from the real drivers.
    let out = dir.join("term");
    let run_args = |out: &std::path::Path| {
        let mut command = crate::cli::command();
        command
            .args([
                "run",
                s(&p),
                "--bench",
                s(&bench),
                "--dut",
                "RL16-0042",
                "--out",
                s(out),
            ])
            .stdout(Stdio::null());
        command
    };
    let mut run = Watched::spawn(run_args(&out));
    // Mid-run: the first record has started.
    run.wait_for_line("] record warm for");
    signal(run.child.id(), "TERM");
    let (status, err) = run.finish();
    assert_eq!(status.code(), Some(143), "{err}");
    let report = json(&out.join("report.json"));
    assert_eq!(report["outcome"], "aborted");
    assert_eq!(
        report["bench_left"]["verified"], true,
        "{}",
        report["bench_left"]
    );

    // SIGKILL: nothing runs; the next part picks up from the log.
    let out = dir.join("kill");
    let mut run = Watched::spawn(run_args(&out));
    // SIGKILL once the first record has started.
    run.wait_for_line("] record warm for");
    run.child.kill().expect("SIGKILL");
    let _killed = run.finish();
    assert!(!out.join("report.json").exists());
    let r = gyrobench(&["run", "--resume", s(&out)]);
    let report = json(&out.join("report.json"));
    // A judged unit: the resumed run gives the verdict (0 or 3), not an
    // error. (Wall-clock tests take their turn apart from the busy ones,
    // so the host keeps up with the served gyro.)
    assert!(
        matches!(r.status.code(), Some(0 | 3)),
        "{}\n{}",
        stderr(&r),
        report["error"]
    );
    assert!(
        matches!(report["outcome"].as_str(), Some("pass" | "fail")),
        "{}",
        report["outcome"]
    );
    assert_eq!(
        report["bench_left"]["verified"], true,
        "{}",
        report["bench_left"]
    );
    assert_eq!(report["measurements"].as_array().map(Vec::len), Some(6));
    drop(served);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A cold ramp with the table away from home, and a cleanup that warms the
/// chamber and brings the table home: the case a full disk left half done.
const COLD_AWAY: &str = r#"
[procedure]
name = "cold_away"
description = "a ramp down with the table away from home"
dut_type = "RL-16"
spec = "test"

[[setup]]
action = "move"
table = { outer_deg = 14.6, inner_deg = 30.0 }

[[setup]]
action = "chamber"
set_c = -10.0
ramp_c_per_min = 2.0

[[main]]
action = "record"
label = "cold"
duration_s = 1800.0

[[cleanup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 2.0

[[cleanup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }
"#;

/// A full disk stops logging, never cleanup: every cleanup step runs, the
/// bench is read back where cleanup left it, and the report says why the
/// run is an error.
#[test]
fn a_full_disk_mid_run_stops_the_log_but_cleanup_runs_to_its_end() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("disk-full");
    let p = write(&dir, "cold.toml", COLD_AWAY);
    let out = dir.join("run");
    let o = gyrobench(&[
        "run",
        s(&p),
        "--out",
        s(&out),
        "--db",
        "none",
        "--inject",
        "disk-full@600",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let r = json(&out.join("report.json"));
    assert_eq!(r["outcome"], "error");
    let msg = r["error"]["message"].as_str().expect("message");
    assert!(msg.contains("No space left on device"), "{msg}");
    assert_eq!(r["cleanup_completed"], true, "{}", stderr(&o));
    let left = &r["bench_left"];
    assert_eq!(left["verified"], true, "{left}");
    assert_eq!(left["intended"], "cleanup", "{left}");
    assert_eq!(left["chamber_set_point_c"], 20.0, "{left}");
    let deg = |i: usize| left["table_deg"][i].as_f64().expect("table angle");
    assert!(
        (deg(0) - 90.0).abs() < 0.01 && deg(1).abs() < 0.01,
        "{left}"
    );
    assert_eq!(left["table_at_rest"], true, "{left}");
    // What reached the disk before it filled is a log `recover` completes.
    let rec = gyrobench(&["recover", s(&out.join("run.mcap"))]);
    assert_eq!(rec.status.code(), Some(0), "{}", stderr(&rec));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// `sim serve` at `speed` and a bench file of its TCP endpoints at the
/// same speed, every link reopened for `window_s` after a drop.
fn served_with_window(dir: &Path, speed: f64, window_s: f64) -> (SimServe, std::path::PathBuf) {
    let served = SimServe::start(dir, speed);
    let bench = served.bench_file(dir, "tcp://", speed);
    let text = std::fs::read_to_string(&bench).expect("bench file");
    let window = format!("reconnect_window_s = {window_s}\n");
    let text = text
        .replace("\nattempts = 3\n", &format!("\nattempts = 3\n{window}"))
        .replace("silence_s = 1.0\n", &format!("silence_s = 1.0\n{window}"));
    std::fs::write(&bench, text).expect("bench file with its windows");
    (served, bench)
}

fn served_run(procedure: &Path, bench: &Path, out: &Path) -> Command {
    let mut command = crate::cli::command();
    command
        .args([
            "run",
            s(procedure),
            "--bench",
            s(bench),
            "--dut",
            "RL16-0042",
            "--operator",
            "J.Doe",
            "--unattended",
            "--out",
            s(out),
        ])
        .stdout(Stdio::null());
    command
}

/// One bench, one run: a second run on a bench in use is refused before
/// it sends anything (no run directory made), naming the run that holds
/// it; once that run ends the bench is free again.
#[test]
fn a_second_run_on_a_bench_in_use_is_refused_naming_the_first() {
    let dir = temp_dir("bench-in-use");
    let _turn = crate::common::wall_clock_turn();
    let served = SimServe::start(&dir, 20.0);
    let bench = served.bench_file(&dir, "tcp://", 20.0);
    let p = write(&dir, "mini.toml", MINI);
    let first_dir = dir.join("first");
    let mut first = Watched::spawn(served_run(&p, &bench, &first_dir));
    first.wait_for_line("] record warm for");
    let second_dir = dir.join("second");
    let second = served_run(&p, &bench, &second_dir).output().expect("runs");
    let err = stderr(&second);
    assert_eq!(second.status.code(), Some(2), "{err}");
    assert!(
        err.contains("is in use by another run: mini on RL16-0042 in ")
            && err.contains(s(&first_dir)),
        "{err}"
    );
    assert!(!second_dir.exists(), "a refused run leaves nothing behind");
    signal(first.child.id(), "TERM");
    let (status, err) = first.finish();
    assert_eq!(status.code(), Some(143), "{err}");
    drop(served);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A bench that vanishes (every device of `sim serve` killed at once)
/// mid-run: the drop is told at once, the run stops when the first link's
/// window ends (not one window per request of the safe state and
/// cleanup), and it writes its report saying the bench is in no known
/// state. A SIGTERM while it waits on the dropped links ends it at once.
#[test]
fn a_run_whose_bench_vanishes_ends_with_its_report_within_the_window() {
    let dir = temp_dir("bench-vanishes");
    let _turn = crate::common::wall_clock_turn();
    let p = write(&dir, "mini.toml", MINI);
    let window = std::time::Duration::from_secs(5);
    for sigterm in [false, true] {
        let (served, bench) = served_with_window(&dir, 20.0, window.as_secs_f64());
        let out = dir.join(if sigterm { "term" } else { "window" });
        let mut run = Watched::spawn(served_run(&p, &bench, &out));
        run.wait_for_line("] record warm for");
        drop(served);
        run.wait_for_line("link dropped");
        if sigterm {
            signal(run.child.id(), "TERM");
        }
        // The issue's bound: the reconnect window plus a minute.
        let (status, err) = run.finish_within(window + std::time::Duration::from_secs(60));
        let report = json(&out.join("report.json"));
        let left = &report["bench_left"];
        assert_eq!(left["verified"], false, "{left}");
        assert!(
            left["summary"]
                .as_str()
                .is_some_and(|t| t.starts_with("UNKNOWN")),
            "{left}"
        );
        if sigterm {
            assert_eq!(status.code(), Some(143), "{err}");
            assert_eq!(report["outcome"], "aborted");
        } else {
            assert_eq!(status.code(), Some(1), "{err}");
            assert!(
                report["error"]["message"]
                    .as_str()
                    .is_some_and(|m| m.contains("could not be reopened within 5 s")),
                "{}",
                report["error"]
            );
            assert!(
                err.contains("could not be reopened within 5 s: the run stops"),
                "{err}"
            );
        }
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A real bench whose procedure asks the operator something needs an
/// answer: with no terminal and no `--unattended`, the run is refused
/// before anything moves, naming the prompt's line; `--unattended` needs
/// the operator who confirms the prompts beforehand, and the log says so.
#[test]
fn a_real_benchs_prompt_needs_an_answer() {
    let dir = temp_dir("prompt-needs-answer");
    let _turn = crate::common::wall_clock_turn();
    let served = SimServe::start(&dir, 200.0);
    let bench = served.bench_file(&dir, "tcp://", 200.0);
    let smoke = concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/smoke.toml");
    let out = dir.join("asked");
    let base = [
        "run",
        smoke,
        "--bench",
        s(&bench),
        "--dut",
        "RL16-0042",
        "--out",
        s(&out),
    ];
    let r = crate::cli::command()
        .args(base)
        .stdin(Stdio::null())
        .output()
        .expect("runs");
    let err = stderr(&r);
    assert_eq!(r.status.code(), Some(2), "{err}");
    assert!(
        err.contains("smoke.toml asks the operator at line 17")
            && err.contains("--unattended --operator NAME"),
        "{err}"
    );
    assert!(!out.exists());
    let r = crate::cli::command()
        .args(base)
        .arg("--unattended")
        .stdin(Stdio::null())
        .output()
        .expect("runs");
    assert_eq!(r.status.code(), Some(2), "{}", stderr(&r));
    assert!(stderr(&r).contains("name them with --operator NAME"));
    drop(served);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Aborting a turn-on procedure leaves the unit unpowered: the safe state
/// switches the supply off and the cleanup's `power on = true` (for a run
/// that went to its end) is skipped. A supply that ignores `OUTP OFF` is
/// flagged: the bench is not as asked.
#[test]
fn an_aborted_turn_on_procedure_leaves_the_unit_unpowered_or_says_it_is_not() {
    let dir = temp_dir("abort-turn-on");
    let p = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/procedures/bias_repeatability.toml"
    );
    // In the first turn-on's record (the main starts near 8000 s).
    for (ignores_off, name) in [(false, "obeys"), (true, "ignores")] {
        let out = dir.join(name);
        let mut args = vec!["run", p, "--out", s(&out), "--inject", "sighup@12000"];
        if ignores_off {
            args.extend(["--inject", "supply-ignores-off@10000"]);
        }
        let r = gyrobench(&args);
        assert_eq!(r.status.code(), Some(129), "{}", stderr(&r));
        let report = json(&out.join("report.json"));
        let left = &report["bench_left"];
        if ignores_off {
            assert_eq!(left["verified"], false, "{left}");
            assert_eq!(left["supply_on"], true, "{left}");
            assert!(
                left["summary"].as_str().is_some_and(|t| t.contains(
                    "the supply was asked to switch the unit's power off but its output is on"
                )),
                "{left}"
            );
        } else {
            assert_eq!(left["verified"], true, "{left}");
            assert_eq!(left["supply_on"], false, "{left}");
            assert!(
                left["summary"]
                    .as_str()
                    .is_some_and(|t| t.contains("except the supply (its cleanup was skipped")),
                "{left}"
            );
        }
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
