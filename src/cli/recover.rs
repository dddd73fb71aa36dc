//! `gyrobench recover RUN.mcap [-o OUT]`: a complete, indexed log from
//! what a killed run had flushed.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use super::Outcome;
use crate::fsutil::{OutputRule, check_output};
use crate::runlog::recover::recover;

#[derive(Debug, Args)]
#[command(after_help = after_help!(
    "gyrobench recover runs/killed/run.mcap",
    "0 recovered, 1 error (nothing of a run in the file, I/O, or damaged parts skipped: the output lacks them), 2 usage (an output that is the input, a run's log or in a run directory without --force)"
))]
pub struct RecoverArgs {
    /// The log of a run that did not finish (or any MCAP log).
    log: PathBuf,
    /// Where to write the recovered log (default: <log>-recovered.mcap
    /// beside it, its own place in the run's directory; another path in a
    /// run directory, or a run's log, only with --force).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Write the --out even if it is a run's log or inside a run
    /// directory.
    #[arg(long)]
    force: bool,
}

pub fn run(args: RecoverArgs) -> Result<Outcome> {
    let stem = args
        .log
        .file_stem()
        .map_or("run".into(), |s| s.to_string_lossy().into_owned());
    let own = args.log.with_file_name(format!("{stem}-recovered.mcap"));
    let out = args.out.unwrap_or_else(|| own.clone());
    check_output(
        &out,
        OutputRule {
            inputs: &[&args.log],
            force: args.force,
            own: Some(&own),
        },
    )?;
    let r = recover(&args.log, &out).context("recovering the log")?;
    if let Some(why) = &r.stopped {
        errln!(
            "warning: the read of {} stopped at a damaged record: {why}; what follows it is lost",
            args.log.display()
        );
    }
    super::out(&format!(
        "recovered {} messages ({} gyro frames) into {}; {} bytes after the last complete record were lost{}\n",
        r.messages,
        r.frames,
        out.display(),
        r.bytes_lost,
        if r.was_complete && r.damage.is_none() {
            " (the log was complete)"
        } else {
            ""
        }
    ))?;
    if let Some(d) = &r.damage {
        errln!(
            "error: {}: {d}; the recovered log holds everything else, and lacks these",
            args.log.display()
        );
        return Ok(Outcome::Error);
    }
    Ok(Outcome::Success)
}
