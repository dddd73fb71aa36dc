//! `gyrobench check PROCEDURE [--bench FILE]`: validate and print the plan.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::Outcome;
use gyrobench::bench::BenchConfig;
use gyrobench::procedure::Procedure;
use gyrobench::procedure::estimate::{Estimate, estimate};

#[derive(Debug, Args)]
#[command(after_help = after_help!(
    "gyrobench check procedures/acceptance.toml",
    "0 the procedure is valid on the bench, 1 it is not (file:line:column and the key say why), \
     2 usage"
))]
pub struct CheckArgs {
    /// Procedure file (TOML).
    procedure: PathBuf,
    /// Bench file (default: the embedded simulated bench).
    #[arg(long)]
    bench: Option<PathBuf>,
}

/// Load the bench file, or the embedded bench.
pub fn load_bench(path: Option<&PathBuf>) -> Result<BenchConfig> {
    match path {
        Some(p) => BenchConfig::load(p).context("loading the bench file"),
        None => Ok(BenchConfig::embedded()),
    }
}

pub fn run(args: CheckArgs) -> Result<Outcome> {
    let bench = load_bench(args.bench.as_ref())?;
    let limits = bench.procedure_limits();
    let p = Procedure::load(&args.procedure, &limits).context("checking the procedure")?;
    outf!("{}", render_plan(&p, &estimate(&p, &limits)))?;
    Ok(Outcome::Success)
}

fn hms(s: f64) -> String {
    let s = s.round() as u64;
    format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}

/// The plan as text: one line per step with its device time, then totals.
pub fn render_plan(p: &Procedure, est: &[(&gyrobench::procedure::Step, Estimate)]) -> String {
    let mut out = format!(
        "procedure {} ({}): {}\nspec: {}\n\n  {:<20} {:>4}  {:<17}  what\n",
        p.meta.name,
        p.meta.dut_type,
        p.meta.description,
        p.meta.spec,
        "step",
        "line",
        "device time"
    );
    let (mut lo, mut hi) = (0.0, 0.0);
    for (s, e) in est {
        let t = if e.min_s == e.max_s {
            hms(e.min_s)
        } else {
            format!("{}..{}", hms(e.min_s), hms(e.max_s))
        };
        out.push_str(&format!(
            "  {:<20} {:>4}  {:<17}  {}\n",
            s.key,
            s.line,
            t,
            s.describe()
        ));
        lo += e.min_s;
        hi += e.max_s;
    }
    let total = if lo == hi {
        hms(lo)
    } else {
        format!("{} .. {}", hms(lo), hms(hi))
    };
    out.push_str(&format!(
        "\n{} steps, {} measurements, estimated device time {total}\n",
        est.len(),
        p.measures().count()
    ));
    out
}
