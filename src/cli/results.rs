//! `gyrobench results ...`: the results store from the command line
//! (`docs/results.md`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};

use super::{Outcome, Usage};
use gyrobench::results::query::{Filter, MeasurementRow, RunRow, Trend, UnitHistory};
use gyrobench::results::{Location, RunState, Store};

#[derive(Debug, Args)]
pub struct StoreArgs {
    /// The results store: a SQLite file, a postgres:// URL (default:
    /// $GYROBENCH_DB, else ~/.local/share/gyrobench/results.sqlite).
    #[arg(long, global = true, value_name = "STORE")]
    db: Option<String>,
}

#[derive(Debug, Args)]
pub struct FilterArgs {
    /// Unit serial number.
    #[arg(long)]
    serial: Option<String>,
    /// Unit type (e.g. RL-16).
    #[arg(long = "type")]
    dut_type: Option<String>,
    /// Procedure name (e.g. acceptance).
    #[arg(long)]
    procedure: Option<String>,
    /// Outcome (reference: an imported run).
    #[arg(long, value_parser = run_state_words())]
    outcome: Option<RunState>,
    /// Bench (as the run named it) or station (host name).
    #[arg(long)]
    bench: Option<String>,
    /// Runs started on or after this UTC time or date (2026-03-01).
    #[arg(long)]
    since: Option<String>,
    /// Runs started before this UTC time or date.
    #[arg(long)]
    until: Option<String>,
    /// Count imported runs (stored as `reference`, never judged) in
    /// trends, yields and exports too.
    #[arg(long)]
    include_reference: bool,
    /// Count the simulated bench's unnamed unit (SIMULATED) in trends and
    /// yields too.
    #[arg(long)]
    include_simulated: bool,
    /// Only units whose compensated figures came from this source:
    /// fitted (within the run), file or store (the unit's set).
    #[arg(long, value_parser = ["fitted", "file", "store"])]
    coeffs_source: Option<String>,
    /// Only runs on this kind of bench: embedded (the simulated bench
    /// inside gyrobench), simulated (devices that identified themselves
    /// as gyrobench's simulators, `sim serve`), hardware, or imported.
    #[arg(long, value_enum)]
    bench_kind: Option<gyrobench::results::facts::BenchKind>,
}

impl FilterArgs {
    fn filter(&self, latest_only: bool, limit: Option<usize>) -> Result<Filter> {
        let outcome = self.outcome;
        for (flag, v) in [("--since", &self.since), ("--until", &self.until)] {
            if let Some(v) = v
                && !looks_like_a_time(v)
            {
                return Err(Usage(format!(
                    "{flag} {v:?}: expected a UTC date or time, e.g. 2026-03-01 or 2026-03-01T08:00:00Z"
                ))
                .into());
            }
        }
        Ok(Filter {
            serial: self.serial.clone(),
            dut_type: self.dut_type.clone(),
            procedure: self.procedure.clone(),
            outcome,
            bench: self.bench.clone(),
            since: self.since.clone(),
            until: self.until.clone(),
            latest_only,
            include_reference: self.include_reference
                || outcome == Some(RunState::Reference)
                || self.bench_kind == Some(gyrobench::results::facts::BenchKind::Imported),
            include_simulated: self.include_simulated
                || self.serial.as_deref() == Some(gyrobench::unit::SIMULATED_SERIAL),
            coeffs_source: self.coeffs_source.clone(),
            bench_kind: self.bench_kind,
            limit,
        })
    }
}

/// A date `YYYY-MM-DD`, optionally followed by a time: compared as text
/// with the stored RFC 3339 times.
fn looks_like_a_time(s: &str) -> bool {
    let b = s.as_bytes();
    b.len() >= 10
        && b[..4].iter().all(u8::is_ascii_digit)
        && b[4] == b'-'
        && b[5..7].iter().all(u8::is_ascii_digit)
        && b[7] == b'-'
        && b[8..10].iter().all(u8::is_ascii_digit)
}

#[derive(Debug, Subcommand)]
pub enum ResultsCommand {
    /// Runs, newest first.
    #[command(after_help = after_help!("gyrobench results list --serial RL16-0042 --outcome fail", store))]
    List {
        #[command(flatten)]
        filter: FilterArgs,
        /// At most this many rows.
        #[arg(long, default_value_t = 50)]
        limit: usize,
        /// Every part of a resumed run (default: each run's latest part).
        #[arg(long)]
        all_parts: bool,
        /// As JSON.
        #[arg(long)]
        json: bool,
    },
    /// One run whole: its record, measurements and parts.
    #[command(after_help = after_help!("gyrobench results show 3f2a9c", store))]
    Show {
        /// The run's id (or its start), as `results list` shows it, or its
        /// run directory.
        run: String,
        /// As JSON.
        #[arg(long)]
        json: bool,
    },
    /// A unit's history: every run and measurement, and its latest
    /// coefficient set.
    #[command(after_help = after_help!("gyrobench results unit RL16-0042", store))]
    Unit {
        /// Serial number.
        serial: String,
        /// As JSON.
        #[arg(long)]
        json: bool,
    },
    /// A measurement across units: count, mean, sigma, min/max, yield,
    /// Cpk; a chart page with --html.
    #[command(
        after_help = after_help!("gyrobench results trend compensated_drift_pp_dph --html trend.html", store)
    )]
    Trend {
        /// Measurement name, e.g. compensated_drift_pp_dph.
        measurement: String,
        #[command(flatten)]
        filter: FilterArgs,
        /// Fewest values a capability index is shown for (default 25:
        /// below it an index says little; lower it to look anyway, with
        /// the index's interval and a warning).
        #[arg(long, default_value_t = gyrobench::results::query::MIN_CAPABILITY_N, value_name = "N")]
        min_values: usize,
        /// Also write a chart page (values against time, limits); not a
        /// run's log, nor inside a run directory, without --force.
        #[arg(long, value_name = "FILE")]
        html: Option<PathBuf>,
        /// Write the --html page even if it is a run's log or inside a
        /// run directory.
        #[arg(long, requires = "html")]
        force: bool,
        /// As JSON.
        #[arg(long)]
        json: bool,
    },
    /// Runs as JUnit XML (one testsuite per run) or CSV (one row per
    /// measurement).
    #[command(
        after_help = after_help!("gyrobench results export --junit results.xml --since 2026-03-01", store)
    )]
    Export {
        #[command(flatten)]
        filter: FilterArgs,
        /// JUnit XML file to write (not a run's log, nor inside a run
        /// directory, without --force).
        #[arg(long, value_name = "FILE", required_unless_present = "csv")]
        junit: Option<PathBuf>,
        /// CSV file to write (as --junit).
        #[arg(long, value_name = "FILE")]
        csv: Option<PathBuf>,
        /// Write the files even if one is a run's log or inside a run
        /// directory.
        #[arg(long)]
        force: bool,
    },
    /// Whether the store tells the truth: every stored run checked against
    /// its log (there, the same SHA-256; every field of its record the log
    /// gives: unit, each unit's outcome and coefficients, operator, times,
    /// bench, host, software, procedure, instruments, each difference
    /// named with the store's value and the log's; the same figures,
    /// recomputed from the frames with --replay), and the logs below
    /// RUNS_DIR the store lacks.
    #[command(after_help = after_help!(
        "gyrobench results verify runs/ --replay",
        "0 the store and the logs agree, 3 they do not (each finding printed), 1 error (a store \
         that cannot be reached), 2 usage"
    ))]
    Verify {
        /// Check only the runs whose logs lie below this directory, and
        /// list the logs there the store lacks.
        runs_dir: Option<PathBuf>,
        /// Recompute every run's figures from its log's frames (slower)
        /// instead of reading its result record.
        #[arg(long)]
        replay: bool,
        /// As JSON.
        #[arg(long)]
        json: bool,
    },
    /// Sign a stored run: reviewed, then approved by another person. The
    /// signature binds the log's SHA-256 and the stored verdict and
    /// figures; `results verify` names a signed run that changed since.
    #[command(after_help = after_help!(
        "gyrobench results sign 0968c2e6 --role reviewed --by \"A. Quality\"",
        "0 signed, 1 error (a store that cannot be reached, no such run), 2 usage (refused: \
         a run not ended or imported, approved before a review or by the reviewer, signed twice)"
    ))]
    Sign {
        /// The run's id (or its start), as `results list` shows it, or its
        /// run directory.
        run: String,
        /// What the signature says: reviewed, or approved (after a review,
        /// by someone else).
        #[arg(long, value_parser = ["reviewed", "approved"])]
        role: String,
        /// Who signs.
        #[arg(long)]
        by: String,
        /// A remark kept with the signature.
        #[arg(long, default_value = "")]
        note: String,
    },
    /// Index run directories from their logs (idempotent: what the store
    /// has is left alone; a run left running is completed).
    #[command(after_help = after_help!("gyrobench results sync runs/", store))]
    Sync {
        /// Directories holding run directories (searched below).
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
    },
}

#[derive(Debug, Args)]
#[command(after_help = after_help!("gyrobench results list", store))]
pub struct ResultsArgs {
    #[command(flatten)]
    store: StoreArgs,
    #[command(subcommand)]
    command: ResultsCommand,
}

fn open(store: &StoreArgs) -> Result<Store> {
    let loc = Location::resolve(store.db.as_deref(), None);
    let mut s = Store::open(&loc)?.ok_or_else(|| {
        Usage("the results store is `none`: give --db or set GYROBENCH_DB".into())
    })?;
    let flushed = s.flush_pending();
    if flushed > 0 {
        errln!("{flushed} queued run(s) written to the results store");
    }
    Ok(s)
}

pub fn run(args: ResultsArgs) -> Result<Outcome> {
    let mut store = open(&args.store)?;
    match args.command {
        ResultsCommand::List {
            filter,
            limit,
            all_parts,
            json,
        } => {
            let rows = store.list(&filter.filter(!all_parts, Some(limit))?)?;
            if json {
                outln!("{}", serde_json::to_string_pretty(&rows)?)?;
            } else {
                outf!("{}", render_list(&rows))?;
                errln!("{} run(s) from {}", rows.len(), store.name());
            }
        }
        ResultsCommand::Show { run, json } => {
            let run = run_id_of_dir(&run).unwrap_or(run);
            let d = store.show(&run)?;
            if json {
                outln!("{}", serde_json::to_string_pretty(&d)?)?;
            } else {
                outf!(
                    "{}",
                    render_run(&d.run, &d.fields, &d.measurements, &d.parts)
                )?;
                outf!("{}", render_signatures(&d.signatures))?;
            }
        }
        ResultsCommand::Sign {
            run,
            role,
            by,
            note,
        } => {
            let role = gyrobench::results::sign::Role::parse(&role)
                .ok_or_else(|| Usage(format!("--role {role:?}: reviewed or approved")))?;
            let run = run_id_of_dir(&run).unwrap_or(run);
            match store.sign(&run, role, &by, &note) {
                Ok(s) => errln!(
                    "{}: {} by {} at {} (log sha256 {}, figures {})",
                    s.run,
                    s.role,
                    gyrobench::view::printable(&s.by),
                    s.signed_utc,
                    s.log_sha256.get(..12).unwrap_or(&s.log_sha256),
                    s.figures_sha256.get(..12).unwrap_or(&s.figures_sha256)
                ),
                Err(gyrobench::results::StoreError::Refused { why }) => {
                    return Err(Usage(why).into());
                }
                Err(e) => return Err(e.into()),
            }
        }
        ResultsCommand::Unit { serial, json } => {
            let h = store.unit(&serial)?;
            if json {
                outln!("{}", serde_json::to_string_pretty(&h)?)?;
            } else {
                outf!("{}", render_unit(&h))?;
            }
        }
        ResultsCommand::Trend {
            measurement,
            filter,
            min_values,
            html,
            force,
            json,
        } => {
            check_outputs(html.iter(), force)?;
            let f = filter.filter(true, None)?;
            let t = store.trend(&measurement, &f, min_values)?;
            if let Some(path) = &html {
                let points = store.trend_points(&measurement, &f, 5000)?;
                write_trend_page(path, &t, &points)?;
            }
            if json {
                outln!("{}", serde_json::to_string_pretty(&t)?)?;
            } else {
                outf!("{}", render_trend(&t))?;
            }
        }
        ResultsCommand::Export {
            filter,
            junit,
            csv,
            force,
        } => {
            check_outputs(junit.iter().chain(&csv), force)?;
            let rows = store.export_rows(&filter.filter(true, None)?)?;
            if let Some(path) = &junit {
                let xml = gyrobench::results::junit::junit(&rows).context("writing JUnit XML")?;
                gyrobench::fsutil::write_output(path, xml.as_bytes())
                    .with_context(|| format!("writing {}", path.display()))?;
                errln!("{} run(s) as JUnit XML in {}", rows.len(), path.display());
            }
            if let Some(path) = &csv {
                let text = gyrobench::results::junit::csv(&rows).context("writing CSV")?;
                gyrobench::fsutil::write_output(path, text.as_bytes())
                    .with_context(|| format!("writing {}", path.display()))?;
                errln!("{} run(s) as CSV in {}", rows.len(), path.display());
            }
        }
        ResultsCommand::Verify {
            runs_dir,
            replay,
            json,
        } => {
            if let Some(d) = &runs_dir
                && !d.is_dir()
            {
                return Err(Usage(format!("{}: not a directory", d.display())).into());
            }
            let v = store.verify(runs_dir.as_deref(), replay)?;
            if json {
                outln!("{}", serde_json::to_string_pretty(&v)?)?;
            } else {
                outf!("{}", v.render_text())?;
            }
            if !v.clean() {
                return Ok(Outcome::Fail);
            }
        }
        ResultsCommand::Sync { dirs } => return sync(&mut store, &dirs),
    }
    Ok(Outcome::Success)
}

/// The files a command will write, each checked before anything is done
/// (`fsutil::check_output`).
fn check_outputs<'a>(paths: impl Iterator<Item = &'a PathBuf>, force: bool) -> Result<()> {
    for p in paths {
        gyrobench::fsutil::check_output(
            p,
            gyrobench::fsutil::OutputRule {
                force,
                ..Default::default()
            },
        )?;
    }
    Ok(())
}

/// The trend's chart page at `path`, each point linked to its report.
fn write_trend_page(
    path: &std::path::Path,
    t: &Trend,
    points: &[gyrobench::results::query::TrendPoint],
) -> Result<()> {
    let page_dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."))
        .to_owned();
    let link = |p: &gyrobench::results::query::TrendPoint| {
        gyrobench::results::page::report_link(p, &page_dir)
    };
    gyrobench::fsutil::write_output(
        path,
        gyrobench::results::page::trend_page(t, points, &link).as_bytes(),
    )
    .with_context(|| format!("writing {}", path.display()))?;
    errln!("chart page in {}", path.display());
    Ok(())
}

/// `results sync`: index each run directory's logs; an error when one
/// could not be read.
fn sync(store: &mut Store, dirs: &[PathBuf]) -> Result<Outcome> {
    let mut failed_any = false;
    for d in dirs {
        anyhow::ensure!(d.is_dir(), "{}: not a directory", d.display());
        let synced = store.sync_dir(d);
        outln!(
            "{}: {} part(s) indexed, {} already in {} ({} of them unchanged since the last sync, not read)",
            d.display(),
            synced.added,
            synced.there + synced.unchanged,
            store.name(),
            synced.unchanged
        )?;
        let failed = synced.failed;
        for f in &failed {
            errln!("warning: {f}");
        }
        failed_any |= !failed.is_empty();
    }
    Ok(if failed_any {
        Outcome::Error
    } else {
        Outcome::Success
    })
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

fn lim(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| format!("{v}"))
}

/// The list as a table.
pub fn render_list(rows: &[RunRow]) -> String {
    let mut s = format!(
        "{:<25} {:<36} {:<8} {:<14} {:<14} {:<12} {:<8}\n",
        "started (UTC)", "run", "type", "serial", "procedure", "bench", "outcome"
    );
    // Stored text is shown, never obeyed: a control character in it is
    // written as an escape, not sent to the terminal.
    let p = gyrobench::view::printable;
    for r in rows {
        s.push_str(&format!(
            "{:<25} {:<36} {:<8} {:<14} {:<14} {:<12} {:<8}\n",
            p(r.started_utc.get(..19).unwrap_or(&r.started_utc)),
            p(&r.id),
            p(&r.dut_type),
            p(&r.serial),
            p(&r.procedure),
            p(&r.bench),
            p(&r.outcome.as_str().to_uppercase())
        ));
    }
    s
}

fn render_measurements(ms: &[MeasurementRow]) -> String {
    let mut s = String::new();
    for m in ms {
        s.push_str(&format!(
            "  {:<32} {:>12} {:<10} {:<18} [{}..{}]  {}\n",
            m.name,
            opt(m.value, 4),
            m.unit,
            m.uncertainty.map_or(String::new(), |u| format!(
                "± {:.4} (k={:.2})",
                u.expanded, u.k
            )),
            lim(m.low),
            lim(m.high),
            m.outcome.as_str().to_uppercase()
        ));
    }
    s
}

/// The run id of run directory `arg` (its report's), when it is one.
fn run_id_of_dir(arg: &str) -> Option<String> {
    let dir = std::path::Path::new(arg);
    if !dir.is_dir() {
        return None;
    }
    let report = std::fs::read_dir(dir)
        .ok()?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("report") && n.ends_with(".json"))
        })
        .min()?;
    let bytes = gyrobench::config::read_at_most(&report, 64 << 20).ok()?;
    let v: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    v["run_id"]
        .as_str()
        .filter(|s| !s.is_empty())
        .map(str::to_owned)
}

/// A run's signatures for the terminal (or that it has none).
fn render_signatures(signed: &[gyrobench::results::sign::Signature]) -> String {
    let p = gyrobench::view::printable;
    if signed.is_empty() {
        return "signatures: none (results sign RUN --role reviewed|approved --by NAME)\n".into();
    }
    let mut s = String::from("signatures:\n");
    for g in signed {
        s.push_str(&format!(
            "  {:<9} by {} at {} (log sha256 {}){}\n",
            g.role,
            p(&g.by),
            g.signed_utc,
            g.log_sha256.get(..12).unwrap_or(&g.log_sha256),
            if g.note.is_empty() {
                String::new()
            } else {
                format!(": {}", p(&g.note))
            }
        ));
    }
    s
}

/// One run as text.
pub fn render_run(
    run: &RunRow,
    fields: &[(String, String)],
    ms: &[MeasurementRow],
    parts: &[RunRow],
) -> String {
    let p = gyrobench::view::printable;
    let mut s = format!(
        "{}: {} on {} {} (run {}, part {}{})\n",
        run.outcome.as_str().to_uppercase(),
        p(&run.procedure),
        p(&run.dut_type),
        p(&run.serial),
        run.id,
        run.part,
        if run.latest {
            ""
        } else {
            ", superseded by a later part"
        }
    );
    s.push_str(&format!(
        "  started {}  bench {}  station {}  operator {}\n",
        run.started_utc,
        p(&run.bench),
        p(&run.station),
        if run.operator.is_empty() {
            "-".into()
        } else {
            p(&run.operator)
        }
    ));
    for (k, v) in fields.iter().filter(|(_, v)| !v.is_empty()) {
        s.push_str(&format!("  {k}: {v}\n"));
    }
    s.push_str(&render_measurements(ms));
    if parts.len() > 1 {
        s.push_str("  parts:\n");
        for p in parts {
            s.push_str(&format!(
                "    {} {} {}\n",
                p.id,
                p.started_utc,
                p.outcome.as_str().to_uppercase()
            ));
        }
    }
    s
}

/// A unit's history as text: one block per run, and the coefficients.
pub fn render_unit(h: &UnitHistory) -> String {
    let p = gyrobench::view::printable;
    let mut s = format!("unit {}: {} run(s)\n", p(&h.serial), h.runs.len());
    for r in &h.runs {
        s.push_str(&format!(
            "{} {} {} {} ({})\n  by {} on bench {}, gyrobench {}; coefficients: {}{}\n",
            r.started_utc.get(..19).unwrap_or(&r.started_utc),
            p(&r.procedure),
            r.outcome.as_str().to_uppercase(),
            r.id,
            p(&r.bench),
            if r.operator.is_empty() {
                "(operator not given)".into()
            } else {
                p(&r.operator)
            },
            if r.bench_id.is_empty() {
                "-".into()
            } else {
                p(&r.bench_id)
            },
            r.software,
            p(&r.coefficients.describe()),
            r.calibration_overdue
                .as_deref()
                .map_or(String::new(), |o| format!("; {o} calibration OVERDUE"))
        ));
        let ms: Vec<MeasurementRow> = h
            .measurements
            .iter()
            .filter(|m| m.run == r.id)
            .cloned()
            .collect();
        s.push_str(&render_measurements(&ms));
    }
    match &h.coefficients {
        Some(c) => s.push_str(&format!(
            "latest coefficient set: version {} of {} ({}; held-out drift {} deg/h; sha256 {})\n{}",
            c.version,
            c.created_utc,
            c.validation,
            opt(c.held_out_drift_pp_dph, 4),
            c.sha256
                .as_deref()
                .map_or("-", |h| h.get(..12).unwrap_or(h)),
            c.coeffs_toml
        )),
        None => s.push_str("coefficients: none calibrated\n"),
    }
    s
}

/// A trend as a small table.
pub fn render_trend(t: &Trend) -> String {
    let idx = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.2}"));
    let why = if t.count < 2 {
        " (needs two values)"
    } else if t.sigma_within.is_none_or(|s| s <= 0.0) {
        " (the values do not vary)"
    } else {
        ""
    };
    format!(
        "{} ({}): {} value(s) of {} judged\n  mean {}  sigma {}  min {}  max {}\n  limits [{}..{}]  yield {}\n  \
         Cpu {}  Cpl {}  Cpk {}  (sigma within {}, from moving ranges){why}\n  Ppu {}  Ppl {}  Ppk {}  (overall sigma)\n",
        t.name,
        t.unit,
        t.count,
        t.judged,
        opt(t.mean, 4),
        opt(t.sigma, 4),
        opt(t.min, 4),
        opt(t.max, 4),
        lim(t.low),
        lim(t.high),
        t.yield_fraction
            .map_or("-".into(), |y| format!("{:.1} %", 100.0 * y)),
        idx(t.within.upper),
        idx(t.within.lower),
        idx(t.within.k),
        opt(t.sigma_within, 4),
        idx(t.overall.upper),
        idx(t.overall.lower),
        idx(t.overall.k),
    ) + &t.percentile.map_or(String::new(), |p| {
        format!(
            "  Ppu {}  Ppl {}  Ppk {}  (percentiles of a {} fit, ISO 22514-2: X50 {}  X99.865 {}){}\n",
            idx(p.upper),
            idx(p.lower),
            idx(p.k),
            p.model,
            opt(Some(p.x_50), 4),
            opt(Some(p.x_99865), 4),
            if p.preferred {
                "\n    a non-negative figure with an upper limit: read its performance here, not on the normal Ppk"
            } else {
                ""
            }
        )
    }) + &t.caveat()
}

/// `--outcome` takes the store's words (`conditional_pass`, not clap's
/// kebab case), and its help lists them.
fn run_state_words() -> impl clap::builder::TypedValueParser<Value = RunState> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(RunState::ALL.map(RunState::as_str))
        .try_map(|w| RunState::parse(&w).ok_or_else(|| format!("not a run state: {w}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stored_serial_is_shown_never_obeyed_by_the_terminal() {
        let row = RunRow {
            id: "r.1".into(),
            started_utc: "2026-12-03T10:00:00+00:00".into(),
            dut_type: "RL-16".into(),
            serial: "RL16\u{1b}[2J\u{202E}42".into(),
            procedure: "acceptance".into(),
            bench: "embedded".into(),
            station: "pc".into(),
            operator: "J.\u{7}Doe".into(),
            outcome: gyrobench::results::RunState::Pass,
            part: 1,
            latest: true,
            device_time_s: None,
            error: None,
            slot: String::new(),
            bench_id: String::new(),
            software: String::new(),
            calibration_overdue: None,
            coefficients: Default::default(),
        };
        let text = render_list(std::slice::from_ref(&row));
        assert!(
            !text.contains('\u{1b}') && !text.contains('\u{202E}'),
            "{text:?}"
        );
        assert!(text.contains("RL16\\u{1b}[2J\\u{202e}42"), "{text}");
        let unit = render_unit(&UnitHistory {
            serial: row.serial.clone(),
            runs: vec![row],
            measurements: Vec::new(),
            coefficients: None,
        });
        assert!(
            !unit.chars().any(|c| c.is_control() && c != '\n'),
            "{unit:?}"
        );
    }
}
