//! A unit's coefficient set (the vocabulary crate's
//! [`gyrobench_model::coefficients`]: the file, its identity, how a run
//! names the set it used) and the choice of one for a run: its text
//! hashed, its identity as the results store checked it, and model 4 as
//! the run compensates with it.

pub use gyrobench_model::coefficients::*;

use std::path::Path;

use crate::analysis::model::Fit;
use crate::config::{ConfigError, Source};

/// A coefficient set chosen for a run: the set, its exact text (what is
/// logged and hashed) and how the record names it.
#[derive(Debug, Clone)]
pub struct Chosen {
    /// The set.
    pub set: CoefficientSet,
    /// Its text as read.
    pub text: String,
    /// How the run's record names it.
    pub used: CoeffsUsed,
}

impl Chosen {
    /// The set in the file `path` (`run --coeffs FILE`).
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let src = Source::read(path)?;
        Self::from_source(&src, CoeffsSource::File, &path.display().to_string())
    }

    /// The set whose text `src` holds, from `from` (a file or a store).
    pub fn from_source(
        src: &Source,
        source: CoeffsSource,
        from: &str,
    ) -> Result<Self, ConfigError> {
        let set = CoefficientSet::from_source(src)?;
        let used = CoeffsUsed::of_set(&set, source, from, &crate::fsutil::sha256_text(&src.text));
        Ok(Self {
            set,
            text: src.text.clone(),
            used,
        })
    }

    /// The set with its identity as checked against the results store:
    /// the run's record names the unit the store knows it as, and its
    /// version only when the store holds this text.
    pub fn identified(mut self, identity: SetIdentity) -> Self {
        self.used.version = match (&identity.status, &identity.stored) {
            (SetStatus::Registered, Some(s)) => Some(s.version),
            _ => None,
        };
        if let Some(s) = &identity.stored {
            self.used.serial = Some(s.serial.clone());
            self.used.dut_type = Some(s.dut_type.clone());
        }
        self.used.identity = Some(identity);
        self
    }

    /// Whether the set may compensate unit `serial` of type `dut_type`:
    /// [`CoefficientSet::check_unit`] on the unit it names, once the store
    /// (when it was asked) agrees that unit is its own.
    pub fn check_unit(&self, from: &str, dut_type: &str, serial: &str) -> Result<(), SetMismatch> {
        if self.set.model4.is_none() {
            return Err(SetMismatch::NoModel4 { from: from.into() });
        }
        if let Some(id) = &self.used.identity
            && let Some(why) = id.disagreement()
        {
            return Err(SetMismatch::NotItsUnit {
                from: from.into(),
                claim: id.claim(),
                why,
                dut_type: dut_type.into(),
                serial: serial.into(),
            });
        }
        self.set.check_unit(from, dut_type, serial)
    }

    /// What a run compensates with, when the set holds model 4.
    pub fn compensation(&self) -> Option<Compensation> {
        Some(Compensation {
            fit: self.set.fit()?,
            used: self.used.clone(),
        })
    }
}

/// Model-4 coefficients to compensate a run with, and how its
/// measurements name them.
#[derive(Debug, Clone)]
pub struct Compensation {
    /// Model 4 as a fit.
    pub fit: Fit,
    /// Where it came from.
    pub used: CoeffsUsed,
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyrobench_model::coefficients::fixtures::set;

    /// What the store found of a set whose text claims `claimed`.
    fn checked(
        status: SetStatus,
        claimed: &CoefficientSet,
        stored: Option<(&str, i64)>,
    ) -> SetIdentity {
        SetIdentity {
            status,
            claimed_unit: claimed.unit.clone(),
            claimed_version: claimed.set.as_ref().and_then(|s| s.version),
            stored: stored.map(|(serial, version)| StoredSet {
                serial: serial.into(),
                dut_type: "RL-16".into(),
                version,
                sha256: Some("cd".repeat(32)),
            }),
            fitted_on_runs: Vec::new(),
            store: Some("results.sqlite".into()),
            note: String::new(),
        }
    }

    fn chosen(s: &CoefficientSet) -> Chosen {
        let text = s.to_toml().unwrap();
        Chosen::from_source(
            &Source::from_text("unit.toml", &text),
            CoeffsSource::File,
            "unit.toml",
        )
        .unwrap()
    }

    #[test]
    fn an_edited_set_is_recorded_as_edited_never_as_the_set_it_claims() {
        // Its serial edited to another unit's: the store knows it as
        // RL16-0042's set 2, so the unit it names is refused.
        let forged = set("RL16-0099");
        let c =
            chosen(&forged).identified(checked(SetStatus::Edited, &forged, Some(("RL16-0042", 2))));
        assert_eq!(c.used.version, None, "an edited set has no version");
        assert_eq!(c.used.serial.as_deref(), Some("RL16-0042"));
        let e = c.check_unit("unit.toml", "RL-16", "RL16-0099").unwrap_err();
        assert!(matches!(e, SetMismatch::NotItsUnit { .. }), "{e}");
        assert!(
            e.to_string()
                .starts_with("unit.toml claims set 2 of RL-16 RL16-0099, but the results store results.sqlite holds it as set 2 of RL-16 RL16-0042"),
            "{e}"
        );
        // Its own unit's set with a coefficient edited: usable, said so.
        let own = set("RL16-0042");
        let c = chosen(&own).identified(checked(SetStatus::Edited, &own, Some(("RL16-0042", 2))));
        assert!(c.check_unit("unit.toml", "RL-16", "RL16-0042").is_ok());
        let words = c.used.describe();
        assert!(
            words.starts_with("an edited copy of set 2 of RL-16 RL16-0042 from unit.toml")
                && words.ends_with("not the text the results store holds"),
            "{words}"
        );
        // The store holds it: its version is the store's.
        let c =
            chosen(&own).identified(checked(SetStatus::Registered, &own, Some(("RL16-0042", 2))));
        assert_eq!(c.used.version, Some(2));
        assert!(
            c.used
                .describe()
                .starts_with("set 2 of RL-16 RL16-0042 from unit.toml")
        );
        // No store: the claim, said to be one.
        let c = chosen(&own).identified(checked(SetStatus::Unchecked, &own, None));
        assert_eq!(c.used.version, None);
        assert!(
            c.used
                .describe()
                .starts_with("set 2 of RL-16 RL16-0042 as its text claims from unit.toml"),
            "{}",
            c.used.describe()
        );
    }

    #[test]
    fn what_a_run_used_is_said_in_words() {
        let s = set("RL16-0042");
        let mut u = CoeffsUsed::of_set(&s, CoeffsSource::File, "unit.toml", &"f".repeat(64));
        assert_eq!(
            u.describe(),
            "set 2 of RL-16 RL16-0042 from unit.toml, sha256 ffffffffffff"
        );
        u.override_reason = Some("sister unit, same batch".into());
        assert!(
            u.describe()
                .ends_with("used for another unit: sister unit, same batch")
        );
        assert_eq!(
            CoeffsUsed::fitted().describe(),
            "fitted within the run (no --coeffs given)"
        );
    }
}
