//! What the station knows of its run, as the page shows it: built by the
//! run's progress callbacks, read by every browser. A page opened late (or
//! reloaded) gets the whole run from its start.

use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

use serde::Serialize;

use gyrobench::analysis::series::Interval;
use gyrobench::procedure::Step;
use gyrobench::sequencer::{BenchState, Event, Observer, Operator};
use gyrobench::view::live::{Drift, DriftWindow};
use gyrobench_model::measurement::Measurement;

/// One step of the plan.
#[derive(Debug, Clone, Serialize)]
pub struct StepView {
    /// Key in the procedure (`main.3`).
    pub key: String,
    /// What it does, in words.
    pub text: String,
}

/// A measurement as computed.
#[derive(Debug, Clone, Serialize)]
pub struct MeasurementView {
    /// Name.
    pub name: String,
    /// Value (null when it could not be computed).
    pub value: Option<f64>,
    /// One standard error of the value, where the figure has one.
    pub std_error: Option<f64>,
    /// Unit.
    pub unit: String,
    /// `low..high`.
    pub limits: String,
    /// The verdict (serialised `pass`, `fail` or `error`).
    pub outcome: gyrobench::sequencer::measure::MeasureOutcome,
}

/// A question the run waits on.
#[derive(Debug, Clone, Serialize)]
pub struct PromptView {
    /// Its number in the run (answers name it).
    pub id: u64,
    /// The procedure's text.
    pub text: String,
}

/// Where the station's run is: the page shows the controls of a running
/// run or of a finished one (serialised `running`, `finished`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RunPhase {
    /// Started, not yet ended.
    #[default]
    Running,
    /// Ended, however it ended ([`RunView::outcome`]).
    Finished,
}

/// The run, without its samples.
#[derive(Debug, Clone, Default, Serialize)]
pub struct RunView {
    /// Station-local number of the run (1, 2, ...).
    pub number: u64,
    /// Running or finished.
    pub phase: RunPhase,
    /// Procedure name.
    pub procedure: String,
    /// Unit serial.
    pub serial: String,
    /// Operator.
    pub operator: String,
    /// Run directory.
    pub dir: String,
    /// Every step in run order.
    pub steps: Vec<StepView>,
    /// Index of the step running now.
    pub current: Option<usize>,
    /// Device time, s.
    pub device_s: f64,
    /// Device time the procedure needs at least (`check`'s estimate), s.
    pub estimate_s: f64,
    /// Wall time since the start, s.
    pub elapsed_wall_s: f64,
    /// Measurements as they were computed.
    pub measurements: Vec<MeasurementView>,
    /// Step starts and notes, oldest first.
    pub events: Vec<String>,
    /// The question the run waits on.
    pub prompt: Option<PromptView>,
    /// Abort was asked (cleanup runs).
    pub abort_requested: bool,
    /// How it ended, once finished (serialised `pass`, `fail`, `error`,
    /// `aborted`, as in the report).
    pub outcome: Option<gyrobench::sequencer::Outcome>,
    /// The report's summary lines once finished.
    pub summary: Option<String>,
    /// How the bench was left, once finished.
    pub bench_left: Option<String>,
    /// Why the run could not start or finish, if so.
    pub error: Option<String>,
    /// The gyro link's figures so far (each second of device time).
    pub link: Option<gyrobench::protocol::frame::LinkStats>,
    /// The unit's supply output as last read (benches with a supply).
    pub supply: Option<SupplyView>,
    /// A batch's units, one tile each (empty: one unit, `serial`).
    pub units: Vec<UnitView>,
    /// The bench and the first unit now, as numbers (none before the
    /// first tick).
    pub now: Option<NowView>,
}

/// The bench and the first unit as the page's read-out shows them: the
/// latest tick's chamber and table, the first unit's latest second and its
/// drift.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct NowView {
    /// Device time of the latest tick, s.
    pub t_s: f64,
    /// Chamber air, degC.
    pub chamber_c: f64,
    /// Chamber set point, degC.
    pub set_point_c: f64,
    /// Table outer axis, deg (measured).
    pub outer_deg: f64,
    /// Table inner axis, deg (measured).
    pub inner_deg: f64,
    /// The first unit's case, degC (none before its first second).
    pub tcase_c: Option<f64>,
    /// Its block sensor T1, degC.
    pub t1_c: Option<f64>,
    /// Its block sensor T2, degC.
    pub t2_c: Option<f64>,
    /// Its drift (none before its first record).
    pub drift: Option<Drift>,
}

/// One unit of a batch, as its tile shows it.
#[derive(Debug, Clone, Default, Serialize)]
pub struct UnitView {
    /// Its slot.
    pub slot: String,
    /// Its serial.
    pub serial: String,
    /// Its rate with the Earth rate removed, the last second's, deg/h
    /// (a slew's or a wait's too: the tile shows `drift`).
    pub bias_dph: Option<f64>,
    /// Its drift: the mean Earth-removed rate over the last 60 s of the
    /// record being taken (or the latest), named (none before a record).
    pub drift: Option<Drift>,
    /// Its case temperature, degC.
    pub tcase_c: Option<f64>,
    /// Its verdict once the run ended (as in its report).
    pub outcome: Option<gyrobench::sequencer::Outcome>,
    /// Its measurements outside their limits so far.
    pub failed: usize,
    /// Its report's file in the run directory, once written
    /// (`report-SERIAL.html`).
    pub report: Option<String>,
}

/// The unit's supply output, as the page shows it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct SupplyView {
    /// Volts measured.
    pub v: f64,
    /// Amperes measured.
    pub a: f64,
    /// Watts delivered.
    pub w: f64,
    /// Output on.
    pub on: bool,
    /// Over-current protection tripped.
    pub tripped: bool,
}

/// One 1 Hz sample of the first unit for the charts, sent as an array:
/// `[t_h, bias_dph, chamber_c, tcase_c, t1_c, t2_c, outer_deg, inner_deg,
/// record_dph, record_mean_dph]` (the last two `null` outside a record,
/// the mean also in a record's first minute).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sample {
    /// Device time, h.
    pub t_h: f64,
    /// Rate with the Earth rate (and the table's) removed, deg/h: every
    /// second, a slew's too.
    pub bias_dph: f64,
    /// Chamber air, degC.
    pub chamber_c: f64,
    /// Case, degC.
    pub tcase_c: f64,
    /// Block T1, degC.
    pub t1_c: f64,
    /// Block T2, degC.
    pub t2_c: f64,
    /// Table outer axis, deg.
    pub outer_deg: f64,
    /// Table inner axis, deg.
    pub inner_deg: f64,
    /// `bias_dph` when the second is one of a record's (the drift chart).
    pub record_dph: Option<f64>,
    /// The mean of the record's last 60 s, once it has lasted that long.
    pub record_mean_dph: Option<f64>,
}

/// As an array, the page's (and the API's) form since its first eight.
impl Serialize for Sample {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut t = s.serialize_tuple(10)?;
        for v in [
            self.t_h,
            self.bias_dph,
            self.chamber_c,
            self.tcase_c,
            self.t1_c,
            self.t2_c,
            self.outer_deg,
            self.inner_deg,
        ] {
            t.serialize_element(&v)?;
        }
        t.serialize_element(&self.record_dph)?;
        t.serialize_element(&self.record_mean_dph)?;
        t.end()
    }
}

/// The station's shared knowledge.
#[derive(Debug, Default)]
pub struct Board {
    /// The current (or last) run.
    pub run: Option<RunView>,
    /// Its samples.
    pub samples: Vec<Sample>,
    /// Bumped on every change (browsers wait on it).
    pub version: u64,
    /// The answer to prompt `id`, once given.
    pub answered: u64,
    /// When the newest sample arrived, Unix ms (a page's latency is its
    /// arrival minus this).
    pub sample_unix_ms: i64,
    /// Where runs are published live for Foxglove (`ws://...`), if they are.
    pub live_url: Option<String>,
    /// The directories of the runs this station ran before the current
    /// one, by number: their files stay reachable.
    pub earlier: std::collections::BTreeMap<u64, String>,
}

/// The board behind a lock, with a wake-up for the run waiting on a
/// prompt.
#[derive(Debug, Default)]
pub struct Shared {
    board: Mutex<Board>,
    answer: Condvar,
    /// Woken on every change (the event streams).
    pub changed: tokio::sync::Notify,
}

impl Shared {
    /// The board, locked (a poisoned lock still holds the last state).
    pub fn lock(&self) -> MutexGuard<'_, Board> {
        self.board.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Change the board and tell the browsers.
    pub fn update(&self, f: impl FnOnce(&mut Board)) {
        {
            let mut b = self.lock();
            f(&mut b);
            b.version += 1;
        }
        self.changed.notify_waiters();
    }

    /// Answer prompt `id`; false when no such prompt waits.
    pub fn answer(&self, id: u64) -> bool {
        let mut ok = false;
        self.update(|b| {
            if let Some(run) = &mut b.run
                && run.prompt.as_ref().is_some_and(|p| p.id == id)
            {
                run.prompt = None;
                run.events.push("operator confirmed".into());
                b.answered = id;
                ok = true;
            }
        });
        self.answer.notify_all();
        ok
    }
}

/// The run's progress, told to the board.
pub struct Reporter {
    /// Where it goes.
    pub shared: Arc<Shared>,
    /// Asked to stop (a prompt stops waiting then).
    pub interrupt: Arc<gyrobench::sequencer::interrupt::Interrupt>,
    /// Wall clock of the start.
    pub started: std::time::Instant,
    /// Prompts asked so far.
    pub prompts: u64,
    /// The state of the latest tick (the first unit's interval after it
    /// takes the table's angles from it for its chart point).
    pub tick: Option<BenchState>,
    /// Each unit's drift window, by slot.
    pub drifts: Vec<DriftWindow>,
}

impl Reporter {
    /// A run's reporter to `shared`, which stops waiting on a prompt when
    /// `interrupt` is asked.
    pub fn new(
        shared: Arc<Shared>,
        interrupt: Arc<gyrobench::sequencer::interrupt::Interrupt>,
    ) -> Self {
        Self {
            shared,
            interrupt,
            started: std::time::Instant::now(),
            prompts: 0,
            tick: None,
            drifts: Vec::new(),
        }
    }
}

impl std::fmt::Debug for Reporter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Reporter")
            .field("prompts", &self.prompts)
            .finish_non_exhaustive()
    }
}

/// The board shows the run as it goes: its steps, warnings, the bench's
/// state, each unit's latest second and measurements, the link figures.
impl Observer for Reporter {
    fn observe(&mut self, event: &Event<'_>) -> std::io::Result<()> {
        match *event {
            Event::Begin { dir, notes } => self.begin(dir, notes),
            Event::Warning(text) => self.warn(text),
            Event::Doing {
                step,
                index,
                restore: false,
                ..
            } => self.step(step, index),
            Event::Doing {
                step,
                index,
                total,
                restore: true,
            } => self.restore(step, index, total),
            Event::State(st) => self.state(st),
            Event::Interval { slot, iv, record } => self.interval(slot, iv, record),
            Event::Link { slot: 0, stats, .. } => self.link(stats),
            Event::Measured { slot: 0, m } => self.measured(m),
            Event::Measured { slot, m } => self.slot_measured(slot, m),
            Event::Link { .. } | Event::Step(_) | Event::Line { .. } | Event::Tick { .. } => {}
        }
        Ok(())
    }
}

impl Reporter {
    fn begin(&mut self, dir: &std::path::Path, notes: &[String]) {
        let dir = dir.display().to_string();
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.dir = dir;
                run.events
                    .extend(notes.iter().map(|n| format!("note: {n}")));
            }
        });
    }

    fn warn(&mut self, text: &str) {
        let line = format!("warning: {text}");
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.events.push(line);
            }
        });
    }

    fn step(&mut self, step: &Step, index: usize) {
        let line = step.start_message();
        let wall = self.started.elapsed().as_secs_f64();
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.current = Some(index);
                run.elapsed_wall_s = wall;
                run.events.push(line);
            }
        });
    }

    fn restore(&mut self, step: &Step, index: usize, total: usize) {
        let line = format!(
            "restoring the bench before the resumed run goes on ({}/{total}): {}",
            index + 1,
            step.describe()
        );
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.events.push(line);
            }
        });
    }

    /// The bench's state after a tick: device time, the supply's reading.
    fn state(&mut self, st: &BenchState) {
        let wall = self.started.elapsed().as_secs_f64();
        self.tick = Some(st.clone());
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.device_s = st.t_s;
                run.elapsed_wall_s = wall;
                let now = run.now.get_or_insert_with(NowView::default);
                now.t_s = st.t_s;
                now.chamber_c = st.chamber.air_c;
                now.set_point_c = st.chamber.set_point_c;
                now.outer_deg = st.table.angles.outer_deg;
                now.inner_deg = st.table.angles.inner_deg;
                if let Some(p) = st.power {
                    run.supply = Some(SupplyView {
                        v: p.v,
                        a: p.a,
                        w: p.v * p.a,
                        on: p.on,
                        tripped: p.tripped,
                    });
                }
            }
        });
    }

    /// Unit `slot`'s latest second (in `record`, if any); the first
    /// unit's is a chart point and the read-out's too.
    fn interval(&mut self, slot: usize, iv: &Interval, record: Option<&str>) {
        if self.drifts.len() <= slot {
            self.drifts.resize_with(slot + 1, DriftWindow::default);
        }
        let window = &mut self.drifts[slot];
        window.push(iv.time_s, iv.bias_dph(), record);
        let drift = window.drift();
        let sample = (slot == 0)
            .then_some(())
            .and(self.tick.as_ref())
            .map(|st| Sample {
                t_h: iv.time_s / 3600.0,
                bias_dph: iv.bias_dph(),
                chamber_c: iv.chamber_c,
                tcase_c: iv.tcase_c,
                t1_c: iv.t1_c,
                t2_c: iv.t2_c,
                outer_deg: st.table.angles.outer_deg,
                inner_deg: st.table.angles.inner_deg,
                record_dph: record.map(|_| iv.bias_dph()),
                record_mean_dph: window.full_mean_dph(),
            });
        self.shared.update(|b| {
            if let Some(u) = b.run.as_mut().and_then(|r| r.units.get_mut(slot)) {
                u.bias_dph = Some(iv.bias_dph());
                u.tcase_c = Some(iv.tcase_c);
                u.drift = drift.clone();
            }
            if slot == 0
                && let Some(now) = b.run.as_mut().and_then(|r| r.now.as_mut())
            {
                now.tcase_c = Some(iv.tcase_c);
                now.t1_c = Some(iv.t1_c);
                now.t2_c = Some(iv.t2_c);
                now.drift = drift;
            }
            if let Some(s) = sample {
                b.samples.push(s);
                b.sample_unix_ms = gyrobench::clock::utc_now().timestamp_millis();
            }
        });
    }

    fn link(&mut self, stats: &gyrobench::protocol::frame::LinkStats) {
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.link = Some(*stats);
            }
        });
    }

    fn measured(&mut self, m: &Measurement) {
        let view = MeasurementView {
            name: m.name.clone(),
            value: m.value,
            std_error: m.std_error,
            unit: m.unit.clone(),
            limits: m.limits_text(),
            outcome: m.outcome,
        };
        let failed = m.outcome != gyrobench::sequencer::measure::MeasureOutcome::Pass;
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.measurements.push(view);
                if let Some(u) = run.units.first_mut() {
                    u.failed += usize::from(failed);
                }
            }
        });
    }

    fn slot_measured(&mut self, slot: usize, m: &Measurement) {
        let failed = m.outcome != gyrobench::sequencer::measure::MeasureOutcome::Pass;
        self.shared.update(|b| {
            if let Some(u) = b.run.as_mut().and_then(|r| r.units.get_mut(slot)) {
                u.failed += usize::from(failed);
            }
        });
    }
}

/// The station's operator answers prompts on the page.
impl Operator for Reporter {
    fn answers_prompts(&self) -> bool {
        true
    }

    fn prompt(
        &mut self,
        text: &str,
    ) -> Result<gyrobench::sequencer::Confirmed, gyrobench::sequencer::Unanswered> {
        self.prompts += 1;
        let id = self.prompts;
        let text = text.to_owned();
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.prompt = Some(PromptView { id, text });
            }
        });
        // The run waits here until the page answers, or an abort.
        let mut b = self.shared.lock();
        while b.answered < id && !self.interrupt.is_requested() {
            b = self
                .shared
                .answer
                .wait_timeout(b, std::time::Duration::from_millis(200))
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
        let answered = b.answered >= id;
        drop(b);
        self.shared.update(|b| {
            if let Some(run) = &mut b.run {
                run.prompt = None;
            }
        });
        if answered {
            Ok(gyrobench::sequencer::Confirmed::Now)
        } else {
            Err(gyrobench::sequencer::Unanswered::Aborted)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrobench::sequencer::Outcome;

    /// The page reads `phase` and `outcome` by these words (and a resume
    /// is offered on `aborted` or `error`): the enums keep them.
    #[test]
    fn phase_and_outcome_serialise_with_the_words_the_page_reads() {
        let mut run = RunView::default();
        let v = serde_json::to_value(&run).expect("json");
        assert_eq!(
            (&v["phase"], &v["outcome"]),
            (&"running".into(), &serde_json::Value::Null)
        );
        for (outcome, word) in [
            (Outcome::Pass, "pass"),
            (Outcome::Fail, "fail"),
            (Outcome::Error, "error"),
            (Outcome::Aborted, "aborted"),
        ] {
            run.phase = RunPhase::Finished;
            run.outcome = Some(outcome);
            let v = serde_json::to_value(&run).expect("json");
            assert_eq!(
                (&v["phase"], &v["outcome"]),
                (&"finished".into(), &word.into())
            );
        }
    }
}
