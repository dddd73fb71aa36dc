//! The bad-input corpus (`fixtures/bad/expected.toml`): every file is
//! refused by every command that reads it, with its expected error at its
//! line, and a refused input never starts a run (no run directory, so no
//! device command) nor leaves an output.

use std::path::Path;

use crate::cli::{gyrobench, temp_dir};

#[derive(Debug, serde::Deserialize)]
struct Corpus {
    case: Vec<Case>,
}

#[derive(Debug, serde::Deserialize)]
struct Case {
    file: String,
    kind: String,
    error: String,
    line: Option<usize>,
    /// A damaged log whose whole parts are still read: a command may
    /// leave what it made of them (a recovered log, a report that says
    /// the log is damaged), but it still exits 1 with the error.
    #[serde(default)]
    partial: bool,
}

#[test]
fn every_bad_file_is_refused_with_its_error_and_line() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let bad = root.join("fixtures/bad");
    let corpus: Corpus =
        toml::from_str(&std::fs::read_to_string(bad.join("expected.toml")).expect("corpus index"))
            .expect("valid index");
    let listed: Vec<&str> = corpus.case.iter().map(|c| c.file.as_str()).collect();
    for entry in std::fs::read_dir(&bad).expect("corpus dir") {
        let name = entry
            .expect("entry")
            .file_name()
            .into_string()
            .expect("utf-8 name");
        assert!(
            name == "expected.toml" || listed.contains(&name.as_str()),
            "{name} has no expected error"
        );
    }
    let smoke = root.join("procedures/smoke.toml");
    let smoke = smoke.to_str().expect("utf-8");
    let dir = temp_dir("bad-input");
    let good_site = dir.join("site.toml");
    std::fs::write(
        &good_site,
        "[site]\nlatitude_deg = 50.45\nlongitude_deg = 30.52\nheight_m = 180.0\nmagnetic_field_ned_ut = [19.5, 2.7, 46.5]\n",
    )
    .expect("site");
    let good_site = good_site.to_str().expect("utf-8");

    for c in &corpus.case {
        let path = bad.join(&c.file);
        let file = path.to_str().expect("utf-8");
        let out_dir = dir.join(&c.file);
        let out = out_dir.to_str().expect("utf-8");
        let runs: Vec<Vec<&str>> = match c.kind.as_str() {
            "procedure" => vec![vec!["check", file], vec!["run", file, "--out", out]],
            "twin" => vec![
                vec!["twin", "study", "--config", file],
                vec!["run", smoke, "--twin", file, "--out", out],
            ],
            "bench" => vec![
                vec!["check", smoke, "--bench", file],
                vec!["run", smoke, "--bench", file, "--out", out],
            ],
            "serve" => vec![vec!["sim", "serve", "--config", file]],
            "csv" => vec![
                vec!["import", file, "--site", good_site, "-o", out],
                vec!["allan", file],
            ],
            "site" => vec![vec![
                "import",
                "tests/it/does-not-matter.csv",
                "--site",
                file,
                "-o",
                out,
            ]],
            "log" => vec![
                vec!["recover", file, "-o", out],
                vec!["replay", file, "--out", out],
                vec!["export", file, "-o", out],
                vec!["allan", file],
            ],
            k => panic!("unknown kind {k}"),
        };
        for args in runs {
            let o = gyrobench(&args);
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(1), "{} {args:?}: {err}", c.file);
            assert!(
                err.contains(&c.error),
                "{}: expected {:?} in {err}",
                c.file,
                c.error
            );
            let at = match c.line {
                Some(l) => format!("{}:{l}:", c.file),
                None => format!("{}:", c.file),
            };
            assert!(
                err.contains(&at),
                "{}: expected the place {at} in {err}",
                c.file
            );
            assert!(
                c.partial || !out_dir.exists(),
                "{}: a refused input must not start a run or leave an output",
                c.file
            );
            if out_dir.is_dir() {
                std::fs::remove_dir_all(&out_dir).expect("clear the partial output");
            } else if out_dir.exists() {
                std::fs::remove_file(&out_dir).expect("clear the partial output");
            }
        }
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
