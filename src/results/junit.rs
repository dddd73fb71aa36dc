//! Exports for other tools: JUnit XML (a CI server or an MES reads it: one
//! `testsuite` per run, one `testcase` per measurement, a failure with the
//! value and its limits) and CSV (one row per measurement).

use quick_xml::Writer;
use quick_xml::events::{BytesDecl, BytesText, Event};

use super::query::{MeasurementRow, RunRow};
use crate::sequencer::measure::MeasureOutcome;

fn num(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| format!("{v}"))
}

fn limits(m: &MeasurementRow) -> String {
    format!("{}..{}", num(m.low), num(m.high))
}

/// The runs and their measurements as JUnit XML (the common schema:
/// `testsuites` > `testsuite` > `testcase` with `failure` / `error`).
pub fn junit(runs: &[(RunRow, Vec<MeasurementRow>)]) -> std::io::Result<String> {
    // XML 1.0 cannot hold control characters at all: a value stored by an
    // earlier gyrobench (or an import) that has one is written escaped.
    let runs = &safe_rows(runs);
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
    w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))?;
    let total_tests: usize = runs.iter().map(|(r, ms)| tests(r, ms)).sum();
    let total_failures: usize = runs.iter().map(|(_, ms)| failures(ms)).sum();
    let total_errors: usize = runs.iter().map(|(r, ms)| errors(r, ms)).sum();
    w.create_element("testsuites")
        .with_attributes([
            ("name", "gyrobench"),
            ("tests", total_tests.to_string().as_str()),
            ("failures", total_failures.to_string().as_str()),
            ("errors", total_errors.to_string().as_str()),
        ])
        .write_inner_content(|w| {
            for (run, ms) in runs {
                write_suite(w, run, ms)?;
            }
            Ok(())
        })?;
    String::from_utf8(w.into_inner()).map_err(std::io::Error::other)
}

/// A run's failed measurements (conditional statements among them: each
/// is written as a failure of its own type).
fn failures(ms: &[MeasurementRow]) -> usize {
    ms.iter()
        .filter(|m| {
            matches!(
                m.outcome,
                MeasureOutcome::Fail
                    | MeasureOutcome::ConditionalPass
                    | MeasureOutcome::ConditionalFail
            )
        })
        .count()
}

/// A run's measurements in error, and the run itself when it ended
/// neither passed nor failed.
fn errors(r: &RunRow, ms: &[MeasurementRow]) -> usize {
    ms.iter()
        .filter(|m| m.outcome == MeasureOutcome::Error)
        .count()
        + usize::from(run_error(r).is_some())
}

/// A run's test cases: its measurements, and the run itself when it ended
/// neither passed nor failed.
fn tests(r: &RunRow, ms: &[MeasurementRow]) -> usize {
    ms.len() + usize::from(run_error(r).is_some())
}

/// One run as a `testsuite`: its properties, a `testcase` per measurement,
/// and one for the run when it ended neither passed nor failed.
fn write_suite(
    w: &mut Writer<Vec<u8>>,
    run: &RunRow,
    ms: &[MeasurementRow],
) -> std::io::Result<()> {
    let name = format!(
        "{} {} {} ({})",
        run.procedure, run.dut_type, run.serial, run.id
    );
    let time = format!("{:.3}", run.device_time_s.unwrap_or(0.0));
    w.create_element("testsuite")
        .with_attributes([
            ("name", name.as_str()),
            ("tests", tests(run, ms).to_string().as_str()),
            ("failures", failures(ms).to_string().as_str()),
            ("errors", errors(run, ms).to_string().as_str()),
            ("skipped", "0"),
            ("timestamp", timestamp(&run.started_utc).as_str()),
            ("hostname", run.station.as_str()),
            ("time", time.as_str()),
        ])
        .write_inner_content(|w| {
            write_properties(w, run)?;
            let class = format!("{}.{}", run.procedure, run.serial);
            for m in ms {
                write_testcase(w, m, &class)?;
            }
            if let Some(e) = run_error(run) {
                write_run_error(w, run, &class, &e)?;
            }
            Ok(())
        })?;
    Ok(())
}

/// The run's identity as the suite's `properties`.
fn write_properties(w: &mut Writer<Vec<u8>>, run: &RunRow) -> std::io::Result<()> {
    w.create_element("properties").write_inner_content(|w| {
        for (k, v) in [
            ("run", run.id.as_str()),
            ("serial", run.serial.as_str()),
            ("dut_type", run.dut_type.as_str()),
            ("procedure", run.procedure.as_str()),
            ("bench", run.bench.as_str()),
            ("operator", run.operator.as_str()),
            ("outcome", run.outcome.as_str()),
        ] {
            w.create_element("property")
                .with_attributes([("name", k), ("value", v)])
                .write_empty()?;
        }
        Ok(())
    })?;
    Ok(())
}

/// One measurement as a `testcase`: empty when it passed, else with a
/// `failure` (outside its limits) or an `error` (not judged).
fn write_testcase(w: &mut Writer<Vec<u8>>, m: &MeasurementRow, class: &str) -> std::io::Result<()> {
    let el = w.create_element("testcase").with_attributes([
        ("name", m.name.as_str()),
        ("classname", class),
        ("time", "0"),
    ]);
    let text = format!(
        "{} = {} {} (limits {}, step {}){}",
        m.name,
        num(m.value),
        m.unit,
        limits(m),
        m.step,
        if m.note.is_empty() {
            String::new()
        } else {
            format!("; {}", m.note)
        }
    );
    match m.outcome {
        MeasureOutcome::Pass => {
            el.write_empty()?;
        }
        outcome => {
            // A conditional statement (non-binary rule) is a failure of
            // its own type: inside or outside a limit by less than its
            // uncertainty, a verdict left for a person to decide.
            let (tag, kind) = match outcome {
                MeasureOutcome::Error => ("error", "not judged"),
                MeasureOutcome::ConditionalPass => ("failure", "conditional pass"),
                MeasureOutcome::ConditionalFail => ("failure", "conditional fail"),
                _ => ("failure", "outside limits"),
            };
            let message = if outcome == MeasureOutcome::Error {
                format!("{} not judged: {}", m.name, m.note)
            } else if matches!(
                outcome,
                MeasureOutcome::ConditionalPass | MeasureOutcome::ConditionalFail
            ) {
                format!(
                    "{} {} {} {} limits {}: within its expanded uncertainty of one (non-binary rule)",
                    m.name,
                    num(m.value),
                    m.unit,
                    if outcome == MeasureOutcome::ConditionalPass {
                        "inside"
                    } else {
                        "outside"
                    },
                    limits(m)
                )
            } else {
                format!(
                    "{} {} {} outside {}",
                    m.name,
                    num(m.value),
                    m.unit,
                    limits(m)
                )
            };
            el.write_inner_content(|w| {
                w.create_element(tag)
                    .with_attributes([("message", message.as_str()), ("type", kind)])
                    .write_text_content(BytesText::new(&text))?;
                Ok(())
            })?;
        }
    }
    Ok(())
}

/// The `testcase` of a run that ended neither passed nor failed: an
/// `error` with what ended it (`e`).
fn write_run_error(
    w: &mut Writer<Vec<u8>>,
    run: &RunRow,
    class: &str,
    e: &str,
) -> std::io::Result<()> {
    w.create_element("testcase")
        .with_attributes([("name", "run"), ("classname", class)])
        .write_inner_content(|w| {
            w.create_element("error")
                .with_attributes([("message", e), ("type", run.outcome.as_str())])
                .write_text_content(BytesText::new(e))?;
            Ok(())
        })?;
    Ok(())
}

/// Every text of the rows as XML 1.0 can hold it ([`crate::view::printable`]).
fn safe_rows(runs: &[(RunRow, Vec<MeasurementRow>)]) -> Vec<(RunRow, Vec<MeasurementRow>)> {
    let p = |s: &str| crate::view::printable(s).into_owned();
    runs.iter()
        .map(|(r, ms)| {
            let run = RunRow {
                id: p(&r.id),
                started_utc: p(&r.started_utc),
                dut_type: p(&r.dut_type),
                serial: p(&r.serial),
                procedure: p(&r.procedure),
                bench: p(&r.bench),
                station: p(&r.station),
                operator: p(&r.operator),
                error: r.error.as_deref().map(p),
                slot: p(&r.slot),
                bench_id: p(&r.bench_id),
                software: p(&r.software),
                ..r.clone()
            };
            let ms = ms
                .iter()
                .map(|m| {
                    let mut m = m.clone();
                    m.run = p(&m.run);
                    m.measurement.name = p(&m.measurement.name);
                    m.measurement.unit = p(&m.measurement.unit);
                    m.measurement.step = p(&m.measurement.step);
                    m.measurement.note = p(&m.measurement.note);
                    m
                })
                .collect();
            (run, ms)
        })
        .collect()
}

/// What ended a run that neither passed nor failed.
fn run_error(r: &RunRow) -> Option<String> {
    (!r.outcome.judged()).then(|| {
        r.error
            .clone()
            .unwrap_or_else(|| format!("the run is {}", r.outcome.as_str()))
    })
}

/// JUnit's timestamp: ISO 8601 without a zone (the common schema's form).
fn timestamp(rfc3339: &str) -> String {
    chrono::DateTime::parse_from_rfc3339(rfc3339)
        .map(|t| t.naive_utc().format("%Y-%m-%dT%H:%M:%S").to_string())
        .unwrap_or_default()
}

/// The runs and their measurements as CSV, one row per measurement.
pub fn csv(runs: &[(RunRow, Vec<MeasurementRow>)]) -> Result<String, csv::Error> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "run",
        "started_utc",
        "dut_type",
        "serial",
        "procedure",
        "bench",
        "station",
        "operator",
        "run_outcome",
        "measurement",
        "value",
        "unit",
        "low",
        "high",
        "outcome",
        "step",
        "note",
    ])?;
    for (r, ms) in runs {
        for m in ms {
            w.write_record([
                r.id.as_str(),
                &r.started_utc,
                &r.dut_type,
                &r.serial,
                &r.procedure,
                &r.bench,
                &r.station,
                &r.operator,
                r.outcome.as_str(),
                &m.name,
                &num(m.value),
                &m.unit,
                &num(m.low),
                &num(m.high),
                m.outcome.as_str(),
                &m.step,
                &m.note,
            ])?;
        }
    }
    let bytes = w.into_inner().map_err(|e| e.into_error())?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runlog::meta::ResultMeasurement;

    #[test]
    fn text_xml_cannot_hold_is_written_escaped_and_the_file_parses() {
        let run = RunRow {
            id: "r.1".into(),
            started_utc: "2026-12-03T10:00:00+00:00".into(),
            dut_type: "RL-16".into(),
            serial: "RL16\u{1b}[31m\u{202E}0042\u{7}".into(),
            procedure: "acceptance".into(),
            bench: "embedded".into(),
            station: "pc".into(),
            operator: "J.\u{0}Doe".into(),
            outcome: crate::results::RunState::Fail,
            part: 1,
            latest: true,
            device_time_s: Some(1.0),
            error: None,
            slot: String::new(),
            bench_id: "embedded".into(),
            software: "0.1.0".into(),
            calibration_overdue: None,
            coefficients: Default::default(),
        };
        let m = MeasurementRow {
            run: "r.1".into(),
            measurement: ResultMeasurement {
                name: "bias\u{1b}".into(),
                value: Some(1.0),
                unit: "deg/h".into(),
                low: None,
                high: Some(0.5),
                outcome: MeasureOutcome::Fail,
                step: "main.1".into(),
                note: "<&>".into(),
                uncertainty: None,
                guard_band: None,
            },
        };
        let xml = junit(&[(run, vec![m])]).expect("xml");
        assert!(
            !xml.chars()
                .any(|c| c.is_control() && c != '\n' && c != '\t'),
            "{xml}"
        );
        assert!(xml.contains("RL16\\u{1b}[31m\\u{202e}0042\\u{7}"), "{xml}");
        let mut reader = quick_xml::Reader::from_str(&xml);
        loop {
            match reader.read_event() {
                Ok(quick_xml::events::Event::Eof) => break,
                Ok(_) => {}
                Err(e) => panic!("not XML: {e}\n{xml}"),
            }
        }
    }
}
