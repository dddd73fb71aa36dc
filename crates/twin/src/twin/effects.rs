//! Extra effects beyond model 4, each off unless its section says
//! `enabled = true`. Names follow the diagnosis library.

use nalgebra::{Rotation3, Vector3};

use super::config::{EffectsConfig, HysteresisShape};
use gyrobench_model::geometry::Site;

/// Inputs an effect may depend on at one thermal step.
#[derive(Debug, Clone, Copy)]
pub struct EffectInputs {
    /// Step length, s.
    pub dt_s: f64,
    /// Time since power-on, s.
    pub t_s: f64,
    /// Case temperature T_K, degC.
    pub case_c: f64,
    /// The two block temperatures, degC.
    pub blocks_c: [f64; 2],
    /// Gravity in the body frame, g.
    pub gravity_body_g: Vector3<f64>,
    /// Earth's field in the body frame, microtesla.
    pub magnetic_body_ut: Vector3<f64>,
}

/// The enabled effects and their memory (play operator, lag filter).
#[derive(Debug, Clone)]
pub struct Effects {
    cfg: EffectsConfig,
    /// The play operators' states (one, or one per width of a smooth loop).
    play_c: Option<Vec<f64>>,
    /// The lag filters' states, in cascade.
    lag_c: Option<Vec<f64>>,
}

/// Half-widths of a smooth loop's plays, as multiples of its `width_c`
/// (their mean normalised output is the loop).
const SMOOTH_PLAYS: [f64; 7] = [0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75];

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
            periodic,
            earth_rate_error
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

    /// What the Earth rate the unit senses adds to the one the bench
    /// states at `site`, NED, deg/h (zero unless `earth_rate_error` is on).
    pub fn earth_rate_error_ned_dph(&self, site: &Site) -> Vector3<f64> {
        self.cfg
            .earth_rate_error
            .as_ref()
            .map_or_else(Vector3::zeros, |e| {
                site.earth_rate_turned_ned() * e.latitude_dph + Vector3::y() * e.east_dph
            })
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
            let t = h.temperature.of(x.case_c, x.blocks_c[0], x.blocks_c[1]);
            let widths: &[f64] = match h.shape {
                HysteresisShape::Play => &[1.0],
                HysteresisShape::Smooth => &SMOOTH_PLAYS,
            };
            let ys = self.play_c.get_or_insert_with(|| vec![t; widths.len()]);
            let mut out = 0.0;
            for (y, k) in ys.iter_mut().zip(widths) {
                let w = h.width_c * k;
                *y = y.clamp(t - w, t + w);
                out += (*y - t) / w;
            }
            bias += h.amplitude_dph * out / widths.len() as f64;
        }
        if let Some(l) = &self.cfg.thermal_lag {
            let t = l.temperature.of(x.case_c, x.blocks_c[0], x.blocks_c[1]);
            let lags = self
                .lag_c
                .get_or_insert_with(|| vec![t; usize::from(l.order.max(1))]);
            let a = -(-x.dt_s / l.tau_s).exp_m1();
            let mut input = t;
            for y in lags.iter_mut() {
                *y += (input - *y) * a;
                input = *y;
            }
            bias += l.coeff_dph_per_c * (input - l.reference_c);
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
    use crate::twin::config::EffectTemperature;

    fn inputs(case_c: f64) -> EffectInputs {
        EffectInputs {
            dt_s: 1.0,
            t_s: 0.0,
            case_c,
            blocks_c: [case_c; 2],
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

    #[test]
    fn memory_acts_on_the_temperature_it_is_of() {
        let mut cfg = TwinConfig::default_rl16().effects;
        let h = cfg.hysteresis.as_mut().expect("fixture has hysteresis");
        h.enabled = true;
        h.temperature = EffectTemperature::Block;
        let amp = h.amplitude_dph;
        let mut e = Effects::new(&cfg);
        // The case heats, the blocks stay: a loop on the block says nothing.
        let mut b = 0.0;
        for i in 0..=100 {
            let mut x = inputs(f64::from(i) * 0.5);
            x.blocks_c = [0.0, 0.0];
            b = e.step_bias_dph(&x);
        }
        assert!(b.abs() < 1e-12, "block loop moved with the case: {b}");
        // The blocks heat: it does.
        for i in 0..=100 {
            let mut x = inputs(50.0);
            x.blocks_c = [f64::from(i) * 0.5; 2];
            b = e.step_bias_dph(&x);
        }
        assert!((b + amp).abs() < 1e-12, "heating branch of the block: {b}");
    }

    #[test]
    fn a_smooth_loop_rounds_the_corners_a_play_has() {
        let turn = |shape: HysteresisShape| {
            let mut cfg = TwinConfig::default_rl16().effects;
            let h = cfg.hysteresis.as_mut().expect("fixture has hysteresis");
            h.enabled = true;
            h.shape = shape;
            let (amp, width) = (h.amplitude_dph, h.width_c);
            let mut e = Effects::new(&cfg);
            for i in 0..=100 {
                e.step_bias_dph(&inputs(f64::from(i) * 0.5));
            }
            // Turn back by half the width, then by four times it.
            let half = e.step_bias_dph(&inputs(50.0 - 0.5 * width)) / amp;
            let far = e.step_bias_dph(&inputs(50.0 - 4.0 * width)) / amp;
            (half, far)
        };
        let (play_half, play_far) = turn(HysteresisShape::Play);
        let (smooth_half, smooth_far) = turn(HysteresisShape::Smooth);
        // A play holds its state inside the width; the narrower plays of a
        // smooth loop have already started to turn.
        assert!((play_half + 0.5).abs() < 1e-12, "{play_half}");
        assert!(smooth_half > play_half + 0.05, "{smooth_half}");
        // Far past the width both sit on the cooling branch.
        assert!((play_far - 1.0).abs() < 1e-12, "{play_far}");
        assert!((smooth_far - 1.0).abs() < 1e-12, "{smooth_far}");
    }

    #[test]
    fn a_cascade_of_lags_starts_slower_than_one() {
        let after_one_tau = |order: u8| {
            let mut cfg = TwinConfig::default_rl16().effects;
            let l = cfg.thermal_lag.as_mut().expect("fixture has a lag");
            l.enabled = true;
            l.order = order;
            l.reference_c = 0.0;
            let (k, tau) = (l.coeff_dph_per_c, l.tau_s);
            let mut e = Effects::new(&cfg);
            e.step_bias_dph(&inputs(0.0));
            let mut b = 0.0;
            let steps = tau as usize;
            for _ in 0..steps {
                b = e.step_bias_dph(&inputs(1.0));
            }
            b / k
        };
        // A unit step through one lag: 1 - e^-1 after tau; through two:
        // 1 - 2 e^-1.
        let one = after_one_tau(1);
        let two = after_one_tau(2);
        assert!((one - (1.0 - (-1.0_f64).exp())).abs() < 1e-3, "{one}");
        assert!((two - (1.0 - 2.0 * (-1.0_f64).exp())).abs() < 1e-3, "{two}");
    }
}
