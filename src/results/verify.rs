//! `results verify`: whether the store tells the truth about the logs. Every
//! stored part of a run is checked against its log: the log is where the
//! store says, its SHA-256 is the one stored when the part ended, and the
//! figures the store holds are the log's (its `result` record, or with
//! `replay` the figures recomputed from its frames). Logs below a runs
//! directory that the store lacks are listed too.

use std::path::Path;

use serde::Serialize;

use super::{Store, StoreError};
use crate::runlog::meta::{ResultMeasurement, ResultMeta};
use crate::sequencer::measure::MeasureOutcome;

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
    /// The store never saw the part end (its run was killed); a sync
    /// completes it from the log.
    Incomplete,
    /// The log's `result` record (or its replay) cannot be read.
    Unreadable,
    /// A log below the runs directory that the store lacks.
    NotIndexed,
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

/// How the figures are compared: a value, its outcome and its name, in
/// order.
fn key(m: &ResultMeasurement) -> (String, Option<u64>, MeasureOutcome) {
    (m.name.clone(), m.value.map(f64::to_bits), m.outcome)
}

fn first_difference(stored: &[ResultMeasurement], log: &[ResultMeasurement]) -> Option<String> {
    if stored.len() != log.len() {
        return Some(format!(
            "the store holds {} measurement(s), the log {}",
            stored.len(),
            log.len()
        ));
    }
    stored.iter().zip(log).find_map(|(a, b)| {
        (key(a) != key(b)).then(|| {
            let v = |m: &ResultMeasurement| m.value.map_or("none".to_owned(), |v| format!("{v}"));
            format!(
                "{}: the store has {} ({}), the log {} ({})",
                a.name,
                v(a),
                a.outcome.as_str(),
                v(b),
                b.outcome.as_str()
            )
        })
    })
}

/// The figures a log holds: its `result` record's (a killed run's log has
/// none: replayed), or replayed when asked.
fn log_figures(log: &Path, replay: bool) -> Result<Vec<ResultMeasurement>, String> {
    if replay {
        // A batch's units in order, each from its own view of the log.
        let units = crate::runlog::view::log_units(log).unwrap_or_default();
        let serials: Vec<Option<&str>> = if crate::runlog::view::is_batch(&units) {
            units.iter().map(|(_, s)| Some(s.as_str())).collect()
        } else {
            vec![None]
        };
        let mut all = Vec::new();
        for serial in serials {
            let r =
                crate::runlog::replay::replay_unit(log, None, serial).map_err(|e| e.to_string())?;
            all.extend(r.result.measurements.iter().map(ResultMeasurement::new));
        }
        return Ok(all);
    }
    // The run's `result`, then a batch's other units' (`result/NAME`, in
    // unit order as written).
    let mut found = None;
    let mut others: Vec<Result<ResultMeta, String>> = Vec::new();
    crate::runlog::read(log, |item| {
        if let crate::runlog::Item::Meta { name, entries } = item {
            let result = crate::runlog::schema::RESULT_META;
            if name == result {
                found = Some(ResultMeta::from_entries(entries).map_err(|e| e.to_string()));
            } else if name
                .strip_prefix(result)
                .is_some_and(|r| r.starts_with('/'))
            {
                others.push(ResultMeta::from_entries(entries).map_err(|e| e.to_string()));
            }
        }
        Ok(())
    })
    .map_err(|e| e.to_string())?;
    match found {
        Some(r) => {
            let mut all = r?.measurements;
            for o in others {
                all.extend(o?.measurements);
            }
            Ok(all)
        }
        // A killed run's log ends without one: its figures are what a
        // replay makes of it, as the sync that completed it did.
        None => log_figures(log, true),
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
        let parts = self.sql().query(
            "SELECT id, log_path, log_sha256, outcome FROM runs ORDER BY started_utc, id",
            &[],
        )?;
        let mut stored_logs = std::collections::HashSet::new();
        for row in &parts {
            let (run, log, sha, outcome) = (
                row.text("id"),
                row.text("log_path"),
                row.text("log_sha256"),
                row.text("outcome"),
            );
            stored_logs.insert(log.clone());
            if let Some(u) = &under
                && !Path::new(&log).starts_with(u)
            {
                v.elsewhere += 1;
                continue;
            }
            v.checked += 1;
            self.check_part(&mut v, &run, &log, &sha, &outcome, replay)?;
        }
        if let Some(dir) = dir {
            self.find_unindexed(&mut v, dir, &stored_logs)?;
        }
        Ok(v)
    }

    /// Check one stored part (`run`, its `log`, the `sha` stored when it
    /// ended, its `outcome`) against its log, in order: the log is there,
    /// the part ended, the log is unchanged, its figures are the stored
    /// ones. The first thing wrong becomes a finding; a part with none
    /// counts as agreeing.
    fn check_part(
        &mut self,
        v: &mut Verification,
        run: &str,
        log: &str,
        sha: &str,
        outcome: &str,
        replay: bool,
    ) -> Result<(), StoreError> {
        let mut find = |problem, detail: String| {
            v.findings.push(Finding {
                problem,
                run: Some(run.to_owned()),
                log: log.to_owned(),
                detail,
            });
        };
        let path = Path::new(log);
        if !path.is_file() {
            find(Problem::Missing, "the log is not there".into());
            return Ok(());
        }
        if outcome == "running" {
            find(
                Problem::Incomplete,
                "the store never saw this part end; `gyrobench results sync` on its directory completes it".into(),
            );
            return Ok(());
        }
        match crate::fsutil::sha256_file(path) {
            Ok(now) if now == sha => {}
            Ok(now) => {
                find(
                    Problem::Changed,
                    format!(
                        "its SHA-256 is {} now, {} when the part ended",
                        &now[..16],
                        sha.get(..16).unwrap_or("(none stored)")
                    ),
                );
                return Ok(());
            }
            Err(e) => {
                find(Problem::Unreadable, e.to_string());
                return Ok(());
            }
        }
        let stored = self.stored_figures(run)?;
        match log_figures(path, replay) {
            Ok(figures) => match first_difference(&stored, &figures) {
                Some(d) => find(Problem::FiguresDiffer, d),
                None => v.agree += 1,
            },
            Err(e) => find(Problem::Unreadable, e),
        }
        Ok(())
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
                    });
                }
            }
        }
        Ok(())
    }

    fn stored_figures(&mut self, run: &str) -> Result<Vec<ResultMeasurement>, StoreError> {
        Ok(self
            .sql()
            .query(
                "SELECT name, value, unit, low, high, outcome, step, note FROM measurements \
                 WHERE run = $1 ORDER BY seq",
                &[run.into()],
            )?
            .iter()
            .map(super::query::measurement_of)
            .collect())
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
                Problem::Incomplete => "INCOMPLETE",
                Problem::Unreadable => "UNREADABLE",
                Problem::NotIndexed => "NOT INDEXED",
            };
            s.push_str(&format!(
                "{what:<15} {} {}\n                {}\n",
                f.run.as_deref().unwrap_or("-"),
                f.log,
                f.detail
            ));
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

    fn m(name: &str, value: Option<f64>, outcome: &str) -> ResultMeasurement {
        ResultMeasurement {
            name: name.into(),
            value,
            unit: "deg/h".into(),
            low: None,
            high: Some(0.05),
            outcome: MeasureOutcome::parse(outcome).expect("a word of the three"),
            step: "main.1".into(),
            note: String::new(),
        }
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
}
