//! `gyrobench calibrate`: the study's models fitted on simulated runs give
//! back the twin's own coefficients, validate on a held-out run, and the
//! file they write compensates a fresh run through `run --coeffs`.

use crate::cli::{gyrobench, temp_dir};
use crate::common::s;

/// A two-hour thermal excursion at power-on: enough to tell the model-4
/// terms apart, quick to simulate.
pub const CYCLE: &str = r#"
[procedure]
name = "mini_cycle"
description = "power-on at +20, up to +40, down to +5"
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
label = "warm"
duration_s = 1800.0

[[main]]
action = "chamber"
set_c = 40.0
ramp_c_per_min = 1.0

[[main]]
action = "record"
label = "up"
duration_s = 2400.0

[[main]]
action = "chamber"
set_c = 5.0
ramp_c_per_min = 1.0

[[main]]
action = "record"
label = "down"
duration_s = 3600.0

[[main]]
action = "measure"
name = "compensated_drift_pp_dph"
metric = "compensated_drift_pp"
records = ["warm", "up", "down"]
averaging_s = 600.0
high = 0.05
unit = "deg/h"
"#;

#[test]
fn calibration_recovers_the_twin_and_its_file_compensates_a_new_run() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("calibrate");
    let procedure = dir.join("cycle.toml");
    std::fs::write(&procedure, CYCLE).expect("procedure");
    let mut logs = Vec::new();
    for seed in ["1", "2"] {
        let out = dir.join(format!("run{seed}"));
        let r = gyrobench(&["run", s(&procedure), "--seed", seed, "--out", s(&out)]);
        assert!(r.status.code().is_some_and(|c| c == 0 || c == 3), "{r:?}");
        logs.push(out.join("run.mcap"));
    }
    let coeffs = dir.join("coeffs.toml");
    let out = gyrobench(&["calibrate", s(&logs[0]), s(&logs[1]), "-o", s(&coeffs)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("leave one run out over 2 runs"), "{text}");
    let html = std::fs::read_to_string(dir.join("coeffs.calibration.html")).expect("html");
    assert!(html.contains("<td>model4</td>") && html.contains("held-out drift"));

    let cal: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("coeffs.calibration.json")).expect("calibration.json"),
    )
    .expect("JSON");
    // The study's progression on held-out data: model 4 far below raw.
    let held = |model: &str| {
        cal["table"]
            .as_array()
            .expect("table")
            .iter()
            .find(|r| r["model"] == model)
            .and_then(|r| r["held_out"]["drift_pp_dph"].as_f64())
            .expect("held-out figure")
    };
    assert!(held("model4") < 0.2 * held("raw"), "{}", cal["table"]);
    assert!(held("model4") < held("model1"), "{}", cal["table"]);
    // Coefficients of the twin (fixtures/twin/rl16.toml) within 4 standard errors.
    let m4 = cal["models"]
        .as_array()
        .expect("models")
        .iter()
        .find(|m| m["model"] == "model4")
        .expect("model 4");
    for (name, truth) in [("k4_tk", -0.007), ("k5_f", 0.36), ("k3_ddt_dt", 20.0)] {
        let c = m4["coefficients"]
            .as_array()
            .expect("coefficients")
            .iter()
            .find(|c| c[0] == name)
            .expect("coefficient");
        let (v, e) = (
            c[1].as_f64().expect("value"),
            c[2].as_f64().expect("stderr"),
        );
        assert!(
            (v - truth).abs() < 4.0 * e,
            "{name}: {v} +- {e}, twin {truth}"
        );
    }
    let tau = m4["warmup_tau_s"].as_f64().expect("tau_w");
    assert!((tau - 600.0).abs() < 120.0, "tau_w {tau}");

    // The file is what run --coeffs takes; a fresh unit run is compensated by it.
    let fresh = dir.join("fresh");
    let r = gyrobench(&[
        "run",
        s(&procedure),
        "--seed",
        "5",
        "--coeffs",
        s(&coeffs),
        "--out",
        s(&fresh),
    ]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fresh.join("report.json")).expect("report"))
            .expect("JSON");
    let m = &report["measurements"][0];
    assert!(
        m["note"]
            .as_str()
            .expect("note")
            .contains("of RL-16 SIMULATED from"),
        "{m}"
    );
    assert!(m["value"].as_f64().expect("value") < 0.05, "{m} {r:?}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_single_run_is_calibrated_in_sample_with_a_warning() {
    let dir = temp_dir("calibrate-one");
    let procedure = dir.join("cycle.toml");
    std::fs::write(&procedure, CYCLE).expect("procedure");
    let run = dir.join("run");
    gyrobench(&["run", s(&procedure), "--out", s(&run)]);
    let out = gyrobench(&[
        "calibrate",
        s(&run.join("run.mcap")),
        "-o",
        s(&dir.join("c.toml")),
    ]);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("in-sample only"), "{text}");
    assert!(text.contains("warning: one run"), "{text}");
    // Not a log at all: a clear error, no coefficients written.
    std::fs::write(dir.join("junk.mcap"), b"not an mcap").expect("junk");
    let out = gyrobench(&[
        "calibrate",
        s(&dir.join("junk.mcap")),
        "-o",
        s(&dir.join("j.toml")),
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not an MCAP log"));
    assert!(!dir.join("j.toml").exists());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
