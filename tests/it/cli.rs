//! The process boundary: spawn the binary, check exit codes, stdout and stderr.

use std::process::{Command, Output};

/// The binary, with its results store and its own files in this test
/// process's temporary directory (never the user's).
pub fn command() -> Command {
    let home = std::env::temp_dir().join(format!("gyrobench-test-home-{}", std::process::id()));
    let mut c = Command::new(env!("CARGO_BIN_EXE_gyrobench"));
    // Bench locks of this test binary's runs, apart from a real bench's.
    c.env("XDG_DATA_HOME", &home)
        .env("GYROBENCH_DB", home.join("results.sqlite"))
        .env("GYROBENCH_LOCK_DIR", home.join("locks"));
    c
}

pub fn gyrobench(args: &[&str]) -> Output {
    command()
        .args(args)
        .output()
        .expect("the gyrobench binary runs")
}

/// `gyrobench ARGS`, which must exit 0 (its stderr shown when it does not).
pub fn gyrobench_ok(args: &[&str]) -> Output {
    let r = gyrobench(args);
    assert_eq!(
        r.status.code(),
        Some(0),
        "gyrobench {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&r.stderr)
    );
    r
}

pub fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("gyrobench-test-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

#[test]
fn twin_study_reproduces_the_study_figures() {
    let out = gyrobench(&["twin", "study", "--json", "--seed", "1"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    let num = |p: &str| j.pointer(p).and_then(serde_json::Value::as_f64).expect(p);
    let self_heating = num("/self_heating_dph").abs();
    let raw = num("/thermal/raw_drift_pp_dph");
    let comp = num("/thermal/compensated_drift_pp_dph");
    assert!(
        (0.4..=0.6).contains(&self_heating),
        "self-heating {self_heating}"
    );
    assert!((0.6..=0.7).contains(&raw), "raw drift {raw}");
    assert!(comp <= 0.05, "compensated drift {comp}");
    assert!(
        comp < raw / 10.0,
        "model 4 must cut the drift by more than 10x"
    );
}

#[test]
fn twin_study_writes_the_interchange_csv() {
    let dir = temp_dir("csv");
    let csv = dir.join("cycle.csv");
    let out = gyrobench(&["twin", "study", "--csv", csv.to_str().expect("utf-8 path")]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&csv).expect("csv written");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step")
    );
    // 6.5 h at 1 Hz.
    assert_eq!(lines.clone().count(), 23_400);
    let hot = lines
        .filter(|l| l.ends_with(",soak_hot"))
        .filter_map(|l| l.split(',').nth(5)?.parse::<f64>().ok())
        .fold(f64::NEG_INFINITY, f64::max);
    assert!((hot - 50.0).abs() < 0.1, "chamber reaches +50 degC: {hot}");

    // allan takes the CSV: one step's rows, the --json contract.
    let out = gyrobench(&[
        "allan",
        csv.to_str().expect("utf-8 path"),
        "--record",
        "soak_hot",
        "--taus",
        "dense",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let arr = |k: &str| -> Vec<f64> {
        j[k].as_array()
            .unwrap_or_else(|| panic!("{k} is an array"))
            .iter()
            .map(|v| v.as_f64().expect("number"))
            .collect()
    };
    let (tau, adev, lo, hi) = (arr("tau_s"), arr("adev_dph"), arr("lo_dph"), arr("hi_dph"));
    assert!(tau.len() >= 20, "dense taus: {}", tau.len());
    assert_eq!(j["tau0_s"], 1.0);
    for i in 0..tau.len() {
        assert!(
            lo[i] < adev[i] && adev[i] < hi[i],
            "tau {}: {} {} {}",
            tau[i],
            lo[i],
            adev[i],
            hi[i]
        );
    }
    assert!(tau.windows(2).all(|w| w[0] < w[1]));
    // Each term is a number, or null with the reason it is not resolved.
    for k in [
        "quantization_arcsec",
        "arw_deg_per_rt_h",
        "bias_instability_dph",
        "rate_random_walk_dph_per_rt_h",
    ] {
        let why = j["noise"]["not_resolved"][k]["reason"].as_str();
        match j["noise"][k].as_f64() {
            Some(v) => assert!(v > 0.0 && why.is_none(), "noise.{k}: {}", j["noise"]),
            None => assert!(
                j["noise"][k].is_null() && why.is_some_and(|w| !w.is_empty()),
                "noise.{k}: {}",
                j["noise"]
            ),
        }
    }
    // An hour at +50 degC at 1 Hz shows no flicker floor: B is not resolved,
    // and says so instead of printing zero.
    assert!(
        j["noise"]["bias_instability_dph"].is_null(),
        "{}",
        j["noise"]
    );
    assert!(j["bias_instability"]["ieee_b_dph"].is_null());
    let table = gyrobench(&[
        "allan",
        csv.to_str().expect("utf-8 path"),
        "--record",
        "soak_hot",
    ]);
    let table = String::from_utf8_lossy(&table.stdout);
    assert!(
        table.contains("bias instability  not resolved ("),
        "{table}"
    );
    assert!(!table.contains(" 0.00000 deg/h"), "{table}");
    // A bad row is refused with its line.
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, text.replacen(",soak_hot", ",soak_hot,extra", 1)).expect("bad csv");
    let out = gyrobench(&["allan", bad.to_str().expect("utf-8 path")]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.csv:") && err.contains("unreadable row"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn bad_twin_file_is_refused_with_file_line_and_key() {
    let dir = temp_dir("bad-twin");
    let path = dir.join("bad.toml");
    let default = gyrobench(&["twin", "default-config"]);
    let text = String::from_utf8(default.stdout).expect("utf-8");
    let bad = text.replacen("case_tau_s = 1200.0", "case_tau_s = -3.0", 1);
    assert_ne!(bad, text, "fixture must contain the line the test edits");
    std::fs::write(&path, bad).expect("write");
    let out = gyrobench(&[
        "twin",
        "study",
        "--config",
        path.to_str().expect("utf-8 path"),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    let line = text
        .lines()
        .position(|l| l.starts_with("case_tau_s"))
        .expect("line")
        + 1;
    assert!(err.contains(&format!("bad.toml:{line}:")), "{err}");
    assert!(err.contains("`thermal.case_tau_s` must be"), "{err}");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn missing_file_and_bad_usage_have_their_exit_codes() {
    let out = gyrobench(&["twin", "study", "--config", "/nonexistent/twin.toml"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot read /nonexistent/twin.toml"));
    let out = gyrobench(&["twin", "no-such-command"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn sim_serve_prints_its_endpoints_serves_and_exits_0_on_sigterm() {
    use std::io::{BufRead, BufReader, Read, Write};
    let mut child = command()
        .args(["sim", "serve"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("sim serve starts");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout"));
    let mut endpoints = Vec::new();
    for _ in 0..9 {
        let mut l = String::new();
        lines.read_line(&mut l).expect("endpoint line");
        endpoints.push(l.trim_end().to_owned());
    }
    for e in &endpoints {
        let f: Vec<&str> = e.split(' ').collect();
        assert_eq!(f.len(), 3, "`<device> <protocol> <address>`: {e}");
        assert!(
            f[2].starts_with("tcp://127.0.0.1:") || f[2].starts_with("pty:///dev/"),
            "loopback or pty only: {e}"
        );
    }
    for want in [
        "chamber espec-ascii tcp://",
        "chamber watlow-f4t-modbus tcp://",
        "table acl tcp://",
        "gyro rlg-frame pty://",
        "supply keysight-e36300 tcp://",
        "supply keysight-e36300 pty://",
    ] {
        assert!(
            endpoints.iter().any(|e| e.starts_with(want)),
            "{want} missing: {endpoints:?}"
        );
    }
    let espec = endpoints
        .iter()
        .find_map(|e| e.strip_prefix("chamber espec-ascii tcp://"))
        .expect("espec endpoint");
    let mut s = std::net::TcpStream::connect(espec).expect("connect");
    s.write_all(b"TEMP?\r\n").expect("send");
    let mut reply = [0u8; 64];
    let n = s.read(&mut reply).expect("reply");
    assert_eq!(&reply[..n], b"20.0,20.0,100.0,-60.0\r\n");

    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let exit = child.wait().expect("sim serve ends");
    assert_eq!(
        exit.code(),
        Some(0),
        "SIGTERM must end sim serve with exit 0"
    );
}

/// Every command's path in the tree (`["results", "show"]`, ...), the
/// top level first, as each command's `--help` lists its subcommands
/// under `Commands:`; clap's own `help` subcommands left out.
fn command_paths(path: Vec<String>, out: &mut Vec<Vec<String>>) {
    out.push(path.clone());
    let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
    args.push("--help");
    let out_ = gyrobench(&args);
    let help = String::from_utf8_lossy(&out_.stdout).into_owned();
    let subs: Vec<String> = help
        .lines()
        .skip_while(|l| *l != "Commands:")
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        // A subcommand's line starts two spaces in; its help's
        // continuation lines further.
        .filter(|l| l.starts_with("  ") && !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|name| *name != "help")
        .map(str::to_owned)
        .collect();
    for sub in subs {
        let mut p = path.clone();
        p.push(sub);
        command_paths(p, out);
    }
}

#[test]
fn every_command_help_has_an_example_of_itself_and_the_exit_codes() {
    let mut paths = Vec::new();
    command_paths(Vec::new(), &mut paths);
    assert!(paths.len() > 20, "{paths:?}");
    for path in paths {
        let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
        args.push("--help");
        let out = gyrobench(&args);
        assert_eq!(out.status.code(), Some(0), "{args:?}");
        let help = String::from_utf8_lossy(&out.stdout);
        let example = format!("Example:\n  gyrobench {}", path.join(" "));
        assert!(
            help.contains(example.trim_end()),
            "{args:?}: no example of the command itself: {help}"
        );
        assert!(
            help.contains("\nExit codes: 0 ") && help.contains(" 2 usage"),
            "{args:?}: no exit codes: {help}"
        );
    }
}

/// A reader that goes away (`sim serve | head -1`) does not stop the
/// server, and SIGTERM right after it says it serves still ends it with 0
/// (the handler is in place before the endpoints are printed).
#[test]
fn sim_serve_outlives_a_closed_stdout_and_stops_cleanly_at_once() {
    use std::io::{BufRead, BufReader};
    let mut child = command()
        .args(["sim", "serve"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("sim serve starts");
    drop(child.stdout.take());
    let mut said = String::new();
    BufReader::new(child.stderr.take().expect("stderr"))
        .read_line(&mut said)
        .expect("stderr");
    assert!(said.starts_with("serving the simulated bench"), "{said}");
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    assert_eq!(child.wait().expect("sim serve ends").code(), Some(0));
}
