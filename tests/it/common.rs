//! Helpers and procedures several whole-system tests share.

use std::path::Path;

/// A path as the `&str` a command line takes.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// A JSON file, parsed.
pub fn json(p: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    serde_json::from_str(&text).expect("JSON")
}

/// A short procedure with every metric, a repeat (steps sharing keys) and
/// a temperature ramp, so compensation has something to fit.
pub const MINI: &str = r#"
[procedure]
name = "mini"
description = "every metric in an hour of device time"
dut_type = "RL-16"
spec = "test"
decision_rule = "simple"  # records this short have an uncertainty no guarded rule passes

[[setup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 1.0

[[main]]
action = "record"
label = "warm"
duration_s = 1800.0

[[main]]
action = "repeat"
positions = [
  { label = "up", table = { outer_deg = 90.0, inner_deg = 0.0 } },
  { label = "east", table = { outer_deg = 0.0, inner_deg = 0.0 } },
]

[[main.steps]]
action = "record"
label = "{label}"
duration_s = 120.0

[[main.steps]]
action = "measure"
name = "bias_dph:{label}"
metric = "mean_bias"
records = ["{label}"]
low = -5.0
high = 5.0
unit = "deg/h"

[[main]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }

[[main]]
action = "chamber"
set_c = 30.0
ramp_c_per_min = 1.0

[[main]]
action = "record"
label = "ramp"
duration_s = 1200.0

[[main]]
action = "measure"
name = "self_heating_dph"
metric = "self_heating"
records = ["warm"]
high = 1.0
unit = "deg/h"

[[main]]
action = "measure"
name = "stability"
metric = "bias_stability"
records = ["up"]
averaging_s = 10.0
high = 0.2
unit = "deg/h"

[[main]]
action = "measure"
name = "raw"
metric = "drift_pp"
records = ["warm", "ramp"]
averaging_s = 600.0
high = 1.0
unit = "deg/h"

[[main]]
action = "measure"
name = "compensated"
metric = "compensated_drift_pp"
records = ["warm", "ramp"]
averaging_s = 600.0
high = 0.1
unit = "deg/h"

[[cleanup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 2.0
"#;

/// A run of a few minutes of device time: a chamber step, two short
/// records, a measure each and a cleanup move.
pub const TINY: &str = r#"
[procedure]
name = "tiny"
description = "two 60 s records"
dut_type = "RL-16"
spec = "test"
decision_rule = "simple"  # records this short have an uncertainty no guarded rule passes

[[setup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 1.0

[[main]]
action = "repeat"
positions = [
  { label = "up", table = { outer_deg = 90.0, inner_deg = 0.0 } },
  { label = "east", table = { outer_deg = 0.0, inner_deg = 0.0 } },
]

[[main.steps]]
action = "record"
label = "{label}"
duration_s = 60.0

[[main.steps]]
action = "measure"
name = "bias_dph:{label}"
metric = "mean_bias"
records = ["{label}"]
low = -5.0
high = 5.0
unit = "deg/h"

[[cleanup]]
action = "move"
table = { outer_deg = 90.0, inner_deg = 0.0 }
"#;

/// Write `text` to `dir/name` and return the path.
pub fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    p
}

/// stderr of a finished command, as text.
pub fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The Python of the third-party checks (`$GYROBENCH_TEST_PYTHON`, the
/// virtualenv `.ci/run` makes). CI must have it; elsewhere a check without
/// it is skipped and says so (`what` names the check).
pub fn python(what: &str) -> Option<String> {
    let p = std::env::var("GYROBENCH_TEST_PYTHON").ok();
    if p.is_none() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI runs {what}: set GYROBENCH_TEST_PYTHON (.ci/run makes the virtualenv)"
        );
        eprintln!("skipped: {what} (set GYROBENCH_TEST_PYTHON)");
    }
    p
}

/// Run `tests/conformance/SCRIPT` with `python` and `args`; it must succeed
/// (its output is the failure message).
pub fn conformance(python: &str, script: &str, args: &[&str]) {
    let out = std::process::Command::new(python)
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/conformance")
                .join(script),
        )
        .args(args)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{script}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Who may run beside whom: tests paced against the wall clock alone,
/// the tests that keep both cores busy beside each other.
static TURN: std::sync::RwLock<()> = std::sync::RwLock::new(());

/// Held by tests that run a simulated bench paced against the wall clock
/// (`sim serve` at 60-200x: a starved reader loses frames, which the run
/// rightly refuses to judge, or falls behind the gyro) and by the README
/// test's paced lines (`--speed`, the 2 kHz link benchmark). They take
/// turns, and never run beside a test holding [`busy_turn`]; the light
/// rest of the suite runs beside them.
pub fn wall_clock_turn() -> std::sync::RwLockWriteGuard<'static, ()> {
    TURN.write()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Held by tests that keep the cores busy for long (self-checks, the
/// fault-and-resume sweep, eight runs at once, Chromium, the README's
/// lines at full speed, one line at a time): they run beside
/// each other but not beside a [`wall_clock_turn`]. Seen in a release
/// build: the sweep beside a run through `sim serve` at 60x made the host
/// fall behind the gyro, and the run (rightly) refused to judge its record.
pub fn busy_turn() -> std::sync::RwLockReadGuard<'static, ()> {
    TURN.read()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// `gyrobench sim serve` in its own process, killed when dropped.
pub struct SimServe {
    child: std::process::Child,
    endpoints: Vec<String>,
}

impl SimServe {
    /// Serve the simulated bench at `speed` (a config file written in `dir`).
    pub fn start(dir: &Path, speed: f64) -> Self {
        Self::with_config(dir, &format!("speed = {speed}\nseed = 1\n"), 9)
    }

    /// Serve the simulated bench of serve file `text` (written in `dir`),
    /// which prints `lines` endpoints.
    pub fn with_config(dir: &Path, text: &str, lines: usize) -> Self {
        use std::io::BufRead;
        let config = write(dir, "serve.toml", text);
        let mut child = crate::cli::command()
            .args(["sim", "serve", "--config", s(&config)])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("sim serve starts");
        let mut out = std::io::BufReader::new(child.stdout.take().expect("stdout"));
        let mut endpoints = Vec::new();
        for _ in 0..lines {
            let mut l = String::new();
            out.read_line(&mut l).expect("endpoint");
            endpoints.push(l.trim().to_owned());
        }
        Self { child, endpoints }
    }

    /// The address of an endpoint (`tcp://...` or `pty://...`).
    pub fn addr(&self, device: &str, protocol: &str, scheme: &str) -> String {
        self.endpoints
            .iter()
            .find_map(|e| {
                e.strip_prefix(&format!("{device} {protocol} "))
                    .filter(|a| a.starts_with(scheme))
            })
            .expect("endpoint")
            .to_owned()
    }

    /// A bench file of this bench's endpoints over `scheme`, at
    /// `time_scale`, written in `dir`.
    pub fn bench_file(&self, dir: &Path, scheme: &str, time_scale: f64) -> std::path::PathBuf {
        let fixture = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/fixtures/bench/sim-serve.toml"
        ))
        .expect("fixture");
        let bench = fixture
            .replace("time_scale = 1.0", &format!("time_scale = {time_scale}"))
            .replace(
                "tcp://127.0.0.1:5001",
                &self.addr("chamber", "espec-ascii", scheme),
            )
            .replace("tcp://127.0.0.1:5003", &self.addr("table", "acl", scheme))
            .replace(
                "tcp://127.0.0.1:5004",
                &self.addr("gyro", "rlg-frame", scheme),
            )
            .replace(
                "tcp://127.0.0.1:5025",
                &self.addr("supply", "keysight-e36300", scheme),
            );
        write(
            dir,
            &format!("bench-{}.toml", scheme.trim_end_matches("://")),
            &bench,
        )
    }
}

impl Drop for SimServe {
    fn drop(&mut self) {
        let _killed = self.child.kill();
        let _reaped = self.child.wait();
    }
}

/// A `gyrobench` child whose stderr (where a run says each step it
/// starts) is read on a thread, so that a test signals a run once it has
/// reached a step instead of after a fixed sleep.
pub struct Watched {
    /// The process.
    pub child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Watched {
    /// Start `command` with its stderr read line by line.
    pub fn spawn(mut command: std::process::Command) -> Self {
        use std::io::BufRead;
        let mut child = command
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("gyrobench starts");
        let err = child.stderr.take().expect("stderr");
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            // Read to the end even if no one listens: a full pipe would
            // stall the run.
            for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
                let _unheard = tx.send(line);
            }
        });
        Self {
            child,
            lines,
            seen: Vec::new(),
        }
    }

    /// Wait until the process prints a line holding `needle` (at most
    /// 120 s); fails with every line seen if it ends or times out first.
    pub fn wait_for_line(&mut self, needle: &str) {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    let hit = line.contains(needle);
                    self.seen.push(line);
                    if hit {
                        return;
                    }
                }
                Err(why) => {
                    // Not left running behind a failed test.
                    let _killed = self.child.kill();
                    panic!("`{needle}` never printed ({why}): {:#?}", self.seen)
                }
            }
        }
    }

    /// Wait at most `limit` for the process to end (killed and failed
    /// past it, with every line it printed): its exit status and stderr.
    pub fn finish_within(
        mut self,
        limit: std::time::Duration,
    ) -> (std::process::ExitStatus, String) {
        let deadline = std::time::Instant::now() + limit;
        loop {
            if let Some(status) = self.child.try_wait().expect("waitable") {
                self.seen.extend(self.lines.iter());
                return (status, self.seen.join("\n"));
            }
            if std::time::Instant::now() > deadline {
                let _killed = self.child.kill();
                let _reaped = self.child.wait();
                self.seen.extend(self.lines.try_iter());
                panic!("still running {} s on: {:#?}", limit.as_secs(), self.seen);
            }
            match self
                .lines
                .recv_timeout(std::time::Duration::from_millis(100))
            {
                Ok(line) => self.seen.push(line),
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                // stderr closed: the process is ending.
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
            }
        }
    }

    /// Wait for the process to end: its exit status and all it printed on
    /// stderr.
    pub fn finish(mut self) -> (std::process::ExitStatus, String) {
        let status = self.child.wait().expect("it ends");
        self.seen.extend(self.lines.iter());
        (status, self.seen.join("\n"))
    }
}

/// Wait until `path` exists (a run started writing), at most 60 s.
pub fn wait_for(path: &Path) {
    for _ in 0..3000 {
        if path.exists() {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    panic!("{} never appeared", path.display());
}

/// (value, standard error) of measurement `name` in `report`.
pub fn figure(report: &serde_json::Value, name: &str) -> (f64, f64) {
    let m = report["measurements"]
        .as_array()
        .expect("measurements")
        .iter()
        .find(|m| m["name"] == name)
        .unwrap_or_else(|| panic!("no {name}: {report}"));
    (
        m["value"].as_f64().expect("a value"),
        m["std_error"].as_f64().expect("a standard error"),
    )
}
