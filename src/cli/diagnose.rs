//! `gyrobench diagnose RUN.mcap... [--twin TWIN.toml] --out DIR`,
//! `gyrobench diagnose --lot LOG... --out DIR` and
//! `gyrobench diagnose selfcheck [--runs N] [--seed S] --out DIR`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand};

use super::{Outcome, Usage};
use gyrobench::diagnose::library::Effect;
use gyrobench::diagnose::{self, Options, data, html, lot_files, lot_html, selfcheck};
use gyrobench::twin::TwinConfig;

#[derive(Debug, Args)]
#[command(
    args_conflicts_with_subcommands = true,
    after_help = after_help!(
        "gyrobench diagnose runs/c1/run.mcap runs/c2/run.mcap --out diag\n  gyrobench diagnose --lot runs/batch/run.mcap --out lot",
        plain
    )
)]
pub struct DiagnoseArgs {
    #[command(subcommand)]
    command: Option<DiagnoseCommand>,
    /// Run logs (live, simulated or imported) of one unit.
    runs: Vec<PathBuf>,
    /// A batch's unit, by serial, in every log given (default: each log's
    /// first unit).
    #[arg(long, value_name = "SERIAL")]
    unit: Option<String>,
    /// Reference simulator: this twin configuration (default: the study's
    /// model 4 fitted on held-out records).
    #[arg(long)]
    twin: Option<PathBuf>,
    /// Where to write diagnosis.json, diagnosis.html, twin-updated.toml
    /// (not a run directory, nor inside one, without --force).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write into --out even if it is a run directory or inside one.
    #[arg(long)]
    force: bool,
    /// When the diagnosis is inconclusive: replications of the deciding
    /// run to simulate its power with on the fitted unit (0: estimate it
    /// from the observed statistic only).
    #[arg(long, default_value_t = diagnose::POWER_REPLICATIONS)]
    power_replications: usize,
    /// Diagnose runs of different units together (refused otherwise: an
    /// effect found could be a difference between the units); the
    /// headline says so.
    #[arg(long)]
    allow_mixed_units: bool,
    /// Diagnose a lot: the logs are of several units (a batch's log holds
    /// several; one unit's logs are grouped by its serial), all of one
    /// type at one site. Each unit is diagnosed alone, then all together:
    /// the effects the lot shares (the bench's, with their likely seat:
    /// fixture, table, site), each unit's own, and the unit unlike the
    /// others. Writes lot.json, lot.html, bench-correction.toml and each
    /// unit's diagnosis and twins under units/SERIAL/.
    #[arg(long, conflicts_with_all = ["unit", "allow_mixed_units"])]
    lot: bool,
}

#[derive(Debug, Subcommand)]
enum DiagnoseCommand {
    /// The withheld-effect experiment on the twin (proves the diagnosis).
    #[command(after_help = after_help!("gyrobench diagnose selfcheck --runs 1 --out selfcheck", plain))]
    Selfcheck(SelfcheckArgs),
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum UnitArg {
    Gap,
    Rms,
}

#[derive(Debug, Args)]
struct SelfcheckArgs {
    /// Runs per case (effect and amplitude, null, outside the library).
    #[arg(long, default_value_t = 10)]
    runs: usize,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Only these library effects (comma-separated names; default: all).
    #[arg(long, value_delimiter = ',')]
    effects: Vec<String>,
    /// Add procedures/separating.toml (axis down, two ramp rates, a pause
    /// mid-ramp) and procedures/rate_transfer_temperatures.toml (the rate
    /// ladder at -40, +20, +50 degC) to each trial: the runs that make
    /// thermal_lag and scale_factor_temperature identifiable. With
    /// --randomize: a trial whose diagnosis reports a pair confounded and
    /// names a shipped procedure that separates it (misalignment.toml,
    /// separating.toml) goes on to that run on the same unit and is
    /// diagnosed again with it.
    #[arg(long)]
    separating: bool,
    /// What an amplitude of 1 is: the held-out gap the effect alone opens
    /// against the reference (`gap`), or its plain RMS (`rms`); both at
    /// 60 s means, in units of the null runs' gap.
    #[arg(long, value_enum, default_value = "gap")]
    unit: UnitArg,
    /// Draw every trial's unit from wide priors unlike the twin's defaults
    /// and diagnose it without a twin (docs/diagnosis.md, "Randomised
    /// units"); writes randomized.json.
    #[arg(long)]
    randomize: bool,
    /// With --randomize: how many units (the cases cycle among them).
    #[arg(long, default_value_t = 300)]
    units: usize,
    /// Lots instead: N lots of three or four randomised units on one
    /// bench, in turn one with a bench fault every unit shares (a fixture
    /// tilt, the latitude or the north stated wrong), one with nothing,
    /// one with an odd unit, each diagnosed as `diagnose --lot` does
    /// (docs/diagnosis.md, "Lots"); writes lots.json.
    #[arg(long, value_name = "N", conflicts_with_all = ["randomize", "separating", "effects"])]
    lots: Option<usize>,
    /// Where to write selfcheck.json and selfcheck.html (or
    /// randomized.json): not a run directory, nor inside one, without
    /// --force.
    #[arg(long)]
    out: PathBuf,
    /// Write into --out even if it is a run directory or inside one.
    #[arg(long)]
    force: bool,
}

/// Each run's unit, `type serial`, from its log's metadata.
fn units_of(paths: &[PathBuf]) -> Result<Vec<(PathBuf, String)>> {
    paths
        .iter()
        .map(|p| {
            let m = gyrobench::runlog::meta::read_run_meta(p)?;
            let u = m.unit().map_or_else(
                || format!("{} {}", m.dut_type, m.dut_serial),
                |u| format!("{} {}", u.dut_type, u.serial),
            );
            Ok((p.clone(), u))
        })
        .collect()
}

fn write(path: &Path, text: &str) -> Result<()> {
    gyrobench::fsutil::write_atomic(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// The units `runs` are of; refused as a usage error when they are of
/// several unless `allow` (then each named, `RUN: UNIT`, for the report).
fn mixed_units_of(runs: &[PathBuf], allow: bool) -> Result<Vec<String>> {
    let units = units_of(runs)?;
    let distinct: std::collections::BTreeSet<&str> =
        units.iter().map(|(_, u)| u.as_str()).collect();
    if distinct.len() <= 1 {
        return Ok(Vec::new());
    }
    let named: Vec<String> = units
        .iter()
        .map(|(p, u)| format!("{}: {u}", p.display()))
        .collect();
    if !allow {
        return Err(Usage(format!(
            "the runs are of {} units ({}); a diagnosis is of one unit: give one unit's runs, or --allow-mixed-units to diagnose them together anyway",
            distinct.len(),
            named.join(", ")
        ))
        .into());
    }
    Ok(named)
}

/// Write `d` into `out`: diagnosis.json, diagnosis.html, the deciding run
/// (or remove an earlier one) and `twin` (default: the RL-16's) updated.
fn write_outputs(out: &Path, d: &diagnose::Diagnosis, twin: Option<TwinConfig>) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write(
        &out.join("diagnosis.json"),
        &serde_json::to_string_pretty(d)?,
    )?;
    write(&out.join("diagnosis.html"), &html::render(d))?;
    let deciding = out.join("deciding-run.toml");
    match &d.deciding_procedure {
        Some(text) => write(&deciding, text)?,
        // A file from an earlier diagnosis in the same place no longer holds.
        None if deciding.exists() => std::fs::remove_file(&deciding)
            .with_context(|| format!("removing {}", deciding.display()))?,
        None => {}
    }
    let base = twin.unwrap_or_else(TwinConfig::default_rl16);
    write(
        &out.join("twin-updated.toml"),
        &format!(
            "# The twin with the effects gyrobench diagnose accepted enabled and fitted,\n# and its thermal network fitted to the runs.\n{}",
            diagnose::updated_twin(&base, d)
                .to_toml()
                .context("writing the updated twin as TOML")?
        ),
    )?;
    Ok(())
}

/// The diagnosis in words on stdout; `fitted_twin`: the runs were
/// diagnosed against a twin file, whose network was fitted.
fn print_summary(d: &diagnose::Diagnosis, out: &Path, fitted_twin: bool) -> Result<()> {
    outln!("{}", diagnose::html::headline(d))?;
    let th = &d.layers.thermal;
    let network = match (&th.form_misfit, th.fitted_gap_c) {
        (Some(m), _) => format!(
            " by the modal model (the twin's network form cannot follow the runs: {:.4} degC held out, most in {} {} from {:.0} s; twin-updated.toml keeps the thermal network it had)",
            m.gap_c,
            m.r#where.first().map_or("", |w| w.run.as_str()),
            m.r#where.first().map_or("", |w| w.sensor.as_str()),
            m.r#where.first().map_or(0.0, |w| w.start_s),
        ),
        (None, Some(g)) if fitted_twin => {
            format!(" ({g:.4} degC with the network fitted to the runs, in twin-updated.toml)")
        }
        _ => String::new(),
    };
    outln!(
        "rate layer: held-out gap {:.5} deg/h -> {:.5} deg/h; thermal layer: {:.4} degC held out (the sensors' noise floor {:.4} degC){network}",
        d.layers.rate.gap_dph,
        d.layers.rate.gap_after_dph,
        th.gap_c,
        th.noise_floor_c,
    )?;
    for e in &th.effects {
        let on =
            e.on.as_deref()
                .map_or(String::new(), |o| format!(" on {o}"));
        let parameters: Vec<String> = e
            .parameters
            .iter()
            .map(|(k, v)| format!("{k} {v:.4}"))
            .collect();
        outln!(
            "  thermal: {}{on} ({}) gap {:.4} -> {:.4} degC (shrink {:.0} %, p {})",
            e.name,
            parameters.join(", "),
            e.held_out_gap_before_c,
            e.held_out_gap_after_c,
            100.0 * e.shrink,
            gyrobench::view::p_phrase(e.p_value)
        )?;
    }
    if d.effects.is_empty() {
        outln!("no library effect is significant")?;
    }
    for e in &d.effects {
        let name = match &e.temperature {
            Some(t) => format!("{} ({t})", e.name),
            None => e.name.clone(),
        };
        outln!(
            "  {:<26} gap {:.5} -> {:.5} deg/h (shrink {:.0} %, p {})",
            name,
            e.held_out_gap_before_dph,
            e.held_out_gap_after_dph,
            100.0 * e.shrink,
            gyrobench::view::p_phrase(e.p_value)
        )?;
    }
    if let Some(i) = &d.inconclusive {
        let r = &i.deciding_run;
        outln!("inconclusive: these improve the held-out gap but miss a bar")?;
        for c in &i.candidates {
            outln!(
                "  {:<26} removes {:.0} % of it (bar {:.0} %), p {:.4} (bar {:.4})",
                c.name,
                100.0 * c.improvement,
                100.0 * diagnose::THRESHOLDS.min_gain,
                c.p_value,
                c.level
            )?;
        }
        if r.passes > 0 {
            outln!(
                "  deciding run for {}: {} ({:.1} h of device time, {}): {}",
                r.effect,
                r.what,
                r.device_time_h,
                r.power_phrase(),
                out.join(&r.file).display()
            )?;
        } else {
            outln!("  {}: {}", r.effect, r.what)?;
        }
    }
    for c in &d.confounded {
        outln!(
            "  confounded: {} / {}: separate with {}",
            c.effects[0],
            c.effects[1],
            c.separate_with
        )?;
    }
    if let Some(s) = d.r#where.first() {
        outln!(
            "  the gap lies most in {} {} ({}, {:.0} % of it)",
            s.run,
            s.record,
            s.regime,
            100.0 * s.share
        )?;
    }
    if let Some(p) = d.unexplained.period_s {
        outln!("  unexplained: periodic, period {p:.0} s")?;
    }
    for o in &d.unexplained.outside {
        outln!("  unexplained: {}", o.describe())?;
    }
    Ok(())
}

pub fn run(args: DiagnoseArgs) -> Result<Outcome> {
    if let Some(DiagnoseCommand::Selfcheck(a)) = args.command {
        return run_selfcheck(a);
    }
    if args.runs.is_empty() {
        return Err(Usage("give one or more run logs (RUN.mcap...)".into()).into());
    }
    if args.lot {
        return run_lot(&args);
    }
    let Some(out) = args.out else {
        return Err(Usage(
            "--out DIR is required: where diagnosis.json, diagnosis.html and twin-updated.toml go"
                .into(),
        )
        .into());
    };
    check_out_dir(&out, args.force)?;
    let twin = match &args.twin {
        Some(p) => Some(TwinConfig::load(p).context("loading the twin file")?),
        None => None,
    };
    let mixed_units = mixed_units_of(&args.runs, args.allow_mixed_units)?;
    // The logs read two at a time (each read is one thread's work).
    let runs = gyrobench_analysis::par::two_at_a_time(&args.runs, |_, p| {
        data::load_unit(p, args.unit.as_deref())
    })
    .into_iter()
    .collect::<Result<Vec<_>, _>>()?;
    let mut d = diagnose::diagnose(
        &runs,
        &Options {
            twin: twin.clone(),
            fit_thermal: true,
            power_replications: args.power_replications,
        },
    );
    d.mixed_units = mixed_units;
    write_outputs(&out, &d, twin)?;
    print_summary(&d, &out, args.twin.is_some())?;
    errln!("diagnosis in {}", out.display());
    Ok(Outcome::Success)
}

/// `diagnose --lot`: the units of the logs as a lot.
fn run_lot(args: &DiagnoseArgs) -> Result<Outcome> {
    let Some(out) = &args.out else {
        return Err(Usage(
            "--out DIR is required: where lot.json, lot.html, bench-correction.toml and each unit's files go"
                .into(),
        )
        .into());
    };
    check_out_dir(out, args.force)?;
    let twin = match &args.twin {
        Some(p) => Some(TwinConfig::load(p).context("loading the twin file")?),
        None => None,
    };
    let units = data::load_lot(&args.runs)?;
    errln!(
        "lot: {} unit(s) in {} log(s): {}",
        units.len(),
        args.runs.len(),
        units
            .iter()
            .map(|u| format!("{} ({} run(s))", u.serial, u.runs.len()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let lot = diagnose::lot::diagnose_lot(
        units,
        &Options {
            twin: twin.clone(),
            fit_thermal: true,
            power_replications: args.power_replications,
        },
    )
    .map_err(|e| Usage(e.to_string()))?;
    write_lot_outputs(out, &lot, twin.as_ref())?;
    outln!("{}", lot_html::headline(&lot))?;
    outln!("{}", render_lot_units(&lot))?;
    errln!("lot diagnosis in {}", out.display());
    Ok(Outcome::Success)
}

/// Write a lot's files into `out`: lot.json, lot.html,
/// bench-correction.toml, deciding-run.toml (or remove an earlier one),
/// and each unit's diagnosis and twins under units/SERIAL/ (`twin`, else
/// the RL-16's, updated).
fn write_lot_outputs(
    out: &Path,
    lot: &diagnose::lot::Lot,
    twin: Option<&TwinConfig>,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write(&out.join("lot.json"), &serde_json::to_string_pretty(lot)?)?;
    write(&out.join("lot.html"), &lot_html::render(lot))?;
    write(
        &out.join("bench-correction.toml"),
        &lot_files::bench_correction(lot).context("writing the bench's correction as TOML")?,
    )?;
    let deciding = out.join("deciding-run.toml");
    match &lot.deciding_procedure {
        Some(text) => write(&deciding, text)?,
        None if deciding.exists() => std::fs::remove_file(&deciding)
            .with_context(|| format!("removing {}", deciding.display()))?,
        None => {}
    }
    let base = twin.cloned().unwrap_or_else(TwinConfig::default_rl16);
    let mut dirs: Vec<PathBuf> = Vec::new();
    for (k, (u, d)) in lot.units.iter().zip(&lot.diagnoses).enumerate() {
        let mut dir = out.join(lot_files::unit_dir(&u.serial));
        // Two serials a file name cannot tell apart each get their own.
        if dirs.contains(&dir) {
            dir = out.join(format!("{}-{k}", lot_files::unit_dir(&u.serial).display()));
        }
        write_outputs(&dir, d, Some(base.clone()))?;
        for (name, on_this_bench) in [
            ("twin-updated.toml", false),
            ("twin-on-this-bench.toml", true),
        ] {
            let t = lot
                .unit_twin(k, &base, on_this_bench)
                .context("a unit of the lot without its diagnosis")?;
            write(
                &dir.join(name),
                &format!(
                    "# Unit {}'s twin from gyrobench diagnose --lot: its thermal network fitted to its runs and {}.
{}",
                    u.serial,
                    if on_this_bench {
                        "its own effects and the effects the lot shares on this bench (the bench's, in bench-correction.toml)"
                    } else {
                        "its own effects alone (the ones the lot shares are the bench's: bench-correction.toml)"
                    },
                    t.to_toml().context("writing a unit's twin as TOML")?
                ),
            )?;
        }
        dirs.push(dir);
    }
    Ok(())
}

/// One line per unit under the headline: its own effects, its gap
/// through the lot's fits, and whether it is unlike the lot.
fn render_lot_units(lot: &diagnose::lot::Lot) -> String {
    let mut lines = Vec::new();
    for s in &lot.shared_effects {
        lines.push(format!(
            "  shared {:<24} seat {:<8} units {} (shrink {:.0} %, p {}, agreement p {})",
            s.name,
            s.seat,
            s.units.join(", "),
            100.0 * s.shrink,
            gyrobench::view::p_phrase(s.p_value),
            gyrobench::view::p_phrase(s.agreement_p)
        ));
    }
    for u in &lot.units {
        let own: Vec<&str> = u.effects.iter().map(|a| a.name.as_str()).collect();
        lines.push(format!(
            "  unit {:<12} own {:<32} gap {:.5} -> {:.5} -> {:.5} deg/h (noise {:.5}){}",
            u.serial,
            if own.is_empty() {
                "none".to_owned()
            } else {
                own.join(", ")
            },
            u.gap_dph,
            u.gap_after_shared_dph,
            u.gap_after_dph,
            u.noise_dph,
            if u.outlier { "  OUTLIER" } else { "" }
        ));
    }
    lines.join("\n")
}

/// An output directory, checked before the work (`fsutil::check_output`).
fn check_out_dir(out: &Path, force: bool) -> Result<()> {
    gyrobench::fsutil::check_output(
        out,
        gyrobench::fsutil::OutputRule {
            force,
            ..Default::default()
        },
    )?;
    Ok(())
}

fn run_selfcheck(a: SelfcheckArgs) -> Result<Outcome> {
    check_out_dir(&a.out, a.force)?;
    if let Some(lots) = a.lots {
        return run_lot_selfcheck(&a, lots);
    }
    if a.randomize {
        return run_randomized(&a);
    }
    let effects: Vec<Effect> = if a.effects.is_empty() {
        selfcheck::all_effects()
    } else {
        a.effects
            .iter()
            .map(|n| {
                Effect::from_name(n).ok_or_else(|| {
                    Usage(format!(
                        "--effects: {n:?} is not a library effect (one of: {})",
                        selfcheck::all_effects()
                            .iter()
                            .map(|e| e.name())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                    .into()
                })
            })
            .collect::<Result<_>>()?
    };
    if a.runs == 0 {
        return Err(Usage("--runs must be 1 or more".into()).into());
    }
    let plan = selfcheck::Plan {
        runs: a.runs,
        seed: a.seed,
        effects,
        separating: a.separating,
        unit: match a.unit {
            UnitArg::Gap => selfcheck::Unit::Gap,
            UnitArg::Rms => selfcheck::Unit::Rms,
        },
    };
    let bar = super::progress::Bar::new(plan.trials() as u64, "{bar:30} {pos}/{len} trials  {msg}");
    errln!(
        "self-check: {} trials of the twin's study runs ({} per case)",
        plan.trials(),
        plan.runs
    );
    let s = selfcheck::run(&plan, &|d| {
        let line = render_trial(&d);
        bar.println(&line);
        bar.set(d.done as u64, line);
    })
    .context("running the self-check")?;
    bar.clear();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    write(
        &a.out.join("selfcheck.json"),
        &serde_json::to_string_pretty(&s)?,
    )?;
    write(&a.out.join("selfcheck.html"), &selfcheck::render_html(&s))?;
    outln!(
        "noise unit {:.5} deg/h; false positives {:.0} %; outside effect attributed {:.0} %, period found {:.0} %",
        s.noise_dph,
        100.0 * s.false_positive_rate,
        100.0 * s.periodic_attributed,
        100.0 * s.periodic_period_found
    )?;
    for p in &s.power {
        let shows = s
            .sizes
            .iter()
            .find(|z| z.effect == p.effect)
            .map_or(f64::NAN, |z| z.gap_per_rms);
        outln!(
            "  {:<26} {:>4}x  named first {:>4.0} %  excess closed {:>4.0} %  (coefficient {:.3e}; gap/RMS {:.2})",
            p.effect,
            p.amplitude,
            100.0 * p.named_first,
            100.0 * p.excess_closed,
            p.coefficient,
            shows
        )?;
    }
    errln!("self-check in {}", a.out.display());
    Ok(Outcome::Success)
}

fn run_lot_selfcheck(a: &SelfcheckArgs, lots: usize) -> Result<Outcome> {
    use gyrobench::diagnose::lot_selfcheck;
    if lots == 0 {
        return Err(Usage("--lots must be 1 or more".into()).into());
    }
    let bar = super::progress::Bar::new(lots as u64, "{bar:30} {pos}/{len} lots  {msg}");
    errln!(
        "self-check on {lots} lots of randomised units from seed {}, diagnosed as lots without a twin",
        a.seed
    );
    let r = lot_selfcheck::run(lots, a.seed, &|done, _, t| {
        let line = render_lot_trial(done, lots, t);
        bar.println(&line);
        bar.set(done as u64, line);
    });
    bar.clear();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    write(&a.out.join("lots.json"), &serde_json::to_string_pretty(&r)?)?;
    outln!("{}", render_lot_selfcheck(&r))?;
    errln!("self-check in {}", a.out.display());
    Ok(Outcome::Success)
}

/// One finished lot of the lot self-check as a progress line.
fn render_lot_trial(done: usize, lots: usize, t: &diagnose::lot_selfcheck::LotTrial) -> String {
    let own: Vec<String> = t
        .own
        .iter()
        .filter(|(_, v)| !v.is_empty())
        .map(|(s, v)| format!("{s}: {}", v.join(", ")))
        .collect();
    format!(
        "[{done}/{lots}] lot seed {} ({} units{}): {}; shared {}; own {}; outliers {}",
        t.seed,
        t.serials.len(),
        if t.low_latitude { ", low latitude" } else { "" },
        t.injected,
        if t.shared.is_empty() {
            "none".to_owned()
        } else {
            t.shared.join("; ")
        },
        if own.is_empty() {
            "none".to_owned()
        } else {
            own.join("; ")
        },
        if t.outliers.is_empty() {
            "none".to_owned()
        } else {
            t.outliers
                .iter()
                .map(|o| match t.evidence.get(o) {
                    Some(why) => format!("{o} ({})", why.join(", ")),
                    None => o.clone(),
                })
                .collect::<Vec<_>>()
                .join(", ")
        },
    )
}

/// The lot self-check's figures, one line each.
fn render_lot_selfcheck(r: &diagnose::lot_selfcheck::LotSelfCheck) -> String {
    let rate = |x: &diagnose::lot_selfcheck::Rate| match x.rate {
        Some(r) => format!("{:.0} % ({} of {})", 100.0 * r, x.hits, x.of),
        None => "no lot of its kind".to_owned(),
    };
    let mut lines = vec![format!(
        "shared fault named right (effect, every unit, seat): {}",
        rate(&r.shared_named_right)
    )];
    for (f, x) in &r.shared_named_right_by_fault {
        lines.push(format!("  {f:<16} {}", rate(x)));
    }
    lines.extend([
        format!(
            "  anything else attributed in a shared lot: {}",
            rate(&r.shared_false_attribution)
        ),
        format!(
            "  a unit's own effect {}; an outlier {}",
            rate(&r.shared_false_own),
            rate(&r.shared_false_outlier)
        ),
        format!(
            "odd unit flagged, and no other: {}",
            rate(&r.outlier_flagged_right)
        ),
        format!("  its own effect named: {}", rate(&r.own_effect_named)),
        format!(
            "  anything else attributed in an outlier lot: {}",
            rate(&r.outlier_false_attribution)
        ),
        format!(
            "  a shared effect named in an outlier lot: {}",
            rate(&r.outlier_false_shared)
        ),
        format!(
            "null lots with anything attributed: {}",
            rate(&r.null_false_attribution)
        ),
        format!(
            "  a shared effect {}; a unit's own effect {}; an outlier {}",
            rate(&r.null_false_shared),
            rate(&r.null_false_own),
            rate(&r.null_false_outlier)
        ),
    ]);
    for why in &r.skipped {
        lines.push(format!("  not diagnosed: {why}"));
    }
    lines.join("\n")
}

fn run_randomized(a: &SelfcheckArgs) -> Result<Outcome> {
    use gyrobench::diagnose::randomized;
    if a.units == 0 {
        return Err(Usage("--units must be 1 or more".into()).into());
    }
    let bar = super::progress::Bar::new(a.units as u64, "{bar:30} {pos}/{len} units  {msg}");
    errln!(
        "self-check on {} randomised units from seed {}, diagnosed without a twin",
        a.units,
        a.seed
    );
    let r = randomized::run(a.units, a.seed, a.separating, &|done, _, t| {
        let line = render_unit_trial(done, a.units, t);
        bar.println(&line);
        bar.set(done as u64, line);
    })
    .context("running the randomised self-check")?;
    bar.clear();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    write(
        &a.out.join("randomized.json"),
        &serde_json::to_string_pretty(&r)?,
    )?;
    print_randomized(&r)?;
    errln!("self-check in {}", a.out.display());
    Ok(Outcome::Success)
}

/// One finished unit of the randomised self-check as a progress line:
/// `[done/units] seed, case: what was named` (and with the separating run).
fn render_unit_trial(done: usize, units: usize, t: &diagnose::randomized::UnitTrial) -> String {
    format!(
        "[{done}/{}] seed {}{} {}: named {} / inconclusive {} (thermal {:.3} degC)",
        units,
        t.seed,
        if t.low_latitude {
            " (low latitude)"
        } else {
            ""
        },
        serde_json::to_string(&t.case).unwrap_or_default(),
        if t.accepted.is_empty() {
            "nothing".to_owned()
        } else {
            t.accepted.join(", ")
        },
        t.inconclusive.as_deref().unwrap_or("-"),
        t.thermal_gap_c
    ) + &t.with_separating_run.as_ref().map_or(String::new(), |r| {
        format!(
            "; with {}: named {}",
            r.procedures.join(", "),
            if r.accepted.is_empty() {
                "nothing".to_owned()
            } else {
                r.accepted.join(", ")
            }
        )
    })
}

/// The randomised self-check's figures on stdout: the headline, the
/// low-latitude units', the units not diagnosed, and a line per case.
fn print_randomized(r: &diagnose::randomized::Randomized) -> Result<()> {
    outln!(
        "named first: {:.0} % at >= 2x, {:.0} % at 1.5x; pairs both named {:.0} % (or reported confounded with a named one {:.0} %; both named with the separating run a confounded pair names {:.0} %); false attribution {:.0} % ({:.0} % with the separating runs); thermal layer within 0.05 degC {:.0} % (network form {:.0} %); median excess closed {:.0} %",
        100.0 * r.named_at_2x,
        100.0 * r.named_at_1_5x,
        100.0 * r.pairs_both_named,
        100.0 * r.pairs_named_or_confounded,
        100.0 * r.pairs_both_named_with_separating_run,
        100.0 * r.false_attribution,
        100.0 * r.false_attribution_with_separating_run,
        100.0 * r.thermal_within_0_05,
        100.0 * r.network_followed,
        100.0 * r.median_excess_closed
    )?;
    let l = &r.low_latitude;
    outln!(
        "  of them {} low-latitude units (table turned north): named first {:.0} % at >= 2x ({:.0} % with the separating run), {:.0} % at 1.5x; pairs both named {:.0} % ({:.0} % with the separating run); false attribution {:.0} %; thermal layer within 0.05 degC {:.0} %",
        l.units,
        100.0 * l.named_at_2x,
        100.0 * l.named_at_2x_with_separating_run,
        100.0 * l.named_at_1_5x,
        100.0 * l.pairs_both_named,
        100.0 * l.pairs_both_named_with_separating_run,
        100.0 * l.false_attribution,
        100.0 * l.thermal_within_0_05
    )?;
    for why in &r.skipped {
        outln!("  not diagnosed: {why}")?;
    }
    for row in &r.rows {
        outln!(
            "  {:<48} {:>3} units  named {:>4.0} %  inconclusive {:>4.0} %  excess closed {}{}",
            row.case,
            row.trials,
            100.0 * row.named,
            100.0 * row.inconclusive,
            row.median_excess_closed
                .map_or("-".to_owned(), |m| format!("{:.0} %", 100.0 * m)),
            if row.separating_runs > 0 {
                format!(
                    "  (separating run in {}: named {:.0} %)",
                    row.separating_runs,
                    100.0 * row.named_with_separating_run
                )
            } else {
                String::new()
            }
        )?;
    }
    Ok(())
}

/// One finished trial as a progress line: `[n/N] what, seed: what was named`.
fn render_trial(d: &selfcheck::TrialDone<'_>) -> String {
    let what = match d.injected {
        selfcheck::Injected::Null => "null (nothing injected)".to_owned(),
        selfcheck::Injected::Effect(name, amp) => format!("{name} at {amp}x"),
        selfcheck::Injected::Periodic => "periodic (outside the library)".to_owned(),
    };
    let named = d
        .trial
        .attributed
        .as_deref()
        .map_or("nothing named".to_owned(), |e| format!("named {e}"));
    format!(
        "[{:>w$}/{}] {what}, seed {}: {named}",
        d.done,
        d.total,
        d.trial.seed,
        w = d.total.to_string().len()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrobench::diagnose::selfcheck::{Injected, Trial, TrialDone};

    fn trial(attributed: Option<&str>) -> Trial {
        Trial {
            injected: String::new(),
            seed: 1001,
            attributed: attributed.map(str::to_owned),
            accepted: Vec::new(),
            gap_before_dph: 0.0,
            gap_after_dph: 0.0,
            excess_closed: None,
            period_s: None,
            candidates: Vec::new(),
            confounded: Vec::new(),
        }
    }

    #[test]
    fn a_trial_line_counts_and_speaks_plainly() {
        let t = trial(Some("self_heating"));
        let line = render_trial(&TrialDone {
            done: 3,
            total: 43,
            injected: &Injected::Effect("self_heating".into(), 1.5),
            trial: &t,
        });
        assert_eq!(
            line,
            "[ 3/43] self_heating at 1.5x, seed 1001: named self_heating"
        );
        let t = trial(None);
        let line = render_trial(&TrialDone {
            done: 43,
            total: 43,
            injected: &Injected::Null,
            trial: &t,
        });
        assert_eq!(
            line,
            "[43/43] null (nothing injected), seed 1001: nothing named"
        );
        assert!(!line.contains("Some(") && !line.contains("None"));
    }
}
