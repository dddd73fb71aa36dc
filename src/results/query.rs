//! Reading the store: runs (filtered), one run whole, a unit's history,
//! and a measurement's trend across units. Figures of a run are those of
//! its latest part (a resumed run's last report covers every part).

use serde::Serialize;

use super::sql::{Row, Value};
use super::{RunState, Store, StoreError};
use crate::runlog::meta::ResultMeasurement;
use crate::sequencer::measure::MeasureOutcome;

/// Which runs.
#[derive(Debug, Clone, Default)]
pub struct Filter {
    /// Unit serial.
    pub serial: Option<String>,
    /// Unit type.
    pub dut_type: Option<String>,
    /// Procedure name.
    pub procedure: Option<String>,
    /// Where the run stands.
    pub outcome: Option<super::RunState>,
    /// Bench (as the run named it) or station (host).
    pub bench: Option<String>,
    /// Started at or after (UTC, RFC 3339 or a date).
    pub since: Option<String>,
    /// Started before (UTC, RFC 3339 or a date).
    pub until: Option<String>,
    /// Only each run's latest part.
    pub latest_only: bool,
    /// Count imported runs (outcome `reference`) in trends and yields
    /// (lists show them always).
    pub include_reference: bool,
    /// At most this many rows (newest first); none: every row.
    pub limit: Option<usize>,
    /// Count runs of the simulated bench's unnamed unit (`SIMULATED`) in
    /// trends and yields (lists show them always): a simulated unit is not
    /// one of the lot's.
    pub include_simulated: bool,
    /// Only units whose compensated figures came from this source
    /// (`fitted`, `file`, `store`): a drift compensated within the run and
    /// one compensated by the unit's delivered set are not one measurand.
    pub coeffs_source: Option<String>,
    /// Only runs on this kind of bench.
    pub bench_kind: Option<super::facts::BenchKind>,
}

impl Filter {
    /// The clause that leaves imported runs (`reference`) out of figures.
    fn reference_clause(&self) -> String {
        let mut out = String::new();
        if !self.include_reference {
            out.push_str(" AND ru.outcome <> 'reference'");
        }
        if !self.include_simulated {
            out.push_str(&format!(
                " AND u.serial <> '{}'",
                crate::unit::SIMULATED_SERIAL
            ));
        }
        out
    }

    /// `WHERE` clauses on `r` (runs), `ru` (run units) and `u` (units),
    /// with their values, numbered from `$first`.
    fn clauses(&self, first: usize) -> (String, Vec<Value>) {
        let mut sql = String::new();
        let mut params: Vec<Value> = Vec::new();
        let mut add = |clause: &str, v: &Option<String>, params: &mut Vec<Value>| {
            if let Some(v) = v {
                params.push(v.clone().into());
                let n = first + params.len() - 1;
                sql.push_str(&format!(" AND {}", clause.replace("$?", &format!("${n}"))));
            }
        };
        add("u.serial = $?", &self.serial, &mut params);
        add("u.dut_type = $?", &self.dut_type, &mut params);
        add("r.procedure_name = $?", &self.procedure, &mut params);
        add(
            "ru.outcome = $?",
            &self.outcome.map(|o| o.as_str().to_owned()),
            &mut params,
        );
        add("(r.bench = $? OR r.station = $?)", &self.bench, &mut params);
        add("r.started_utc >= $?", &self.since, &mut params);
        add("r.started_utc < $?", &self.until, &mut params);
        add("ru.coeffs_source = $?", &self.coeffs_source, &mut params);
        add(
            "r.bench_kind = $?",
            &self.bench_kind.map(|k| k.as_str().to_owned()),
            &mut params,
        );
        if self.latest_only {
            sql.push_str(" AND r.latest = 1");
        }
        (sql, params)
    }
}

/// One part of a run, as lists show it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunRow {
    /// `RUN_ID.PART`.
    pub id: String,
    /// UTC start of this part.
    pub started_utc: String,
    /// Unit type.
    pub dut_type: String,
    /// Serial number.
    pub serial: String,
    /// Procedure name.
    pub procedure: String,
    /// Bench.
    pub bench: String,
    /// Station (host).
    pub station: String,
    /// Operator.
    pub operator: String,
    /// Outcome.
    pub outcome: RunState,
    /// Which part.
    pub part: i64,
    /// The run's latest part.
    pub latest: bool,
    /// Device time, s.
    pub device_time_s: Option<f64>,
    /// What ended it, when it did not pass or fail.
    pub error: Option<String>,
    /// The unit's slot on the bench (empty: the bench's only one).
    pub slot: String,
    /// The bench's id (empty for runs stored before schema 3).
    pub bench_id: String,
    /// The gyrobench version and revision that ran it.
    pub software: String,
    /// Instruments past their calibration due date, comma separated.
    pub calibration_overdue: Option<String>,
    /// The coefficients the unit's compensated figures used.
    pub coefficients: StoredCoeffs,
}

pub use super::sets::StoredCoeffs;

/// The columns of a run's row, each read back by its name.
const RUN_COLUMNS: &[(&str, &str)] = &[
    ("r.id", "id"),
    ("r.started_utc", "started_utc"),
    ("u.dut_type", "dut_type"),
    ("u.serial", "serial"),
    ("r.procedure_name", "procedure"),
    ("r.bench", "bench"),
    ("r.station", "station"),
    ("r.operator", "operator"),
    ("ru.outcome", "outcome"),
    ("r.part", "part"),
    ("r.latest", "latest"),
    ("r.device_time_s", "device_time_s"),
    ("r.error_message", "error"),
    ("ru.slot", "slot"),
    ("r.bench_id", "bench_id"),
    ("r.software_version", "software_version"),
    ("r.software_revision", "software_revision"),
    ("r.calibration_overdue", "calibration_overdue"),
    ("ru.coeffs_source", "coeffs_source"),
    ("ru.coeffs_serial", "coeffs_serial"),
    ("ru.coeffs_version", "coeffs_version"),
    ("ru.coeffs_sha256", "coeffs_sha256"),
    ("ru.coeffs_override_reason", "coeffs_override_reason"),
    ("ru.coeffs_identity", "coeffs_identity"),
    ("ru.coeffs_claimed_version", "coeffs_claimed_version"),
    ("ru.coeffs_identity_note", "coeffs_identity_note"),
];

/// The select list of [`RUN_COLUMNS`].
fn run_columns() -> String {
    RUN_COLUMNS
        .iter()
        .map(|(expr, name)| format!("{expr} AS {name}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn run_row(r: &Row) -> RunRow {
    let version = r.text("software_version");
    let revision = r.text("software_revision");
    RunRow {
        id: r.text("id"),
        started_utc: r.text("started_utc"),
        dut_type: r.text("dut_type"),
        serial: r.text("serial"),
        procedure: r.text("procedure"),
        bench: r.text("bench"),
        station: r.text("station"),
        operator: r.text("operator"),
        // A word no build writes reads as an error, never as judged.
        outcome: RunState::parse(&r.text("outcome")).unwrap_or(RunState::Error),
        part: r.int("part").unwrap_or(1),
        latest: r.int("latest") == Some(1),
        device_time_s: r.real("device_time_s"),
        error: r.opt_text("error"),
        slot: r.text("slot"),
        bench_id: r.text("bench_id"),
        software: if revision.is_empty() {
            version
        } else {
            format!("{version} ({revision})")
        },
        calibration_overdue: r.opt_text("calibration_overdue"),
        coefficients: StoredCoeffs::of_row(r),
    }
}

/// A measurement of a run: the run part it belongs to and the measurement
/// as the log's `result` record has it (it reads as the measurement).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeasurementRow {
    /// The run part it belongs to.
    pub run: String,
    /// The measurement.
    #[serde(flatten)]
    pub measurement: ResultMeasurement,
}

const MEASUREMENT_COLUMNS: &str = "m.run, m.name, m.value, m.unit, m.low, m.high, m.outcome, m.step, m.note, m.u, m.expanded_u, m.k, m.guard_band";

impl std::ops::Deref for MeasurementRow {
    type Target = ResultMeasurement;
    fn deref(&self) -> &ResultMeasurement {
        &self.measurement
    }
}

fn measurement_row(r: &Row) -> MeasurementRow {
    MeasurementRow {
        run: r.text("run"),
        measurement: measurement_of(r),
    }
}

/// A measurement read from a row of `measurements` columns.
pub(super) fn measurement_of(r: &Row) -> ResultMeasurement {
    ResultMeasurement {
        name: r.text("name"),
        value: r.real("value"),
        unit: r.text("unit"),
        low: r.real("low"),
        high: r.real("high"),
        // A word no build writes reads as not judged, never as a pass.
        outcome: MeasureOutcome::parse(&r.text("outcome")).unwrap_or(MeasureOutcome::Error),
        step: r.text("step"),
        note: r.text("note"),
        uncertainty: match (r.real("u"), r.real("expanded_u"), r.real("k")) {
            (Some(u), Some(expanded), Some(k)) => {
                Some(crate::analysis::uncertainty::Expanded { u, expanded, k })
            }
            _ => None,
        },
        guard_band: r.real("guard_band"),
    }
}

/// One run part whole.
#[derive(Debug, Clone, Serialize)]
pub struct RunDetail {
    /// The list's view of it.
    pub run: RunRow,
    /// Everything else the store keeps of it, by column name.
    pub fields: Vec<(String, String)>,
    /// Its measurements (every part's, as its report has them).
    pub measurements: Vec<MeasurementRow>,
    /// The other parts of the same run.
    pub parts: Vec<RunRow>,
    /// Who reviewed and approved it (`results sign`).
    pub signatures: Vec<super::sign::Signature>,
}

/// A unit's history.
#[derive(Debug, Clone, Serialize)]
pub struct UnitHistory {
    /// Serial number.
    pub serial: String,
    /// Every run of the unit (latest parts), oldest first.
    pub runs: Vec<RunRow>,
    /// Their measurements, in run order.
    pub measurements: Vec<MeasurementRow>,
    /// The latest coefficient set, if any.
    pub coefficients: Option<CoefficientRow>,
}

/// A stored coefficient set.
#[derive(Debug, Clone, Serialize)]
pub struct CoefficientRow {
    /// Version (1 for the unit's first).
    pub version: i64,
    /// When calibrate wrote it, UTC.
    pub created_utc: String,
    /// How it was validated.
    pub validation: String,
    /// Model 4's held-out drift, deg/h.
    pub held_out_drift_pp_dph: Option<f64>,
    /// The runs it came from (JSON list of [part key, log path]).
    pub source_runs: String,
    /// SHA-256 of its text (none for sets stored before schema 3).
    pub sha256: Option<String>,
    /// The coefficients file.
    pub coeffs_toml: String,
}

/// A measurement across units.
#[derive(Debug, Clone, Serialize)]
pub struct Trend {
    /// Measurement name.
    pub name: String,
    /// Unit of the values.
    pub unit: String,
    /// Values counted (latest parts, not null).
    pub count: i64,
    /// Measurements judged (with or without a value).
    pub judged: i64,
    /// Mean.
    pub mean: Option<f64>,
    /// Sample standard deviation.
    pub sigma: Option<f64>,
    /// Smallest.
    pub min: Option<f64>,
    /// Largest.
    pub max: Option<f64>,
    /// Share judged pass, 0..1.
    pub yield_fraction: Option<f64>,
    /// The limits of the newest measurement.
    pub low: Option<f64>,
    /// The limits of the newest measurement.
    pub high: Option<f64>,
    /// Sigma from run to run: the mean moving range of consecutive values
    /// in run order over d2 = 1.128.
    pub sigma_within: Option<f64>,
    /// Capability on `sigma_within` (Cpu, Cpl, Cpk).
    pub within: Capability,
    /// Performance on the overall `sigma` (Ppu, Ppl, Ppk).
    pub overall: Capability,
    /// Performance by ISO 22514-2's percentile method on a lognormal fit,
    /// for a figure whose values are all above zero (none otherwise).
    pub percentile: Option<Percentile>,
    /// Values below which no index is shown (`--min-values`, default
    /// [`MIN_CAPABILITY_N`]).
    pub min_values: usize,
}

/// Performance by the percentile method (ISO 22514-2): `Ppu = (USL -
/// X50) / (X99.865 - X50)`, `Ppl = (X50 - LSL) / (X50 - X0.135)`, the
/// percentiles those of a lognormal fitted to the values (the mean and
/// standard deviation of their logarithms). For a non-negative, skewed
/// figure (a peak-to-peak, a stability, a noise term) the normal indices
/// put the process's tail where it is not; these put it where the values'
/// own shape does.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Percentile {
    /// The distribution the percentiles come from.
    pub model: &'static str,
    /// The 0.135 % percentile.
    pub x_0135: f64,
    /// The median.
    pub x_50: f64,
    /// The 99.865 % percentile.
    pub x_99865: f64,
    /// Against the upper limit.
    pub upper: Option<f64>,
    /// Against the lower limit.
    pub lower: Option<f64>,
    /// The smaller (Ppk by percentiles).
    pub k: Option<f64>,
    /// The figure is one to read on these rather than on the normal
    /// indices: every value above zero and an upper limit alone (ours:
    /// a magnitude bounded below by zero is skewed by its nature).
    pub preferred: bool,
}

impl Percentile {
    /// The percentile indices of `values` against `(low, high)`; none
    /// unless every value is above zero and their logarithms vary.
    fn of(values: &[f64], (low, high): (Option<f64>, Option<f64>)) -> Option<Self> {
        if values.len() < 2 || values.iter().any(|v| !(*v > 0.0 && v.is_finite())) {
            return None;
        }
        let logs: Vec<f64> = values.iter().map(|v| v.ln()).collect();
        let n = logs.len() as f64;
        let mu = logs.iter().sum::<f64>() / n;
        let s = (logs.iter().map(|l| (l - mu) * (l - mu)).sum::<f64>() / (n - 1.0)).sqrt();
        if s.is_nan() || s <= 0.0 {
            return None;
        }
        let (x_0135, x_50, x_99865) = ((mu - 3.0 * s).exp(), mu.exp(), (mu + 3.0 * s).exp());
        let upper = high.map(|h| (h - x_50) / (x_99865 - x_50));
        let lower = low.map(|l| (x_50 - l) / (x_50 - x_0135));
        let k = match (upper, lower) {
            (Some(u), Some(l)) => Some(u.min(l)),
            (u, l) => u.or(l),
        };
        Some(Self {
            model: "lognormal",
            x_0135,
            x_50,
            x_99865,
            upper,
            lower,
            k,
            preferred: high.is_some() && low.is_none_or(|l| l <= 0.0),
        })
    }
}

impl Trend {
    /// The 95 % interval of Cpk and Ppk, and a warning when too few values
    /// stand behind them to call them a capability.
    pub fn caveat(&self) -> String {
        let t = self;
        let interval = |c: &Capability| {
            c.k_interval
                .map_or("-".to_owned(), |[a, b]| format!("{a:.2}..{b:.2}"))
        };
        let mut s = String::new();
        if t.within.k.is_some() || t.overall.k.is_some() {
            s.push_str(&format!(
                "  95 % interval: Cpk {}  Ppk {}\n",
                interval(&t.within),
                interval(&t.overall)
            ));
        }
        if t.within.k.is_some() && !t.within.enough {
            s.push_str(&format!(
                "  {} value(s), fewer than {}: the indices say little about the process (their interval above)\n",
                t.count,
                MIN_CAPABILITY_N
            ));
        }
        if let Some(why) = &t.within.withheld {
            s.push_str(&format!("  indices not shown: {why}\n"));
        }
        s
    }
}

/// d2 of a moving range of two: E[|x1 - x2|] = 1.128 sigma.
pub const D2_MOVING_RANGE: f64 = 1.128;

/// One-sided and two-sided indices of one spread (`docs/results.md`):
/// `upper = (USL - mean) / 3 sigma`, `lower = (mean - LSL) / 3 sigma`,
/// `k` the smaller of those that exist (a figure with one limit is judged
/// on that one).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Capability {
    /// Against the upper limit (Cpu, Ppu).
    pub upper: Option<f64>,
    /// Against the lower limit (Cpl, Ppl).
    pub lower: Option<f64>,
    /// The smaller (Cpk, Ppk).
    pub k: Option<f64>,
    /// Its approximate 95 % confidence interval from the number of values
    /// (Bissell: k +- 1.96 sqrt(1 / 9n + k^2 / 2(n - 1))).
    pub k_interval: Option<[f64; 2]>,
    /// Whether enough values stand behind it (`MIN_CAPABILITY_N`); with
    /// fewer, and `--min-values` lowered to show it, the index is shown
    /// with its interval and a warning, never as a capability.
    pub enough: bool,
    /// Why the indices are not shown: fewer values than `--min-values`
    /// (none: shown).
    pub withheld: Option<String>,
}

/// Values below which a capability index is not a statement about the
/// process (ours, the common floor of capability studies; ISO 22514-2
/// asks far more, 125, for a full study): with 25 values the 95 %
/// interval of a Cpk of 1.33 is still about +-0.4.
pub const MIN_CAPABILITY_N: usize = 25;

impl Capability {
    fn of(
        mean: Option<f64>,
        sigma: Option<f64>,
        (low, high): (Option<f64>, Option<f64>),
        n: usize,
        min_values: usize,
    ) -> Self {
        let (Some(m), Some(s)) = (mean, sigma.filter(|s| *s > 0.0)) else {
            return Self::default();
        };
        if n < min_values {
            return Self {
                withheld: Some(withheld(n, min_values)),
                ..Self::default()
            };
        }
        let upper = high.map(|h| (h - m) / (3.0 * s));
        let lower = low.map(|l| (m - l) / (3.0 * s));
        let k = match (upper, lower) {
            (Some(u), Some(l)) => Some(u.min(l)),
            (u, l) => u.or(l),
        };
        let k_interval = k.filter(|_| n > 1).map(|k| {
            let n = n as f64;
            let half = 1.96 * (1.0 / (9.0 * n) + k * k / (2.0 * (n - 1.0))).sqrt();
            [k - half, k + half]
        });
        Self {
            upper,
            lower,
            k,
            k_interval,
            enough: n >= MIN_CAPABILITY_N,
            withheld: None,
        }
    }
}

/// Why a capability index is not shown for `n` values.
fn withheld(n: usize, min_values: usize) -> String {
    format!(
        "{n} value(s), fewer than {min_values}: a capability index from so few says little \
         (--min-values lowers the floor)"
    )
}

/// A value of a trend, with the run it came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrendPoint {
    /// UTC start of the run's part.
    pub started_utc: String,
    /// The unit.
    pub serial: String,
    /// The value.
    pub value: f64,
    /// `pass`, `fail` or `error`.
    pub outcome: MeasureOutcome,
    /// The run part's key.
    pub run: String,
    /// Its log (the report sits beside it).
    pub log_path: String,
    /// The unit's slot on a batch's bench (empty: a run of one unit). A
    /// batch unit's report is `report-SERIAL.html`, a single unit's
    /// `report.html`.
    pub slot: String,
    /// An imported run (judged for reference only).
    pub reference: bool,
}

/// The run of a part's key `RUN_ID.PART`.
fn run_id_of(key: &str) -> &str {
    key.rsplit_once('.').map_or(key, |(r, _)| r)
}

fn one<T>(rows: Vec<Row>, f: impl Fn(&Row) -> T) -> Option<T> {
    rows.first().map(f)
}

impl Store {
    /// Runs (parts) matching `f`, newest first.
    pub fn list(&mut self, f: &Filter) -> Result<Vec<RunRow>, StoreError> {
        let (clauses, mut params) = f.clauses(1);
        let mut sql = format!(
            "SELECT {} FROM runs r JOIN run_units ru ON ru.run = r.id JOIN units u ON u.id = ru.unit_id WHERE 1 = 1{clauses} \
             ORDER BY r.started_utc DESC, r.id DESC",
            run_columns()
        );
        if let Some(n) = f.limit {
            params.push((n as i64).into());
            sql.push_str(&format!(" LIMIT ${}", params.len()));
        }
        Ok(self
            .sql()
            .query(&sql, &params)?
            .iter()
            .map(run_row)
            .collect())
    }

    /// One run part by its key or an unambiguous start of it.
    pub fn show(&mut self, id: &str) -> Result<RunDetail, StoreError> {
        let run = self.part_named(id)?;
        let fields = self.detail_fields(&run.id)?;
        let measurements = self
            .sql()
            .query(
                &format!("SELECT {MEASUREMENT_COLUMNS} FROM measurements m WHERE m.run = $1 ORDER BY m.seq"),
                &[run.id.clone().into()],
            )?
            .iter()
            .map(measurement_row)
            .collect();
        let run_id = run_id_of(&run.id).to_owned();
        let parts = self
            .sql()
            .query(
                &format!(
                    "SELECT {} FROM runs r JOIN run_units ru ON ru.run = r.id JOIN units u ON u.id = ru.unit_id \
                     WHERE r.run_id = $1 ORDER BY r.part",
                    run_columns()
                ),
                &[run_id.into()],
            )?
            .iter()
            .map(run_row)
            .collect();
        let signatures = self.signatures(&run.id)?;
        Ok(RunDetail {
            run,
            fields,
            measurements,
            parts,
            signatures,
        })
    }

    /// The run part `id` names: its key, or an unambiguous start of one
    /// (several parts of one run: the latest). None, or several runs, is
    /// an error saying so.
    pub(super) fn part_named(&mut self, id: &str) -> Result<RunRow, StoreError> {
        let store = self.name.clone();
        let rows = self.sql().query(
            &format!(
                "SELECT {} FROM runs r JOIN run_units ru ON ru.run = r.id JOIN units u ON u.id = ru.unit_id \
                 WHERE r.id = $1 OR r.id LIKE $2 ORDER BY r.id LIMIT 50",
                run_columns()
            ),
            &[id.into(), format!("{}%", id.replace(['%', '_'], "")).into()],
        )?;
        Ok(match rows.as_slice() {
            [] => {
                return Err(StoreError::NotFound {
                    store,
                    what: format!("no run {id}; `gyrobench results list` shows the runs"),
                });
            }
            [r] => run_row(r),
            many if many.iter().any(|r| r.text("id") == id) => run_row(&many[0]),
            // The parts of one run: its latest part.
            many if many
                .iter()
                .all(|r| run_id_of(&r.text("id")) == run_id_of(&many[0].text("id"))) =>
            {
                many.iter()
                    .map(run_row)
                    .max_by_key(|r| r.part)
                    .unwrap_or_else(|| run_row(&many[0]))
            }
            many => {
                return Err(StoreError::NotFound {
                    store,
                    what: format!(
                        "{id} names several runs ({}, ...): give more of the id",
                        many.iter()
                            .map(|r| r.text("id"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                });
            }
        })
    }

    /// Everything else the store keeps of the part `key`, by column name
    /// (empty when the part has no row).
    fn detail_fields(&mut self, key: &str) -> Result<Vec<(String, String)>, StoreError> {
        let names = [
            "procedure_path",
            "procedure_sha256",
            "run_started_utc",
            "ended_utc",
            "frames",
            "error_step",
            "error_device",
            "cleanup_completed",
            "bench_left",
            "bench_left_verified",
            "link_lost_frames",
            "link_crc_errors",
            "link_reconnects",
            "link_longest_gap_ms",
            "software_version",
            "seed",
            "log_path",
            "log_sha256",
            "imported_from",
            "bench_kind",
            "bench_id",
            "host",
            "software_revision",
            "instruments",
            "calibration_overdue",
            "parent_id",
            "recorded_utc",
        ];
        let sql = format!("SELECT {} FROM runs WHERE id = $1", names.join(", "));
        let row = self.sql().query(&sql, &[key.into()])?;
        Ok(names
            .iter()
            .map(|n| {
                (
                    (*n).to_owned(),
                    row.first().map_or(String::new(), |r| r.text(n)),
                )
            })
            .collect())
    }

    /// Every run of the unit `serial` (its latest parts) with every
    /// measurement, and its latest coefficient set.
    pub fn unit(&mut self, serial: &str) -> Result<UnitHistory, StoreError> {
        let store = self.name.clone();
        let runs: Vec<RunRow> = self
            .sql()
            .query(
                &format!(
                    "SELECT {} FROM runs r JOIN run_units ru ON ru.run = r.id JOIN units u ON u.id = ru.unit_id \
                     WHERE u.serial = $1 AND r.latest = 1 ORDER BY r.started_utc, r.id",
                    run_columns()
                ),
                &[serial.into()],
            )?
            .iter()
            .map(run_row)
            .collect();
        if runs.is_empty() {
            return Err(StoreError::NotFound {
                store,
                what: format!("no run of a unit with serial {serial}"),
            });
        }
        let measurements = self
            .sql()
            .query(
                &format!(
                    "SELECT {MEASUREMENT_COLUMNS} FROM measurements m JOIN run_units ru ON ru.run = m.run AND ru.slot = m.slot \
                     JOIN runs r ON r.id = m.run JOIN units u ON u.id = ru.unit_id WHERE u.serial = $1 AND r.latest = 1 \
                     ORDER BY r.started_utc, r.id, m.seq"
                ),
                &[serial.into()],
            )?
            .iter()
            .map(measurement_row)
            .collect();
        let coefficients = one(
            self.sql().query(
                "SELECT c.version, c.created_utc, c.validation, c.held_out_drift_pp_dph, c.source_runs, \
                 c.coeffs_toml, c.sha256 FROM coefficient_sets c JOIN units u ON u.id = c.unit_id \
                 WHERE u.serial = $1 ORDER BY c.version DESC LIMIT 1",
                &[serial.into()],
            )?,
            |r| CoefficientRow {
                version: r.int("version").unwrap_or(0),
                created_utc: r.text("created_utc"),
                validation: r.text("validation"),
                held_out_drift_pp_dph: r.real("held_out_drift_pp_dph"),
                source_runs: r.text("source_runs"),
                coeffs_toml: r.text("coeffs_toml"),
                sha256: r.opt_text("sha256"),
            },
        );
        Ok(UnitHistory {
            serial: serial.to_owned(),
            runs,
            measurements,
            coefficients,
        })
    }

    /// The newest coefficient set of unit `serial` of type `dut_type`:
    /// its version and its text.
    pub fn latest_coefficients(
        &mut self,
        dut_type: &str,
        serial: &str,
    ) -> Result<Option<(i64, String)>, StoreError> {
        Ok(one(
            self.sql().query(
                "SELECT c.version, c.coeffs_toml FROM coefficient_sets c JOIN units u ON u.id = c.unit_id \
                 WHERE u.dut_type = $1 AND u.serial = $2 ORDER BY c.version DESC LIMIT 1",
                &[dut_type.into(), serial.into()],
            )?,
            |r| (r.int("version").unwrap_or(0), r.text("coeffs_toml")),
        ))
    }

    /// The statistics of measurement `name` over the runs `f` selects
    /// (their latest parts): one pass over the values in run order, the
    /// figures computed here (the mean first, then the squares about it,
    /// which do not cancel as the mean of the squares would).
    pub fn trend(
        &mut self,
        name: &str,
        f: &Filter,
        min_values: usize,
    ) -> Result<Trend, StoreError> {
        let (clauses, params) = f.clauses(2);
        let reference = f.reference_clause();
        let mut all = vec![Value::from(name)];
        all.extend(params);
        let rows = self.sql().query(
            &format!(
                "SELECT m.value, m.outcome, m.low, m.high, m.unit \
                 FROM measurements m JOIN run_units ru ON ru.run = m.run AND ru.slot = m.slot \
                 JOIN runs r ON r.id = m.run JOIN units u ON u.id = ru.unit_id \
                 WHERE m.name = $1 AND r.latest = 1{reference}{clauses} \
                 ORDER BY r.started_utc, r.id, m.seq"
            ),
            &all,
        )?;
        let judged = rows.len() as i64;
        let Some(newest) = rows.last() else {
            return Err(StoreError::NotFound {
                store: self.name.clone(),
                what: format!("no measurement named {name} in the runs asked for"),
            });
        };
        let low = newest.real("low");
        let high = newest.real("high");
        let unit = newest.text("unit");
        let values: Vec<f64> = rows.iter().filter_map(|r| r.real("value")).collect();
        let passed = rows.iter().filter(|r| r.text("outcome") == "pass").count();
        let count = values.len();
        let n = count as f64;
        let mean = (count > 0).then(|| values.iter().sum::<f64>() / n);
        let sigma = mean
            .filter(|_| count > 1)
            .map(|m| (values.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (n - 1.0)).sqrt());
        // The spread from one run to the next (moving ranges in run order):
        // what the process does over short times, without its drifts.
        let sigma_within = (count > 1).then(|| {
            let mr: f64 = values.windows(2).map(|w| (w[1] - w[0]).abs()).sum();
            mr / (n - 1.0) / D2_MOVING_RANGE
        });
        let index =
            |spread: Option<f64>| Capability::of(mean, spread, (low, high), count, min_values);
        let percentile = Percentile::of(&values, (low, high)).filter(|_| count >= min_values);
        Ok(Trend {
            name: name.to_owned(),
            unit,
            count: count as i64,
            judged,
            mean,
            sigma,
            min: values.iter().copied().reduce(f64::min),
            max: values.iter().copied().reduce(f64::max),
            yield_fraction: Some(passed as f64 / judged as f64),
            low,
            high,
            sigma_within,
            within: index(sigma_within),
            overall: index(sigma),
            percentile,
            min_values,
        })
    }

    /// The values of measurement `name` with their run, unit and log,
    /// oldest first (at most `max`, the newest).
    pub fn trend_points(
        &mut self,
        name: &str,
        f: &Filter,
        max: usize,
    ) -> Result<Vec<TrendPoint>, StoreError> {
        let (clauses, params) = f.clauses(2);
        let reference = f.reference_clause();
        let mut all = vec![Value::from(name)];
        all.extend(params);
        all.push((max as i64).into());
        let rows = self.sql().query(
            &format!(
                "SELECT r.started_utc, u.serial, m.value, m.outcome, r.id, r.log_path, ru.slot, ru.outcome AS run_outcome FROM measurements m \
                 JOIN run_units ru ON ru.run = m.run AND ru.slot = m.slot \
                 JOIN runs r ON r.id = m.run JOIN units u ON u.id = ru.unit_id \
                 WHERE m.name = $1 AND r.latest = 1 AND m.value IS NOT NULL{reference}{clauses} \
                 ORDER BY r.started_utc DESC, r.id DESC LIMIT ${}",
                all.len()
            ),
            &all,
        )?;
        let mut out: Vec<TrendPoint> = rows
            .iter()
            .filter_map(|r| {
                Some(TrendPoint {
                    started_utc: r.text("started_utc"),
                    serial: r.text("serial"),
                    value: r.real("value")?,
                    outcome: MeasureOutcome::parse(&r.text("outcome"))
                        .unwrap_or(MeasureOutcome::Error),
                    run: r.text("id"),
                    log_path: r.text("log_path"),
                    slot: r.text("slot"),
                    reference: r.text("run_outcome") == "reference",
                })
            })
            .collect();
        out.reverse();
        Ok(out)
    }

    /// Runs matching `f` (latest parts) with their measurements, for export.
    pub fn export_rows(
        &mut self,
        f: &Filter,
    ) -> Result<Vec<(RunRow, Vec<MeasurementRow>)>, StoreError> {
        let runs = self.list(f)?;
        let mut out = Vec::with_capacity(runs.len());
        for r in runs
            .into_iter()
            .filter(|r| f.include_reference || r.outcome != RunState::Reference)
        {
            let ms = self
                .sql()
                .query(
                    &format!(
                        "SELECT {MEASUREMENT_COLUMNS} FROM measurements m WHERE m.run = $1 AND m.slot = $2 ORDER BY m.seq"
                    ),
                    // A batch's row is one unit's: its own slot's figures.
                    &[r.id.clone().into(), r.slot.clone().into()],
                )?
                .iter()
                .map(measurement_row)
                .collect();
            out.push((r, ms));
        }
        Ok(out)
    }
}
