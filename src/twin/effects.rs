//! Extra effects beyond model 4, each off unless its section says
//! `enabled = true`. Names follow the diagnosis library.

use nalgebra::{Rotation3, Vector3};

use super::config::EffectsConfig;

/// Inputs an effect may depend on at one thermal step.
#[derive(Debug, Clone, Copy)]
pub struct EffectInputs {
    /// Step length, s.
    pub dt_s: f64,
    /// Time since power-on, s.
    pub t_s: f64,
    /// Case temperature T_K, degC.
    pub case_c: f64,
    /// Gravity in the body frame, g.
    pub gravity_body_g: Vector3<f64>,
    /// Earth's field in the body frame, microtesla.
    pub magnetic_body_ut: Vector3<f64>,
}

/// The enabled effects and their memory (play operator, lag filter).
#[derive(Debug, Clone)]
pub struct Effects {
    cfg: EffectsConfig,
    play_c: Option<f64>,
    lag_c: Option<f64>,
}

impl Effects {
    /// Keep only the enabled effects.
    pub fn new(cfg: &EffectsConfig) -> Self {
        let mut cfg = cfg.clone();
        macro_rules! keep_enabled {
            ($($field:ident),*) => {$(
                if cfg.$field.as_ref().is_some_and(|e| !e.enabled) {
                    cfg.$field = None;
                }
            )*};
        }
        keep_enabled!(
            hysteresis,
            thermal_lag,
            g_sensitivity,
            magnetic_sensitivity,
            axis_misalignment,
            scale_factor_temperature,
            periodic
        );
        Self {
            cfg,
            play_c: None,
            lag_c: None,
        }
    }

    /// The true sensitive axis in the body frame (body x unless misaligned).
    pub fn sensitive_axis_body(&self) -> Vector3<f64> {
        match &self.cfg.axis_misalignment {
            Some(m) => {
                let to_rad = |arcmin: f64| (arcmin / 60.0).to_radians();
                let r = Rotation3::from_euler_angles(
                    0.0,
                    to_rad(m.about_y_arcmin),
                    to_rad(m.about_z_arcmin),
                );
                r * Vector3::x()
            }
            None => Vector3::x(),
        }
    }

    /// Multiplier on the sensed (kinematic) rate at block temperature `block_c`.
    pub fn scale_factor(&self, block_c: f64) -> f64 {
        match &self.cfg.scale_factor_temperature {
            Some(s) => 1.0 + s.ppm_per_c * 1e-6 * (block_c - s.reference_c),
            None => 1.0,
        }
    }

    /// Bias added by the enabled effects over one step, deg/h.
    pub fn step_bias_dph(&mut self, x: &EffectInputs) -> f64 {
        let mut bias = 0.0;
        if let Some(h) = &self.cfg.hysteresis {
            let y = self.play_c.get_or_insert(x.case_c);
            *y = y.clamp(x.case_c - h.width_c, x.case_c + h.width_c);
            bias += h.amplitude_dph * (*y - x.case_c) / h.width_c;
        }
        if let Some(l) = &self.cfg.thermal_lag {
            let lag = self.lag_c.get_or_insert(x.case_c);
            *lag += (x.case_c - *lag) * (-(-x.dt_s / l.tau_s).exp_m1());
            bias += l.coeff_dph_per_c * (*lag - l.reference_c);
        }
        if let Some(g) = &self.cfg.g_sensitivity {
            bias += Vector3::from(g.coeff_dph_per_g).dot(&x.gravity_body_g);
        }
        if let Some(m) = &self.cfg.magnetic_sensitivity {
            bias += Vector3::from(m.coeff_dph_per_ut).dot(&x.magnetic_body_ut);
        }
        if let Some(p) = &self.cfg.periodic {
            bias += p.amplitude_dph * (std::f64::consts::TAU * x.t_s / p.period_s).sin();
        }
        bias
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::twin::TwinConfig;

    fn inputs(case_c: f64) -> EffectInputs {
        EffectInputs {
            dt_s: 1.0,
            t_s: 0.0,
            case_c,
            gravity_body_g: Vector3::zeros(),
            magnetic_body_ut: Vector3::zeros(),
        }
    }

    #[test]
    fn disabled_effects_do_nothing() {
        let mut e = Effects::new(&TwinConfig::default_rl16().effects);
        assert_eq!(e.sensitive_axis_body(), Vector3::x());
        assert_eq!(e.scale_factor(60.0), 1.0);
        let mut x = inputs(20.0);
        x.gravity_body_g = Vector3::new(0.3, 0.5, 0.8);
        assert_eq!(e.step_bias_dph(&x), 0.0);
    }

    #[test]
    fn hysteresis_remembers_heating_and_cooling() {
        let mut cfg = TwinConfig::default_rl16().effects;
        let h = cfg.hysteresis.as_mut().expect("fixture has hysteresis");
        h.enabled = true;
        let (amp, width) = (h.amplitude_dph, h.width_c);
        let mut e = Effects::new(&cfg);
        let mut b = 0.0;
        for i in 0..=100 {
            b = e.step_bias_dph(&inputs(f64::from(i) * 0.5));
        }
        assert!((b + amp).abs() < 1e-12, "heating branch: {b}");
        // Turning back by less than the play width leaves the state alone:
        // the bias depends on where the temperature came from.
        let b_mid = e.step_bias_dph(&inputs(50.0 - width));
        assert!(b_mid.abs() < 1e-12, "{b_mid}");
        for i in 0..=100 {
            b = e.step_bias_dph(&inputs(50.0 - f64::from(i) * 0.5));
        }
        assert!((b - amp).abs() < 1e-12, "cooling branch: {b}");
    }
}
