//! `gyrobench station`: the operator's page. A local web app (axum) that
//! starts runs on the bench through the same session code `run` uses, and
//! shows them live to any number of browsers (server-sent events); the
//! state lives here, so a browser closed, reloaded or opened later sees the
//! run from its start.
//!
//! Every state change is a POST carrying the station's token (printed with
//! the URL at start): another site's page cannot post to it (a custom
//! header needs a CORS preflight the station never grants), and on a lab
//! network nobody without the URL can.

mod gate;
pub mod listener;
mod routes;
mod sign;
mod state;

pub use routes::router;
pub use sign::SignRequest;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};

use gyrobench::bench::BenchConfig;
use gyrobench::procedure::Procedure;
use gyrobench::procedure::estimate::min_total_s;
use gyrobench::sequencer::Outcome;
use gyrobench::sequencer::interrupt::Interrupt;
use gyrobench::session::{self, Place, Plan};
use state::{Reporter, RunPhase, RunView, Shared, StepView};

/// How the station runs its benches.
#[derive(Debug, Clone)]
pub struct Config {
    /// The bench.
    pub bench: BenchConfig,
    /// The bench as named to the operator (`embedded` or the file).
    pub bench_label: String,
    /// Where the procedures are (`*.toml`).
    pub procedures: PathBuf,
    /// Where run directories go.
    pub runs: PathBuf,
    /// The results store.
    pub store: gyrobench::results::Location,
    /// `max` or a factor (the embedded bench).
    pub speed: String,
    /// Pacing of the embedded bench.
    pub pacing: gyrobench::clock::Pacing,
    /// Token every state change carries.
    pub token: String,
    /// The store as given (`--db`), for resumed runs.
    pub db: Option<String>,
    /// The live Foxglove stream every run publishes on, if any.
    pub live: Option<Arc<gyrobench::runlog::live::Live>>,
}

/// The station: its configuration, the board and the run going on.
#[derive(Debug)]
pub struct Station {
    cfg: Config,
    shared: Arc<Shared>,
    /// The running run's stop request (none when idle).
    interrupt: std::sync::Mutex<Option<Arc<Interrupt>>>,
    runs_started: std::sync::atomic::AtomicU64,
    /// Set when the station stops: event streams end, so that open
    /// browsers do not hold the shutdown.
    stopping: std::sync::atomic::AtomicBool,
    /// Each procedure file as last checked: its (size, modification
    /// time), the offer and the procedure.
    offers: std::sync::Mutex<OfferCache>,
}

/// Procedure files as checked, by file name.
type OfferCache = std::collections::HashMap<
    String,
    (
        (u64, Option<std::time::SystemTime>),
        Offer,
        Option<Procedure>,
    ),
>;

/// A procedure the page offers.
#[derive(Debug, Clone, Serialize)]
pub struct Offer {
    /// File name in the procedures directory.
    pub file: String,
    /// Procedure name (or the file's, when it does not load).
    pub name: String,
    /// Its description.
    pub description: String,
    /// Device time it needs at least, s.
    pub device_s: Option<f64>,
    /// Its prompt steps (a checklist for the operator).
    pub prompts: Vec<String>,
    /// Why it cannot run, when `check` refuses it.
    pub problem: Option<String>,
}

/// Why the station refused a request.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// Missing or wrong token.
    #[error("this needs the station's token (the URL printed at start carries it)")]
    Token,
    /// A request's body did not arrive whole in time.
    #[error(
        "the request's body did not arrive within {} s of its head; send the whole body at once",
        timeout.as_secs_f64()
    )]
    SlowBody {
        /// The time a body has.
        timeout: Duration,
    },
    /// A request announced a body longer than the station reads.
    #[error("the request's body is longer than the {limit} bytes the station reads")]
    TooLarge {
        /// Bytes at most.
        limit: usize,
    },
    /// A request's body could not be read.
    #[error("the request's body could not be read (at most {limit} bytes, sent whole): {why}")]
    Body {
        /// Bytes at most.
        limit: usize,
        /// What failed.
        why: String,
    },
    /// A run is going on.
    #[error("the bench is busy: run {0} is going on; wait for it or abort it")]
    Busy(u64),
    /// Bad request.
    #[error("{0}")]
    Bad(String),
    /// Nothing of that name.
    #[error("{0}")]
    NotFound(String),
    /// A request for the results store on a station that keeps none.
    #[error(
        "this station keeps no results store (--db none): start it with --db STORE to sign \
         runs here, or sign with `gyrobench results sign`"
    )]
    NoStore,
    /// The results store could not be opened or failed.
    #[error("{0}")]
    Store(String),
}

impl IntoResponse for Refused {
    fn into_response(self) -> Response {
        let code = match self {
            Self::Token => StatusCode::FORBIDDEN,
            Self::Busy(_) => StatusCode::CONFLICT,
            Self::Bad(_) | Self::Body { .. } => StatusCode::BAD_REQUEST,
            Self::NotFound(_) => StatusCode::NOT_FOUND,
            Self::NoStore => StatusCode::CONFLICT,
            Self::Store(_) => StatusCode::SERVICE_UNAVAILABLE,
            Self::SlowBody { .. } => StatusCode::REQUEST_TIMEOUT,
            Self::TooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
        };
        let body = axum::Json(serde_json::json!({ "error": self.to_string() }));
        if matches!(
            self,
            Self::Token | Self::SlowBody { .. } | Self::TooLarge { .. } | Self::Body { .. }
        ) {
            // Whoever has no token gets no connection to keep either, nor
            // does a request whose body is unread or half read.
            let close = [(axum::http::header::CONNECTION, "close")];
            return (code, close, body).into_response();
        }
        (code, body).into_response()
    }
}

/// A start request.
#[derive(Debug, Clone, Deserialize)]
pub struct Start {
    /// File name of the procedure (as offered).
    pub procedure: String,
    /// Unit serial (scanned or typed); on a bench with slots, `serials`.
    #[serde(default)]
    pub serial: String,
    /// A bench with slots: each slot's unit serial by slot name (a slot
    /// left blank stays empty).
    #[serde(default)]
    pub serials: std::collections::BTreeMap<String, String>,
    /// Who runs it.
    #[serde(default)]
    pub operator: String,
}

impl Station {
    /// A station with nothing run yet.
    pub fn new(cfg: Config) -> Arc<Self> {
        let shared = Arc::new(Shared::default());
        shared.lock().live_url = cfg.live.as_ref().map(|l| l.url());
        Arc::new(Self {
            cfg,
            shared,
            interrupt: std::sync::Mutex::new(None),
            runs_started: std::sync::atomic::AtomicU64::new(0),
            stopping: std::sync::atomic::AtomicBool::new(false),
            offers: std::sync::Mutex::new(OfferCache::new()),
        })
    }

    /// The procedure files of the directory, by name.
    fn procedure_files(&self) -> Vec<String> {
        let mut files: Vec<String> = std::fs::read_dir(&self.cfg.procedures)
            .map(|d| {
                d.filter_map(|e| Some(e.ok()?.file_name().to_string_lossy().into_owned()))
                    .filter(|f| f.ends_with(".toml"))
                    .collect()
            })
            .unwrap_or_default();
        files.sort();
        files
    }

    /// The procedure `file` of the directory as offered, and the
    /// procedure itself when it passes `check`: checked once per version
    /// of the file (its size and modification time), not on every request.
    fn offer(&self, file: String) -> (Offer, Option<Procedure>) {
        let path = self.cfg.procedures.join(&file);
        let version = std::fs::metadata(&path)
            .ok()
            .map(|m| (m.len(), m.modified().ok()));
        let mut cache = self
            .offers
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(v) = &version
            && let Some((seen, offer, procedure)) = cache.get(&file)
            && seen == v
        {
            return (offer.clone(), procedure.clone());
        }
        let made = self.check_offer(file.clone());
        if let Some(v) = version {
            cache.insert(file, (v, made.0.clone(), made.1.clone()));
        }
        made
    }

    fn check_offer(&self, file: String) -> (Offer, Option<Procedure>) {
        let limits = self.cfg.bench.procedure_limits();
        match Procedure::load(&self.cfg.procedures.join(&file), &limits) {
            Ok(proc_) => (
                Offer {
                    file,
                    name: proc_.meta.name.clone(),
                    description: proc_.meta.description.clone(),
                    device_s: Some(min_total_s(&proc_, &limits)),
                    prompts: proc_
                        .steps()
                        .filter_map(|s| match &s.kind {
                            gyrobench::procedure::StepKind::Prompt { text } => Some(text.clone()),
                            _ => None,
                        })
                        .collect(),
                    problem: None,
                },
                Some(proc_),
            ),
            Err(e) => (
                Offer {
                    name: file.trim_end_matches(".toml").to_owned(),
                    file,
                    description: String::new(),
                    device_s: None,
                    prompts: Vec::new(),
                    problem: Some(e.to_string()),
                },
                None,
            ),
        }
    }

    /// The procedures of the directory, checked against the bench.
    pub fn offers(&self) -> Vec<Offer> {
        self.procedure_files()
            .into_iter()
            .map(|f| self.offer(f).0)
            .collect()
    }

    /// Start a run: refused when the serial is empty, the procedure does
    /// not pass `check`, or the bench is busy.
    pub fn start(self: &Arc<Self>, req: &Start) -> Result<u64, Refused> {
        self.which_serials(req)?;
        let batch = self.batch(req)?;
        // A scanner's trailing newline or blank is not part of the serial.
        let serial = batch
            .first()
            .map_or(req.serial.trim(), |u| u.serial.as_str());
        gyrobench::unit::check_serial(serial).map_err(|e| Refused::Bad(e.to_string()))?;
        if serial == gyrobench::unit::SIMULATED_SERIAL && !self.cfg.bench.is_embedded() {
            return Err(Refused::Bad(format!(
                "{serial} names no unit; scan the serial of the unit on this bench"
            )));
        }
        let operator = req.operator.trim();
        gyrobench::unit::check_operator(operator)
            .map_err(|e| Refused::Bad(format!("operator: {e}")))?;
        // Only a file the directory lists (never a path given by the page).
        let file = self
            .procedure_files()
            .into_iter()
            .find(|f| *f == req.procedure)
            .ok_or_else(|| Refused::NotFound(format!("no procedure {}", req.procedure)))?;
        let (offer, procedure) = self.offer(file);
        let Some(procedure) = procedure else {
            return Err(Refused::Bad(format!(
                "{} does not pass check: {}",
                offer.file,
                offer.problem.unwrap_or_default()
            )));
        };
        session::check_calibration(
            &self.cfg.bench,
            &self.cfg.bench_label,
            gyrobench::clock::utc_now().date_naive(),
        )
        .map_err(|e| Refused::Bad(e.to_string()))?;
        let path = self.cfg.procedures.join(&offer.file);
        let plan = Plan::new(
            procedure,
            path.display().to_string(),
            self.cfg.bench.clone(),
        )
        .with_bench_label(self.cfg.bench_label.clone())
        .with_store(self.cfg.store.clone())
        .with_dut(serial)
        .with_operator(operator)
        .with_seed(self.runs_started.load(std::sync::atomic::Ordering::Relaxed) + 1)
        .with_speed(self.cfg.speed.clone(), self.cfg.pacing)
        .with_live(self.cfg.live.clone())
        .with_batch(batch);
        let place = Place::Auto {
            base: self.cfg.runs.clone(),
        };
        self.launch(plan, place, offer.device_s.unwrap_or(0.0), None)
    }

    /// The request names its units the way this bench takes them: `serial`
    /// for a bench of one unit, `serials` by slot for a bench with slots;
    /// never both (one would be ignored). A blank `serial` or an empty
    /// `serials` is not given.
    fn which_serials(&self, req: &Start) -> Result<(), Refused> {
        let serial = !req.serial.trim().is_empty();
        let serials = !req.serials.is_empty();
        let slots = &self.cfg.bench.slots;
        if serial && serials {
            return Err(Refused::Bad(
                "`serial` and `serials` given together: give `serial` for a bench of one unit, \
                 or `serials` (each slot's unit) for a bench with slots, not both"
                    .into(),
            ));
        }
        if serials && slots.is_empty() {
            return Err(Refused::Bad(
                "this bench holds one unit: give its serial in `serial` (`serials` is for a bench with slots)"
                    .into(),
            ));
        }
        if serial && !slots.is_empty() {
            let names: Vec<&str> = slots.iter().map(|s| s.name.as_str()).collect();
            return Err(Refused::Bad(format!(
                "this bench has slots ({}): give each unit's serial by slot in `serials`, not `serial`",
                names.join(", ")
            )));
        }
        Ok(())
    }

    /// A bench with slots: the batch the request's serials make (every
    /// serial trimmed, blank slots empty, at least one unit); empty on a
    /// bench without.
    fn batch(&self, req: &Start) -> Result<Vec<session::BatchUnit>, Refused> {
        if self.cfg.bench.slots.is_empty() {
            return Ok(Vec::new());
        }
        let given: Vec<(String, String)> = req
            .serials
            .iter()
            .map(|(slot, serial)| (slot.clone(), serial.trim().to_owned()))
            .filter(|(_, serial)| !serial.is_empty())
            .collect();
        if given.is_empty() {
            return Err(Refused::Bad(
                "scan the serial of the unit in each slot (a slot left blank stays empty)".into(),
            ));
        }
        let path = Path::new(&self.cfg.bench_label);
        session::batch_units(&self.cfg.bench, Some(path), &given)
            .map_err(|(at, why)| Refused::Bad(format!("slot {}: {why}", given[at].0)))
    }

    /// Resume run `number` (interrupted: aborted or stopped by an error)
    /// from its last completed step, in a new part of its directory, as
    /// `run --resume` does.
    pub fn resume(self: &Arc<Self>, number: u64) -> Result<u64, Refused> {
        let dir = {
            let b = self.shared.lock();
            let run = b
                .run
                .as_ref()
                .filter(|r| r.number == number)
                .ok_or_else(|| Refused::NotFound(format!("no run {number} here")))?;
            if run.phase != RunPhase::Finished
                || !matches!(run.outcome, Some(Outcome::Aborted | Outcome::Error))
                || run.dir.is_empty()
            {
                return Err(Refused::Bad(format!(
                    "run {number} is not an interrupted run: only an aborted run or one stopped by an error resumes"
                )));
            }
            PathBuf::from(&run.dir)
        };
        if self.busy().is_some() {
            return Err(Refused::Busy(
                self.runs_started.load(std::sync::atomic::Ordering::Relaxed),
            ));
        }
        let locked = session::lock_for_resume(&dir).map_err(|e| Refused::Bad(e.to_string()))?;
        let plan = session::plan_resume(
            &dir,
            self.cfg.pacing,
            &self.cfg.speed,
            self.cfg.db.as_deref(),
        )
        .map_err(|e| Refused::Bad(e.to_string()))?;
        let plan = plan.with_live(self.cfg.live.clone());
        let summary = plan.resumed().map(|r| r.summary.clone());
        let estimate_s = session::estimated_s(&plan);
        self.launch(plan, Place::Resume(locked), estimate_s, summary)
    }

    /// The interrupt of the run going on, if one is.
    fn busy(&self) -> Option<Arc<Interrupt>> {
        self.interrupt
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// Take the bench for `plan` and run it on a thread of its own.
    fn launch(
        self: &Arc<Self>,
        plan: Plan,
        place: Place,
        estimate_s: f64,
        note: Option<String>,
    ) -> Result<u64, Refused> {
        let interrupt = Arc::new(Interrupt::default());
        {
            let mut slot = self
                .interrupt
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            if slot.is_some() {
                let n = self.runs_started.load(std::sync::atomic::Ordering::Relaxed);
                return Err(Refused::Busy(n));
            }
            *slot = Some(interrupt.clone());
        }
        let number = self
            .runs_started
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            + 1;
        let view = RunView {
            number,
            phase: RunPhase::Running,
            procedure: plan.procedure().meta.name.clone(),
            serial: plan.dut().to_owned(),
            operator: plan.operator().to_owned(),
            steps: plan
                .procedure()
                .steps()
                .map(|s| StepView {
                    key: s.key.clone(),
                    text: s.describe(),
                })
                .collect(),
            estimate_s,
            events: note.into_iter().collect(),
            units: plan
                .batch()
                .iter()
                .map(|u| state::UnitView {
                    slot: u.slot.name.clone(),
                    serial: u.serial.clone(),
                    ..state::UnitView::default()
                })
                .collect(),
            ..RunView::default()
        };
        self.shared.update(|b| {
            if let Some(done) = b.run.replace(view)
                && !done.dir.is_empty()
            {
                b.earlier.insert(done.number, done.dir);
            }
            b.samples.clear();
            b.answered = 0;
        });
        let station = self.clone();
        let spawned = std::thread::Builder::new()
            .name(format!("run-{number}"))
            .spawn(move || station.execute(plan, place, interrupt));
        if let Err(e) = spawned {
            *self
                .interrupt
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
            return Err(Refused::Bad(format!("cannot start the run: {e}")));
        }
        Ok(number)
    }

    /// The run, on its own thread and runtime, as `run` does it.
    fn execute(self: Arc<Self>, plan: Plan, place: Place, interrupt: Arc<Interrupt>) {
        let mut reporter = Reporter::new(self.shared.clone(), interrupt.clone());
        let finished = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .map_err(|e| format!("starting the async runtime: {e}"))
            .and_then(|rt| {
                session::execute(plan, place, &rt, &mut reporter, interrupt)
                    .map_err(|e| e.to_string())
            });
        self.shared.update(|b| {
            let Some(run) = &mut b.run else {
                return;
            };
            run.phase = RunPhase::Finished;
            run.prompt = None;
            match &finished {
                Ok(f) => {
                    run.outcome = Some(f.report.outcome);
                    run.summary = Some(f.report.render_text());
                    run.bench_left = f.report.bench_left.as_ref().map(|l| l.summary.clone());
                    run.dir = f.dir.display().to_string();
                    run.link = Some(f.report.link);
                    for (view, u) in run.units.iter_mut().zip(&f.units) {
                        view.outcome = Some(u.report.outcome);
                        view.report = Some(format!("{}.html", u.file));
                    }
                    if !f.units.is_empty() {
                        run.outcome = Some(f.result.worst());
                    }
                    if let Some(e) = &f.report_error {
                        run.error = Some(format!("the report could not be written: {e}"));
                    }
                }
                Err(e) => {
                    run.outcome = Some(Outcome::Error);
                    run.error = Some(e.clone());
                }
            }
        });
        *self
            .interrupt
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = None;
    }

    /// Ask the running run to stop: the bench goes to its safe state and
    /// cleanup runs, as Ctrl-C does.
    pub fn abort(&self) -> Result<(), Refused> {
        let slot = self
            .interrupt
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let Some(i) = slot.as_ref() else {
            return Err(Refused::Bad("no run is going on".into()));
        };
        i.request("abort from the station page");
        drop(slot);
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.abort_requested = true;
                run.events
                    .push("abort asked: the bench goes to its safe state, cleanup runs".into());
            }
        });
        Ok(())
    }

    /// The station stops: a run going on is aborted (its cleanup runs)
    /// and every event stream ends; returns when no run is going on.
    pub async fn shut_down(&self) {
        self.stopping
            .store(true, std::sync::atomic::Ordering::Relaxed);
        self.shared.changed.notify_waiters();
        let _not_running = self.abort();
        self.wait_idle().await;
    }

    /// Until no run is going on.
    pub async fn wait_idle(&self) {
        loop {
            let busy = self
                .interrupt
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .is_some();
            if !busy {
                return;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// A file of run `number`'s directory: its report page or its log.
    fn run_file(&self, number: u64, name: &str) -> Result<PathBuf, Refused> {
        let b = self.shared.lock();
        let dir = b
            .run
            .as_ref()
            .filter(|r| r.number == number && !r.dir.is_empty())
            .map(|r| r.dir.as_str())
            .or_else(|| b.earlier.get(&number).map(String::as_str))
            .ok_or_else(|| Refused::NotFound(format!("no run {number} here")))?;
        let path = Path::new(dir).join(name);
        // A regular file of the run directory itself: a link planted there
        // (to a key, to another bench's data) is never followed.
        let regular = std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_file());
        if regular {
            Ok(path)
        } else {
            Err(Refused::NotFound(format!(
                "run {number} has no {name} (yet)"
            )))
        }
    }
}

/// A fresh random token (16 bytes, hex).
pub fn new_token() -> String {
    session::new_run_id()
}
