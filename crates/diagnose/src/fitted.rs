//! An effect as the selection fitted it, as a typed value: its term (the
//! effect and its nonlinear parameter) and its coefficients in the order
//! of [`Effect::terms`], with their standard errors. `diagnosis.json`'s
//! `parameters` and `uncertainties` are read off it, and the updated twin
//! is built from it ([`FittedEffect::apply_to`]), never from the names.

use std::collections::BTreeMap;

use crate::engine::Scored;
use crate::library::{Effect, Param};
use crate::twin::TwinConfig;
use crate::twin::config::EffectTemperature;

/// An effect as fitted.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedEffect {
    /// The effect.
    pub effect: Effect,
    /// Its nonlinear parameter.
    pub param: Param,
    /// Its coefficients, in the order of [`Effect::terms`].
    pub coeffs: Vec<f64>,
    /// Their standard errors (autocorrelation-inflated).
    pub stderr: Vec<f64>,
}

impl FittedEffect {
    /// Term `k` of `s`'s model as fitted in `s` (none: no such term).
    pub fn of(s: &Scored, k: usize) -> Option<Self> {
        let t = s.model.get(k)?;
        let at: usize = s.model[..k].iter().map(|t| t.effect.terms().len()).sum();
        let n = t.effect.terms().len();
        let take = |v: &[f64]| -> Vec<f64> {
            (at..at + n)
                .map(|i| v.get(i).copied().unwrap_or(f64::NAN))
                .collect()
        };
        Some(Self {
            effect: t.effect,
            param: t.param,
            coeffs: take(&s.coeffs),
            stderr: take(&s.stderr),
        })
    }

    /// Coefficient `i` (NaN past the effect's terms).
    fn coeff(&self, i: usize) -> f64 {
        self.coeffs.get(i).copied().unwrap_or(f64::NAN)
    }

    /// Its three coefficients, for an effect of a body vector.
    fn vector(&self) -> [f64; 3] {
        [self.coeff(0), self.coeff(1), self.coeff(2)]
    }

    /// Its coefficients and nonlinear parameter by their names
    /// (`diagnosis.json`'s `parameters`).
    pub fn parameters(&self) -> BTreeMap<String, f64> {
        let mut out: BTreeMap<String, f64> = self
            .effect
            .terms()
            .iter()
            .zip(&self.coeffs)
            .map(|(n, v)| ((*n).to_owned(), *v))
            .collect();
        if let Some(name) = self.effect.parameter() {
            out.insert(name.to_owned(), self.param.value());
        }
        out
    }

    /// Its coefficients' standard errors by name (`uncertainties`).
    pub fn uncertainties(&self) -> BTreeMap<String, f64> {
        self.effect
            .terms()
            .iter()
            .zip(&self.stderr)
            .map(|(n, v)| ((*n).to_owned(), *v))
            .collect()
    }

    /// The temperature a memory effect acts on.
    pub fn temperature(&self) -> Option<EffectTemperature> {
        self.param.temperature()
    }

    /// `t` with this effect enabled at its fitted values (a model-4 term
    /// switched on with its coefficient; an outside disturbance, never an
    /// accepted effect, leaves it as it is).
    pub fn apply_to(&self, t: &mut TwinConfig) {
        use crate::twin::config as tc;
        let on = self.temperature().unwrap_or_default();
        let value = self.param.value();
        match self.effect {
            Effect::Hysteresis => {
                t.effects.hysteresis = Some(tc::Hysteresis {
                    enabled: true,
                    amplitude_dph: self.coeff(0),
                    width_c: value,
                    temperature: on,
                    shape: tc::HysteresisShape::Play,
                });
            }
            Effect::ThermalLag => {
                t.effects.thermal_lag = Some(tc::ThermalLag {
                    enabled: true,
                    coeff_dph_per_c: self.coeff(0),
                    tau_s: value,
                    reference_c: 20.0,
                    temperature: on,
                    order: 1,
                });
            }
            Effect::GSensitivity => {
                t.effects.g_sensitivity = Some(tc::GSensitivity {
                    enabled: true,
                    coeff_dph_per_g: self.vector(),
                });
            }
            Effect::MagneticSensitivity => {
                t.effects.magnetic_sensitivity = Some(tc::MagneticSensitivity {
                    enabled: true,
                    coeff_dph_per_ut: self.vector(),
                });
            }
            Effect::AxisMisalignment => {
                // Axis x + theta_z y - theta_y z: the coefficients on the
                // Earth rate's y and z body components are theta_z, -theta_y.
                let arcmin = |rad: f64| rad.to_degrees() * 60.0;
                t.effects.axis_misalignment = Some(tc::AxisMisalignment {
                    enabled: true,
                    about_y_arcmin: arcmin(-self.coeff(1)),
                    about_z_arcmin: arcmin(self.coeff(0)),
                });
            }
            Effect::EarthRateError => {
                t.effects.earth_rate_error = Some(tc::EarthRateError {
                    enabled: true,
                    latitude_dph: self.coeff(0),
                    east_dph: self.coeff(1),
                });
            }
            Effect::ScaleFactorTemperature => {
                t.effects.scale_factor_temperature = Some(tc::ScaleFactorTemperature {
                    enabled: true,
                    ppm_per_c: self.coeff(0) * 1e6,
                    reference_c: 20.0,
                });
            }
            Effect::SelfHeating => {
                t.bias.terms.self_heating = true;
                t.bias.model4.k5_dph = self.coeff(0);
                t.bias.model4.warmup_tau_s = value;
            }
            Effect::GradientRate => {
                t.bias.terms.gradient_rate = true;
                t.bias.model4.k3_dph_per_c_per_s = self.coeff(0);
            }
            Effect::GradientQuadratic => {
                t.bias.terms.gradient_quadratic = true;
                t.bias.model4.k2_dph_per_c2 = self.coeff(0);
            }
            Effect::CaseTemperature => {
                t.bias.terms.case_temperature = true;
                t.bias.model4.k4_dph_per_c = self.coeff(0);
            }
            // Outside disturbances are never accepted effects.
            Effect::Gradient | Effect::BiasStep | Effect::BiasDrift | Effect::Periodic => {}
        }
    }
}
