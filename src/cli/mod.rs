//! Command-line interface: argument parsing, dispatch, exit codes.
//!
//! Each subcommand lives in its own file with `run(args) -> Result<Outcome>`;
//! rendering (`render_*` -> String) is kept apart from printing so it can be
//! unit tested. Results go to stdout, diagnostics to stderr.

/// `print!` to stdout through [`out`].
macro_rules! outf {
    ($($t:tt)*) => { $crate::cli::out(&format!($($t)*)) };
}

/// `eprintln!` that never fails: progress, notes and warnings on stderr
/// must not stop a run when nobody reads them any more (`2>&1 | head`).
macro_rules! errln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _unread = writeln!(std::io::stderr().lock(), $($t)*);
    }};
}

/// `println!` to stdout through [`out`].
macro_rules! outln {
    ($($t:tt)*) => { $crate::cli::out(&format!("{}\n", format_args!($($t)*))) };
}

/// `--help`'s closing for every command, in one layout: one example and
/// the exit codes (`plain`: a command that does its job or not; `store`:
/// one of the results store's).
macro_rules! after_help {
    ($example:literal, store) => {
        after_help!(
            $example,
            "0 done, 1 error (a store that cannot be reached, no such run or measurement), \
             2 usage (bad filters, the store `none`)"
        )
    };
    ($example:literal, plain) => {
        after_help!(
            $example,
            "0 done, 1 error (a file that cannot be read or written, bad data), 2 usage (bad arguments)"
        )
    };
    ($example:literal, $codes:literal) => {
        concat!("Example:\n  ", $example, "\n\nExit codes: ", $codes, ".")
    };
}

mod allan;
mod calibrate;
mod check;
mod diagnose;
mod import;
mod progress;
mod recover;
mod replay;
mod results;
mod run;
mod sim;
mod station;
mod twin;

use std::io::Write;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::{Parser, Subcommand};

/// Set once stdout's reader went away.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);

/// Write `text` to stdout. A reader that went away (`gyrobench ... | head
/// -1`) is not an error: the rest of the output is dropped quietly and the
/// command goes on to its end, so its files are complete and its exit code
/// is its own.
pub fn out(text: &str) -> std::io::Result<()> {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return Ok(());
    }
    let mut o = std::io::stdout().lock();
    match o.write_all(text.as_bytes()).and_then(|()| o.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
            STDOUT_CLOSED.store(true, Ordering::Relaxed);
            Ok(())
        }
        r => r,
    }
}

/// How a command ended, mapped to the process exit code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Done (or the unit passed): exit 0.
    Success,
    /// The unit failed its limits (a conditional fail included): exit 3.
    Fail,
    /// The unit passed conditionally (non-binary rule: within its limits
    /// by less than its uncertainty): exit 4.
    ConditionalPass,
    /// A device or data failure ended the run (reported): exit 1.
    Error,
    /// Interrupted: exit 128 + the signal (130 Ctrl-C, 143 SIGTERM,
    /// 129 SIGHUP, 131 SIGQUIT).
    Interrupted(u8),
}

/// On stderr: `file` was cut short (a run killed mid-way); `done` says
/// what was made of what it holds.
pub fn warn_incomplete(file: &std::path::Path, read: &crate::runlog::ReadSummary, done: &str) {
    if read.complete {
        return;
    }
    errln!(
        "warning: {} is incomplete ({}); {done}; {} bytes after the last complete chunk are missing",
        file.display(),
        read.stopped
            .as_deref()
            .unwrap_or("the run did not finish writing it"),
        read.bytes_lost
    );
}

/// A usage error found after parsing (a bad value, options that do not go
/// together, a run directory that is taken): exit 2, like clap's own.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Usage(pub String);

/// Exit code for an error (bad input, device or I/O failure).
pub const EXIT_ERROR: u8 = 1;
/// Exit code for a usage error.
pub const EXIT_USAGE: u8 = 2;
/// Exit code of a unit that passed conditionally (a procedure judged by
/// the non-binary decision rule): not a plain pass, not a fail.
pub const EXIT_CONDITIONAL_PASS: u8 = 4;

impl Outcome {
    /// The exit of a run that ended `o`, interrupted by signal code
    /// `signal` when it was aborted.
    pub fn of_run(o: crate::sequencer::Outcome, signal: u8) -> Self {
        use crate::sequencer::Outcome as Run;
        match o {
            Run::Pass => Self::Success,
            Run::Fail | Run::ConditionalFail => Self::Fail,
            Run::ConditionalPass => Self::ConditionalPass,
            Run::Error => Self::Error,
            Run::Aborted => Self::Interrupted(signal),
        }
    }
}

impl Outcome {
    fn code(self) -> u8 {
        match self {
            Self::Success => 0,
            Self::Fail => 3,
            Self::ConditionalPass => EXIT_CONDITIONAL_PASS,
            Self::Error => EXIT_ERROR,
            Self::Interrupted(code) => code,
        }
    }
}

#[derive(Debug, Parser)]
#[command(
    name = "gyrobench",
    version,
    about = "Hardware-in-the-loop test bench controller for ring laser gyroscopes",
    after_help = after_help!(
        "gyrobench run procedures/acceptance.toml",
        "0 success (for a run: the unit passed), 1 error, 2 usage, 3 the unit failed its limits, \
         4 it passed conditionally (a non-binary decision rule), \
         130 Ctrl-C, 143 SIGTERM, 129 SIGHUP, 131 SIGQUIT; `gyrobench COMMAND --help` gives each \
         command's"
    )
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run an acceptance procedure: log to MCAP, judge, report.
    Run(run::RunArgs),
    /// Rewrite the log of a killed run as a complete, indexed file.
    Recover(recover::RecoverArgs),
    /// Allan deviation, confidence intervals and noise terms of a log or CSV.
    Allan(allan::AllanArgs),
    /// Fit the thermal compensation on recorded runs and write coefficients.
    Calibrate(calibrate::CalibrateArgs),
    /// A run recorded elsewhere (interchange CSV) as a log.
    Import(import::ImportArgs),
    /// A log as interchange CSV at 1 Hz.
    Export(import::ExportArgs),
    /// Where the simulator and recorded runs disagree, and which effect explains it.
    Diagnose(diagnose::DiagnoseArgs),
    /// Recompute a run's measurements and verdict from its log alone.
    Replay(replay::ReplayArgs),
    /// Every run of every unit: list, show, unit history, trends, JUnit
    /// and CSV exports, sync from run directories.
    Results(results::ResultsArgs),
    /// Validate a procedure and print its plan with estimated device times.
    Check(check::CheckArgs),
    /// The simulated RL-16 and its bench (digital twin).
    #[command(subcommand, after_help = after_help!("gyrobench twin study", plain))]
    Twin(twin::TwinCommand),
    /// The operator's page: run, watch and answer procedures from a browser.
    Station(station::StationArgs),
    /// Simulated instruments speaking the real protocols.
    #[command(subcommand, after_help = after_help!("gyrobench sim serve", plain))]
    Sim(sim::SimCommand),
}

/// The command tree, as `--help` shows it (the tests walk it to check every
/// command's help).
pub fn command() -> clap::Command {
    <Cli as clap::CommandFactory>::command()
}

/// Parse arguments, run, print the error chain once, and map to an exit code.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { EXIT_USAGE } else { 0 });
        }
    };
    let result = match cli.command {
        Command::Run(args) => run::run(args),
        Command::Check(args) => check::run(args),
        Command::Recover(args) => recover::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Results(args) => results::run(args),
        Command::Allan(args) => allan::run(args),
        Command::Diagnose(args) => diagnose::run(args),
        Command::Import(args) => import::run_import(args),
        Command::Export(args) => import::run_export(args),
        Command::Calibrate(args) => calibrate::run(args),
        Command::Twin(cmd) => twin::run(cmd),
        Command::Sim(cmd) => sim::run(cmd),
        Command::Station(args) => station::run(args),
    };
    match result {
        Ok(outcome) => ExitCode::from(outcome.code()),
        Err(e) => {
            errln!("error: {e:#}");
            // An output that is one of the inputs, or in a run directory,
            // is a bad pair of arguments.
            let usage = e.chain().any(|c| {
                c.is::<Usage>()
                    || c.is::<crate::fsutil::SamePath>()
                    || c.is::<crate::fsutil::OutputRefused>()
            });
            ExitCode::from(if usage { EXIT_USAGE } else { EXIT_ERROR })
        }
    }
}
