//! The twin's TOML configuration (`twins/rl16.toml` in this crate is the
//! default; the workspace's `fixtures/twin/` is a link to that folder).
//!
//! Every key is documented in `docs/twin.md`. Structs mirror the file with
//! `deny_unknown_fields`; [`TwinConfig::load`] then validates the values and
//! reports a bad one with its key and place in the file.

use std::path::Path;

use serde::{Deserialize, Serialize};

use gyrobench_analysis::compensation::{Model4, Model4Terms};
use gyrobench_model::config::{Checker, ConfigError, Source};
use gyrobench_model::geometry::{Site, TableAngles, TableGeometry};

pub use super::thermal_effects::ThermalEffects;

/// The default twin configuration, embedded so the tool runs without files
/// (the file is the crate's own, so the package holds what it embeds).
pub const DEFAULT_TWIN_TOML: &str = include_str!("../../twins/rl16.toml");

/// Complete configuration of the simulated gyro and its bench.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwinConfig {
    /// Bench site (latitude for Earth rate, magnetic field).
    pub site: Site,
    /// Climatic chamber air model and capability.
    pub chamber: ChamberConfig,
    /// Gyro thermal network.
    pub thermal: ThermalConfig,
    /// Digital output.
    pub gyro: GyroConfig,
    /// The study's model-4 thermal bias and the turn-on bias.
    pub bias: BiasConfig,
    /// Random noise terms.
    pub noise: NoiseConfig,
    /// Two-axis motion simulator.
    pub table: TableConfig,
    /// Extra effects beyond model 4, each off unless enabled.
    #[serde(default)]
    pub effects: EffectsConfig,
    /// How the output follows the input rate (scale factor, nonlinearity,
    /// asymmetry, lock-in); nominal unless set.
    #[serde(default)]
    pub rate_response: RateResponseConfig,
    /// The path-length control's resets (mode hops); none unless set,
    /// and left out of a file that has none.
    #[serde(default, skip_serializing_if = "PathLengthControlConfig::is_off")]
    pub path_length_control: PathLengthControlConfig,
}

/// The path-length control (`docs/twin.md`, "Path-length control"): it
/// holds the cavity on its lasing mode by moving a mirror, and its
/// transducer's travel covers only so much of the block's expansion;
/// past it the control resets to the next mode. While it relocks the
/// status word's lock bit is clear and the output is not fit to use; the
/// new mode has its own bias. Off by default (`reset_span_c = 0`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PathLengthControlConfig {
    /// Change of the block's mean temperature, from the last reset (or
    /// the power-on), that the control follows before it resets, degC
    /// (0: never resets).
    pub reset_span_c: f64,
    /// How long a reset keeps the control out of lock, s.
    pub relock_s: f64,
    /// Bias of the second mode against the first, deg/h: the unit steps
    /// by it at one reset and back at the next.
    pub mode_bias_dph: f64,
    /// Rate error of the output while out of lock, deg/h (its sign drawn
    /// at each reset): what a record would take in if it kept those frames.
    pub relock_error_dph: f64,
}

impl Default for PathLengthControlConfig {
    fn default() -> Self {
        Self {
            reset_span_c: 0.0,
            relock_s: 0.5,
            mode_bias_dph: 0.0,
            relock_error_dph: 0.0,
        }
    }
}

impl PathLengthControlConfig {
    /// True when the control never resets.
    pub fn is_off(&self) -> bool {
        self.reset_span_c == 0.0
    }

    fn validate(&self, c: &Checker<'_>) -> Result<(), ConfigError> {
        c.within(
            self.reset_span_c,
            0.0,
            1000.0,
            "path_length_control.reset_span_c",
        )?;
        c.within(self.relock_s, 0.0, 60.0, "path_length_control.relock_s")?;
        c.within(
            self.mode_bias_dph,
            -100.0,
            100.0,
            "path_length_control.mode_bias_dph",
        )?;
        c.within(
            self.relock_error_dph,
            0.0,
            1e6,
            "path_length_control.relock_error_dph",
        )?;
        Ok(())
    }
}

/// The output's response to the input rate (`docs/twin.md`, "Rate
/// response"). Every term is zero by default: the output is the input.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RateResponseConfig {
    /// Scale factor error against the nominal count (`gyro.lsb_arcsec`), ppm.
    pub scale_factor_error_ppm: f64,
    /// Scale-factor nonlinearity: the scale factor changes by this much at
    /// `full_scale_dps`, in proportion to |rate| (an output error growing
    /// with the square of the rate), ppm.
    pub nonlinearity_ppm: f64,
    /// Input rate at which `nonlinearity_ppm` applies, deg/s (the unit's
    /// range).
    pub full_scale_dps: f64,
    /// Scale factor for positive input rates minus that for negative ones,
    /// ppm (each half of it on either side).
    pub asymmetry_ppm: f64,
    /// Lock-in threshold left after dither, deg/h: an input (with the
    /// bias) smaller than this gives no output; above it the output is
    /// `sign(x) sqrt(x^2 - lock_in^2)` (the Adler equation of a ring laser).
    /// A locking gyro is a dithered one: its frames then also carry the
    /// dither-stripping residual, one count rms of white angle jitter.
    pub lock_in_dph: f64,
    /// Random walk the dither adds to the angle output, deg/sqrt(h)
    /// (beyond `noise.arw_deg_per_rt_h`).
    pub dither_random_walk_deg_per_rt_h: f64,
    /// The dither-stripping residual of a locking gyro: white angle jitter
    /// of this many counts rms on its frames (default 1, a dithered
    /// unit's). 0: no dither at all, a clean locked output: inside the
    /// lock-in the beams lock and the unit sends no counts, not even its
    /// noise's.
    pub dither_residual_counts: f64,
}

impl Default for RateResponseConfig {
    fn default() -> Self {
        Self {
            scale_factor_error_ppm: 0.0,
            nonlinearity_ppm: 0.0,
            full_scale_dps: 0.0,
            asymmetry_ppm: 0.0,
            lock_in_dph: 0.0,
            dither_random_walk_deg_per_rt_h: 0.0,
            dither_residual_counts: 1.0,
        }
    }
}

impl RateResponseConfig {
    /// The output rate, deg/h, for the input `input_dph` (Earth and
    /// table rate on the sensitive axis) times the temperature scale
    /// factor `sf_temperature`, plus `bias_dph`; no noise. The twin's
    /// output follows this exactly (tests compare figures with it).
    pub fn output_dph(&self, input_dph: f64, sf_temperature: f64, bias_dph: f64) -> f64 {
        let mut k = sf_temperature * (1.0 + self.scale_factor_error_ppm * 1e-6);
        if self.asymmetry_ppm != 0.0 {
            k *= 1.0 + 0.5e-6 * self.asymmetry_ppm * input_dph.signum();
        }
        if self.nonlinearity_ppm != 0.0 && self.full_scale_dps > 0.0 {
            k *= 1.0
                + 1e-6 * self.nonlinearity_ppm * input_dph.abs() / (self.full_scale_dps * 3600.0);
        }
        let x = k * input_dph + bias_dph;
        if self.locked(x) {
            return 0.0;
        }
        if self.lock_in_dph > 0.0 {
            let l = self.lock_in_dph;
            if x.abs() <= l {
                0.0
            } else {
                x.signum() * (x * x - l * l).sqrt()
            }
        } else {
            x
        }
    }

    /// Whether an input of `x` deg/h (scaled, bias added) lies inside the
    /// lock-in: the beams lock and the output is zero.
    pub fn locked(&self, x: f64) -> bool {
        self.lock_in_dph > 0.0 && x.abs() <= self.lock_in_dph
    }

    /// Whether the unit, undithered, sends no counts at all while locked
    /// (its noise included): `dither_residual_counts = 0`.
    pub fn locks_clean(&self) -> bool {
        self.lock_in_dph > 0.0 && self.dither_residual_counts == 0.0
    }

    fn validate(&self, c: &Checker<'_>) -> Result<(), ConfigError> {
        c.within(
            self.scale_factor_error_ppm,
            -1e5,
            1e5,
            "rate_response.scale_factor_error_ppm",
        )?;
        c.within(
            self.nonlinearity_ppm,
            -1e5,
            1e5,
            "rate_response.nonlinearity_ppm",
        )?;
        c.within(
            self.full_scale_dps,
            0.0,
            1e4,
            "rate_response.full_scale_dps",
        )?;
        c.ensure(
            self.nonlinearity_ppm == 0.0 || self.full_scale_dps > 0.0,
            "rate_response.full_scale_dps",
            "must be above 0 deg/s when nonlinearity_ppm is set",
        )?;
        c.within(self.asymmetry_ppm, -1e5, 1e5, "rate_response.asymmetry_ppm")?;
        c.within(self.lock_in_dph, 0.0, 3600.0, "rate_response.lock_in_dph")?;
        c.within(
            self.dither_random_walk_deg_per_rt_h,
            0.0,
            1.0,
            "rate_response.dither_random_walk_deg_per_rt_h",
        )?;
        c.within(
            self.dither_residual_counts,
            0.0,
            100.0,
            "rate_response.dither_residual_counts",
        )?;
        Ok(())
    }
}

/// Chamber air: follows a ramped set point through a first-order lag.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChamberConfig {
    /// Lowest set point the chamber can hold, degC.
    pub min_c: f64,
    /// Highest set point the chamber can hold, degC.
    pub max_c: f64,
    /// Fastest set-point ramp, degC/min.
    pub max_ramp_c_per_min: f64,
    /// Lag of the air behind the controller's ramped set point, s.
    pub air_tau_s: f64,
    /// Air (and soaked unit) temperature at the start, degC.
    pub initial_c: f64,
}

/// Three-node thermal network: case, block side 1 (sensor T1), block side 2 (T2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalConfig {
    /// Time constant of the case towards chamber air, s.
    pub case_tau_s: f64,
    /// Time constant of block node 1 towards the case, s.
    pub block1_tau_s: f64,
    /// Time constant of block node 2 towards the case, s.
    pub block2_tau_s: f64,
    /// Time constant of the exchange between the two block nodes, s
    /// (with no convection help).
    pub coupling_tau_s: f64,
    /// Extra exchange between the block nodes when the line joining the two
    /// sensors is vertical (internal convection), fraction: 0.5 = 50 % faster.
    pub convection_gain: f64,
    /// Direction from sensor 2 to sensor 1 in the body frame.
    pub sensor_axis_body: [f64; 3],
    /// Steady rise of the case above the air from the gyro's own dissipation, degC.
    pub case_rise_c: f64,
    /// Steady rise of block node 1 above the case it would reach alone, degC.
    pub block1_rise_c: f64,
    /// Steady rise of block node 2 above the case it would reach alone, degC.
    pub block2_rise_c: f64,
    /// White noise of each temperature sensor reading, degC (1 sigma).
    pub sensor_noise_c: f64,
    /// Time constant of a mount node between the chamber air and the case
    /// (a fixture, a jacket), s; 0 = none: the case sees the air.
    #[serde(default)]
    pub mount_tau_s: f64,
    /// The air the unit sees per degC of the chamber's air reading (1: the
    /// reading is that air; a chamber sensor with a gain error, or a
    /// workspace gradient, shows as a few percent off).
    #[serde(default = "one")]
    pub air_gain: f64,
    /// Offsets of the T1, T2 and TK readings, degC.
    #[serde(default)]
    pub sensor_offset_c: [f64; 3],
    /// Heat capacity of block node 1 and of block node 2 over the case's
    /// (0: the blocks follow the case without warming or cooling it back).
    #[serde(default)]
    pub block_capacity_ratio: [f64; 2],
    /// Time constant of a heat sink on the case (a baseplate, a bracket:
    /// a mass the case warms and cools that the air does not reach), s; 0
    /// = none.
    #[serde(default)]
    pub sink_tau_s: f64,
    /// The sink's heat capacity over the case's: its heat flows back into
    /// the case (0 = none).
    #[serde(default)]
    pub sink_capacity_ratio: f64,
    /// Heat capacity of block node 1 over block node 2's (1: equal): the
    /// conductance between them is one, so block 2's exchange time
    /// constant is `coupling_tau_s` over this.
    #[serde(default = "one")]
    pub block_capacity_1_over_2: f64,
    /// What the unit's thermal physics holds beyond this network (sensor
    /// lags and gain errors, a coupling that changes with orientation, a
    /// path from the air to a block, a case conductance that changes with
    /// temperature), each off by default.
    #[serde(default, skip_serializing_if = "ThermalEffects::is_none")]
    pub effects: ThermalEffects,
}

fn one() -> f64 {
    1.0
}

/// Digital output of the gyro.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GyroConfig {
    /// Frames per second, Hz.
    pub frame_rate_hz: f64,
    /// Angle per count of the delta-angle output, arcsec.
    pub lsb_arcsec: f64,
    /// Resolution of the temperature fields, degC.
    pub temp_lsb_c: f64,
    /// Error of the unit's frame oscillator, ppm: its frames come at
    /// `(1 + e 1e-6)` times `frame_rate_hz` of true time, each covering
    /// that much less of it, while the bench still takes them to be
    /// `frame_rate_hz` apart. 0 (the default, left out of the file): the
    /// frames come at `frame_rate_hz` exactly.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub frame_clock_error_ppm: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// Largest frame-clock error the twin takes, ppm (a crystal oscillator is
/// off by tens of ppm; a thousand is a broken one). Within it a frame
/// period holds at most two frame ends.
pub const MAX_FRAME_CLOCK_ERROR_PPM: f64 = 1000.0;

/// Model-4 thermal bias `K1 dT + K2 dT^2 + K3 d(dT)/dt + K4 T_K + K5 F(tau)`
/// with `dT = T1 - T2`, `F(tau) = exp(-tau/tau_w)`, plus a fixed bias (the
/// model's constant) and a turn-on bias. In the file, the model's keys sit
/// flat in `[bias]` beside the others.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "RawBias", into = "RawBias")]
pub struct BiasConfig {
    /// The model-4 coefficients; `offset_dph` is the fixed bias, deg/h.
    pub model4: Model4,
    /// Run-to-run (turn-on) bias repeatability, deg/h, 1 sigma.
    pub turn_on_sigma_dph: f64,
    /// Which model-4 terms act (all true reproduces the study).
    pub terms: Model4Terms,
}

/// `[bias]` as the file has it.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBias {
    offset_dph: f64,
    turn_on_sigma_dph: f64,
    k1_dph_per_c: f64,
    k2_dph_per_c2: f64,
    k3_dph_per_c_per_s: f64,
    k4_dph_per_c: f64,
    k5_dph: f64,
    warmup_tau_s: f64,
    terms: Model4Terms,
}

impl From<RawBias> for BiasConfig {
    fn from(r: RawBias) -> Self {
        Self {
            model4: Model4 {
                k1_dph_per_c: r.k1_dph_per_c,
                k2_dph_per_c2: r.k2_dph_per_c2,
                k3_dph_per_c_per_s: r.k3_dph_per_c_per_s,
                k4_dph_per_c: r.k4_dph_per_c,
                k5_dph: r.k5_dph,
                warmup_tau_s: r.warmup_tau_s,
                offset_dph: r.offset_dph,
            },
            turn_on_sigma_dph: r.turn_on_sigma_dph,
            terms: r.terms,
        }
    }
}

impl From<BiasConfig> for RawBias {
    fn from(b: BiasConfig) -> Self {
        let m = b.model4;
        Self {
            offset_dph: m.offset_dph,
            turn_on_sigma_dph: b.turn_on_sigma_dph,
            k1_dph_per_c: m.k1_dph_per_c,
            k2_dph_per_c2: m.k2_dph_per_c2,
            k3_dph_per_c_per_s: m.k3_dph_per_c_per_s,
            k4_dph_per_c: m.k4_dph_per_c,
            k5_dph: m.k5_dph,
            warmup_tau_s: m.warmup_tau_s,
            terms: b.terms,
        }
    }
}

/// Random noise terms of the rate output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseConfig {
    /// Angle random walk N, deg/sqrt(h).
    pub arw_deg_per_rt_h: f64,
    /// Bias-instability coefficient B (IEEE: ADEV floor = 0.664 B), deg/h.
    pub bias_instability_dph: f64,
    /// Rate random walk K, deg/h/sqrt(h).
    pub rrw_dph_per_rt_h: f64,
}

/// The two-axis motion simulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableConfig {
    /// Axis directions and gyro mount.
    pub geometry: TableGeometry,
    /// Fastest axis rate, deg/s.
    pub max_rate_dps: f64,
    /// Largest axis acceleration, deg/s^2.
    pub max_acc_dps2: f64,
    /// Table angles at the start.
    pub initial: TableAngles,
    /// Fastest rate in rate mode, deg/s (`max_rate_dps` is the profile of
    /// position moves).
    #[serde(default = "default_rate_mode_max_dps")]
    pub rate_mode_max_dps: f64,
    /// Largest acceleration in rate mode, deg/s^2.
    #[serde(default = "default_rate_mode_max_acc_dps2")]
    pub rate_mode_max_acc_dps2: f64,
}

fn default_rate_mode_max_dps() -> f64 {
    500.0
}

fn default_rate_mode_max_acc_dps2() -> f64 {
    100.0
}

/// Extra effects, named as in the diagnosis library.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectsConfig {
    /// Heating/cooling memory: play operator on the case temperature.
    pub hysteresis: Option<Hysteresis>,
    /// Bias following the case temperature through a first-order lag.
    pub thermal_lag: Option<ThermalLag>,
    /// Bias proportional to gravity in the body frame.
    pub g_sensitivity: Option<GSensitivity>,
    /// Bias proportional to the Earth's field in the body frame.
    pub magnetic_sensitivity: Option<MagneticSensitivity>,
    /// Sensitive axis tilted from the body x axis.
    pub axis_misalignment: Option<AxisMisalignment>,
    /// Scale factor drifting with block temperature.
    pub scale_factor_temperature: Option<ScaleFactorTemperature>,
    /// A slow periodic disturbance of the bias, outside the diagnosis
    /// library (its self-check uses it as the effect it must not name).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub periodic: Option<Periodic>,
    /// The bench's, not the unit's: the Earth rate the unit senses off
    /// the one the bench states (a lot's diagnosis names it; a twin of a
    /// unit on that bench plays it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub earth_rate_error: Option<EarthRateError>,
}

/// The temperature a memory effect (hysteresis, thermal lag) acts on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectTemperature {
    /// The case, T_K.
    #[default]
    Case,
    /// The block: the mean of the two blocks, (T1 + T2) / 2.
    Block,
    /// The mean of the block and the case.
    Mean,
}

impl EffectTemperature {
    /// Every form, in the order the diagnosis tries them.
    pub const ALL: [Self; 3] = [Self::Case, Self::Block, Self::Mean];

    /// Its name in the configuration and the diagnosis.
    pub fn name(self) -> &'static str {
        match self {
            Self::Case => "case",
            Self::Block => "block",
            Self::Mean => "mean",
        }
    }

    /// Its value from the case and the two block temperatures, degC.
    pub fn of(self, case_c: f64, t1_c: f64, t2_c: f64) -> f64 {
        let block = 0.5 * (t1_c + t2_c);
        match self {
            Self::Case => case_c,
            Self::Block => block,
            Self::Mean => 0.5 * (block + case_c),
        }
    }

    fn is_case(&self) -> bool {
        *self == Self::Case
    }
}

/// The shape of a hysteresis loop.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HysteresisShape {
    /// One play (backlash) operator: sharp corners.
    #[default]
    Play,
    /// The mean of plays of half-widths 0.25 to 1.75 times `width_c`: the
    /// loop's corners rounded, as a unit's many internal memories would
    /// make them (the diagnosis library has only the sharp play).
    Smooth,
}

impl HysteresisShape {
    fn is_play(&self) -> bool {
        *self == Self::Play
    }
}

/// `amplitude * (y - T) / width`, y the play (backlash) operator of a
/// temperature T (`temperature`, the case unless said) with half-width
/// `width_c`: `-amplitude` while heating, `+amplitude` while cooling.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Hysteresis {
    /// Whether the effect acts.
    pub enabled: bool,
    /// Bias step between heating and cooling branches / 2, deg/h.
    pub amplitude_dph: f64,
    /// Half-width of the play operator, degC.
    pub width_c: f64,
    /// The temperature the memory is of.
    #[serde(default, skip_serializing_if = "EffectTemperature::is_case")]
    pub temperature: EffectTemperature,
    /// The loop's shape.
    #[serde(default, skip_serializing_if = "HysteresisShape::is_play")]
    pub shape: HysteresisShape,
}

/// `coeff * (lag(T) - reference)`, lag `order` first-order filters of
/// `tau_s` in cascade on a temperature T (`temperature`, the case unless
/// said).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalLag {
    /// Whether the effect acts.
    pub enabled: bool,
    /// deg/h per degC of the lagged temperature.
    pub coeff_dph_per_c: f64,
    /// Lag time constant, s.
    pub tau_s: f64,
    /// Temperature at which the term is zero, degC.
    pub reference_c: f64,
    /// The temperature lagged.
    #[serde(default, skip_serializing_if = "EffectTemperature::is_case")]
    pub temperature: EffectTemperature,
    /// Filters in cascade (1-3; the diagnosis library has only the first
    /// order).
    #[serde(default = "first_order", skip_serializing_if = "is_first_order")]
    pub order: u8,
}

fn first_order() -> u8 {
    1
}

fn is_first_order(o: &u8) -> bool {
    *o == 1
}

/// `k . g_body`, g in units of g.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GSensitivity {
    /// Whether the effect acts.
    pub enabled: bool,
    /// deg/h per g along body x, y, z.
    pub coeff_dph_per_g: [f64; 3],
}

/// `k . B_body`, B in microtesla.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MagneticSensitivity {
    /// Whether the effect acts.
    pub enabled: bool,
    /// deg/h per microtesla along body x, y, z.
    pub coeff_dph_per_ut: [f64; 3],
}

/// The true sensitive axis is body x turned by small angles about y then z.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisMisalignment {
    /// Whether the effect acts.
    pub enabled: bool,
    /// Tilt about body y, arcmin.
    pub about_y_arcmin: f64,
    /// Tilt about body z, arcmin.
    pub about_z_arcmin: f64,
}

/// Scale factor `1 + ppm * 1e-6 * (T_block - reference)` on the sensed rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleFactorTemperature {
    /// Whether the effect acts.
    pub enabled: bool,
    /// Scale-factor change per degC, ppm.
    pub ppm_per_c: f64,
    /// Temperature of the nominal scale factor, degC.
    pub reference_c: f64,
}

/// `[effects.periodic]`: `amplitude_dph * sin(2 pi t / period_s)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Periodic {
    /// On or off.
    pub enabled: bool,
    /// Amplitude, deg/h.
    pub amplitude_dph: f64,
    /// Period, s.
    pub period_s: f64,
}

/// `[effects.earth_rate_error]`: the Earth rate the unit senses is the
/// one the bench states (from the site's latitude and the table's north)
/// turned by a small angle: the site's latitude or the table's north
/// stated wrong, or the table's axis off level. Every unit on the bench
/// reads it along its sensitive axis alike. The turn adds a vector across
/// the Earth rate, fixed in north-east-down: `latitude_dph` along
/// `(-sin lat, 0, -cos lat)` (the way the Earth rate turns as the
/// latitude grows: a latitude stated `x` rad too high gives
/// `-x * 15.04 deg/h`) and `east_dph` east (an axis turned `psi` rad about
/// down from its stated azimuth gives `-psi * 15.04 cos lat`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EarthRateError {
    /// On or off.
    pub enabled: bool,
    /// Part in the north-down plane, across the Earth rate, deg/h.
    pub latitude_dph: f64,
    /// East part, deg/h.
    pub east_dph: f64,
}

/// The largest Earth-rate error a twin takes, deg/h: an error of the
/// stated site or table turns the Earth rate (15.04 deg/h) by an angle,
/// and more than the Earth rate itself is no such error.
pub const EARTH_RATE_ERROR_MAX_DPH: f64 = 16.0;

impl TwinConfig {
    /// This unit on `bench`'s bench: one of a batch's units keeps its own
    /// thermal network, bias, noise, effects and rate response; the
    /// chamber, the table, the site and the gyro links' rate and
    /// resolution are the bench's, shared by every unit.
    #[must_use]
    pub fn on_bench_of(self, bench: &Self) -> Self {
        Self {
            site: bench.site,
            chamber: bench.chamber.clone(),
            gyro: bench.gyro.clone(),
            table: bench.table.clone(),
            ..self
        }
    }

    /// The embedded default (the study's RL-16 bench).
    pub fn default_rl16() -> Self {
        // The embedded file is validated by a unit test, so this cannot fail.
        match Self::from_source(&Source::from_text(
            "fixtures/twin/rl16.toml",
            DEFAULT_TWIN_TOML,
        )) {
            Ok(cfg) => cfg,
            Err(e) => unreachable!("embedded twin config is invalid: {e}"),
        }
    }

    /// Read and validate a twin file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::from_source(&Source::read(path)?)
    }

    /// Parse and validate a twin configuration from text.
    pub fn from_source(src: &Source) -> Result<Self, ConfigError> {
        let cfg: Self = src.parse()?;
        cfg.validate(&Checker::new(src))?;
        Ok(cfg)
    }

    /// The configuration as TOML text (for logs and `twin-updated.toml`).
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string_pretty(self)
    }

    fn validate(&self, c: &Checker<'_>) -> Result<(), ConfigError> {
        self.site.validate(c, "site")?;

        let ch = &self.chamber;
        c.within(ch.min_c, -100.0, 300.0, "chamber.min_c")?;
        c.within(ch.max_c, -100.0, 300.0, "chamber.max_c")?;
        c.ensure(
            ch.max_c > ch.min_c,
            "chamber.max_c",
            "must be above chamber.min_c",
        )?;
        c.positive(ch.max_ramp_c_per_min, "chamber.max_ramp_c_per_min")?;
        c.positive(ch.air_tau_s, "chamber.air_tau_s")?;
        c.within(ch.initial_c, ch.min_c, ch.max_c, "chamber.initial_c")?;

        self.thermal.validate(c)?;

        let g = &self.gyro;
        c.within(g.frame_rate_hz, 1.0, 100_000.0, "gyro.frame_rate_hz")?;
        c.within(g.lsb_arcsec, 1e-6, 100.0, "gyro.lsb_arcsec")?;
        c.within(g.temp_lsb_c, 1e-6, 1.0, "gyro.temp_lsb_c")?;
        c.within(
            g.frame_clock_error_ppm,
            -MAX_FRAME_CLOCK_ERROR_PPM,
            MAX_FRAME_CLOCK_ERROR_PPM,
            "gyro.frame_clock_error_ppm",
        )?;

        c.non_negative(self.bias.turn_on_sigma_dph, "bias.turn_on_sigma_dph")?;
        c.model4(&self.bias.model4, "bias")?;

        let nz = &self.noise;
        c.non_negative(nz.arw_deg_per_rt_h, "noise.arw_deg_per_rt_h")?;
        c.non_negative(nz.bias_instability_dph, "noise.bias_instability_dph")?;
        c.non_negative(nz.rrw_dph_per_rt_h, "noise.rrw_dph_per_rt_h")?;

        let t = &self.table;
        c.positive(t.max_rate_dps, "table.max_rate_dps")?;
        c.positive(t.max_acc_dps2, "table.max_acc_dps2")?;
        c.positive(t.rate_mode_max_dps, "table.rate_mode_max_dps")?;
        c.positive(t.rate_mode_max_acc_dps2, "table.rate_mode_max_acc_dps2")?;
        t.geometry.validate(c, "table.geometry")?;
        // A table's axes read within a turn or so; an angle far beyond
        // is a slip of the keyboard (1e300 deg was reported as the bench's
        // safe state).
        c.within(
            t.initial.outer_deg,
            -360.0,
            360.0,
            "table.initial.outer_deg",
        )?;
        c.within(
            t.initial.inner_deg,
            -360.0,
            360.0,
            "table.initial.inner_deg",
        )?;

        self.rate_response.validate(c)?;
        self.path_length_control.validate(c)?;
        self.effects.validate(c)
    }
}

impl ThermalConfig {
    /// `[thermal]`: time constants, capacities, offsets, the sensor axis
    /// and the rises, each within what a gyro's network can be.
    fn validate(&self, c: &Checker<'_>) -> Result<(), ConfigError> {
        let th = self;
        c.positive(th.case_tau_s, "thermal.case_tau_s")?;
        c.positive(th.block1_tau_s, "thermal.block1_tau_s")?;
        c.positive(th.block2_tau_s, "thermal.block2_tau_s")?;
        c.positive(th.coupling_tau_s, "thermal.coupling_tau_s")?;
        c.non_negative(th.convection_gain, "thermal.convection_gain")?;
        c.non_negative(th.mount_tau_s, "thermal.mount_tau_s")?;
        c.within(th.air_gain, 0.5, 2.0, "thermal.air_gain")?;
        for (k, v) in th.block_capacity_ratio.iter().enumerate() {
            c.within(
                *v,
                0.0,
                100.0,
                &format!("thermal.block_capacity_ratio[{k}]"),
            )?;
        }
        c.non_negative(th.sink_tau_s, "thermal.sink_tau_s")?;
        c.ensure(
            th.sink_capacity_ratio == 0.0 || th.sink_tau_s > 0.0,
            "thermal.sink_capacity_ratio",
            "a heat sink needs thermal.sink_tau_s above 0 (or set the ratio to 0: no sink)",
        )?;
        c.within(
            th.sink_capacity_ratio,
            0.0,
            100.0,
            "thermal.sink_capacity_ratio",
        )?;
        c.within(
            th.block_capacity_1_over_2,
            0.01,
            100.0,
            "thermal.block_capacity_1_over_2",
        )?;
        for (k, v) in th.sensor_offset_c.iter().enumerate() {
            c.within(*v, -20.0, 20.0, &format!("thermal.sensor_offset_c[{k}]"))?;
        }
        c.direction(&th.sensor_axis_body, "thermal.sensor_axis_body")?;
        c.within(th.case_rise_c, 0.0, 50.0, "thermal.case_rise_c")?;
        c.within(th.block1_rise_c, 0.0, 50.0, "thermal.block1_rise_c")?;
        c.within(th.block2_rise_c, 0.0, 50.0, "thermal.block2_rise_c")?;
        c.within(th.sensor_noise_c, 0.0, 5.0, "thermal.sensor_noise_c")?;
        th.effects.validate(c)
    }
}

impl EffectsConfig {
    fn validate(&self, c: &Checker<'_>) -> Result<(), ConfigError> {
        if let Some(h) = &self.hysteresis {
            c.finite(h.amplitude_dph, "effects.hysteresis.amplitude_dph")?;
            // Up to 1000 degC / 11 days: the diagnosis carries the value
            // with its temperature in one number below 1e6.
            c.within(h.width_c, 1e-3, 1000.0, "effects.hysteresis.width_c")?;
        }
        if let Some(l) = &self.thermal_lag {
            c.finite(l.coeff_dph_per_c, "effects.thermal_lag.coeff_dph_per_c")?;
            c.within(l.tau_s, 1e-3, 1e6 - 1.0, "effects.thermal_lag.tau_s")?;
            c.within(f64::from(l.order), 1.0, 3.0, "effects.thermal_lag.order")?;
            c.finite(l.reference_c, "effects.thermal_lag.reference_c")?;
        }
        if let Some(g) = &self.g_sensitivity {
            for v in g.coeff_dph_per_g {
                c.finite(v, "effects.g_sensitivity.coeff_dph_per_g")?;
            }
        }
        if let Some(m) = &self.magnetic_sensitivity {
            for v in m.coeff_dph_per_ut {
                c.finite(v, "effects.magnetic_sensitivity.coeff_dph_per_ut")?;
            }
        }
        if let Some(a) = &self.axis_misalignment {
            c.within(
                a.about_y_arcmin,
                -600.0,
                600.0,
                "effects.axis_misalignment.about_y_arcmin",
            )?;
            c.within(
                a.about_z_arcmin,
                -600.0,
                600.0,
                "effects.axis_misalignment.about_z_arcmin",
            )?;
        }
        if let Some(s) = &self.scale_factor_temperature {
            c.finite(s.ppm_per_c, "effects.scale_factor_temperature.ppm_per_c")?;
            c.finite(
                s.reference_c,
                "effects.scale_factor_temperature.reference_c",
            )?;
        }
        if let Some(p) = &self.periodic {
            c.finite(p.amplitude_dph, "effects.periodic.amplitude_dph")?;
            c.positive(p.period_s, "effects.periodic.period_s")?;
        }
        if let Some(e) = &self.earth_rate_error {
            let m = EARTH_RATE_ERROR_MAX_DPH;
            c.within(
                e.latitude_dph,
                -m,
                m,
                "effects.earth_rate_error.latitude_dph",
            )?;
            c.within(e.east_dph, -m, m, "effects.earth_rate_error.east_dph")?;
        }
        Ok(())
    }

    /// Names of the enabled effects, as in the diagnosis library.
    pub fn enabled_names(&self) -> Vec<&'static str> {
        let mut out = Vec::new();
        let on = |e: Option<bool>| e.unwrap_or(false);
        if on(self.hysteresis.as_ref().map(|e| e.enabled)) {
            out.push("hysteresis");
        }
        if on(self.thermal_lag.as_ref().map(|e| e.enabled)) {
            out.push("thermal_lag");
        }
        if on(self.g_sensitivity.as_ref().map(|e| e.enabled)) {
            out.push("g_sensitivity");
        }
        if on(self.magnetic_sensitivity.as_ref().map(|e| e.enabled)) {
            out.push("magnetic_sensitivity");
        }
        if on(self.axis_misalignment.as_ref().map(|e| e.enabled)) {
            out.push("axis_misalignment");
        }
        if on(self.scale_factor_temperature.as_ref().map(|e| e.enabled)) {
            out.push("scale_factor_temperature");
        }
        if on(self.periodic.as_ref().map(|e| e.enabled)) {
            out.push("periodic (outside the library)");
        }
        if on(self.earth_rate_error.as_ref().map(|e| e.enabled)) {
            out.push("earth_rate_error");
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(replace: &str, by: &str) -> Result<TwinConfig, ConfigError> {
        assert!(
            DEFAULT_TWIN_TOML.contains(replace),
            "fixture lacks {replace}"
        );
        let text = DEFAULT_TWIN_TOML.replacen(replace, by, 1);
        TwinConfig::from_source(&Source::from_text("rl16.toml", &text))
    }

    fn line_of(needle: &str) -> usize {
        DEFAULT_TWIN_TOML
            .lines()
            .position(|l| l.starts_with(needle))
            .map(|i| i + 1)
            .expect("needle present")
    }

    #[test]
    fn default_fixture_is_valid_and_has_every_effect_off() {
        let cfg = TwinConfig::from_source(&Source::from_text("rl16.toml", DEFAULT_TWIN_TOML))
            .expect("default twin must load");
        assert!(cfg.effects.enabled_names().is_empty());
        let t = cfg.bias.terms;
        assert!(t.gradient && t.gradient_quadratic && t.gradient_rate);
        assert!(t.case_temperature && t.self_heating);
    }

    #[test]
    fn unknown_key_is_refused_with_its_line() {
        let err = with("case_tau_s", "case_tau_sec = 1.0\ncase_tau_s").expect_err("unknown key");
        let msg = err.to_string();
        assert!(msg.contains("unknown field `case_tau_sec`"), "{msg}");
        assert_eq!(err.line(), Some(line_of("case_tau_s")));
    }

    #[test]
    fn missing_field_is_refused_and_named() {
        let line = DEFAULT_TWIN_TOML
            .lines()
            .find(|l| l.starts_with("warmup_tau_s"))
            .expect("fixture has warmup_tau_s");
        let err = with(line, "").expect_err("missing field");
        assert!(
            err.to_string().contains("missing field `warmup_tau_s`"),
            "{err}"
        );
    }

    #[test]
    fn negative_time_constant_is_refused_with_key_and_place() {
        let line = DEFAULT_TWIN_TOML
            .lines()
            .find(|l| l.starts_with("block1_tau_s"))
            .expect("fixture has block1_tau_s");
        let err = with(line, "block1_tau_s = -5.0").expect_err("negative tau");
        let msg = err.to_string();
        assert!(msg.contains("`thermal.block1_tau_s` must be"), "{msg}");
        assert_eq!(err.line(), Some(line_of("block1_tau_s")));
    }

    #[test]
    fn a_sink_ratio_without_a_sink_is_refused() {
        let err = with("case_tau_s", "sink_capacity_ratio = 2.0\ncase_tau_s")
            .expect_err("a ratio with no sink time constant");
        let msg = err.to_string();
        assert!(msg.contains("`thermal.sink_capacity_ratio`"), "{msg}");
        assert!(msg.contains("sink_tau_s above 0"), "{msg}");
    }

    #[test]
    fn latitude_beyond_ninety_is_refused() {
        let line = DEFAULT_TWIN_TOML
            .lines()
            .find(|l| l.starts_with("latitude_deg"))
            .expect("fixture has latitude");
        let err = with(line, "latitude_deg = 91.0").expect_err("latitude > 90");
        assert!(
            err.to_string()
                .contains("`site.latitude_deg` must be between -90 and 90"),
            "{err}"
        );
        assert_eq!(err.line(), Some(line_of("latitude_deg")));
    }

    #[test]
    fn a_frame_clock_error_beyond_a_thousand_ppm_is_refused_with_its_key() {
        let line = DEFAULT_TWIN_TOML
            .lines()
            .find(|l| l.starts_with("temp_lsb_c"))
            .expect("fixture has temp_lsb_c");
        let ok = with(line, &format!("{line}\nframe_clock_error_ppm = -50.0")).expect("50 ppm");
        assert_eq!(ok.gyro.frame_clock_error_ppm, -50.0);
        let err = with(line, &format!("{line}\nframe_clock_error_ppm = 1500.0"))
            .expect_err("beyond 1000 ppm");
        let msg = err.to_string();
        assert!(
            msg.contains("`gyro.frame_clock_error_ppm` must be between -1000 and 1000, got 1500"),
            "{msg}"
        );
        assert_eq!(err.line(), Some(line_of("temp_lsb_c") + 1));
        // Written back when set; at 0 it stays out of the file the twin
        // writes (the logs of runs without it are as before).
        assert!(
            ok.to_toml()
                .expect("renders")
                .contains("frame_clock_error_ppm = -50.0")
        );
        let nominal = with(line, line).expect("as shipped");
        assert!(
            !nominal
                .to_toml()
                .expect("renders")
                .contains("frame_clock_error_ppm")
        );
    }

    #[test]
    fn wrong_type_is_refused() {
        let line = DEFAULT_TWIN_TOML
            .lines()
            .find(|l| l.starts_with("frame_rate_hz"))
            .expect("fixture has frame rate");
        let err = with(line, "frame_rate_hz = \"fast\"").expect_err("string for number");
        assert_eq!(err.line(), Some(line_of("frame_rate_hz")));
    }

    #[test]
    fn round_trips_through_toml() {
        let cfg = TwinConfig::default_rl16();
        let back =
            TwinConfig::from_source(&Source::from_text("x", &cfg.to_toml().expect("renders")))
                .expect("rendered config must load");
        assert_eq!(cfg, back);
    }
}
