//! The run report: `report.json` (a contract other tools read, see
//! `docs/report.md`) and a self-contained `report.html`.

pub(crate) mod html;

use serde::Serialize;

use crate::analysis::allan::{Taus, analyse};
use crate::analysis::series::Interval;
use crate::bench::Instrument;
use crate::coeffs::CoeffsUsed;
use crate::geometry::{Orientation, TableAngles};
use crate::procedure::{Metric, Procedure, StepKind};
use crate::protocol::frame::LinkStats;
use crate::runlog::meta::RunMeta;
use crate::sequencer::measure::Records;
use crate::sequencer::{BenchLeft, Outcome, RunError, RunResult};
use gyrobench_model::measurement::Measurement;

pub use html::render_html;

/// A run's outcome in the report's capitals.
pub fn outcome_word(o: Outcome) -> &'static str {
    match o {
        Outcome::Pass => "PASS",
        Outcome::Fail => "FAIL",
        Outcome::Error => "ERROR",
        Outcome::Aborted => "ABORTED",
        Outcome::ConditionalPass => "CONDITIONAL PASS",
        Outcome::ConditionalFail => "CONDITIONAL FAIL",
    }
}

/// The unit under test.
#[derive(Debug, Clone, Serialize)]
pub struct Dut {
    /// Unit type.
    #[serde(rename = "type")]
    pub kind: String,
    /// Serial number.
    pub serial: String,
}

/// `report.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// `pass`, `fail`, `error` or `aborted`.
    pub outcome: Outcome,
    /// Procedure name.
    pub procedure: String,
    /// Unit under test.
    pub dut: Dut,
    /// The unit's slot on the bench's fixture (empty: its only one).
    pub slot: String,
    /// The run's id (the same in every part; empty for a log of the
    /// first format).
    pub run_id: String,
    /// Who ran it (empty when not given).
    pub operator: String,
    /// The bench's id.
    pub bench_id: String,
    /// The computer it ran on.
    pub host: String,
    /// The name the bench PC records its runs under.
    pub station: String,
    /// The gyrobench's source revision.
    pub software_revision: String,
    /// The chamber and the table as they reported themselves, with their
    /// calibration due dates.
    pub instruments: Vec<Instrument>,
    /// Instruments past their calibration due date when the run started.
    pub calibration_overdue: Vec<String>,
    /// The coefficients the compensated figures use.
    pub coefficients: CoeffsUsed,
    /// The decision rule every figure was judged by, stated.
    pub decision_rule: RuleStated,
    /// Every measurement.
    pub measurements: Vec<Measurement>,
    /// What ended the run, when it did not finish.
    pub error: Option<RunError>,
    /// Whether cleanup ran to its end.
    pub cleanup_completed: bool,
    /// The state the run left the bench in, read back from the devices
    /// (none for a run that was never on a bench: an imported one).
    pub bench_left: Option<BenchLeft>,
    /// Spec text of the procedure.
    pub spec: String,
    /// UTC start time.
    pub start_time_utc: String,
    /// Device time covered, s.
    pub device_time_s: f64,
    /// Frames received.
    pub frames: u64,
    /// Gyro link figures.
    pub link: LinkStats,
    /// Seed of the simulated bench (none on hardware).
    pub seed: Option<u64>,
    /// Bench the run used (`embedded` or the bench file).
    pub bench: String,
    /// Software version.
    pub software_version: String,
    /// The three "bias instability" figures of the longest record judged
    /// for bias stability, and its Allan deviation (none without one).
    pub noise: Option<NoiseFigures>,
    /// Where each record a measurement uses was taken (the table pose of
    /// the move before it), in run order.
    pub positions: Vec<Position>,
    /// When the unit was switched on: the run's first power-on, the one
    /// the figures that count from power-on rest on (self-heating, model
    /// 4's warm-up), and how the run knows it.
    pub power_on: PowerOnStated,
    /// Every power-on of the run, in order (a turn-on procedure's several).
    pub power_ons: Vec<PowerOnStated>,
    /// What the unit's status bits took from the run's records, and its
    /// mode hops.
    pub gyro_status: GyroStatus,
    /// Who reviewed and approved the run, as the results store holds it
    /// (`results sign`): empty in the report a run writes; a replay with
    /// `--store` fills it.
    pub signatures: Vec<Signature>,
}

/// One signature of the run (`results sign`), as the results store keeps
/// it and a replayed report shows it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Signature {
    /// The part signed (`RUN_ID.PART`, the run's latest when signed).
    pub run: String,
    /// `reviewed` or `approved`.
    pub role: String,
    /// Who signed.
    pub by: String,
    /// When, UTC, RFC 3339.
    pub signed_utc: String,
    /// The log's SHA-256 the store held when it was signed.
    pub log_sha256: String,
    /// The digest of the part's stored verdict and figures when signed.
    pub figures_sha256: String,
    /// A remark (may be empty).
    pub note: String,
}

/// The decision rule as `report.json` states it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RuleStated {
    /// `simple`, `guarded` or `non_binary`.
    pub rule: &'static str,
    /// The guard band as a multiple of U (`guarded` only).
    pub guard_band_u: Option<f64>,
    /// Whether the procedure names it (else the default, or, in a log
    /// written before decision rules, simple acceptance as it was judged).
    pub named: bool,
    /// The rule in a sentence, as the report's first page prints it.
    pub statement: String,
}

impl RuleStated {
    /// The rule `p`'s run logged in `format` was judged by.
    pub fn of(p: &Procedure, format: u32) -> Self {
        let rule = crate::sequencer::measure::Judging::rule_for(p, format);
        Self {
            rule: rule.name(),
            guard_band_u: match rule {
                crate::procedure::DecisionRule::Guarded { guard_band_u } => Some(guard_band_u),
                _ => None,
            },
            named: p.meta.rule_named,
            statement: rule.statement(),
        }
    }

    /// The rule in a few words: `guarded, w = 1 U`.
    pub fn short(&self) -> String {
        match self.guard_band_u {
            Some(w) => format!("{}, w = {w} U", self.rule),
            None => self.rule.replace('_', "-"),
        }
    }
}

/// The pose of the unit while a record was taken.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Position {
    /// Record label.
    pub record: String,
    /// The position in an operator's words (`axis up, azimuth 90 deg`).
    pub description: String,
    /// Orientation of the unit, deg.
    pub orientation: Orientation,
    /// Table axis angles, deg (null where not known: a run imported from
    /// another bench without them).
    pub table: Option<TableAngles>,
}

impl Position {
    /// The pose of every record of `p` a measurement uses, from the poses
    /// logged with the records (an imported run: its orientation as the
    /// file gave it, table angles where known), in run order.
    pub fn logged(
        p: &Procedure,
        poses: &[(String, Orientation, Option<TableAngles>)],
    ) -> Vec<Self> {
        let used = |label: &str| p.measures().any(|m| m.records.iter().any(|r| r == label));
        poses
            .iter()
            .filter(|(label, _, _)| used(label))
            .map(|(label, orientation, table)| Self {
                record: label.clone(),
                description: describe(orientation),
                orientation: *orientation,
                table: *table,
            })
            .collect()
    }

    /// The position as a batch's unit on its own mount (`geometry`) saw
    /// it: its orientation from the table's angles (none: as it is).
    fn on(mut self, geometry: Option<crate::geometry::TableGeometry>) -> Self {
        if let (Some(g), Some(t)) = (geometry, self.table) {
            self.orientation = g.orientation(t);
            self.description = describe(&self.orientation);
        }
        self
    }

    /// The pose of every record of `p` a measurement uses: the last move
    /// before the record step (records before any move have none).
    pub fn of(p: &Procedure) -> Vec<Self> {
        let used = |label: &str| p.measures().any(|m| m.records.iter().any(|r| r == label));
        let mut pose: Option<(TableAngles, Orientation)> = None;
        let mut out: Vec<Self> = Vec::new();
        for step in p.steps() {
            match &step.kind {
                StepKind::Move {
                    angles,
                    orientation,
                } => pose = Some((*angles, *orientation)),
                StepKind::Record { label, .. } if used(label) => {
                    if let Some((table, orientation)) = pose {
                        out.retain(|q| &q.record != label);
                        out.push(Self {
                            record: label.clone(),
                            description: describe(&orientation),
                            orientation,
                            table: Some(table),
                        });
                    }
                }
                _ => {}
            }
        }
        out
    }
}

/// An orientation as the operator names it: the sensitive axis up or down
/// (and the azimuth it faces), horizontal (and the roll about it), or
/// tilted from the vertical.
fn describe(o: &Orientation) -> String {
    let whole = |v: f64| format!("{}", v.round() + 0.0);
    let az = whole(o.azimuth_deg.rem_euclid(360.0));
    if (o.elevation_deg - 90.0).abs() < 0.5 {
        format!("axis up, azimuth {az} deg")
    } else if (o.elevation_deg + 90.0).abs() < 0.5 {
        format!("axis down, azimuth {az} deg")
    } else if o.elevation_deg.abs() < 0.5 {
        format!(
            "axis horizontal toward azimuth {az} deg, roll {} deg",
            whole(o.roll_deg.rem_euclid(360.0))
        )
    } else {
        format!(
            "axis tilted {} deg from vertical, toward azimuth {az} deg",
            whole(90.0 - o.elevation_deg)
        )
    }
}

/// Which "bias instability" the report judges, with the others beside it
/// (`docs/physics.md`), and the Allan deviation they come from (1 Hz means of
/// the Earth-removed rate).
#[derive(Debug, Clone, Serialize)]
pub struct NoiseFigures {
    /// Record analysed.
    pub record: String,
    /// The figure the limits judge, by name.
    pub judged: String,
    /// Judged: 1-sigma of the tau-averaged output (GJB 2426A), deg/h.
    pub bias_stability_dph: Option<f64>,
    /// Its averaging time, s.
    pub bias_stability_averaging_s: f64,
    /// IEEE Std 952 coefficient B = ADEV floor / 0.664 (noise fit), deg/h;
    /// `None` when the curve does not resolve it (`not_resolved` says why).
    pub ieee_b_dph: Option<f64>,
    /// Raw minimum of the ADEV, deg/h.
    pub adev_min_dph: f64,
    /// Where it lies, s.
    pub adev_min_tau_s: f64,
    /// Angle random walk from the fit, deg/sqrt(h); `None` when unresolved.
    pub arw_deg_per_rt_h: Option<f64>,
    /// Rate random walk from the fit, deg/h/sqrt(h); `None` when unresolved.
    pub rate_random_walk_dph_per_rt_h: Option<f64>,
    /// Each term above the curve does not resolve: why, in words (the
    /// keys of [`crate::analysis::allan::TERM_KEYS`], `ieee_b_dph` for B).
    pub not_resolved: std::collections::BTreeMap<&'static str, String>,
    /// Averaging times, s.
    pub tau_s: Vec<f64>,
    /// Overlapping ADEV, deg/h.
    pub adev_dph: Vec<f64>,
    /// One-sigma lower bounds (Greenhall EDF), deg/h.
    pub lo_dph: Vec<f64>,
    /// One-sigma upper bounds, deg/h.
    pub hi_dph: Vec<f64>,
}

impl NoiseFigures {
    /// Figures of the longest record a bias-stability measurement judges.
    pub fn of(measurements: &[Measurement], records: &Records) -> Option<Self> {
        // Chosen by length, then read: one record's intervals in memory.
        let (label, _) = records
            .order
            .iter()
            .filter_map(|l| Some((l, records.len_of(l)?)))
            .filter(|(l, _)| {
                measurements
                    .iter()
                    .any(|m| m.metric == Metric::BiasStability && m.records.contains(l))
            })
            .max_by_key(|&(_, n)| n)?;
        let faults_before = records.read_faults();
        let series = records.get(label)?;
        // Not from a record the temporary file could not give back whole.
        if records.read_faults().since(&faults_before).is_some() {
            return None;
        }
        let bias: Vec<f64> = series.iter().map(Interval::bias_dph).collect();
        let a = analyse(&bias, 1.0, Taus::Octave);
        if a.points.len() < 2 {
            return None;
        }
        let judged = measurements
            .iter()
            .find(|m| m.metric == Metric::BiasStability && m.records.contains(label))?;
        // A term the curve does not resolve is no figure (as `allan` says).
        let shown = |i: usize, v: f64| a.noise.resolved[i].is_resolved().then_some(v);
        Some(Self {
            record: label.clone(),
            judged: format!(
                "bias stability: 1-sigma of {} s averages (GJB 2426A), measurement {}",
                judged.averaging_s, judged.name
            ),
            bias_stability_dph: judged.value,
            bias_stability_averaging_s: judged.averaging_s,
            ieee_b_dph: shown(2, a.bias_instability.ieee_b_dph),
            adev_min_dph: a.bias_instability.adev_min_dph,
            adev_min_tau_s: a.bias_instability.adev_min_tau_s,
            arw_deg_per_rt_h: shown(1, a.noise.arw_deg_per_rt_h),
            rate_random_walk_dph_per_rt_h: shown(3, a.noise.rate_random_walk_dph_per_rt_h),
            not_resolved: [
                (1, "arw_deg_per_rt_h"),
                (2, "ieee_b_dph"),
                (3, "rate_random_walk_dph_per_rt_h"),
            ]
            .into_iter()
            .filter_map(|(i, key)| Some((key, a.noise.resolved[i].reason()?)))
            .collect(),
            tau_s: a.points.iter().map(|p| p.tau_s).collect(),
            adev_dph: a.points.iter().map(|p| p.adev).collect(),
            lo_dph: a.points.iter().map(|p| p.lo).collect(),
            hi_dph: a.points.iter().map(|p| p.hi).collect(),
        })
    }
}

/// What the unit's status bits took from the records (`gyro_status` in
/// report.json; `docs/figures.md`, "Status bits").
#[derive(Debug, Clone, Serialize)]
pub struct GyroStatus {
    /// Device time of the records' intervals left out because a frame of
    /// theirs said the unit was not fit (not lasing, dither off,
    /// path-length control out of lock), s.
    pub dropped_s: f64,
    /// Those intervals.
    pub dropped_intervals: u64,
    /// Resets of the path-length control (mode hops) the frames showed,
    /// over the whole run.
    pub mode_hops: usize,
    /// Device time of each, s since its part of the run started.
    pub mode_hop_times_s: Vec<f64>,
    /// Each record the status bits touched.
    pub records: Vec<RecordStatus>,
    /// The same in words.
    pub words: String,
}

/// One record's share of [`GyroStatus`].
#[derive(Debug, Clone, Serialize)]
pub struct RecordStatus {
    /// The record's label.
    pub record: String,
    /// Device time left out, s.
    pub dropped_s: f64,
    /// Why: the fitness bits its left-out frames lacked, in words.
    pub why: Vec<String>,
    /// Mode hops during it.
    pub mode_hops: usize,
}

impl GyroStatus {
    /// What `records`' status bits took from them.
    pub fn of(records: &Records) -> Self {
        let bits = records.status_bits();
        let hops = records.hops();
        let mut by_record: Vec<RecordStatus> = Vec::new();
        for label in &records.order {
            if by_record.iter().any(|r| &r.record == label) {
                continue;
            }
            let d = records.dropped().get(label).copied().unwrap_or_default();
            let n = hops
                .iter()
                .filter(|(_, r)| r.as_ref() == Some(label))
                .count();
            if d.intervals > 0 || n > 0 {
                by_record.push(RecordStatus {
                    record: label.clone(),
                    dropped_s: d.s,
                    why: bits.unfit_words(!d.missing),
                    mode_hops: n,
                });
            }
        }
        let dropped_s = by_record.iter().map(|r| r.dropped_s).sum::<f64>();
        let dropped_intervals = records.dropped().values().map(|d| d.intervals).sum();
        let words = match (dropped_intervals, hops.len()) {
            (0, 0) => "every frame of the records fit to use; no mode hop".to_owned(),
            (d, h) => {
                let mut w = Vec::new();
                if d > 0 {
                    w.push(format!(
                        "{dropped_s:.0} s of records left out, the unit not fit ({} of {} records)",
                        by_record.iter().filter(|r| r.dropped_s > 0.0).count(),
                        records.order.len()
                    ));
                }
                if h > 0 {
                    w.push(format!(
                        "{h} mode hop{} (path-length control reset)",
                        if h == 1 { "" } else { "s" }
                    ));
                }
                w.join("; ")
            }
        };
        Self {
            dropped_s,
            dropped_intervals,
            mode_hops: hops.len(),
            mode_hop_times_s: hops.iter().map(|(t, _)| *t).collect(),
            records: by_record,
            words,
        }
    }
}

/// A power-on as the report states it (`power_on` in report.json).
#[derive(Debug, Clone, Serialize)]
pub struct PowerOnStated {
    /// Device time of the power-on, s since its part of the run started.
    pub device_time_s: f64,
    /// The same moment in UTC.
    pub utc: String,
    /// How the run knows it: `switched` (the run switched the supply on,
    /// from off), `operator` (an operator switched it on and confirmed
    /// it), `assumed` (not known: the start of the run is taken).
    pub source: crate::sequencer::PowerOnSource,
    /// The part of the run it was in (1 unless resumed).
    pub part: u32,
    /// The same in words.
    pub words: String,
}

impl PowerOnStated {
    /// The statement of power-on `on` in `part`.
    pub fn of(part: u32, on: &crate::sequencer::PowerOn) -> Self {
        Self {
            device_time_s: on.t_s,
            utc: on.utc.clone(),
            source: on.source,
            part,
            words: format!(
                "at {:.1} s of device time{}{}, {}",
                on.t_s,
                if part > 1 {
                    format!(" of part {part}")
                } else {
                    String::new()
                },
                if on.utc.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", on.utc)
                },
                on.source.describe()
            ),
        }
    }

    /// The run's first power-on, or the run's start taken for it.
    fn first(records: &Records, start_utc: &str) -> Self {
        records.power_ons().first().map_or_else(
            || Self {
                device_time_s: 0.0,
                utc: start_utc.to_owned(),
                source: crate::sequencer::PowerOnSource::Assumed,
                part: 1,
                words: "not recorded: the figures that count from power-on take the start of \
                        the run"
                    .to_owned(),
            },
            |(part, on)| Self::of(*part, on),
        )
    }
}

/// The table's geometry with a batch's unit on its slot's mount (none: the
/// run's one unit, on the bench's mount as the procedure was checked).
fn unit_geometry(meta: &RunMeta) -> Option<crate::geometry::TableGeometry> {
    let mount = meta.unit()?.mount?;
    let bench: crate::bench::BenchConfig = toml::from_str(&meta.bench_toml).ok()?;
    Some(bench.geometry_with(Some(mount)))
}

impl Report {
    /// Assemble the report of a run from its procedure, its result and
    /// its log's `run` metadata (so a replay of the log gives the same).
    pub fn new(p: &Procedure, r: &RunResult, meta: &RunMeta, link: LinkStats) -> Self {
        let unit = meta.unit();
        Self {
            outcome: r.outcome,
            procedure: p.meta.name.clone(),
            dut: Dut {
                kind: p.meta.dut_type.clone(),
                serial: unit.map_or_else(|| meta.dut_serial.clone(), |u| u.serial.clone()),
            },
            slot: unit.map_or(String::new(), |u| u.slot.clone()),
            run_id: meta.run_id.clone(),
            operator: meta.operator.clone(),
            bench_id: meta.bench_id.clone(),
            host: meta.host.clone(),
            station: meta.station.clone(),
            software_revision: meta.software_revision.clone(),
            instruments: meta.instruments.clone(),
            calibration_overdue: meta
                .instruments
                .iter()
                .filter(|i| i.calibration_overdue)
                .map(|i| i.role.clone())
                .collect(),
            coefficients: unit.map_or_else(CoeffsUsed::fitted, |u| u.coefficients.clone()),
            decision_rule: RuleStated::of(p, meta.format),
            measurements: r.measurements.clone(),
            error: r.error.clone(),
            cleanup_completed: r.cleanup_completed,
            bench_left: r.bench_left.clone(),
            spec: p.meta.spec.clone(),
            start_time_utc: meta.start_time_utc.clone(),
            device_time_s: r.device_time_s,
            frames: r.frames,
            link,
            seed: meta.seed.filter(|_| meta.is_embedded()),
            bench: meta.bench.clone(),
            software_version: meta.software_version.clone(),
            noise: NoiseFigures::of(&r.measurements, &r.records),
            positions: Position::of(p)
                .into_iter()
                .map(|q| q.on(unit_geometry(meta)))
                .collect(),
            power_on: PowerOnStated::first(&r.records, &meta.start_time_utc),
            power_ons: r
                .records
                .power_ons()
                .iter()
                .map(|(part, on)| PowerOnStated::of(*part, on))
                .collect(),
            gyro_status: GyroStatus::of(&r.records),
            signatures: Vec::new(),
        }
    }

    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }

    /// What the verdict line adds about the instruments: ` (chamber
    /// calibration OVERDUE)` when one was past its due date.
    pub fn overdue_flag(&self) -> String {
        if self.calibration_overdue.is_empty() {
            String::new()
        } else {
            format!(
                " ({} calibration OVERDUE)",
                self.calibration_overdue.join(" and ")
            )
        }
    }

    /// A short text summary for the terminal.
    pub fn render_text(&self) -> String {
        let mut s = format!(
            "{}{}: {} on {} {} ({:.1} h device time, {} frames)\n",
            self.outcome_word(),
            self.overdue_flag(),
            self.procedure,
            self.dut.kind,
            self.dut.serial,
            self.device_time_s / 3600.0,
            self.frames
        );
        s.push_str(&format!("  power-on: {}\n", self.power_on.words));
        if self.gyro_status.dropped_intervals > 0 || self.gyro_status.mode_hops > 0 {
            s.push_str(&format!("  gyro status: {}\n", self.gyro_status.words));
        }
        s.push_str(&format!(
            "  decision rule: {}{}\n",
            self.decision_rule.short(),
            if self.decision_rule.named {
                ""
            } else {
                " (the default)"
            }
        ));
        for m in &self.measurements {
            s.push_str(&format!(
                "  {:<38} {:>10} {:<6} {:<18} {}  {}\n",
                m.name,
                m.value.map_or("n/a".to_owned(), |v| format!("{v:.4}")),
                m.unit,
                match (&m.uncertainty, m.std_error) {
                    (Some(u), _) => format!("± {:.4} (k={:.2})", u.expanded, u.k),
                    (None, Some(se)) => format!("± {se:.4} (1 s.e.)"),
                    (None, None) => String::new(),
                },
                if m.low.is_none() && m.high.is_none() {
                    "(informative)".to_owned()
                } else {
                    format!("[{}]", m.limits_text())
                },
                if m.low.is_none() && m.high.is_none() {
                    ""
                } else {
                    m.outcome.word()
                }
            ));
        }
        if let Some(e) = &self.error {
            // A measurement whose data were unsound ran to its end but was
            // not judged; anything else stopped the run.
            let unjudged = self.measurements.iter().any(|m| {
                m.step == e.step && m.outcome == crate::sequencer::measure::MeasureOutcome::Error
            });
            s.push_str(&format!(
                "  {} step {}{}: {}\n",
                if unjudged {
                    "not judged in"
                } else {
                    "stopped in"
                },
                e.step,
                e.device
                    .as_ref()
                    .map_or(String::new(), |d| format!(" ({d})")),
                e.message
            ));
        }
        if let Some(b) = &self.bench_left {
            s.push_str(&format!("  bench left: {}\n", b.summary));
        }
        if self
            .measurements
            .iter()
            .any(|m| m.metric == Metric::CompensatedDriftPp)
        {
            s.push_str(&format!(
                "  coefficients: {}\n",
                self.coefficients.describe()
            ));
        }
        for i in self.instruments.iter().filter(|i| i.calibration_overdue) {
            s.push_str(&format!("  {}\n", i.describe()));
        }
        s
    }

    /// PASS, FAIL, ERROR, ABORTED, CONDITIONAL PASS or CONDITIONAL FAIL.
    pub fn outcome_word(&self) -> &'static str {
        outcome_word(self.outcome)
    }
}
