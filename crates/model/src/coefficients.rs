//! A unit's coefficient set: the compensation coefficients `calibrate`
//! fitted for one unit, with whose they are and where they came from. The
//! same type is the file (`unit.toml`, what `run --coeffs` reads), the
//! results store's record (its text, byte for byte) and what a run logs:
//!
//! ```toml
//! [unit]
//! serial = "RL16-0042"
//! type = "RL-16"
//!
//! [set]
//! version = 2                     # the store's set number (none: not stored)
//! created_utc = "2026-12-03T10:00:00+00:00"
//! software = "gyrobench 0.1.0 (1a2b3c4d5e6f)"
//! models = ["model4", "model3", "model1"]
//! fitted_on = [{ run_id = "...", log_sha256 = "...", log = "runs/c1/run.mcap" }]
//!
//! [model4]
//! k1_dph_per_c = -0.12
//! ...
//! ```
//!
//! A set whose `[unit]` is missing (a file of an earlier version, or runs
//! of several units fitted together) names no unit: `run --coeffs` refuses
//! it without `--coeffs-override`. What the text claims (unit, version) is
//! checked against the results store when a run chooses the set
//! ([`identity`]): the run records what was verified, never a claim as a
//! fact. Choosing a set for a run (its text hashed, its identity checked)
//! is the controller's.

pub mod identity;

use std::path::Path;

use serde::{Deserialize, Serialize};

use gyrobench_analysis::compensation::{Model1, Model3, Model4};
use gyrobench_analysis::model::Fit;
pub use identity::{SetIdentity, SetStatus, StoredSet};

use crate::config::{Checker, ConfigError, Source};

/// `[unit]`: whose coefficients these are.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnitSection {
    /// Serial number.
    pub serial: String,
    /// Unit type (the procedures' `dut_type`).
    #[serde(rename = "type")]
    pub dut_type: String,
}

/// A run a set was fitted on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FittedOn {
    /// The run's id (empty for a log of the first format).
    pub run_id: String,
    /// SHA-256 of the log file as it was read.
    pub log_sha256: String,
    /// The log as it was named to `calibrate`.
    pub log: String,
}

/// `[set]`: the set's identity and provenance.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetSection {
    /// The results store's number of this set among the unit's sets (1 for
    /// the first); none when it was not recorded in a store.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub version: Option<i64>,
    /// When it was fitted, UTC, RFC 3339.
    pub created_utc: String,
    /// The gyrobench that fitted it, with its source revision.
    pub software: String,
    /// The models it holds.
    pub models: Vec<String>,
    /// The runs it was fitted on.
    #[serde(default)]
    pub fitted_on: Vec<FittedOn>,
}

/// A coefficient set (the file `run --coeffs` reads and `calibrate`
/// writes). `run --coeffs` compensates with `[model4]`; the other models,
/// `[scale_factor]` and `[calibration]` (validation, uncertainties) are
/// for the engineer.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoefficientSet {
    /// Whose coefficients (none: the set names no unit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<UnitSection>,
    /// Version and provenance (none in files of earlier versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub set: Option<SetSection>,
    /// The study's model 4 (none in a set of the scale factor alone).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model4: Option<Model4>,
    /// Model 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model3: Option<Model3>,
    /// Model 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model1: Option<Model1>,
    /// The scale factor from rate runs (`calibrate` with rate-table runs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_factor: Option<ScaleFactorCoeffs>,
    /// How the fit was validated, written by `gyrobench calibrate`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<toml::Table>,
}

/// `[scale_factor]`: the unit's scale factor against nominal and its
/// temperature coefficient, `K = (1 + error 1e-6) (1 + ppm_per_c 1e-6 (T -
/// reference_c))`, T the block temperature.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleFactorCoeffs {
    /// Scale factor error at `reference_c`, ppm.
    pub error_ppm: f64,
    /// Its standard error, ppm.
    pub error_ppm_stderr: f64,
    /// Change per degC of the block, ppm/degC (none: the runs spanned
    /// less than 1 degC).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ppm_per_c: Option<f64>,
    /// Its standard error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ppm_per_c_stderr: Option<f64>,
    /// Block temperature the error applies at, degC.
    pub reference_c: f64,
    /// Rate records the fit used.
    pub records: usize,
}

impl ScaleFactorCoeffs {
    /// In words, for the operator.
    pub fn render_text(&self) -> String {
        let mut s = format!(
            "scale factor from {} rate records: {:+.3} ± {:.3} ppm against nominal at {:.1} degC (block)",
            self.records, self.error_ppm, self.error_ppm_stderr, self.reference_c
        );
        match (self.ppm_per_c, self.ppm_per_c_stderr) {
            (Some(c), Some(e)) => s.push_str(&format!(", {c:+.4} ± {e:.4} ppm/degC\n")),
            _ => s.push_str("; the records span less than 1 degC: no temperature coefficient\n"),
        }
        s
    }
}

/// The heading comment of a set's text.
const HEADER: &str = "# A unit's coefficient set, written by gyrobench calibrate.\n\
# `gyrobench run --coeffs FILE` (or `--coeffs latest`) compensates with [model4];\n\
# a set of another unit is refused.\n";

impl CoefficientSet {
    /// Read and check a coefficient set file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::from_source(&Source::read(path)?)
    }

    /// Parse and check a set's text.
    pub fn from_source(src: &Source) -> Result<Self, ConfigError> {
        let f: Self = src.parse()?;
        let c = Checker::new(src);
        if let Some(m) = &f.model4 {
            c.model4(m, "model4")?;
        }
        if let Some(u) = &f.unit {
            c.ensure(
                crate::unit::check_serial(&u.serial).is_ok(),
                "unit.serial",
                "is not a serial number (1 to 64 printable characters)",
            )?;
        }
        Ok(f)
    }

    /// The set's text (what the file and the store hold).
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        Ok(format!("{HEADER}\n{}", toml::to_string_pretty(self)?))
    }

    /// Model 4 as a fit, if the set holds it.
    pub fn fit(&self) -> Option<Fit> {
        self.model4.as_ref().map(Fit::from)
    }

    /// The set in words: `set 2 of RL-16 RL16-0042`, `a set naming no unit`.
    pub fn describe(&self) -> String {
        let version = self
            .set
            .as_ref()
            .and_then(|s| s.version)
            .map_or_else(|| "a set".to_owned(), |v| format!("set {v}"));
        match &self.unit {
            Some(u) => format!("{version} of {} {}", u.dut_type, u.serial),
            None => format!("{version} naming no unit"),
        }
    }
}

/// Where the coefficients a run compensated with came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoeffsSource {
    /// None given: model 4 fitted on the run's own records.
    Fitted,
    /// A coefficient set file (`--coeffs FILE`).
    File,
    /// The unit's newest set in the results store (`--coeffs latest`).
    Store,
}

/// The coefficients a run used, as its log, its report and the store name
/// them.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CoeffsUsed {
    /// Where they came from.
    pub source: CoeffsSource,
    /// The set's unit serial (none: fitted, or a set naming no unit).
    pub serial: Option<String>,
    /// The set's unit type.
    pub dut_type: Option<String>,
    /// The set's version in the store.
    pub version: Option<i64>,
    /// SHA-256 of the set's text (the file's bytes).
    pub sha256: Option<String>,
    /// The file as given, or the store.
    pub from: Option<String>,
    /// Why a set of another unit (or naming none) was used anyway.
    pub override_reason: Option<String>,
    /// The set's identity as checked against the results store when the
    /// run chose it (none: fitted, or a log written before the check).
    /// `serial`, `dut_type` and `version` above are what the check
    /// verified: `version` only for a set the store holds byte for byte.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity: Option<SetIdentity>,
}

impl CoeffsUsed {
    /// Model 4 fitted on the run's own records.
    pub fn fitted() -> Self {
        Self {
            source: CoeffsSource::Fitted,
            serial: None,
            dut_type: None,
            version: None,
            sha256: None,
            from: None,
            override_reason: None,
            identity: None,
        }
    }

    /// A set read from `from` (a file or a store) whose text hashes to
    /// `sha256`.
    pub fn of_set(set: &CoefficientSet, source: CoeffsSource, from: &str, sha256: &str) -> Self {
        Self {
            source,
            serial: set.unit.as_ref().map(|u| u.serial.clone()),
            dut_type: set.unit.as_ref().map(|u| u.dut_type.clone()),
            version: set.set.as_ref().and_then(|s| s.version),
            sha256: Some(sha256.to_owned()),
            from: Some(from.to_owned()),
            override_reason: None,
            identity: None,
        }
    }

    /// In words, for the report and the measurement notes.
    pub fn describe(&self) -> String {
        if self.source == CoeffsSource::Fitted {
            return "fitted within the run (no --coeffs given)".into();
        }
        if self.sha256.is_none() && self.from.is_none() {
            // A log written before coefficient sets were named.
            return "the coefficients given by --coeffs".into();
        }
        let (head, checked) = match &self.identity {
            Some(id) => (id.head(), id.tail()),
            // A log written before sets were checked: the set as it named
            // itself.
            None => {
                let version = self
                    .version
                    .map_or_else(|| "a set not in a store".to_owned(), |v| format!("set {v}"));
                let unit = match (&self.dut_type, &self.serial) {
                    (Some(t), Some(s)) => format!(" of {t} {s}"),
                    _ => " naming no unit".into(),
                };
                (format!("{version}{unit}"), "")
            }
        };
        let sha = self.sha256.as_deref().map_or(String::new(), |h| {
            format!(", sha256 {}", &h[..h.len().min(12)])
        });
        let from = self
            .from
            .as_deref()
            .map_or(String::new(), |f| match self.source {
                CoeffsSource::Store => format!(" from the results store {f}"),
                _ => format!(" from {f}"),
            });
        let why = self
            .override_reason
            .as_deref()
            .map_or(String::new(), |r| format!("; used for another unit: {r}"));
        format!("{head}{from}{sha}{checked}{why}")
    }
}

/// Why a set may not compensate a unit.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SetMismatch {
    /// The set is another unit's.
    #[error(
        "{from} holds {set}: the coefficients of another unit, not of {dut_type} {serial}; calibrate this unit, or give --coeffs-override REASON to use them anyway (the reason goes in the report and the store)"
    )]
    OtherUnit {
        /// The file or the store.
        from: String,
        /// The set in words.
        set: String,
        /// The run's unit type.
        dut_type: String,
        /// The run's serial.
        serial: String,
    },
    /// The set names a unit the results store contradicts: it holds the
    /// set (or the set it was edited from) as another unit's, or the runs
    /// it was fitted on are another unit's.
    #[error(
        "{from} claims {claim}, but {why}: its unit is not the one it names; calibrate {dut_type} {serial}, or give --coeffs-override REASON to use it anyway (the reason goes in the report and the store)"
    )]
    NotItsUnit {
        /// The file or the store.
        from: String,
        /// What the set claims to be, in words.
        claim: String,
        /// What the store knows instead.
        why: String,
        /// The run's unit type.
        dut_type: String,
        /// The run's serial.
        serial: String,
    },
    /// The set names no unit.
    #[error(
        "{from} names no unit ([unit] is missing: a file of an earlier gyrobench, or runs of several units fitted together); calibrate this unit, or give --coeffs-override REASON to use it for {dut_type} {serial} anyway"
    )]
    NoUnit {
        /// The file or the store.
        from: String,
        /// The run's unit type.
        dut_type: String,
        /// The run's serial.
        serial: String,
    },
    /// The set has no model 4.
    #[error(
        "{from} holds no [model4] (a scale factor alone); calibrate with thermal runs for compensation coefficients"
    )]
    NoModel4 {
        /// The file or the store.
        from: String,
    },
}

impl CoefficientSet {
    /// Whether this set may compensate unit `serial` of type `dut_type`.
    pub fn check_unit(&self, from: &str, dut_type: &str, serial: &str) -> Result<(), SetMismatch> {
        if self.model4.is_none() {
            return Err(SetMismatch::NoModel4 { from: from.into() });
        }
        match &self.unit {
            None => Err(SetMismatch::NoUnit {
                from: from.into(),
                dut_type: dut_type.into(),
                serial: serial.into(),
            }),
            Some(u) if u.serial != serial || u.dut_type != dut_type => {
                Err(SetMismatch::OtherUnit {
                    from: from.into(),
                    set: self.describe(),
                    dut_type: dut_type.into(),
                    serial: serial.into(),
                })
            }
            Some(_) => Ok(()),
        }
    }
}

/// Example values for tests, here and in the crates that build on this one
/// (their dev-dependency turns on the `fixtures` feature).
#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures {
    use super::*;

    /// The twin's model 4 (`fixtures/twin/rl16.toml`: k1..k5, a 600 s warm-up).
    pub fn model4() -> Model4 {
        Model4 {
            k1_dph_per_c: -0.12,
            k2_dph_per_c2: -0.01,
            k3_dph_per_c_per_s: 20.0,
            k4_dph_per_c: -0.007,
            k5_dph: 0.36,
            warmup_tau_s: 600.0,
            offset_dph: 0.0,
        }
    }

    /// A version-2 set of [`model4`] for `serial`, fitted on one run.
    pub fn set(serial: &str) -> CoefficientSet {
        CoefficientSet {
            unit: Some(UnitSection {
                serial: serial.into(),
                dut_type: "RL-16".into(),
            }),
            set: Some(SetSection {
                version: Some(2),
                created_utc: "2026-12-03T10:00:00+00:00".into(),
                software: "gyrobench 0.1.0".into(),
                models: vec!["model4".into()],
                fitted_on: vec![FittedOn {
                    run_id: "ab".into(),
                    log_sha256: "cd".into(),
                    log: "runs/c1/run.mcap".into(),
                }],
            }),
            model4: Some(model4()),
            model3: None,
            model1: None,
            scale_factor: None,
            calibration: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::fixtures::{model4, set};
    use super::*;

    #[test]
    fn a_set_reads_back_as_written_and_names_its_unit() {
        let s = set("RL16-0042");
        let text = s.to_toml().unwrap();
        let back = CoefficientSet::from_source(&Source::from_text("unit.toml", &text)).unwrap();
        assert_eq!(back, s);
        assert!(
            text.contains("[unit]") && text.contains("serial = \"RL16-0042\""),
            "{text}"
        );
        assert_eq!(s.describe(), "set 2 of RL-16 RL16-0042");
    }

    #[test]
    fn a_set_of_another_unit_or_of_none_is_refused() {
        let s = set("SIMULATED");
        assert!(s.check_unit("unit.toml", "RL-16", "SIMULATED").is_ok());
        let e = s.check_unit("unit.toml", "RL-16", "RL16-0099").unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("set 2 of RL-16 SIMULATED") && msg.contains("RL-16 RL16-0099"),
            "{msg}"
        );
        assert!(matches!(
            s.check_unit("unit.toml", "FOG-9", "SIMULATED"),
            Err(SetMismatch::OtherUnit { .. })
        ));
        let old = CoefficientSet {
            unit: None,
            set: None,
            ..s.clone()
        };
        assert!(matches!(
            old.check_unit("old.toml", "RL-16", "SIMULATED"),
            Err(SetMismatch::NoUnit { .. })
        ));
        let sf_only = CoefficientSet { model4: None, ..s };
        assert!(matches!(
            sf_only.check_unit("sf.toml", "RL-16", "SIMULATED"),
            Err(SetMismatch::NoModel4 { .. })
        ));
    }

    #[test]
    fn a_file_of_an_earlier_version_still_reads() {
        let text = "[model4]\nk1_dph_per_c = -0.12\nk2_dph_per_c2 = -0.01\nk3_dph_per_c_per_s = 20.0\n\
                    k4_dph_per_c = -0.007\nk5_dph = 0.36\nwarmup_tau_s = 600.0\n";
        let s = CoefficientSet::from_source(&Source::from_text("old.toml", text)).unwrap();
        assert_eq!(s.model4, Some(model4()));
        assert!(s.unit.is_none());
        let bad = text.replace("600.0", "-1.0");
        let e = CoefficientSet::from_source(&Source::from_text("old.toml", &bad)).unwrap_err();
        assert!(e.to_string().contains("model4.warmup_tau_s"), "{e}");
    }
}
