//! Writing the store: a part of a run when it starts and when it ends (by
//! the run itself), a part from its log (`results sync`, `replay --store`,
//! a queued run), and the coefficient sets `calibrate` makes.

use std::path::Path;

use sha2::Digest;

use super::sql::{Sql, Value, transaction};
use super::{Store, StoreError};
use crate::protocol::frame::LinkStats;
use crate::runlog::meta::RunMeta;
use crate::runlog::replay::replay;
use crate::sequencer::RunResult;

/// The SHA-256 of a file, in hex.
pub fn sha256_file(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    let mut f = std::fs::File::open(path)?;
    let mut h = sha2::Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(hex(&h.finalize()))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The SHA-256 of a text, in hex.
pub fn sha256_text(text: &str) -> String {
    hex(&sha2::Sha256::digest(text.as_bytes()))
}

/// The store's key of a part of a run: `RUN_ID.PART`. A log of the first
/// format has no run id: its first part's SHA-256 stands for it.
pub fn part_key(meta: &RunMeta, log: &Path) -> Result<String, StoreError> {
    Ok(format!("{}.{}", run_id(meta, log)?, meta.part))
}

/// The store's key of the part of a run whose log is `log` (its metadata
/// read from the log), or none when the log cannot be read.
pub fn part_key_of_log(log: &Path) -> Option<String> {
    let mut meta = None;
    let _read = crate::runlog::read(log, |item| {
        if let crate::runlog::Item::Meta { name, entries } = item
            && name == crate::runlog::schema::RUN_META
        {
            meta = RunMeta::from_entries(entries).ok();
            return Err("enough".into());
        }
        Ok(())
    });
    part_key(&meta?, log).ok()
}

fn run_id(meta: &RunMeta, log: &Path) -> Result<String, StoreError> {
    if !meta.run_id.is_empty() {
        return Ok(meta.run_id.clone());
    }
    let first = log.with_file_name("run.mcap");
    let sha = sha256_file(&first).map_err(|e| StoreError::Log {
        path: first.display().to_string(),
        message: format!("the first part of a run without a run id: {e}"),
    })?;
    Ok(format!("sha256-{}", &sha[..32]))
}

/// How a part ended, for the store.
#[derive(Debug)]
pub struct PartEnd<'a> {
    /// The run's result (every part so far).
    pub result: &'a RunResult,
    /// The link figures (every part so far).
    pub link: LinkStats,
    /// When the part ended, UTC, RFC 3339.
    pub ended_utc: String,
}

/// What indexing a log did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Indexed {
    /// The part was not in the store; it is now.
    Added,
    /// The part was there, still running (its process died): completed.
    Completed,
    /// The part was there, complete: nothing done.
    AlreadyThere,
}

fn unit_id(sql: &mut dyn Sql, dut_type: &str, serial: &str) -> Result<i64, StoreError> {
    sql.execute(
        "INSERT INTO units (dut_type, serial) VALUES ($1, $2) ON CONFLICT (dut_type, serial) DO NOTHING",
        &[dut_type.into(), serial.into()],
    )?;
    let rows = sql.query(
        "SELECT id FROM units WHERE dut_type = $1 AND serial = $2",
        &[dut_type.into(), serial.into()],
    )?;
    rows.first()
        .and_then(|r| r.first())
        .and_then(Value::int)
        .ok_or_else(|| StoreError::NotFound {
            store: String::new(),
            what: format!("unit {dut_type} {serial} just written"),
        })
}

fn outcome_of(sql: &mut dyn Sql, id: &str) -> Result<Option<String>, StoreError> {
    Ok(sql
        .query("SELECT outcome FROM runs WHERE id = $1", &[id.into()])?
        .first()
        .and_then(|r| r.first())
        .map(Value::text))
}

impl Store {
    /// Record that a part of a run started: its row, outcome `running`.
    /// Earlier parts missing from the store are indexed from their logs
    /// first. Returns the part's key.
    pub fn begin_part(&mut self, meta: &RunMeta, log: &Path) -> Result<String, StoreError> {
        self.ensure_earlier_parts(meta, log)?;
        let key = part_key(meta, log)?;
        let run = run_id(meta, log)?;
        let now = crate::clock::utc_now().to_rfc3339();
        let log_path = std::path::absolute(log)
            .unwrap_or_else(|_| log.to_owned())
            .display()
            .to_string();
        let parent = (meta.part > 1).then(|| format!("{run}.{}", meta.part - 1));
        let procedure_name = crate::procedure::raw_name(&meta.procedure_toml).unwrap_or_default();
        let store = self.name.clone();
        transaction(self.sql(), |sql| {
            let unit = unit_id(sql, &meta.dut_type, &meta.dut_serial).map_err(|e| match e {
                StoreError::NotFound { what, .. } => StoreError::NotFound { store, what },
                e => e,
            })?;
            sql.execute(
                "UPDATE runs SET latest = 0 WHERE run_id = $1 AND part < $2",
                &[run.clone().into(), i64::from(meta.part).into()],
            )?;
            sql.execute(
                "INSERT INTO runs (id, run_id, part, parent_id, latest, unit_id, procedure_name, \
                 procedure_sha256, procedure_path, bench, station, operator, seed, software_version, \
                 run_started_utc, started_utc, outcome, log_path, imported_from, recorded_utc) \
                 VALUES ($1, $2, $3, $4, 1, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, 'running', $16, $17, $18)",
                &[
                    key.clone().into(),
                    run.clone().into(),
                    i64::from(meta.part).into(),
                    parent.into(),
                    unit.into(),
                    procedure_name.into(),
                    super::record::sha256_text(&meta.procedure_toml).into(),
                    meta.procedure_path.clone().into(),
                    meta.bench.clone().into(),
                    meta.station.clone().into(),
                    meta.operator.clone().into(),
                    meta.seed.and_then(|s| i64::try_from(s).ok()).into(),
                    meta.software_version.clone().into(),
                    meta.start_time_utc.clone().into(),
                    meta.part_start_time_utc.clone().into(),
                    log_path.into(),
                    meta.imported_from.clone().into(),
                    now.into(),
                ],
            )?;
            Ok(())
        })?;
        Ok(key)
    }

    /// Record how a part ended: its outcome, figures, link, bench state,
    /// log checksum, and every measurement of the run so far.
    pub fn finish_part(
        &mut self,
        key: &str,
        log: &Path,
        end: &PartEnd<'_>,
    ) -> Result<(), StoreError> {
        let sha = sha256_file(log).ok();
        let r = end.result;
        let l = &end.link;
        let left = r.bench_left.as_ref();
        let store = self.name.clone();
        transaction(self.sql(), |sql| {
            let n = sql.execute(
                "UPDATE runs SET ended_utc = $2, device_time_s = $3, frames = $4, outcome = $5, \
                 error_step = $6, error_device = $7, error_message = $8, cleanup_completed = $9, \
                 bench_left = $10, bench_left_verified = $11, link_frames = $12, link_lost_frames = $13, \
                 link_crc_errors = $14, link_reconnects = $15, link_longest_gap_ms = $16, log_sha256 = $17 \
                 WHERE id = $1 AND outcome = 'running'",
                &[
                    key.into(),
                    end.ended_utc.clone().into(),
                    r.device_time_s.into(),
                    i64::try_from(r.frames).ok().into(),
                    r.outcome.as_str().into(),
                    r.error.as_ref().map(|e| e.step.clone()).into(),
                    r.error.as_ref().and_then(|e| e.device.clone()).into(),
                    r.error.as_ref().map(|e| e.message.clone()).into(),
                    r.cleanup_completed.into(),
                    left.map(|b| b.summary.clone()).into(),
                    left.map(|b| b.verified).into(),
                    i64::try_from(l.frames).ok().into(),
                    i64::try_from(l.lost_frames).ok().into(),
                    i64::try_from(l.crc_errors).ok().into(),
                    i64::try_from(l.reconnects).ok().into(),
                    i64::try_from(l.longest_gap_ms).ok().into(),
                    sha.clone().into(),
                ],
            )?;
            if n != 1 {
                return Err(StoreError::NotFound {
                    store,
                    what: format!(
                        "no running part {key} to complete (it ended already, or never started here)"
                    ),
                });
            }
            // One statement for every measurement (a round trip each would
            // cost a lab's server more than the rest of the run's record).
            for (chunk_at, chunk) in r.measurements.chunks(100).enumerate() {
                let mut values = Vec::with_capacity(chunk.len());
                let mut params: Vec<Value> = Vec::with_capacity(10 * chunk.len());
                for (i, m) in chunk.iter().enumerate() {
                    let b = params.len();
                    values.push(format!(
                        "(${}, ${}, ${}, ${}, ${}, ${}, ${}, ${}, ${}, ${})",
                        b + 1,
                        b + 2,
                        b + 3,
                        b + 4,
                        b + 5,
                        b + 6,
                        b + 7,
                        b + 8,
                        b + 9,
                        b + 10
                    ));
                    params.extend([
                        key.into(),
                        ((chunk_at * 100 + i) as i64).into(),
                        m.name.clone().into(),
                        m.value.into(),
                        m.unit.clone().into(),
                        m.low.into(),
                        m.high.into(),
                        m.outcome.as_str().into(),
                        m.step.clone().into(),
                        m.note.clone().into(),
                    ]);
                }
                sql.execute(
                    &format!(
                        "INSERT INTO measurements (run, seq, name, value, unit, low, high, outcome, step, note) VALUES {}",
                        values.join(", ")
                    ),
                    &params,
                )?;
            }
            Ok(())
        })
    }

    /// Index a part of a run from its log: added when missing, completed
    /// when it was left running (its process died), left alone when it is
    /// there already (so a sync is idempotent). Earlier parts come first.
    pub fn index_log(&mut self, log: &Path) -> Result<Indexed, StoreError> {
        let bad = |message: String| StoreError::Log {
            path: log.display().to_string(),
            message,
        };
        let r = replay(log, None).map_err(|e| bad(e.to_string()))?;
        let key = part_key(&r.meta, log)?;
        let before = outcome_of(self.sql(), &key)?;
        if before.as_deref().is_some_and(|o| o != "running") {
            return Ok(Indexed::AlreadyThere);
        }
        if before.is_none() {
            self.begin_part(&r.meta, log)?;
        }
        let ended = std::fs::metadata(log)
            .and_then(|m| m.modified())
            .map(|t| chrono::DateTime::<chrono::Utc>::from(t).to_rfc3339())
            .unwrap_or_default();
        self.finish_part(
            &key,
            log,
            &PartEnd {
                result: &r.result,
                link: r.link,
                ended_utc: ended,
            },
        )?;
        Ok(if before.is_none() {
            Indexed::Added
        } else {
            Indexed::Completed
        })
    }

    /// Index the parts before this one that the store lacks.
    fn ensure_earlier_parts(&mut self, meta: &RunMeta, log: &Path) -> Result<(), StoreError> {
        let Some(prev) = &meta.previous_part else {
            return Ok(());
        };
        let prev_log = log.with_file_name(prev);
        let run = run_id(meta, log)?;
        let prev_key = format!("{run}.{}", meta.part.saturating_sub(1));
        if outcome_of(self.sql(), &prev_key)?.is_none() {
            self.index_log(&prev_log)?;
        }
        Ok(())
    }

    /// Every run directory below `dir` (those holding a `run.mcap`), each
    /// part indexed in order. Returns (added or completed, already there,
    /// failures with their reason).
    pub fn sync_dir(&mut self, dir: &Path) -> (usize, usize, Vec<String>) {
        let (mut added, mut there, mut failed) = (0, 0, Vec::new());
        for run_dir in run_dirs(dir) {
            let mut part = 1;
            loop {
                let log = if part == 1 {
                    run_dir.join("run.mcap")
                } else {
                    run_dir.join(format!("run.part{part}.mcap"))
                };
                if !log.exists() {
                    break;
                }
                match self.index_log(&log) {
                    Ok(Indexed::AlreadyThere) => there += 1,
                    Ok(_) => added += 1,
                    Err(e) => failed.push(e.to_string()),
                }
                part += 1;
            }
        }
        (added, there, failed)
    }

    /// Record a coefficient set `calibrate` made for a unit: the next
    /// version of that unit's sets, with the runs it came from.
    pub fn record_coefficients(&mut self, set: &CoefficientSet<'_>) -> Result<i64, StoreError> {
        let now = crate::clock::utc_now().to_rfc3339();
        transaction(self.sql(), |sql| {
            let unit = unit_id(sql, set.dut_type, set.serial)?;
            let next = sql
                .query(
                    "SELECT COALESCE(MAX(version), 0) + 1 FROM coefficient_sets WHERE unit_id = $1",
                    &[unit.into()],
                )?
                .first()
                .and_then(|r| r.first())
                .and_then(Value::int)
                .unwrap_or(1);
            sql.execute(
                "INSERT INTO coefficient_sets (unit_id, version, created_utc, coeffs_toml, validation, \
                 held_out_drift_pp_dph, source_runs) VALUES ($1, $2, $3, $4, $5, $6, $7)",
                &[
                    unit.into(),
                    next.into(),
                    now.into(),
                    set.coeffs_toml.into(),
                    set.validation.into(),
                    set.held_out_drift_pp_dph.into(),
                    serde_json::to_string(&set.sources).unwrap_or_default().into(),
                ],
            )?;
            Ok(next)
        })
    }
}

/// A coefficient set as `calibrate` made it.
#[derive(Debug)]
pub struct CoefficientSet<'a> {
    /// Unit type.
    pub dut_type: &'a str,
    /// Serial number.
    pub serial: &'a str,
    /// The coefficients file's text.
    pub coeffs_toml: &'a str,
    /// How it was validated.
    pub validation: &'a str,
    /// Model 4's held-out drift, deg/h.
    pub held_out_drift_pp_dph: Option<f64>,
    /// The runs it came from: (part key, log path).
    pub sources: Vec<(String, String)>,
}

/// Run directories at or below `dir`, sorted.
pub fn run_dirs(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        if d.join("run.mcap").is_file() {
            out.push(d.clone());
        }
        if let Ok(entries) = std::fs::read_dir(&d) {
            for e in entries.filter_map(Result::ok) {
                let p = e.path();
                if e.file_type().is_ok_and(|t| t.is_dir()) && !p.ends_with("replay") {
                    stack.push(p);
                }
            }
        }
    }
    out.sort();
    out
}
