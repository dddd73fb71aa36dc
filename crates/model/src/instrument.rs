//! An instrument of a run (the chamber, the table, the supply) as the
//! run's record keeps it: what it reported itself to be, and when its
//! calibration is due.

use serde::{Deserialize, Serialize};

/// An instrument of a run as the record keeps it: what it said it is and
/// when its calibration is due.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Instrument {
    /// `chamber` or `table`.
    pub role: String,
    /// Its spec in the bench file.
    pub spec: String,
    /// What it reported (none: it did not answer its identity query).
    pub identity: Option<gyrobench_protocol::Identity>,
    /// Why it reported nothing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity_error: Option<String>,
    /// Calibration due date from the bench file, `YYYY-MM-DD`.
    pub calibration_due: Option<String>,
    /// Past its due date on the day the run started.
    pub calibration_overdue: bool,
}

impl Instrument {
    /// In words: `chamber Espec SCP-220,TEMP, firmware ..., calibration due 2027-03-31`.
    pub fn describe(&self) -> String {
        let who = match (&self.identity, &self.identity_error) {
            (Some(i), _) => i.describe(),
            (None, Some(e)) => format!("identity not reported ({e})"),
            (None, None) => "identity not reported".into(),
        };
        let due = match (&self.calibration_due, self.calibration_overdue) {
            (Some(d), true) => format!(", calibration OVERDUE since {d}"),
            (Some(d), false) => format!(", calibration due {d}"),
            (None, _) => ", no calibration due date in the bench file".into(),
        };
        format!("{} {who}{due}", self.role)
    }
}
