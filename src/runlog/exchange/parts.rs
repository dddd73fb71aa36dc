//! Which imported rows were records, and the steps they belong to.
//!
//! A row is recorded when the file says so (the `record` column, or an
//! import map's `step.record`), or, in a file that does not say, when its
//! step label is not the key of a gyrobench step (`main.2.steps.0`: what
//! `export` wrote for the rows outside records before it wrote the
//! `record` column). Whatever the file says, a row taken while the table
//! turned is never recorded: its 1 Hz mean mixes poses, and the Earth rate
//! of one orientation does not hold for it (a rate-table record, which
//! turns on purpose, needs the table's rate, which the CSV does not carry).
//!
//! Rows then fall into parts: stretches of one step label, recorded or
//! not. A procedure made from the CSV has one step per part (a `record`,
//! or a `wait` for rows outside records) and the acceptance's figures where
//! the data allow them; a procedure carried by the export's sidecar is
//! matched part by part, in run order.

use std::collections::BTreeMap;

use super::super::interchange::Row;
use crate::procedure::raw::{RawMeta, RawProcedure, RawStep};
use crate::procedure::{Procedure, Step, StepKind};

/// A stretch of rows with one step label, all recorded or none.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Part {
    /// The record's label (made unique for a procedure made from the
    /// CSV: a label met again gets `#2`, ...); the step label when not
    /// recorded.
    pub label: String,
    /// The rows' step label as the file gives it.
    pub step: String,
    /// Whether the rows were recorded.
    pub recorded: bool,
    /// First row.
    pub a: usize,
    /// One past the last row.
    pub b: usize,
}

/// Whether each row was taken while the table turned: its orientation
/// differs from that of the row a second before it by more than
/// [`MOVING_DEG`](crate::diagnose::data::MOVING_DEG) (a row's orientation
/// is the table's at the end of its second, so the row in which a move
/// ends is still a move; the row before a move is not).
pub(crate) fn moving(rows: &[Row]) -> Vec<bool> {
    let mut out = vec![false; rows.len()];
    for i in 1..rows.len() {
        let (a, b) = (&rows[i - 1], &rows[i]);
        if b.time_s - a.time_s <= 1.5 {
            let turned = crate::geometry::rotation_distance_deg(
                &a.orientation().rotation(),
                &b.orientation().rotation(),
            );
            out[i] = turned > crate::diagnose::data::MOVING_DEG;
        }
    }
    out
}

/// The label a run gives its last second, after its last step.
const END_OF_RUN: &str = "end of run";

/// True for a label gyrobench gives rows outside records: a step's key
/// (`setup.0`, `main.3`, `main.2.positions.0`, `main.2.steps.1`,
/// `main.5.turn`, `cleanup.0`), `end of run`, or the run's own switch-on
/// at its start ([`crate::sequencer::RUN_POWER_ON`]).
pub(crate) fn is_step_key(label: &str) -> bool {
    if label == END_OF_RUN || label == crate::sequencer::RUN_POWER_ON {
        return true;
    }
    let mut it = label.split('.');
    let group_ok = matches!(it.next(), Some("setup" | "main" | "cleanup"));
    let number =
        |s: Option<&str>| s.is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
    if !group_ok || !number(it.next()) {
        return false;
    }
    while let Some(part) = it.next() {
        match part {
            "positions" | "steps" => {
                if !number(it.next()) {
                    return false;
                }
            }
            "turn" | "record" | "rest" => {}
            _ => return false,
        }
    }
    true
}

/// The record a row belongs to, if recorded (see the module's rules).
fn record_of(row: &Row, moving: bool) -> Option<String> {
    if moving {
        return None;
    }
    match &row.record {
        Some(r) if r.is_empty() => None,
        Some(r) => Some(r.clone()),
        None if is_step_key(&row.step) => None,
        None if row.step.is_empty() => Some("unlabelled".to_owned()),
        None => Some(row.step.clone()),
    }
}

/// The rows' parts, in order; `unique` makes each record's label unique
/// (a label met again gets `#2`, ...), as a procedure made from the CSV
/// needs.
pub(crate) fn parts(rows: &[Row], unique: bool) -> Vec<Part> {
    let moving = moving(rows);
    let recs: Vec<Option<String>> = rows
        .iter()
        .zip(&moving)
        .map(|(r, m)| record_of(r, *m))
        .collect();
    let mut out: Vec<Part> = Vec::new();
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut start = 0;
    for i in 1..=rows.len() {
        if i < rows.len() && rows[i].step == rows[start].step && recs[i] == recs[start] {
            continue;
        }
        let (label, recorded) = match &recs[start] {
            Some(base) if unique => {
                let n = seen.entry(base.clone()).or_insert(0);
                *n += 1;
                let label = if *n == 1 {
                    base.clone()
                } else {
                    format!("{base}#{n}")
                };
                (label, true)
            }
            Some(base) => (base.clone(), true),
            None => (rows[start].step.clone(), false),
        };
        out.push(Part {
            label,
            step: rows[start].step.clone(),
            recorded,
            a: start,
            b: i,
        });
        start = i;
    }
    out
}

/// The procedure an imported run without a sidecar is judged by: a step
/// per part (a `record`, or a `wait` for rows outside records), then the
/// acceptance's figures where the records allow them; built as the
/// procedure's value and written as a procedure file.
pub(crate) fn procedure_text(
    name: &str,
    dut_type: &str,
    parts: &[Part],
    rows: &[Row],
) -> Result<String, toml::ser::Error> {
    let mut main: Vec<RawStep> = parts
        .iter()
        .map(|p| {
            let duration_s = (p.b - p.a) as f64;
            if p.recorded {
                RawStep::Record {
                    label: p.label.clone(),
                    duration_s,
                }
            } else {
                RawStep::Wait { duration_s }
            }
        })
        .collect();
    let measure =
        |name: &str, metric: &str, records: &[&str], averaging_s, high| RawStep::Measure {
            name: name.to_owned(),
            metric: metric.to_owned(),
            records: records.iter().map(|r| (*r).to_owned()).collect(),
            averaging_s,
            band: None,
            low: None,
            high,
            unit: "deg/h".to_owned(),
        };
    let records: Vec<&Part> = parts.iter().filter(|p| p.recorded).collect();
    let all: Vec<&str> = records.iter().map(|p| p.label.as_str()).collect();
    let recorded_rows: usize = records.iter().map(|p| p.b - p.a).sum();
    if let Some(first) = records.first()
        && rows[first.a].time_s < 60.0
        && rows[first.b - 1].time_s >= 1800.0
    {
        main.push(measure(
            "self_heating_dph",
            "self_heating",
            &[&first.label],
            None,
            Some(1.0),
        ));
    }
    if recorded_rows >= 1200 {
        main.push(measure(
            "raw_drift_pp_dph",
            "drift_pp",
            &all,
            Some(600.0),
            Some(1.0),
        ));
        main.push(measure(
            "compensated_drift_pp_dph",
            "compensated_drift_pp",
            &all,
            Some(600.0),
            Some(0.05),
        ));
        // The fit's own residual beside the judged, held-out figure:
        // informative, as the shipped thermal procedures show it.
        main.push(measure(
            "compensated_drift_fit_residual_pp_dph",
            "compensated_drift_fit_residual_pp",
            &all,
            Some(600.0),
            None,
        ));
    }
    // Bias stability where it means something: records after the warm-up
    // with the chamber steady (within 1 degC), as the acceptance's positions.
    for p in &records {
        let air = rows[p.a..p.b].iter().map(|r| r.chamber_c);
        let spread =
            air.clone().fold(f64::NEG_INFINITY, f64::max) - air.fold(f64::INFINITY, f64::min);
        if p.b - p.a >= 300 && rows[p.a].time_s >= 1800.0 && spread <= 1.0 {
            main.push(measure(
                &format!("bias_stability_dph:{}", p.label),
                "bias_stability",
                &[&p.label],
                Some(100.0),
                Some(0.05),
            ));
        }
    }
    RawProcedure {
        procedure: RawMeta {
            name: "imported".to_owned(),
            description: format!("run imported from {name}"),
            dut_type: dut_type.to_owned(),
            spec: "model-4 compensated drift 0.05 deg/h (p-p of 600 s averages); bias stability 0.05 deg/h (1-sigma of 100 s averages)".to_owned(),
            decision_rule: None,
            guard_band_u: None,
        },
        setup: Vec::new(),
        main,
        cleanup: Vec::new(),
    }
    .to_toml(&[
        &format!("Made by gyrobench import from {name}: one record per stretch of recorded rows with"),
        "one step label, a wait for rows outside records, judged with the limits of",
        "procedures/acceptance.toml.",
    ])
}

/// Whether `part`'s rows were taken in `step`: a record by its label, rows
/// outside records by the step's key (or the record step they turned in).
fn part_in(part: &Part, step: &Step) -> bool {
    match &step.kind {
        StepKind::Record { label, .. } if part.recorded => *label == part.label,
        StepKind::Record { label, .. } => *label == part.step || step.key == part.step,
        _ => !part.recorded && step.key == part.step,
    }
}

/// The step of a carried procedure (its index in run order, setup and
/// cleanup included) each part was taken in, matched in run order: a
/// part goes on in the step before it when it fits, or takes the next
/// step that fits; the steps in between took no rows (measures, notes,
/// set points). Rows outside records whose step label is no step of the
/// procedure at all (the run's last second, `end of run`) belong to no
/// step (none). A part that fits no later step is refused, naming its
/// first row's time and step.
pub(crate) fn assign(
    procedure: &Procedure,
    parts: &[Part],
    rows: &[Row],
) -> Result<Vec<Option<usize>>, String> {
    let steps: Vec<&Step> = procedure.steps().collect();
    let mut out = Vec::with_capacity(parts.len());
    let mut open: Option<usize> = None;
    let mut next = 0;
    for p in parts {
        if let Some(j) = open.filter(|j| part_in(p, steps[*j])) {
            out.push(Some(j));
            continue;
        }
        if let Some(j) = (next..steps.len()).find(|j| part_in(p, steps[*j])) {
            out.push(Some(j));
            (open, next) = (Some(j), j + 1);
            continue;
        }
        if !p.recorded && !steps.iter().any(|s| part_in(p, s)) {
            out.push(None);
            open = None;
            continue;
        }
        let after = next.checked_sub(1).map_or_else(
            || "from its start".to_owned(),
            |j| format!("after step {}", steps[j].key),
        );
        return Err(format!(
            "the rows from time_s = {} (step {:?}{}) are of no step of the procedure {after}",
            rows[p.a].time_s,
            p.step,
            if p.recorded {
                format!(", record {:?}", p.label)
            } else {
                String::new()
            },
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(t: f64, roll: f64, step: &str, record: Option<&str>) -> Row {
        Row {
            time_s: t,
            rate_dph: 12.0,
            t1_c: 20.0,
            t2_c: 20.0,
            tcase_c: 20.0,
            chamber_c: 20.0,
            azimuth_deg: 0.0,
            elevation_deg: 90.0,
            roll_deg: roll,
            step: step.into(),
            outer_deg: None,
            inner_deg: None,
            record: record.map(str::to_owned),
        }
    }

    #[test]
    fn step_keys_are_told_from_record_labels() {
        for k in [
            "setup.0",
            "main.1",
            "main.2.positions.0",
            "main.2.steps.0",
            "main.5.turn",
            "main.5.record",
            "cleanup.0",
            "main.2.steps.1.positions.3",
            "end of run",
        ] {
            assert!(is_step_key(k), "{k}");
        }
        for l in [
            "az000",
            "main",
            "main.x",
            "main.2.steps",
            "warm_up",
            "",
            "main.1.foo",
        ] {
            assert!(!is_step_key(l), "{l}");
        }
    }

    /// A move's rows, and the rows of a step that is a gyrobench key, are
    /// never a record; the row before a move still belongs to its record.
    #[test]
    fn moves_and_waits_are_not_records_and_a_record_keeps_its_last_row() {
        let mut rows = Vec::new();
        let mut t = 0.5;
        for _ in 0..5 {
            rows.push(row(t, -90.0, "main.1", None));
            t += 1.0;
        }
        for roll in [-60.0, -30.0, 0.0, 0.0, 0.0] {
            rows.push(row(t, roll, "up", None));
            t += 1.0;
        }
        for _ in 0..3 {
            rows.push(row(t, 0.0, "up", None));
            t += 1.0;
        }
        let p = parts(&rows, true);
        let got: Vec<(&str, bool, usize, usize)> = p
            .iter()
            .map(|p| (p.label.as_str(), p.recorded, p.a, p.b))
            .collect();
        assert_eq!(
            got,
            [
                ("main.1", false, 0, 5),
                ("up", false, 5, 8),
                ("up", true, 8, 13)
            ]
        );
        // The record column rules, but never over a move.
        let mut with = rows.clone();
        for r in &mut with {
            r.record = Some(if r.step == "up" {
                "up".into()
            } else {
                String::new()
            });
        }
        with[12].record = Some(String::new());
        let p = parts(&with, false);
        let got: Vec<(bool, usize, usize)> = p.iter().map(|p| (p.recorded, p.a, p.b)).collect();
        assert_eq!(
            got,
            [(false, 0, 5), (false, 5, 8), (true, 8, 12), (false, 12, 13)]
        );
    }
}
