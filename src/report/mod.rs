//! The run report: `report.json` (a contract other tools read, see
//! `docs/report.md`) and a self-contained `report.html`.

mod html;

use serde::Serialize;

use crate::procedure::Procedure;
use crate::protocol::frame::LinkStats;
use crate::sequencer::measure::Measurement;
use crate::sequencer::{Outcome, RunError, RunResult};

pub use html::render_html;

/// The unit under test.
#[derive(Debug, Clone, Serialize)]
pub struct Dut {
    /// Unit type.
    #[serde(rename = "type")]
    pub kind: String,
    /// Serial number.
    pub serial: String,
}

/// `report.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// `pass`, `fail`, `error` or `aborted`.
    pub outcome: Outcome,
    /// Procedure name.
    pub procedure: String,
    /// Unit under test.
    pub dut: Dut,
    /// Every measurement.
    pub measurements: Vec<Measurement>,
    /// What ended the run, when it did not finish.
    pub error: Option<RunError>,
    /// Whether cleanup ran to its end.
    pub cleanup_completed: bool,
    /// Spec text of the procedure.
    pub spec: String,
    /// UTC start time.
    pub start_time_utc: String,
    /// Device time covered, s.
    pub device_time_s: f64,
    /// Frames received.
    pub frames: u64,
    /// Gyro link figures.
    pub link: LinkStats,
    /// Seed of the simulated bench (none on hardware).
    pub seed: Option<u64>,
    /// Bench the run used (`embedded` or the bench file).
    pub bench: String,
    /// Software version.
    pub software_version: String,
}

impl Report {
    /// Assemble the report of a run.
    pub fn new(
        p: &Procedure,
        r: &RunResult,
        serial: &str,
        start_time_utc: &str,
        link: LinkStats,
        seed: Option<u64>,
        bench: &str,
    ) -> Self {
        Self {
            outcome: r.outcome,
            procedure: p.meta.name.clone(),
            dut: Dut {
                kind: p.meta.dut_type.clone(),
                serial: serial.to_owned(),
            },
            measurements: r.measurements.clone(),
            error: r.error.clone(),
            cleanup_completed: r.cleanup_completed,
            spec: p.meta.spec.clone(),
            start_time_utc: start_time_utc.to_owned(),
            device_time_s: r.device_time_s,
            frames: r.frames,
            link,
            seed,
            bench: bench.to_owned(),
            software_version: env!("CARGO_PKG_VERSION").to_owned(),
        }
    }

    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }

    /// A short text summary for the terminal.
    pub fn render_text(&self) -> String {
        let mut s = format!(
            "{}: {} on {} {} ({:.1} h device time, {} frames)\n",
            self.outcome_word(),
            self.procedure,
            self.dut.kind,
            self.dut.serial,
            self.device_time_s / 3600.0,
            self.frames
        );
        for m in &self.measurements {
            s.push_str(&format!(
                "  {:<32} {:>10} {:<6} [{}]  {}\n",
                m.name,
                m.value.map_or("n/a".to_owned(), |v| format!("{v:.4}")),
                m.unit,
                m.limits_text(),
                m.outcome.as_str().to_uppercase()
            ));
        }
        if let Some(e) = &self.error {
            s.push_str(&format!(
                "  stopped in step {}{}: {}\n",
                e.step,
                e.device
                    .as_ref()
                    .map_or(String::new(), |d| format!(" ({d})")),
                e.message
            ));
        }
        s
    }

    /// PASS, FAIL, ERROR or ABORTED.
    pub fn outcome_word(&self) -> &'static str {
        match self.outcome {
            Outcome::Pass => "PASS",
            Outcome::Fail => "FAIL",
            Outcome::Error => "ERROR",
            Outcome::Aborted => "ABORTED",
        }
    }
}
