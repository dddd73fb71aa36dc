//! `gyrobench run PROCEDURE`: run an acceptance procedure, log it, judge it.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

use anyhow::{Context, Result};
use clap::Args;

use super::check::load_bench;
use super::{Outcome, Usage};
use gyrobench::clock::Pacing;
use gyrobench::coeffs::{Chosen, CoeffsSource, SetIdentity, SetStatus};
use gyrobench::procedure::Procedure;
use gyrobench::runlog::live::{Live as LiveStream, LiveError};
use gyrobench::sequencer::{self, Event, Interrupt, Observer, Operator};
use gyrobench::session::rundir::RunDirError;
use gyrobench::session::{self, Place, Plan, SessionError};
use gyrobench::sim::embedded::Fault;
use gyrobench::twin::TwinConfig;
use gyrobench::unit::{SIMULATED_SERIAL, check_operator, check_serial};

#[derive(Debug, Args)]
#[command(after_help = after_help!(
    "gyrobench run procedures/smoke.toml --out runs/smoke",
    "0 the unit passed, 3 it failed its limits, 1 error (bad input, I/O, a device, data that could \
     not be judged, a bench not left in a known state), 2 usage (bad arguments, a run directory \
     that holds a run or is in use, a bench another run is using), 130 Ctrl-C, 143 SIGTERM, \
     129 SIGHUP, 131 SIGQUIT"
))]
pub struct RunArgs {
    /// Procedure file (TOML), e.g. procedures/acceptance.toml.
    #[arg(required_unless_present = "resume")]
    procedure: Option<PathBuf>,
    /// Continue the interrupted run in DIR from its last completed step,
    /// logging into a new part file beside the first (procedure, bench,
    /// twin, coefficients, seed and unit come from its log).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["procedure", "bench", "out", "seed", "coeffs", "coeffs_override", "twin", "dut", "operator", "force"])]
    resume: Option<PathBuf>,
    /// Bench file (default: the embedded simulated bench, on virtual time).
    #[arg(long)]
    bench: Option<PathBuf>,
    /// Run directory (default: runs/<procedure>-<UTC time>). It must not
    /// hold a run already.
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// With --out: move a run already in that directory aside (to
    /// DIR.replaced-N) instead of refusing.
    #[arg(long)]
    force: bool,
    /// Simulated bench speed: `max` or a factor over real time.
    #[arg(long, default_value = "max")]
    speed: String,
    /// Seed of the simulated bench.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The unit's coefficient set to compensate with: a file `calibrate`
    /// wrote, or `latest` for the unit's newest set in the results store
    /// (default: model 4 fitted on the run's own records). The set is
    /// checked against the results store: a set it holds is recorded with
    /// its version, an edited or unknown one as such (never as the set it
    /// claims to be), and without a store as not checked. A set of another
    /// unit (as it names itself, or as the store knows it) is refused.
    #[arg(long, value_name = "FILE|latest")]
    coeffs: Option<String>,
    /// Use the --coeffs set although it is another unit's or names no
    /// unit; REASON goes in the report and the results store.
    #[arg(long, value_name = "REASON", requires = "coeffs")]
    coeffs_override: Option<String>,
    /// Twin configuration of the simulated bench (default: the RL-16 twin).
    #[arg(long)]
    twin: Option<PathBuf>,
    /// Serial number of the unit under test (required with a bench file;
    /// on the embedded simulated bench it defaults to SIMULATED, which
    /// names no unit and no real bench accepts). On a bench with slots,
    /// SLOT=SERIAL for each unit, repeated (a slot not named stays empty).
    #[arg(long, value_name = "SERIAL|SLOT=SERIAL")]
    dut: Vec<String>,
    /// Who runs it (recorded in the log and the results store).
    #[arg(long, default_value = "")]
    operator: String,
    /// The results store: a SQLite file, a postgres:// URL, or `none`
    /// (default: $GYROBENCH_DB, else the bench file's [results] db, else
    /// ~/.local/share/gyrobench/results.sqlite).
    #[arg(long, value_name = "STORE")]
    db: Option<String>,
    /// Simulated bench only: play a fault, FAULT@SECONDS of device time
    /// (chamber-alarm, chamber-silent, table-interlock, gyro-silent,
    /// gyro-corrupt, gyro-stuck, gyro-saturated, process-kill, panic,
    /// supply-overcurrent, disk-full, sighup, sigquit; unit-lost: a
    /// batch's last unit's link lost for good, the others go on;
    /// supply-ignores-off: the supply leaves its output on when told off).
    #[arg(long, value_name = "FAULT@SECONDS")]
    inject: Vec<String>,
    /// Nobody watches the run: the procedure's prompts (unit mounted,
    /// chamber door closed, ...) count as confirmed by --operator before
    /// it starts, and the log says so at each one. Without it, a run on
    /// real devices whose procedure asks something needs a terminal.
    #[arg(long)]
    unattended: bool,
    /// Publish the run's channels live on a Foxglove WebSocket server
    /// (loopback only; default 127.0.0.1:8765, port 0 picks a free one):
    /// Foxglove or Lichtblick shows the run as it goes.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    live: Option<std::net::SocketAddr>,
}

/// Progress on stderr: a live bar on a terminal, plain lines otherwise.
struct Live {
    bar: super::progress::Bar,
    last_line_s: f64,
    /// The tick going on: its device time and the chamber in words, then
    /// the first unit's second in words (shown once the tick is told).
    now_s: f64,
    chamber: String,
    rate: String,
    /// The operator confirmed the procedure's prompts before the run
    /// (`--unattended`).
    unattended: bool,
    /// The first unit's drift: the last minute of its record.
    drift: gyrobench::view::live::DriftWindow,
}

impl Live {
    fn new(total_s: f64, unattended: bool) -> Self {
        Self {
            bar: super::progress::Bar::new(
                total_s.max(1.0) as u64,
                "{bar:30} {pos}/{len} s device time  {msg}",
            ),
            last_line_s: 0.0,
            now_s: 0.0,
            chamber: String::new(),
            rate: String::new(),
            unattended,
            drift: gyrobench::view::live::DriftWindow::default(),
        }
    }

    /// The tick's line: the bar on a terminal, else a line an hour.
    fn show(&mut self) {
        let msg = format!("{}{}", self.chamber, self.rate);
        if self.bar.is_live() {
            self.bar.set(self.now_s as u64, msg);
        } else if self.now_s - self.last_line_s >= 3600.0 {
            self.last_line_s = self.now_s;
            errln!("  t = {:.2} h  {msg}", self.now_s / 3600.0);
        }
    }
}

impl Observer for Live {
    fn observe(&mut self, event: &Event<'_>) -> std::io::Result<()> {
        match *event {
            Event::Begin { dir, notes } => {
                for n in notes {
                    self.bar.println(&format!("note: {n}"));
                }
                self.bar.println(&format!("logging to {}", dir.display()));
            }
            Event::Doing {
                step,
                index,
                total,
                restore,
            } => {
                let what = if restore { "restore " } else { "" };
                self.bar.println(&format!(
                    "[{what}{}/{total}] {}",
                    index + 1,
                    step.describe()
                ));
            }
            Event::Warning(text) => self.bar.println(&format!("warning: {text}")),
            Event::State(st) => {
                self.now_s = st.t_s;
                self.chamber = format!(
                    "chamber {:+.2} degC (set {:+.1})",
                    st.chamber.air_c, st.chamber.set_point_c
                );
                self.rate.clear();
            }
            Event::Interval {
                slot: 0,
                iv,
                record,
            } => {
                self.drift.push(iv.time_s, iv.bias_dph(), record);
                self.rate = render_unit(iv, self.drift.drift().as_ref());
            }
            // The first unit's link figures close every tick.
            Event::Link { slot: 0, .. } => self.show(),
            _ => {}
        }
        Ok(())
    }
}

/// The first unit on the progress line: its drift (the mean Earth-removed
/// rate over the last minute of its record, the window named), never one
/// 1 s sample, then its temperatures.
fn render_unit(
    iv: &gyrobench::analysis::series::Interval,
    drift: Option<&gyrobench::view::live::Drift>,
) -> String {
    let drift = drift.map_or_else(
        || "drift - (no record yet)".to_owned(),
        |d| format!("drift {}", d.render()),
    );
    format!(
        "  {drift}  T1/T2/TK {:.2}/{:.2}/{:.2} degC",
        iv.t1_c, iv.t2_c, iv.tcase_c
    )
}

impl Operator for Live {
    fn prompt(&mut self, text: &str) -> Result<sequencer::Confirmed, sequencer::Unanswered> {
        use std::io::IsTerminal;
        if self.unattended {
            self.bar.println(&format!(
                "prompt (confirmed beforehand, --unattended): {text}"
            ));
            return Ok(sequencer::Confirmed::Beforehand);
        }
        if !std::io::stdin().is_terminal() {
            return Err(sequencer::Unanswered::NoTerminal);
        }
        self.bar
            .suspend(|| errln!("{text} -- press Enter to continue"));
        let mut line = String::new();
        match std::io::stdin().read_line(&mut line) {
            Ok(0) => Err(sequencer::Unanswered::TerminalClosed),
            Ok(_) => Ok(sequencer::Confirmed::Now),
            Err(e) => Err(sequencer::Unanswered::TerminalUnreadable(e)),
        }
    }
}

/// A run on real devices whose procedure asks the operator something
/// needs someone to answer: a terminal, or `--unattended` (whose prompts
/// the named operator confirmed before starting). Said before anything
/// moves, naming the first prompt.
fn check_prompts(plan: &Plan, unattended: bool) -> Result<()> {
    use std::io::IsTerminal;
    if unattended && plan.operator().trim().is_empty() {
        return Err(Usage(
            "--unattended records the procedure's prompts as confirmed beforehand by the operator: \
             name them with --operator NAME"
                .into(),
        )
        .into());
    }
    let p = plan.procedure();
    // On a bench without a supply the operator switches the unit, and the
    // moment they confirm is its power-on: never confirmed beforehand.
    let by_hand = |s: &&gyrobench::procedure::Step| {
        plan.bench().devices.supply.is_none()
            && matches!(s.kind, gyrobench::procedure::StepKind::Power { .. })
    };
    if unattended
        && !plan.bench().is_embedded()
        && let Some(s) = p
            .setup
            .iter()
            .chain(&p.main)
            .chain(&p.cleanup)
            .find(by_hand)
    {
        return Err(Usage(format!(
            "{} has the operator switch the unit at line {} ({}): the bench has no supply, and \
             --unattended cannot confirm when a unit was switched; run it with an operator at \
             the bench, or on a bench with [devices.supply]",
            plan.procedure_path(),
            s.line,
            s.describe()
        ))
        .into());
    }
    if plan.bench().is_embedded() || unattended || std::io::stdin().is_terminal() {
        return Ok(());
    }
    let first =
        p.setup.iter().chain(&p.main).chain(&p.cleanup).find(|s| {
            matches!(s.kind, gyrobench::procedure::StepKind::Prompt { .. }) || by_hand(s)
        });
    match first {
        Some(s) => Err(Usage(format!(
            "{} asks the operator at line {} ({}), and {}",
            plan.procedure_path(),
            s.line,
            s.describe(),
            sequencer::Unanswered::NoTerminal
        ))
        .into()),
        None => Ok(()),
    }
}

fn parse_inject(s: &str) -> Result<(f64, Fault)> {
    Ok(Fault::parse_at(s).map_err(|e| Usage(format!("--inject {e}")))?)
}

/// Slowest and fastest pacing of the embedded bench (factors over real time).
const SPEED_RANGE: (f64, f64) = (1e-3, 1e6);

pub(super) fn pacing(speed: &str) -> Result<Pacing> {
    if speed == "max" {
        return Ok(Pacing::Max);
    }
    let f: f64 = speed
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && (SPEED_RANGE.0..=SPEED_RANGE.1).contains(v))
        .ok_or_else(|| {
            Usage(format!(
                "--speed {speed:?}: expected `max` or a factor over real time between {} and {}",
                SPEED_RANGE.0, SPEED_RANGE.1
            ))
        })?;
    Ok(Pacing::Factor(f))
}

/// A twin file on the embedded bench says where the simulated unit
/// stands: with no bench file, the bench takes the twin's site and table
/// (the run is that twin's world); with one, the two must agree, since the
/// bench file is what the log and the analysis take as the truth.
fn place_twin(
    bench_cfg: &mut gyrobench::bench::BenchConfig,
    bench_given: bool,
    twin: &TwinConfig,
    twin_path: &std::path::Path,
) -> Result<()> {
    if !bench_given {
        bench_cfg.site = twin.site;
        bench_cfg.table.geometry = twin.table.geometry;
        return Ok(());
    }
    let differs = [
        (bench_cfg.site != twin.site, "[site]"),
        (
            bench_cfg.table.geometry != twin.table.geometry,
            "[table.geometry]",
        ),
    ];
    if let Some((_, what)) = differs.iter().find(|(d, _)| *d) {
        return Err(Usage(format!(
            "{}: its {what} differs from the bench file's; the embedded bench simulates the bench file's \
             site and table, so give the twin the same {what} (or leave out --bench to run at the twin's)",
            twin_path.display()
        ))
        .into());
    }
    Ok(())
}

fn fresh(args: &RunArgs, procedure_path: &std::path::Path, pacing: Pacing) -> Result<Plan> {
    let mut bench_cfg = load_bench(args.bench.as_ref())?;
    // Options that do not go together are said before any file is read.
    if !bench_cfg.is_embedded() && args.twin.is_some() {
        return Err(Usage("--twin applies to the embedded simulated bench only".into()).into());
    }
    if !bench_cfg.is_embedded() && !args.inject.is_empty() {
        return Err(Usage(
            "--inject applies to the embedded simulated bench only; a served bench plays the device faults itself: `gyrobench sim serve --inject FAULT@SECONDS`".into(),
        )
        .into());
    }
    let batch = if bench_cfg.slots.is_empty() {
        Vec::new()
    } else {
        batch_units(&args.dut, &bench_cfg, args.bench.as_deref())?
    };
    let dut = match batch.first() {
        Some(u) => u.serial.clone(),
        None if args.dut.len() > 1 => {
            return Err(Usage(
                "this bench holds one unit: give --dut once (SLOT=SERIAL is for a bench with [[slots]])"
                    .into(),
            )
            .into());
        }
        None => serial(
            args.dut.first().map(String::as_str),
            bench_cfg.is_embedded(),
        )?,
    };
    if !batch.is_empty() && args.coeffs.is_some() {
        return Err(Usage(
            "--coeffs names one unit's set; a batch compensates each unit with the model fitted on its own records"
                .into(),
        )
        .into());
    }
    check_operator(&args.operator).map_err(|e| Usage(format!("--operator: {e}")))?;
    let twin = match &args.twin {
        Some(p) => TwinConfig::load(p).context("loading the twin file")?,
        None => TwinConfig::default_rl16(),
    };
    if let Some(path) = &args.twin {
        place_twin(&mut bench_cfg, args.bench.is_some(), &twin, path)?;
    }
    let procedure = Procedure::load(procedure_path, &bench_cfg.procedure_limits())
        .context("checking the procedure")?;
    let faults: Vec<(f64, Fault)> = args
        .inject
        .iter()
        .map(|s| parse_inject(s))
        .collect::<Result<_>>()?;
    let store = gyrobench::results::Location::resolve(
        args.db.as_deref(),
        bench_cfg.results.as_ref().and_then(|r| r.db.as_deref()),
    );
    let coeffs = match args.coeffs.as_deref() {
        None => None,
        Some(choice) => Some(choose_coeffs(
            choice,
            args.coeffs_override.as_deref(),
            &store,
            &procedure.meta.dut_type,
            &dut,
        )?),
    };
    if batch.len() < 2 && faults.iter().any(|(_, f)| *f == Fault::UnitLost) {
        return Err(Usage(
            "--inject unit-lost loses a batch's last unit: it needs a bench with slots and two units or more".into(),
        )
        .into());
    }
    let bench_label = args
        .bench
        .as_ref()
        .map_or("embedded".into(), |p| p.display().to_string());
    Ok(
        Plan::new(procedure, procedure_path.display().to_string(), bench_cfg)
            .with_bench_label(bench_label)
            .with_store(store)
            .with_dut(dut)
            .with_operator(args.operator.clone())
            .with_twin(twin)
            .with_coeffs(coeffs)
            .with_seed(args.seed)
            .with_speed(args.speed.clone(), pacing)
            .with_faults(faults)
            .with_batch(batch),
    )
}

/// A batch's units from `--dut SLOT=SERIAL` arguments, in the bench's slot
/// order ([`session::batch_units`]); the slots not named are said on
/// stderr.
fn batch_units(
    duts: &[String],
    bench: &gyrobench::bench::BenchConfig,
    bench_path: Option<&std::path::Path>,
) -> Result<Vec<session::BatchUnit>> {
    let names = bench.slot_names();
    if duts.is_empty() {
        return Err(Usage(format!(
            "this bench holds slots {names}: give --dut SLOT=SERIAL for each unit on it"
        ))
        .into());
    }
    let mut given = Vec::new();
    for d in duts {
        let Some((slot, serial)) = d.split_once('=') else {
            return Err(Usage(format!(
                "--dut {d:?}: this bench holds slots {names}: give SLOT=SERIAL"
            ))
            .into());
        };
        given.push((slot.to_owned(), serial.to_owned()));
    }
    let units = session::batch_units(bench, bench_path, &given)
        .map_err(|(at, why)| Usage(format!("--dut {:?}: {why}", duts[at])))?;
    for slot in &bench.slots {
        if !units.iter().any(|u| u.slot.name == slot.name) {
            errln!("slot {}: empty (no --dut {}=SERIAL)", slot.name, slot.name);
        }
    }
    Ok(units)
}

/// The serial a run is recorded under: `--dut` (checked), or on the
/// embedded bench [`SIMULATED_SERIAL`]; a real bench needs the unit's.
fn serial(dut: Option<&str>, embedded: bool) -> Result<String> {
    match dut {
        Some(d) => {
            check_serial(d).map_err(|e| Usage(format!("--dut {d:?}: {e}")))?;
            if !embedded && d == SIMULATED_SERIAL {
                return Err(Usage(format!(
                    "--dut {SIMULATED_SERIAL} names no unit and is kept for the embedded simulated bench; give the serial of the unit on this bench"
                ))
                .into());
            }
            Ok(d.to_owned())
        }
        None if embedded => Ok(SIMULATED_SERIAL.to_owned()),
        None => Err(Usage(
            "a bench file drives real devices: give the unit's serial number with --dut SERIAL (as on its housing)".into(),
        )
        .into()),
    }
}

/// The coefficient set `--coeffs` names (a file, or `latest` from the
/// store), its identity checked against the results store, then checked
/// against the unit: another unit's set, one the store knows as another
/// unit's, or one naming none, needs `--coeffs-override REASON`.
fn choose_coeffs(
    choice: &str,
    override_reason: Option<&str>,
    store: &gyrobench::results::Location,
    dut_type: &str,
    serial: &str,
) -> Result<Chosen> {
    let mut chosen = if choice == "latest" {
        latest_set(store, dut_type, serial)?
    } else {
        let chosen = Chosen::from_file(std::path::Path::new(choice))
            .context("loading the coefficient set")?;
        identified(chosen, store)
    };
    let from = chosen
        .used
        .from
        .clone()
        .unwrap_or_else(|| choice.to_owned());
    match (chosen.check_unit(&from, dut_type, serial), override_reason) {
        (Ok(()), None) => {}
        (Ok(()), Some(_)) => {
            return Err(Usage(format!(
                "--coeffs-override: {from} holds {}, this unit's own set; there is nothing to override",
                chosen.set.describe()
            ))
            .into());
        }
        (Err(e @ gyrobench::coeffs::SetMismatch::NoModel4 { .. }), _) => {
            return Err(Usage(e.to_string()).into());
        }
        (Err(e), None) => return Err(Usage(e.to_string()).into()),
        (Err(e), Some(reason)) => {
            let reason = reason.trim();
            if reason.is_empty() || reason.chars().any(char::is_control) || reason.len() > 500 {
                return Err(Usage(
                    "--coeffs-override needs a reason: one line of at most 500 characters".into(),
                )
                .into());
            }
            errln!("warning: {e}; used anyway: {reason}");
            chosen.used.override_reason = Some(reason.to_owned());
        }
    }
    if let Some(id) = chosen
        .used
        .identity
        .as_ref()
        .filter(|i| i.status != SetStatus::Registered)
    {
        errln!(
            "warning: {from}: {}; the run records it as {}",
            id.note,
            id.head()
        );
    }
    Ok(chosen)
}

/// The set of `chosen` with its identity as the results store `store`
/// knows it. A store that is not given or cannot be reached never stops
/// the run: the set is recorded as not checked, saying why.
fn identified(chosen: Chosen, store: &gyrobench::results::Location) -> Chosen {
    let sha = chosen.used.sha256.clone().unwrap_or_default();
    let identity = match gyrobench::results::Store::open(store) {
        Ok(Some(mut s)) => match s.identify_set(&chosen.set, &sha) {
            Ok(id) => id,
            Err(e) => SetIdentity::unchecked(&chosen.set, Some(s.name()), &e.to_string()),
        },
        Ok(None) => SetIdentity::unchecked(
            &chosen.set,
            None,
            "no results store (--db none) to check it against",
        ),
        Err(e) => SetIdentity::unchecked(&chosen.set, Some(&store.describe()), &e.to_string()),
    };
    chosen.identified(identity)
}

/// The unit's newest coefficient set in the results store, its text
/// checked against what the store recorded of it.
fn latest_set(
    store: &gyrobench::results::Location,
    dut_type: &str,
    serial: &str,
) -> Result<Chosen> {
    let Some(mut s) = gyrobench::results::Store::open(store)
        .context("opening the results store for --coeffs latest")?
    else {
        return Err(Usage(
            "--coeffs latest reads the unit's sets from the results store; --db none names none"
                .into(),
        )
        .into());
    };
    let Some((version, text)) = s.latest_coefficients(dut_type, serial)? else {
        return Err(Usage(format!(
            "the results store {} holds no coefficient set of {dut_type} {serial}; run `gyrobench calibrate` on the unit's runs first, or give --coeffs FILE",
            s.name()
        ))
        .into());
    };
    let src = gyrobench::config::Source::from_text(
        &format!("coefficient set {version} of {serial} in {}", s.name()),
        &text,
    );
    let chosen = Chosen::from_source(&src, CoeffsSource::Store, s.name())?;
    let sha = chosen.used.sha256.clone().unwrap_or_default();
    let identity = s.identify_set(&chosen.set, &sha)?;
    Ok(chosen.identified(identity))
}

pub fn run(args: RunArgs) -> Result<Outcome> {
    let pacing = pacing(&args.speed)?;
    if args.force && args.out.is_none() {
        return Err(Usage("--force applies with --out DIR only".into()).into());
    }
    let (plan, place) = match (&args.resume, &args.procedure) {
        (Some(dir), _) => {
            let locked = session::lock_for_resume(dir)?;
            let plan = session::plan_resume(dir, pacing, &args.speed, args.db.as_deref())?;
            if let Some(r) = plan.resumed() {
                errln!("{}", r.summary);
            }
            (plan, Place::Resume(locked))
        }
        (None, Some(p)) => {
            let plan = fresh(&args, p, pacing)?;
            let place = match &args.out {
                Some(path) => Place::At {
                    path: path.clone(),
                    force: args.force,
                },
                None => Place::Auto {
                    base: PathBuf::from("runs"),
                },
            };
            (plan, place)
        }
        (None, None) => return Err(Usage("give a procedure file or --resume DIR".into()).into()),
    };
    check_prompts(&plan, args.unattended)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let interrupt = Arc::new(Interrupt::default());
    let exit_code = Arc::new(AtomicU8::new(130));
    rt.block_on(async { watch_signals(interrupt.clone(), exit_code.clone()) })?;
    let live = match args.live {
        Some(addr) => {
            let live = rt.block_on(LiveStream::start(addr)).map_err(|e| match e {
                LiveError::NotLoopback(_) => anyhow::Error::from(Usage(e.to_string())),
                e => e.into(),
            })?;
            errln!("{}", live.banner());
            Some(Arc::new(live))
        }
        None => None,
    };
    let plan = plan.with_live(live.clone());
    let mut progress = Live::new(session::estimated_s(&plan), args.unattended);
    errln!("running {}", plan.procedure().meta.name);
    let finished = match session::execute(plan, place, &rt, &mut progress, interrupt) {
        Ok(f) => f,
        Err(
            e @ (SessionError::RunDir(
                RunDirError::Exists { .. }
                | RunDirError::NotARun { .. }
                | RunDirError::Locked { .. }
                | RunDirError::Suspicious { .. },
            )
            | SessionError::CalibrationOverdue { .. }
            | SessionError::BenchLock(gyrobench::session::benchlock::BenchLockError::InUse {
                ..
            })),
        ) => {
            return Err(Usage(e.to_string()).into());
        }
        Err(e) => return Err(e.into()),
    };
    for n in finished.notes.iter().skip(finished.notes_at_begin) {
        errln!("note: {n}");
    }
    if let Some(live) = live.and_then(|l| Arc::try_unwrap(l).ok()) {
        rt.block_on(live.stop());
    }
    if finished.units.is_empty() {
        outf!("{}", finished.report.render_text())?;
    } else {
        for u in &finished.units {
            outf!("{}", u.report.render_text())?;
        }
        outf!("{}", render_batch(&finished.units))?;
    }
    outf!("  run directory: {}\n", finished.dir.display())?;
    match &finished.report_error {
        None => errln!("log and report in {}", finished.dir.display()),
        Some(e) => {
            errln!(
                "log in {}; the report could not be written ({e}); the figures are above, and report.json follows:",
                finished.dir.display()
            );
            errln!("{}", finished.report.to_json());
        }
    }
    // A batch ends as its worst unit.
    Ok(match finished.result.worst() {
        _ if finished.report_error.is_some() => Outcome::Error,
        worst => Outcome::of_run(worst, exit_code.load(Ordering::Relaxed)),
    })
}

/// The batch's summary: one line per unit (slot, serial, verdict, report).
fn render_batch(units: &[session::FinishedUnit]) -> String {
    let mut out = format!("batch of {} units:\n", units.len());
    for u in units {
        let why = u
            .report
            .error
            .as_ref()
            .map_or(String::new(), |e| format!(" ({})", e.message));
        out.push_str(&format!(
            "  slot {:<4} {:<20} {:<7} {}.html{why}\n",
            u.slot,
            u.serial,
            u.report.outcome.as_str().to_uppercase(),
            u.file
        ));
    }
    out
}

/// The signals that stop a run, how the report names them, and the exit
/// code of a run they stop (128 + the signal's number).
fn stop_signals() -> [(tokio::signal::unix::SignalKind, &'static str, u8); 4] {
    use tokio::signal::unix::SignalKind;
    [
        (SignalKind::interrupt(), "Ctrl-C (SIGINT)", 130),
        (SignalKind::terminate(), "SIGTERM", 143),
        (SignalKind::hangup(), "SIGHUP", 129),
        // Ctrl-\ would otherwise kill the run without its safe state.
        (SignalKind::quit(), "SIGQUIT (Ctrl-\\)", 131),
    ]
}

/// First Ctrl-C, SIGTERM, SIGHUP or SIGQUIT: stop, bring the bench to its safe
/// state, clean up, write the report. A second one: exit at once, without
/// cleanup. The handlers are installed before this returns, so no early
/// signal kills the run.
fn watch_signals(interrupt: Arc<Interrupt>, exit_code: Arc<AtomicU8>) -> Result<()> {
    use tokio::signal::unix::signal;
    for (kind, name, code) in stop_signals() {
        let mut sig = signal(kind).with_context(|| format!("installing the {name} handler"))?;
        let interrupt = interrupt.clone();
        let exit_code = exit_code.clone();
        tokio::spawn(async move {
            while sig.recv().await.is_some() {
                if interrupt.request(name) {
                    exit_code.store(code, Ordering::Relaxed);
                    errln!(
                        "{name}: stopping; the bench goes to its safe state and cleanup runs (again to exit at once, without cleanup)"
                    );
                } else {
                    errln!("{name} again: exiting without cleanup");
                    std::process::exit(i32::from(code));
                }
            }
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrobench::analysis::series::Interval;

    /// The progress line shows the record's mean over its last minute,
    /// named, and neither the 1 s sample nor a slew's second.
    #[test]
    fn the_progress_line_shows_the_drift_over_a_named_window() {
        let mut live = Live::new(3600.0, false);
        let second = |t: f64, rate: f64| Interval {
            time_s: t,
            rate_dph: rate,
            t1_c: 26.28,
            t2_c: 25.33,
            tcase_c: 21.17,
            ..Interval::default()
        };
        let before = second(0.5, 4477.9);
        let _ok = live.observe(&Event::Interval {
            slot: 0,
            iv: &before,
            record: None,
        });
        assert_eq!(
            live.rate,
            "  drift - (no record yet)  T1/T2/TK 26.28/25.33/21.17 degC"
        );
        for k in 0..90 {
            let r = if k % 2 == 0 { 0.152 } else { 0.652 };
            let iv = second(1.5 + f64::from(k), r);
            let _ok = live.observe(&Event::Interval {
                slot: 0,
                iv: &iv,
                record: Some("up"),
            });
        }
        assert_eq!(
            live.rate,
            "  drift +0.402 deg/h, mean of the last 60 s of record up  T1/T2/TK 26.28/25.33/21.17 degC"
        );
        let slew = second(95.5, -4701.8);
        let _ok = live.observe(&Event::Interval {
            slot: 0,
            iv: &slew,
            record: None,
        });
        assert!(
            live.rate.contains("+0.402 deg/h") && live.rate.contains("(ended)"),
            "{}",
            live.rate
        );
    }
}
