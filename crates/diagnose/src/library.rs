//! The candidate library: each effect of diagnosis.md as a named group of
//! regressors built from the logged inputs (temperatures, time, the
//! orientation and the site), mirroring how the twin produces it so a
//! fitted coefficient maps back to a twin parameter.

use std::sync::LazyLock;

use super::data::{RunData, Sample};
use crate::analysis::figures::derivative_by_time;
use crate::analysis::model::DERIVATIVE_HALF_WINDOW_S;
use crate::twin::config::EffectTemperature;

/// Every effect the diagnosis knows, by its library name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Effect {
    /// Warm-up transient exp(-t/tau_w).
    SelfHeating,
    /// d(dT)/dt.
    GradientRate,
    /// dT^2.
    GradientQuadratic,
    /// Case temperature T_K.
    CaseTemperature,
    /// Block gradient dT (model 4's first term; in the base, not a candidate).
    Gradient,
    /// Play operator on the case or block temperature, or their mean.
    Hysteresis,
    /// The case or block temperature, or their mean, through a first-order
    /// lag.
    ThermalLag,
    /// Gravity in the body frame.
    GSensitivity,
    /// The Earth's magnetic field in the body frame.
    MagneticSensitivity,
    /// Earth and table rate on the body's transverse axes (the sensitive axis off by
    /// small angles).
    AxisMisalignment,
    /// Scale factor drifting with the block temperature (times the input rate).
    ScaleFactorTemperature,
    /// The bench's, never a unit's: the Earth rate the bench subtracts
    /// turned from the one the units sense (the site's latitude or the
    /// table's north stated wrong, the table's axis off level), read along
    /// the sensitive axis: a vector fixed in north-east-down across the
    /// Earth rate (a misstated angle turns it, never scales it), its part
    /// in the north-down plane (a latitude's) and its east part (a
    /// north's). Weighed on a lot's runs only ([`BENCH`]): one unit's
    /// runs cannot tell it from the unit's own effects.
    EarthRateError,
    /// Outside the library: a jump of the bias within one run (a ring laser
    /// gyro's mode hop). Its parameter is the stacked row the jump is at
    /// ([`Param::Row`]); [`super::engine::Data::columns`] builds it (never
    /// a candidate).
    BiasStep,
    /// Outside the library: the bias drifting linearly through one run.
    /// Its parameter is the run's index ([`Param::Run`]); built by
    /// [`super::engine::Data::columns`] (never a candidate).
    BiasDrift,
    /// Outside the library: a sine of the bias through one run, its phase
    /// free (a lab's air-conditioning cycle, a periodic supply). Its
    /// parameter is the run's index and the period ([`Param::Periodic`]);
    /// built by [`super::engine::Data::columns`] (never a candidate).
    Periodic,
}

/// An effect's one nonlinear parameter, typed by what it is (each effect
/// takes one kind: [`Effect::grid`] gives its values).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Param {
    /// The effect has none (every linear effect).
    None,
    /// The warm-up's time constant, s ([`Effect::SelfHeating`]).
    TauS(f64),
    /// A memory effect ([`Effect::Hysteresis`], [`Effect::ThermalLag`]):
    /// the temperature it acts on and its width (degC) or time constant (s).
    Memory {
        /// Case, block or their mean.
        on: EffectTemperature,
        /// The play's width, degC, or the lag's time constant, s.
        value: f64,
    },
    /// A bias step: the stacked row it is at ([`Effect::BiasStep`]).
    Row(usize),
    /// A bias drift through this run, by index ([`Effect::BiasDrift`]).
    Run(usize),
    /// A periodic disturbance through one run ([`Effect::Periodic`]).
    Periodic {
        /// The run's index.
        run: usize,
        /// The period, s.
        period_s: f64,
    },
}

impl Param {
    /// The parameter's number, as the report gives it: the time constant,
    /// width or period (`NaN` when the effect has none, a row or run
    /// index as a number).
    pub fn value(self) -> f64 {
        match self {
            Self::None => f64::NAN,
            Self::TauS(v) | Self::Memory { value: v, .. } => v,
            Self::Row(i) | Self::Run(i) => i as f64,
            Self::Periodic { period_s, .. } => period_s,
        }
    }

    /// The same parameter at another value (the temperature, run and kind
    /// kept; a parameter without a value stays as it is).
    pub fn with_value(self, v: f64) -> Self {
        match self {
            Self::TauS(_) => Self::TauS(v),
            Self::Memory { on, .. } => Self::Memory { on, value: v },
            Self::Periodic { run, .. } => Self::Periodic { run, period_s: v },
            other => other,
        }
    }

    /// The temperature a memory effect acts on.
    pub fn temperature(self) -> Option<EffectTemperature> {
        match self {
            Self::Memory { on, .. } => Some(on),
            _ => None,
        }
    }

    /// A key that tells parameters apart bit for bit (the columns a
    /// parameter gives are built once per key).
    pub fn key(self) -> (u8, u64, u64) {
        match self {
            Self::None => (0, 0, 0),
            Self::TauS(v) => (1, 0, v.to_bits()),
            Self::Memory { on, value } => (2, on as u64, value.to_bits()),
            Self::Row(i) => (3, i as u64, 0),
            Self::Run(i) => (4, i as u64, 0),
            Self::Periodic { run, period_s } => (5, run as u64, period_s.to_bits()),
        }
    }
}

/// The units of a lot a term acts in (`lot`: runs of several units
/// stacked, each run a unit's): a set of unit indices, one bit each. A
/// unit's own term acts in its runs alone (its columns zero in the
/// others'); a term the lot shares acts in every unit's runs with one
/// coefficient. A diagnosis of one unit has every term in [`Units::ALL`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Units(u64);

impl Units {
    /// Every unit (the one of a single unit's diagnosis).
    pub const ALL: Self = Self(u64::MAX);
    /// The most units a lot may hold (one bit each).
    pub const MAX: usize = 64;

    /// Unit `u` alone (`u` below [`Units::MAX`]; beyond it, none).
    pub fn one(u: usize) -> Self {
        Self(1_u64.checked_shl(u as u32).unwrap_or(0))
    }

    /// The units `us` (those beyond [`Units::MAX`] left out).
    pub fn of(us: impl IntoIterator<Item = usize>) -> Self {
        Self(us.into_iter().fold(0, |m, u| m | Self::one(u).0))
    }

    /// Whether unit `u` is among them.
    pub fn holds(self, u: usize) -> bool {
        self.0 & Self::one(u).0 != 0
    }

    /// Whether the two share no unit (their columns never meet in a row).
    pub fn apart(self, other: Self) -> bool {
        self.0 & other.0 == 0
    }
}

/// One term of a model: an effect at its parameter, in some units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Term {
    /// The effect.
    pub effect: Effect,
    /// Its nonlinear parameter.
    pub param: Param,
    /// The units it acts in ([`Units::ALL`] but in a lot's own terms).
    pub units: Units,
}

impl Term {
    /// `effect` at `param`, in every unit.
    pub fn new(effect: Effect, param: Param) -> Self {
        Self::in_units(effect, param, Units::ALL)
    }

    /// `effect` at `param`, in `units` alone.
    pub fn in_units(effect: Effect, param: Param, units: Units) -> Self {
        Self {
            effect,
            param,
            units,
        }
    }
}

/// The candidates named in diagnosis.md, in its order.
pub const LIBRARY: [Effect; 10] = [
    Effect::SelfHeating,
    Effect::GradientRate,
    Effect::GradientQuadratic,
    Effect::CaseTemperature,
    Effect::Hysteresis,
    Effect::ThermalLag,
    Effect::GSensitivity,
    Effect::MagneticSensitivity,
    Effect::AxisMisalignment,
    Effect::ScaleFactorTemperature,
];

/// The bench's own effects, weighed only where several units share a
/// bench (`lot`): what the bench states about where it is.
pub const BENCH: [Effect; 1] = [Effect::EarthRateError];

/// Model 4's terms (the base of the reference simulator).
pub const MODEL4: [Effect; 5] = [
    Effect::Gradient,
    Effect::GradientQuadratic,
    Effect::GradientRate,
    Effect::CaseTemperature,
    Effect::SelfHeating,
];

/// Grids of the one nonlinear parameter some effects have (ours: spans
/// the time constants and play widths a gyro on a -40..+50 cycle shows;
/// a play wider than 16 degC on a 90 degC swing, or a lag longer than 4 h
/// on a day's cycle, is hardly told from a temperature term).
const SELF_HEATING_TAU_S: [f64; 6] = [150.0, 300.0, 600.0, 1200.0, 2400.0, 4800.0];
const HYSTERESIS_WIDTH_C: [f64; 6] = [0.5, 1.0, 2.0, 4.0, 8.0, 16.0];
const THERMAL_LAG_TAU_S: [f64; 6] = [300.0, 900.0, 1800.0, 3600.0, 7200.0, 14_400.0];

/// Every temperature with every value of a grid.
fn forms(values: &[f64]) -> Vec<Param> {
    EffectTemperature::ALL
        .iter()
        .flat_map(|&on| values.iter().map(move |&value| Param::Memory { on, value }))
        .collect()
}

static SELF_HEATING_GRID: LazyLock<Vec<Param>> =
    LazyLock::new(|| SELF_HEATING_TAU_S.iter().map(|&v| Param::TauS(v)).collect());
static HYSTERESIS_GRID: LazyLock<Vec<Param>> = LazyLock::new(|| forms(&HYSTERESIS_WIDTH_C));
static THERMAL_LAG_GRID: LazyLock<Vec<Param>> = LazyLock::new(|| forms(&THERMAL_LAG_TAU_S));

impl Effect {
    /// Library name (diagnosis.md).
    pub fn name(self) -> &'static str {
        match self {
            Self::SelfHeating => "self_heating",
            Self::GradientRate => "gradient_rate",
            Self::GradientQuadratic => "gradient_quadratic",
            Self::CaseTemperature => "case_temperature",
            Self::Gradient => "gradient",
            Self::Hysteresis => "hysteresis",
            Self::ThermalLag => "thermal_lag",
            Self::GSensitivity => "g_sensitivity",
            Self::MagneticSensitivity => "magnetic_sensitivity",
            Self::AxisMisalignment => "axis_misalignment",
            Self::ScaleFactorTemperature => "scale_factor_temperature",
            Self::EarthRateError => "earth_rate_error",
            Self::BiasStep => "bias_step",
            Self::BiasDrift => "bias_drift",
            Self::Periodic => "periodic",
        }
    }

    /// By library name.
    pub fn from_name(name: &str) -> Option<Self> {
        LIBRARY
            .iter()
            .chain(&BENCH)
            .chain(&[Self::Gradient])
            .copied()
            .find(|e| e.name() == name)
    }

    /// Values of the nonlinear parameter to try (one [`Param::None`] when
    /// none; the outside disturbances' parameters come from the data).
    pub fn grid(self) -> &'static [Param] {
        match self {
            Self::SelfHeating => &SELF_HEATING_GRID,
            Self::Hysteresis => &HYSTERESIS_GRID,
            Self::ThermalLag => &THERMAL_LAG_GRID,
            _ => &[Param::None],
        }
    }

    /// Names of the regressors (the fitted coefficients).
    pub fn terms(self) -> &'static [&'static str] {
        match self {
            Self::SelfHeating => &["k5_dph"],
            Self::GradientRate => &["k3_dph_per_c_per_s"],
            Self::GradientQuadratic => &["k2_dph_per_c2"],
            Self::CaseTemperature => &["k4_dph_per_c"],
            Self::Gradient => &["k1_dph_per_c"],
            Self::Hysteresis => &["amplitude_dph"],
            Self::ThermalLag => &["coeff_dph_per_c"],
            Self::GSensitivity => &["x_dph_per_g", "y_dph_per_g", "z_dph_per_g"],
            Self::MagneticSensitivity => &["x_dph_per_ut", "y_dph_per_ut", "z_dph_per_ut"],
            Self::AxisMisalignment => &["earth_y", "earth_z"],
            Self::ScaleFactorTemperature => &["per_c"],
            Self::EarthRateError => &["latitude_dph", "east_dph"],
            Self::BiasStep => &["step_dph"],
            Self::BiasDrift => &["drift_dph"],
            Self::Periodic => &["sin_dph", "cos_dph"],
        }
    }

    /// Fitted quantities: the regressors plus the nonlinear parameter.
    pub fn complexity(self) -> usize {
        self.terms().len() + usize::from(self.parameter().is_some())
    }

    /// The nonlinear parameter's name, when there is one.
    pub fn parameter(self) -> Option<&'static str> {
        match self {
            Self::SelfHeating => Some("warmup_tau_s"),
            Self::Hysteresis => Some("width_c"),
            Self::ThermalLag => Some("tau_s"),
            _ => None,
        }
    }

    /// Whether its parameter carries a temperature ([`Param::Memory`]).
    pub fn has_forms(self) -> bool {
        matches!(self, Self::Hysteresis | Self::ThermalLag)
    }

    /// Whether this is a disturbance outside the library (a nuisance the
    /// selection weighs a candidate against, never named as an effect).
    pub fn is_outside(self) -> bool {
        matches!(self, Self::BiasStep | Self::BiasDrift | Self::Periodic)
    }

    /// Regressor columns over one run's samples, for parameter `p` (the
    /// outside disturbances span runs and are built from the stacked data:
    /// here they are zero).
    pub fn columns(self, run: &RunData, p: Param) -> Vec<Vec<f64>> {
        let s = &run.samples;
        let col = |f: &dyn Fn(&Sample) -> f64| -> Vec<f64> { s.iter().map(f).collect() };
        match self {
            Self::Gradient => vec![col(&|x| x.iv.gradient_c())],
            Self::GradientQuadratic => vec![col(&|x| x.iv.gradient_c().powi(2))],
            Self::GradientRate => vec![gradient_rate(s)],
            Self::CaseTemperature => vec![col(&|x| x.iv.tcase_c)],
            Self::SelfHeating => {
                let tau = p.value();
                vec![col(&|x| (-x.iv.time_s / tau).exp())]
            }
            Self::Hysteresis => {
                let (t, w) = (p.temperature().unwrap_or_default(), p.value());
                vec![play(s, t, w)]
            }
            Self::ThermalLag => {
                let (t, tau) = (p.temperature().unwrap_or_default(), p.value());
                vec![lag(s, t, tau)]
            }
            Self::GSensitivity => (0..3).map(|i| col(&|x| x.gravity_body()[i])).collect(),
            Self::MagneticSensitivity => (0..3)
                .map(|i| col(&|x| x.magnetic_body(&run.site)[i]))
                .collect(),
            Self::AxisMisalignment => (1..3)
                .map(|i| col(&|x| x.inertial_rate_body(&run.site)[i]))
                .collect(),
            Self::EarthRateError => {
                let across = run.site.earth_rate_turned_ned();
                vec![
                    col(&|x| x.orientation.sensitive_axis_ned().dot(&across)),
                    col(&|x| x.orientation.sensitive_axis_ned().y),
                ]
            }
            Self::ScaleFactorTemperature => vec![col(&|x| {
                x.iv.reference_dph * (0.5 * (x.iv.t1_c + x.iv.t2_c) - 20.0)
            })],
            Self::BiasStep | Self::BiasDrift | Self::Periodic => {
                vec![vec![0.0; s.len()]; self.terms().len()]
            }
        }
    }
}

/// d(dT)/dt by local regression, as model 4 uses it, over the samples'
/// own times (never across the gap between two records).
fn gradient_rate(s: &[Sample]) -> Vec<f64> {
    let t: Vec<f64> = s.iter().map(|x| x.iv.time_s).collect();
    let g: Vec<f64> = s.iter().map(|x| x.iv.gradient_c()).collect();
    derivative_by_time(&t, &g, DERIVATIVE_HALF_WINDOW_S)
}

/// A sample's temperature `t` (case, block or mean), from its sensors.
fn temperature(x: &Sample, t: EffectTemperature) -> f64 {
    t.of(x.iv.tcase_c, x.iv.t1_c, x.iv.t2_c)
}

/// Play (backlash) operator of width `w` on temperature `form`,
/// normalised as the twin's hysteresis: (y - T) / w, in -1..1.
fn play(s: &[Sample], form: EffectTemperature, w: f64) -> Vec<f64> {
    let mut y: Option<f64> = None;
    s.iter()
        .map(|x| {
            let t = temperature(x, form);
            let v = y.get_or_insert(t);
            *v = v.clamp(t - w, t + w);
            (*v - t) / w
        })
        .collect()
}

/// Temperature `form` through a first-order lag of `tau` s.
fn lag(s: &[Sample], form: EffectTemperature, tau: f64) -> Vec<f64> {
    let mut y: Option<f64> = None;
    let mut last_t: Option<f64> = None;
    s.iter()
        .map(|x| {
            let t = temperature(x, form);
            let dt = last_t.map_or(1.0, |l| (x.iv.time_s - l).max(0.0));
            last_t = Some(x.iv.time_s);
            let v = y.get_or_insert(t);
            *v += (t - *v) * (-(-dt / tau).exp_m1());
            *v
        })
        .collect()
}

/// The shipped procedure that tells two effects apart, when there is one
/// (run it on the same unit and diagnose it with the runs that could not).
pub fn separating_procedure(a: Effect, b: Effect) -> Option<&'static str> {
    use Effect::*;
    let pair = |x: Effect, y: Effect| (a == x && b == y) || (a == y && b == x);
    if pair(AxisMisalignment, GSensitivity) || pair(AxisMisalignment, MagneticSensitivity) {
        Some("procedures/misalignment.toml")
    } else if a == ScaleFactorTemperature || b == ScaleFactorTemperature {
        Some("procedures/separating.toml")
    } else {
        None
    }
}

/// Which extra position or run would tell two effects apart (ours, from
/// the geometry of `docs/physics.md`: Earth rate, gravity and the magnetic field
/// lie nearly in the north-down plane).
pub fn separate_with(a: Effect, b: Effect) -> String {
    use Effect::*;
    let pair = |x: Effect, y: Effect| (a == x && b == y) || (a == y && b == x);
    if pair(AxisMisalignment, GSensitivity) || pair(AxisMisalignment, MagneticSensitivity) {
        "procedures/misalignment.toml, diagnosed with these runs: the axis horizontal, the outer axis turning one way and the other at two rolls 90 deg apart (a misaligned axis reads a share of the table rate that changes sign with it; what gravity and the magnetic field add does not). At one site Earth rate lies in the plane of gravity and the magnetic field, so no static position tells a misalignment from a mix of g- and magnetic sensitivity".into()
    } else if pair(GSensitivity, MagneticSensitivity) {
        "a run with the magnetic field changed (a Helmholtz coil or a mu-metal shield), or roll positions about a north-pointing axis".into()
    } else if pair(Hysteresis, ThermalLag) {
        "a long soak after a temperature step (a lag decays at constant temperature, hysteresis does not)".into()
    } else if pair(ThermalLag, CaseTemperature)
        || pair(ThermalLag, GradientRate)
        || pair(ThermalLag, GradientQuadratic)
    {
        "no temperature profile alone: only the part of a case-temperature lag that model 4's block-gradient terms cannot follow tells them apart (a fifth of it in the study's thermal cycle; ramps at two rates and a pause mid-ramp did not add to it in the self-check); a temperature measured where the lag acts would".into()
    } else if a == ScaleFactorTemperature || b == ScaleFactorTemperature {
        "procedures/separating.toml, the thermal cycle repeated axis down: the Earth rate on the axis changes sign and a scale-factor drift with it, a bias drift does not".into()
    } else if pair(SelfHeating, CaseTemperature) || pair(SelfHeating, ThermalLag) {
        "a power-on at another chamber temperature (a cold start after a soak at -20 degC)".into()
    } else {
        "a run with another temperature profile and more positions".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_memory_effects_parameter_keeps_its_temperature_and_its_value_exactly() {
        // Packed into one f64 (value + 1e6 x the temperature's index), a
        // width of sqrt(8 x 16) degC on the block came back 1e-10 off.
        let w = (8.0_f64 * 16.0).sqrt();
        let p = Param::Memory {
            on: EffectTemperature::Block,
            value: 8.0,
        }
        .with_value(w);
        assert_eq!(p.temperature(), Some(EffectTemperature::Block));
        assert_eq!(p.value().to_bits(), w.to_bits());
        let on_case = Param::Memory {
            on: EffectTemperature::Case,
            value: w,
        };
        assert_ne!(p.key(), on_case.key());
        assert_eq!(Param::TauS(w).with_value(2.0), Param::TauS(2.0));
        assert_eq!(Param::Row(7).with_value(2.0), Param::Row(7));
        assert_ne!(Param::Row(7).key(), Param::Run(7).key());
    }

    #[test]
    fn every_grid_holds_its_effects_kind_of_parameter() {
        for e in LIBRARY.iter().chain(&[Effect::Gradient]) {
            for p in e.grid() {
                let fits = match p {
                    Param::None => e.parameter().is_none(),
                    Param::TauS(_) => *e == Effect::SelfHeating,
                    Param::Memory { .. } => e.has_forms(),
                    Param::Row(_) | Param::Run(_) | Param::Periodic { .. } => false,
                };
                assert!(fits, "{e:?} at {p:?}");
            }
        }
    }
}

#[cfg(test)]
#[path = "library_tests.rs"]
mod more_tests;
