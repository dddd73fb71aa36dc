//! `gyrobench twin ...`: run the study on the simulated RL-16, benchmark it.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};

use super::{Outcome, Usage};
use crate::clock::time_it;
use crate::study::{StudyReport, interchange_csv, run_study};
use crate::twin::{Twin, TwinConfig};

#[derive(Debug, Subcommand)]
pub enum TwinCommand {
    /// Run the study's thermal cycle (-40..+50 degC, starting with the
    /// self-heating half hour at +20 degC) on the twin and print its figures.
    #[command(after_help = after_help!("gyrobench twin study --seed 7 --json", plain))]
    Study(StudyArgs),
    /// Measure how fast the twin simulates: frames/s and times real time.
    #[command(after_help = after_help!("gyrobench twin bench --hours 1", plain))]
    Bench(BenchArgs),
    /// Print the default twin configuration (fixtures/twin/rl16.toml).
    #[command(after_help = after_help!("gyrobench twin default-config > my-twin.toml", plain))]
    DefaultConfig,
}

#[derive(Debug, Args)]
pub struct StudyArgs {
    /// Twin configuration (default: the embedded RL-16 twin).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Seed of the random terms.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Also write the 1 Hz series as an interchange CSV (not a run's log,
    /// nor inside a run directory, without --force).
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Write the --csv even if it is a run's log or inside a run directory.
    #[arg(long, requires = "csv")]
    force: bool,
}

#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Hours of device time to simulate.
    #[arg(long, default_value_t = 10.0)]
    hours: f64,
    /// Twin configuration (default: the embedded RL-16 twin).
    #[arg(long)]
    config: Option<PathBuf>,
}

fn load(config: Option<&PathBuf>) -> Result<TwinConfig> {
    match config {
        Some(path) => TwinConfig::load(path).context("loading the twin file"),
        None => Ok(TwinConfig::default_rl16()),
    }
}

pub fn run(cmd: TwinCommand) -> Result<Outcome> {
    match cmd {
        TwinCommand::Study(args) => {
            if let Some(path) = &args.csv {
                let inputs: Vec<&std::path::Path> =
                    args.config.iter().map(PathBuf::as_path).collect();
                crate::fsutil::check_output(
                    path,
                    crate::fsutil::OutputRule {
                        inputs: &inputs,
                        force: args.force,
                        own: None,
                    },
                )?;
            }
            let cfg = load(args.config.as_ref())?;
            errln!(
                "simulating the 6.5 h thermal cycle at {} Hz ...",
                cfg.gyro.frame_rate_hz
            );
            let (report, wall_s) = time_it(|| run_study(&cfg, args.seed));
            let (report, series) = report.context("running the study on the twin")?;
            if let Some(path) = &args.csv {
                let text = interchange_csv(&series);
                crate::fsutil::write_output(path, text.as_bytes())
                    .with_context(|| format!("writing {}", path.display()))?;
                errln!("wrote {}", path.display());
            }
            if args.json {
                outln!("{}", serde_json::to_string_pretty(&report)?)?;
            } else {
                outf!("{}", render_study(&report))?;
            }
            errln!("done in {wall_s:.1} s of wall time");
            Ok(Outcome::Success)
        }
        TwinCommand::Bench(args) => {
            let cfg = load(args.config.as_ref())?;
            if !(args.hours > 0.0 && args.hours.is_finite()) {
                return Err(Usage("--hours must be a positive number".into()).into());
            }
            let device_s = args.hours * 3600.0;
            let mut twin = Twin::new(cfg, 1);
            let mut sum: i64 = 0;
            let ((), wall_s) =
                time_it(|| twin.run_until(device_s, |_, g| sum += i64::from(g.delta_counts)));
            outf!(
                "{}",
                render_bench(
                    device_s,
                    twin.config().gyro.frame_rate_hz,
                    wall_s,
                    peak_rss_kib()
                )
            )?;
            errln!("(checksum of counts: {sum})");
            Ok(Outcome::Success)
        }
        TwinCommand::DefaultConfig => {
            outf!("{}", crate::twin::config::DEFAULT_TWIN_TOML)?;
            Ok(Outcome::Success)
        }
    }
}

/// Peak resident memory of this process, KiB (Linux; `None` elsewhere).
fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

pub fn render_bench(device_s: f64, rate_hz: f64, wall_s: f64, rss_kib: Option<u64>) -> String {
    let frames = device_s * rate_hz;
    let mut s = format!(
        "device time      {:.1} h at {rate_hz} Hz ({frames:.0} frames)\nwall time        {wall_s:.2} s\nframes/s         {:.3e}\nreal-time factor {:.0}x\n",
        device_s / 3600.0,
        frames / wall_s,
        device_s / wall_s,
    );
    if let Some(kib) = rss_kib {
        s.push_str(&format!(
            "peak RSS         {:.1} MiB\n",
            kib as f64 / 1024.0
        ));
    }
    s
}

pub fn render_study(r: &StudyReport) -> String {
    let t = &r.thermal;
    let tau = t.model4.warmup_tau_s.unwrap_or(f64::NAN);
    let sh = r
        .self_heating_dph
        .map_or("n/a".to_owned(), |v| format!("{:.3}", v.abs()));
    format!(
        "RL-16 twin, thermal cycle -40..+50 degC at 1 degC/min (seed {seed}, {hours:.1} h, {frames} frames)\n\
         \n\
         figure                                         deg/h    study\n\
         self-heating, first 30 min at +20 degC         {sh:>6}   ~0.5\n\
         raw drift, p-p of 600 s averages               {raw:>6.3}   0.6-0.7\n\
         compensated, model 1 (cubic in T_K)            {m1:>6.3}\n\
         compensated, model 3 (dT, dT^2, d(dT)/dt)      {m3:>6.3}\n\
         compensated, model 4 (+ T_K, F(tau))           {m4:>6.3}   0.03-0.05\n\
         bias stability, 1-sigma of 100 s, raw          {bsr:>6.4}\n\
         bias stability, 1-sigma of 100 s, model 4      {bsc:>6.4}\n\
         \n\
         Earth rate removed with the site latitude; compensation fitted on this run; \
         model-4 warm-up time constant {tau:.0} s.\n",
        seed = r.seed,
        hours = r.device_hours,
        frames = r.frames,
        raw = t.raw_drift_pp_dph,
        m1 = t.model1_drift_pp_dph,
        m3 = t.model3_drift_pp_dph,
        m4 = t.compensated_drift_pp_dph,
        bsr = t.raw_bias_stability_dph,
        bsc = t.compensated_bias_stability_dph,
    )
}
