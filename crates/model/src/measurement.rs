//! One measurement as a run's report gives it: the figure a `measure`
//! step computed, its limits, its verdict and how that verdict was
//! reached (uncertainty, guard band, margin). The sequencer computes it,
//! the report, the log's `result` record, the results store and the
//! station read it.

use gyrobench_analysis::figures::DriftTrace;
use gyrobench_analysis::uncertainty::Uncertainty;
use serde::Serialize;

use crate::outcome::MeasureOutcome;
use crate::procedure::Metric;

/// One measurement as the report gives it (`report.json` contract:
/// `name`, `value`, `unit`, `low`, `high`, `outcome`, `step`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Measurement {
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
    /// Verdict.
    pub outcome: MeasureOutcome,
    /// Step key in the procedure.
    pub step: String,
    /// Figure computed.
    pub metric: Metric,
    /// Averaging time, s.
    pub averaging_s: f64,
    /// Records it was computed on.
    pub records: Vec<String>,
    /// How the value was obtained (compensation source, why it is missing).
    pub note: String,
    /// One standard error of the value, where the figure has one (the
    /// rate-table figures).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std_error: Option<f64>,
    /// Its uncertainty: `{u, U, k, dof, budget}` (`docs/figures.md` gives
    /// each figure's budget), or null beside `uncertainty_reason`.
    pub uncertainty: Option<Uncertainty>,
    /// Why it has no uncertainty.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_reason: Option<String>,
    /// The guard band the decision rule moved the limits by, in the
    /// figure's unit (none: simple acceptance, no limits, or no
    /// uncertainty).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub guard_band: Option<f64>,
    /// Distance to the nearer limit, in the figure's unit (negative
    /// outside it; none without limits).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub margin: Option<f64>,
    /// The margin in expanded uncertainties.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub margin_u: Option<f64>,
    /// For a compensated drift: what a perfectly compensated unit with the
    /// run's own noise would read (`docs/figures.md`), deg/h.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_floor: Option<f64>,
    /// For a drift: the smoothed series its peak-to-peak was taken on (for
    /// the report's charts; not part of `report.json`).
    #[serde(skip)]
    pub trace: Option<DriftTrace>,
    /// For a warm-up time: its band (for the report's chart; the
    /// procedure in the log holds it).
    #[serde(skip)]
    pub band: Option<f64>,
}

impl Measurement {
    /// `low..high` as text.
    pub fn limits_text(&self) -> String {
        let f = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
        format!("{}..{}", f(self.low), f(self.high))
    }
}
