//! The decision rule a procedure judges its figures by (ISO/IEC 17025
//! 7.1.3 and 7.8.6; ILAC G8:2019): how a value and its expanded
//! uncertainty `U` become a statement of conformity against a limit.
//!
//! - `simple`: a value within the limits passes (the false-accept risk
//!   reaches 50 % at a limit);
//! - `guarded` (the default): the acceptance limit is the tolerance limit
//!   moved inward by the guard band `w = guard_band_u x U`; a value inside
//!   it passes, any other fails (with `w = U` at k = 2, the specific
//!   false-accept risk at the acceptance limit is about 2.5 %);
//! - `non_binary`: pass when the whole interval `value +- U` lies within
//!   the limits, fail when it lies wholly outside, and conditional pass or
//!   conditional fail when the interval straddles a limit (the value
//!   inside or outside it).
//!
//! A figure whose uncertainty could not be formed has no guard band: every
//! rule judges it by simple acceptance, and its note says so.

use serde::{Deserialize, Serialize};

/// How a procedure judges its figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "rule", rename_all = "snake_case")]
pub enum DecisionRule {
    /// The value against the limits alone.
    Simple,
    /// The limits moved inward by `w = guard_band_u x U`.
    Guarded {
        /// The guard band as a multiple of the expanded uncertainty.
        guard_band_u: f64,
    },
    /// Pass, conditional pass, conditional fail, fail, by where `value +-
    /// U` lies.
    NonBinary,
}

impl Default for DecisionRule {
    /// Guarded acceptance with `w = U`: what an accredited lab chooses for
    /// an acceptance (a unit is accepted only when its figure is shown
    /// inside its limit at 95 % coverage; ILAC G8 4.2.2; `docs/figures.md`).
    fn default() -> Self {
        Self::Guarded { guard_band_u: 1.0 }
    }
}

/// How one figure was judged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Statement {
    /// Conforms.
    Pass,
    /// Within the limits, but within `U` of one (non-binary rule).
    ConditionalPass,
    /// Outside the limits, but within `U` of one (non-binary rule).
    ConditionalFail,
    /// Does not conform.
    Fail,
}

/// What is wrong with a procedure's `decision_rule` and `guard_band_u`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RuleError {
    /// No rule of that name.
    #[error("unknown decision rule {0:?}; expected \"simple\", \"guarded\" or \"non_binary\"")]
    Unknown(String),
    /// A guard band given with a rule that has none.
    #[error("guard_band_u goes with decision_rule = \"guarded\", not {0:?}")]
    BandWithout(&'static str),
    /// A guard band out of range.
    #[error("guard_band_u = {0}: expected a multiple of U from 0 to 10 (1 is usual)")]
    Band(f64),
}

impl DecisionRule {
    /// `simple`, `guarded` or `non_binary`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Simple => "simple",
            Self::Guarded { .. } => "guarded",
            Self::NonBinary => "non_binary",
        }
    }

    /// The rule from a procedure's `decision_rule` and `guard_band_u`;
    /// what is wrong with them otherwise.
    pub fn parse(rule: &str, guard_band_u: Option<f64>) -> Result<Self, RuleError> {
        let band = |name: &'static str| match guard_band_u {
            Some(_) => Err(RuleError::BandWithout(name)),
            None => Ok(()),
        };
        match rule {
            "simple" => band("simple").map(|()| Self::Simple),
            "non_binary" => band("non_binary").map(|()| Self::NonBinary),
            "guarded" => {
                let w = guard_band_u.unwrap_or(1.0);
                if !(w.is_finite() && (0.0..=10.0).contains(&w)) {
                    return Err(RuleError::Band(w));
                }
                Ok(Self::Guarded { guard_band_u: w })
            }
            other => Err(RuleError::Unknown(other.to_owned())),
        }
    }

    /// The rule in a sentence, as the report's first page states it.
    pub fn statement(self) -> String {
        match self {
            Self::Simple => "simple acceptance (ILAC G8 4.2.1): a value within its limits passes; \
                 the uncertainty is stated, not used (the false-accept risk reaches 50 % at a limit)"
                .to_owned(),
            Self::Guarded { guard_band_u } => format!(
                "guarded acceptance (ILAC G8 4.2.2): a value passes only inside its limits moved \
                 inward by the guard band w = {} U (expanded uncertainty, k from its degrees of \
                 freedom for 95 % coverage); a figure without an uncertainty is judged by its \
                 limits alone, as its note says",
                num(guard_band_u)
            ),
            Self::NonBinary => "non-binary statement (ILAC G8 4.2.3): pass when value +- U lies \
                 within the limits, fail when it lies outside, conditional pass or conditional \
                 fail when it straddles a limit; a figure without an uncertainty is judged by its \
                 limits alone"
                .to_owned(),
        }
    }

    /// The guard band of a figure of expanded uncertainty `expanded`, in
    /// its unit (none for simple acceptance).
    pub fn guard_band(self, expanded: f64) -> Option<f64> {
        match self {
            Self::Simple => None,
            Self::Guarded { guard_band_u } => Some(guard_band_u * expanded),
            Self::NonBinary => Some(expanded),
        }
    }

    /// Judge `value` against `low..high` with expanded uncertainty
    /// `expanded` (none: it could not be formed, judged by the limits
    /// alone).
    pub fn judge(
        self,
        value: f64,
        low: Option<f64>,
        high: Option<f64>,
        expanded: Option<f64>,
    ) -> Statement {
        let within =
            |w: f64| low.is_none_or(|lo| value >= lo + w) && high.is_none_or(|hi| value <= hi - w);
        let Some(u) = expanded.filter(|u| u.is_finite()) else {
            return if within(0.0) {
                Statement::Pass
            } else {
                Statement::Fail
            };
        };
        match self {
            Self::Simple => {
                if within(0.0) {
                    Statement::Pass
                } else {
                    Statement::Fail
                }
            }
            Self::Guarded { guard_band_u } => {
                if within(guard_band_u * u) {
                    Statement::Pass
                } else {
                    Statement::Fail
                }
            }
            Self::NonBinary => {
                if within(u) {
                    Statement::Pass
                } else if within(0.0) {
                    Statement::ConditionalPass
                } else if within(-u) {
                    Statement::ConditionalFail
                } else {
                    Statement::Fail
                }
            }
        }
    }
}

fn num(v: f64) -> String {
    format!("{v}")
}

#[cfg(test)]
mod tests {
    use super::*;

    const HIGH: Option<f64> = Some(0.05);

    #[test]
    fn a_value_in_the_guard_band_fails_guarded_and_passes_simple() {
        let guarded = DecisionRule::default();
        let (v, u) = (0.045, Some(0.01));
        assert_eq!(guarded.judge(v, None, HIGH, u), Statement::Fail);
        assert_eq!(
            DecisionRule::Simple.judge(v, None, HIGH, u),
            Statement::Pass
        );
        assert_eq!(guarded.judge(0.039, None, HIGH, u), Statement::Pass);
        // No uncertainty: the limits alone.
        assert_eq!(guarded.judge(v, None, HIGH, None), Statement::Pass);
        // A two-sided limit.
        assert_eq!(
            guarded.judge(-4.5, Some(-5.0), Some(5.0), Some(1.0)),
            Statement::Fail
        );
    }

    #[test]
    fn the_non_binary_rule_has_four_statements() {
        let r = DecisionRule::NonBinary;
        let u = Some(0.01);
        assert_eq!(r.judge(0.030, None, HIGH, u), Statement::Pass);
        assert_eq!(r.judge(0.045, None, HIGH, u), Statement::ConditionalPass);
        assert_eq!(r.judge(0.055, None, HIGH, u), Statement::ConditionalFail);
        assert_eq!(r.judge(0.070, None, HIGH, u), Statement::Fail);
    }

    #[test]
    fn a_rule_is_read_from_its_words_or_refused() {
        assert_eq!(
            DecisionRule::parse("guarded", Some(2.0)),
            Ok(DecisionRule::Guarded { guard_band_u: 2.0 })
        );
        assert_eq!(
            DecisionRule::parse("guarded", None),
            Ok(DecisionRule::default())
        );
        assert!(DecisionRule::parse("simple", Some(1.0)).is_err());
        assert!(DecisionRule::parse("guarded", Some(f64::NAN)).is_err());
        assert!(DecisionRule::parse("strict", None).is_err_and(|e| {
            e.to_string()
                .contains("expected \"simple\", \"guarded\" or \"non_binary\"")
        }));
    }
}
