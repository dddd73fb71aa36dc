//! `results verify`: whether the store tells the truth about the logs. Every
//! stored part of a run is checked against its log: the log is where the
//! store says, its SHA-256 is the one stored when the part ended, every
//! field of its record the log gives is the log's (the unit, each unit's
//! outcome and coefficients, the operator, the times, the bench, the
//! software, the procedure, the instruments: the lists of
//! [`super::facts`], the ones the store is written from), and the figures
//! the store holds are the log's (its `result` records, or with `replay`
//! the figures recomputed from its frames). Logs below a runs directory
//! that the store lacks are listed too.

use std::path::Path;

use serde::Serialize;

use super::facts::{self, Column, LogFacts};
use super::sql::{Row, Value};
use super::{Store, StoreError};
use crate::runlog::meta::ResultMeasurement;

/// What is wrong with a stored part or a log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Problem {
    /// The log is not where the store says.
    Missing,
    /// The log's SHA-256 is not the one stored.
    Changed,
    /// The stored figures are not the log's.
    FiguresDiffer,
    /// Fields of the stored record (the run's row, its units' rows) are
    /// not what the log says.
    RecordDiffers,
    /// The store never saw the part end (its run was killed); a sync
    /// completes it from the log.
    Incomplete,
    /// The log's `result` record (or its replay) cannot be read.
    Unreadable,
    /// A log below the runs directory that the store lacks.
    NotIndexed,
    /// A signed part whose log or stored figures are no longer what was
    /// signed.
    SignatureBroken,
}

/// One finding.
#[derive(Debug, Clone, Serialize)]
pub struct Finding {
    /// What is wrong.
    pub problem: Problem,
    /// The part's key (`RUN_ID.PART`), when the store has it.
    pub run: Option<String>,
    /// The log.
    pub log: String,
    /// In words.
    pub detail: String,
    /// Each field that differs (a record that differs).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub differences: Vec<Difference>,
}

/// A stored field that is not what the log says.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Difference {
    /// The field: a column of the run's row (`operator`, `outcome`), the
    /// unit it names (`serial`, `dut_type`), or a unit's (`unit.outcome`,
    /// `unit[B].coeffs_sha256` in a batch).
    pub field: String,
    /// What the store holds (null: nothing).
    pub store: serde_json::Value,
    /// What the log says (null: nothing).
    pub log: serde_json::Value,
}

/// The outcome of a verification.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Verification {
    /// Stored parts checked.
    pub checked: usize,
    /// Of them, those that agree with their logs.
    pub agree: usize,
    /// Stored parts whose logs lie outside the runs directory given (not
    /// checked: another bench's).
    pub elsewhere: usize,
    /// Logs below the runs directory.
    pub logs_found: usize,
    /// Everything wrong.
    pub findings: Vec<Finding>,
}

/// How the figures are compared: every field of each measurement (its
/// value and limits to the bit) and the unit's slot, in order.
fn same_figure(a: &(String, ResultMeasurement), b: &(String, ResultMeasurement)) -> bool {
    let bits = |v: Option<f64>| v.map(f64::to_bits);
    let ((sa, a), (sb, b)) = (a, b);
    sa == sb
        && a.name == b.name
        && bits(a.value) == bits(b.value)
        && a.outcome == b.outcome
        && a.unit == b.unit
        && bits(a.low) == bits(b.low)
        && bits(a.high) == bits(b.high)
        && a.step == b.step
        && a.note == b.note
}

/// A measurement as a finding names it.
fn figure_text((slot, m): &(String, ResultMeasurement)) -> String {
    let f = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
    format!(
        "{}{} = {} {} [{}..{}] {} (step {}, note {:?})",
        m.name,
        if slot.is_empty() {
            String::new()
        } else {
            format!(" of unit {slot}")
        },
        m.value.map_or("none".to_owned(), |v| format!("{v}")),
        m.unit,
        f(m.low),
        f(m.high),
        m.outcome.as_str(),
        m.step,
        m.note
    )
}

fn first_difference(
    stored: &[(String, ResultMeasurement)],
    log: &[(String, ResultMeasurement)],
) -> Option<String> {
    if stored.len() != log.len() {
        return Some(format!(
            "the store holds {} measurement(s), the log {}",
            stored.len(),
            log.len()
        ));
    }
    stored.iter().zip(log).find_map(|(a, b)| {
        (!same_figure(a, b)).then(|| {
            format!(
                "{}: the store has {}, the log {}",
                b.1.name,
                figure_text(a),
                figure_text(b)
            )
        })
    })
}

/// Whether a stored value is the log's: text as text, numbers to the bit
/// (an integer column and a float the same number), and a field the log
/// leaves empty the same as a null the store holds for it (a run stored
/// before the store had the column).
fn same(stored: &Value, log: &Value) -> bool {
    let blank = |v: &Value| match v {
        Value::Null => true,
        Value::Text(t) => t.is_empty() || t == "[]",
        _ => false,
    };
    match (stored, log) {
        (a, b) if blank(a) && blank(b) => true,
        (Value::Text(a), Value::Text(b)) => a == b,
        (a @ (Value::Int(_) | Value::Real(_)), b @ (Value::Int(_) | Value::Real(_))) => {
            a.real().map(f64::to_bits) == b.real().map(f64::to_bits)
        }
        _ => false,
    }
}

/// A value as a finding holds it.
fn shown(v: &Value) -> serde_json::Value {
    match v {
        Value::Null => serde_json::Value::Null,
        Value::Int(i) => (*i).into(),
        Value::Real(r) => (*r).into(),
        Value::Text(t) => t.clone().into(),
    }
}

/// The differences between the `expected` columns and the stored `row`,
/// each named `prefix` + its column.
fn differences(prefix: &str, expected: &[Column], row: &Row) -> Vec<Difference> {
    expected
        .iter()
        .filter(|(name, want)| !same(row.get(name), want))
        .map(|(name, want)| Difference {
            field: format!("{prefix}{name}"),
            store: shown(row.get(name)),
            log: shown(want),
        })
        .collect()
}

/// The `runs` columns the log gives, with the unit the row names.
fn expected_run(f: &LogFacts, key: &str, run: &str) -> Vec<Column> {
    let mut cols = facts::begun(&f.meta, key, run);
    cols.extend([
        ("dut_type", f.meta.dut_type.clone().into()),
        ("serial", f.meta.dut_serial.clone().into()),
    ]);
    cols.extend(facts::ended(
        &f.result,
        f.link.as_ref(),
        f.ended_utc.as_deref(),
    ));
    if f.meta.imported_from.is_some() {
        // An imported run is kept for reference, never judged.
        for (name, v) in &mut cols {
            if *name == "outcome" {
                *v = "reference".into();
            }
        }
    }
    cols
}

/// The differences between each unit the log names and its stored row
/// (`rows`, one per slot): the unit, its outcome (`outcome` the run's as
/// stored for one unit), the coefficients it used.
fn unit_differences(f: &LogFacts, rows: &[Row]) -> Vec<Difference> {
    let mut out = Vec::new();
    let imported = f.meta.imported_from.is_some();
    for (k, u) in f.meta.units.iter().enumerate() {
        let prefix = if u.slot.is_empty() {
            "unit.".to_owned()
        } else {
            format!("unit[{}].", u.slot)
        };
        let Some(row) = rows.iter().find(|r| r.text("slot") == u.slot) else {
            out.push(Difference {
                field: prefix.trim_end_matches('.').to_owned(),
                store: serde_json::Value::Null,
                log: format!("{} {}", u.dut_type, u.serial).into(),
            });
            continue;
        };
        let outcome = if imported {
            "reference"
        } else {
            f.result.unit(k).outcome.as_str()
        };
        let mut cols: Vec<Column> = vec![
            ("dut_type", u.dut_type.clone().into()),
            ("serial", u.serial.clone().into()),
            ("outcome", outcome.into()),
        ];
        let coeffs = facts::coefficients(&u.coefficients);
        // A run stored before the store kept coefficients (schema 3), of a
        // log that names no set: nothing to compare but the source.
        let legacy = row.get("coeffs_source") == &Value::Null && u.coefficients.sha256.is_none();
        cols.extend(
            coeffs
                .into_iter()
                .filter(|(name, _)| !(legacy && *name == "coeffs_source")),
        );
        out.extend(differences(&prefix, &cols, row));
    }
    for r in rows {
        let slot = r.text("slot");
        if !f.meta.units.iter().any(|u| u.slot == slot) {
            out.push(Difference {
                field: if slot.is_empty() {
                    "unit".into()
                } else {
                    format!("unit[{slot}]")
                },
                store: format!("{} {}", r.text("dut_type"), r.text("serial")).into(),
                log: serde_json::Value::Null,
            });
        }
    }
    out
}

/// What a stored part's log shows, read apart from the store.
enum Examined {
    /// The log is not there.
    Missing,
    /// The store never saw the part end.
    Running,
    /// The log's SHA-256 is not the stored one (what differs, said).
    Changed(String),
    /// The log cannot be read, or its record (or replay) not made.
    Unreadable(String),
    /// Its record and figures (replayed when asked).
    Read(Box<LogFacts>),
}

impl Examined {
    /// The part of `row`: its log looked at, in the order
    /// [`Store::check_part`] reports.
    fn of(row: &Row, replay: bool) -> Self {
        let log = row.text("log_path");
        let sha = row.text("log_sha256");
        let path = Path::new(&log);
        if !path.is_file() {
            return Self::Missing;
        }
        if row.text("outcome") == "running" {
            return Self::Running;
        }
        match crate::fsutil::sha256_file(path) {
            Ok(now) if now == sha => {}
            Ok(now) => {
                return Self::Changed(format!(
                    "its SHA-256 is {} now, {} when the part ended",
                    &now[..16],
                    sha.get(..16).unwrap_or("(none stored)")
                ));
            }
            Err(e) => return Self::Unreadable(e.to_string()),
        }
        match LogFacts::read(path, replay) {
            Ok(f) => Self::Read(Box::new(f)),
            Err(e) => Self::Unreadable(e.to_string()),
        }
    }
}

impl Store {
    /// Check every stored part against its log (only those whose logs lie
    /// below `dir` when given, and then also the logs there the store
    /// lacks); `replay` recomputes the figures from the frames.
    pub fn verify(&mut self, dir: Option<&Path>, replay: bool) -> Result<Verification, StoreError> {
        let mut v = Verification::default();
        let under = dir
            .map(std::path::absolute)
            .transpose()
            .map_err(|e| StoreError::Log {
                path: dir.map_or(String::new(), |d| d.display().to_string()),
                message: e.to_string(),
            })?;
        // Every column of each part, with the unit its row names.
        let parts = self.sql().query(
            "SELECT r.*, u.dut_type AS dut_type, u.serial AS serial FROM runs r \
             JOIN units u ON u.id = r.unit_id ORDER BY r.started_utc, r.id",
            &[],
        )?;
        let stored_logs: std::collections::HashSet<String> =
            parts.iter().map(|row| row.text("log_path")).collect();
        let mine: Vec<&Row> = parts
            .iter()
            .filter(|row| {
                under
                    .as_ref()
                    .is_none_or(|u| Path::new(&row.text("log_path")).starts_with(u))
            })
            .collect();
        v.elsewhere = parts.len() - mine.len();
        // The logs are read (hashed, and replayed when asked) two at a
        // time, apart from the store; then each part is checked in order.
        let examined =
            gyrobench_analysis::par::two_at_a_time(&mine, |_, row| Examined::of(row, replay));
        for (row, examined) in mine.into_iter().zip(examined) {
            v.checked += 1;
            let found = v.findings.len();
            self.check_part(&mut v, row, examined)?;
            if v.findings.len() == found {
                v.agree += 1;
            }
        }
        if let Some(dir) = dir {
            self.find_unindexed(&mut v, dir, &stored_logs)?;
        }
        Ok(v)
    }

    /// Check one stored part (its `row` of `runs`) against its log, in
    /// order: the log is there, the part ended, the log is unchanged; then
    /// its record and its figures are the log's (`examined`: what its log
    /// showed). Each thing wrong becomes a finding.
    fn check_part(
        &mut self,
        v: &mut Verification,
        row: &Row,
        examined: Examined,
    ) -> Result<(), StoreError> {
        let run = row.text("id");
        let log = row.text("log_path");
        for why in self.broken_signatures(&run)? {
            v.findings.push(Finding {
                problem: Problem::SignatureBroken,
                run: Some(run.clone()),
                log: log.clone(),
                detail: why,
                differences: Vec::new(),
            });
        }
        let mut find = |problem, detail: String, differences: Vec<Difference>| {
            v.findings.push(Finding {
                problem,
                run: Some(run.clone()),
                log: log.clone(),
                detail,
                differences,
            });
        };
        let path = Path::new(&log);
        let facts = match examined {
            Examined::Read(facts) => *facts,
            Examined::Missing => {
                find(Problem::Missing, "the log is not there".into(), Vec::new());
                return Ok(());
            }
            Examined::Running => {
                find(
                    Problem::Incomplete,
                    "the store never saw this part end; `gyrobench results sync` on its directory completes it".into(),
                    Vec::new(),
                );
                return Ok(());
            }
            Examined::Changed(detail) => {
                find(Problem::Changed, detail, Vec::new());
                return Ok(());
            }
            Examined::Unreadable(detail) => {
                find(Problem::Unreadable, detail, Vec::new());
                return Ok(());
            }
        };
        let diffs = self.record_differences(row, &facts, path)?;
        if !diffs.is_empty() {
            let fields: Vec<&str> = diffs.iter().map(|d| d.field.as_str()).collect();
            find(
                Problem::RecordDiffers,
                format!(
                    "{} field(s) of the stored record are not the log's: {}",
                    diffs.len(),
                    fields.join(", ")
                ),
                diffs,
            );
        }
        let stored = self.stored_figures(&run)?;
        if let Some(d) = first_difference(&stored, &facts.figures) {
            find(Problem::FiguresDiffer, d, Vec::new());
        }
        Ok(())
    }

    /// Every field of the part's stored record (its `row` of `runs`, its
    /// units' rows) that is not what its log's `facts` say.
    fn record_differences(
        &mut self,
        row: &Row,
        facts: &LogFacts,
        log: &Path,
    ) -> Result<Vec<Difference>, StoreError> {
        let key = super::record::part_key(&facts.meta, log)?;
        let run = key.rsplit_once('.').map_or(key.as_str(), |(r, _)| r);
        let mut out = differences("", &expected_run(facts, &key, run), row);
        let units = self.sql().query(
            "SELECT ru.*, u.dut_type AS dut_type, u.serial AS serial FROM run_units ru \
             JOIN units u ON u.id = ru.unit_id WHERE ru.run = $1 ORDER BY ru.slot",
            &[row.get("id").clone()],
        )?;
        out.extend(unit_differences(facts, &units));
        Ok(out)
    }

    /// Count the logs below `dir` and list those the store lacks: neither
    /// among the `stored_logs` nor, stored under another path, known by
    /// their part's key.
    fn find_unindexed(
        &mut self,
        v: &mut Verification,
        dir: &Path,
        stored_logs: &std::collections::HashSet<String>,
    ) -> Result<(), StoreError> {
        for run_dir in super::record::run_dirs(dir) {
            for (n, log) in (1..).zip(super::record::parts(&run_dir)) {
                let abs = std::path::absolute(&log).unwrap_or_else(|_| log.clone());
                if stored_logs.contains(&abs.display().to_string()) {
                    v.logs_found += 1;
                    continue;
                }
                // Not a part of the run it lies with: sync refuses it too.
                if super::record::not_a_part(&run_dir, &log, n).is_some() {
                    continue;
                }
                v.logs_found += 1;
                // Stored under another path (a directory moved, a
                // copy): known by its key.
                let known = match super::record::part_key_of_log(&log) {
                    Some(k) => !self
                        .sql()
                        .query("SELECT id FROM runs WHERE id = $1", &[k.into()])?
                        .is_empty(),
                    None => false,
                };
                if !known {
                    v.findings.push(Finding {
                        problem: Problem::NotIndexed,
                        run: None,
                        log: abs.display().to_string(),
                        detail: "the store has no record of this log; `gyrobench results sync` indexes it".into(),
                        differences: Vec::new(),
                    });
                }
            }
        }
        Ok(())
    }

    /// The part's stored figures, each with its unit's slot, in order.
    fn stored_figures(
        &mut self,
        run: &str,
    ) -> Result<Vec<(String, ResultMeasurement)>, StoreError> {
        Ok(self
            .sql()
            .query(
                "SELECT name, value, unit, low, high, outcome, step, note, u, expanded_u, k, guard_band, slot FROM measurements \
                 WHERE run = $1 ORDER BY seq",
                &[run.into()],
            )?
            .iter()
            .map(|r| (r.text("slot"), super::query::measurement_of(r)))
            .collect())
    }
}

/// A value for the terminal: `none`, a number, or text quoted with what a
/// terminal would obey shown as text; a long one (the instruments' JSON)
/// cut to its start.
fn clipped(v: &serde_json::Value) -> String {
    const MAX: usize = 160;
    let v = match v {
        serde_json::Value::Null => return "none".into(),
        v => v.to_string(),
    };
    let v = crate::view::printable(&v);
    match v.char_indices().nth(MAX) {
        Some((at, _)) => format!("{}... ({} characters)", &v[..at], v.chars().count()),
        None => v.into_owned(),
    }
}

impl Verification {
    /// True when the store and the logs agree everywhere checked.
    pub fn clean(&self) -> bool {
        self.findings.is_empty()
    }

    /// A report for the terminal.
    pub fn render_text(&self) -> String {
        let mut s = String::new();
        for f in &self.findings {
            let what = match f.problem {
                Problem::Missing => "MISSING",
                Problem::Changed => "CHANGED",
                Problem::FiguresDiffer => "FIGURES DIFFER",
                Problem::RecordDiffers => "RECORD DIFFERS",
                Problem::Incomplete => "INCOMPLETE",
                Problem::Unreadable => "UNREADABLE",
                Problem::NotIndexed => "NOT INDEXED",
                Problem::SignatureBroken => "SIGNATURE BROKEN",
            };
            s.push_str(&format!(
                "{what:<15} {} {}\n                {}\n",
                f.run.as_deref().unwrap_or("-"),
                f.log,
                f.detail
            ));
            for d in &f.differences {
                s.push_str(&format!(
                    "                  {}: the store has {}, the log {}\n",
                    d.field,
                    clipped(&d.store),
                    clipped(&d.log)
                ));
            }
        }
        s.push_str(&format!(
            "{} stored part(s) checked, {} agree with their logs, {} finding(s){}{}\n",
            self.checked,
            self.agree,
            self.findings.len(),
            if self.elsewhere > 0 {
                format!(
                    "; {} part(s) with logs outside the directory not checked",
                    self.elsewhere
                )
            } else {
                String::new()
            },
            if self.logs_found > 0 {
                format!("; {} log(s) in the directory", self.logs_found)
            } else {
                String::new()
            }
        ));
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sequencer::measure::MeasureOutcome;

    fn m(name: &str, value: Option<f64>, outcome: &str) -> (String, ResultMeasurement) {
        (
            String::new(),
            ResultMeasurement {
                name: name.into(),
                value,
                unit: "deg/h".into(),
                low: None,
                high: Some(0.05),
                outcome: MeasureOutcome::parse(outcome).expect("a word of the three"),
                step: "main.1".into(),
                note: String::new(),
                uncertainty: None,
                guard_band: None,
            },
        )
    }

    #[test]
    fn figures_differ_to_the_bit_in_value_or_outcome_or_count() {
        let log = [m("a", Some(0.03), "pass"), m("b", None, "error")];
        assert_eq!(first_difference(&log, &log), None);
        let nudged = [
            m("a", Some(0.03 + 1e-17_f64.max(f64::EPSILON)), "pass"),
            m("b", None, "error"),
        ];
        let d = first_difference(&nudged, &log).expect("a value a bit off");
        assert!(d.starts_with("a: the store has"), "{d}");
        let judged = [m("a", Some(0.03), "fail"), m("b", None, "error")];
        assert!(first_difference(&judged, &log).is_some());
        assert!(
            first_difference(&log[..1], &log)
                .is_some_and(|d| d.contains("1 measurement(s), the log 2"))
        );
    }

    #[test]
    fn a_figures_limits_step_note_and_unit_are_compared_too() {
        let log = [m("a", Some(0.03), "pass")];
        let edits: [fn(&mut (String, ResultMeasurement)); 5] = [
            |x| x.1.high = Some(0.5),
            |x| x.1.low = Some(-1.0),
            |x| x.1.step = "main.2".into(),
            |x| x.1.note = "model 4 with set 9".into(),
            |x| x.0 = "B".into(),
        ];
        for edit in edits {
            let mut stored = log.clone();
            edit(&mut stored[0]);
            let d = first_difference(&stored, &log).expect("an edited figure differs");
            assert!(d.starts_with("a: the store has a"), "{d}");
        }
    }

    #[test]
    fn a_stored_value_is_the_logs_as_text_or_to_the_bit_and_blank_is_blank() {
        assert!(same(&Value::Text("ana".into()), &"ana".into()));
        assert!(!same(&Value::Text("bob".into()), &"ana".into()));
        assert!(same(&Value::Real(40620.0), &Value::Int(40620)));
        assert!(!same(&Value::Real(0.1 + 0.2), &Value::Real(0.3)));
        // A column the store did not have when it stored the run.
        assert!(same(&Value::Null, &"".into()) && same(&Value::Null, &"[]".into()));
        assert!(!same(&Value::Null, &"ana".into()), "a value nulled out");
        assert!(!same(&Value::Text("1".into()), &Value::Int(1)));
    }
}
