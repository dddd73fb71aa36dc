//! Batch runs: several units on one table in one chamber, one procedure,
//! a verdict and a report per unit. Each test runs the binary as an
//! operator would, on the embedded bench with slots.

use std::path::Path;

use crate::cli::{command, temp_dir};
use crate::common::{MINI, TINY, json, s, stderr, write};

/// The embedded bench's site, table, devices and limits (no supply: a
/// bench with slots powers its units by hand), then `tail`.
fn bench(dir: &Path, name: &str, mount: Option<&str>, tail: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/embedded.toml"),
    )
    .expect("the embedded bench file");
    let mut out = String::new();
    let mut skip = false;
    for line in text.lines() {
        if line.starts_with('[') {
            skip = line.starts_with("[devices.supply]");
        }
        if let (Some(m), true) = (mount, line.starts_with("mount = ")) {
            out.push_str(&format!("mount = {m}\n"));
            continue;
        }
        if !skip {
            out.push_str(line);
            out.push('\n');
        }
    }
    out.push_str(tail);
    write(dir, name, &out)
}

fn run(args: &[&str]) -> std::process::Output {
    command()
        .args(["run", "--db", "none"])
        .args(args)
        .output()
        .expect("the gyrobench binary runs")
}

/// name -> value of every measurement of a report.
fn figures(report: &Path) -> Vec<(String, f64)> {
    json(report)["measurements"]
        .as_array()
        .expect("measurements")
        .iter()
        .map(|m| {
            (
                m["name"].as_str().expect("name").to_owned(),
                m["value"].as_f64().expect("value"),
            )
        })
        .collect()
}

/// The RL-16 twin g-sensitive along its axis: 8 deg/h with the axis up or
/// down, past the +-5 deg/h bias limit.
fn g_sensitive_twin() -> String {
    let twin = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/twin/rl16.toml"),
    )
    .expect("the twin file")
    .replace(
        "[effects.g_sensitivity]\nenabled = false\ncoeff_dph_per_g = [0.0, 0.03, 0.02]",
        "[effects.g_sensitivity]\nenabled = true\ncoeff_dph_per_g = [8.0, 0.0, 0.0]",
    );
    assert!(twin.contains("coeff_dph_per_g = [8.0"));
    twin
}

const Y_MOUNT: &str = "{ azimuth_deg = 0.0, elevation_deg = 0.0, roll_deg = 0.0 }";

#[test]
fn a_unit_of_a_batch_gives_the_figures_of_the_same_unit_run_alone() {
    let dir = temp_dir("batch-same");
    let p = write(&dir, "mini.toml", MINI);
    // Slot B: its own seed and a mount turned a quarter turn from A's.
    let quad = bench(
        &dir,
        "pair.toml",
        None,
        &format!(
            "\n[[slots]]\nname = \"A\"\n\n[[slots]]\nname = \"B\"\nseed = 7\nmount = {Y_MOUNT}\n"
        ),
    );
    let o = run(&[
        s(&p),
        "--bench",
        s(&quad),
        "--dut",
        "B=RL16-0902",
        "--dut",
        "A=RL16-0901",
        "--out",
        s(&dir.join("batch")),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    for line in ["slot A", "slot B", "RL16-0901", "RL16-0902"] {
        assert!(out.contains(line), "{line} in\n{out}");
    }
    // The same unit alone: a bench whose only unit sits on B's mount.
    let alone = bench(&dir, "alone.toml", Some(Y_MOUNT), "");
    let o = run(&[
        s(&p),
        "--bench",
        s(&alone),
        "--dut",
        "RL16-0902",
        "--seed",
        "7",
        "--out",
        s(&dir.join("alone")),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let batch = figures(&dir.join("batch/report-RL16-0902.json"));
    let single = figures(&dir.join("alone/report.json"));
    assert!(!batch.is_empty());
    assert_eq!(batch, single, "unit B of the batch against B alone");
    // And unit A is another unit: its own noise, its own figures.
    let a = figures(&dir.join("batch/report-RL16-0901.json"));
    assert_ne!(a, batch);
    let report = json(&dir.join("batch/report-RL16-0902.json"));
    assert_eq!(report["dut"]["serial"], "RL16-0902");
    assert_eq!(report["slot"], "B");
}

#[test]
fn a_batch_in_which_one_unit_carries_an_effect_fails_that_unit_alone() {
    let dir = temp_dir("batch-effect");
    let p = write(&dir, "mini.toml", MINI);
    write(&dir, "g.toml", &g_sensitive_twin());
    let quad = bench(
        &dir,
        "quad.toml",
        None,
        "\n[[slots]]\nname = \"A\"\n\n[[slots]]\nname = \"B\"\n\n[[slots]]\nname = \"C\"\ntwin = \"g.toml\"\n\n[[slots]]\nname = \"D\"\n",
    );
    let mut args = vec![s(&p), "--bench", s(&quad)];
    let duts = ["A=U-1", "B=U-2", "C=U-3", "D=U-4"];
    for d in &duts {
        args.extend(["--dut", d]);
    }
    let out = dir.join("run");
    args.extend(["--out", s(&out)]);
    let o = run(&args);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    for (serial, want) in [
        ("U-1", "pass"),
        ("U-2", "pass"),
        ("U-3", "fail"),
        ("U-4", "pass"),
    ] {
        let r = json(&out.join(format!("report-{serial}.json")));
        assert_eq!(r["outcome"], want, "{serial}");
        let up = r["measurements"]
            .as_array()
            .expect("measurements")
            .iter()
            .find(|m| m["name"] == "bias_dph:up")
            .expect("bias_dph:up");
        let v = up["value"].as_f64().expect("value");
        if serial == "U-3" {
            assert!(v.abs() > 5.0, "{serial}: {v}");
        } else {
            assert!(v.abs() < 2.0, "{serial}: {v}");
        }
    }
    assert!(out.join("report-U-3.html").is_file());
    assert!(
        !out.join("report.json").exists(),
        "a batch's reports are per unit"
    );

    // Replay gives every unit's report byte for byte, --unit one of them.
    let log = out.join("run.mcap");
    let again = dir.join("replay");
    let o = command()
        .args(["replay", s(&log), "--out", s(&again)])
        .output()
        .expect("replay runs");
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    for serial in ["U-1", "U-2", "U-3", "U-4"] {
        for ext in ["json", "html"] {
            let name = format!("report-{serial}.{ext}");
            assert_eq!(
                std::fs::read(out.join(&name)).expect("run's report"),
                std::fs::read(again.join(&name)).expect("replay's report"),
                "{name}"
            );
        }
    }
    let one = dir.join("replay-one");
    let o = command()
        .args(["replay", s(&log), "--unit", "U-2", "--out", s(&one)])
        .output()
        .expect("replay runs");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(one.join("report-U-2.json").is_file());
    assert!(!one.join("report-U-3.json").exists());
    // The other tools read one unit with --unit; a unit the log lacks is
    // named with the ones it holds.
    let csv = dir.join("u3.csv");
    let o = command()
        .args(["export", s(&log), "--unit", "U-3", "-o", s(&csv)])
        .output()
        .expect("export runs");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let o = command()
        .args([
            "export",
            s(&log),
            "--unit",
            "U-9",
            "-o",
            s(&dir.join("u9.csv")),
        ])
        .output()
        .expect("export runs");
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("the log holds no unit U-9 (its units: U-1, U-2, U-3, U-4)"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_batch_is_recorded_in_the_store_unit_by_unit_and_verifies_against_its_log() {
    let dir = temp_dir("batch-store");
    let p = write(&dir, "mini.toml", MINI);
    let db = dir.join("results.sqlite");
    let quad = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/quad.toml");
    let out = dir.join("run");
    let o = command()
        .env("GYROBENCH_DB", &db)
        .args(["run", s(&p), "--bench", s(&quad), "--out", s(&out)])
        .args(["--dut", "A=S-1", "--dut", "B=S-2", "--dut", "D=S-4"])
        .output()
        .expect("run");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let results = |args: &[&str]| {
        command()
            .env("GYROBENCH_DB", &db)
            .arg("results")
            .args(args)
            .output()
            .expect("results")
    };
    for serial in ["S-1", "S-2", "S-4"] {
        let o = results(&["unit", serial, "--json"]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        // Its own figures: the report's, not another unit's.
        let report = json(&out.join(format!("report-{serial}.json")));
        let bias = report["measurements"]
            .as_array()
            .expect("measurements")
            .iter()
            .find(|m| m["name"] == "bias_dph:up")
            .expect("bias_dph:up")["value"]
            .as_f64()
            .expect("value");
        assert!(
            text.contains(&format!("{bias}")),
            "{serial}: {bias} in {text}"
        );
    }
    for args in [&["verify"][..], &["verify", "--replay"][..]] {
        let o = results(args);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
    }
    // The export gives each unit its own figures, once: as many rows as its
    // report has measurements, each value the report's.
    let csv_path = dir.join("export.csv");
    let o = results(&["export", "--csv", s(&csv_path)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let rows: Vec<csv::StringRecord> = csv::Reader::from_path(&csv_path)
        .expect("csv")
        .records()
        .collect::<Result<_, _>>()
        .expect("csv rows");
    for serial in ["S-1", "S-2", "S-4"] {
        let report = figures(&out.join(format!("report-{serial}.json")));
        let exported: Vec<(&str, f64)> = rows
            .iter()
            .filter(|r| &r[3] == serial)
            .map(|r| (&r[9], r[10].parse().unwrap_or(f64::NAN)))
            .collect();
        assert_eq!(exported.len(), report.len(), "{serial}: {exported:?}");
        for ((name, value), (want_name, want)) in exported.iter().zip(&report) {
            assert_eq!(name, want_name, "{serial}");
            assert!(
                (value - want).abs() <= 1e-9 * want.abs().max(1.0),
                "{serial} {name}: {value} != {want}"
            );
        }
    }
    // The trend page links each unit's own report, which the batch wrote.
    let page = dir.join("trend.html");
    let o = results(&["trend", "bias_dph:up", "--html", s(&page)]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let html = std::fs::read_to_string(&page).expect("page");
    let links: Vec<&str> = html
        .split("<a href=\"")
        .skip(1)
        .filter_map(|a| a.split('"').next())
        .filter(|h| h.ends_with(".html"))
        .collect();
    for serial in ["S-1", "S-2", "S-4"] {
        let want = format!("run/report-{serial}.html");
        assert!(links.contains(&want.as_str()), "{want} in {links:?}");
    }
    for h in &links {
        assert!(dir.join(h).is_file(), "{h} links no report");
    }
}

#[test]
fn a_batch_names_its_units_by_slot_and_refuses_what_does_not_fit() {
    let dir = temp_dir("batch-args");
    let p = write(&dir, "mini.toml", MINI);
    let quad = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/quad.toml");
    for (duts, says) in [
        (
            vec![],
            "this bench holds slots A, B, C, D: give --dut SLOT=SERIAL",
        ),
        (vec!["RL16-1"], "give SLOT=SERIAL"),
        (
            vec!["E=RL16-1"],
            "the bench has no slot \"E\" (its slots: A, B, C, D)",
        ),
        (vec!["A=RL16-1", "A=RL16-2"], "slot A is given twice"),
        (
            vec!["A=RL16-1", "B=RL16-1"],
            "unit RL16-1 is given for two slots",
        ),
    ] {
        let mut args = vec![s(&p), "--bench", s(&quad)];
        for d in &duts {
            args.extend(["--dut", d]);
        }
        let o = run(&args);
        assert_eq!(o.status.code(), Some(2), "{duts:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{duts:?}: {}", stderr(&o));
    }
    // A slot left empty is said, and the others run.
    let out = dir.join("two");
    let o = run(&[
        s(&p),
        "--bench",
        s(&quad),
        "--dut",
        "A=RL16-1",
        "--dut",
        "C=RL16-3",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).contains("slot B: empty"), "{}", stderr(&o));
    assert!(stderr(&o).contains("slot D: empty"), "{}", stderr(&o));
    assert!(out.join("report-RL16-1.json").is_file());
    assert!(out.join("report-RL16-3.json").is_file());
    // One unit's bench takes one --dut.
    let o = run(&[s(&p), "--dut", "X", "--dut", "Y"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("this bench holds one unit"));
}

#[test]
fn a_bench_file_checks_its_slots() {
    let dir = temp_dir("batch-bench");
    let p = write(&dir, "mini.toml", MINI);
    for (tail, says) in [
        (
            "\n[[slots]]\nname = \"A\"\n\n[[slots]]\nname = \"A\"\n",
            "slot \"A\" is declared twice",
        ),
        ("\n[[slots]]\nname = \"A B\"\n", "must be 1 to 16 letters"),
        (
            "\n[[slots]]\nname = \"A\"\nmount = { azimuth_deg = nan, elevation_deg = 0.0, roll_deg = 0.0 }\n",
            "slots.0.mount.azimuth_deg",
        ),
    ] {
        let b = bench(&dir, "bad.toml", None, tail);
        let o = run(&[s(&p), "--bench", s(&b), "--dut", "A=RL16-1"]);
        assert_eq!(o.status.code(), Some(1), "{tail}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{tail}: {}", stderr(&o));
        assert!(stderr(&o).contains("bad.toml:"), "{tail}: {}", stderr(&o));
    }
}

#[test]
fn a_unit_whose_link_is_lost_ends_in_error_and_the_others_are_judged() {
    let dir = temp_dir("batch-lost");
    let p = write(&dir, "mini.toml", MINI);
    let quad = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/quad.toml");
    let out = dir.join("run");
    // Unit C (the batch's last) sends nothing from 600 s on.
    let o = run(&[
        s(&p),
        "--bench",
        s(&quad),
        "--dut",
        "A=L-1",
        "--dut",
        "B=L-2",
        "--dut",
        "C=L-3",
        "--inject",
        "unit-lost@600",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    for serial in ["L-1", "L-2"] {
        let r = json(&out.join(format!("report-{serial}.json")));
        assert_eq!(r["outcome"], "pass", "{serial}: {r}");
    }
    let lost = json(&out.join("report-L-3.json"));
    assert_eq!(lost["outcome"], "error", "{lost}");
    let why = lost["error"]["message"].as_str().expect("a reason");
    assert!(why.contains("no gyro frame"), "{why}");
    // The shared bench was left as cleanup asked, for every unit.
    assert_eq!(lost["bench_left"]["verified"], true, "{lost}");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("L-3") && stdout.contains("ERROR"),
        "{stdout}"
    );
    // One unit's bench has no batch to lose a unit of.
    let o = run(&[s(&p), "--inject", "unit-lost@600"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

#[test]
fn a_triads_units_each_measure_and_describe_what_their_own_axis_saw() {
    let dir = temp_dir("batch-triad");
    let p = write(&dir, "mini.toml", MINI);
    let triad = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/triad.toml");
    let out = dir.join("run");
    let o = run(&[
        s(&p),
        "--bench",
        s(&triad),
        "--dut",
        "X=T-1",
        "--dut",
        "Y=T-2",
        "--dut",
        "Z=T-3",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // The platform "up" puts X's axis up and Y's and Z's horizontal (Y
    // north, Z west); "east" puts X's axis east, Y's north, Z's up.
    for (serial, up, east) in [
        ("T-1", "axis up", "axis horizontal toward azimuth 90"),
        (
            "T-2",
            "axis horizontal toward azimuth 0",
            "axis horizontal toward azimuth 0",
        ),
        ("T-3", "axis horizontal toward azimuth 270", "axis up"),
    ] {
        let r = json(&out.join(format!("report-{serial}.json")));
        let pose = |record: &str| {
            r["positions"]
                .as_array()
                .expect("positions")
                .iter()
                .find(|q| q["record"] == record)
                .and_then(|q| q["description"].as_str())
                .unwrap_or_default()
                .to_owned()
        };
        assert!(pose("up").starts_with(up), "{serial} up: {}", pose("up"));
        assert!(
            pose("east").starts_with(east),
            "{serial} east: {}",
            pose("east")
        );
        // Each unit's reference is its own axis's Earth rate: its bias is
        // the twin's (about 0.5 deg/h), not off by the difference between
        // the platform's axis and its own (several deg/h at 50 deg N).
        for m in r["measurements"].as_array().expect("measurements") {
            if m["name"]
                .as_str()
                .is_some_and(|n| n.starts_with("bias_dph:"))
            {
                let v = m["value"].as_f64().expect("value");
                assert!(v.abs() < 1.5, "{serial} {}: {v}", m["name"]);
            }
        }
    }
}

#[test]
fn a_killed_batch_resumes_every_unit_and_replays_to_the_same_reports() {
    let dir = temp_dir("batch-resume");
    let p = write(&dir, "mini.toml", MINI);
    // Unit A on a twin of its own (g-sensitive: it fails), C on the run's:
    // a resume must not give C the first unit's twin.
    write(&dir, "g.toml", &g_sensitive_twin());
    let quad = bench(
        &dir,
        "pair.toml",
        None,
        "\n[[slots]]\nname = \"A\"\ntwin = \"g.toml\"\n\n[[slots]]\nname = \"C\"\n",
    );
    let out = dir.join("run");
    let o = run(&[
        s(&p),
        "--bench",
        s(&quad),
        "--dut",
        "A=Q-1",
        "--dut",
        "C=Q-3",
        "--inject",
        "process-kill@2000",
        "--out",
        s(&out),
    ]);
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&o.status),
        Some(9),
        "killed: {}",
        stderr(&o)
    );
    let o = run(&["--resume", s(&out)]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    assert!(out.join("run.part2.mcap").is_file());
    let again = dir.join("replay");
    let o = command()
        .args(["replay", s(&out.join("run.part2.mcap")), "--out", s(&again)])
        .output()
        .expect("replay runs");
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    // Each unit resumed on its own twin: A still g-sensitive, C not.
    for (serial, want) in [("Q-1", "fail"), ("Q-3", "pass")] {
        let name = format!("report-{serial}.json");
        let r = json(&out.join(&name));
        assert_eq!(r["outcome"], want, "{serial}: {r}");
        // Every measurement of the procedure, from both parts' records.
        assert_eq!(r["measurements"].as_array().map(Vec::len), Some(6), "{r}");
        assert_eq!(
            std::fs::read(out.join(&name)).expect("run's"),
            std::fs::read(again.join(&name)).expect("replay's"),
            "{name}"
        );
    }
}

#[test]
fn serials_that_would_share_a_report_file_are_refused() {
    let dir = temp_dir("batch-names");
    let p = write(&dir, "mini.toml", MINI);
    let quad = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/quad.toml");
    let o = run(&[
        s(&p),
        "--bench",
        s(&quad),
        "--dut",
        "A=SN/1",
        "--dut",
        "B=SN 1",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("would share one report file (report-SN_1.html)"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_bench_may_stop_the_whole_batch_when_a_unit_cannot_be_judged() {
    let dir = temp_dir("batch-stop");
    let p = write(&dir, "mini.toml", MINI);
    let quad = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/quad.toml"),
    )
    .expect("quad.toml");
    // Top-level keys come before the first table.
    let b = write(
        &dir,
        "stop.toml",
        &format!("on_unit_error = \"stop\"\n{quad}"),
    );
    let out = dir.join("run");
    let o = run(&[
        s(&p),
        "--bench",
        s(&b),
        "--dut",
        "A=S-1",
        "--dut",
        "B=S-2",
        "--inject",
        "unit-lost@600",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    for serial in ["S-1", "S-2"] {
        let r = json(&out.join(format!("report-{serial}.json")));
        assert_eq!(r["outcome"], "error", "{serial}: {r}");
        let why = r["error"]["message"].as_str().expect("a reason");
        assert!(
            why.contains("slot B (S-2)") && why.contains("on_unit_error = \"stop\""),
            "{serial}: {why}"
        );
        assert_eq!(r["bench_left"]["verified"], true, "{serial}: {r}");
    }
    // A bench of one unit has no batch to stop.
    let one = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/embedded.toml"),
    )
    .expect("embedded.toml");
    let b = write(
        &dir,
        "one.toml",
        &format!("on_unit_error = \"stop\"\n{one}"),
    );
    let o = run(&[s(&p), "--bench", s(&b), "--dut", "S-9"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("on_unit_error"), "{}", stderr(&o));
}

/// A batch of four through `sim serve` at 60x, run on `TINY` (two 60 s
/// records, each unit's bias judged against its own axis's reference):
/// slot D is turned a quarter turn (its axis north where A's is east) on
/// the served fixture and in the bench file alike.
struct ServedQuad {
    dir: std::path::PathBuf,
    served: crate::common::SimServe,
    _turn: std::sync::RwLockWriteGuard<'static, ()>,
}

impl ServedQuad {
    const SPEED: f64 = 60.0;

    fn start(name: &str) -> Self {
        let dir = temp_dir(name);
        let turn = crate::common::wall_clock_turn();
        // The units powered from the start, as by hand: a bench with
        // slots names no supply.
        let text = format!(
            "speed = {}\nseed = 1\nunit_powered = true\n\
             [[slots]]\nname = \"A\"\n[[slots]]\nname = \"B\"\n[[slots]]\nname = \"C\"\n\
             [[slots]]\nname = \"D\"\nmount = {Y_MOUNT}\n",
            Self::SPEED
        );
        // Chamber (2), table, four gyros and the supply on TCP; the same
        // but the Watlow chamber on ptys.
        let served = crate::common::SimServe::with_config(&dir, &text, 15);
        Self {
            dir,
            served,
            _turn: turn,
        }
    }

    /// Slot `slot`'s gyro line over `scheme` (`tcp://`, `pty://`).
    fn gyro(&self, slot: &str, scheme: &str) -> String {
        self.served
            .addr(&format!("gyro/{slot}"), "rlg-frame", scheme)
    }

    /// Run `TINY` on `fixtures/bench/sim-quad.toml` reading the served
    /// chamber and table and slot k's gyro at `gyros[k]` (a dropped link
    /// reopened for 1 s), the units `duts`; the run and its directory.
    fn run(&self, gyros: [&str; 4], duts: &[&str]) -> (std::process::Output, std::path::PathBuf) {
        let fixture = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/bench/sim-quad.toml"),
        )
        .expect("the fixture");
        let addr = |device, protocol| self.served.addr(device, protocol, "tcp://");
        let text = fixture
            .replace("time_scale = 1.0", &format!("time_scale = {}", Self::SPEED))
            .replace(
                "silence_s = 1.0",
                "silence_s = 1.0\nreconnect_window_s = 1.0",
            )
            .replace("tcp://127.0.0.1:5001", &addr("chamber", "espec-ascii"))
            .replace("tcp://127.0.0.1:5003", &addr("table", "acl"))
            .replace("tcp://127.0.0.1:5004", gyros[0])
            .replace("tcp://127.0.0.1:5005", gyros[1])
            .replace("tcp://127.0.0.1:5006", gyros[2])
            .replace(
                "gyro = { spec = \"tcp://127.0.0.1:5007\" }",
                &format!("gyro = {{ spec = \"{}\" }}\nmount = {Y_MOUNT}", gyros[3]),
            );
        let bench = write(&self.dir, "bench.toml", &text);
        let p = write(&self.dir, "tiny.toml", TINY);
        let out = self.dir.join("out");
        let o = run(&[&[s(&p), "--bench", s(&bench), "--out", s(&out)], duts].concat());
        (o, out)
    }

    fn finish(self) {
        let Self { dir, served, .. } = self;
        drop(served);
        std::fs::remove_dir_all(&dir).expect("cleanup");
    }
}

const QUAD_DUTS: [&str; 8] = [
    "--dut", "A=S-1", "--dut", "B=S-2", "--dut", "C=S-3", "--dut", "D=S-4",
];

/// What a cut link carries: 80 s of 20-byte frames at 400 Hz, less
/// than `TINY`'s two 60 s records and the move between them need.
const CUT_AFTER_BYTES: usize = 80 * 400 * 20;

#[test]
fn a_batch_through_sim_serve_over_tcp_and_ptys_loses_no_frame() {
    let q = ServedQuad::start("batch-served");
    // Two units on TCP, two on ptys.
    let (a, b, c, d) = (
        q.gyro("A", "tcp://"),
        q.gyro("B", "tcp://"),
        q.gyro("C", "pty://"),
        q.gyro("D", "pty://"),
    );
    let (o, out) = q.run([&a, &b, &c, &d], &QUAD_DUTS);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for serial in ["S-1", "S-2", "S-3", "S-4"] {
        let r = json(&out.join(format!("report-{serial}.json")));
        assert_eq!(r["outcome"], "pass", "{serial}: {r}");
        let link = &r["link"];
        for k in [
            "lost_frames",
            "crc_errors",
            "resyncs",
            "duplicates",
            "reconnects",
        ] {
            assert_eq!(link[k], 0, "{serial}: {k} in {link}");
        }
        // Both records whole: 2 x 60 s at 400 Hz at the least.
        let frames = r["frames"].as_u64().expect("frames");
        assert!(frames >= 48_000, "{serial}: {frames} frames");
    }
    // D's axis is north where A's is east: each bias is judged against
    // its own axis's share of the Earth's rate (9.6 deg/h apart at the
    // east position), so both pass only if each unit's reference is its own.
    let east = |serial: &str| {
        figures(&out.join(format!("report-{serial}.json")))
            .into_iter()
            .find(|(n, _)| n == "bias_dph:east")
            .expect("bias east")
            .1
    };
    assert!(east("S-1").abs() < 1.5 && east("S-4").abs() < 1.5);
    // The log holds every unit's frames: replay gives every report.
    let again = q.dir.join("again");
    let o = command()
        .args(["replay", s(&out.join("run.mcap")), "--out", s(&again)])
        .output()
        .expect("replay");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    for serial in ["S-1", "S-2", "S-3", "S-4"] {
        let name = format!("report-{serial}.json");
        assert_eq!(
            std::fs::read(out.join(&name)).expect("run"),
            std::fs::read(again.join(&name)).expect("replay"),
            "{name}"
        );
    }
    q.finish();
}

/// Forward `upstream`'s bytes to one client of a loopback port for
/// `bytes` bytes, then drop both ends and stop listening: a link that is
/// lost for good. Returns the port's address.
fn cut_after(upstream: &str, bytes: usize) -> String {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("listen");
    let addr = listener.local_addr().expect("address");
    let upstream = upstream.trim_start_matches("tcp://").to_owned();
    std::thread::spawn(move || {
        let Ok((mut client, _)) = listener.accept() else {
            return;
        };
        drop(listener);
        let Ok(mut up) = std::net::TcpStream::connect(upstream) else {
            return;
        };
        let mut left = bytes;
        let mut buf = [0u8; 4096];
        while left > 0 {
            let Ok(n) = up.read(&mut buf[..left.min(4096)]) else {
                return;
            };
            if n == 0 || client.write_all(&buf[..n]).is_err() {
                return;
            }
            left -= n;
        }
    });
    format!("tcp://{addr}")
}

#[test]
fn a_served_batch_goes_on_without_a_unit_whose_link_is_lost_for_good() {
    let q = ServedQuad::start("batch-served-lost");
    // B's link is gone after CUT_AFTER_BYTES: no reconnect finds it.
    let b = cut_after(&q.gyro("B", "tcp://"), CUT_AFTER_BYTES);
    let (a, c, d) = (
        q.gyro("A", "tcp://"),
        q.gyro("C", "tcp://"),
        q.gyro("D", "tcp://"),
    );
    let (o, out) = q.run([&a, &b, &c, &d], &QUAD_DUTS);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("slot B (S-2): gyro/B") && err.contains("the batch goes on"),
        "{err}"
    );
    let lost = json(&out.join("report-S-2.json"));
    assert_eq!(lost["outcome"], "error", "{lost}");
    assert!(lost["error"]["message"].as_str().is_some(), "{lost}");
    for serial in ["S-1", "S-3", "S-4"] {
        let r = json(&out.join(format!("report-{serial}.json")));
        assert_eq!(r["outcome"], "pass", "{serial}: {r}");
        assert_eq!(r["link"]["lost_frames"], 0, "{serial}");
    }
    // The shared bench was left safe for every unit.
    assert_eq!(
        lost["bench_left"]["verified"], true,
        "{}",
        lost["bench_left"]
    );
    q.finish();
}

#[test]
fn a_served_batch_leaves_an_empty_slots_link_closed_and_reads_the_others_as_theirs() {
    let q = ServedQuad::start("batch-served-empty");
    // Nothing listens behind slot B's link: it is left empty, and must
    // not be opened.
    let nowhere = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").expect("a free port");
        format!("tcp://{}", l.local_addr().expect("address"))
    };
    let (a, c, d) = (
        q.gyro("A", "tcp://"),
        q.gyro("C", "tcp://"),
        q.gyro("D", "tcp://"),
    );
    let duts = ["--dut", "A=S-1", "--dut", "C=S-3", "--dut", "D=S-4"];
    let (o, out) = q.run([&a, &nowhere, &c, &d], &duts);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // D (axis north) passes only on its own frames and its own reference.
    for serial in ["S-1", "S-3", "S-4"] {
        let r = json(&out.join(format!("report-{serial}.json")));
        assert_eq!(r["outcome"], "pass", "{serial}: {r}");
        assert_eq!(r["link"]["lost_frames"], 0, "{serial}");
    }
    assert!(!out.join("report-S-2.json").exists());
    q.finish();
}

#[test]
fn a_served_batch_whose_every_link_is_lost_stops_with_the_bench_safe() {
    let q = ServedQuad::start("batch-served-all-lost");
    let (a, b) = (
        cut_after(&q.gyro("A", "tcp://"), CUT_AFTER_BYTES),
        cut_after(&q.gyro("B", "tcp://"), CUT_AFTER_BYTES),
    );
    let (c, d) = (q.gyro("C", "tcp://"), q.gyro("D", "tcp://"));
    let (o, out) = q.run([&a, &b, &c, &d], &["--dut", "A=S-1", "--dut", "B=S-2"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    for serial in ["S-1", "S-2"] {
        let r = json(&out.join(format!("report-{serial}.json")));
        assert_eq!(r["outcome"], "error", "{serial}: {r}");
        let why = r["error"]["message"].as_str().expect("a reason");
        assert!(
            why.contains("every unit's gyro link is lost"),
            "{serial}: {why}"
        );
        assert_eq!(r["bench_left"]["verified"], true, "{}", r["bench_left"]);
    }
    q.finish();
}
