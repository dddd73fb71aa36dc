//! The gyro's status bits: records taken while the unit said it was not
//! fit are left out of the figures, and its mode hops are counted.

use std::path::Path;

use gyrobench::twin::TwinConfig;

use crate::cli::{gyrobench, temp_dir};
use crate::common::{json, s, stderr, write};

const THERMAL_CYCLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/thermal_cycle.toml");

/// The RL-16 twin whose path-length control resets every 25 degC of its
/// blocks, 0.5 s out of lock each time, with `relock_error_dph` on its
/// output while out of lock (a whole number of counts per frame at 400 Hz
/// and 0.25 arcsec: 2000 deg/h is 20 counts).
fn resetting(dir: &Path, name: &str, relock_error_dph: f64) -> std::path::PathBuf {
    let mut t = TwinConfig::default_rl16();
    t.path_length_control.reset_span_c = 25.0;
    t.path_length_control.relock_s = 0.5;
    t.path_length_control.mode_bias_dph = 0.01;
    t.path_length_control.relock_error_dph = relock_error_dph;
    write(dir, name, &t.to_toml().expect("twin TOML"))
}

fn run(dir: &Path, twin: &Path, out: &str) -> serde_json::Value {
    let out = dir.join(out);
    let o = gyrobench(&[
        "run",
        THERMAL_CYCLE,
        "--twin",
        s(twin),
        "--db",
        "none",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    json(&out.join("report.json"))
}

/// From the log alone: the falls of the path-length control's lock bit
/// (bit 2) between consecutive frames, and the 1 Hz intervals whose
/// ticks held a frame without it.
fn from_log(log: &Path) -> (usize, Vec<(f64, f64)>) {
    let bytes = std::fs::read(log).expect("log");
    let mut falls = 0;
    let mut last: Option<bool> = None;
    let mut unlocked_tick = false;
    let mut spoiled = Vec::new();
    for m in mcap::MessageStream::new(&bytes).expect("a readable MCAP file") {
        let m = m.expect("every message decodes");
        let v: serde_json::Value = serde_json::from_slice(&m.data).expect("JSON");
        match m.channel.topic.as_str() {
            "/gyro/frames" => {
                let status = v["status"].as_array().expect("status array");
                if status.is_empty() {
                    last = None;
                }
                unlocked_tick = false;
                for s in status {
                    let locked = s.as_u64().expect("a status word") & 0b100 != 0;
                    falls += usize::from(last == Some(true) && !locked);
                    unlocked_tick |= !locked;
                    last = Some(locked);
                }
            }
            "/gyro/rate_1hz" if unlocked_tick => {
                spoiled.push((
                    v["t_s"].as_f64().expect("t_s"),
                    v["bias_dph"].as_f64().expect("bias"),
                ));
            }
            _ => {}
        }
    }
    (falls, spoiled)
}

/// A unit whose path-length control resets through the thermal cycle:
/// the report counts the resets the frames show, leaves the intervals
/// they spoil out of every figure (the figures are those of the same
/// unit whose output stays clean while out of lock, to the bit), and
/// says how many seconds it left out; replay agrees.
#[test]
fn unfit_frames_are_left_out_and_mode_hops_counted() {
    let dir = temp_dir("status-bits");
    let spoiling = resetting(&dir, "spoiling.toml", 2000.0);
    let clean = resetting(&dir, "clean.toml", 0.0);
    let a = run(&dir, &spoiling, "spoiling");
    let b = run(&dir, &clean, "clean");

    let (falls, spoiled) = from_log(&dir.join("spoiling/run.mcap"));
    let st = &a["gyro_status"];
    assert!(falls >= 3, "the cycle makes several resets: {falls}");
    assert_eq!(st["mode_hops"].as_u64(), Some(falls as u64), "{st}");
    // The intervals the resets fell in carry the relock error (hundreds
    // of deg/h over a 1 s mean): they were there to be left out.
    assert!(
        spoiled.iter().filter(|(_, b)| b.abs() > 100.0).count() >= falls,
        "{spoiled:?}"
    );
    let dropped = st["dropped_s"].as_f64().expect("dropped_s");
    assert!(
        dropped >= 1.0 && dropped <= 2.0 * spoiled.len() as f64,
        "{st}"
    );
    assert!(
        st["words"].as_str().expect("words").contains("mode hop"),
        "{st}"
    );
    assert!(
        st["records"][0]["why"][0]
            .as_str()
            .is_some_and(|w| w.contains("path-length control out of lock")),
        "{st}"
    );

    let figures = |r: &serde_json::Value| -> Vec<(String, Option<f64>)> {
        r["measurements"]
            .as_array()
            .expect("measurements")
            .iter()
            .map(|m| {
                (
                    m["name"].as_str().unwrap_or_default().to_owned(),
                    m["value"].as_f64(),
                )
            })
            .collect()
    };
    assert_eq!(
        figures(&a),
        figures(&b),
        "the relock error reached a figure"
    );
    assert!(
        a["measurements"]
            .as_array()
            .expect("measurements")
            .iter()
            .any(|m| m["note"].as_str().is_some_and(|n| n.contains("left out"))),
        "a figure whose records lost intervals says so"
    );

    let replay = dir.join("replayed");
    let o = gyrobench(&[
        "replay",
        s(&dir.join("spoiling/run.mcap")),
        "--out",
        s(&replay),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = json(&replay.join("report.json"));
    assert_eq!(r["gyro_status"], a["gyro_status"]);
    assert_eq!(figures(&r), figures(&a));
}

/// A unit that never resets: nothing is left out, no hop is counted, and
/// the terminal says nothing of it.
#[test]
fn a_steady_unit_loses_nothing_to_its_status() {
    let dir = temp_dir("status-steady");
    let out = dir.join("smoke");
    let o = gyrobench(&[
        "run",
        concat!(env!("CARGO_MANIFEST_DIR"), "/procedures/smoke.toml"),
        "--db",
        "none",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let r = json(&out.join("report.json"));
    assert_eq!(r["gyro_status"]["dropped_intervals"], 0);
    assert_eq!(r["gyro_status"]["mode_hops"], 0);
    assert!(!String::from_utf8_lossy(&o.stdout).contains("gyro status"));
}
