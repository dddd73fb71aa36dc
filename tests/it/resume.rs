//! `gyrobench run --resume DIR`: an interrupted run goes on from its last
//! completed step in a new part file; the report covers every part.

use std::path::Path;

use crate::cli::{gyrobench, temp_dir};
use crate::common::{MINI, json, s};

/// (frames, event messages) of one log.
fn frames_and_events(path: &Path) -> (u64, Vec<String>) {
    let bytes = std::fs::read(path).expect("log");
    let (mut frames, mut events) = (0, Vec::new());
    for m in mcap::MessageStream::new(&bytes).expect("complete log") {
        let m = m.expect("message");
        let j: serde_json::Value = serde_json::from_slice(&m.data).expect("JSON");
        match m.channel.topic.as_str() {
            "/gyro/frames" => frames += j["counts"].as_array().expect("counts").len() as u64,
            "/events" => events.push(j["message"].as_str().expect("text").to_owned()),
            _ => {}
        }
    }
    (frames, events)
}

#[test]
fn an_interrupted_run_resumes_from_its_last_completed_step() {
    let dir = temp_dir("resume");
    let procedure = dir.join("p.toml");
    std::fs::write(&procedure, MINI).expect("procedure");
    let run = dir.join("run");
    // A chamber alarm during the ramp record ends the first part in error.
    let out = gyrobench(&[
        "run",
        s(&procedure),
        "--out",
        s(&run),
        "--inject",
        "chamber-alarm@2500",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let first = json(&run.join("report.json"));
    assert_eq!(first["outcome"], "error");
    assert_eq!(first["measurements"].as_array().expect("list").len(), 2);

    let out = gyrobench(&["run", "--resume", s(&run)]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let err = String::from_utf8_lossy(&out.stderr);
    // What a resume retakes is said once, and counted the way the progress
    // lines count: the step it goes on at is the next `[n/N]` line.
    assert!(
        err.contains("10 of 16 steps were done before the break"),
        "{err}"
    );
    let (_, at) = err
        .split_once("going on at step ")
        .expect("the step it goes on at");
    let (n, rest) = at.split_once(" of ").expect("n of N");
    let total: String = rest.chars().take_while(char::is_ascii_digit).collect();
    assert!(
        err.contains(&format!("\n[{n}/{total}] ")),
        "the first step after the resume is not [{n}/{total}]: {err}"
    );
    assert!(
        err.contains("[restore 1/"),
        "the restore shows no progress: {err}"
    );
    // The report covers both parts: every measurement once, in order, and
    // the frames of both logs.
    let r = json(&run.join("report.json"));
    assert_eq!(r["outcome"], "pass");
    let names: Vec<&str> = r["measurements"]
        .as_array()
        .expect("list")
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
    assert_eq!(r["measurements"][0], first["measurements"][0]);
    let (f1, _) = frames_and_events(&run.join("run.mcap"));
    let (f2, events) = frames_and_events(&run.join("run.part2.mcap"));
    assert_eq!(r["frames"].as_u64(), Some(f1 + f2));
    // The ramp record was cut short, so its thermal segment is taken again
    // from its chamber step, after the set point before it is restored and
    // held as long as the procedure held it (warm, up, east: 2040 s).
    for want in [
        "restore setup.0",
        "setup.0.resume_arrive",
        "setup.0.resume_dwell (line 9): wait 2040 s",
        "step main.3 (line",
        "step main.4 (line",
    ] {
        assert!(
            events.iter().any(|e| e.contains(want)),
            "{want}: {events:?}"
        );
    }
    assert!(
        !events.iter().any(|e| e.starts_with("step main.0 ")),
        "{events:?}"
    );
    // Replaying the last part gives the same report (it reads the first).
    let replayed = dir.join("replayed");
    gyrobench(&[
        "replay",
        s(&run.join("run.part2.mcap")),
        "--out",
        s(&replayed),
    ]);
    assert!(
        std::fs::read(run.join("report.json")).expect("report")
            == std::fs::read(replayed.join("report.json")).expect("replayed report"),
        "replay of the resumed run differs"
    );
    // A finished run has nothing to resume.
    let out = gyrobench(&["run", "--resume", s(&run)]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("nothing to resume"));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// The fault-and-resume sweep on a short procedure with a thermal segment
/// (the full sweep of the acceptance runs in CI, `examples/resume_sweep`):
/// interrupted at every step boundary and mid-step by a kill, a chamber
/// alarm, a silent gyro, a full disk, SIGHUP of the run and SIGQUIT of the
/// station running it, every resume passes with figures in the
/// reference spread, nothing is lost or overwritten, no step before the
/// interrupted segment is taken again, and the bench is left safe.
#[test]
fn the_quick_fault_and_resume_sweep_finds_nothing_wrong() {
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("resume-sweep");
    let procedure = dir.join("mini.toml");
    std::fs::write(&procedure, MINI).expect("procedure");
    let sweep = crate::sweep::Sweep {
        bin: env!("CARGO_BIN_EXE_gyrobench").into(),
        procedure,
        dir: dir.join("runs"),
        seeds: (1..=8).collect(),
        faults: vec![
            ("process-kill".into(), 1),
            ("chamber-alarm".into(), 2),
            ("gyro-silent".into(), 3),
            ("disk-full".into(), 4),
            ("sighup".into(), 5),
            ("station-sigquit".into(), 6),
        ],
        jobs: 2,
    };
    let (rows, totals) = sweep.run();
    let table = crate::sweep::render(&rows, &totals);
    assert!(totals.runs >= 30, "{table}");
    assert_eq!(
        (
            totals.lost,
            totals.overwritten,
            totals.resumes_failed,
            totals.bench_unsafe,
            totals.figures_outside,
            totals.retaken_outside
        ),
        (0, 0, 0, 0, 0, 0),
        "{table}\n{}",
        crate::sweep::render_rows(&rows)
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A part file of another run in a run's directory (copied in, left from
/// a reused directory) is never taken as the run's own.
#[test]
fn a_part_of_another_run_is_refused_by_name() {
    // Runs beside no wall-clock test (see `busy_turn`).
    let _busy = crate::common::busy_turn();
    let dir = temp_dir("resume-foreign");
    let procedure = dir.join("p.toml");
    std::fs::write(&procedure, MINI).expect("procedure");
    let interrupted = |name: &str| {
        let run = dir.join(name);
        let out = gyrobench(&[
            "run",
            s(&procedure),
            "--out",
            s(&run),
            "--db",
            "none",
            "--inject",
            "chamber-alarm@2500",
        ]);
        assert_eq!(out.status.code(), Some(1));
        run
    };
    let (x, y) = (interrupted("x"), interrupted("y"));
    let out = gyrobench(&["run", "--resume", s(&x), "--db", "none"]);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::copy(x.join("run.part2.mcap"), y.join("run.part2.mcap")).expect("copy");
    let before = std::fs::read(y.join("report.json")).expect("report");
    let out = gyrobench(&["run", "--resume", s(&y), "--db", "none"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(0), "{err}");
    assert!(
        err.contains("run.part2.mcap") && err.contains("the parts are of two runs"),
        "{err}"
    );
    assert!(!y.join("run.part3.mcap").exists(), "nothing resumed");
    assert_eq!(
        std::fs::read(y.join("report.json")).expect("report"),
        before
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
