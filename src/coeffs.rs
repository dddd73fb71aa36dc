//! The compensation coefficients file (`--coeffs`, written by calibration):
//!
//! ```toml
//! [model4]
//! k1_dph_per_c = -0.12
//! k2_dph_per_c2 = -0.01
//! k3_dph_per_c_per_s = 20.0
//! k4_dph_per_c = -0.007
//! k5_dph = 0.36
//! warmup_tau_s = 600.0
//! offset_dph = 0.0
//! ```

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::analysis::model::{Fit, ModelKind};
use crate::config::{Checker, ConfigError, Source};

/// `[model4]` of a coefficients file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model4Coeffs {
    /// K1, deg/h per degC of dT.
    pub k1_dph_per_c: f64,
    /// K2, deg/h per degC^2.
    pub k2_dph_per_c2: f64,
    /// K3, deg/h per degC/s.
    pub k3_dph_per_c_per_s: f64,
    /// K4, deg/h per degC of case temperature.
    pub k4_dph_per_c: f64,
    /// K5, deg/h.
    pub k5_dph: f64,
    /// tau_w, s.
    pub warmup_tau_s: f64,
    /// Constant, deg/h (drift figures do not depend on it).
    #[serde(default)]
    pub offset_dph: f64,
}

/// `[model3]`: the study's model 3 (no case-temperature or warm-up term).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model3Coeffs {
    /// K1, deg/h per degC of dT.
    pub k1_dph_per_c: f64,
    /// K2, deg/h per degC^2.
    pub k2_dph_per_c2: f64,
    /// K3, deg/h per degC/s.
    pub k3_dph_per_c_per_s: f64,
    /// Constant, deg/h.
    #[serde(default)]
    pub offset_dph: f64,
}

/// `[model1]`: the classic cubic in the case temperature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model1Coeffs {
    /// deg/h per degC^3.
    pub k1_dph_per_c3: f64,
    /// deg/h per degC^2.
    pub k2_dph_per_c2: f64,
    /// deg/h per degC.
    pub k3_dph_per_c: f64,
    /// Constant, deg/h.
    #[serde(default)]
    pub offset_dph: f64,
}

/// A coefficients file. `run --coeffs` compensates with `[model4]`; the
/// other models and `[calibration]` (how the file was made: runs,
/// validation, uncertainties) are for the engineer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoeffsFile {
    /// The study's model 4.
    pub model4: Model4Coeffs,
    /// Model 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model3: Option<Model3Coeffs>,
    /// Model 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model1: Option<Model1Coeffs>,
    /// The scale factor from rate runs (`calibrate` with rate-table runs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_factor: Option<ScaleFactorCoeffs>,
    /// Provenance written by `gyrobench calibrate`.
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

impl CoeffsFile {
    /// Read and check a coefficients file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::from_source(&Source::read(path)?)
    }

    /// Parse and check coefficients text.
    pub fn from_source(src: &Source) -> Result<Self, ConfigError> {
        let f: Self = src.parse()?;
        let c = Checker::new(src);
        let m = &f.model4;
        for (v, k) in [
            (m.k1_dph_per_c, "model4.k1_dph_per_c"),
            (m.k2_dph_per_c2, "model4.k2_dph_per_c2"),
            (m.k3_dph_per_c_per_s, "model4.k3_dph_per_c_per_s"),
            (m.k4_dph_per_c, "model4.k4_dph_per_c"),
            (m.k5_dph, "model4.k5_dph"),
            (m.offset_dph, "model4.offset_dph"),
        ] {
            c.finite(v, k)?;
        }
        c.positive(m.warmup_tau_s, "model4.warmup_tau_s")?;
        Ok(f)
    }

    /// The file's text.
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string_pretty(self)
    }

    /// As a fitted model.
    pub fn fit(&self) -> Fit {
        let m = &self.model4;
        Fit {
            kind: ModelKind::Model4,
            coeffs: vec![
                m.k1_dph_per_c,
                m.k2_dph_per_c2,
                m.k3_dph_per_c_per_s,
                m.k4_dph_per_c,
                m.k5_dph,
                m.offset_dph,
            ],
            warmup_tau_s: Some(m.warmup_tau_s),
            rms_dph: f64::NAN,
        }
    }
}
