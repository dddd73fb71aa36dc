//! A run is never lost, overwritten or mixed: run directories are new and
//! locked, no output is written over an input or through a planted link,
//! names cannot escape `runs/`, a full disk says what it could not write,
//! and tools that read nothing of a run say so.

use std::path::Path;
use std::process::{Command, Stdio};

use crate::cli::{gyrobench, temp_dir};
use crate::common::{MINI, TINY, json, s, stderr, wait_for, write};

fn bin() -> Command {
    crate::cli::command()
}

#[test]
fn a_directory_holding_a_run_is_refused_and_force_moves_it_aside() {
    let dir = temp_dir("integrity-exists");
    let p = write(&dir, "tiny.toml", TINY);
    let out = dir.join("run");
    assert_eq!(
        gyrobench(&["run", s(&p), "--out", s(&out)]).status.code(),
        Some(0)
    );
    let first = std::fs::read(out.join("run.mcap")).expect("log");

    let again = gyrobench(&["run", s(&p), "--out", s(&out), "--seed", "2"]);
    assert_eq!(again.status.code(), Some(2), "{}", stderr(&again));
    let err = stderr(&again);
    assert!(
        err.contains("holds a run already") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(out.join("run.mcap")).expect("log"),
        first,
        "the old log is untouched"
    );
    assert!(!out.join("run.part2.mcap").exists());

    let forced = gyrobench(&["run", s(&p), "--out", s(&out), "--seed", "2", "--force"]);
    assert_eq!(forced.status.code(), Some(0), "{}", stderr(&forced));
    let aside = dir.join("run.replaced-1");
    assert_eq!(std::fs::read(aside.join("run.mcap")).expect("moved"), first);
    assert!(
        stderr(&forced).contains("run.replaced-1"),
        "{}",
        stderr(&forced)
    );
    assert_ne!(std::fs::read(out.join("run.mcap")).expect("new log"), first);
    assert!(
        !out.join("run.lock").exists(),
        "the lock is released at the end"
    );

    // --force moves runs aside, nothing else.
    let notes = dir.join("notes");
    std::fs::create_dir_all(&notes).expect("dir");
    std::fs::write(notes.join("todo.txt"), "keep").expect("file");
    let r = gyrobench(&["run", s(&p), "--out", s(&notes), "--force"]);
    assert_eq!(r.status.code(), Some(2), "{}", stderr(&r));
    assert!(
        stderr(&r).contains("is not a run directory"),
        "{}",
        stderr(&r)
    );
    assert_eq!(
        std::fs::read(notes.join("todo.txt")).expect("kept"),
        b"keep"
    );

    // Replay never writes its report over the run's own.
    let report = std::fs::read(out.join("report.json")).expect("report");
    let r = gyrobench(&["replay", s(&out.join("run.mcap")), "--out", s(&out)]);
    assert_eq!(r.status.code(), Some(2), "{}", stderr(&r));
    assert!(stderr(&r).contains("is a run directory"), "{}", stderr(&r));
    assert_eq!(
        std::fs::read(out.join("report.json")).expect("kept"),
        report
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn runs_started_together_get_their_own_directories() {
    let dir = temp_dir("integrity-unique");
    let p = write(&dir, "tiny.toml", TINY);
    let children: Vec<_> = (0..3)
        .map(|_| {
            bin()
                .args(["run", s(&p)])
                .current_dir(&dir)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("run starts")
        })
        .collect();
    for mut c in children {
        assert_eq!(c.wait().expect("ends").code(), Some(0));
    }
    let runs: Vec<_> = std::fs::read_dir(dir.join("runs"))
        .expect("runs/")
        .map(|e| e.expect("entry").path())
        .collect();
    assert_eq!(runs.len(), 3, "{runs:?}");
    for r in &runs {
        assert_eq!(
            json(&r.join("report.json"))["outcome"],
            "pass",
            "{}",
            r.display()
        );
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_second_run_or_resume_in_a_directory_in_use_is_refused() {
    let dir = temp_dir("integrity-lock");
    let p = write(&dir, "mini.toml", MINI);
    let out = dir.join("run");
    // An interrupted run to resume.
    let first = gyrobench(&[
        "run",
        s(&p),
        "--out",
        s(&out),
        "--inject",
        "chamber-alarm@2500",
    ]);
    assert_eq!(first.status.code(), Some(1));
    // Two resumes at once: the first holds the lock (paced, so it lasts),
    // the second is refused naming it, and only one part is written.
    let mut a = bin()
        .args(["run", "--resume", s(&out), "--speed", "400"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("resume starts");
    wait_for(&out.join("run.part2.mcap"));
    let b = gyrobench(&["run", "--resume", s(&out)]);
    assert_eq!(b.status.code(), Some(1));
    let err = stderr(&b);
    assert!(
        err.contains("in use by another run") && err.contains(&format!("pid {}", a.id())),
        "{err}"
    );
    // A fresh run into the same directory is refused too.
    let c = gyrobench(&["run", s(&p), "--out", s(&out)]);
    assert_eq!(c.status.code(), Some(2), "{}", stderr(&c));
    assert_eq!(a.wait().expect("ends").code(), Some(0));
    assert!(!out.join("run.part3.mcap").exists());
    assert_eq!(json(&out.join("report.json"))["outcome"], "pass");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_resume_after_a_kill_reports_the_stale_lock_it_takes_over() {
    let dir = temp_dir("integrity-stale");
    let p = write(&dir, "mini.toml", MINI);
    let out = dir.join("run");
    let mut command = bin();
    command
        .args(["run", s(&p), "--out", s(&out), "--speed", "400"])
        .stdout(Stdio::null());
    let mut run = crate::common::Watched::spawn(command);
    let pid = run.child.id();
    // SIGKILL once the first record has started.
    run.wait_for_line("] record warm for");
    run.child.kill().expect("SIGKILL");
    let _killed = run.finish();
    let lock = std::fs::read_to_string(out.join("run.lock")).expect("the killed run's lock");
    assert!(lock.contains(&format!("pid={pid}")), "{lock}");
    let r = gyrobench(&["run", "--resume", s(&out)]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    let err = stderr(&r);
    assert!(
        err.contains(&format!("took over the lock of pid {pid}")) && err.contains("no longer runs"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn an_output_that_names_an_input_is_refused_and_the_input_kept() {
    let dir = temp_dir("integrity-same");
    let p = write(&dir, "tiny.toml", TINY);
    let out = dir.join("run");
    assert_eq!(
        gyrobench(&["run", s(&p), "--out", s(&out)]).status.code(),
        Some(0)
    );
    let log = out.join("run.mcap");
    let bytes = std::fs::read(&log).expect("log");
    let dotted = out.join("..").join("run").join("run.mcap");
    let csv = dir.join("run.csv");
    assert_eq!(
        gyrobench(&["export", s(&log), "-o", s(&csv)]).status.code(),
        Some(0)
    );
    let csv_bytes = std::fs::read(&csv).expect("csv");
    let site = write(
        &dir,
        "site.toml",
        "[site]\nlatitude_deg = 50.45\nlongitude_deg = 30.52\nheight_m = 180.0\nmagnetic_field_ned_ut = [19.5, 2.7, 46.5]\n",
    );
    for args in [
        vec!["export", s(&log), "-o", s(&log)],
        vec!["export", s(&log), "-o", s(&dotted)],
        vec!["recover", s(&log), "-o", s(&log)],
        vec!["calibrate", s(&log), "-o", s(&log)],
        vec!["import", s(&csv), "--site", s(&site), "-o", s(&csv)],
    ] {
        let r = gyrobench(&args);
        // Two arguments that name one file: a usage error.
        assert_eq!(r.status.code(), Some(2), "{args:?}");
        assert!(
            stderr(&r).contains("would destroy the input"),
            "{args:?}: {}",
            stderr(&r)
        );
    }
    assert_eq!(std::fs::read(&log).expect("log"), bytes);
    assert_eq!(std::fs::read(&csv).expect("csv"), csv_bytes);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_symlink_planted_at_the_old_temporary_name_is_not_followed() {
    let dir = temp_dir("integrity-symlink");
    let p = write(&dir, "tiny.toml", TINY);
    let out = dir.join("run");
    assert_eq!(
        gyrobench(&["run", s(&p), "--out", s(&out)]).status.code(),
        Some(0)
    );
    let victim = write(&dir, "victim.txt", "precious");
    let csv = dir.join("x.csv");
    std::os::unix::fs::symlink(&victim, dir.join("x.csv.partial")).expect("plant");
    let recovered = dir.join("r.mcap");
    std::os::unix::fs::symlink(&victim, dir.join("r.mcap.partial")).expect("plant");
    assert_eq!(
        gyrobench(&["export", s(&out.join("run.mcap")), "-o", s(&csv)])
            .status
            .code(),
        Some(0)
    );
    assert_eq!(
        gyrobench(&["recover", s(&out.join("run.mcap")), "-o", s(&recovered)])
            .status
            .code(),
        Some(0)
    );
    assert_eq!(
        std::fs::read_to_string(&victim).expect("victim"),
        "precious"
    );
    assert!(
        std::fs::read_to_string(&csv)
            .expect("csv")
            .starts_with("time_s,")
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_procedure_name_that_would_leave_runs_is_refused_with_its_line() {
    let dir = temp_dir("integrity-name");
    for name in ["../../escaped", "/tmp/escaped", ".hidden", "a/b"] {
        let text = TINY.replace("name = \"tiny\"", &format!("name = {name:?}"));
        let p = write(&dir, "p.toml", &text);
        let r = crate::cli::command()
            .args(["run", s(&p)])
            .current_dir(&dir)
            .output()
            .expect("runs");
        assert_eq!(r.status.code(), Some(1), "{name}");
        let err = stderr(&r);
        assert!(
            err.contains("p.toml:3:") && err.contains("procedure.name"),
            "{name}: {err}"
        );
        assert!(!dir.join("runs").exists(), "{name}: nothing was created");
    }
    assert!(!Path::new("/tmp/escaped").exists());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn recover_of_anything_but_a_run_is_an_error_and_writes_nothing() {
    let dir = temp_dir("integrity-recover");
    let mut random = vec![0u8; 4096];
    let mut x: u32 = 12345;
    for b in &mut random {
        x = x.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        *b = (x >> 16) as u8;
    }
    let mut magic_then_junk = b"\x89MCAP0\r\n".to_vec();
    magic_then_junk.extend_from_slice(&random);
    for (name, bytes) in [
        ("empty.mcap", Vec::new()),
        ("random.mcap", random.clone()),
        ("text.mcap", b"time_s,rate_dph\n1,2\n".to_vec()),
        ("junk.mcap", magic_then_junk),
    ] {
        let input = dir.join(name);
        std::fs::write(&input, &bytes).expect("input");
        let out = dir.join(format!("{name}.recovered"));
        let r = gyrobench(&["recover", s(&input), "-o", s(&out)]);
        assert_eq!(r.status.code(), Some(1), "{name}: {}", stderr(&r));
        assert!(!out.exists(), "{name}: no output for nothing recovered");
        assert!(
            !String::from_utf8_lossy(&r.stdout).contains("recovered 0"),
            "{name}"
        );
    }
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .expect("list")
        .map(|e| e.expect("entry").file_name())
        .filter(|n| n.to_string_lossy().contains("partial"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn export_and_allan_fail_on_a_log_with_nothing_and_warn_on_a_truncated_one() {
    let dir = temp_dir("integrity-truncated");
    let p = write(&dir, "mini.toml", MINI);
    let out = dir.join("run");
    assert_eq!(
        gyrobench(&["run", s(&p), "--out", s(&out)]).status.code(),
        Some(0)
    );
    let bytes = std::fs::read(out.join("run.mcap")).expect("log");
    let half = write(&dir, "half.mcap", "");
    std::fs::write(&half, &bytes[..bytes.len() / 2]).expect("half");
    let head = dir.join("head.mcap");
    std::fs::write(&head, &bytes[..3000]).expect("head");

    let r = gyrobench(&["export", s(&half), "-o", s(&dir.join("half.csv"))]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    assert!(stderr(&r).contains("incomplete"), "{}", stderr(&r));
    let r = gyrobench(&["allan", s(&half), "--record", "warm"]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    assert!(stderr(&r).contains("incomplete"), "{}", stderr(&r));

    let r = gyrobench(&["export", s(&head), "-o", s(&dir.join("head.csv"))]);
    assert_eq!(r.status.code(), Some(1), "{}", stderr(&r));
    assert!(!dir.join("head.csv").exists());
    let r = gyrobench(&["allan", s(&head)]);
    assert_eq!(r.status.code(), Some(1), "{}", stderr(&r));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_full_disk_mid_run_names_the_file_and_step_and_keeps_what_was_written() {
    let dir = temp_dir("integrity-full");
    let p = write(&dir, "mini.toml", MINI);
    let out = dir.join("run");
    // A file size limit (in 512-byte blocks) makes the log's writes fail
    // as a full disk does; the small report files still fit.
    let r = Command::new("sh")
        .env("GYROBENCH_DB", "none")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f 400; exec {} run {} --out {}",
            env!("CARGO_BIN_EXE_gyrobench"),
            s(&p),
            s(&out)
        ))
        .output()
        .expect("runs");
    assert_eq!(r.status.code(), Some(1), "{}", stderr(&r));
    let text = format!("{}{}", String::from_utf8_lossy(&r.stdout), stderr(&r));
    assert!(
        text.contains("run.mcap") && text.contains("File too large"),
        "{text}"
    );
    assert!(text.contains("gyrobench recover"), "{text}");
    let report = json(&out.join("report.json"));
    assert_eq!(report["outcome"], "error");
    let message = report["error"]["message"].as_str().expect("message");
    assert!(
        message.contains("writing the log") && message.contains("run.mcap"),
        "{message}"
    );
    assert!(
        report["error"]["step"]
            .as_str()
            .expect("step")
            .starts_with("main."),
        "{report}"
    );
    let log = out.join("run.mcap");
    assert!(
        std::fs::metadata(&log).expect("log").len() > 100_000,
        "what was written is kept"
    );
    let recovered = dir.join("recovered.mcap");
    let r = gyrobench(&["recover", s(&log), "-o", s(&recovered)]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn calibrate_refuses_runs_of_different_units_unless_told() {
    let dir = temp_dir("integrity-serials");
    let p = write(&dir, "mini.toml", MINI);
    let mut logs = Vec::new();
    for (seed, dut) in [("1", "RL16-0001"), ("2", "RL16-0002")] {
        let out = dir.join(dut);
        let r = gyrobench(&["run", s(&p), "--seed", seed, "--dut", dut, "--out", s(&out)]);
        assert!(
            r.status.code().is_some_and(|c| c == 0 || c == 3),
            "{}",
            stderr(&r)
        );
        logs.push(out.join("run.mcap"));
    }
    let coeffs = dir.join("c.toml");
    let r = gyrobench(&["calibrate", s(&logs[0]), s(&logs[1]), "-o", s(&coeffs)]);
    assert_eq!(r.status.code(), Some(1));
    let err = stderr(&r);
    assert!(
        err.contains("different units") && err.contains("RL16-0001") && err.contains("RL16-0002"),
        "{err}"
    );
    assert!(!coeffs.exists());
    let r = gyrobench(&[
        "calibrate",
        s(&logs[0]),
        s(&logs[1]),
        "-o",
        s(&coeffs),
        "--allow-mixed-serials",
    ]);
    assert!(!stderr(&r).contains("different units"), "{}", stderr(&r));

    // One run twice, or a copy of it, would score the fit on its own data.
    let _ = std::fs::remove_file(&coeffs);
    let copy = dir.join("copy.mcap");
    std::fs::copy(&logs[0], &copy).expect("copy");
    for twice in [&logs[0], &copy] {
        let r = gyrobench(&["calibrate", s(&logs[0]), s(twice), "-o", s(&coeffs)]);
        assert_eq!(r.status.code(), Some(2), "{}", stderr(&r));
        assert!(stderr(&r).contains("are the same run"), "{}", stderr(&r));
        assert!(!coeffs.exists());
    }

    // A run too short for the 600 s drift smoothing scores nothing.
    let t = write(&dir, "tiny.toml", TINY);
    let short = dir.join("short");
    let r = gyrobench(&["run", s(&t), "--out", s(&short)]);
    assert_eq!(r.status.code(), Some(0), "{}", stderr(&r));
    let r = gyrobench(&["calibrate", s(&short.join("run.mcap")), "-o", s(&coeffs)]);
    assert_eq!(r.status.code(), Some(1), "{}", stderr(&r));
    assert!(
        stderr(&r).contains("too short to score a drift"),
        "{}",
        stderr(&r)
    );
    assert!(!coeffs.exists());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn a_closed_stdout_ends_a_command_quietly_after_its_files_are_complete() {
    let dir = temp_dir("integrity-pipe");
    let p = write(&dir, "tiny.toml", TINY);
    let out = dir.join("run");
    assert_eq!(
        gyrobench(&["run", s(&p), "--out", s(&out)]).status.code(),
        Some(0)
    );
    let csv = dir.join("run.csv");
    let mut child = bin()
        .args(["export", s(&out.join("run.mcap")), "-o", s(&csv)])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("export starts");
    drop(child.stdout.take());
    let done = child.wait_with_output().expect("ends");
    assert_eq!(done.status.code(), Some(0), "{}", stderr(&done));
    assert!(!stderr(&done).contains("panicked"), "{}", stderr(&done));
    let text = std::fs::read_to_string(&csv).expect("csv");
    assert!(text.starts_with("time_s,") && text.ends_with('\n'));
    // The run's own summary too: the log and report are whole.
    let mut child = bin()
        .args(["run", s(&p), "--out", s(&dir.join("run2"))])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run starts");
    drop(child.stdout.take());
    let done = child.wait_with_output().expect("ends");
    assert_eq!(done.status.code(), Some(0), "{}", stderr(&done));
    assert!(!stderr(&done).contains("panicked"), "{}", stderr(&done));
    assert_eq!(json(&dir.join("run2/report.json"))["outcome"], "pass");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Data a record cannot be judged on (a link that corrupts frames, an
/// output stuck at one value or pinned at its limit) are never judged: the
/// measurement's outcome is `error` with the reason, the run is an error,
/// and replay says the same from the log.
#[test]
fn unsound_gyro_data_are_not_judged_and_replay_agrees() {
    let dir = temp_dir("integrity-unsound");
    let p = write(&dir, "tiny.toml", TINY);
    for (fault, why) in [
        ("gyro-corrupt", "missing"),
        ("gyro-stuck", "it is stuck"),
        ("gyro-saturated", "saturated"),
    ] {
        let out = dir.join(fault);
        let r = gyrobench(&[
            "run",
            s(&p),
            "--out",
            s(&out),
            "--inject",
            &format!("{fault}@0"),
        ]);
        assert_eq!(r.status.code(), Some(1), "{fault}: {}", stderr(&r));
        let text = String::from_utf8_lossy(&r.stdout);
        assert!(text.contains("not judged in step"), "{fault}: {text}");
        let report = json(&out.join("report.json"));
        assert_eq!(report["outcome"], "error", "{fault}");
        for m in report["measurements"].as_array().expect("list") {
            assert_eq!(m["outcome"], "error", "{fault}: {m}");
            let note = m["note"].as_str().expect("note");
            assert!(
                note.starts_with("not judged: record") && note.contains(why),
                "{fault}: {note}"
            );
        }
        let replayed = dir.join(format!("{fault}-replay"));
        let rr = gyrobench(&["replay", s(&out.join("run.mcap")), "--out", s(&replayed)]);
        assert_eq!(rr.status.code(), Some(1), "{fault}");
        assert_eq!(
            std::fs::read(out.join("report.json")).expect("report"),
            std::fs::read(replayed.join("report.json")).expect("replayed"),
            "{fault}: replay judges the same"
        );
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
