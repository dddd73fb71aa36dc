//! Exports for other tools: JUnit XML (a CI server or an MES reads it: one
//! `testsuite` per run, one `testcase` per measurement, a failure with the
//! value and its limits) and CSV (one row per measurement).

use quick_xml::Writer;
use quick_xml::events::{BytesDecl, BytesText, Event};

use super::query::{MeasurementRow, RunRow};

fn num(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| format!("{v}"))
}

fn limits(m: &MeasurementRow) -> String {
    format!("{}..{}", num(m.low), num(m.high))
}

/// The runs and their measurements as JUnit XML (the common schema:
/// `testsuites` > `testsuite` > `testcase` with `failure` / `error`).
pub fn junit(runs: &[(RunRow, Vec<MeasurementRow>)]) -> std::io::Result<String> {
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
    w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))?;
    let failures = |ms: &[MeasurementRow]| ms.iter().filter(|m| m.outcome == "fail").count();
    let errors = |r: &RunRow, ms: &[MeasurementRow]| {
        ms.iter().filter(|m| m.outcome == "error").count() + usize::from(run_error(r).is_some())
    };
    let tests = |r: &RunRow, ms: &[MeasurementRow]| ms.len() + usize::from(run_error(r).is_some());
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
                        let class = format!("{}.{}", run.procedure, run.serial);
                        for m in ms {
                            let el = w.create_element("testcase").with_attributes([
                                ("name", m.name.as_str()),
                                ("classname", class.as_str()),
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
                            match m.outcome.as_str() {
                                "pass" => {
                                    el.write_empty()?;
                                }
                                outcome => {
                                    let (tag, kind) = if outcome == "error" {
                                        ("error", "not judged")
                                    } else {
                                        ("failure", "outside limits")
                                    };
                                    let message = if outcome == "error" {
                                        format!("{} not judged: {}", m.name, m.note)
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
                                            .with_attributes([
                                                ("message", message.as_str()),
                                                ("type", kind),
                                            ])
                                            .write_text_content(BytesText::new(&text))?;
                                        Ok(())
                                    })?;
                                }
                            }
                        }
                        if let Some(e) = run_error(run) {
                            w.create_element("testcase")
                                .with_attributes([("name", "run"), ("classname", class.as_str())])
                                .write_inner_content(|w| {
                                    w.create_element("error")
                                        .with_attributes([
                                            ("message", e.as_str()),
                                            ("type", run.outcome.as_str()),
                                        ])
                                        .write_text_content(BytesText::new(&e))?;
                                    Ok(())
                                })?;
                        }
                        Ok(())
                    })?;
            }
            Ok(())
        })?;
    String::from_utf8(w.into_inner()).map_err(std::io::Error::other)
}

/// What ended a run that neither passed nor failed.
fn run_error(r: &RunRow) -> Option<String> {
    match r.outcome.as_str() {
        "pass" | "fail" => None,
        other => Some(
            r.error
                .clone()
                .unwrap_or_else(|| format!("the run is {other}")),
        ),
    }
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
                &r.outcome,
                &m.name,
                &num(m.value),
                &m.unit,
                &num(m.low),
                &num(m.high),
                &m.outcome,
                &m.step,
                &m.note,
            ])?;
        }
    }
    let bytes = w.into_inner().map_err(|e| e.into_error())?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}
