//! A coefficient set is what the results store knows it as, never what its
//! text claims: a set the store holds keeps its version, an edited copy or
//! a set the store never held is recorded as such, a set the store knows
//! as another unit's is refused, and without a store the run goes on and
//! says the set could not be checked (`docs/results.md`, "A coefficient
//! set's identity"). One calibrated set, then each kind of edit.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::cli::{command, temp_dir};
use crate::common::{MINI, TINY, json, s, stderr, write};

/// A unit's set as calibrate stored it, and a short procedure to use it on.
struct Fixture {
    dir: PathBuf,
    db: PathBuf,
    tiny: PathBuf,
    /// The set's file, set 1 of RL-16 RL16-0042 in `db`.
    set: PathBuf,
}

impl Fixture {
    fn new() -> Self {
        let dir = temp_dir("set-identity");
        let db = dir.join("results.sqlite");
        let f = Self {
            tiny: write(&dir, "tiny.toml", TINY),
            set: dir.join("unit.toml"),
            db,
            dir,
        };
        let mini = write(&f.dir, "mini.toml", MINI);
        let fitted = f.dir.join("fitted");
        f.ok(&["run", s(&mini), "--dut", "RL16-0042", "--out", s(&fitted)]);
        let log = fitted.join("run.mcap");
        f.ok(&["calibrate", s(&log), "-o", s(&f.set)]);
        assert!(f.text().contains("version = 1"), "{}", f.text());
        f
    }

    fn gyrobench(&self, args: &[&str]) -> Output {
        command()
            .env("GYROBENCH_DB", &self.db)
            .env("XDG_DATA_HOME", self.dir.join("home"))
            .args(args)
            .output()
            .expect("the gyrobench binary runs")
    }

    /// A command that must end with exit 0 or a verdict (0, 3).
    fn ok(&self, args: &[&str]) -> Output {
        let o = self.gyrobench(args);
        assert!(
            matches!(o.status.code(), Some(0 | 3)),
            "{args:?}: {}",
            stderr(&o)
        );
        o
    }

    fn text(&self) -> String {
        std::fs::read_to_string(&self.set).expect("the set")
    }

    /// The set's text edited by `edit`, written as `name`.
    fn variant(&self, name: &str, edit: impl Fn(&str) -> String) -> PathBuf {
        write(&self.dir, name, &edit(&self.text()))
    }

    /// `run TINY --dut SERIAL --coeffs SET --out DIR` and `more`.
    fn run(&self, serial: &str, set: &Path, out: &str, more: &[&str]) -> (Output, PathBuf) {
        let out = self.dir.join(out);
        let mut args = vec!["run", s(&self.tiny), "--dut", serial, "--coeffs", s(set)];
        args.extend(["--out", s(&out)]);
        args.extend(more);
        (self.gyrobench(&args), out)
    }
}

/// The set a run's report names: its version, its identity's status, the
/// version its text claimed.
fn recorded_as(run: &Path) -> (Option<i64>, String, Option<i64>) {
    let c = json(&run.join("report.json"))["coefficients"].clone();
    let status = c["identity"]["status"].as_str().unwrap_or("none");
    let claimed = c["identity"]["claimed_version"].as_i64();
    (c["version"].as_i64(), status.to_owned(), claimed)
}

/// Its provenance edited: another time of fitting.
fn refitted(t: &str) -> String {
    t.replacen("created_utc = \"", "created_utc = \"1", 1)
}

#[test]
fn an_edited_coefficient_set_is_never_recorded_as_the_stored_set() {
    let f = Fixture::new();
    // The set as calibrate wrote it: the store holds it, set 1.
    let (o, run) = f.run("RL16-0042", &f.set, "registered", &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(recorded_as(&run), (Some(1), "registered".into(), Some(1)));
    another_units_serial_is_refused(&f);
    edited_sets_are_recorded_as_what_they_are(&f);
    without_a_store_the_set_is_recorded_as_not_checked(&f);
    std::fs::remove_dir_all(&f.dir).expect("cleanup");
}

/// The serial edited to another unit's: the store knows the set as
/// RL16-0042's set 1 (or its runs as RL16-0042's), so RL16-0099 refuses
/// it, naming both; with a reason it is used, as the copy it is.
fn another_units_serial_is_refused(f: &Fixture) {
    let forged = f.variant("forged.toml", |t| t.replace("RL16-0042", "RL16-0099"));
    let (o, run) = f.run("RL16-0099", &forged, "forged", &[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("claims set 1 of RL-16 RL16-0099, but the results store")
            && e.contains("holds it as set 1 of RL-16 RL16-0042"),
        "{e}"
    );
    assert!(!run.exists(), "nothing ran");
    // Its provenance edited as well: the runs it was fitted on are still
    // RL16-0042's in the store.
    let forged2 = f.variant("forged2.toml", |t| {
        refitted(&t.replace("RL16-0042", "RL16-0099"))
    });
    let (o, _) = f.run("RL16-0099", &forged2, "forged", &[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("is a run of RL-16 RL16-0042"),
        "{}",
        stderr(&o)
    );
    let reason = ["--coeffs-override", "bench trial"];
    let (o, run) = f.run("RL16-0099", &forged, "forged-override", &reason);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(recorded_as(&run), (None, "edited".into(), Some(1)));
    let c = json(&run.join("report.json"))["coefficients"].clone();
    assert_eq!(c["serial"], "RL16-0042", "{c}");
}

/// A coefficient edited on its own unit: used, recorded as an edited copy
/// of set 1 (never as set 1) in the report, its replay and the store; a
/// set number the unit has not got, as a set the store does not hold.
fn edited_sets_are_recorded_as_what_they_are(f: &Fixture) {
    let edited = f.variant("edited.toml", |t| {
        t.replacen("warmup_tau_s = ", "warmup_tau_s = 1", 1)
    });
    let (o, run) = f.run("RL16-0042", &edited, "edited", &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("warning: "), "{}", stderr(&o));
    assert_eq!(recorded_as(&run), (None, "edited".into(), Some(1)));
    let replay = f.dir.join("edited-replay");
    f.ok(&["replay", s(&run.join("run.mcap")), "--out", s(&replay)]);
    assert_eq!(recorded_as(&replay), (None, "edited".into(), Some(1)));
    let unknown = f.variant("unknown.toml", |t| {
        refitted(&t.replace("version = 1", "version = 999"))
    });
    let (o, run) = f.run("RL16-0042", &unknown, "unknown", &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(recorded_as(&run), (None, "unregistered".into(), Some(999)));
    let h = f.ok(&["results", "unit", "RL16-0042", "--json"]);
    let h: serde_json::Value = serde_json::from_slice(&h.stdout).expect("JSON");
    let stored: Vec<(String, Option<i64>, Option<i64>)> = h["runs"]
        .as_array()
        .expect("runs")
        .iter()
        .map(|r| &r["coefficients"])
        .filter(|c| c["source"] == "file")
        .map(|c| {
            let status = c["identity"].as_str().unwrap_or("none").to_owned();
            (status, c["version"].as_i64(), c["claimed_version"].as_i64())
        })
        .collect();
    assert_eq!(
        stored,
        [
            ("registered".into(), Some(1), Some(1)),
            ("edited".into(), None, Some(1)),
            ("unregistered".into(), None, Some(999)),
        ]
    );
}

/// No store to ask, or one that cannot be reached: the run goes on, and
/// its record says the set could not be checked, and why.
fn without_a_store_the_set_is_recorded_as_not_checked(f: &Fixture) {
    let (o, run) = f.run("RL16-0042", &f.set, "no-store", &["--db", "none"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(recorded_as(&run), (None, "unchecked".into(), Some(1)));
    let broken = write(&f.dir, "broken.sqlite", &"not a database ".repeat(400));
    let (o, run) = f.run("RL16-0042", &f.set, "unreachable", &["--db", s(&broken)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("could not be checked"),
        "{}",
        stderr(&o)
    );
    assert_eq!(recorded_as(&run), (None, "unchecked".into(), Some(1)));
    let note = json(&run.join("report.json"))["coefficients"]["identity"]["note"].clone();
    assert!(
        note.as_str().is_some_and(|n| n.contains("not a database")),
        "{note}"
    );
}
