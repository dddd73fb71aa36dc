//! How runs and measurements end, in the words the report, the log, the
//! store and the station all use: a measurement's verdict
//! ([`MeasureOutcome`]), a run's ([`Outcome`]), the failure that ended it
//! ([`RunError`]), the state it left the bench in ([`BenchLeft`]), and
//! where a stored run stands ([`RunState`]: a run's outcome, or still
//! running, or an imported reference).

use serde::{Deserialize, Serialize};

use crate::procedure::rule::Statement;

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Every measurement passed by the procedure's decision rule.
    Pass,
    /// A measurement outside its limits (or, guarded, inside its guard
    /// band).
    Fail,
    /// A device or data failure ended the run.
    Error,
    /// The operator interrupted the run.
    Aborted,
    /// Non-binary rule: none failed, and at least one passed only
    /// conditionally (within its limits by less than its uncertainty).
    ConditionalPass,
    /// Non-binary rule: none failed outright, and at least one failed
    /// conditionally (beyond its limits by less than its uncertainty).
    ConditionalFail,
}

impl Outcome {
    /// Every outcome.
    pub const ALL: [Self; 6] = [
        Self::Pass,
        Self::Fail,
        Self::Error,
        Self::Aborted,
        Self::ConditionalPass,
        Self::ConditionalFail,
    ];

    /// `pass`, `fail`, `error`, `aborted`, `conditional_pass` or
    /// `conditional_fail`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Pass => "pass",
            Self::Fail => "fail",
            Self::Error => "error",
            Self::Aborted => "aborted",
            Self::ConditionalPass => "conditional_pass",
            Self::ConditionalFail => "conditional_fail",
        }
    }

    /// The outcome named by [`Outcome::as_str`].
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|o| o.as_str() == s)
    }

    /// A verdict a run that went to its end gives (not an error or an
    /// abort).
    pub fn is_verdict(self) -> bool {
        !matches!(self, Self::Error | Self::Aborted)
    }
}

/// Verdict of one measurement (`pass`, `fail`, `error` in the report,
/// the log's `result` record, the store and the station).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeasureOutcome {
    /// Within limits, as the decision rule judges.
    Pass,
    /// Outside limits, or not computable.
    Fail,
    /// Not judged: the data it would be computed on are unsound (a link
    /// that lost frames, a stuck or saturated output).
    Error,
    /// Within its limits but within its expanded uncertainty of one (the
    /// non-binary rule's conditional pass).
    ConditionalPass,
    /// Outside its limits but within its expanded uncertainty of one (the
    /// non-binary rule's conditional fail).
    ConditionalFail,
}

impl MeasureOutcome {
    /// Every outcome.
    pub const ALL: [Self; 5] = [
        Self::Pass,
        Self::Fail,
        Self::Error,
        Self::ConditionalPass,
        Self::ConditionalFail,
    ];

    /// `pass`, `fail`, `error`, `conditional_pass` or `conditional_fail`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Pass => "pass",
            Self::Fail => "fail",
            Self::Error => "error",
            Self::ConditionalPass => "conditional_pass",
            Self::ConditionalFail => "conditional_fail",
        }
    }

    /// In the report's capitals (`PASS`, `COND. PASS`, ...).
    pub fn word(self) -> &'static str {
        match self {
            Self::Pass => "PASS",
            Self::Fail => "FAIL",
            Self::Error => "ERROR",
            Self::ConditionalPass => "COND. PASS",
            Self::ConditionalFail => "COND. FAIL",
        }
    }

    /// The outcome a word names.
    pub fn parse(word: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|o| o.as_str() == word)
    }

    /// The statement of a decision rule as a measurement's outcome.
    pub fn of(s: Statement) -> Self {
        match s {
            Statement::Pass => Self::Pass,
            Statement::ConditionalPass => Self::ConditionalPass,
            Statement::ConditionalFail => Self::ConditionalFail,
            Statement::Fail => Self::Fail,
        }
    }
}

/// Where a stored run part stands: running, ended with the run's outcome,
/// or an imported run kept as a reference (never judged). Serialised, and
/// stored, with the words the store has always held.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunState {
    /// Begun, not (yet) ended: a run going on, or one killed before its end.
    Running,
    /// Every measurement within its limits.
    Pass,
    /// A measurement outside its limits.
    Fail,
    /// A device or data failure ended it.
    Error,
    /// The operator interrupted it.
    Aborted,
    /// An imported run: another bench's data, kept for comparison.
    Reference,
    /// Non-binary rule: passed conditionally.
    ConditionalPass,
    /// Non-binary rule: failed conditionally.
    ConditionalFail,
}

impl RunState {
    /// Every state, in the order the help lists them.
    pub const ALL: [Self; 8] = [
        Self::Running,
        Self::Pass,
        Self::Fail,
        Self::Error,
        Self::Aborted,
        Self::Reference,
        Self::ConditionalPass,
        Self::ConditionalFail,
    ];

    /// The store's word.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Running => "running",
            Self::Pass => "pass",
            Self::Fail => "fail",
            Self::Error => "error",
            Self::Aborted => "aborted",
            Self::Reference => "reference",
            Self::ConditionalPass => "conditional_pass",
            Self::ConditionalFail => "conditional_fail",
        }
    }

    /// The state a word names.
    pub fn parse(word: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.as_str() == word)
    }

    /// A run that ended so.
    pub fn ended(o: Outcome) -> Self {
        match o {
            Outcome::Pass => Self::Pass,
            Outcome::Fail => Self::Fail,
            Outcome::Error => Self::Error,
            Outcome::Aborted => Self::Aborted,
            Outcome::ConditionalPass => Self::ConditionalPass,
            Outcome::ConditionalFail => Self::ConditionalFail,
        }
    }

    /// True for a run judged PASS or FAIL (conditionally or not).
    pub fn judged(self) -> bool {
        matches!(
            self,
            Self::Pass | Self::Fail | Self::ConditionalPass | Self::ConditionalFail
        )
    }
}

impl From<Outcome> for RunState {
    fn from(o: Outcome) -> Self {
        Self::ended(o)
    }
}

/// The failure that ended a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunError {
    /// Device at fault, if any.
    pub device: Option<String>,
    /// Step key where it happened.
    pub step: String,
    /// What happened.
    pub message: String,
}

/// The state a run left the bench in, read back from the devices.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchLeft {
    /// What the end of the run asked for: `cleanup` (the procedure's
    /// cleanup steps) or `safe_state` (the bench's safe state).
    pub intended: String,
    /// Chamber mode read back (`off`, `standby`, `constant`), or `unknown`.
    pub chamber_mode: String,
    /// Chamber set point read back, degC.
    pub chamber_set_point_c: Option<f64>,
    /// Chamber air read back, degC.
    pub chamber_air_c: Option<f64>,
    /// Table angles read back (outer, inner), deg.
    pub table_deg: Option<[f64; 2]>,
    /// Both table axes at rest.
    pub table_at_rest: Option<bool>,
    /// The supply's output read back: on (none: the bench has no supply,
    /// or it could not be read).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply_on: Option<bool>,
    /// The voltage it reads, V.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply_v: Option<f64>,
    /// The current it reads, A.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply_a: Option<f64>,
    /// The state read back is the one asked for.
    pub verified: bool,
    /// In words, for the report and the operator.
    pub summary: String,
}
