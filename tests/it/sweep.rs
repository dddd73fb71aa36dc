//! The fault-and-resume sweep: a procedure is interrupted at every step
//! boundary and in the middle of every step, by each fault kind, on the
//! embedded bench at full speed, and resumed; every resumed run is checked.
//!
//! Shared by the quick sweep in `cargo test` (`resume.rs`) and the full
//! sweep of the shipped acceptance that CI runs
//! (`cargo run --release --example resume_sweep`).
//!
//! For each interruption: the first part's log is never overwritten; the
//! resume passes (a passing unit); every figure lies within the spread of
//! uninterrupted runs of other seeds; no step the first part completed is
//! taken again, except the records of the interrupted thermal segment
//! (`resume_plan`); the bench is left verified safe by every part; and
//! replaying the last part gives its report byte for byte (nothing lost).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use gyrobench::bench::BenchConfig;
use gyrobench::config::Source;
use gyrobench::procedure::Procedure;
use gyrobench::sequencer::resume_plan;

/// What a sweep needs.
#[derive(Debug, Clone)]
pub struct Sweep {
    /// The gyrobench binary.
    pub bin: PathBuf,
    /// The procedure.
    pub procedure: PathBuf,
    /// Where the runs go.
    pub dir: PathBuf,
    /// Seeds of the uninterrupted reference runs (the first is the one
    /// interrupted).
    pub seeds: Vec<u64>,
    /// Fault kinds, each with the share of the points it is played at
    /// (1 = every point, 3 = every third).
    pub faults: Vec<(String, usize)>,
    /// Processes at once.
    pub jobs: usize,
}

/// One interruption and its resume.
#[derive(Debug, Clone)]
pub struct Row {
    /// Fault kind.
    pub fault: String,
    /// Device time of the fault, s.
    pub at_s: f64,
    /// The step it fell in.
    pub step: String,
    /// Exit code of the first part.
    pub first_exit: Option<i32>,
    /// Exit code of the resume.
    pub resume_exit: Option<i32>,
    /// Outcome of the resumed run.
    pub outcome: String,
    /// What went wrong (empty: nothing).
    pub problems: Vec<String>,
    /// The worst figure, in standard deviations of the reference runs.
    pub worst: (String, f64),
    /// Steps the first part completed that were taken again.
    pub retaken: usize,
}

/// The totals of a sweep.
#[derive(Debug, Clone, Default)]
pub struct Totals {
    /// Interruptions played.
    pub runs: usize,
    /// Runs whose log or report could not be read back whole.
    pub lost: usize,
    /// First-part logs changed by the resume.
    pub overwritten: usize,
    /// Resumes that did not pass.
    pub resumes_failed: usize,
    /// Parts that left the bench unverified.
    pub bench_unsafe: usize,
    /// Resumed runs with a figure outside the reference spread.
    pub figures_outside: usize,
    /// Steps taken again outside the interrupted segment.
    pub retaken_outside: usize,
}

fn json(p: &Path) -> Option<serde_json::Value> {
    serde_json::from_str(&std::fs::read_to_string(p).ok()?).ok()
}

/// A `/steps` event of a setup or main step.
struct StepAt {
    index: usize,
    key: String,
    phase: String,
    t_s: f64,
}

/// The setup and main step events of a log, read as far as it reads (a
/// killed run's log has no footer).
fn steps_of(log: &Path) -> Vec<StepAt> {
    let bytes = std::fs::read(log).unwrap_or_default();
    let opts = mcap::read::Options::IgnoreEndMagic.into();
    let Ok(stream) = mcap::MessageStream::new_with_options(&bytes, opts) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for m in stream {
        let Ok(m) = m else { break };
        if m.channel.topic != "/steps" {
            continue;
        }
        let Ok(e) = serde_json::from_slice::<serde_json::Value>(&m.data) else {
            continue;
        };
        if let (Some(i), Some(t), Some(phase), false) = (
            e["index"].as_u64(),
            e["t_s"].as_f64(),
            e["phase"].as_str(),
            e["group"] == "cleanup",
        ) {
            out.push(StepAt {
                index: i as usize,
                key: e["key"].as_str().unwrap_or("").to_owned(),
                phase: phase.to_owned(),
                t_s: t,
            });
        }
    }
    out
}

/// (key, start, end) of every setup and main step a log ran.
fn step_times(log: &Path) -> Vec<(String, f64, f64)> {
    let steps = steps_of(log);
    let mut out = Vec::new();
    for start in steps.iter().filter(|e| e.phase == "start") {
        if let Some(end) = steps
            .iter()
            .find(|e| e.phase == "end" && e.index == start.index)
        {
            out.push((start.key.clone(), start.t_s, end.t_s));
        }
    }
    out
}

/// Indices of the steps a log started and completed.
fn started_and_completed(log: &Path) -> (Vec<usize>, Vec<usize>) {
    let steps = steps_of(log);
    let of = |phase: &str| {
        steps
            .iter()
            .filter(|e| e.phase == phase)
            .map(|e| e.index)
            .collect()
    };
    (of("start"), of("end"))
}

fn gyrobench(bin: &Path, dir: &Path, args: &[&str]) -> std::process::Output {
    // The sweep's runs go into a store of its own, never the user's.
    Command::new(bin)
        .env("XDG_DATA_HOME", dir.join("data"))
        .env("GYROBENCH_DB", dir.join("results.sqlite"))
        .args(args)
        .output()
        .expect("gyrobench runs")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// A resumed run's figure is within the run-to-run spread when it lies
/// within the reference runs' range, or within this many of their
/// standard deviations from their mean.
pub const SPREAD_SD: f64 = 4.0;

/// Mean and spread of every figure over the reference runs.
#[derive(Debug, Clone)]
struct Spread {
    mean: f64,
    sd: f64,
    min: f64,
    max: f64,
}

impl Sweep {
    /// Run the sweep; the rows and the totals.
    pub fn run(&self) -> (Vec<Row>, Totals) {
        let _ = std::fs::remove_dir_all(&self.dir);
        std::fs::create_dir_all(&self.dir).expect("sweep dir");
        let text = std::fs::read_to_string(&self.procedure).expect("procedure");
        let procedure = Procedure::from_source(
            &Source::from_text(s(&self.procedure), &text),
            &BenchConfig::embedded().procedure_limits(),
        )
        .expect("the procedure loads");
        // Reference runs: the figures' spread, and where each step lies.
        let next = std::sync::atomic::AtomicUsize::new(0);
        let reports = std::sync::Mutex::new(Vec::new());
        std::thread::scope(|scope| {
            for _ in 0..self.jobs.max(1) {
                scope.spawn(|| {
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(seed) = self.seeds.get(i) else { break };
                        let out = self.dir.join(format!("reference-{seed}"));
                        let r = gyrobench(
                            &self.bin,
                            &self.dir,
                            &[
                                "run",
                                s(&self.procedure),
                                "--seed",
                                &seed.to_string(),
                                "--out",
                                s(&out),
                            ],
                        );
                        // A sound unit: a pass, or under a non-binary rule a
                        // conditional pass (exit 4; docs/figures.md).
                        assert!(
                            matches!(r.status.code(), Some(0 | 4)),
                            "reference seed {seed} must pass: exit {:?}",
                            r.status.code()
                        );
                        let report = json(&out.join("report.json")).expect("reference report");
                        reports
                            .lock()
                            .unwrap_or_else(std::sync::PoisonError::into_inner)
                            .push(report);
                    }
                });
            }
        });
        let mut values: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        for report in reports
            .into_inner()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
        {
            for m in report["measurements"].as_array().into_iter().flatten() {
                if let (Some(n), Some(v)) = (m["name"].as_str(), m["value"].as_f64()) {
                    values.entry(n.to_owned()).or_default().push(v);
                }
            }
        }
        let steps = step_times(
            &self
                .dir
                .join(format!("reference-{}/run.mcap", self.seeds[0])),
        );
        let spread: BTreeMap<String, Spread> = values
            .into_iter()
            .map(|(n, v)| {
                let mean = v.iter().sum::<f64>() / v.len() as f64;
                let var =
                    v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len().max(2) - 1) as f64;
                let min = v.iter().copied().fold(f64::INFINITY, f64::min);
                let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                (
                    n,
                    Spread {
                        mean,
                        sd: var.sqrt(),
                        min,
                        max,
                    },
                )
            })
            .collect();
        // Every step boundary and the middle of every step that lasts.
        let mut points: Vec<(f64, String)> = Vec::new();
        for (key, t0, t1) in &steps {
            points.push((t0 + 0.5, key.clone()));
            if t1 - t0 > 2.0 {
                points.push((0.5 * (t0 + t1), key.clone()));
            }
        }
        let mut jobs: Vec<(String, f64, String)> = Vec::new();
        for (fault, stride) in &self.faults {
            for (i, (t, key)) in points.iter().enumerate() {
                if i % stride.max(&1) == 0 {
                    jobs.push((fault.clone(), *t, key.clone()));
                }
            }
        }
        let rows: Vec<Row> =
            gyrobench_analysis::par::on_threads(self.jobs, &jobs, |i, (fault, t, key)| {
                self.one(i, &procedure, &spread, fault, *t, key)
            });
        let mut t = Totals {
            runs: rows.len(),
            ..Totals::default()
        };
        for r in &rows {
            let has = |w: &str| r.problems.iter().any(|p| p.starts_with(w));
            t.lost += usize::from(has("lost"));
            t.overwritten += usize::from(has("overwritten"));
            t.resumes_failed += usize::from(has("resume failed"));
            t.bench_unsafe += usize::from(has("bench"));
            t.figures_outside += usize::from(has("figure"));
            t.retaken_outside += usize::from(has("retaken"));
        }
        (rows, t)
    }

    fn one(
        &self,
        n: usize,
        procedure: &Procedure,
        spread: &BTreeMap<String, Spread>,
        fault: &str,
        at_s: f64,
        step: &str,
    ) -> Row {
        let mut problems = Vec::new();
        // `station-sighup@T`: the station runs the procedure and is sent
        // the signal near device time T (the terminal it was started from
        // closed); every other fault is `run --inject FAULT@T`.
        let (dir, first_exit, at_s) = match fault.strip_prefix("station-") {
            Some(signal) => {
                let runs = self.dir.join(format!("{n:04}-{fault}"));
                match self.station_first_part(&runs, signal, at_s) {
                    Ok(first) => first,
                    Err(why) => {
                        problems.push(format!("lost: the station's part: {why}"));
                        return Row {
                            fault: fault.to_owned(),
                            at_s,
                            step: step.to_owned(),
                            first_exit: None,
                            resume_exit: None,
                            outcome: "none".into(),
                            problems,
                            worst: (String::new(), 0.0),
                            retaken: 0,
                        };
                    }
                }
            }
            None => {
                let dir = self.dir.join(format!("{n:04}-{fault}"));
                let first = gyrobench(
                    &self.bin,
                    &self.dir,
                    &[
                        "run",
                        s(&self.procedure),
                        "--seed",
                        &self.seeds[0].to_string(),
                        "--out",
                        s(&dir),
                        "--inject",
                        &format!("{fault}@{at_s}"),
                    ],
                );
                (dir, first.status.code(), at_s)
            }
        };
        let log1 = dir.join("run.mcap");
        let before = std::fs::read(&log1).unwrap_or_default();
        if let Some(r) = json(&dir.join("report.json"))
            && r["bench_left"]["verified"] != true
        {
            problems.push(format!(
                "bench unverified after part 1: {}",
                r["bench_left"]
            ));
        }
        // A fault after the last step finds the run over: nothing to resume.
        if let Some(r) = json(&dir.join("report.json"))
            && (r["outcome"] == "pass" || r["outcome"] == "conditional_pass")
        {
            return Row {
                fault: fault.to_owned(),
                at_s,
                step: step.to_owned(),
                first_exit,
                resume_exit: None,
                outcome: "pass (finished before the fault)".into(),
                problems,
                worst: (String::new(), 0.0),
                retaken: 0,
            };
        }
        let (_, completed1) = started_and_completed(&log1);
        let resume = gyrobench(&self.bin, &self.dir, &["run", "--resume", s(&dir)]);
        let mut parts = 1;
        while dir.join(format!("run.part{}.mcap", parts + 1)).exists() {
            parts += 1;
        }
        let last = if parts == 1 {
            log1.clone()
        } else {
            dir.join(format!("run.part{parts}.mcap"))
        };
        if std::fs::read(&log1).unwrap_or_default() != before {
            problems.push("overwritten: the first part's log changed".into());
        }
        let report = json(&dir.join("report.json"));
        let outcome = report
            .as_ref()
            .and_then(|r| r["outcome"].as_str().map(str::to_owned))
            .unwrap_or_else(|| "none".into());
        let judged_sound = matches!(
            (resume.status.code(), outcome.as_str()),
            (Some(0), "pass") | (Some(4), "conditional_pass")
        );
        if !judged_sound {
            problems.push(format!(
                "resume failed: exit {:?}, outcome {outcome}: {}",
                resume.status.code(),
                String::from_utf8_lossy(&resume.stderr)
                    .lines()
                    .filter(|l| l.starts_with("error") || l.contains("stopped in"))
                    .collect::<Vec<_>>()
                    .join(" / ")
            ));
        }
        let worst = match &report {
            Some(r) => {
                self.resumed_report(r, spread, &dir, &last, resume.status.code(), &mut problems)
            }
            None => {
                problems.push("lost: no report after the resume".into());
                (String::new(), 0.0)
            }
        };
        // Steps taken again: only the interrupted segment's.
        let retaken = retaken_steps(procedure, &completed1, &dir, parts, &mut problems);
        Row {
            fault: fault.to_owned(),
            at_s,
            step: step.to_owned(),
            first_exit,
            resume_exit: resume.status.code(),
            outcome,
            problems,
            worst,
            retaken,
        }
    }

    /// The resumed run's report `r` checked: the bench verified, every
    /// figure within the reference runs' spread, and the last part `last`
    /// replayed to the same report; the figure furthest from its
    /// references, in their standard deviations.
    fn resumed_report(
        &self,
        r: &serde_json::Value,
        spread: &BTreeMap<String, Spread>,
        dir: &Path,
        last: &Path,
        resume_exit: Option<i32>,
        problems: &mut Vec<String>,
    ) -> (String, f64) {
        let mut worst = (String::new(), 0.0);
        if r["bench_left"]["verified"] != true {
            problems.push(format!(
                "bench unverified after the resume: {}",
                r["bench_left"]
            ));
        }
        // A resume that switched the unit on again inside the thermal
        // cycle (a power-on in a later part) puts a second warm-up in
        // the records: the temperature-rate fit, one constant per
        // power-on and no warm-up term, reads part of it as a rate
        // sensitivity (seen: -0.065 against the references'
        // -0.060..-0.052 for a break at the end of the cold soak,
        // whose segment is retaken after an hour at +50 degC from a
        // fresh switch-on). That figure is then another experiment's:
        // still judged against its limits, not against uninterrupted
        // runs' spread.
        let powered_again = r["power_ons"].as_array().is_some_and(|ons| {
            ons.iter()
                .any(|o| o["part"].as_u64().is_some_and(|p| p > 1))
        });
        for m in r["measurements"].as_array().into_iter().flatten() {
            let (Some(name), Some(v)) = (m["name"].as_str(), m["value"].as_f64()) else {
                continue;
            };
            if powered_again && m["metric"] == "temperature_rate_sensitivity" {
                continue;
            }
            let Some(sp) = spread.get(name) else { continue };
            let z = (v - sp.mean).abs() / sp.sd.max(1e-12);
            if z > worst.1 {
                worst = (name.to_owned(), z);
            }
            if z > SPREAD_SD && (v < sp.min || v > sp.max) {
                problems.push(format!(
                    "figure {name} = {v:.4} outside the reference runs' {:.4}..{:.4} by more than {SPREAD_SD} sd ({:.4})",
                    sp.min, sp.max, sp.sd
                ));
            }
        }
        // Nothing lost: the last part replays to the same report.
        let replayed = dir.join("replay");
        let rr = gyrobench(
            &self.bin,
            &self.dir,
            &["replay", s(last), "--out", s(&replayed)],
        );
        let same = std::fs::read(dir.join("report.json")).ok()
            == std::fs::read(replayed.join("report.json")).ok();
        if rr.status.code() != resume_exit || !same {
            problems.push("lost: the last part does not replay to the report".into());
        }
        worst
    }

    /// The first part through the station: it is started on the embedded
    /// bench at full speed, runs the procedure for a unit, and is sent
    /// SIG`signal` once the run's device time reaches `at_s`. The run
    /// directory, the station's exit code and the device time the signal
    /// found.
    fn station_first_part(
        &self,
        runs: &Path,
        signal: &str,
        at_s: f64,
    ) -> Result<(PathBuf, Option<i32>, f64), String> {
        use std::io::BufRead;
        let offered = self.procedure.parent().ok_or("the procedure's directory")?;
        let file = self
            .procedure
            .file_name()
            .and_then(|f| f.to_str())
            .ok_or("the procedure's file name")?;
        let mut child = Command::new(&self.bin)
            .env("XDG_DATA_HOME", self.dir.join("data"))
            .env("GYROBENCH_DB", self.dir.join("results.sqlite"))
            .args([
                "station",
                "--listen",
                "127.0.0.1:0",
                "--no-live",
                "--procedures",
                s(offered),
                "--runs",
                s(runs),
            ])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .map_err(|e| format!("the station does not start: {e}"))?;
        let mut line = String::new();
        if let Some(out) = child.stdout.take() {
            std::io::BufReader::new(out)
                .read_line(&mut line)
                .map_err(|e| format!("the station's URL: {e}"))?;
        }
        let url = line.trim().strip_prefix("station ").unwrap_or_default();
        let Some((base, token)) = url.split_once("/?token=") else {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("no station URL in {line:?}"));
        };
        let host = base.trim_start_matches("http://").to_owned();
        let request = |method: &str, path: &str, body: &str| -> Result<String, String> {
            match crate::http::request(&host, Some(token), method, path, body)? {
                (200, body) => Ok(body),
                (code, body) => Err(format!("{method} {path}: {code} {body}")),
            }
        };
        let started = request(
            "POST",
            "/api/start",
            &format!(r#"{{"procedure":"{file}","serial":"RL16-SWEEP","operator":"sweep"}}"#),
        );
        let mut dir = None;
        let mut seen_s = 0.0;
        if let Err(why) = started {
            let _ = child.kill();
            let _ = child.wait();
            return Err(why);
        }
        // Poll until the run reaches `at_s` (or ends first).
        for _ in 0..60_000 {
            let Ok(state) = request("GET", "/api/state", "") else {
                break;
            };
            let state: serde_json::Value = serde_json::from_str(&state).unwrap_or_default();
            let run = &state["run"];
            if let Some(d) = run["dir"].as_str() {
                dir = Some(PathBuf::from(d));
            }
            seen_s = run["device_s"].as_f64().unwrap_or(0.0);
            if seen_s >= at_s || run["phase"] == "finished" {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let _ = Command::new("kill")
            .args([
                format!("-{}", signal.to_uppercase().trim_start_matches("SIG")),
                child.id().to_string(),
            ])
            .status();
        let mut code = None;
        for _ in 0..1200 {
            match child.try_wait() {
                Ok(Some(st)) => {
                    code = Some(st.code());
                    break;
                }
                Ok(None) => std::thread::sleep(std::time::Duration::from_millis(100)),
                Err(_) => break,
            }
        }
        let Some(code) = code else {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!(
                "SIG{signal}: the station did not stop within 120 s"
            ));
        };
        let dir = dir.ok_or("the station named no run directory")?;
        Ok((dir, code, seen_s))
    }
}

/// The totals as a markdown table, one line per fault kind and a total.
pub fn render(rows: &[Row], totals: &Totals) -> String {
    let mut kinds: BTreeMap<&str, (usize, usize, f64)> = BTreeMap::new();
    for r in rows {
        let k = kinds.entry(r.fault.as_str()).or_default();
        k.0 += 1;
        k.1 += usize::from(!r.problems.is_empty());
        k.2 = k.2.max(r.worst.1);
    }
    let mut out = String::from(
        "| fault | interruptions | with a problem | worst figure (sd of the references) |\n|---|---|---|---|\n",
    );
    for (k, (n, bad, z)) in &kinds {
        out.push_str(&format!("| {k} | {n} | {bad} | {z:.1} |\n"));
    }
    out.push_str(&format!(
        "\nruns {} · lost {} · overwritten {} · resumes failed {} · bench left unsafe {} · figures outside the spread {} · steps retaken outside the interrupted segment {}\n",
        totals.runs,
        totals.lost,
        totals.overwritten,
        totals.resumes_failed,
        totals.bench_unsafe,
        totals.figures_outside,
        totals.retaken_outside
    ));
    for r in rows.iter().filter(|r| !r.problems.is_empty()) {
        out.push_str(&format!(
            "\n- {} at {:.0} s ({}): {}",
            r.fault,
            r.at_s,
            r.step,
            r.problems.join("; ")
        ));
    }
    out
}

/// Every interruption, one line each.
pub fn render_rows(rows: &[Row]) -> String {
    let mut out = String::from(
        "| fault | at s | step | part 1 exit | resume exit | outcome | steps retaken | worst figure | problems |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {:.0} | {} | {} | {} | {} | {} | {} {:.1} sd | {} |\n",
            r.fault,
            r.at_s,
            r.step,
            r.first_exit.map_or("signal".into(), |c| c.to_string()),
            r.resume_exit.map_or("-".into(), |c| c.to_string()),
            r.outcome,
            r.retaken,
            r.worst.0,
            r.worst.1,
            if r.problems.is_empty() {
                "-".into()
            } else {
                r.problems.join("; ")
            }
        ));
    }
    out
}

/// The steps of parts 2..=`parts` in `dir` taken again (completed in the
/// first part, `completed1`), each one before the interrupted segment a
/// problem.
fn retaken_steps(
    procedure: &Procedure,
    completed1: &[usize],
    dir: &Path,
    parts: usize,
    problems: &mut Vec<String>,
) -> usize {
    let mut completed = completed1.iter().max().map_or(0, |m| m + 1);
    let steps: Vec<_> = procedure.setup.iter().chain(&procedure.main).collect();
    if completed >= steps.len() {
        // Every step done but the log cut short before its end record
        // (a full disk at the very end): the interrupted segment is the
        // last record's.
        completed = steps
            .iter()
            .rposition(|s| matches!(s.kind, gyrobench::procedure::StepKind::Record { .. }))
            .unwrap_or(completed);
    }
    let (start_at, _) = resume_plan(procedure, completed);
    let mut retaken = 0;
    for k in 2..=parts {
        let (started, _) = started_and_completed(&dir.join(format!("run.part{k}.mcap")));
        for i in started {
            if completed1.contains(&i) {
                retaken += 1;
                if i < start_at {
                    problems.push(format!(
                        "retaken: step {i} is before the segment at {start_at}"
                    ));
                }
            }
        }
    }
    retaken
}
