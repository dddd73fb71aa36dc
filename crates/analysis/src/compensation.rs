//! The study's thermal compensation models as data: one type per model,
//! shared by everything that holds such coefficients (the twin's bias, a
//! fit, a coefficient set, the diagnosis's updated twin), and model 4's
//! formula written once.
//!
//! - model 1 (classic): `K1 T^3 + K2 T^2 + K3 T`, T the case temperature;
//! - model 3: `K1 dT + K2 dT^2 + K3 d(dT)/dt`, dT = T1 - T2;
//! - model 4: model 3 `+ K4 T_K + K5 F(tau)`, `F(tau) = exp(-tau/tau_w)`.
//!
//! Each carries the constant the fit found with it (`offset_dph`); drift
//! figures never depend on it.

use serde::{Deserialize, Serialize};

/// The study's model 4 (`[model4]` of a coefficient set, the twin's
/// `[bias]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model4 {
    /// K1, deg/h per degC of dT.
    pub k1_dph_per_c: f64,
    /// K2, deg/h per degC^2 of dT.
    pub k2_dph_per_c2: f64,
    /// K3, deg/h per degC/s of d(dT)/dt.
    pub k3_dph_per_c_per_s: f64,
    /// K4, deg/h per degC of case temperature.
    pub k4_dph_per_c: f64,
    /// K5, deg/h at power-on (times F(tau)).
    pub k5_dph: f64,
    /// Warm-up time constant tau_w of F(tau), s.
    pub warmup_tau_s: f64,
    /// Constant, deg/h.
    #[serde(default)]
    pub offset_dph: f64,
}

/// Which model-4 terms act (names as in the diagnosis library).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model4Terms {
    /// K1 dT.
    pub gradient: bool,
    /// K2 dT^2.
    pub gradient_quadratic: bool,
    /// K3 d(dT)/dt.
    pub gradient_rate: bool,
    /// K4 T_K.
    pub case_temperature: bool,
    /// K5 F(tau).
    pub self_heating: bool,
}

impl Model4Terms {
    /// Every term (the study's model 4).
    pub const ALL: Self = Self {
        gradient: true,
        gradient_quadratic: true,
        gradient_rate: true,
        case_temperature: true,
        self_heating: true,
    };
}

/// Inputs of model 4 at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Model4Inputs {
    /// dT = T1 - T2, degC.
    pub gradient_c: f64,
    /// d(dT)/dt, degC/s.
    pub gradient_rate_c_per_s: f64,
    /// Case temperature T_K, degC.
    pub case_c: f64,
    /// Time since power-on, s.
    pub tau_s: f64,
}

impl Model4 {
    /// The thermal bias `K1 dT + K2 dT^2 + K3 d(dT)/dt + K4 T_K + K5
    /// exp(-tau/tau_w)` with the terms `terms` switches off left out
    /// (without the constant), deg/h.
    pub fn thermal_bias_dph(&self, x: &Model4Inputs, terms: Model4Terms) -> f64 {
        let on = |flag: bool| if flag { 1.0 } else { 0.0 };
        on(terms.gradient) * self.k1_dph_per_c * x.gradient_c
            + on(terms.gradient_quadratic) * self.k2_dph_per_c2 * x.gradient_c * x.gradient_c
            + on(terms.gradient_rate) * self.k3_dph_per_c_per_s * x.gradient_rate_c_per_s
            + on(terms.case_temperature) * self.k4_dph_per_c * x.case_c
            + on(terms.self_heating) * self.k5_dph * (-x.tau_s / self.warmup_tau_s).exp()
    }
}

/// Model 3 (no case-temperature or warm-up term).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model3 {
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

/// Model 1: the classic cubic in the case temperature.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model1 {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model4_adds_its_terms_and_leaves_out_those_switched_off() {
        let m = Model4 {
            k1_dph_per_c: 1.0,
            k2_dph_per_c2: 2.0,
            k3_dph_per_c_per_s: 3.0,
            k4_dph_per_c: 4.0,
            k5_dph: 5.0,
            warmup_tau_s: 100.0,
            offset_dph: 100.0,
        };
        let x = Model4Inputs {
            gradient_c: 0.5,
            gradient_rate_c_per_s: 0.1,
            case_c: 2.0,
            tau_s: 100.0,
        };
        let all = 0.5 + 2.0 * 0.25 + 0.3 + 8.0 + 5.0 * (-1.0f64).exp();
        assert!((m.thermal_bias_dph(&x, Model4Terms::ALL) - all).abs() < 1e-12);
        let no_case = Model4Terms {
            case_temperature: false,
            ..Model4Terms::ALL
        };
        assert!((m.thermal_bias_dph(&x, no_case) - (all - 8.0)).abs() < 1e-12);
    }
}
