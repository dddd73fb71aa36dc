//! Writing the store: a part of a run when it starts and when it ends (by
//! the run itself), a part from its log (`results sync`, `replay --store`,
//! a queued run), and the coefficient sets `calibrate` makes.

use std::path::Path;

use super::facts::{self, Column};
use super::sql::{Sql, Value, transaction};
use super::{Store, StoreError};
use crate::coeffs::CoefficientSet;
use crate::protocol::frame::LinkStats;
use crate::runlog::meta::RunMeta;
use crate::sequencer::RunResult;
use gyrobench_model::measurement::Measurement;

pub use crate::fsutil::{sha256_file, sha256_text};

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
            return std::ops::ControlFlow::Break(crate::runlog::Stop::Enough);
        }
        std::ops::ControlFlow::Continue(())
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
    /// A batch's slots, in the order of `result`'s units (empty: one unit,
    /// its slot as begun).
    pub slots: Vec<String>,
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

/// A run part's units, each `running` with the coefficients it uses (a
/// log of one unit written before batches: that unit, with fitted ones);
/// `unit` is the id of the run's first unit.
fn insert_run_units(
    sql: &mut dyn Sql,
    key: &str,
    meta: &RunMeta,
    unit: i64,
) -> Result<(), StoreError> {
    let fallback = [crate::runlog::meta::RunUnit {
        slot: String::new(),
        serial: meta.dut_serial.clone(),
        dut_type: meta.dut_type.clone(),
        coefficients: crate::coeffs::CoeffsUsed::fitted(),
        mount: None,
        twin_toml: None,
        seed: None,
    }];
    let units = if meta.units.is_empty() {
        &fallback[..]
    } else {
        &meta.units[..]
    };
    for u in units {
        let id = if u.serial == meta.dut_serial && u.dut_type == meta.dut_type {
            unit
        } else {
            unit_id(sql, &u.dut_type, &u.serial)?
        };
        let mut cols: Vec<Column> = vec![
            ("run", key.into()),
            ("slot", u.slot.clone().into()),
            ("unit_id", id.into()),
            ("outcome", "running".into()),
        ];
        cols.extend(facts::coefficients(&u.coefficients));
        insert(sql, "run_units", cols)?;
    }
    Ok(())
}

/// `INSERT INTO table` of `cols`.
fn insert(sql: &mut dyn Sql, table: &str, cols: Vec<Column>) -> Result<u64, StoreError> {
    let (names, values): (Vec<&str>, Vec<Value>) = cols.into_iter().unzip();
    let marks: Vec<String> = (1..=values.len()).map(|i| format!("${i}")).collect();
    sql.execute(
        &format!(
            "INSERT INTO {table} ({}) VALUES ({})",
            names.join(", "),
            marks.join(", ")
        ),
        &values,
    )
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
        .and_then(|r| r.int("id"))
        .ok_or_else(|| StoreError::NotFound {
            store: String::new(),
            what: format!("unit {dut_type} {serial} just written"),
        })
}

fn outcome_of(sql: &mut dyn Sql, id: &str) -> Result<Option<String>, StoreError> {
    Ok(sql
        .query("SELECT outcome FROM runs WHERE id = $1", &[id.into()])?
        .first()
        .map(|r| r.text("outcome")))
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
            let mut cols = facts::begun(meta, &key, &run);
            cols.extend([
                ("latest", 1.into()),
                ("unit_id", unit.into()),
                ("outcome", "running".into()),
                ("log_path", log_path.into()),
                ("recorded_utc", now.into()),
            ]);
            insert(sql, "runs", cols)?;
            insert_run_units(sql, &key, meta, unit)
        })?;
        Ok(key)
    }

    /// Record how a part ended: its outcome (`reference` for an imported
    /// run, which is never judged), figures, link, bench state, log
    /// checksum, and every measurement of the run so far.
    pub fn finish_part(
        &mut self,
        key: &str,
        log: &Path,
        end: &PartEnd<'_>,
    ) -> Result<(), StoreError> {
        let sha = sha256_file(log).ok();
        let r = end.result;
        let store = self.name.clone();
        let mut cols = facts::ended(r, Some(&end.link), Some(&end.ended_utc));
        cols.push(("log_sha256", sha.into()));
        let (names, mut values): (Vec<&str>, Vec<Value>) = cols.into_iter().unzip();
        let set: Vec<String> = names
            .iter()
            .enumerate()
            .map(|(i, n)| format!("{n} = ${}", i + 2))
            .collect();
        values.insert(0, key.into());
        transaction(self.sql(), |sql| {
            let n = sql.execute(
                &format!(
                    "UPDATE runs SET {} WHERE id = $1 AND outcome = 'running'",
                    set.join(", ")
                ),
                &values,
            )?;
            if n != 1 {
                return Err(StoreError::NotFound {
                    store,
                    what: format!(
                        "no running part {key} to complete (it ended already, or never started here)"
                    ),
                });
            }
            // A run recorded elsewhere and imported is for reference: its
            // figures were judged at our limits, never by its own bench.
            sql.execute(
                "UPDATE runs SET outcome = 'reference' WHERE id = $1 AND imported_from IS NOT NULL",
                &[key.into()],
            )?;
            sql.execute(
                "UPDATE run_units SET outcome = (SELECT outcome FROM runs WHERE id = $1) WHERE run = $1",
                &[key.into()],
            )?;
            // A batch: each unit its own outcome (an imported run's stay
            // `reference`), and its measurements under its slot.
            let units: Vec<(String, RunResult)> = match end.slots.len() {
                0 | 1 => vec![(end.slots.first().cloned().unwrap_or_default(), r.unit(0))],
                _ => end
                    .slots
                    .iter()
                    .cloned()
                    .zip((0..r.units()).map(|k| r.unit(k)))
                    .collect(),
            };
            if units.len() > 1 {
                for (slot, u) in &units {
                    sql.execute(
                        "UPDATE run_units SET outcome = $3 WHERE run = $1 AND slot = $2 AND outcome <> 'reference'",
                        &[key.into(), slot.clone().into(), u.outcome.as_str().into()],
                    )?;
                }
            }
            let all: Vec<(&str, &Measurement)> = units
                .iter()
                .flat_map(|(slot, u)| u.measurements.iter().map(move |m| (slot.as_str(), m)))
                .collect();
            insert_measurements(sql, key, &all)
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
        // A part the store has complete is known by its key alone, read
        // from the log's first metadata: no replay.
        if let Some(key) = part_key_of_log(log)
            && outcome_of(self.sql(), &key)?.is_some_and(|o| o != "running")
        {
            return Ok(Indexed::AlreadyThere);
        }
        let r = facts::replay_all(log).map_err(|e| bad(e.to_string()))?;
        let slots = r.meta.units.iter().map(|u| u.slot.clone()).collect();
        let key = part_key(&r.meta, log)?;
        let before = outcome_of(self.sql(), &key)?;
        if before.as_deref().is_some_and(|o| o != "running") {
            return Ok(Indexed::AlreadyThere);
        }
        if before.is_none() {
            self.begin_part(&r.meta, log)?;
        }
        // When the part ended, as its log states it (a log without its end
        // record, or of an earlier gyrobench: when the file was last
        // written).
        let ended = match &r.end_time_utc {
            Some(t) => t.clone(),
            None => std::fs::metadata(log)
                .and_then(|m| m.modified())
                .map(|t| chrono::DateTime::<chrono::Utc>::from(t).to_rfc3339())
                .unwrap_or_default(),
        };
        self.finish_part(
            &key,
            log,
            &PartEnd {
                result: &r.result,
                link: r.link,
                ended_utc: ended,
                slots,
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
    /// part indexed in order. A log whose path, size, modification time
    /// and summary are those the store noted when it last indexed it is
    /// not read again.
    pub fn sync_dir(&mut self, dir: &Path) -> Synced {
        let mut done = Synced::default();
        let known = match self.indexed_logs() {
            Ok(k) => k,
            Err(e) => {
                done.failed.push(e.to_string());
                return done;
            }
        };
        for run_dir in run_dirs(dir) {
            for (n, log) in (1..).zip(parts(&run_dir)) {
                let Ok(seen) = LogFile::of(&log) else {
                    done.failed
                        .push(format!("{}: cannot be read", log.display()));
                    continue;
                };
                if known.get(&seen.path) == Some(&seen) {
                    done.unchanged += 1;
                    continue;
                }
                if let Some(why) = not_a_part(&run_dir, &log, n) {
                    done.failed.push(why);
                    continue;
                }
                match self.index_log(&log) {
                    Ok(indexed) => {
                        if indexed == Indexed::AlreadyThere {
                            done.there += 1;
                        } else {
                            done.added += 1;
                        }
                        if let Err(e) = self.note_indexed(&seen, &log) {
                            done.failed.push(e.to_string());
                        }
                    }
                    Err(e) => done.failed.push(e.to_string()),
                }
            }
        }
        done
    }

    /// The logs a sync has indexed, by path.
    fn indexed_logs(&mut self) -> Result<std::collections::HashMap<String, LogFile>, StoreError> {
        Ok(self
            .sql()
            .query(
                "SELECT path, size, mtime_ns, summary_sha256 FROM log_files",
                &[],
            )?
            .iter()
            .filter_map(|r| {
                let f = LogFile {
                    path: r.text("path"),
                    size: r.int("size")?,
                    mtime_ns: r.int("mtime_ns")?,
                    summary_sha256: r.text("summary_sha256"),
                };
                Some((f.path.clone(), f))
            })
            .collect())
    }

    /// Note that `log`, as `seen`, is in the store.
    fn note_indexed(&mut self, seen: &LogFile, log: &Path) -> Result<(), StoreError> {
        let key = part_key_of_log(log).unwrap_or_default();
        let now = crate::clock::utc_now().to_rfc3339();
        transaction(self.sql(), |sql| {
            sql.execute(
                "DELETE FROM log_files WHERE path = $1",
                &[seen.path.clone().into()],
            )?;
            sql.execute(
                "INSERT INTO log_files (path, size, mtime_ns, summary_sha256, part_key, indexed_utc) \
                 VALUES ($1, $2, $3, $4, $5, $6)",
                &[
                    seen.path.clone().into(),
                    seen.size.into(),
                    seen.mtime_ns.into(),
                    seen.summary_sha256.clone().into(),
                    key.into(),
                    now.into(),
                ],
            )?;
            Ok(())
        })
    }

    /// Record a coefficient set `calibrate` made for its unit: the next
    /// version of that unit's sets. The set gets that version, and its text
    /// (returned: what the file must hold) is stored with its SHA-256.
    pub fn record_coefficients(
        &mut self,
        set: &mut CoefficientSet,
        rec: &SetRecord<'_>,
    ) -> Result<String, StoreError> {
        let store = self.name.clone();
        let Some(unit) = set.unit.clone() else {
            return Err(StoreError::NotFound {
                store,
                what: "a coefficient set that names no unit cannot be recorded".into(),
            });
        };
        let now = crate::clock::utc_now().to_rfc3339();
        transaction(self.sql(), |sql| {
            let unit_id = unit_id(sql, &unit.dut_type, &unit.serial)?;
            let next = sql
                .query(
                    "SELECT COALESCE(MAX(version), 0) + 1 AS next FROM coefficient_sets WHERE unit_id = $1",
                    &[unit_id.into()],
                )?
                .first()
                .and_then(|r| r.int("next"))
                .unwrap_or(1);
            let provenance = set.set.get_or_insert_with(|| crate::coeffs::SetSection {
                version: None,
                created_utc: now.clone(),
                software: crate::version::software(),
                models: Vec::new(),
                fitted_on: Vec::new(),
            });
            provenance.version = Some(next);
            let fitted_on = serde_json::to_string(&provenance.fitted_on).unwrap_or_default();
            let software = provenance.software.clone();
            let text = set.to_toml().map_err(|e| StoreError::Log {
                path: "coefficient set".into(),
                message: e.to_string(),
            })?;
            sql.execute(
                "INSERT INTO coefficient_sets (unit_id, version, created_utc, coeffs_toml, validation, \
                 held_out_drift_pp_dph, source_runs, sha256, software, fitted_on) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10)",
                &[
                    unit_id.into(),
                    next.into(),
                    now.clone().into(),
                    text.clone().into(),
                    rec.validation.into(),
                    rec.held_out_drift_pp_dph.into(),
                    serde_json::to_string(&rec.sources).unwrap_or_default().into(),
                    sha256_text(&text).into(),
                    software.into(),
                    fitted_on.into(),
                ],
            )?;
            Ok(text)
        })
    }
}

/// What the store keeps beside a coefficient set's text.
#[derive(Debug)]
pub struct SetRecord<'a> {
    /// How it was validated.
    pub validation: &'a str,
    /// Model 4's held-out drift, deg/h.
    pub held_out_drift_pp_dph: Option<f64>,
    /// The runs it came from: (part key, log path).
    pub sources: Vec<(String, String)>,
}

/// What a sync did.
#[derive(Debug, Default)]
pub struct Synced {
    /// Parts added or completed.
    pub added: usize,
    /// Parts read and found in the store already.
    pub there: usize,
    /// Logs not read: as the store last saw them.
    pub unchanged: usize,
    /// Logs that could not be indexed, with the reason.
    pub failed: Vec<String>,
}

/// A log as a sync last saw it: where, how large, when last written, and
/// a hash of its summary (the MCAP summary section and footer; the last
/// 64 KiB of a log without one).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogFile {
    /// Absolute path.
    pub path: String,
    /// Size, bytes.
    pub size: i64,
    /// Modification time, ns since the Unix epoch.
    pub mtime_ns: i64,
    /// SHA-256 of its summary.
    pub summary_sha256: String,
}

impl LogFile {
    /// How `log` looks now.
    pub fn of(log: &Path) -> std::io::Result<Self> {
        use std::io::{Read, Seek, SeekFrom};
        let path = std::path::absolute(log)?;
        let mut f = std::fs::File::open(&path)?;
        let md = f.metadata()?;
        let size = md.len();
        let mtime_ns = md
            .modified()?
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
        // The footer: opcode, length, summary start (u64 LE), summary
        // offset start, CRC, then the 8-byte magic.
        const FOOTER_AND_MAGIC: u64 = 1 + 8 + 8 + 8 + 4 + 8;
        let mut start = size.saturating_sub(64 * 1024);
        if size >= FOOTER_AND_MAGIC {
            let mut footer = [0u8; FOOTER_AND_MAGIC as usize];
            f.seek(SeekFrom::Start(size - FOOTER_AND_MAGIC))?;
            f.read_exact(&mut footer)?;
            let summary_start = u64::from_le_bytes(footer[9..17].try_into().unwrap_or_default());
            if footer[0] == 0x02 && summary_start > 0 && summary_start < size {
                start = summary_start;
            }
        }
        f.seek(SeekFrom::Start(start))?;
        let mut tail = Vec::new();
        f.take(size - start).read_to_end(&mut tail)?;
        let mut hashed = format!("{size}:").into_bytes();
        hashed.extend_from_slice(&tail);
        Ok(Self {
            path: path.display().to_string(),
            size: i64::try_from(size).unwrap_or(i64::MAX),
            mtime_ns,
            summary_sha256: crate::fsutil::sha256_bytes(&hashed),
        })
    }
}

/// The logs of a run directory in part order: `run.mcap`, `run.part2.mcap`, ...
pub fn parts(run_dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for part in 1.. {
        let log = if part == 1 {
            run_dir.join("run.mcap")
        } else {
            run_dir.join(format!("run.part{part}.mcap"))
        };
        // A regular file only: opening a FIFO put there would wait for ever.
        if !log.is_file() {
            break;
        }
        out.push(log);
    }
    out
}

/// Why `log`, found as part `n` of the run in `run_dir` (`run.partN.mcap`),
/// is not that run's part: its own metadata name another run or another
/// part (a file put there by hand or with `--force`). `None` when it is
/// the run's, and for the first part (it names the run).
pub fn not_a_part(run_dir: &Path, log: &Path, n: u32) -> Option<String> {
    if n < 2 {
        return None;
    }
    let first = run_dir.join("run.mcap");
    let first_meta = crate::runlog::meta::read_run_meta(&first).ok()?;
    let ours = run_id(&first_meta, &first).ok()?;
    let why = match crate::runlog::meta::read_run_meta(log) {
        Err(e) => format!("its run metadata cannot be read: {}", e.detail()),
        Ok(m) => {
            let theirs = run_id(&m, log).unwrap_or_default();
            if theirs == ours && m.part == n {
                return None;
            }
            format!(
                "it is part {} of run {theirs}, not part {n} of run {ours}",
                m.part
            )
        }
    };
    Some(format!(
        "{}: not indexed: {why}; move it out of the run directory {}",
        log.display(),
        run_dir.display()
    ))
}

/// Run directories at or below `dir`, sorted; a run directory's `replay`
/// directory (`replay`'s own place) is not searched.
pub fn run_dirs(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        let is_run = d.join("run.mcap").is_file();
        if is_run {
            out.push(d.clone());
        }
        if let Ok(entries) = std::fs::read_dir(&d) {
            for e in entries.filter_map(Result::ok) {
                let p = e.path();
                if e.file_type().is_ok_and(|t| t.is_dir()) && !(is_run && e.file_name() == "replay")
                {
                    stack.push(p);
                }
            }
        }
    }
    out.sort();
    out
}

/// Every measurement of a part (each with its unit's slot), numbered in
/// order, one statement per hundred.
fn insert_measurements(
    sql: &mut dyn Sql,
    key: &str,
    all: &[(&str, &Measurement)],
) -> Result<(), StoreError> {
    const COLUMNS: usize = 15;
    // One statement for every measurement (a round trip each would
    // cost a lab's server more than the rest of the run's record).
    for (chunk_at, chunk) in all.chunks(100).enumerate() {
        let mut values = Vec::with_capacity(chunk.len());
        let mut params: Vec<Value> = Vec::with_capacity(COLUMNS * chunk.len());
        for (i, (slot, m)) in chunk.iter().enumerate() {
            let b = params.len();
            let marks: Vec<String> = (1..=COLUMNS).map(|c| format!("${}", b + c)).collect();
            values.push(format!("({})", marks.join(", ")));
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
                (*slot).into(),
                m.uncertainty.as_ref().map(|u| u.u).into(),
                m.uncertainty.as_ref().map(|u| u.expanded).into(),
                m.uncertainty.as_ref().map(|u| u.k).into(),
                m.guard_band.into(),
            ]);
        }
        sql.execute(
            &format!(
                "INSERT INTO measurements (run, seq, name, value, unit, low, high, outcome, step, note, slot, \
                 u, expanded_u, k, guard_band) VALUES {}",
                values.join(", ")
            ),
            &params,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::sql::{Engine, migrations};
    use super::super::{Location, Store};
    use super::*;

    /// A store written by a gyrobench of schema 2 (one unit per run, no
    /// run-unit relation, an imported run stored as a pass) opens in this
    /// one with its runs whole, each with its unit, the import a reference.
    #[test]
    fn a_store_of_schema_2_is_migrated_with_its_runs_and_units() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("old.sqlite");
        {
            let mut sql = super::super::sqlite::Sqlite::open(&path).expect("sqlite");
            for (v, _, text) in &migrations(Engine::Sqlite)[..2] {
                assert!(*v <= 2);
                sql.batch(text).expect("old migration");
            }
            sql.batch(
                "CREATE TABLE gyrobench_schema (version BIGINT NOT NULL);
                 INSERT INTO gyrobench_schema (version) VALUES (2);
                 INSERT INTO units (id, dut_type, serial) VALUES (1, 'RL-16', 'RL16-0042'), (2, 'gyro', 'LAB-7');
                 INSERT INTO runs (id, run_id, part, latest, unit_id, procedure_name, procedure_sha256,
                   procedure_path, bench, station, operator, software_version, run_started_utc, started_utc,
                   outcome, log_path, recorded_utc, imported_from)
                 VALUES ('r1.1', 'r1', 1, 1, 1, 'acceptance', 'x', 'p', 'embedded', 'pc', '', '0.1.0',
                   '2026-11-01T00:00:00Z', '2026-11-01T00:00:00Z', 'pass', '/l/r1.mcap', 'now', NULL),
                        ('r2.1', 'r2', 1, 1, 2, 'imported', 'x', 'p', 'imported', 'pc', '', '0.1.0',
                   '2026-11-02T00:00:00Z', '2026-11-02T00:00:00Z', 'pass', '/l/r2.mcap', 'now', 'lab.csv');
                 INSERT INTO measurements (run, seq, name, value, unit, low, high, outcome, step, note)
                 VALUES ('r1.1', 0, 'compensated_drift_pp_dph', 0.03, 'deg/h', NULL, 0.05, 'pass', 'main.3', ''),
                        ('r2.1', 0, 'compensated_drift_pp_dph', 0.04, 'deg/h', NULL, 0.05, 'pass', 'main.1', '');",
            )
            .expect("an old store's rows");
        }
        let mut store = Store::open(&Location::Sqlite(path))
            .expect("migrates")
            .expect("a store");
        let rows = store.list(&Default::default()).expect("list");
        let outcome = |id: &str| {
            rows.iter()
                .find(|r| r.id == id)
                .map(|r| (r.serial.clone(), r.outcome))
        };
        assert_eq!(
            outcome("r1.1"),
            Some(("RL16-0042".into(), crate::results::RunState::Pass))
        );
        assert_eq!(
            outcome("r2.1"),
            Some(("LAB-7".into(), crate::results::RunState::Reference))
        );
        let h = store.unit("RL16-0042").expect("history");
        assert_eq!(h.measurements.len(), 1, "measurements keep their unit");
        // Schema 7 classes the old parts' benches from what they kept.
        let mut kind = |k| {
            let f = super::super::query::Filter {
                bench_kind: Some(k),
                include_reference: true,
                ..Default::default()
            };
            let rows = store.list(&f).expect("list");
            rows.into_iter().map(|r| r.id).collect::<Vec<_>>()
        };
        use super::super::facts::BenchKind;
        assert_eq!(kind(BenchKind::Embedded), ["r1.1"]);
        assert_eq!(kind(BenchKind::Imported), ["r2.1"]);
        assert!(kind(BenchKind::Hardware).is_empty());
        let t = store
            .trend("compensated_drift_pp_dph", &Default::default(), 0)
            .expect("trend");
        assert_eq!(t.judged, 1, "the reference is left out");
    }
}
