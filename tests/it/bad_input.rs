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

/// `args` run to their end within `deadline_s`, or the test fails (and
/// the process is killed): a reader that waits on a FIFO or reads a
/// device to its end would hang the test rather than fail it.
fn ends_within(args: &[&str], deadline_s: u64) -> std::process::Output {
    let mut child = crate::cli::command()
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("gyrobench starts");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(deadline_s);
    while child.try_wait().expect("wait").is_none() {
        if std::time::Instant::now() > deadline {
            let _killed = child.kill();
            panic!(
                "{args:?} still runs after {deadline_s} s: it waits on or reads what is not a file"
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.wait_with_output().expect("output")
}

fn mkfifo(path: &Path) {
    let made = std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .expect("mkfifo runs");
    assert!(made.success(), "mkfifo {}", path.display());
}

/// Every configuration reader, and `import`'s data file, refuses a device
/// or a FIFO by name at once: `check /dev/zero` read 6-8 GB in 8 s, and a
/// FIFO blocked for ever.
#[test]
fn a_device_or_a_fifo_is_refused_at_once_by_every_reader() {
    let dir = temp_dir("bad-input-not-a-file");
    let fifo = dir.join("stream.toml");
    mkfifo(&fifo);
    let (fifo_csv, fifo_log) = (dir.join("stream.csv"), dir.join("stream.mcap"));
    mkfifo(&fifo_csv);
    mkfifo(&fifo_log);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let smoke = root.join("procedures/smoke.toml");
    let fixtures = root.join("fixtures/import");
    let (lab, site, map) = (
        fixtures.join("lab-run.csv"),
        fixtures.join("site.toml"),
        fixtures.join("iso-dps-kelvin.map.toml"),
    );
    let out = dir.join("out.mcap");
    let s = |p: &Path| p.to_str().expect("utf-8").to_owned();
    let (fifo_s, smoke_s, out_s) = (s(&fifo), s(&smoke), s(&out));
    let (csv_s, log_s) = (s(&fifo_csv), s(&fifo_log));
    let (lab_s, site_s, map_s) = (s(&lab), s(&site), s(&map));
    let cases: Vec<(Vec<&str>, &str, &str)> = vec![
        (
            vec!["check", "/dev/zero"],
            "/dev/zero",
            "a character device",
        ),
        (vec!["check", &fifo_s], &fifo_s, "a FIFO (named pipe)"),
        (
            vec!["check", &smoke_s, "--bench", &fifo_s],
            &fifo_s,
            "a FIFO",
        ),
        (
            vec!["twin", "study", "--config", "/dev/zero"],
            "/dev/zero",
            "a character device",
        ),
        (vec!["sim", "serve", "--config", &fifo_s], &fifo_s, "a FIFO"),
        (
            vec!["run", &smoke_s, "--coeffs", &fifo_s, "--out", &out_s],
            &fifo_s,
            "a FIFO",
        ),
        (
            vec!["import", &fifo_s, "--site", &site_s, "-o", &out_s],
            &fifo_s,
            "a FIFO",
        ),
        (
            vec!["import", "/dev/zero", "--site", &site_s, "-o", &out_s],
            "/dev/zero",
            "a character device",
        ),
        (
            vec!["import", &lab_s, "--site", &fifo_s, "-o", &out_s],
            &fifo_s,
            "a FIFO",
        ),
        (
            vec![
                "import", &lab_s, "--map", &fifo_s, "--site", &site_s, "-o", &out_s,
            ],
            &fifo_s,
            "a FIFO",
        ),
        (
            vec![
                "import", &fifo_s, "--map", &map_s, "--site", &site_s, "-o", &out_s,
            ],
            &fifo_s,
            "a FIFO",
        ),
        (vec!["allan", &csv_s], &csv_s, "a FIFO"),
        // A log read by the log crate's reader: said as not a log.
        (vec!["replay", &log_s, "--out", &out_s], &log_s, ""),
    ];
    for (args, file, kind) in cases {
        let o = ends_within(&args, 60);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.contains(file) && err.contains(kind) && err.contains("not a regular file"),
            "{args:?}: {err}"
        );
        assert!(!out.exists(), "{args:?}: nothing written");
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A data file is read a line at a time, each at most 1 MiB: a file
/// without line ends (a disk image, zeros) is refused at its first line,
/// not held whole.
#[test]
fn an_import_line_longer_than_its_limit_is_refused_with_its_line() {
    let dir = temp_dir("bad-input-long-line");
    let csv = dir.join("lab.csv");
    let mut text = String::from(
        "time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n",
    );
    text.push_str(&"9".repeat((1 << 20) + 1));
    std::fs::write(&csv, text).expect("csv");
    let site = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/import/site.toml");
    let out = dir.join("out.mcap");
    let o = gyrobench(&[
        "import",
        csv.to_str().expect("utf-8"),
        "--site",
        site.to_str().expect("utf-8"),
        "-o",
        out.to_str().expect("utf-8"),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("lab.csv:2: the line is longer than 1048576 bytes"),
        "{err}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A FIFO among the station's procedures is offered as a problem, named;
/// the list, a start and SIGTERM are not held by it (they were, for ever).
#[test]
fn a_fifo_among_the_stations_procedures_is_listed_as_a_problem_not_waited_on() {
    use std::io::BufRead;
    let dir = temp_dir("bad-input-station-fifo");
    let procs = dir.join("procedures");
    std::fs::create_dir_all(&procs).expect("procedures");
    let smoke = Path::new(env!("CARGO_MANIFEST_DIR")).join("procedures/smoke.toml");
    std::fs::copy(&smoke, procs.join("smoke.toml")).expect("smoke");
    mkfifo(&procs.join("stream.toml"));
    let p = |x: &Path| x.to_str().expect("utf-8").to_owned();
    let mut child = crate::cli::command()
        .args([
            "station",
            "--listen",
            "127.0.0.1:0",
            "--live",
            "127.0.0.1:0",
            "--procedures",
            &p(&procs),
            "--runs",
            &p(&dir.join("runs")),
            "--db",
            &p(&dir.join("results.sqlite")),
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("station starts");
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().expect("stdout"))
        .read_line(&mut line)
        .expect("the URL");
    let url = line
        .trim()
        .strip_prefix("station ")
        .expect("URL")
        .to_owned();
    let (base, token) = url.split_once("/?token=").expect("token");
    let (host, token) = (
        base.trim_start_matches("http://").to_owned(),
        token.to_owned(),
    );
    // The list, within a deadline: the request runs on a thread of its own.
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _gone = tx.send(crate::http::request(
            &host,
            Some(&token),
            "GET",
            "/api/procedures",
            "",
        ));
    });
    let listed = rx.recv_timeout(std::time::Duration::from_secs(60));
    let pid = child.id().to_string();
    let _sent = std::process::Command::new("kill")
        .args(["-TERM", &pid])
        .status();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let stopped = loop {
        if let Some(status) = child.try_wait().expect("station") {
            break Some(status);
        }
        if std::time::Instant::now() > deadline {
            let _killed = child.kill();
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let (code, body) = listed
        .expect("the procedure list within 60 s")
        .expect("an HTTP response");
    assert_eq!(code, 200, "{body}");
    let offers: serde_json::Value = serde_json::from_str(&body).expect("JSON");
    let offers = offers.as_array().expect("a list");
    let fifo = offers
        .iter()
        .find(|o| o["file"] == "stream.toml")
        .unwrap_or_else(|| panic!("the FIFO offered with its problem: {offers:?}"));
    assert!(
        fifo["problem"]
            .as_str()
            .is_some_and(|p| p.contains("a FIFO (named pipe), not a regular file")),
        "{fifo}"
    );
    assert!(
        offers
            .iter()
            .any(|o| o["file"] == "smoke.toml" && o["problem"].is_null()),
        "{offers:?}"
    );
    assert_eq!(
        stopped.map(|s| s.code()),
        Some(Some(0)),
        "SIGTERM ends the station"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
