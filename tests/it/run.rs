//! `gyrobench run` across the process boundary: verdicts, exit codes, the
//! report contract and the MCAP log, on the embedded simulated bench.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::cli::{gyrobench, temp_dir};
use crate::common::{SimServe, stderr};

fn report(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("report.json")).expect("report.json written");
    serde_json::from_str(&text).expect("report.json is JSON")
}

/// (topic, schema name, message JSON) of every message of a log.
fn messages(path: &Path) -> Vec<(String, String, serde_json::Value)> {
    let bytes = std::fs::read(path).expect("run.mcap written");
    mcap::MessageStream::new(&bytes)
        .expect("a readable MCAP file")
        .map(|m| {
            let m = m.expect("every message decodes");
            let schema = m
                .channel
                .schema
                .as_ref()
                .expect("every channel has a schema");
            assert_eq!(schema.encoding, "jsonschema");
            assert_eq!(m.channel.message_encoding, "json");
            let json = serde_json::from_slice(&m.data).expect("JSON message");
            (m.channel.topic.clone(), schema.name.clone(), json)
        })
        .collect()
}

fn frames_logged(msgs: &[(String, String, serde_json::Value)]) -> u64 {
    msgs.iter()
        .filter(|(t, _, _)| t == "/gyro/frames")
        .map(|(_, _, j)| j["counts"].as_array().expect("counts array").len() as u64)
        .sum()
}

fn events(msgs: &[(String, String, serde_json::Value)]) -> Vec<String> {
    msgs.iter()
        .filter(|(t, s, _)| t == "/events" && s == "foxglove.Log")
        .map(|(_, _, j)| j["message"].as_str().expect("message").to_owned())
        .collect()
}

fn smoke() -> String {
    concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/smoke.toml").to_owned()
}

fn run(dir: &Path, extra: &[&str]) -> std::process::Output {
    let out = dir.to_str().expect("utf-8 path");
    let mut args = vec!["run", extra[0], "--out", out];
    args.extend_from_slice(&extra[1..]);
    gyrobench(&args)
}

#[test]
fn smoke_passes_with_the_report_contract_and_a_complete_log() {
    let dir = temp_dir("run-pass");
    let out = run(&dir, &[&smoke(), "--dut", "RL16-0042"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).starts_with("PASS: smoke"));
    let r = report(&dir);
    assert_eq!(r["outcome"], "pass");
    assert_eq!(r["procedure"], "smoke");
    assert_eq!(r["dut"]["serial"], "RL16-0042");
    let ms = r["measurements"].as_array().expect("measurements");
    assert_eq!(ms.len(), 2);
    for m in ms {
        for key in ["name", "value", "unit", "low", "high", "outcome", "step"] {
            assert!(m.get(key).is_some(), "measurement lacks {key}: {m}");
        }
        assert_eq!(m["outcome"], "pass");
        assert!(m["value"].as_f64().expect("value") < m["high"].as_f64().expect("high"));
    }
    assert!(dir.join("report.html").exists());
    // A noise term the curve does not resolve is null with its reason,
    // never a number (3 min records resolve no rate random walk).
    let noise = &r["noise"];
    for k in [
        "arw_deg_per_rt_h",
        "ieee_b_dph",
        "rate_random_walk_dph_per_rt_h",
    ] {
        let why = noise["not_resolved"][k].as_str();
        match noise[k].as_f64() {
            Some(v) => assert!(v > 0.0 && why.is_none(), "noise.{k}: {noise}"),
            None => assert!(
                noise[k].is_null() && why.is_some_and(|w| !w.is_empty()),
                "noise.{k}: {noise}"
            ),
        }
    }
    assert!(noise["rate_random_walk_dph_per_rt_h"].is_null(), "{noise}");
    // The embedded bench's supply starts off: the run switched the unit on
    // at its start, and the report says when, on its first page too.
    assert_eq!(r["power_on"]["source"], "switched", "{}", r["power_on"]);
    assert_eq!(r["power_ons"].as_array().map(Vec::len), Some(1));
    let html = std::fs::read_to_string(dir.join("report.html")).expect("report.html");
    assert!(
        html.contains("<th>power-on</th><td>at 0.0 s of device time")
            && html.contains("switched on by the run, from off"),
        "the first page states the power-on"
    );
    let msgs = messages(&dir.join("run.mcap"));
    assert_eq!(
        frames_logged(&msgs),
        r["frames"].as_u64().expect("frames"),
        "every frame is kept"
    );
    for topic in [
        "/gyro/rate_1hz",
        "/chamber/state",
        "/table/state",
        "/gyro/link",
        "/supply/state",
    ] {
        assert!(msgs.iter().any(|(t, _, _)| t == topic), "{topic} missing");
    }
    let size = std::fs::metadata(dir.join("run.mcap")).expect("log").len();
    assert!(
        size as f64 / (r["frames"].as_f64().expect("frames")) <= 12.0,
        "{size} bytes"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_unit_beyond_its_limits_fails_with_exit_3() {
    let dir = temp_dir("run-fail");
    let twin = dir.join("noisy.toml");
    let default = String::from_utf8(gyrobench(&["twin", "default-config"]).stdout).expect("utf-8");
    let noisy = default.replacen("arw_deg_per_rt_h = 0.002", "arw_deg_per_rt_h = 0.05", 1);
    assert_ne!(noisy, default);
    std::fs::write(&twin, noisy).expect("write twin");
    let out = run(
        &dir.join("run"),
        &[&smoke(), "--twin", twin.to_str().expect("utf-8")],
    );
    assert_eq!(
        out.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r = report(&dir.join("run"));
    assert_eq!(r["outcome"], "fail");
    assert!(
        r["measurements"]
            .as_array()
            .expect("list")
            .iter()
            .any(|m| m["outcome"] == "fail")
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn an_unmodelled_effect_beyond_the_spec_fails_the_thermal_cycle() {
    let dir = temp_dir("run-hysteresis");
    let twin = dir.join("hysteresis.toml");
    let default = String::from_utf8(gyrobench(&["twin", "default-config"]).stdout).expect("utf-8");
    let with = default.replacen(
        "[effects.hysteresis]\nenabled = false\namplitude_dph = 0.05",
        "[effects.hysteresis]\nenabled = true\namplitude_dph = 0.1",
        1,
    );
    assert_ne!(with, default);
    std::fs::write(&twin, with).expect("write twin");
    let proc_ = concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/thermal_cycle.toml");
    let out = run(
        &dir.join("run"),
        &[proc_, "--twin", twin.to_str().expect("utf-8")],
    );
    assert_eq!(
        out.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let r = report(&dir.join("run"));
    let comp = r["measurements"]
        .as_array()
        .expect("list")
        .iter()
        .find(|m| m["name"] == "compensated_drift_pp_dph")
        .expect("compensated drift measured");
    assert_eq!(comp["outcome"], "fail", "{comp}");
    // The page shows the failure: the figure on its own chart, titled with
    // its value and verdict, inside the limit band, between its highest
    // and lowest points; the sentence under the verdict names it.
    let html = std::fs::read_to_string(dir.join("run/report.html")).expect("report.html");
    let value = comp["value"].as_f64().expect("value");
    for part in [
        format!("compensated_drift_pp_dph: {value:.4} deg/h peak to peak (FAIL)"),
        "limit: 0.05 deg/h peak to peak, centred on the trace".to_owned(),
        "highest +".to_owned(),
        "lowest ".to_owned(),
        format!("outside their limits: compensated_drift_pp_dph = {value:.4} deg/h"),
    ] {
        assert!(html.contains(&part), "report.html lacks {part:?}");
    }
    // The start time to the second, not the nanosecond.
    let start = html
        .split("Started ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .expect("start time");
    assert_eq!(start.len(), 10, "{start}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_device_failure_mid_run_is_an_error_after_cleanup_with_a_readable_log() {
    let dir = temp_dir("run-error");
    let out = run(&dir, &[&smoke(), "--inject", "chamber-alarm@200"]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r = report(&dir);
    assert_eq!(r["outcome"], "error");
    assert_eq!(r["error"]["device"], "chamber");
    assert!(
        r["error"]["step"]
            .as_str()
            .expect("step")
            .starts_with("main."),
        "{}",
        r["error"]
    );
    assert_eq!(r["cleanup_completed"], true);
    let msgs = messages(&dir.join("run.mcap"));
    let ev = events(&msgs);
    assert!(ev.iter().any(|e| e.contains("alarm [9]")), "{ev:?}");
    assert!(
        ev.iter().any(|e| e.starts_with("cleanup cleanup.0")),
        "cleanup ran: {ev:?}"
    );
    assert_eq!(frames_logged(&msgs), r["frames"].as_u64().expect("frames"));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn ctrl_c_runs_cleanup_and_exits_130() {
    let dir: PathBuf = temp_dir("run-sigint");
    let mut command = crate::cli::command();
    command
        .args([
            "run",
            &smoke(),
            "--speed",
            "20",
            "--out",
            dir.to_str().expect("utf-8"),
        ])
        .stdout(std::process::Stdio::null());
    let mut run = crate::common::Watched::spawn(command);
    // Mid-run: a record has started.
    run.wait_for_line("] record ");
    let kill = Command::new("kill")
        .args(["-INT", &run.child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(kill.success());
    let (status, err) = run.finish();
    assert_eq!(status.code(), Some(130), "{err}");
    let r = report(&dir);
    assert_eq!(r["outcome"], "aborted");
    assert_eq!(r["cleanup_completed"], true);
    let ev = events(&messages(&dir.join("run.mcap")));
    assert!(
        ev.iter().any(|e| e.starts_with("cleanup cleanup.0")),
        "cleanup ran: {ev:?}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A short procedure: one move, two minutes recorded, a loose limit.
const QUICK: &str = r#"
[procedure]
name = "quick"
dut_type = "RL-16"

[[setup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 1.0

[[main]]
action = "move"
orientation = { azimuth_deg = 90.0, elevation_deg = 0.0, roll_deg = 0.0 }

[[main]]
action = "record"
label = "east"
duration_s = 120.0

[[main]]
action = "measure"
name = "bias_stability_dph:east"
metric = "bias_stability"
records = ["east"]
averaging_s = 10.0
high = 0.5
unit = "deg/h"

[[cleanup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }
"#;

#[test]
fn a_procedure_through_sim_serve_over_tcp_and_ptys_gives_the_embedded_verdict() {
    let dir = temp_dir("run-served");
    let proc_path = dir.join("quick.toml");
    std::fs::write(&proc_path, QUICK).expect("procedure");
    let _turn = crate::common::wall_clock_turn();
    let served = SimServe::start(&dir, 60.0);
    let p = proc_path.to_str().expect("utf-8");
    let embedded = dir.join("embedded");
    let out = run(&embedded, &[p]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let want = report(&embedded);
    for scheme in ["tcp://", "pty://"] {
        let bench_path = served.bench_file(&dir, scheme, 60.0);
        let run_dir = dir.join(scheme.trim_end_matches("://"));
        let out = run(
            &run_dir,
            &[
                p,
                "--bench",
                bench_path.to_str().expect("utf-8"),
                "--dut",
                "RL16-0042",
            ],
        );
        assert_eq!(
            out.status.code(),
            Some(0),
            "{scheme}: {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let got = report(&run_dir);
        assert_eq!(got["outcome"], want["outcome"], "{scheme}");
        let frames = got["frames"].as_f64().expect("frames");
        assert!(
            frames > 0.9 * want["frames"].as_f64().expect("frames"),
            "{scheme}: {frames} frames"
        );
        assert_eq!(got["link"]["crc_errors"], 0, "{scheme}");
        // The served instruments identified themselves through the real
        // drivers, as the embedded bench reports them.
        for i in 0..2 {
            assert_eq!(
                got["instruments"][i]["identity"], want["instruments"][i]["identity"],
                "{scheme}"
            );
        }
        assert_eq!(got["instruments"][1]["identity"]["serial"], "SIM-TABLE");
        let msgs = messages(&run_dir.join("run.mcap"));
        assert_eq!(
            frames_logged(&msgs),
            frames as u64,
            "{scheme}: every frame received is logged"
        );
        assert_eq!(
            got["bench_left"]["verified"], true,
            "{scheme}: {}",
            got["bench_left"]
        );
    }
    drop(served);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The `counts` of every frame in a log, in order, read leniently (a
/// truncated file is read up to its last complete chunk).
fn counts_and_seqs(path: &Path) -> (Vec<i64>, Vec<u8>) {
    let bytes = std::fs::read(path).expect("log");
    let stream =
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .expect("the start of a log reads");
    let (mut counts, mut seqs) = (Vec::new(), Vec::new());
    for m in stream {
        let Ok(m) = m else { break };
        if m.channel.topic == "/gyro/frames" {
            let j: serde_json::Value = serde_json::from_slice(&m.data).expect("JSON");
            counts.extend(
                j["counts"]
                    .as_array()
                    .expect("counts")
                    .iter()
                    .map(|v| v.as_i64().expect("int")),
            );
            seqs.extend(
                j["seq"]
                    .as_array()
                    .expect("seq")
                    .iter()
                    .map(|v| v.as_u64().expect("int") as u8),
            );
        }
    }
    (counts, seqs)
}

#[test]
fn a_run_killed_with_sigkill_is_recovered_to_what_was_flushed() {
    let dir = temp_dir("run-sigkill");
    let killed = dir.join("killed");
    let proc_ = concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/thermal_cycle.toml");
    let mut child = crate::cli::command()
        .args([
            "run",
            proc_,
            "--speed",
            "1000",
            "--out",
            killed.to_str().expect("utf-8"),
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("run starts");
    // Kill once a few chunks are on disk (the log grows by about 0.5 MB a
    // wall second at this speed), whatever the machine's pace.
    let log = killed.join("run.mcap");
    for _ in 0..600 {
        if std::fs::metadata(&log).map_or(0, |m| m.len()) > 1_000_000 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().expect("SIGKILL");
    let status = child.wait().expect("reaped");
    assert_eq!(
        status.code(),
        None,
        "the run must have been killed, not finished"
    );
    assert!(!killed.join("report.json").exists());

    let flushed = counts_and_seqs(&log);
    assert!(
        flushed.0.len() > 100_000,
        "{} frames flushed",
        flushed.0.len()
    );
    let recovered_path = dir.join("recovered.mcap");
    let out = gyrobench(&[
        "recover",
        log.to_str().expect("utf-8"),
        "-o",
        recovered_path.to_str().expect("utf-8"),
    ]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Complete and indexed: the strict reader (footer, summary) takes it.
    let bytes = std::fs::read(&recovered_path).expect("recovered log");
    let summary = mcap::Summary::read(&bytes)
        .expect("summary reads")
        .expect("has a summary");
    assert_eq!(
        summary.channels.len(),
        8,
        "every channel of the log, /steps and /supply/state included"
    );
    let recovered = counts_and_seqs(&recovered_path);
    assert_eq!(
        recovered.0.len(),
        flushed.0.len(),
        "every flushed frame is recovered"
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains(&format!("{} gyro frames", flushed.0.len()))
    );
    for w in recovered.1.windows(2) {
        assert_eq!(
            w[1],
            w[0].wrapping_add(1),
            "no hole in the recovered frames"
        );
    }
    // Replay takes the recovered log: every recovered frame, and an error
    // outcome saying where the log ends (the run never finished).
    let replayed = dir.join("replayed");
    let out = gyrobench(&[
        "replay",
        recovered_path.to_str().expect("utf-8"),
        "--out",
        replayed.to_str().expect("utf-8"),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let r = report(&replayed);
    assert_eq!(r["frames"].as_u64(), Some(flushed.0.len() as u64));
    assert_eq!(r["outcome"], "error");
    // Exactly the start of the same run carried to its end (same seed).
    let full = dir.join("full");
    let out = run(&full, &[proc_]);
    assert_eq!(out.status.code(), Some(0));
    let whole = counts_and_seqs(&full.join("run.mcap"));
    assert_eq!(
        &whole.0[..recovered.0.len()],
        &recovered.0[..],
        "recovered frames are the run's own"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_table_interlock_or_a_silent_gyro_ends_the_run_in_error_naming_the_device() {
    for (fault, device) in [
        ("table-interlock@300", "table"),
        ("gyro-silent@300", "gyro"),
    ] {
        let dir = temp_dir(&format!("run-{device}"));
        let out = run(&dir, &[&smoke(), "--inject", fault]);
        assert_eq!(
            out.status.code(),
            Some(1),
            "{fault}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let r = report(&dir);
        assert_eq!(r["outcome"], "error", "{fault}");
        assert_eq!(r["error"]["device"], device, "{fault}: {}", r["error"]);
        let msgs = messages(&dir.join("run.mcap"));
        assert_eq!(
            frames_logged(&msgs),
            r["frames"].as_u64().expect("frames"),
            "{fault}: log complete"
        );
        assert!(
            events(&msgs).iter().any(|e| e.contains("safe state")),
            "{fault}: safe state attempted"
        );
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}

/// A lab near the equator: its simulated bench stands at its own site on
/// a table turned north, and the twin with it. The Earth rate the bench
/// expects in each pose is the one the simulated unit sees, so the rolls
/// about north (15 deg/h of Earth rate on the axis) read the unit's own
/// bias, as the axis-up poses do.
#[test]
fn the_north_procedures_run_on_the_north_bench_where_the_twin_stands_with_it() {
    let root = env!("CARGO_MANIFEST_DIR");
    let bench = format!("{root}/fixtures/bench/embedded-north.toml");
    let dir = temp_dir("north");
    let out = run(
        &dir,
        &[
            &format!("{root}/procedures/orientation_north.toml"),
            "--bench",
            &bench,
        ],
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let r = report(&dir);
    let bias = |label: &str| {
        r["measurements"]
            .as_array()
            .expect("measurements")
            .iter()
            .find(|m| m["name"] == format!("bias_dph:{label}"))
            .and_then(|m| m["value"].as_f64())
            .unwrap_or_else(|| panic!("no bias at {label}"))
    };
    for label in ["roll000", "roll090", "roll180", "roll270", "tilt55"] {
        assert!(
            (bias(label) - bias("az000")).abs() < 0.2,
            "{label}: {} against {} axis up",
            bias(label),
            bias("az000")
        );
    }
    // A twin file standing elsewhere is refused on this bench, naming why.
    let out = run(
        &temp_dir("north-twin"),
        &[
            &format!("{root}/procedures/smoke.toml"),
            "--bench",
            &bench,
            "--twin",
            &format!("{root}/fixtures/twin/rl16.toml"),
        ],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("[site] differs"), "{}", stderr(&out));
}
