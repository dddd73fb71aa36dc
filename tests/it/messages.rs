//! What the operator reads when something is wrong: each cause said once,
//! naming the file, the device or the port to look at; usage errors exit 2.

use crate::cli::{command, gyrobench, temp_dir};
use crate::common::{s, stderr, write};

/// How often `needle` occurs in `hay`.
fn count(hay: &str, needle: &str) -> usize {
    hay.matches(needle).count()
}

#[test]
fn a_missing_file_is_named_once_with_the_os_error_once() {
    let dir = temp_dir("missing-files");
    let proc = write(&dir, "tiny.toml", crate::common::TINY);
    let out = gyrobench(&[
        "run",
        s(&proc),
        "--out",
        s(&dir.join("run")),
        "--db",
        "none",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let run_log = dir.join("run").join("run.mcap");
    let ml = s(&run_log);
    let site = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/site.toml");
    let cases: Vec<Vec<&str>> = vec![
        vec!["run", "missing-procedure.toml"],
        vec!["check", "missing-procedure.toml"],
        vec!["check", s(&proc), "--bench", "missing-bench.toml"],
        vec!["run", s(&proc), "--coeffs", "missing-coeffs.toml"],
        vec!["run", s(&proc), "--twin", "missing-twin.toml"],
        vec![
            "import",
            "x.csv",
            "--site",
            "missing-site.toml",
            "-o",
            "x.mcap",
        ],
        vec!["import", "missing-run.csv", "--site", site, "-o", "x.mcap"],
        vec!["replay", "missing-log.mcap"],
        vec!["replay", ml, "--coeffs", "missing-coeffs.toml"],
        vec!["recover", "missing-log.mcap"],
        vec!["export", "missing-log.mcap", "-o", "x.csv"],
        vec!["calibrate", "missing-log.mcap", "-o", "u.toml"],
        vec!["diagnose", "missing-log.mcap", "--out", "d"],
        vec!["diagnose", ml, "--twin", "missing-twin.toml", "--out", "d"],
        vec!["allan", "missing-run.csv"],
        vec!["allan", "missing-log.mcap"],
        vec!["sim", "serve", "--config", "missing-serve.toml"],
        vec!["twin", "study", "--config", "missing-twin.toml"],
        vec!["export", ml, "-o", "missing-dir/x.csv"],
    ];
    for args in cases {
        // In the temporary directory: nothing lands in the repository.
        let out = command()
            .current_dir(&dir)
            .args(&args)
            .output()
            .expect("gyrobench runs");
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        let missing = args
            .iter()
            .find_map(|a| a.strip_prefix("missing-").map(|_| *a))
            .expect("a missing file in the case");
        assert_eq!(
            count(&err, "(os error 2)"),
            1,
            "{args:?}: the OS error once: {err}"
        );
        assert_eq!(
            count(&err, missing),
            1,
            "{args:?}: {missing} named once: {err}"
        );
        assert!(!err.contains(".partial"), "{args:?}: {err}");
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// A loopback port nothing listens on (bound, then let go).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

#[test]
fn a_device_that_refuses_names_the_bench_file_and_its_spec() {
    let dir = temp_dir("refused-device");
    let port = free_port();
    let bench = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/fixtures/bench/sim-serve.toml"
    ))
    .expect("fixture")
    .replace("tcp://127.0.0.1:5001", &format!("tcp://127.0.0.1:{port}"));
    let bench = write(&dir, "lab-bench.toml", &bench);
    let proc = write(&dir, "tiny.toml", crate::common::TINY);
    let out = gyrobench(&[
        "run",
        s(&proc),
        "--bench",
        s(&bench),
        "--dut",
        "RL16-0042",
        "--out",
        s(&dir.join("run")),
        "--db",
        "none",
    ]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(count(&err, s(&bench)), 1, "the bench file, once: {err}");
    assert!(
        err.contains(&format!("chamber: cannot open tcp://127.0.0.1:{port}: ")),
        "the device and its spec: {err}"
    );
    assert!(err.contains("devices.chamber.spec"), "{err}");
    assert_eq!(count(&err, "(os error 111)"), 1, "refused, once: {err}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn sim_serve_names_the_port_it_cannot_take() {
    let dir = temp_dir("port-taken");
    let holder = std::net::TcpListener::bind("127.0.0.1:0").expect("a port");
    let port = holder.local_addr().expect("address").port();
    let config = write(
        &dir,
        "serve.toml",
        &format!("ptys = false\n\n[ports]\nacl = {port}\n"),
    );
    let out = gyrobench(&["sim", "serve", "--config", s(&config)]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!("table acl: cannot listen on 127.0.0.1:{port}: ")),
        "the endpoint and its address: {err}"
    );
    assert!(err.contains("`ports.acl`"), "the key to change: {err}");
    assert!(err.contains(s(&config)), "the configuration: {err}");
    assert_eq!(count(&err, "(os error 98)"), 1, "{err}");
    drop(holder);
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

/// Bad flag values, missing required options and options that do not go
/// together exit 2, whichever command finds them (clap or the command).
#[test]
fn usage_errors_exit_2_everywhere() {
    let dir = temp_dir("usage-errors");
    let proc = write(&dir, "tiny.toml", crate::common::TINY);
    let p = s(&proc);
    let bench = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/bench/sim-serve.toml");
    let site = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/site.toml");
    let csv = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/import/lab-run.csv");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["diagnose", "some.mcap"], "--out DIR is required"),
        (vec!["diagnose", "--out", "d"], "give one or more run logs"),
        (vec!["run", p, "--speed", "fast"], "--speed \"fast\""),
        (
            vec!["run", p, "--inject", "bogus"],
            "expected FAULT@SECONDS",
        ),
        (vec!["run", p, "--inject", "no-such-fault@10"], "--inject"),
        (
            vec!["run", p, "--inject", "gyro-silent@soon"],
            "seconds of device time",
        ),
        (
            vec!["run", p, "--bench", bench, "--inject", "gyro-silent@10"],
            "embedded",
        ),
        (vec!["run", p, "--bench", bench, "--twin", site], "embedded"),
        (vec!["run", p, "--force"], "--force applies with --out"),
        (
            vec!["run", p, "--live", "0.0.0.0:8765"],
            "listens on loopback only",
        ),
        (
            vec!["station", "--live", "192.168.1.2:8765"],
            "listens on loopback only",
        ),
        (vec!["run"], "PROCEDURE"),
        (vec!["run", p, "--resume", "runs/x"], "cannot be used with"),
        (
            vec!["diagnose", "selfcheck", "--out", "x", "--runs", "0"],
            "--runs",
        ),
        (
            vec!["diagnose", "selfcheck", "--out", "x", "--effects", "bogus"],
            "not a library effect",
        ),
        (vec!["diagnose", "selfcheck"], "--out"),
        (vec!["twin", "bench", "--hours", "0"], "--hours"),
        (vec!["sim", "link-bench", "--seconds", "0"], "--seconds"),
        (
            vec!["sim", "serve", "--inject", "process-kill@10"],
            "a fault of the controller",
        ),
        (
            vec!["sim", "serve", "--inject", "unit-lost@10"],
            "two slots or more",
        ),
        (
            vec!["sim", "serve", "--inject", "chamber-alarm"],
            "FAULT@SECONDS",
        ),
        (vec!["allan", "x.csv", "--taus", "sparse"], "--taus"),
        (vec!["import", csv, "--site", site], "--out"),
        (
            vec!["import", csv, "--site", site, "-o", csv],
            "would destroy the input",
        ),
        (vec!["results", "list", "--outcome", "maybe"], "--outcome"),
        (vec!["results", "list", "--since", "yesterday"], "--since"),
        (vec!["results", "export"], "--junit"),
        (vec!["replay", "x.mcap", "--db", "x.sqlite"], "--store"),
        (vec!["no-such-command"], "unrecognized subcommand"),
    ];
    for (args, says) in cases {
        let out = command()
            .current_dir(&dir)
            .args(&args)
            .output()
            .expect("gyrobench runs");
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: expected {says:?} in {err}");
    }
    // Nothing was started: no run directory, no output.
    assert!(!dir.join("runs").exists());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
