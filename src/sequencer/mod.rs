//! The sequencer: runs a validated procedure on a bench.
//!
//! Setup, main and cleanup as test sequencers have them: cleanup always
//! runs once setup has started, also after a device failure or an
//! interrupt. Time advances in one-second ticks of device time; every tick
//! hands the frames and the device state to its [`Observer`]s (the
//! recorder, the display) and to the record store that measure steps
//! compute on.

pub mod compensated;
pub mod device;
pub mod events;
pub mod finish;
pub mod guard;
pub mod health;
pub mod interrupt;
mod links;
pub mod measure;
pub mod resume;
pub mod spill;
pub mod uncertainty;

use std::sync::Arc;

use async_trait::async_trait;

use crate::driver::{ChamberReading, DeviceError, InPosition, TableReading};
use crate::geometry::{Orientation, TableAngles};
use crate::procedure::{POWER_TIMEOUT_S, Procedure, Step, StepKind};
pub use events::{Level, PowerOn, PowerOnSource, StepEvent, StepPhase};
use gyrobench_model::measurement::Measurement;
pub use interrupt::Interrupt;
use measure::Records;
pub use resume::{Resume, resume_plan};

/// One gyro frame as received (wire units).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameRecord {
    /// Sequence counter.
    pub seq: u8,
    /// Delta-angle counts.
    pub counts: i32,
    /// T1, T2, TK in the frame's temperature LSB.
    pub temps_raw: [i16; 3],
    /// Status bits.
    pub status: u16,
}

/// Device state at the end of a tick.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchState {
    /// Device time, s since the run started.
    pub t_s: f64,
    /// Chamber.
    pub chamber: ChamberReading,
    /// Table (measured).
    pub table: TableReading,
    /// Table angles last commanded.
    pub commanded: TableAngles,
    /// Body orientation (from the measured angles and the geometry).
    pub orientation: Orientation,
    /// Earth + table rate on the nominal sensitive axis, deg/h.
    pub reference_dph: f64,
    /// Both axes at their commanded angles and at rest (as last judged).
    pub in_position: bool,
    /// The unit's supply channel (none: the bench has no supply).
    pub power: Option<crate::driver::SupplyReading>,
}

/// What one tick brought.
#[derive(Debug, Clone, Default)]
pub struct Tick {
    /// Device time of the first frame's end, s.
    pub t0_s: f64,
    /// Frames received during the tick.
    pub frames: Vec<FrameRecord>,
    /// State at the end of the tick.
    pub state: Option<BenchState>,
    /// A batch's other units (slots after the first, in the bench's
    /// order): each one's frames and pose (the first unit's are `frames`
    /// and `state`'s).
    pub slots: Vec<SlotTick>,
}

/// What one tick brought from one more unit of a batch.
#[derive(Debug, Clone, Default)]
pub struct SlotTick {
    /// Frames received during the tick.
    pub frames: Vec<FrameRecord>,
    /// Its body orientation at the end of the tick (from the table's
    /// angles and its slot's mount).
    pub orientation: Orientation,
    /// Earth + table rate on its sensitive axis, the tick's mean, deg/h.
    pub reference_dph: f64,
}

impl BenchState {
    /// The state as unit `slot` of a batch sees it (0: the first, as is):
    /// its own orientation and reference.
    pub fn for_slot(&self, slot: usize, tick: &Tick) -> Self {
        let mut st = self.clone();
        if let Some(s) = slot.checked_sub(1).and_then(|k| tick.slots.get(k)) {
            st.orientation = s.orientation;
            st.reference_dph = s.reference_dph;
        }
        st
    }
}

impl Tick {
    /// The frames unit `slot` sent during the tick (0: the first).
    pub fn slot_frames(&self, slot: usize) -> &[FrameRecord] {
        match slot.checked_sub(1) {
            None => &self.frames,
            Some(k) => self.slots.get(k).map_or(&[], |s| &s.frames),
        }
    }
}

/// A bench the sequencer can drive.
#[async_trait]
pub trait BenchIo: Send {
    /// Device time now, s since the run started.
    fn now_s(&self) -> f64;
    /// True when the devices are simulated (prompts answer themselves).
    fn is_simulated(&self) -> bool;
    /// A simulated bench without a supply: its operator switches the unit
    /// on or off by hand, now (a device bench's operator does it on the
    /// bench; nothing to do here).
    fn power_by_hand(&mut self, _on: bool) {}
    /// Frame period, s.
    fn frame_dt_s(&self) -> f64;
    /// Device time by which a record's ends may fall off its frames', s:
    /// a record spans the host's clock, and frames reach the host late by
    /// a varying delay ([`BenchConfig::record_edge_s`](crate::bench::BenchConfig::record_edge_s)).
    fn record_edge_s(&self) -> f64;
    /// Angle per count, arcsec.
    fn lsb_arcsec(&self) -> f64;
    /// Temperature per LSB in frames, degC.
    fn temp_lsb_c(&self) -> f64;
    /// New chamber set point reached at `ramp_c_per_min`.
    async fn set_chamber(&mut self, set_c: f64, ramp_c_per_min: f64) -> Result<(), DeviceError>;
    /// Move the table (position mode).
    async fn move_table(&mut self, angles: TableAngles) -> Result<(), DeviceError>;
    /// Turn one table axis (`inner` or the outer) at `rate_dps` in rate
    /// mode; 0 brings it to rest, still in rate mode (a move returns it to
    /// position mode).
    async fn rotate_table(&mut self, inner: bool, rate_dps: f64) -> Result<(), DeviceError>;
    /// Safe state: table to a controlled stop, chamber to standby, the
    /// supply's output as the bench file's `safe_state` says (off unless
    /// it says otherwise).
    async fn safe_state(&mut self) -> Result<(), DeviceError>;
    /// Switch the unit's supply output on at `volts` with the current
    /// limit `limit_a` (and the bench's protection), or off.
    async fn set_power(&mut self, on: bool, volts: f64, limit_a: f64) -> Result<(), DeviceError>;
    /// The unit's supply output as read now (none: the bench has no
    /// supply).
    async fn read_power(&mut self) -> Result<Option<crate::driver::SupplyReading>, DeviceError>;
    /// Advance to device time `t_s`, filling `tick`.
    async fn advance(&mut self, t_s: f64, tick: &mut Tick) -> Result<(), DeviceError>;
    /// Link figures of the gyro so far.
    fn link_stats(&self) -> crate::protocol::frame::LinkStats;
    /// Units the bench reads: 1, or a batch's slots.
    fn units(&self) -> usize {
        1
    }
    /// What the status word of unit `slot`'s frames means (0: the first
    /// unit's; default: the documented frame's).
    fn status_bits(&self, _slot: usize) -> crate::protocol::frame::StatusBits {
        crate::protocol::frame::StatusBits::default()
    }
    /// Link figures of unit `slot`'s gyro so far (0: the first unit's,
    /// [`BenchIo::link_stats`]).
    fn slot_link_stats(&self, slot: usize) -> crate::protocol::frame::LinkStats {
        if slot == 0 {
            self.link_stats()
        } else {
            crate::protocol::frame::LinkStats::default()
        }
    }
    /// A batch's units whose links failed since last asked: the unit (0:
    /// the first) and why. The batch goes on without them; the run says
    /// so, and their records show what they lost.
    fn take_unit_faults(&mut self) -> Vec<(usize, String)> {
        Vec::new()
    }
    /// Device time until the commands given are carried out by the bench
    /// itself, s: a chamber ramp stepped by the host goes on only while
    /// the run ticks (0 when nothing is pending).
    fn pending_s(&self) -> f64 {
        0.0
    }
    /// Read the chamber and the table back (to verify the state a run
    /// leaves them in).
    async fn read_back(&mut self) -> Result<(ChamberReading, TableReading), DeviceError>;
    /// Let device time pass to `t_s` without the gyro (the end of a run,
    /// when the gyro may be what failed): commands the host carries out go
    /// on; the chamber and table as read at `t_s`.
    async fn idle(&mut self, t_s: f64) -> Result<(ChamberReading, TableReading), DeviceError>;
    /// Ask the chamber and the table what they are, each as it reports
    /// itself (or why it did not).
    async fn identify(&mut self) -> Identities;
    /// What the bench's links say as they drop, come back or are lost
    /// (none: a bench without links, the embedded one).
    fn link_watch(&self) -> Option<std::sync::Arc<crate::driver::LinkWatch>> {
        None
    }
}

/// The identities a bench's instruments reported.
#[derive(Debug, Clone)]
pub struct Identities {
    /// The chamber's.
    pub chamber: Result<crate::driver::Identity, String>,
    /// The table's.
    pub table: Result<crate::driver::Identity, String>,
    /// The supply's (none: the bench has no supply).
    pub supply: Option<Result<crate::driver::Identity, String>>,
}

/// What a run says as it goes, in order: one shape for whoever watches it
/// (the log, the progress display, the station, a study's collector). Each
/// takes what it needs and lets the rest go.
#[derive(Debug, Clone, Copy)]
pub enum Event<'a> {
    /// The run's directory and log are ready; the steps start next.
    /// `notes` are what the operator should know first (a stale lock
    /// taken over, an earlier run moved aside).
    Begin {
        /// The run's directory.
        dir: &'a std::path::Path,
        /// Said first.
        notes: &'a [String],
    },
    /// Step `index` of `total` (setup, main and cleanup, from 0) is taken
    /// up; `restore`: a resumed run restores the bench before going on,
    /// and this is its restore step `index` of `total`.
    Doing {
        /// The step.
        step: &'a Step,
        /// Which.
        index: usize,
        /// Of how many.
        total: usize,
        /// A restore step of a resumed run.
        restore: bool,
    },
    /// A step started, ended or was run to restore a resumed run, as the
    /// log keeps it.
    Step(&'a StepEvent),
    /// A line for people (note, measurement, error; step starts and ends
    /// in words at [`Level::Debug`]).
    Line {
        /// Device time, s.
        t_s: f64,
        /// How much it matters.
        level: Level,
        /// The words.
        message: &'a str,
    },
    /// A tick: every unit's frames and the bench's state, in order.
    Tick {
        /// The tick.
        tick: &'a Tick,
        /// The record being taken, if any.
        record: Option<&'a str>,
        /// The step's key.
        step: &'a str,
    },
    /// The bench's state after a tick (before its units' intervals).
    State(&'a BenchState),
    /// A 1 Hz interval of unit `slot` closed (0: the first unit; a batch's
    /// others after it, each after the tick's [`Event::State`]).
    Interval {
        /// The unit.
        slot: usize,
        /// Its mean second.
        iv: &'a crate::analysis::series::Interval,
        /// The record it belongs to, if any.
        record: Option<&'a str>,
    },
    /// Unit `slot`'s gyro link figures so far, after every tick (the log
    /// keeps them once a minute of device time).
    Link {
        /// The unit.
        slot: usize,
        /// Device time, s.
        t_s: f64,
        /// The figures.
        stats: &'a crate::protocol::frame::LinkStats,
    },
    /// A measurement of unit `slot` was computed.
    Measured {
        /// The unit.
        slot: usize,
        /// The measurement.
        m: &'a Measurement,
    },
    /// Something the operator should know now, the run going on (a
    /// batch's unit whose link failed).
    Warning(&'a str),
}

/// Whoever watches a run: the log (whose failed write stops the run,
/// except once cleanup has begun), the progress display, the station.
pub trait Observer {
    /// Take `event` (what the observer does not keep, it lets go).
    fn observe(&mut self, event: &Event<'_>) -> std::io::Result<()>;
}

/// An observer that is the run's operator too: it may be asked to
/// confirm a prompt.
pub trait Operator: Observer {
    /// Ask the operator to confirm `text`; returns how it was confirmed,
    /// or why it cannot be (the run then stops at the prompt). The
    /// default has no operator to ask: on a real bench a prompt it meets
    /// stops the run (a simulated one never asks it).
    fn prompt(&mut self, _text: &str) -> Result<Confirmed, Unanswered> {
        Err(Unanswered::NobodyWatches)
    }
    /// Whether an operator answers prompts even on a simulated bench (a
    /// station page); else a simulated run goes on without asking.
    fn answers_prompts(&self) -> bool {
        false
    }
}

/// Why a prompt was not answered (the run stops at it, saying so).
#[derive(Debug, thiserror::Error)]
pub enum Unanswered {
    /// No operator watches the run (the default [`Operator`]).
    #[error("nobody watches this run to answer it")]
    NobodyWatches,
    /// The run's standard input is not a terminal.
    #[error(
        "there is no terminal to answer it on; run it from a terminal or the station, or confirm \
         the procedure's prompts beforehand with --unattended --operator NAME"
    )]
    NoTerminal,
    /// The terminal closed (end of input) while the prompt waited.
    #[error("the terminal closed before it was answered")]
    TerminalClosed,
    /// The terminal could not be read.
    #[error("the terminal could not be read ({0})")]
    TerminalUnreadable(#[source] std::io::Error),
    /// The run was aborted while the prompt waited (the station's Abort).
    #[error("the run was aborted at the prompt")]
    Aborted,
}

/// How an operator confirmed a prompt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Confirmed {
    /// Answered when asked (the terminal, the station's page).
    Now,
    /// Confirmed before the run started, for a run nobody watches
    /// (`run --unattended --operator NAME`).
    Beforehand,
}

/// Tell the run's operator (a display: whatever fails there loses nothing)
/// and then its log `e`; what the log's write came to.
fn tell(log: &mut dyn Observer, watch: &mut dyn Operator, e: &Event<'_>) -> std::io::Result<()> {
    let _ = watch.observe(e);
    log.observe(e)
}

/// How a run ended, the failure that ended it and the state it left the
/// bench in (the vocabulary crate's).
pub use gyrobench_model::outcome::{BenchLeft, Outcome, RunError};

/// Everything a run produced.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Verdict.
    pub outcome: Outcome,
    /// Measurements made (in step order).
    pub measurements: Vec<Measurement>,
    /// The failure, when outcome is error.
    pub error: Option<RunError>,
    /// Whether cleanup ran to its end.
    pub cleanup_completed: bool,
    /// Device time at the end, s.
    pub device_time_s: f64,
    /// Frames received.
    pub frames: u64,
    /// The 1 Hz records.
    pub records: Records,
    /// The state the bench was left in, as read back at the end.
    pub bench_left: Option<BenchLeft>,
    /// A batch's other units, in the bench's slot order (the fields above
    /// are the first unit's).
    pub others: Vec<UnitResult>,
}

/// What a run produced for one more unit of a batch.
#[derive(Debug, Clone, Default)]
pub struct UnitResult {
    /// Its verdict (none: the run stopped before its end, and every unit
    /// with it: the run's outcome and error are its).
    pub outcome: Option<Outcome>,
    /// Its measurements (in step order).
    pub measurements: Vec<Measurement>,
    /// Why it is an error, when it is.
    pub error: Option<RunError>,
    /// Frames received from it.
    pub frames: u64,
    /// Its 1 Hz records.
    pub records: Records,
}

impl RunResult {
    /// Units in the run: 1, or a batch's slots.
    pub fn units(&self) -> usize {
        1 + self.others.len()
    }

    /// Unit `k`'s 1 Hz records (0: the first unit's).
    pub fn unit_records(&self, k: usize) -> &Records {
        k.checked_sub(1)
            .and_then(|i| self.others.get(i))
            .map_or(&self.records, |u| &u.records)
    }

    /// The outcome of the whole run: its one unit's, or a batch's worst
    /// unit's (an aborted run aborted every unit; then an error before a
    /// failure before a pass).
    pub fn worst(&self) -> Outcome {
        self.unit(self.worst_unit()).outcome
    }

    /// Which unit is the worst ([`RunResult::worst`]; the first of equals).
    pub fn worst_unit(&self) -> usize {
        let rank = |o: Outcome| match o {
            Outcome::Pass => 0,
            Outcome::ConditionalPass => 1,
            Outcome::ConditionalFail => 2,
            Outcome::Fail => 3,
            Outcome::Error => 4,
            Outcome::Aborted => 5,
        };
        let outcome = |k: usize| match k.checked_sub(1).and_then(|i| self.others.get(i)) {
            Some(u) => u.outcome.unwrap_or(self.outcome),
            None => self.outcome,
        };
        (0..self.units())
            .rev()
            .max_by_key(|&k| rank(outcome(k)))
            .unwrap_or(0)
    }

    /// The run as unit `k` of a batch had it (0: the first): its verdict,
    /// measurements, frames and records, the shared end (cleanup, the
    /// bench left) as is.
    pub fn unit(&self, k: usize) -> Self {
        let Some(u) = k.checked_sub(1).and_then(|k| self.others.get(k)) else {
            return Self {
                others: Vec::new(),
                ..self.clone()
            };
        };
        Self {
            outcome: u.outcome.unwrap_or(self.outcome),
            measurements: u.measurements.clone(),
            error: match u.outcome {
                Some(_) => u.error.clone(),
                None => self.error.clone(),
            },
            cleanup_completed: self.cleanup_completed,
            device_time_s: self.device_time_s,
            frames: u.frames,
            records: u.records.clone(),
            bench_left: self.bench_left.clone(),
            others: Vec::new(),
        }
    }
}

/// No display and no operator: a run nobody watches.
#[derive(Debug)]
pub struct Quiet;

impl Observer for Quiet {
    fn observe(&mut self, _: &Event<'_>) -> std::io::Result<()> {
        Ok(())
    }
}

impl Operator for Quiet {}

/// Run options.
#[derive(Debug, Clone)]
pub struct Options {
    /// Model-4 coefficients for compensation (else fitted on the run).
    pub coeffs: Option<crate::coeffs::Compensation>,
    /// Asked to stop the run (cleanup still runs).
    pub interrupt: Arc<Interrupt>,
    /// Bench limit on the gyro's temperatures, degC.
    pub dut_max_c: f64,
    /// In-position tolerance, deg, and settle time, s.
    pub in_position: (f64, f64),
    /// Longest a move may take, s.
    pub move_timeout_s: f64,
    /// Continue an interrupted run instead of starting from the top.
    pub resume: Option<Resume>,
    /// The bench's safe state leaves the supply's output on
    /// (`devices.supply.safe_state = "on"`).
    pub supply_safe_on: bool,
    /// The bench's supply voltage and current limit (none: the bench has
    /// no supply): a run whose procedure does not switch the unit on
    /// itself switches it on at its start with them.
    pub supply: Option<(f64, f64)>,
    /// Wall time of this part's device time zero (the log's start): the
    /// UTC of a power-on.
    pub part_start_utc: Option<chrono::DateTime<chrono::Utc>>,
    /// A batch's units as the operator knows them (`slot A (RL16-0101)`),
    /// in order (empty: one unit).
    pub units: Vec<String>,
    /// A batch stops when one of its units cannot be judged (the bench's
    /// `on_unit_error = "stop"`); else that unit ends in error alone.
    pub stop_on_unit_error: bool,
    /// What the figures are judged by (the procedure's decision rule, the
    /// bench's declared uncertainties).
    pub judging: measure::Judging,
}

/// How long past its expected end the bench may take to settle at the end
/// of a run, s.
pub const SETTLE_MARGIN_S: f64 = 120.0;

/// The step key of the run's own switch-on at its start (a procedure
/// that does not switch the unit on itself): its rows and events say so.
pub const RUN_POWER_ON: &str = "power-on";

/// How long after switching the unit on the `power` step reads the bench
/// fast, s (ours: an RLG's turn-on inrush, the discharge igniting, is over
/// within a few tenths of a second; a 1 s tick would never see it).
pub const TURN_ON_WATCH_S: f64 = 1.0;

/// Below this share of its current limit, a unit just switched on draws
/// nothing: it has not started (ours: an RLG's converters draw from the
/// moment they are powered; the RL-16 draws 55 % of its 1 A limit).
pub const NO_DRAW_SHARE: f64 = 0.01;

/// How long a batch's unit may send no frame before a soak stops waiting
/// on its case, s (ours: ten ticks; a unit whose link is lost would
/// otherwise hold the whole batch until the soak's timeout).
pub const SOAK_STALE_S: f64 = 10.0;

/// The tick while a turn-on is watched, s (50 readings a second; a real
/// bench reads as fast as its instruments answer, at most this fast).
pub const TURN_ON_TICK_S: f64 = 0.02;

enum Stop {
    Device(DeviceError),
    Data(String),
    Interrupted,
}

impl Stop {
    fn message(&self) -> String {
        match self {
            Self::Device(d) => d.to_string(),
            Self::Data(m) => m.clone(),
            Self::Interrupted => "interrupted".into(),
        }
    }
}

struct Run<'a> {
    bench: &'a mut dyn BenchIo,
    log: &'a mut dyn Observer,
    watch: &'a mut dyn Operator,
    opts: &'a Options,
    records: Records,
    tick: Tick,
    last: Option<BenchState>,
    frames: u64,
    measurements: Vec<Measurement>,
    /// Cleanup is running: alarms were already acted on.
    cleaning_up: bool,
    /// The first log write that failed where the run could not stop for
    /// it (the safe state, cleanup): it still makes the run an error.
    log_failed: Option<String>,
    /// The link figures of the record step that just ended (for its end
    /// event).
    record_link: Option<crate::protocol::frame::LinkStats>,
    /// What the bench was last asked to do (verified at the end).
    expected: finish::Expected,
    /// A batch's other units (slots after the first).
    others: Vec<Lane>,
    /// The units (0: the first) whose record store's temporary file
    /// failed, and that was said.
    spill_said: Vec<usize>,
    /// The power-on a step just made (for its end event).
    pending_power_on: Option<PowerOn>,
}

/// One more unit of a batch as the run keeps it: the first unit's are the
/// run's own `records`, `frames` and `measurements`.
#[derive(Debug, Default)]
struct Lane {
    records: Records,
    frames: u64,
    measurements: Vec<Measurement>,
    link_before: crate::protocol::frame::LinkStats,
    /// Its link figures over the record step that just ended.
    record_link: Option<crate::protocol::frame::LinkStats>,
}

impl Run<'_> {
    /// Bring the bench to its safe state; false when that failed (said in
    /// the log).
    async fn safe_state(&mut self) -> bool {
        match self.bench.safe_state().await {
            Ok(()) => {
                self.expected.safe();
                true
            }
            Err(e) => {
                self.note(Level::Error, &format!("safe state failed: {e}"));
                // The supply was asked off (unless the bench keeps it on):
                // read back against that, so an output still on shows.
                if !self.expected.supply_safe_on {
                    self.expected.power_on = Some(false);
                }
                false
            }
        }
    }

    /// Tick until the bench has carried out what it was asked (a chamber
    /// ramp the host steps reaches its set point) and the table is at
    /// rest; bounded by the time that takes plus two minutes. Another stop
    /// request ends the wait.
    async fn settle(&mut self) -> Result<(), Stop> {
        let pending = self.bench.pending_s();
        if pending > 0.0 {
            self.note(
                Level::Info,
                &format!("the chamber reaches its final set point in {pending:.0} s"),
            );
        }
        let until = self.bench.now_s() + pending + SETTLE_MARGIN_S;
        // Not the last tick's table: a tick that failed (a log write, say)
        // after the bench moved on left it stale. At rest is seen afresh.
        let mut table: Option<TableReading> = None;
        // Ticks log the bench as it settles; when a tick fails (the gyro,
        // or the device that stopped the run), time passes without them.
        let mut ticking = true;
        loop {
            let at_rest = table.is_some_and(|t| {
                t.rates.outer_deg.abs() <= finish::AT_REST_DPS
                    && t.rates.inner_deg.abs() <= finish::AT_REST_DPS
            });
            if self.bench.pending_s() <= 0.0 && at_rest {
                return Ok(());
            }
            if self.bench.now_s() >= until {
                return Err(Stop::Data(format!(
                    "the bench still had {:.0} s of commands to carry out, or the table had not stopped, {SETTLE_MARGIN_S} s after it should have",
                    self.bench.pending_s()
                )));
            }
            if ticking {
                match self.tick(until, None, "end of run").await {
                    Ok(()) => table = self.last.as_ref().map(|st| st.table),
                    Err(Stop::Device(_)) => ticking = false,
                    Err(e) => return Err(e),
                }
            } else {
                let t = (self.bench.now_s() + 1.0).min(until);
                let (_, tr) = self.bench.idle(t).await.map_err(Stop::Device)?;
                table = Some(tr);
            }
        }
    }

    /// What a write to the log came to: a failure stops the run, except
    /// once cleanup has begun: a full disk stops logging, never cleanup
    /// (the failure is kept, and the run ends as an error naming it).
    fn written(&mut self, r: std::io::Result<()>) -> Result<(), Stop> {
        written(&mut self.log_failed, self.cleaning_up, r)
    }

    /// Write a line for people; a log that cannot be written stops the run
    /// (not its cleanup, [`Run::written`]).
    fn log(&mut self, level: Level, message: &str) -> Result<(), Stop> {
        let line = Event::Line {
            t_s: self.bench.now_s(),
            level,
            message,
        };
        let r = tell(self.log, self.watch, &line);
        self.written(r)
    }

    /// Tell the display that step `index` of `total` is taken up (a
    /// restore step of a resumed run when `restore`).
    fn doing(&mut self, step: &Step, index: usize, total: usize, restore: bool) {
        let e = Event::Doing {
            step,
            index,
            total,
            restore,
        };
        let _ = self.watch.observe(&e);
    }

    /// Tell the operator something now, the run going on.
    fn warn(&mut self, text: &str) {
        let _ = self.watch.observe(&Event::Warning(text));
    }

    /// Write a line where a failure must not stop what is being done
    /// (bringing the bench to a safe state); the failure is kept.
    fn note(&mut self, level: Level, message: &str) {
        if let Err(Stop::Data(e)) = self.log(level, message) {
            self.log_failed.get_or_insert(e);
        }
    }

    /// [`Run::log_step`] where a failure must not stop what is being done.
    fn note_step(&mut self, phase: StepPhase, index: usize, s: &Step) {
        if let Err(Stop::Data(e)) = self.log_step(phase, index, s) {
            self.log_failed.get_or_insert(e);
        }
    }

    /// Write a step event (and its line in words).
    fn log_step(&mut self, phase: StepPhase, index: usize, s: &Step) -> Result<(), Stop> {
        let mut e = crate::sequencer::events::step_event(self.bench.now_s(), phase, index, s);
        if phase != StepPhase::Start {
            e.power_on = self.pending_power_on.take();
        }
        if phase == StepPhase::End {
            e.link = self.record_link.take();
            if e.link.is_some() {
                e.slot_links = self
                    .others
                    .iter_mut()
                    .filter_map(|l| l.record_link.take())
                    .collect();
            }
        }
        let r = tell(self.log, self.watch, &Event::Step(&e));
        self.written(r)?;
        let words = match phase {
            StepPhase::Start => s.start_message(),
            StepPhase::End => format!("end of step {}", s.key),
            StepPhase::Restore => match &e.power_on {
                Some(on) => format!(
                    "power-on at {:.3} s of device time ({})",
                    on.t_s,
                    on.source.describe()
                ),
                None => format!("restore {} (line {}): {}", s.key, s.line, s.describe()),
            },
        };
        self.log(Level::Debug, &words)
    }

    /// Say which of a batch's links failed since the last tick: the batch
    /// goes on without those units.
    fn say_unit_faults(&mut self) {
        self.say_links();
        for (k, why) in self.bench.take_unit_faults() {
            let unit = self
                .opts
                .units
                .get(k)
                .map_or_else(|| format!("unit {}", k + 1), Clone::clone);
            let text = format!("{unit}: {why}; the batch goes on, its records say what it lost");
            self.warn(&text);
            self.note(Level::Warning, &text);
        }
        self.say_spill_faults();
    }

    /// Tell what the bench's links said since last asked (a drop, a
    /// return, a loss).
    fn say_links(&mut self) {
        if let Some(links) = self.bench.link_watch() {
            let t_s = self.bench.now_s();
            links::say(&links, t_s, self.log, self.watch, &mut self.log_failed);
        }
    }

    /// Say once per unit that its record store's temporary file failed
    /// (its rows stay in memory: nothing is lost).
    fn say_spill_faults(&mut self) {
        let faults: Vec<(usize, String)> = std::iter::once(&self.records)
            .chain(self.others.iter().map(|l| &l.records))
            .enumerate()
            .filter(|(k, _)| !self.spill_said.contains(k))
            .filter_map(|(k, r)| Some((k, r.write_fault()?)))
            .collect();
        for (k, why) in faults {
            self.spill_said.push(k);
            let unit = match self.opts.units.get(k) {
                Some(serial) if !self.others.is_empty() => format!("{serial}: "),
                _ if !self.others.is_empty() => format!("unit {}: ", k + 1),
                _ => String::new(),
            };
            let text = format!(
                "{unit}{why}: the run goes on, its memory now grows with its length (free space where TMPDIR points, or point TMPDIR at a disk with room, before the next run)"
            );
            self.warn(&text);
            self.note(Level::Warning, &text);
        }
    }

    /// What a tick's state stops the run for (not once cleanup has
    /// begun, for an alarm or a trip): a chamber alarm, the supply's
    /// over-current trip, a unit hotter than the bench allows (frames'
    /// temperatures at `tl` degC a count).
    fn judge_state(&self, state: &BenchState, tl: f64) -> Result<(), Stop> {
        if !state.chamber.alarms.is_empty() && !self.cleaning_up {
            return Err(Stop::Device(DeviceError::Alarm {
                device: "chamber".into(),
                codes: state.chamber.alarms.clone(),
            }));
        }
        if let Some(p) = &state.power
            && p.tripped
            && !self.cleaning_up
        {
            return Err(Stop::Device(DeviceError::Overcurrent {
                device: "supply".into(),
                limit_a: p.limit_a,
            }));
        }
        let units = self.bench.units();
        let (unit, hot) = (0..units)
            .map(|k| {
                let hottest = self
                    .tick
                    .slot_frames(k)
                    .iter()
                    .flat_map(|f| f.temps_raw)
                    .map(|r| f64::from(r) * tl)
                    .fold(f64::NEG_INFINITY, f64::max);
                (k, hottest)
            })
            .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
        if hot > self.opts.dut_max_c {
            let which = match self.opts.units.get(unit).filter(|_| units > 1) {
                Some(name) => format!(" of {name}"),
                None => String::new(),
            };
            return Err(Stop::Data(format!(
                "the gyro{which} reads {hot:.2} degC, above the bench limit dut_max_c = {} degC",
                self.opts.dut_max_c
            )));
        }
        Ok(())
    }

    /// Advance one tick (at most 1 s, never past `until_s`).
    async fn tick(&mut self, until_s: f64, record: Option<&str>, step: &str) -> Result<(), Stop> {
        if self.opts.interrupt.is_requested() {
            return Err(Stop::Interrupted);
        }
        let t0 = self.bench.now_s();
        let t = (t0 + 1.0).min(until_s);
        let links = self.bench.link_watch();
        let advanced = links::telling(
            self.bench.advance(t, &mut self.tick),
            links.as_deref(),
            t0,
            self.log,
            self.watch,
            &mut self.log_failed,
        )
        .await;
        if let Err(e) = advanced {
            // A wait on a dropped link that an interrupt ended: the run
            // stops as interrupted, the link's state said.
            if matches!(e, DeviceError::GaveUp { .. }) && !self.cleaning_up {
                if self.opts.interrupt.cause().is_some() {
                    self.note(Level::Warning, &e.to_string());
                    return Err(Stop::Interrupted);
                }
                // Found down after another link was lost: the run stops
                // for the first loss.
                if let Some(lost) = links.as_deref().and_then(|l| l.first_loss()) {
                    self.note(Level::Warning, &e.to_string());
                    return Err(Stop::Device(lost));
                }
            }
            return Err(Stop::Device(e));
        }
        self.say_unit_faults();
        self.frames += self.tick.frames.len() as u64;
        let r = tell(
            self.log,
            self.watch,
            &Event::Tick {
                tick: &self.tick,
                record,
                step,
            },
        );
        self.written(r)?;
        let dt = self.bench.frame_dt_s();
        let lsb = self.bench.lsb_arcsec();
        let tl = self.bench.temp_lsb_c();
        if let Some(state) = &self.tick.state {
            // The tick's state is the truth whatever it says (an alarm, a
            // hot unit): what follows the run's end judges from it.
            self.last = Some(state.clone());
            self.judge_state(state, tl)?;
            let r = tell(self.log, self.watch, &Event::State(state));
            written(&mut self.log_failed, self.cleaning_up, r)?;
            let iv = self
                .records
                .push_tick(&self.tick.frames, state, record, dt, lsb, tl);
            for (k, lane) in self.others.iter_mut().enumerate() {
                let frames = self.tick.slot_frames(k + 1);
                lane.frames += frames.len() as u64;
                let st = state.for_slot(k + 1, &self.tick);
                if let Some(iv) = lane.records.push_tick(frames, &st, record, dt, lsb, tl) {
                    let e = Event::Interval {
                        slot: k + 1,
                        iv: &iv,
                        record,
                    };
                    let r = tell(self.log, self.watch, &e);
                    written(&mut self.log_failed, self.cleaning_up, r)?;
                }
            }
            if let Some(p) = &state.power {
                // Replay files the logged reading the same way.
                self.records.push_power(
                    measure::PowerSample::of(state.t_s, p),
                    record.filter(|_| iv.is_some()),
                );
            }
            if let Some(iv) = iv {
                let e = Event::Interval {
                    slot: 0,
                    iv: &iv,
                    record,
                };
                let r = tell(self.log, self.watch, &e);
                written(&mut self.log_failed, self.cleaning_up, r)?;
            }
            for slot in 0..self.bench.units() {
                let stats = if slot == 0 {
                    self.bench.link_stats()
                } else {
                    self.bench.slot_link_stats(slot)
                };
                let e = Event::Link {
                    slot,
                    t_s: state.t_s,
                    stats: &stats,
                };
                let r = tell(self.log, self.watch, &e);
                written(&mut self.log_failed, self.cleaning_up, r)?;
            }
            self.last = Some(state.clone());
        }
        Ok(())
    }

    async fn run_for(
        &mut self,
        duration_s: f64,
        record: Option<&str>,
        step: &str,
    ) -> Result<(), Stop> {
        let end = self.bench.now_s() + duration_s;
        while self.bench.now_s() < end - 1e-9 {
            self.tick(end, record, step).await?;
        }
        Ok(())
    }

    async fn step(&mut self, s: &Step) -> Result<(), Stop> {
        let key = s.key.as_str();
        match &s.kind {
            StepKind::Chamber {
                set_c,
                ramp_c_per_min,
            } => {
                self.bench
                    .set_chamber(*set_c, *ramp_c_per_min)
                    .await
                    .map_err(Stop::Device)?;
                self.expected.chamber_set(*set_c);
                Ok(())
            }
            StepKind::Move { angles, .. } => self.move_step(key, *angles).await,
            StepKind::Soak {
                band_c,
                case_slope_c_per_min,
                hold_s,
                timeout_s,
            } => {
                self.soak_step(key, *band_c, *case_slope_c_per_min, *hold_s, *timeout_s)
                    .await
            }
            StepKind::Turn {
                inner,
                rate_dps,
                settle_s,
                acc_dps2,
            } => {
                self.turn_step(key, *inner, *rate_dps, *settle_s, *acc_dps2)
                    .await
            }
            StepKind::Power { on, .. } if self.opts.supply.is_none() => self.by_hand(s, *on),
            StepKind::Power {
                on: true,
                volts,
                limit_a,
                rest_if_on_s,
            } => self.switch_on(s, *volts, *limit_a, *rest_if_on_s).await,
            StepKind::Power {
                on: false,
                volts,
                limit_a,
                ..
            } => self.power_step(key, false, *volts, *limit_a).await,
            StepKind::Wait { duration_s } => self.run_for(*duration_s, None, key).await,
            StepKind::Record { label, duration_s } => {
                self.records
                    .start_frames(label, *duration_s, self.bench.record_edge_s());
                let before = self.bench.link_stats();
                for (k, lane) in self.others.iter_mut().enumerate() {
                    lane.records
                        .start_frames(label, *duration_s, self.bench.record_edge_s());
                    lane.link_before = self.bench.slot_link_stats(k + 1);
                }
                self.run_for(*duration_s, Some(label), key).await?;
                for (k, lane) in self.others.iter_mut().enumerate() {
                    let after = self.bench.slot_link_stats(k + 1);
                    let link = health::link_delta(&lane.link_before, &after);
                    lane.records.set_link(label, link);
                    lane.record_link = Some(link);
                }
                let link = health::link_delta(&before, &self.bench.link_stats());
                self.records.set_link(label, link);
                self.record_link = Some(link);
                Ok(())
            }
            StepKind::Measure(m) => self.measure_step(key, m),
            StepKind::Note { text } => self.log(Level::Info, text),
            StepKind::Prompt { text } => {
                self.log(Level::Info, &format!("prompt: {text}"))?;
                // Simulated benches have no operator to wait for.
                if !self.bench.is_simulated() || self.watch.answers_prompts() {
                    match self.watch.prompt(text) {
                        Ok(Confirmed::Now) => self.log(Level::Info, "operator confirmed")?,
                        Ok(Confirmed::Beforehand) => self.log(
                            Level::Info,
                            "confirmed beforehand by the operator (run --unattended)",
                        )?,
                        Err(_) if self.opts.interrupt.is_requested() => {
                            return Err(Stop::Interrupted);
                        }
                        Err(why) => {
                            return Err(Stop::Data(format!(
                                "the prompt of step {key} (line {}) needs an operator's answer before the run may go on: {why}",
                                s.line
                            )));
                        }
                    }
                }
                Ok(())
            }
        }
    }

    /// Move the table and wait until it is at rest in position.
    async fn move_step(&mut self, key: &str, angles: TableAngles) -> Result<(), Stop> {
        self.bench.move_table(angles).await.map_err(Stop::Device)?;
        self.expected.table_moved(angles);
        let (tol, settle) = self.opts.in_position;
        let mut ip = InPosition::new(tol, 0.01, settle);
        let deadline = self.bench.now_s() + self.opts.move_timeout_s;
        loop {
            self.tick(f64::INFINITY, None, key).await?;
            if let Some(st) = &self.last
                && ip.update(&st.table, angles, st.t_s)
            {
                return Ok(());
            }
            if self.bench.now_s() > deadline {
                return Err(Stop::Data(format!(
                    "the table did not settle on outer {:.3} / inner {:.3} deg within {} s; check the table",
                    angles.outer_deg, angles.inner_deg, self.opts.move_timeout_s
                )));
            }
        }
    }

    /// Wait until the chamber air is in its band and the case has settled, held for `hold_s`.
    async fn soak_step(
        &mut self,
        key: &str,
        band_c: f64,
        case_slope_c_per_min: f64,
        hold_s: f64,
        timeout_s: f64,
    ) -> Result<(), Stop> {
        let start = self.bench.now_s();
        let mut held_since: Option<f64> = None;
        // Every unit's case (a batch soaks until the slowest has settled).
        let mut cases = vec![std::collections::VecDeque::new(); self.bench.units()];
        loop {
            self.tick(f64::INFINITY, None, key).await?;
            let Some(st) = &self.last else { continue };
            for (k, case) in cases.iter_mut().enumerate() {
                let tk = self
                    .tick
                    .slot_frames(k)
                    .last()
                    .map(|f| f64::from(f.temps_raw[2]) * self.bench.temp_lsb_c());
                if let Some(tk) = tk {
                    case.push_back((st.t_s, tk));
                }
                while case.len() > 120 {
                    case.pop_front();
                }
            }
            // A batch's unit that has sent nothing for a while (its link
            // lost) is not waited on: the others soak on.
            let batch = cases.len() > 1;
            let read = cases
                .iter()
                .filter(|c| !batch || c.back().is_some_and(|(t, _)| st.t_s - t <= SOAK_STALE_S))
                .collect::<Vec<_>>();
            let (slope, settled) =
                read.iter()
                    .fold((0.0_f64, !read.is_empty()), |(worst, all), case| {
                        let slope = slope_per_min(case);
                        let worst = if slope.abs() > worst.abs() {
                            slope
                        } else {
                            worst
                        };
                        (worst, all && case.len() >= 60)
                    });
            // An air-only soak (no case criterion) needs no frames:
            // it holds while the unit is off.
            let case_ok = case_slope_c_per_min.is_infinite()
                || (settled && slope.abs() <= case_slope_c_per_min);
            let ok = (st.chamber.air_c - st.chamber.set_point_c).abs() <= band_c && case_ok;
            held_since = if ok {
                held_since.or(Some(st.t_s))
            } else {
                None
            };
            if held_since.is_some_and(|h| st.t_s - h >= hold_s) {
                return Ok(());
            }
            if st.t_s - start > timeout_s {
                return Err(Stop::Data(format!(
                    "soak not reached within {timeout_s} s (air {:.2} degC for set point {:.2}, case slope {slope:.3} degC/min)",
                    st.chamber.air_c, st.chamber.set_point_c
                )));
            }
        }
    }

    /// Turn a table axis at a rate (ramped at `acc_dps2` when given) and let it settle.
    async fn turn_step(
        &mut self,
        key: &str,
        inner: bool,
        rate_dps: f64,
        settle_s: f64,
        acc_dps2: Option<f64>,
    ) -> Result<(), Stop> {
        let axis_rate = |st: &BenchState| {
            if inner {
                st.table.rates.inner_deg
            } else {
                st.table.rates.outer_deg
            }
        };
        // A ramp at `acc_dps2` is the host's: the demand steps
        // towards the rate each tick (the table's own acceleration
        // is higher); without it the table ramps as fast as it can.
        let mut demand = match (acc_dps2, &self.last) {
            (Some(_), Some(st)) => axis_rate(st),
            _ => rate_dps,
        };
        self.bench
            .rotate_table(inner, demand)
            .await
            .map_err(Stop::Device)?;
        // At the rate when the axis reads it to a part in a thousand.
        let tol = 1e-3 * rate_dps.abs() + 1e-4;
        let deadline = self.bench.now_s()
            + self.opts.move_timeout_s
            + acc_dps2.map_or(0.0, |a| (rate_dps - demand).abs() / a);
        loop {
            let before = self.bench.now_s();
            self.tick(f64::INFINITY, None, key).await?;
            if let Some(a) = acc_dps2
                && demand != rate_dps
            {
                let dt = self.bench.now_s() - before;
                let step = a * dt;
                demand = if (rate_dps - demand).abs() <= step {
                    rate_dps
                } else {
                    demand + step * (rate_dps - demand).signum()
                };
                self.bench
                    .rotate_table(inner, demand)
                    .await
                    .map_err(Stop::Device)?;
            }
            if let Some(st) = &self.last
                && demand == rate_dps
                && (axis_rate(st) - rate_dps).abs() <= tol
            {
                break;
            }
            if self.bench.now_s() > deadline {
                return Err(Stop::Data(format!(
                    "the table's {} axis did not reach {rate_dps} deg/s within {} s; check the table",
                    if inner { "inner" } else { "outer" },
                    self.opts.move_timeout_s
                )));
            }
        }
        self.run_for(settle_s, None, key).await
    }

    /// A `power` step's switch-on: from off (a unit found powered is
    /// switched off and rested first when the step says how long, else
    /// the run refuses to go on), the moment recorded as the power-on
    /// the figures after it count from.
    async fn switch_on(
        &mut self,
        s: &Step,
        volts: f64,
        limit_a: f64,
        rest_if_on_s: Option<f64>,
    ) -> Result<(), Stop> {
        let key = s.key.as_str();
        let found_on = self
            .bench
            .read_power()
            .await
            .map_err(Stop::Device)?
            .is_some_and(|r| r.on);
        if found_on {
            let Some(rest) = rest_if_on_s else {
                return Err(Stop::Data(format!(
                    "the unit is already powered at step {key} (line {}), which switches it on: \
                     the figures after it count from that moment, and a warm unit would be judged \
                     as if cold; switch the unit off and let it cool before the run, or give the \
                     step rest_if_on_s",
                    s.line
                )));
            };
            let text = format!(
                "the unit was found powered at step {key} (line {}): switched off for a {rest:.0} s \
                 rest before its power-on, so that a warm unit is not judged as if cold",
                s.line
            );
            self.warn(&text);
            self.log(Level::Warning, &text)?;
            self.power_step(key, false, volts, limit_a).await?;
            self.run_for(rest, None, key).await?;
        }
        let t_on = self.bench.now_s();
        self.power_step(key, true, volts, limit_a).await?;
        self.powered_on(t_on, PowerOnSource::Switched);
        Ok(())
    }

    /// A `power` step on a bench without a supply: the operator switches
    /// the unit and confirms it, and a switch-on's moment is the
    /// confirmation's (source `operator`). A power-on confirmed before the
    /// run (`--unattended`) says nothing of when it happened: refused.
    fn by_hand(&mut self, s: &Step, on: bool) -> Result<(), Stop> {
        let what = if on { "on" } else { "off" };
        let text = format!(
            "switch the unit {what} now and confirm when it is {what} (step {}, line {}: the bench \
             has no supply{})",
            s.key,
            s.line,
            if on {
                "; the figures that count from power-on count from your confirmation"
            } else {
                ""
            }
        );
        self.log(Level::Info, &format!("prompt: {text}"))?;
        if !self.bench.is_simulated() || self.watch.answers_prompts() {
            match self.watch.prompt(&text) {
                Ok(Confirmed::Now) => self.log(Level::Info, "operator confirmed")?,
                Ok(Confirmed::Beforehand) => {
                    return Err(Stop::Data(format!(
                        "step {} (line {}) needs an operator at the bench to switch the unit {what}: \
                         a power-on confirmed beforehand (run --unattended) says nothing of when it \
                         happened",
                        s.key, s.line
                    )));
                }
                Err(_) if self.opts.interrupt.is_requested() => return Err(Stop::Interrupted),
                Err(why) => {
                    return Err(Stop::Data(format!(
                        "step {} (line {}) needs an operator's answer before the run may go on: {why}",
                        s.key, s.line
                    )));
                }
            }
        }
        // The simulated bench's operator switches its units at once.
        self.bench.power_by_hand(on);
        if on {
            self.powered_on(self.bench.now_s(), PowerOnSource::Operator);
        }
        Ok(())
    }

    /// Record a power-on at device time `t_on` (for the figures, and for
    /// the end event of the step that made it).
    fn powered_on(&mut self, t_on: f64, source: PowerOnSource) {
        let utc = self
            .opts
            .part_start_utc
            .map(|start| {
                (start + chrono::Duration::microseconds((t_on * 1e6).round() as i64))
                    .to_rfc3339_opts(chrono::SecondsFormat::Millis, true)
            })
            .unwrap_or_default();
        let on = PowerOn {
            t_s: t_on,
            utc,
            source,
        };
        // A batch's units share the one supply (or the operator's hand).
        for lane in &mut self.others {
            lane.records.power_on(on.clone());
        }
        self.records.power_on(on.clone());
        self.pending_power_on = Some(on);
    }

    /// At the start of a part: a bench with a supply whose procedure does
    /// not switch the unit on itself before anything else (its first
    /// `power` step is not a switch-on) has the unit switched on here,
    /// from off, the moment recorded. A unit found powered is left so,
    /// its power-on not known. `restoring`: a resumed part whose restore
    /// sets the power itself.
    async fn power_at_start(&mut self, p: &Procedure, restoring: bool) -> Result<(), Stop> {
        let first = p.setup.iter().chain(&p.main).find_map(|s| match s.kind {
            StepKind::Power { on, .. } => Some(on),
            _ => None,
        });
        let Some((volts, limit_a)) = self.opts.supply else {
            // A simulated bench without a supply whose procedure has its
            // operator switch the unit on: off until then.
            if first == Some(true) && !restoring && self.bench.is_simulated() {
                self.bench.power_by_hand(false);
            }
            return Ok(());
        };
        let Some(reading) = self.bench.read_power().await.map_err(Stop::Device)? else {
            return Ok(());
        };
        self.expected.power_on = Some(reading.on);
        if first == Some(true) || restoring {
            return Ok(());
        }
        if reading.on {
            return self.log(
                Level::Info,
                "the unit was found powered at the start of the run and is left on: its \
                 power-on time is not known, so the figures that count from power-on take the \
                 run's start",
            );
        }
        let step = Step {
            group: crate::procedure::Group::Setup,
            key: RUN_POWER_ON.into(),
            line: 0,
            kind: StepKind::Power {
                on: true,
                volts,
                limit_a,
                rest_if_on_s: None,
            },
        };
        self.log(
            Level::Info,
            "the run switches the unit on at its start (its procedure has no power step before \
             its records)",
        )?;
        let t_on = self.bench.now_s();
        self.power_step(&step.key, true, volts, limit_a).await?;
        self.powered_on(t_on, PowerOnSource::Switched);
        self.log_step(StepPhase::Restore, 0, &step)
    }

    /// Switch the unit's supply and wait until it reads so.
    async fn power_step(
        &mut self,
        key: &str,
        on: bool,
        volts: f64,
        limit_a: f64,
    ) -> Result<(), Stop> {
        self.bench
            .set_power(on, volts, limit_a)
            .await
            .map_err(Stop::Device)?;
        self.expected.power_set(on);
        // Until the output reads what was asked: on at the voltage
        // (within 2 %, out of current limit), or off. A turn-on is
        // read fast for its first second, so the inrush is seen.
        let now = self.bench.now_s();
        let deadline = now + POWER_TIMEOUT_S;
        let watch_end = if on { now + TURN_ON_WATCH_S } else { now };
        loop {
            let now = self.bench.now_s();
            let until = if now < watch_end - 1e-9 {
                (now + TURN_ON_TICK_S).min(watch_end)
            } else {
                f64::INFINITY
            };
            self.tick(until, None, key).await?;
            if self.bench.now_s() < watch_end - 1e-9 {
                continue;
            }
            let reached = self.last.as_ref().and_then(|st| st.power).is_some_and(|p| {
                if on {
                    p.on && (p.v - volts).abs() <= 0.02 * volts
                } else {
                    !p.on && p.v.abs() < 0.02 * p.set_v.max(1.0)
                }
            });
            if reached {
                return self.drawing(on, volts, limit_a);
            }
            if self.bench.now_s() > deadline {
                let now = self.last.as_ref().and_then(|st| st.power);
                return Err(Stop::Data(format!(
                    "the supply did not reach {} within {POWER_TIMEOUT_S} s (it reads {}); check the supply and the unit's cable",
                    if on {
                        format!("{volts} V")
                    } else {
                        "output off".into()
                    },
                    now.map_or("nothing".into(), |p| format!(
                        "{:.3} V, {:.4} A, output {}",
                        p.v,
                        p.a,
                        if p.on { "on" } else { "off" }
                    ))
                )));
            }
        }
    }

    /// After a turn-on: a unit that draws no current has not started (a
    /// voltage below its turn-on threshold, an open cable): the run stops
    /// here, not hours later on records without frames.
    fn drawing(&self, on: bool, volts: f64, limit_a: f64) -> Result<(), Stop> {
        let Some(p) = self.last.as_ref().and_then(|st| st.power).filter(|_| on) else {
            return Ok(());
        };
        if p.a >= NO_DRAW_SHARE * limit_a {
            return Ok(());
        }
        Err(Stop::Data(format!(
            "the unit draws no current at {volts} V ({:.4} A {TURN_ON_WATCH_S} s after switching on): it did not start; check the voltage against the unit's rating and its power cable",
            p.a
        )))
    }

    /// Compute a figure on the records so far and judge it.
    fn measure_step(&mut self, key: &str, m: &crate::procedure::Measure) -> Result<(), Stop> {
        let meas = measure::compute(
            m,
            &self.records,
            self.opts.coeffs.as_ref(),
            key,
            &self.opts.judging,
        );
        let msg = format!(
            "{} = {} {} [{}] ({})",
            meas.name,
            meas.value.map_or("n/a".to_owned(), |v| format!("{v:.4}")),
            meas.unit,
            meas.limits_text(),
            meas.outcome.as_str()
        );
        let level = if meas.outcome == measure::MeasureOutcome::Pass {
            Level::Info
        } else {
            Level::Warning
        };
        self.log(level, &msg)?;
        let _ = self.watch.observe(&Event::Measured { slot: 0, m: &meas });
        let mut unjudged = (meas.outcome == measure::MeasureOutcome::Error)
            .then(|| (0, format!("{} was {}", meas.name, meas.note)));
        self.measurements.push(meas);
        for (k, lane) in self.others.iter_mut().enumerate() {
            // Each unit is judged on its own records; coefficients are the
            // first unit's alone (a batch fits each unit's on its run).
            let meas = measure::compute(m, &lane.records, None, key, &self.opts.judging);
            let _ = self.watch.observe(&Event::Measured {
                slot: k + 1,
                m: &meas,
            });
            if meas.outcome == measure::MeasureOutcome::Error && unjudged.is_none() {
                unjudged = Some((k + 1, format!("{} was {}", meas.name, meas.note)));
            }
            lane.measurements.push(meas);
        }
        match unjudged {
            Some((unit, why)) if self.opts.stop_on_unit_error && !self.others.is_empty() => {
                let name = self.opts.units.get(unit).map_or("a unit", String::as_str);
                Err(Stop::Data(format!(
                    "{name}: {why}; the bench stops the batch when a unit cannot be judged (on_unit_error = \"stop\")"
                )))
            }
            _ => Ok(()),
        }
    }
}

/// Least-squares slope of (t s, value) pairs, per minute.
fn slope_per_min(pts: &std::collections::VecDeque<(f64, f64)>) -> f64 {
    let n = pts.len() as f64;
    if n < 2.0 {
        return f64::INFINITY;
    }
    let (mt, mv) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, v)| (a + t / n, b + v / n));
    let (sxy, sxx) = pts.iter().fold((0.0, 0.0), |(a, b), (t, v)| {
        (a + (t - mt) * (v - mv), b + (t - mt) * (t - mt))
    });
    if sxx > 0.0 {
        60.0 * sxy / sxx
    } else {
        f64::INFINITY
    }
}

/// Run `p` on `bench`, logging to `log`, watched by `watch`.
pub async fn run(
    p: &Procedure,
    bench: &mut dyn BenchIo,
    log: &mut dyn Observer,
    watch: &mut dyn Operator,
    opts: &Options,
) -> RunResult {
    let mut r = Run {
        bench,
        log,
        watch,
        opts,
        records: Records::default(),
        tick: Tick::default(),
        last: None,
        frames: 0,
        measurements: Vec::new(),
        cleaning_up: false,
        log_failed: None,
        record_link: None,
        expected: finish::Expected {
            supply_safe_on: opts.supply_safe_on,
            // Read at the start ([`Run::power_at_start`]).
            power_on: None,
            ..finish::Expected::default()
        },
        others: Vec::new(),
        spill_said: Vec::new(),
        pending_power_on: None,
    };
    r.others
        .resize_with(r.bench.units().saturating_sub(1), Lane::default);
    r.records.set_status_bits(r.bench.status_bits(0));
    for (k, lane) in r.others.iter_mut().enumerate() {
        lane.records.set_status_bits(r.bench.status_bits(k + 1));
    }
    // An interrupt ends every wait on a dropped link: the run stops now,
    // and a link found down from then on is tried once.
    if let Some(links) = r.bench.link_watch() {
        opts.interrupt
            .on_request(move |cause| links.stop_waiting(&format!("{cause} asked to stop")));
    }
    let total = p.steps().count();
    let mut stop: Option<(Stop, String)> = None;
    let start_at = opts.resume.as_ref().map_or(0, |res| res.start_at);
    if let Some(res) = &opts.resume {
        r.carry_on_from(res);
    }
    let restoring = opts.resume.as_ref().is_some_and(|res| {
        resume_plan(p, res.completed)
            .1
            .iter()
            .any(|(_, s)| matches!(s.kind, StepKind::Power { .. }))
    });
    if let Err(e) = r.power_at_start(p, restoring).await {
        stop = Some((e, "power-on".to_owned()));
    }
    if stop.is_none()
        && let Some(res) = &opts.resume
    {
        stop = restore(&mut r, p, res).await.err();
    }
    let run_order = p.setup.iter().chain(&p.main).enumerate();
    for (i, s) in run_order.skip(start_at) {
        if stop.is_some() {
            break;
        }
        r.doing(s, i, total, false);
        let done = async {
            r.log_step(StepPhase::Start, i, s)?;
            r.step(s).await?;
            r.log_step(StepPhase::End, i, s)
        };
        if let Err(e) = done.await {
            stop = Some((e, s.key.clone()));
        }
    }
    // Cleanup always runs once setup has started; a safe state comes first
    // whenever the run did not end normally. Failing log writes no longer
    // stop anything here: the bench comes first.
    let mut cleanup_completed = true;
    if stop.is_some() {
        r.note(
            Level::Warning,
            "run stopped: bringing the bench to a safe state",
        );
        cleanup_completed &= r.safe_state().await;
    }
    let interrupted = matches!(stop, Some((Stop::Interrupted, _)));
    r.opts.interrupt.rearm();
    r.cleaning_up = true;
    // A device that failed stays in its safe state: cleanup does not drive
    // it again (after a chamber alarm, a late set point would override
    // the standby the alarm called for).
    let faulted = match &stop {
        Some((Stop::Device(e), _)) => device_of(e),
        _ => None,
    };
    cleanup_completed &= r.cleanup(p, total, faulted.as_deref(), &mut stop).await;
    let (left, left_ok) = r.leave_bench(&mut stop).await;
    cleanup_completed &= left_ok;
    if stop.is_none()
        && let Some(e) = r.log_failed.take()
    {
        stop = Some((Stop::Data(e), "cleanup".into()));
    }
    // A store that failed in the run's last ticks is said too.
    r.say_spill_faults();
    let others = r.unit_results(stop.as_ref());
    let (outcome, error) = r.outcome(stop, interrupted);
    RunResult {
        others,
        outcome,
        measurements: r.measurements,
        error,
        cleanup_completed,
        device_time_s: r.bench.now_s() + opts.resume.as_ref().map_or(0.0, |res| res.device_time_s),
        frames: r.frames + opts.resume.as_ref().map_or(0, |res| res.frames),
        records: r.records,
        bench_left: Some(left),
    }
}

impl Run<'_> {
    /// A resumed run starts from what its earlier parts leave: every unit's
    /// records (taken from here in part `res.part`), measurements and
    /// frames.
    fn carry_on_from(&mut self, res: &Resume) {
        self.records = res.records.clone();
        self.records.set_part(res.part);
        self.measurements = res.measurements.clone();
        for (lane, earlier) in self.others.iter_mut().zip(&res.others) {
            lane.records = earlier.records.clone();
            lane.records.set_part(res.part);
            lane.measurements = earlier.measurements.clone();
            lane.frames = earlier.frames;
        }
    }

    /// The cleanup steps, each skipped when it would drive the device that
    /// failed (`faulted`); false when one was skipped or failed. A failed
    /// cleanup step becomes the run's stop when nothing else stopped it.
    async fn cleanup(
        &mut self,
        p: &Procedure,
        total: usize,
        faulted: Option<&str>,
        stop: &mut Option<(Stop, String)>,
    ) -> bool {
        let mut cleanup_completed = true;
        let first_cleanup = p.setup.len() + p.main.len();
        for (i, s) in p.cleanup.iter().enumerate() {
            let index = first_cleanup + i;
            self.doing(s, index, total, false);
            let needs = match s.kind {
                StepKind::Chamber { .. } | StepKind::Soak { .. } => Some("chamber"),
                StepKind::Move { .. } => Some("table"),
                StepKind::Power { .. } => Some("supply"),
                _ => None,
            };
            // A run that stopped leaves the unit as the safe state left it:
            // a cleanup that powers it again (a turn-on procedure's) is for
            // a run that went to its end, unless the bench's safe state
            // itself keeps the unit powered.
            if stop.is_some()
                && matches!(s.kind, StepKind::Power { on: true, .. })
                && !self.opts.supply_safe_on
            {
                cleanup_completed = false;
                if !self.expected.skipped.iter().any(|x| x == "supply") {
                    self.expected.skipped.push("supply".to_owned());
                }
                self.note(
                    Level::Warning,
                    &format!(
                        "cleanup step {} skipped: the run stopped, so the unit stays unpowered as the safe state left it (a bench whose devices.supply.safe_state is \"on\" powers it again)",
                        s.key
                    ),
                );
                continue;
            }
            if let (Some(d), Some(f)) = (needs, faulted)
                && d == f
            {
                cleanup_completed = false;
                if !self.expected.skipped.iter().any(|x| x == d) {
                    self.expected.skipped.push(d.to_owned());
                }
                self.note(
                    Level::Warning,
                    &format!(
                        "cleanup step {} skipped: the {d} failed during the run and stays in its safe state",
                        s.key
                    ),
                );
                continue;
            }
            self.note_step(StepPhase::Start, index, s);
            if let Err(e) = self.step(s).await {
                cleanup_completed = false;
                let msg = e.message();
                self.note(
                    Level::Error,
                    &format!("cleanup step {} failed: {msg}", s.key),
                );
                self.safe_state().await;
                if stop.is_none() {
                    *stop = Some((e, s.key.clone()));
                }
                break;
            }
            self.note_step(StepPhase::End, index, s);
        }
        cleanup_completed
    }

    /// Let the bench settle and read it back; a bench not as cleanup left
    /// it is brought to its safe state and read again. The bench as left,
    /// and false when it did not settle or is not in a known state (which
    /// becomes the run's stop when nothing else stopped it).
    async fn leave_bench(&mut self, stop: &mut Option<(Stop, String)>) -> (BenchLeft, bool) {
        let mut cleanup_completed = true;
        // The bench finishes what it was asked (a ramp the host steps goes on
        // to its set point) and comes to rest; then its state is read back.
        if let Err(e) = self.settle().await {
            cleanup_completed = false;
            self.note(
                Level::Error,
                &format!("the bench did not settle: {}", e.message()),
            );
            self.safe_state().await;
        }
        let in_position = self.opts.in_position.0;
        let mut left = finish::bench_left(self.bench, &self.expected, in_position).await;
        if !left.verified && !self.expected.safe_state {
            self.note(
                Level::Warning,
                &format!(
                    "the bench is not as cleanup asked ({}): bringing it to its safe state",
                    left.summary
                ),
            );
            self.safe_state().await;
            let _settled = self.settle().await;
            left = finish::bench_left(self.bench, &self.expected, in_position).await;
        }
        self.note(
            if left.verified {
                Level::Info
            } else {
                Level::Error
            },
            &format!("bench left: {}", left.summary),
        );
        if !left.verified {
            cleanup_completed = false;
            if stop.is_none() {
                *stop = Some((
                    Stop::Data(format!(
                        "the bench is not in a known state: {}",
                        left.summary
                    )),
                    "end of run".into(),
                ));
            }
        }
        (left, cleanup_completed)
    }

    /// A batch's other units at the end: each judged on its own
    /// measurements when the run went to its end; a run stopped early
    /// stopped every unit with it (the first unit's outcome and error).
    fn unit_results(&mut self, stop: Option<&(Stop, String)>) -> Vec<UnitResult> {
        let stopped = stop.is_some();
        std::mem::take(&mut self.others)
            .into_iter()
            .map(|lane| {
                let (outcome, error) = if stopped {
                    (None, None)
                } else {
                    let (o, e) = verdict(&lane.measurements);
                    (Some(o), e)
                };
                UnitResult {
                    outcome,
                    measurements: lane.measurements,
                    error,
                    frames: lane.frames,
                    records: lane.records,
                }
            })
            .collect()
    }

    /// The run's outcome and error from what stopped it (none: the
    /// verdict of the measurements).
    fn outcome(
        &mut self,
        stop: Option<(Stop, String)>,
        interrupted: bool,
    ) -> (Outcome, Option<RunError>) {
        match stop {
            None => verdict(&self.measurements),
            Some((Stop::Interrupted, step)) if interrupted => (
                Outcome::Aborted,
                Some(RunError {
                    device: None,
                    step,
                    message: format!(
                        "interrupted by {}",
                        self.opts
                            .interrupt
                            .cause()
                            .unwrap_or_else(|| "the operator".into())
                    ),
                }),
            ),
            Some((e, step)) => {
                let device = match &e {
                    Stop::Device(d) => device_of(d),
                    _ => None,
                };
                let message = e.message();
                self.note(Level::Error, &format!("error in step {step}: {message}"));
                (
                    Outcome::Error,
                    Some(RunError {
                        device,
                        step,
                        message,
                    }),
                )
            }
        }
    }
}

/// Bring the bench back to the conditions a resumed run needs
/// ([`resume_plan`]); the error names the restore step that failed.
async fn restore(r: &mut Run<'_>, p: &Procedure, res: &Resume) -> Result<(), (Stop, String)> {
    let (_, restore) = resume_plan(p, res.completed);
    let at = |e| (e, "resume".to_owned());
    r.log(
        Level::Info,
        &format!(
            "resume, part {}: {}",
            res.part,
            resume::describe_resume(p, res.completed)
        ),
    )
    .map_err(at)?;
    for (k, (index, s)) in restore.iter().enumerate() {
        r.doing(s, k, restore.len(), true);
        r.log_step(StepPhase::Restore, *index, s).map_err(at)?;
        r.step(s).await.map_err(|e| (e, s.key.clone()))?;
        // A restored switch-on is a power-on: said in a restore event.
        if r.pending_power_on.is_some() {
            r.log_step(StepPhase::Restore, *index, s).map_err(at)?;
        }
    }
    Ok(())
}

/// [`Run::written`] on the fields it needs.
fn written(
    log_failed: &mut Option<String>,
    cleaning_up: bool,
    r: std::io::Result<()>,
) -> Result<(), Stop> {
    match r {
        Ok(()) => Ok(()),
        Err(e) if cleaning_up => {
            log_failed.get_or_insert_with(|| format!("writing the log: {e}"));
            Ok(())
        }
        Err(e) => Err(Stop::Data(format!("writing the log: {e}"))),
    }
}

/// The verdict of a run that ran to its end: pass when every measurement
/// is within its limits, fail when one is not, and an error naming the
/// first measurement that could not be judged (its data unsound).
pub fn verdict(measurements: &[Measurement]) -> (Outcome, Option<RunError>) {
    use measure::MeasureOutcome;
    if let Some(m) = measurements
        .iter()
        .find(|m| m.outcome == MeasureOutcome::Error)
    {
        return (
            Outcome::Error,
            Some(RunError {
                device: Some("gyro".into()),
                step: m.step.clone(),
                message: format!("{} was {}", m.name, m.note),
            }),
        );
    }
    let any = |o: MeasureOutcome| measurements.iter().any(|m| m.outcome == o);
    let outcome = if any(MeasureOutcome::Fail) {
        Outcome::Fail
    } else if any(MeasureOutcome::ConditionalFail) {
        Outcome::ConditionalFail
    } else if any(MeasureOutcome::ConditionalPass) {
        Outcome::ConditionalPass
    } else {
        Outcome::Pass
    };
    (outcome, None)
}

fn device_of(e: &DeviceError) -> Option<String> {
    match e {
        DeviceError::Timeout { device, .. }
        | DeviceError::Refused { device, .. }
        | DeviceError::Malformed { device, .. }
        | DeviceError::OutOfRange { device, .. }
        | DeviceError::Connect { device, .. }
        | DeviceError::Open { device, .. }
        | DeviceError::Alarm { device, .. }
        | DeviceError::Interlock { device }
        | DeviceError::Overcurrent { device, .. }
        | DeviceError::Unreachable { device, .. }
        | DeviceError::GaveUp { device, .. }
        | DeviceError::Silent { device, .. } => Some(device.clone()),
    }
}
