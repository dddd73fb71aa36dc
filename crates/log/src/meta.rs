//! The run's metadata records, typed: `run` (the configuration a part of
//! a run started with) and `result` (how it ended). MCAP metadata is
//! string to string; these types are the only place that knows the keys,
//! and reading one back says which key is wrong instead of guessing.

use std::collections::BTreeMap;

use gyrobench_model::coefficients::{CoeffsSource, CoeffsUsed};
use gyrobench_model::instrument::Instrument;
use gyrobench_model::outcome::{BenchLeft, Outcome, RunError};
use serde::Serialize;

/// A metadata value that does not parse.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the `{record}` metadata has {key} = {value:?}: {why}")]
pub struct MetaError {
    /// `run` or `result`.
    pub record: &'static str,
    /// The key.
    pub key: String,
    /// Its value.
    pub value: String,
    /// What was expected.
    pub why: String,
}

/// The `run` metadata of one part of a run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunMeta {
    /// Log layout version (1 when absent: logs written before the key).
    pub format: u32,
    /// Identity of the run, the same in every part (empty in format 1).
    pub run_id: String,
    /// The procedure's text, exactly as run.
    pub procedure_toml: String,
    /// Where the procedure was read from.
    pub procedure_path: String,
    /// The bench configuration (empty: the embedded bench, format 1).
    pub bench_toml: String,
    /// The bench as the operator named it (`embedded`, a bench file path).
    pub bench: String,
    /// Twin of a simulated run.
    pub twin_toml: Option<String>,
    /// Coefficients the run compensated with.
    pub coeffs_toml: Option<String>,
    /// The site as JSON (informative; the bench holds it too).
    pub site_json: String,
    /// Serial number of the unit under test.
    pub dut_serial: String,
    /// Unit type.
    pub dut_type: String,
    /// Who ran it (empty when not given).
    pub operator: String,
    /// The bench PC it ran on (its host name, or the bench file's
    /// `[results] station`).
    pub station: String,
    /// gyrobench version that wrote the log.
    pub software_version: String,
    /// UTC start of the run (of its first part), RFC 3339.
    pub start_time_utc: String,
    /// UTC start of this part, RFC 3339.
    pub part_start_time_utc: String,
    /// Seed of a simulated bench.
    pub seed: Option<u64>,
    /// Which part of the run this file is (1 for the first).
    pub part: u32,
    /// File name of the part before this one.
    pub previous_part: Option<String>,
    /// Steps the earlier parts completed (run order), where a resume picked up.
    pub resume_completed_steps: Option<usize>,
    /// Speed of a simulated bench (`max` or a factor).
    pub speed: String,
    /// The CSV an imported run came from.
    pub imported_from: Option<String>,
    /// The bench's id (empty in logs written before the key).
    pub bench_id: String,
    /// The computer the run ran on, its host name.
    pub host: String,
    /// The source revision of the gyrobench that wrote the log.
    pub software_revision: String,
    /// The chamber and table as they reported themselves, with their
    /// calibration due dates (empty in logs written before the key).
    pub instruments: Vec<Instrument>,
    /// The units of the run, one per slot, with the coefficients each was
    /// compensated with. Logs written before the key have one, made of
    /// `dut_serial`, `dut_type` and `coeffs_toml`.
    pub units: Vec<RunUnit>,
    /// Keys this build does not know (kept, never dropped).
    pub other: BTreeMap<String, String>,
}

/// A unit of a run: its slot on the bench (empty on a bench with one unit
/// position), its identity, and the coefficients it was compensated with.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RunUnit {
    /// Slot on the bench's fixture (empty: the bench's only one).
    pub slot: String,
    /// Serial number.
    pub serial: String,
    /// Unit type.
    #[serde(rename = "type")]
    pub dut_type: String,
    /// The coefficients its compensated figures use.
    pub coefficients: CoeffsUsed,
    /// Its body orientation in NED with both table angles at zero (a
    /// batch's slots; none: the bench's `[table.geometry] mount`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mount: Option<gyrobench_model::geometry::Orientation>,
    /// A batch unit's own twin (its slot's twin file, as read; none: the
    /// run's, `twin_toml`), for a resume on the same units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twin_toml: Option<String>,
    /// A simulated batch unit's own seed (its slot's, or the run's plus
    /// the slot's index; none: the run's `seed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
}

fn take(m: &mut BTreeMap<String, String>, k: &str) -> String {
    m.remove(k).unwrap_or_default()
}

fn take_opt(m: &mut BTreeMap<String, String>, k: &str) -> Option<String> {
    m.remove(k).filter(|v| !v.trim().is_empty())
}

fn parse<T: std::str::FromStr>(
    record: &'static str,
    m: &mut BTreeMap<String, String>,
    k: &str,
    why: &str,
) -> Result<Option<T>, MetaError> {
    match take_opt(m, k) {
        None => Ok(None),
        Some(v) => v.trim().parse().map(Some).map_err(|_| MetaError {
            record,
            key: k.to_owned(),
            why: why.to_owned(),
            value: v,
        }),
    }
}

/// A JSON value under `k`, or none when the key is absent or empty.
fn json<T: serde::de::DeserializeOwned>(
    record: &'static str,
    m: &mut BTreeMap<String, String>,
    k: &str,
) -> Result<Option<T>, MetaError> {
    match take_opt(m, k) {
        None => Ok(None),
        Some(v) => serde_json::from_str(&v).map(Some).map_err(|e| MetaError {
            record,
            key: k.to_owned(),
            why: e.to_string(),
            value: v,
        }),
    }
}

/// An RFC 3339 time as ns since the epoch (log times count from it), or
/// none when it does not parse or falls outside 1970..2554.
pub fn utc_ns(t: &str) -> Option<u64> {
    let t = chrono::DateTime::parse_from_rfc3339(t).ok()?;
    u64::try_from(t.timestamp_nanos_opt()?).ok()
}

impl RunMeta {
    /// Where this part's device time starts, in log time (ns since the
    /// epoch).
    pub fn part_start_ns(&self) -> Option<u64> {
        utc_ns(&self.part_start_time_utc)
    }

    /// Read the `run` record's entries; unknown keys are kept in `other`.
    pub fn from_entries(entries: &BTreeMap<String, String>) -> Result<Self, MetaError> {
        let m = &mut entries.clone();
        let r = "run";
        Ok(Self {
            format: parse(r, m, "format", "expected a format number")?.unwrap_or(1),
            run_id: take(m, "run_id"),
            procedure_toml: take(m, "procedure_toml"),
            procedure_path: take(m, "procedure_path"),
            bench_toml: take(m, "bench_toml"),
            bench: take_opt(m, "bench").unwrap_or_else(|| "embedded".into()),
            twin_toml: take_opt(m, "twin_toml"),
            coeffs_toml: take_opt(m, "coeffs_toml"),
            site_json: take(m, "site"),
            dut_serial: take(m, "dut_serial"),
            dut_type: take(m, "dut_type"),
            operator: take(m, "operator"),
            station: take(m, "station"),
            software_version: take(m, "software_version"),
            start_time_utc: take(m, "start_time_utc"),
            part_start_time_utc: take(m, "part_start_time_utc"),
            seed: parse(
                r,
                m,
                "seed",
                "expected the simulated bench's seed, an integer",
            )?,
            part: parse(r, m, "part", "expected the part number, 1 or more")?
                .filter(|p| *p >= 1)
                .unwrap_or(1),
            previous_part: take_opt(m, "previous_part"),
            resume_completed_steps: parse(
                r,
                m,
                "resume_completed_steps",
                "expected a number of steps",
            )?,
            speed: take(m, "speed"),
            imported_from: take_opt(m, "imported_from"),
            bench_id: take(m, "bench_id"),
            host: take(m, "host"),
            software_revision: take(m, "software_revision"),
            instruments: json(r, m, "instruments")?.unwrap_or_default(),
            units: json(r, m, "units")?.unwrap_or_default(),
            other: BTreeMap::new(),
        }
        .with_units_of_format_2()
        .with_other(std::mem::take(m)))
    }

    /// A log written before `units`: its one unit from `dut_serial`,
    /// `dut_type` and whether it names coefficients.
    fn with_units_of_format_2(mut self) -> Self {
        if self.units.is_empty() {
            self.units.push(RunUnit {
                slot: String::new(),
                serial: self.dut_serial.clone(),
                dut_type: self.dut_type.clone(),
                coefficients: match &self.coeffs_toml {
                    Some(_) => CoeffsUsed {
                        source: CoeffsSource::File,
                        ..CoeffsUsed::fitted()
                    },
                    None => CoeffsUsed::fitted(),
                },
                mount: None,
                twin_toml: None,
                seed: None,
            });
        }
        self
    }

    fn with_other(mut self, other: BTreeMap<String, String>) -> Self {
        self.other = other;
        self
    }

    /// The run's first unit (its only one on a bench with one position).
    pub fn unit(&self) -> Option<&RunUnit> {
        self.units.first()
    }

    /// A batch: its units sit in named slots (a bench with `[[slots]]`,
    /// even with one unit in it).
    pub fn is_batch(&self) -> bool {
        self.units.iter().any(|u| !u.slot.is_empty())
    }

    /// The run as unit `k` of a batch is recorded: its serial and its
    /// unit alone (what its report and its store record name).
    pub fn for_unit(&self, k: usize) -> Self {
        let mut m = self.clone();
        if let Some(u) = self.units.get(k) {
            m.dut_serial = u.serial.clone();
            m.seed = u.seed.or(m.seed);
            m.units = vec![u.clone()];
        }
        m
    }

    /// The entries as written to the log.
    pub fn to_entries(&self) -> BTreeMap<String, String> {
        let mut m = self.other.clone();
        let mut put = |k: &str, v: &str| {
            m.insert(k.to_owned(), v.to_owned());
        };
        put("format", &self.format.to_string());
        put("run_id", &self.run_id);
        put("procedure_toml", &self.procedure_toml);
        put("procedure_path", &self.procedure_path);
        put("bench_toml", &self.bench_toml);
        put("bench", &self.bench);
        put("twin_toml", self.twin_toml.as_deref().unwrap_or(""));
        put("coeffs_toml", self.coeffs_toml.as_deref().unwrap_or(""));
        put("site", &self.site_json);
        put("dut_serial", &self.dut_serial);
        put("dut_type", &self.dut_type);
        put("operator", &self.operator);
        put("station", &self.station);
        put("software_version", &self.software_version);
        put("start_time_utc", &self.start_time_utc);
        put("part_start_time_utc", &self.part_start_time_utc);
        put("seed", &self.seed.map_or(String::new(), |s| s.to_string()));
        put("part", &self.part.to_string());
        put("previous_part", self.previous_part.as_deref().unwrap_or(""));
        put(
            "resume_completed_steps",
            &self
                .resume_completed_steps
                .map_or(String::new(), |s| s.to_string()),
        );
        put("speed", &self.speed);
        if let Some(f) = &self.imported_from {
            put("imported_from", f);
        }
        put("bench_id", &self.bench_id);
        put("host", &self.host);
        put("software_revision", &self.software_revision);
        put(
            "instruments",
            &serde_json::to_string(&self.instruments).unwrap_or_else(|_| "[]".into()),
        );
        put(
            "units",
            &serde_json::to_string(&self.units).unwrap_or_else(|_| "[]".into()),
        );
        m
    }

    /// True when the run ran on the embedded simulated bench.
    pub fn is_embedded(&self) -> bool {
        self.bench == "embedded"
    }
}

/// Why a log's `run` metadata cannot be had.
#[derive(Debug, thiserror::Error)]
pub enum RunMetaError {
    /// The file cannot be read as a log.
    #[error(transparent)]
    Read(#[from] crate::ReadError),
    /// The metadata is there and a value of it does not parse.
    #[error("{path}: {source}")]
    Invalid {
        /// File.
        path: String,
        /// The key and its value.
        #[source]
        source: MetaError,
    },
    /// The file holds no `run` metadata: not a gyrobench log.
    #[error("{path}: no run metadata")]
    Missing {
        /// File.
        path: String,
    },
}

impl RunMetaError {
    /// What is wrong, for a message that names the file already (a read
    /// error names it itself).
    pub fn detail(&self) -> String {
        match self {
            Self::Read(e) => e.to_string(),
            Self::Invalid { source, .. } => source.to_string(),
            Self::Missing { .. } => "no run metadata".into(),
        }
    }
}

/// The `run` metadata of the log at `path` (its first part's when the
/// file holds several), or why it cannot be read.
pub fn read_run_meta(path: &std::path::Path) -> Result<RunMeta, RunMetaError> {
    let mut meta = None;
    let read = crate::read(path, |item| {
        if let crate::Item::Meta { name, entries } = item
            && name == crate::schema::RUN_META
        {
            meta = Some(RunMeta::from_entries(entries));
            return std::ops::ControlFlow::Break(crate::Stop::Enough);
        }
        std::ops::ControlFlow::Continue(())
    });
    let path = || path.display().to_string();
    match (meta, read) {
        (Some(m), _) => m.map_err(|source| RunMetaError::Invalid {
            path: path(),
            source,
        }),
        (None, Err(e)) => Err(e.into()),
        (None, Ok(_)) => Err(RunMetaError::Missing { path: path() }),
    }
}

/// One measurement as the `result` record lists it (for a store or a
/// reader that does not replay).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct ResultMeasurement {
    /// Name from the procedure.
    pub name: String,
    /// Value (null when it could not be computed).
    pub value: Option<f64>,
    /// Unit.
    pub unit: String,
    /// Lower limit.
    pub low: Option<f64>,
    /// Upper limit.
    pub high: Option<f64>,
    /// The verdict (`pass`, `fail` or `error`).
    pub outcome: gyrobench_model::outcome::MeasureOutcome,
    /// Step key.
    pub step: String,
    /// How it was obtained, or why it could not be.
    pub note: String,
    /// Its uncertainty `{u, U, k}` (none: it could not be formed, or a log
    /// written before format 3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<gyrobench_analysis::uncertainty::Expanded>,
    /// The guard band the decision rule moved its limits by (none: simple
    /// acceptance, no limit or no uncertainty).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guard_band: Option<f64>,
}

/// The record's entry of a measurement the run made.
impl From<&gyrobench_model::measurement::Measurement> for ResultMeasurement {
    fn from(m: &gyrobench_model::measurement::Measurement) -> Self {
        Self {
            name: m.name.clone(),
            value: m.value,
            unit: m.unit.clone(),
            low: m.low,
            high: m.high,
            outcome: m.outcome,
            step: m.step.clone(),
            note: m.note.clone(),
            uncertainty: m.uncertainty.as_ref().map(|u| u.brief()),
            guard_band: m.guard_band,
        }
    }
}

/// The `result` metadata: how a part of a run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct ResultMeta {
    /// Verdict or how it stopped.
    pub outcome: Outcome,
    /// Whether cleanup ran to its end.
    pub cleanup_completed: bool,
    /// Device time of the run so far (every part), s.
    pub device_time_s: Option<f64>,
    /// Frames of the run so far (every part).
    pub frames: u64,
    /// The failure that ended it.
    pub error: Option<RunError>,
    /// Every measurement made (every part).
    pub measurements: Vec<ResultMeasurement>,
    /// The state the bench was left in, as read back.
    pub bench_left: Option<BenchLeft>,
    /// When the part ended, UTC, RFC 3339: the time the results store
    /// records as its end (none in logs written before the key, and in an
    /// import's).
    pub end_time_utc: Option<String>,
}

impl ResultMeta {
    /// The record, stating that the part ended at `utc` (RFC 3339).
    pub fn ended_at(self, utc: &str) -> Self {
        Self {
            end_time_utc: Some(utc.to_owned()),
            ..self
        }
    }

    /// The entries as written to the log.
    pub fn to_entries(&self) -> BTreeMap<String, String> {
        let mut m = BTreeMap::new();
        let mut put = |k: &str, v: String| {
            m.insert(k.to_owned(), v);
        };
        put("outcome", self.outcome.as_str().to_owned());
        put("cleanup_completed", self.cleanup_completed.to_string());
        if let Some(t) = self.device_time_s {
            put("device_time_s", format!("{t:?}"));
        }
        put("frames", self.frames.to_string());
        if let Some(e) = &self.error {
            put("error_step", e.step.clone());
            put("error_message", e.message.clone());
            if let Some(d) = &e.device {
                put("error_device", d.clone());
            }
        }
        put(
            "measurements",
            serde_json::to_string(&self.measurements).unwrap_or_else(|_| "[]".into()),
        );
        if let Some(b) = &self.bench_left
            && let Ok(j) = serde_json::to_string(b)
        {
            put("bench_left", j);
        }
        if let Some(t) = &self.end_time_utc {
            put("end_time_utc", t.clone());
        }
        m
    }

    /// Read the `result` record's entries (format 1 has no measurements
    /// and no bench state).
    pub fn from_entries(entries: &BTreeMap<String, String>) -> Result<Self, MetaError> {
        let m = &mut entries.clone();
        let r = "result";
        let bad = |key: &str, value: String, why: String| MetaError {
            record: r,
            key: key.to_owned(),
            value,
            why,
        };
        let outcome_text = take(m, "outcome");
        let outcome = Outcome::parse(&outcome_text).ok_or_else(|| {
            bad(
                "outcome",
                outcome_text.clone(),
                "expected pass, fail, error or aborted".into(),
            )
        })?;
        let error = take_opt(m, "error_step").map(|step| RunError {
            device: take_opt(m, "error_device"),
            step,
            message: take(m, "error_message"),
        });
        let measurements = match take_opt(m, "measurements") {
            None => Vec::new(),
            Some(j) => serde_json::from_str(&j)
                .map_err(|e| bad("measurements", j.clone(), e.to_string()))?,
        };
        let bench_left = match take_opt(m, "bench_left") {
            None => None,
            Some(j) => Some(
                serde_json::from_str(&j)
                    .map_err(|e| bad("bench_left", j.clone(), e.to_string()))?,
            ),
        };
        Ok(Self {
            outcome,
            cleanup_completed: take(m, "cleanup_completed") == "true",
            device_time_s: parse(r, m, "device_time_s", "expected seconds")?,
            frames: parse(r, m, "frames", "expected a frame count")?.unwrap_or(0),
            error,
            measurements,
            bench_left,
            end_time_utc: take_opt(m, "end_time_utc"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_meta_round_trips_and_keeps_unknown_keys() {
        let mut m = RunMeta {
            format: 2,
            bench: "embedded".into(),
            run_id: "r1".into(),
            procedure_toml: "[procedure]".into(),
            seed: Some(7),
            part: 2,
            previous_part: Some("run.mcap".into()),
            resume_completed_steps: Some(4),
            bench_id: "bench-2".into(),
            host: "pc-7".into(),
            software_revision: "1a2b3c4d5e6f".into(),
            instruments: vec![Instrument {
                role: "chamber".into(),
                spec: "tcp://10.0.0.5:10001".into(),
                identity: Some(gyrobench_protocol::Identity {
                    manufacturer: Some("Espec".into()),
                    model: Some("SCP-220".into()),
                    serial: None,
                    firmware: Some("1.05".into()),
                    raw: "TYPE? SCP-220 | ROM? 1.05".into(),
                }),
                identity_error: None,
                calibration_due: Some("2027-03-31".into()),
                calibration_overdue: false,
            }],
            units: vec![RunUnit {
                slot: "A".into(),
                serial: "RL16-0042".into(),
                dut_type: "RL-16".into(),
                coefficients: CoeffsUsed {
                    source: CoeffsSource::Store,
                    serial: Some("RL16-0042".into()),
                    dut_type: Some("RL-16".into()),
                    version: Some(3),
                    sha256: Some("ab".repeat(32)),
                    from: Some("results.sqlite".into()),
                    override_reason: None,
                    identity: Some(gyrobench_model::coefficients::SetIdentity {
                        status: gyrobench_model::coefficients::SetStatus::Edited,
                        claimed_unit: None,
                        claimed_version: Some(9),
                        stored: None,
                        fitted_on_runs: Vec::new(),
                        store: Some("results.sqlite".into()),
                        note: "an edited copy".into(),
                    }),
                },
                mount: Some(gyrobench_model::geometry::Orientation::new(90.0, 0.0, 0.0)),
                twin_toml: None,
                seed: None,
            }],
            ..RunMeta::default()
        };
        m.other.insert("from_the_future".into(), "x".into());
        let back = RunMeta::from_entries(&m.to_entries()).expect("parses");
        assert_eq!(back, m);
    }

    #[test]
    fn a_log_written_before_units_has_its_one_unit_from_the_dut_keys() {
        let mut e = BTreeMap::new();
        e.insert("dut_serial".to_owned(), "RL16-0007".to_owned());
        e.insert("dut_type".to_owned(), "RL-16".to_owned());
        e.insert("coeffs_toml".to_owned(), "[model4]".to_owned());
        let m = RunMeta::from_entries(&e).expect("an older log");
        let u = m.unit().expect("one unit");
        assert_eq!(
            (u.serial.as_str(), u.dut_type.as_str()),
            ("RL16-0007", "RL-16")
        );
        assert_eq!(u.coefficients.source, CoeffsSource::File);
        assert_eq!(
            u.coefficients.describe(),
            "the coefficients given by --coeffs"
        );
        e.insert("instruments".to_owned(), "not json".to_owned());
        let err = RunMeta::from_entries(&e).expect_err("a bad value is said");
        assert_eq!(err.key, "instruments");
    }

    #[test]
    fn a_bad_seed_is_an_error_naming_the_key_not_seed_one() {
        let mut e = RunMeta::default().to_entries();
        e.insert("seed".into(), "seven".into());
        let err = RunMeta::from_entries(&e).expect_err("must not guess");
        assert_eq!(err.key, "seed");
        assert!(err.to_string().contains("\"seven\""), "{err}");
    }

    #[test]
    fn format_1_entries_read_with_defaults() {
        let mut e = BTreeMap::new();
        e.insert("procedure_toml".to_owned(), "x".to_owned());
        e.insert("seed".to_owned(), "1".to_owned());
        let m = RunMeta::from_entries(&e).expect("format 1");
        assert_eq!((m.format, m.part, m.seed), (1, 1, Some(1)));
        assert!(m.is_embedded());
        let mut r = BTreeMap::new();
        r.insert("outcome".to_owned(), "pass".to_owned());
        let res = ResultMeta::from_entries(&r).expect("format 1 result");
        assert_eq!(res.outcome, Outcome::Pass);
        assert!(res.measurements.is_empty() && res.device_time_s.is_none());
    }

    #[test]
    fn a_result_states_when_its_part_ended_and_an_older_one_reads_without() {
        let mut r = BTreeMap::new();
        r.insert("outcome".to_owned(), "pass".to_owned());
        let older = ResultMeta::from_entries(&r).expect("a result of an earlier gyrobench");
        assert_eq!(older.end_time_utc, None);
        let ended = older.ended_at("2026-12-03T10:00:00+00:00");
        let back = ResultMeta::from_entries(&ended.to_entries()).expect("reads back");
        assert_eq!(
            back.end_time_utc.as_deref(),
            Some("2026-12-03T10:00:00+00:00")
        );
    }

    #[test]
    fn an_unknown_outcome_is_refused() {
        let mut r = BTreeMap::new();
        r.insert("outcome".to_owned(), "maybe".to_owned());
        assert!(ResultMeta::from_entries(&r).is_err());
    }
}
