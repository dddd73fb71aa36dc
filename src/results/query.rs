//! Reading the store: runs (filtered), one run whole, a unit's history,
//! and a measurement's trend across units. Figures of a run are those of
//! its latest part (a resumed run's last report covers every part).

use serde::Serialize;

use super::sql::{Row, Value};
use super::{Store, StoreError};
use crate::runlog::meta::ResultMeasurement;

/// Which runs.
#[derive(Debug, Clone, Default)]
pub struct Filter {
    /// Unit serial.
    pub serial: Option<String>,
    /// Unit type.
    pub dut_type: Option<String>,
    /// Procedure name.
    pub procedure: Option<String>,
    /// Outcome (`running`, `pass`, `fail`, `error`, `aborted`).
    pub outcome: Option<String>,
    /// Bench (as the run named it) or station (host).
    pub bench: Option<String>,
    /// Started at or after (UTC, RFC 3339 or a date).
    pub since: Option<String>,
    /// Started before (UTC, RFC 3339 or a date).
    pub until: Option<String>,
    /// Only each run's latest part.
    pub latest_only: bool,
    /// At most this many rows (newest first); none: every row.
    pub limit: Option<usize>,
}

impl Filter {
    /// `WHERE` clauses on `r` (runs) and `u` (units), with their values,
    /// numbered from `$first`.
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
        add("r.outcome = $?", &self.outcome, &mut params);
        add("(r.bench = $? OR r.station = $?)", &self.bench, &mut params);
        add("r.started_utc >= $?", &self.since, &mut params);
        add("r.started_utc < $?", &self.until, &mut params);
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
    pub outcome: String,
    /// Which part.
    pub part: i64,
    /// The run's latest part.
    pub latest: bool,
    /// Device time, s.
    pub device_time_s: Option<f64>,
    /// What ended it, when it did not pass or fail.
    pub error: Option<String>,
}

const RUN_COLUMNS: &str = "r.id, r.started_utc, u.dut_type, u.serial, r.procedure_name, r.bench, \
    r.station, r.operator, r.outcome, r.part, r.latest, r.device_time_s, r.error_message";

fn run_row(r: &Row) -> RunRow {
    let t = |i: usize| r.get(i).map_or(String::new(), Value::text);
    RunRow {
        id: t(0),
        started_utc: t(1),
        dut_type: t(2),
        serial: t(3),
        procedure: t(4),
        bench: t(5),
        station: t(6),
        operator: t(7),
        outcome: t(8),
        part: r.get(9).and_then(Value::int).unwrap_or(1),
        latest: r.get(10).and_then(Value::int) == Some(1),
        device_time_s: r.get(11).and_then(Value::real),
        error: r.get(12).map(Value::text).filter(|s| !s.is_empty()),
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

const MEASUREMENT_COLUMNS: &str =
    "m.run, m.name, m.value, m.unit, m.low, m.high, m.outcome, m.step, m.note";

impl std::ops::Deref for MeasurementRow {
    type Target = ResultMeasurement;
    fn deref(&self) -> &ResultMeasurement {
        &self.measurement
    }
}

fn measurement_row(r: &Row) -> MeasurementRow {
    let t = |i: usize| r.get(i).map_or(String::new(), Value::text);
    let f = |i: usize| r.get(i).and_then(Value::real);
    MeasurementRow {
        run: t(0),
        measurement: ResultMeasurement {
            name: t(1),
            value: f(2),
            unit: t(3),
            low: f(4),
            high: f(5),
            outcome: t(6),
            step: t(7),
            note: t(8),
        },
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
    /// Process capability min(USL - mean, mean - LSL) / (3 sigma), where
    /// both limits exist.
    pub cpk: Option<f64>,
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
            "SELECT {RUN_COLUMNS} FROM runs r JOIN units u ON u.id = r.unit_id WHERE 1 = 1{clauses} \
             ORDER BY r.started_utc DESC, r.id DESC"
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
        let store = self.name.clone();
        let rows = self.sql().query(
            &format!(
                "SELECT {RUN_COLUMNS} FROM runs r JOIN units u ON u.id = r.unit_id \
                 WHERE r.id = $1 OR r.id LIKE $2 ORDER BY r.id LIMIT 50"
            ),
            &[id.into(), format!("{}%", id.replace(['%', '_'], "")).into()],
        )?;
        let run = match rows.as_slice() {
            [] => {
                return Err(StoreError::NotFound {
                    store,
                    what: format!("no run {id}; `gyrobench results list` shows the runs"),
                });
            }
            [r] => run_row(r),
            many if many
                .iter()
                .any(|r| r.first().map(Value::text).as_deref() == Some(id)) =>
            {
                run_row(&many[0])
            }
            // The parts of one run: its latest part.
            many if many.iter().all(|r| {
                run_id_of(&r.first().map(Value::text).unwrap_or_default())
                    == run_id_of(&many[0].first().map(Value::text).unwrap_or_default())
            }) =>
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
                            .filter_map(|r| r.first().map(Value::text))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                });
            }
        };
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
            "parent_id",
            "recorded_utc",
        ];
        let sql = format!("SELECT {} FROM runs WHERE id = $1", names.join(", "));
        let values = one(
            self.sql().query(&sql, &[run.id.clone().into()])?,
            Clone::clone,
        )
        .unwrap_or_default();
        let fields = names
            .iter()
            .zip(values)
            .map(|(n, v)| ((*n).to_owned(), v.text()))
            .collect();
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
                    "SELECT {RUN_COLUMNS} FROM runs r JOIN units u ON u.id = r.unit_id \
                     WHERE r.run_id = $1 ORDER BY r.part"
                ),
                &[run_id.into()],
            )?
            .iter()
            .map(run_row)
            .collect();
        Ok(RunDetail {
            run,
            fields,
            measurements,
            parts,
        })
    }

    /// Every run of the unit `serial` (its latest parts) with every
    /// measurement, and its latest coefficient set.
    pub fn unit(&mut self, serial: &str) -> Result<UnitHistory, StoreError> {
        let store = self.name.clone();
        let runs: Vec<RunRow> = self
            .sql()
            .query(
                &format!(
                    "SELECT {RUN_COLUMNS} FROM runs r JOIN units u ON u.id = r.unit_id \
                     WHERE u.serial = $1 AND r.latest = 1 ORDER BY r.started_utc, r.id"
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
                    "SELECT {MEASUREMENT_COLUMNS} FROM measurements m JOIN runs r ON r.id = m.run \
                     JOIN units u ON u.id = r.unit_id WHERE u.serial = $1 AND r.latest = 1 \
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
                 c.coeffs_toml FROM coefficient_sets c JOIN units u ON u.id = c.unit_id \
                 WHERE u.serial = $1 ORDER BY c.version DESC LIMIT 1",
                &[serial.into()],
            )?,
            |r| CoefficientRow {
                version: r.first().and_then(Value::int).unwrap_or(0),
                created_utc: r.get(1).map_or(String::new(), Value::text),
                validation: r.get(2).map_or(String::new(), Value::text),
                held_out_drift_pp_dph: r.get(3).and_then(Value::real),
                source_runs: r.get(4).map_or(String::new(), Value::text),
                coeffs_toml: r.get(5).map_or(String::new(), Value::text),
            },
        );
        Ok(UnitHistory {
            serial: serial.to_owned(),
            runs,
            measurements,
            coefficients,
        })
    }

    /// The statistics of measurement `name` over the runs `f` selects
    /// (their latest parts).
    pub fn trend(&mut self, name: &str, f: &Filter) -> Result<Trend, StoreError> {
        let (clauses, params) = f.clauses(2);
        let mut all = vec![Value::from(name)];
        all.extend(params);
        let from = format!(
            "FROM measurements m JOIN runs r ON r.id = m.run JOIN units u ON u.id = r.unit_id \
             WHERE m.name = $1 AND r.latest = 1{clauses}"
        );
        let stats = self.sql().query(
            &format!(
                "SELECT COUNT(m.value), AVG(m.value), MIN(m.value), MAX(m.value), \
                 SUM(CASE WHEN m.outcome = 'pass' THEN 1 ELSE 0 END), COUNT(*) {from}"
            ),
            &all,
        )?;
        let s = stats.first().cloned().unwrap_or_default();
        let g = |i: usize| s.get(i).and_then(Value::real);
        let count = s.first().and_then(Value::int).unwrap_or(0);
        let judged = s.get(5).and_then(Value::int).unwrap_or(0);
        if judged == 0 {
            return Err(StoreError::NotFound {
                store: self.name.clone(),
                what: format!("no measurement named {name} in the runs asked for"),
            });
        }
        let mean = g(1);
        let n = count as f64;
        // Two passes: the squares about the mean, not the mean of the
        // squares (which cancels catastrophically for a large mean).
        let sigma = match mean {
            Some(m) if count > 1 => {
                let k = all.len() + 1;
                let mut with_mean = all.clone();
                with_mean.push(Value::from(m));
                let ss = self.sql().query(
                    &format!("SELECT SUM((m.value - ${k}) * (m.value - ${k})) {from}"),
                    &with_mean,
                )?;
                ss.first()
                    .and_then(|r| r.first())
                    .and_then(Value::real)
                    .map(|ss| (ss.max(0.0) / (n - 1.0)).sqrt())
            }
            _ => None,
        };
        let newest = self.sql().query(
            &format!("SELECT m.low, m.high, m.unit {from} ORDER BY r.started_utc DESC LIMIT 1"),
            &all,
        )?;
        let low = newest.first().and_then(|r| r.first()).and_then(Value::real);
        let high = newest.first().and_then(|r| r.get(1)).and_then(Value::real);
        let unit = newest
            .first()
            .and_then(|r| r.get(2))
            .map_or(String::new(), Value::text);
        let cpk = match (mean, sigma, low, high) {
            (Some(m), Some(s), Some(lo), Some(hi)) if s > 0.0 => {
                Some(((hi - m).min(m - lo)) / (3.0 * s))
            }
            _ => None,
        };
        Ok(Trend {
            name: name.to_owned(),
            unit,
            count,
            judged,
            mean,
            sigma,
            min: g(2),
            max: g(3),
            yield_fraction: g(4).map(|p| p / judged as f64),
            low,
            high,
            cpk,
        })
    }

    /// The values of measurement `name` with their run's start and unit,
    /// oldest first (at most `max`, the newest).
    pub fn trend_points(
        &mut self,
        name: &str,
        f: &Filter,
        max: usize,
    ) -> Result<Vec<(String, String, f64, String)>, StoreError> {
        let (clauses, params) = f.clauses(2);
        let mut all = vec![Value::from(name)];
        all.extend(params);
        all.push((max as i64).into());
        let rows = self.sql().query(
            &format!(
                "SELECT r.started_utc, u.serial, m.value, m.outcome FROM measurements m \
                 JOIN runs r ON r.id = m.run JOIN units u ON u.id = r.unit_id \
                 WHERE m.name = $1 AND r.latest = 1 AND m.value IS NOT NULL{clauses} \
                 ORDER BY r.started_utc DESC LIMIT ${}",
                all.len()
            ),
            &all,
        )?;
        let mut out: Vec<(String, String, f64, String)> = rows
            .iter()
            .filter_map(|r| {
                Some((
                    r.first()?.text(),
                    r.get(1)?.text(),
                    r.get(2)?.real()?,
                    r.get(3)?.text(),
                ))
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
        for r in runs {
            let ms = self
                .sql()
                .query(
                    &format!(
                        "SELECT {MEASUREMENT_COLUMNS} FROM measurements m WHERE m.run = $1 ORDER BY m.seq"
                    ),
                    &[r.id.clone().into()],
                )?
                .iter()
                .map(measurement_row)
                .collect();
            out.push((r, ms));
        }
        Ok(out)
    }
}
