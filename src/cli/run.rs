//! `gyrobench run PROCEDURE`: run an acceptance procedure, log it, judge it.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result};
use clap::Args;

use super::Outcome;
use super::check::load_bench;
use crate::analysis::series::Interval;
use crate::bench::BenchConfig;
use crate::bench::open_bench;
use crate::clock::{Pacing, VirtualClock, utc_now};
use crate::coeffs::CoeffsFile;
use crate::procedure::Procedure;
use crate::procedure::estimate::estimate;
use crate::protocol::frame::LinkStats;
use crate::recorder::{Recorder, RunMeta};
use crate::replay::{RESULT_META, add_link, logged, replay, result_entries, resume_from};
use crate::report::{Report, render_html};
use crate::sequencer::Resume;
use crate::sequencer::device::DeviceBench;
use crate::sequencer::embedded::{EmbeddedBench, Fault};
use crate::sequencer::guard::Guarded;
use crate::sequencer::{self, BenchIo, BenchState, Options, Progress, Sink};
use crate::twin::TwinConfig;

#[derive(Debug, Args)]
pub struct RunArgs {
    /// Procedure file (TOML), e.g. procedures/acceptance.toml.
    #[arg(required_unless_present = "resume")]
    procedure: Option<PathBuf>,
    /// Continue the interrupted run in DIR from its last completed step,
    /// logging into a new part file beside the first (procedure, bench,
    /// twin, coefficients, seed and unit come from its log).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["procedure", "bench", "out", "seed", "coeffs", "twin", "dut"])]
    resume: Option<PathBuf>,
    /// Bench file (default: the embedded simulated bench, on virtual time).
    #[arg(long)]
    bench: Option<PathBuf>,
    /// Run directory (default: runs/<procedure>-<UTC time>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Simulated bench speed: `max` or a factor over real time.
    #[arg(long, default_value = "max")]
    speed: String,
    /// Seed of the simulated bench.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Model-4 coefficients for compensation (default: fitted on the run).
    #[arg(long)]
    coeffs: Option<PathBuf>,
    /// Twin configuration of the simulated bench (default: the RL-16 twin).
    #[arg(long)]
    twin: Option<PathBuf>,
    /// Serial number of the unit under test.
    #[arg(long, default_value = "SIM-0001")]
    dut: String,
    /// Simulated bench only: play a fault, FAULT@SECONDS of device time
    /// (chamber-alarm, chamber-silent, table-interlock, gyro-silent).
    #[arg(long, value_name = "FAULT@SECONDS")]
    inject: Vec<String>,
}

/// Progress on stderr: a live bar on a terminal, plain lines otherwise.
struct Live {
    bar: Option<indicatif::ProgressBar>,
    last_line_s: f64,
}

impl Live {
    fn new(total_s: f64) -> Self {
        use std::io::IsTerminal;
        let bar = std::io::stderr().is_terminal().then(|| {
            let b = indicatif::ProgressBar::new(total_s.max(1.0) as u64);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "{bar:30} {pos}/{len} s device time  {msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            b
        });
        Self {
            bar,
            last_line_s: 0.0,
        }
    }
}

impl Progress for Live {
    fn step(&mut self, s: &crate::procedure::Step, i: usize, n: usize) {
        let line = format!("[{}/{n}] {}", i + 1, s.describe());
        match &self.bar {
            Some(b) => b.println(line),
            None => eprintln!("{line}"),
        }
    }

    fn prompt(&mut self, text: &str) {
        use std::io::IsTerminal;
        if !std::io::stdin().is_terminal() {
            eprintln!("prompt (no terminal, going on): {text}");
            return;
        }
        let ask = format!("{text} -- press Enter to continue");
        match &self.bar {
            Some(b) => b.suspend(|| eprintln!("{ask}")),
            None => eprintln!("{ask}"),
        }
        let mut line = String::new();
        let _ = std::io::stdin().read_line(&mut line);
    }

    fn tick(&mut self, st: &BenchState, iv: Option<&Interval>) {
        let rate = iv.map_or(String::new(), |iv| {
            format!(
                "  rate {:+.3} deg/h  T1/T2/TK {:.2}/{:.2}/{:.2} degC",
                iv.bias_dph(),
                iv.t1_c,
                iv.t2_c,
                iv.tcase_c
            )
        });
        let msg = format!(
            "chamber {:+.2} degC (set {:+.1}){rate}",
            st.chamber.air_c, st.chamber.set_point_c
        );
        match &self.bar {
            Some(b) => {
                b.set_position(st.t_s as u64);
                b.set_message(msg);
            }
            None if st.t_s - self.last_line_s >= 3600.0 => {
                self.last_line_s = st.t_s;
                eprintln!("  t = {:.2} h  {msg}", st.t_s / 3600.0);
            }
            None => {}
        }
    }
}

fn parse_inject(s: &str) -> Result<(f64, Fault)> {
    let (f, t) = s.split_once('@').with_context(|| {
        format!("--inject {s:?}: expected FAULT@SECONDS, e.g. chamber-silent@600")
    })?;
    let fault: Fault = f.parse().map_err(anyhow::Error::msg)?;
    let at: f64 = t
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v >= 0.0)
        .with_context(|| format!("--inject {s:?}: the time must be seconds of device time"))?;
    Ok((at, fault))
}

fn pacing(speed: &str) -> Result<Pacing> {
    if speed == "max" {
        return Ok(Pacing::Max);
    }
    let f: f64 = speed
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v > 0.0)
        .with_context(|| format!("--speed {speed:?}: expected `max` or a positive factor"))?;
    Ok(Pacing::Factor(f))
}

/// What a run (or a resumed part of one) works with.
struct Setup {
    procedure: Procedure,
    procedure_path: String,
    bench_cfg: BenchConfig,
    bench_label: String,
    twin: TwinConfig,
    coeffs_file: Option<CoeffsFile>,
    /// The run's seed (reported); a resumed part seeds its twin with
    /// `seed + part - 1` (a new power-on, fresh noise).
    seed: u64,
    dut: String,
    out: Option<PathBuf>,
    /// UTC start of the run (of its first part).
    start_time_utc: Option<String>,
    resume: Option<Resumed>,
}

struct Resumed {
    state: Resume,
    previous_file: String,
    link: LinkStats,
}

fn fresh(args: &RunArgs, procedure_path: &Path) -> Result<Setup> {
    let bench_cfg = load_bench(args.bench.as_ref())?;
    let procedure = Procedure::load(procedure_path, &bench_cfg)
        .with_context(|| format!("checking procedure {}", procedure_path.display()))?;
    let twin = match &args.twin {
        Some(p) => TwinConfig::load(p).with_context(|| format!("loading twin {}", p.display()))?,
        None => TwinConfig::default_rl16(),
    };
    let coeffs_file = match &args.coeffs {
        Some(p) => Some(
            CoeffsFile::load(p).with_context(|| format!("loading coefficients {}", p.display()))?,
        ),
        None => None,
    };
    anyhow::ensure!(
        bench_cfg.is_embedded() || args.twin.is_none(),
        "--twin applies to the embedded simulated bench only"
    );
    Ok(Setup {
        procedure,
        procedure_path: procedure_path.display().to_string(),
        bench_label: args
            .bench
            .as_ref()
            .map_or("embedded".into(), |p| p.display().to_string()),
        bench_cfg,
        twin,
        coeffs_file,
        seed: args.seed,
        dut: args.dut.clone(),
        out: args.out.clone(),
        start_time_utc: None,
        resume: None,
    })
}

/// The newest part of the run in `dir`: `run.mcap`, `run.part2.mcap`, ...
fn last_part(dir: &Path) -> Result<PathBuf> {
    let first = dir.join("run.mcap");
    anyhow::ensure!(
        first.exists(),
        "{} holds no run.mcap: not a run directory",
        dir.display()
    );
    let mut n = 1;
    while dir.join(format!("run.part{}.mcap", n + 1)).exists() {
        n += 1;
    }
    Ok(if n == 1 {
        first
    } else {
        dir.join(format!("run.part{n}.mcap"))
    })
}

fn resumed(dir: &Path) -> Result<Setup> {
    let last = last_part(dir)?;
    let prev = replay(&last, None).with_context(|| format!("reading {}", last.display()))?;
    anyhow::ensure!(
        matches!(
            prev.result.outcome,
            sequencer::Outcome::Error | sequencer::Outcome::Aborted
        ),
        "the run in {} finished (outcome {:?}); there is nothing to resume",
        dir.display(),
        prev.result.outcome
    );
    let meta = |k: &str| prev.meta.get(k).cloned().unwrap_or_default();
    let config = logged(&prev.meta).map_err(|e| anyhow::anyhow!("{}: {e}", last.display()))?;
    let completed = prev.completed_steps;
    let state = resume_from(&prev, completed);
    let start_at = state.start_at;
    eprintln!(
        "resuming {}: {} of {} steps completed, going on from step {} (last part {}, ended: {})",
        dir.display(),
        completed,
        prev.procedure.setup.len() + prev.procedure.main.len(),
        start_at + 1,
        last.display(),
        prev.result
            .error
            .as_ref()
            .map_or("-".to_owned(), |e| format!(
                "{} in step {}",
                e.message, e.step
            ))
    );
    Ok(Setup {
        procedure: prev.procedure.clone(),
        procedure_path: meta("procedure_path"),
        bench_label: prev
            .meta
            .get("bench")
            .cloned()
            .unwrap_or_else(|| "embedded".into()),
        bench_cfg: config.bench,
        twin: config.twin.unwrap_or_else(TwinConfig::default_rl16),
        coeffs_file: config.coeffs,
        seed: meta("seed").parse().unwrap_or(1),
        dut: meta("dut_serial"),
        out: Some(dir.to_path_buf()),
        start_time_utc: Some(meta("start_time_utc")),
        resume: Some(Resumed {
            state,
            previous_file: last
                .file_name()
                .map_or(String::new(), |f| f.to_string_lossy().into_owned()),
            link: prev.link,
        }),
    })
}

pub fn run(args: RunArgs) -> Result<Outcome> {
    let setup = match (&args.resume, &args.procedure) {
        (Some(dir), _) => resumed(dir)?,
        (None, Some(p)) => fresh(&args, p)?,
        (None, None) => anyhow::bail!("give a procedure file or --resume DIR"),
    };
    let Setup {
        procedure,
        procedure_path,
        bench_cfg,
        bench_label,
        twin,
        coeffs_file,
        seed,
        dut,
        out,
        start_time_utc,
        resume,
    } = setup;
    let embedded = bench_cfg.is_embedded();
    let specs = [
        &bench_cfg.devices.chamber.spec,
        &bench_cfg.devices.table.spec,
        &bench_cfg.devices.gyro.spec,
    ];
    anyhow::ensure!(
        embedded || specs.iter().all(|s| !s.starts_with("sim://")),
        "the bench file mixes sim:// and real devices; use all sim:// (the embedded bench) or none"
    );
    anyhow::ensure!(
        embedded || args.inject.is_empty(),
        "--inject applies to the embedded simulated bench only"
    );
    let coeffs = coeffs_file.as_ref().map(CoeffsFile::fit);
    let part = resume.as_ref().map_or(1, |r| r.state.part);
    let faults: Vec<(f64, Fault)> = args
        .inject
        .iter()
        .map(|s| parse_inject(s))
        .collect::<Result<_>>()?;
    let pacing = pacing(&args.speed)?;

    let start = utc_now();
    let run_start = start_time_utc.unwrap_or_else(|| start.to_rfc3339());
    let out = out.unwrap_or_else(|| {
        PathBuf::from("runs").join(format!(
            "{}-{}",
            procedure.meta.name,
            start.format("%Y%m%dT%H%M%SZ")
        ))
    });
    std::fs::create_dir_all(&out)
        .with_context(|| format!("creating the run directory {}", out.display()))?;

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let limits = bench_cfg.limits.clone();
    let mut bench: Box<dyn BenchIo> = if embedded {
        let clock = Arc::new(VirtualClock::new(pacing));
        let mut b = EmbeddedBench::new(twin.clone(), seed.wrapping_add(u64::from(part) - 1), clock);
        for (at, f) in faults {
            b.schedule(at, f);
        }
        Box::new(Guarded::new(b, limits))
    } else {
        let open = rt
            .block_on(open_bench(&bench_cfg))
            .context("opening the bench's devices")?;
        let device = rt
            .block_on(DeviceBench::start(&bench_cfg, open))
            .context("bringing the bench up (servo on, first reading)")?;
        Box::new(Guarded::new(device, limits))
    };
    let mut meta = RunMeta::default();
    for (k, v) in [
        ("procedure_toml", procedure.text.clone()),
        ("procedure_path", procedure_path.clone()),
        (
            "bench_toml",
            toml::to_string_pretty(&bench_cfg).unwrap_or_default(),
        ),
        (
            "twin_toml",
            if embedded {
                twin.to_toml()
            } else {
                String::new()
            },
        ),
        (
            "site",
            serde_json::to_string(&bench_cfg.site).unwrap_or_default(),
        ),
        ("dut_serial", dut.clone()),
        ("dut_type", procedure.meta.dut_type.clone()),
        ("software_version", env!("CARGO_PKG_VERSION").to_owned()),
        ("start_time_utc", run_start.clone()),
        ("part_start_time_utc", start.to_rfc3339()),
        ("seed", seed.to_string()),
        ("part", part.to_string()),
        (
            "previous_part",
            resume
                .as_ref()
                .map_or(String::new(), |r| r.previous_file.clone()),
        ),
        (
            "resume_completed_steps",
            resume
                .as_ref()
                .map_or(String::new(), |r| r.state.completed.to_string()),
        ),
        ("speed", args.speed.clone()),
        ("bench", bench_label.clone()),
        (
            "coeffs_toml",
            coeffs_file
                .as_ref()
                .map(CoeffsFile::to_toml)
                .unwrap_or_default(),
        ),
    ] {
        meta.entries.insert(k.to_owned(), v);
    }
    let mcap_path = if part == 1 {
        out.join("run.mcap")
    } else {
        out.join(format!("run.part{part}.mcap"))
    };
    anyhow::ensure!(
        !mcap_path.exists() || resume.is_none(),
        "{} exists already",
        mcap_path.display()
    );
    let start_ns = start.timestamp_nanos_opt().unwrap_or(0).max(0) as u64;
    let mut recorder = Recorder::create(
        &mcap_path,
        &meta,
        start_ns,
        bench.frame_dt_s(),
        bench.lsb_arcsec(),
        bench.temp_lsb_c(),
    )
    .with_context(|| format!("creating {}", mcap_path.display()))?;

    let interrupt = Arc::new(AtomicBool::new(false));
    let opts = Options {
        coeffs,
        interrupt: interrupt.clone(),
        dut_max_c: bench_cfg.limits.dut_max_c,
        in_position: (
            bench_cfg.devices.table.in_position_deg,
            bench_cfg.devices.table.settle_s,
        ),
        move_timeout_s: 600.0,
        resume: resume.as_ref().map(|r| r.state.clone()),
    };
    eprintln!("running {} -> {}", procedure.meta.name, out.display());
    let result = rt.block_on(async {
        watch_ctrl_c(interrupt)?;
        let total: f64 = estimate(&procedure, &bench_cfg)
            .iter()
            .map(|(_, e)| e.min_s)
            .sum();
        let mut progress = Live::new(total);
        Ok::<_, anyhow::Error>(
            sequencer::run(
                &procedure,
                bench.as_mut(),
                &mut recorder,
                &mut progress,
                &opts,
            )
            .await,
        )
    })?;
    let part_link = bench.link_stats();
    let link = match &resume {
        Some(r) => add_link(&r.link, &part_link),
        None => part_link,
    };
    recorder
        .link(bench.now_s(), &part_link)
        .and_then(|()| recorder.metadata(RESULT_META, result_entries(&result)))
        .and_then(|()| recorder.finish())
        .with_context(|| format!("finishing {}", mcap_path.display()))?;

    let report = Report::new(
        &procedure,
        &result,
        &dut,
        &run_start,
        link,
        embedded.then_some(seed),
        &bench_label,
    );
    write(&out.join("report.json"), report.to_json().as_bytes())?;
    write(
        &out.join("report.html"),
        render_html(&report, &result.records).as_bytes(),
    )?;
    print!("{}", report.render_text());
    eprintln!("log and report in {}", out.display());
    Ok(match result.outcome {
        sequencer::Outcome::Pass => Outcome::Success,
        sequencer::Outcome::Fail => Outcome::Fail,
        sequencer::Outcome::Error => Outcome::Error,
        sequencer::Outcome::Aborted => Outcome::Interrupted,
    })
}

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    crate::fsutil::write_atomic(path, bytes).with_context(|| format!("writing {}", path.display()))
}

/// First Ctrl-C: stop and clean up. Second: abort at once. The handler
/// is installed before this returns, so no early signal kills the run.
fn watch_ctrl_c(interrupt: Arc<AtomicBool>) -> Result<()> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut sigint = signal(SignalKind::interrupt()).context("installing the Ctrl-C handler")?;
    tokio::spawn(async move {
        if sigint.recv().await.is_some() {
            eprintln!("interrupted: running cleanup (Ctrl-C again to abort without cleanup)");
            interrupt.store(true, Ordering::Relaxed);
        }
        if sigint.recv().await.is_some() {
            eprintln!("aborted without cleanup");
            std::process::exit(130);
        }
    });
    Ok(())
}
