//! Random terms of the rate output: angle random walk (per frame),
//! bias instability and rate random walk (per thermal step).

use rand::RngExt;
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

use super::config::NoiseConfig;

/// Correlation times of the Gauss-Markov processes whose sum approximates
/// flicker (1/f) rate noise, s. Half-decade spacing from 1 s to 1e5 s keeps
/// the Allan floor flat to a few percent over 3 s .. 2e4 s (ours).
const FLICKER_TAUS_S: [f64; 11] = [
    1.0, 3.162, 10.0, 31.62, 100.0, 316.2, 1000.0, 3162.0, 1.0e4, 3.162e4, 1.0e5,
];

/// Noise state; draws come from the twin's one seeded generator.
#[derive(Debug, Clone)]
pub struct Noise {
    /// 1-sigma white angle increment per frame, arcsec.
    white_arcsec_per_frame: f64,
    /// (decay, drive sigma, state in deg/h) per Gauss-Markov process.
    flicker: Vec<(f64, f64, f64)>,
    /// 1-sigma rate increment per step, deg/h.
    rrw_step_dph: f64,
    rrw_dph: f64,
}

impl Noise {
    /// Noise for frames of `frame_dt_s` and bias steps of `step_dt_s`.
    pub fn new(cfg: &NoiseConfig, frame_dt_s: f64, step_dt_s: f64) -> Self {
        // Rate white noise sigma = N*60/sqrt(dt) deg/h; times dt gives the
        // angle increment in arcsec (1 deg/h = 1 arcsec/s).
        let white_arcsec_per_frame = cfg.arw_deg_per_rt_h * 60.0 * frame_dt_s.sqrt();
        // A sum of GM processes with equal variance s^2 and taus spaced by a
        // factor r has PSD ~ s^2 / (2 f ln r); flicker with coefficient B has
        // PSD B^2 / (2 pi f), so s^2 = B^2 ln(r) / pi.
        let r: f64 = 10f64.sqrt();
        let sigma = cfg.bias_instability_dph * (r.ln() / std::f64::consts::PI).sqrt();
        let flicker = if cfg.bias_instability_dph > 0.0 {
            FLICKER_TAUS_S
                .iter()
                .map(|&tau| {
                    let a = (-step_dt_s / tau).exp();
                    (a, sigma * (1.0 - a * a).sqrt(), 0.0)
                })
                .collect()
        } else {
            Vec::new()
        };
        // RRW K deg/h/sqrt(h) = K/60 deg/h/sqrt(s).
        let rrw_step_dph = cfg.rrw_dph_per_rt_h / 60.0 * step_dt_s.sqrt();
        Self {
            white_arcsec_per_frame,
            flicker,
            rrw_step_dph,
            rrw_dph: 0.0,
        }
    }

    /// Start the correlated processes in their stationary distribution, as a
    /// gyro that has been on long enough for them to forget power-on would.
    pub fn randomize(&mut self, rng: &mut Xoshiro256PlusPlus) {
        for (a, drive, x) in &mut self.flicker {
            let stationary = *drive / (1.0 - *a * *a).sqrt();
            *x = stationary * rng.sample::<f64, _>(StandardNormal);
        }
        self.rrw_dph = 0.0;
    }

    /// White angle increment for one frame, arcsec.
    #[inline]
    pub fn frame_angle_arcsec(&self, rng: &mut Xoshiro256PlusPlus) -> f64 {
        if self.white_arcsec_per_frame == 0.0 {
            return 0.0;
        }
        self.white_arcsec_per_frame * rng.sample::<f64, _>(StandardNormal)
    }

    /// Advance the correlated terms one step; their sum, deg/h.
    pub fn step_bias_dph(&mut self, rng: &mut Xoshiro256PlusPlus) -> f64 {
        let mut sum = 0.0;
        for (a, drive, x) in &mut self.flicker {
            *x = *a * *x + *drive * rng.sample::<f64, _>(StandardNormal);
            sum += *x;
        }
        if self.rrw_step_dph > 0.0 {
            self.rrw_dph += self.rrw_step_dph * rng.sample::<f64, _>(StandardNormal);
        }
        sum + self.rrw_dph
    }
}
