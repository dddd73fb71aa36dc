//! One rule for every output a command writes (`fsutil::check_output`):
//! nothing lands inside a run directory, or over a run's log, without
//! `--force`; a refused command leaves the run's files as they were and
//! adds none. The refusals come before any work, so these tests are quick.

use std::path::{Path, PathBuf};

use crate::cli::{gyrobench, temp_dir};
use crate::common::{TINY, s, stderr, write};

/// Every file below `dir`, with its bytes.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("list") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.clone(), std::fs::read(&p).expect("read")));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn no_command_writes_into_another_runs_directory_without_force() {
    let dir = temp_dir("outputs-guard");
    let db = dir.join("results.sqlite");
    let p = write(&dir, "tiny.toml", TINY);
    let run = |name: &str| {
        let out = dir.join(name);
        let o = gyrobench(&["run", s(&p), "--db", s(&db), "--out", s(&out)]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        out
    };
    let (a, b) = (run("a"), run("b"));
    let a_log = a.join("run.mcap");
    let before = snapshot(&b);
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/import");
    let (lab, site) = (fixtures.join("lab-run.csv"), fixtures.join("site.toml"));
    let inside = b.join("new").join("deeper");
    let dotted = a.join("..").join("b").join("x.csv");
    let in_b = |name: &str| s(&b.join(name)).to_owned();
    let (log, part2) = (s(&a_log), in_b("run.part2.mcap"));
    let (db, inside_s) = (s(&db), s(&inside));
    let unit = s(&inside.join("unit.toml")).to_owned();
    let owned = |v: &[&str]| v.iter().map(|a| (*a).to_owned()).collect::<Vec<String>>();
    let commands: Vec<Vec<String>> = vec![
        // The three: the log, the report, the report's JSON.
        owned(&["calibrate", log, "-o", &in_b("run.mcap")]),
        owned(&["twin", "study", "--csv", &in_b("report.html")]),
        owned(&[
            "results",
            "export",
            "--db",
            db,
            "--junit",
            &in_b("report.json"),
        ]),
        // A new file that would be read as the run's next part.
        owned(&[
            "import",
            s(&lab),
            "--site",
            s(&site),
            "--db",
            "none",
            "-o",
            &part2,
        ]),
        owned(&["export", log, "-o", &part2]),
        owned(&["recover", log, "-o", &part2]),
        // Side files, directories and deeper places; `..` resolved.
        owned(&["calibrate", log, "-o", &unit]),
        owned(&["results", "export", "--db", db, "--csv", s(&dotted)]),
        owned(&[
            "results",
            "trend",
            "bias_dph:up",
            "--db",
            db,
            "--html",
            &in_b("trend.html"),
        ]),
        owned(&["diagnose", log, "--out", inside_s]),
        owned(&["diagnose", "selfcheck", "--runs", "1", "--out", s(&b)]),
        owned(&["replay", log, "--out", &in_b("replay")]),
    ];
    let b_real = b.canonicalize().expect("b");
    for args in &commands {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = gyrobench(&args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains(&format!("run directory {}", b_real.display())) && err.contains("--force"),
            "{args:?}: the message names the run directory and the way out: {err}"
        );
    }
    assert_eq!(
        snapshot(&b),
        before,
        "the run's files as they were, none added"
    );

    // A run's own replay goes to its place in the run directory, and
    // --force writes where it is told.
    let o = gyrobench(&["replay", s(&b.join("run.mcap"))]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(b.join("replay").join("report.json").is_file());
    let notes = b.join("notes.csv");
    let o = gyrobench(&["export", s(&a_log), "-o", s(&notes), "--force"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(notes.is_file());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A log put in a run directory under a part's name with `--force` (or by
/// hand) is not indexed as that run's part: its own metadata say whose
/// it is.
#[test]
fn results_sync_indexes_a_run_directorys_own_parts_only() {
    let dir = temp_dir("outputs-sync");
    let db = dir.join("results.sqlite");
    let p = write(&dir, "tiny.toml", TINY);
    let runs = dir.join("runs");
    let run = runs.join("replay");
    let o = gyrobench(&["run", s(&p), "--db", "none", "--out", s(&run)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // The run's own replay, in its place: never a run of its own.
    let o = gyrobench(&["replay", s(&run.join("run.mcap"))]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/import");
    let foreign = run.join("run.part2.mcap");
    let o = gyrobench(&[
        "import",
        s(&fixtures.join("lab-run.csv")),
        "--site",
        s(&fixtures.join("site.toml")),
        "--db",
        "none",
        "--force",
        "-o",
        s(&foreign),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = gyrobench(&["results", "--db", s(&db), "sync", s(&runs)]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!("{}: not indexed", foreign.display()))
            && stderr(&o).contains("not part 2 of run"),
        "{}",
        stderr(&o)
    );
    // One run, one part: the run directory named `replay` is a run (only
    // a run directory's own `replay` is passed over), the imported log is
    // not its part.
    let o = gyrobench(&[
        "results",
        "--db",
        s(&db),
        "list",
        "--all-parts",
        "--json",
        "--include-reference",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let rows: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    let rows = rows.as_array().expect("rows");
    assert_eq!(rows.len(), 1, "{rows:?}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A batch writes `report-SERIAL.*` per unit: two serials that differ
/// only in letter case would be one file on a case-insensitive share (one
/// unit's report replacing the other's), so the batch is refused before
/// it starts.
#[test]
fn batch_serials_that_differ_only_in_case_are_refused() {
    let dir = temp_dir("outputs-serial-case");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = dir.join("batch");
    let o = gyrobench(&[
        "run",
        s(&root.join("procedures/smoke.toml")),
        "--bench",
        s(&root.join("fixtures/bench/quad.toml")),
        "--dut",
        "A=s1",
        "--dut",
        "B=S1",
        "--db",
        "none",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--dut \"B=S1\": units s1 and S1 would share one report file")
            && stderr(&o).contains("letter case"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists(), "refused before the run began");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
