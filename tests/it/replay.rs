//! `gyrobench replay`: the verdict and every measurement recomputed from
//! the log alone, identical to the live run's; truncated logs read to their
//! last complete chunk.

use std::path::Path;

use crate::cli::{gyrobench, temp_dir};
use crate::common::{MINI, json, s, stderr};

const COEFFS: &str = "[unit]
serial = \"SIMULATED\"
type = \"RL-16\"

[model4]
k1_dph_per_c = -0.12
k2_dph_per_c2 = -0.01
k3_dph_per_c_per_s = 20.0
k4_dph_per_c = -0.007
k5_dph = 0.36
warmup_tau_s = 600.0
";

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Live run, then replay of its log: both reports byte for byte.
fn live_then_replay(dir: &Path, extra: &[&str]) -> (std::process::Output, std::process::Output) {
    let procedure = dir.join("mini.toml");
    std::fs::write(&procedure, MINI).expect("procedure");
    let live = dir.join("live");
    let mut args = vec!["run", s(&procedure), "--out", s(&live)];
    args.extend_from_slice(extra);
    let run = gyrobench(&args);
    let replayed = dir.join("replayed");
    let replay = gyrobench(&["replay", s(&live.join("run.mcap")), "--out", s(&replayed)]);
    assert_eq!(
        replay.status.code(),
        run.status.code(),
        "{}",
        String::from_utf8_lossy(&replay.stderr)
    );
    for name in ["report.json", "report.html"] {
        assert!(
            read(&live.join(name)) == read(&replayed.join(name)),
            "{name} differs between the live run and its replay"
        );
    }
    // The same verdict text; the run also says where its directory is.
    let live_text = String::from_utf8_lossy(&run.stdout);
    let dir_line = format!("  run directory: {}\n", live.display());
    assert!(live_text.ends_with(&dir_line), "{live_text}");
    assert_eq!(
        live_text.trim_end_matches(&dir_line),
        String::from_utf8_lossy(&replay.stdout),
        "the same verdict text"
    );
    (run, replay)
}

#[test]
fn replay_of_an_unchanged_log_is_identical_to_the_live_run() {
    let dir = temp_dir("replay-same");
    let (run, _) = live_then_replay(&dir, &["--seed", "3"]);
    assert_eq!(run.status.code(), Some(0));
    let r = json(&dir.join("replayed/report.json"));
    let names: Vec<&str> = r["measurements"]
        .as_array()
        .expect("measurements")
        .iter()
        .map(|m| m["name"].as_str().expect("name"))
        .collect();
    assert_eq!(
        names,
        [
            "bias_dph:up",
            "bias_dph:east",
            "self_heating_dph",
            "stability",
            "raw",
            "compensated"
        ]
    );
    assert!(
        r["measurements"][5]["note"]
            .as_str()
            .expect("note")
            .contains("fitted held out")
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn allan_reads_a_record_of_a_log_at_the_frame_rate() {
    let dir = temp_dir("allan-log");
    let procedure = dir.join("mini.toml");
    std::fs::write(&procedure, MINI).expect("procedure");
    let live = dir.join("live");
    gyrobench(&["run", s(&procedure), "--out", s(&live)]);
    let log = live.join("run.mcap");
    let out = gyrobench(&["allan", s(&log), "--record", "up", "--json"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(j["record"], "up");
    assert_eq!(j["tau0_s"], 0.0025);
    assert_eq!(j["samples"], 120 * 400);
    // Default: the longest record; text output names the three figures.
    let out = gyrobench(&["allan", s(&log)]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(", warm:") && text.contains("IEEE coefficient B"),
        "{text}"
    );
    let out = gyrobench(&["allan", s(&log), "--record", "nowhere"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("records in this log: warm, up, east, ramp"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn the_run_coefficients_travel_in_the_log_and_replay_can_swap_them() {
    let dir = temp_dir("replay-coeffs");
    let coeffs = dir.join("coeffs.toml");
    std::fs::write(&coeffs, COEFFS).expect("coeffs");
    live_then_replay(&dir, &["--coeffs", s(&coeffs)]);
    let live = json(&dir.join("live/report.json"));
    let note = live["measurements"][5]["note"].as_str().expect("note");
    assert!(
        note.contains("a set not in a store of RL-16 SIMULATED from"),
        "{note}"
    );
    assert_eq!(live["coefficients"]["source"], "file");
    // Without the run's coefficients, the same log gives another figure.
    let other = dir.join("other.toml");
    std::fs::write(&other, COEFFS.replace("k5_dph = 0.36", "k5_dph = 3.6")).expect("coeffs");
    let out = dir.join("swapped");
    gyrobench(&[
        "replay",
        s(&dir.join("live/run.mcap")),
        "--coeffs",
        s(&other),
        "--out",
        s(&out),
    ]);
    let swapped = json(&out.join("report.json"));
    assert_ne!(
        swapped["measurements"][5]["value"],
        live["measurements"][5]["value"]
    );
    assert_eq!(
        swapped["measurements"][4]["value"], live["measurements"][4]["value"],
        "uncompensated figures do not depend on the coefficients"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_run_ended_by_a_device_fault_replays_to_the_same_error() {
    let dir = temp_dir("replay-error");
    let (run, _) = live_then_replay(&dir, &["--inject", "chamber-alarm@2500"]);
    assert_eq!(run.status.code(), Some(1));
    let r = json(&dir.join("replayed/report.json"));
    assert_eq!(r["error"]["device"], "chamber");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_truncated_log_is_read_to_its_last_complete_chunk_and_says_so() {
    let dir = temp_dir("replay-truncated");
    let procedure = dir.join("mini.toml");
    std::fs::write(&procedure, MINI).expect("procedure");
    let live = dir.join("live");
    gyrobench(&["run", s(&procedure), "--out", s(&live)]);
    let bytes = std::fs::read(live.join("run.mcap")).expect("log");
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).expect("cut log");
    let out = gyrobench(&["replay", s(&cut), "--out", s(&dir.join("r"))]);
    assert_eq!(out.status.code(), Some(1), "a run that did not finish");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("incomplete") && err.contains("bytes"), "{err}");
    let r = json(&dir.join("r/report.json"));
    let full = json(&live.join("report.json"));
    assert_eq!(r["outcome"], "error");
    assert!(
        r["error"]["message"]
            .as_str()
            .expect("message")
            .contains("log ends")
    );
    let (got, all) = (
        r["frames"].as_u64().expect("frames"),
        full["frames"].as_u64().expect("frames"),
    );
    assert!(got > all / 3 && got < all, "{got} of {all} frames");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Logs of the first format (steps only as `/events` lines, no `/steps`,
/// no attachments) replay to the figures their run reported, a resumed
/// run across both of its parts.
#[test]
fn logs_of_the_first_format_still_replay_to_their_figures() {
    let dir = temp_dir("replay-format1");
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/logs/format1");
    for (run, log) in [("whole", "run.mcap"), ("resumed", "run.part2.mcap")] {
        let out = dir.join(run);
        let r = gyrobench(&["replay", s(&fixtures.join(run).join(log)), "--out", s(&out)]);
        assert_eq!(
            r.status.code(),
            Some(0),
            "{run}: {}",
            String::from_utf8_lossy(&r.stderr)
        );
        let then = json(&fixtures.join(run).join("report.json"));
        let now = json(&out.join("report.json"));
        for field in ["outcome", "frames", "device_time_s", "dut", "seed", "noise"] {
            assert_eq!(now[field], then[field], "{run}: {field}");
        }
        // Each figure as it was judged then, key for key (a replay adds
        // the uncertainty, guard band and margin the format had none of).
        let (ms_now, ms_then) = (&now["measurements"], &then["measurements"]);
        assert_eq!(
            ms_now.as_array().map(Vec::len),
            ms_then.as_array().map(Vec::len)
        );
        for (m_now, m_then) in ms_now
            .as_array()
            .into_iter()
            .flatten()
            .zip(ms_then.as_array().into_iter().flatten())
        {
            for (k, v) in m_then.as_object().expect("a measurement") {
                assert_eq!(&m_now[k], v, "{run}: {} {k}", m_then["name"]);
            }
        }
        // Judged as it was then: simple acceptance.
        assert_eq!(now["decision_rule"]["rule"], "simple", "{run}");
        // The link figures it had; later figures (reconnects) are new.
        for (k, v) in then["link"].as_object().expect("link") {
            assert_eq!(&now["link"][k], v, "{run}: link.{k}");
        }
        assert_eq!(now["measurements"].as_array().map(Vec::len), Some(2));
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The offsets of the top-level chunk records of an MCAP file.
fn chunk_offsets(bytes: &[u8]) -> Vec<usize> {
    let mut at = 8;
    let mut out = Vec::new();
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().expect("8 bytes")) as usize;
        if bytes[at] == 0x06 {
            out.push(at);
        }
        at += 9 + len;
    }
    out
}

/// One flipped bit in one chunk of nine loses that chunk, not the rest:
/// recover, replay and export skip it, say what is missing by time and
/// count, and exit non-zero.
#[test]
fn a_damaged_chunk_loses_only_itself_and_every_reader_says_so() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("replay-damaged");
    let procedure = dir.join("mini.toml");
    std::fs::write(&procedure, MINI).expect("procedure");
    let live = dir.join("live");
    let o = gyrobench(&["run", s(&procedure), "--out", s(&live), "--db", "none"]);
    assert_eq!(o.status.code(), Some(0));
    let log = live.join("run.mcap");
    let whole = std::fs::read(&log).expect("log");
    let chunks = chunk_offsets(&whole);
    assert!(chunks.len() >= 9, "{} chunks", chunks.len());
    // The intact log's counts.
    let r = gyrobench(&["recover", s(&log), "-o", s(&dir.join("intact.mcap"))]);
    assert_eq!(r.status.code(), Some(0));
    let messages = |out: &std::process::Output| -> u64 {
        let text = String::from_utf8_lossy(&out.stdout);
        text.split_whitespace()
            .nth(1)
            .and_then(|n| n.parse().ok())
            .expect("recovered N")
    };
    let all = messages(&r);
    let e = gyrobench(&["export", s(&log), "-o", s(&dir.join("intact.csv"))]);
    assert_eq!(e.status.code(), Some(0));
    let all_rows = std::fs::read_to_string(dir.join("intact.csv"))
        .expect("csv")
        .lines()
        .count();

    let mut damaged = whole.clone();
    let third = chunks[2];
    let len = u64::from_le_bytes(damaged[third + 1..third + 9].try_into().expect("len")) as usize;
    damaged[third + 9 + len * 3 / 4] ^= 0x10;
    let bad = dir.join("damaged.mcap");
    std::fs::write(&bad, &damaged).expect("damaged log");

    let r = gyrobench(&["recover", s(&bad), "-o", s(&dir.join("rec.mcap"))]);
    assert_eq!(r.status.code(), Some(1), "{}", stderr(&r));
    let err = stderr(&r);
    assert!(err.contains("1 damaged part(s) skipped"), "{err}");
    let got = messages(&r);
    assert!(got > all / 2 && got < all, "{got} of {all} messages");
    // The count it reports lost is the count that is missing.
    let lost: u64 = err
        .split(" damaged part(s) skipped, the rest read: ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("a count of lost messages in {err}"));
    assert_eq!(got + lost, all, "{err}");

    let e = gyrobench(&["export", s(&bad), "-o", s(&dir.join("damaged.csv"))]);
    assert_eq!(e.status.code(), Some(1), "{}", stderr(&e));
    let rows = std::fs::read_to_string(dir.join("damaged.csv"))
        .expect("csv")
        .lines()
        .count();
    assert!(
        rows > all_rows / 2 && rows < all_rows,
        "{rows} of {all_rows} rows"
    );

    let p = gyrobench(&["replay", s(&bad), "--out", s(&dir.join("rp"))]);
    assert_eq!(p.status.code(), Some(1), "{}", stderr(&p));
    let report = json(&dir.join("rp/report.json"));
    let msg = report["error"]["message"].as_str().unwrap_or_default();
    assert!(msg.contains("damaged"), "{report}");
    // Its last state is the end of the run, not where the damage was.
    assert!(
        report["device_time_s"].as_f64().expect("device time")
            > 0.9
                * json(&live.join("report.json"))["device_time_s"]
                    .as_f64()
                    .expect("t"),
        "{report}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
