//! Acceptance procedures in TOML (`docs/procedures.md`), loaded in two
//! stages: [`raw`] mirrors the file; [`Procedure::load`] validates it
//! against the bench (chamber limits, table reach) and expands `repeat`
//! into plain steps. The sequencer only ever sees a validated procedure.

pub mod estimate;
pub mod key;
pub mod raw;
pub mod rule;

pub use key::{KeyPart, StepKey, StepKeyBuf};
pub use rule::{DecisionRule, Statement};

use std::collections::HashSet;
use std::path::Path;

use serde::Serialize;

use crate::config::{Checker, ConfigError, Source};
use crate::geometry::{Orientation, TableAngles, TableGeometry};
use crate::limits::BenchLimits;
use raw::{RawPosition, RawProcedure, RawStep};

/// Longest a single step may last (a wait, a record, a soak's timeout), s:
/// seven days, longer than any acceptance a lab runs in one go.
pub const MAX_STEP_S: f64 = 7.0 * 86_400.0;

/// Slowest chamber ramp a procedure may ask for, degC/min: slower ramps are
/// a constant set point in all but name.
pub const MIN_RAMP_C_PER_MIN: f64 = 0.01;

/// Which group a step belongs to (the log's word for it).
/// Which group a step belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Group {
    /// Brings the bench to its starting state.
    Setup,
    /// The measurement.
    Main,
    /// Always runs once setup has started.
    Cleanup,
}

impl Group {
    /// Its name in a step's dotted key (`setup.0`, `main.3`).
    pub fn key(self) -> &'static str {
        match self {
            Self::Setup => "setup",
            Self::Main => "main",
            Self::Cleanup => "cleanup",
        }
    }
}

/// Figures a `measure` step can compute (`docs/figures.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    /// 1-sigma of `averaging_s` averages of the Earth-removed rate.
    BiasStability,
    /// Peak-to-peak of the Earth-removed rate smoothed over `averaging_s`.
    DriftPp,
    /// The same after model-4 compensation by coefficients that did not
    /// see the judged records: the unit's set (`--coeffs`), else model 4
    /// fitted held out within the run (blocked cross-validation).
    CompensatedDriftPp,
    /// The same on the residual of model 4 fitted to the very records it
    /// is taken on: the fit's residual, informative.
    CompensatedDriftFitResidualPp,
    /// Self-heating transient over the first half hour after power-on.
    SelfHeating,
    /// Mean Earth-removed rate.
    MeanBias,
    /// Slope of the Earth-removed rate against the case temperature,
    /// deg/h per degC (jointly with the temperature rate).
    TemperatureSensitivity,
    /// Slope against the rate of change of the case temperature, deg/h
    /// per degC/min (jointly with the temperature).
    TemperatureRateSensitivity,
    /// Scale factor error against nominal, ppm: the least-squares line of
    /// output against input rate over rate records.
    ScaleFactor,
    /// Largest residual of that line, ppm of the output there.
    ScaleFactorNonlinearity,
    /// Scale factor for positive minus negative input rates, ppm.
    ScaleFactorAsymmetry,
    /// Scale factor change per degC of the block (rate records at several
    /// temperatures), ppm/degC.
    ScaleFactorTemperature,
    /// Half-width of the input band around zero where the output is under
    /// 10 % of the expected, deg/h (IEEE dead band), from a lock-in fit.
    DeadBand,
    /// Smallest input giving at least 50 % of the expected output, deg/h
    /// (IEEE threshold), from the same fit.
    Threshold,
    /// Turn-on to turn-on bias repeatability, deg/h: 1-sigma of the mean
    /// Earth-removed rates of records made after separate turn-ons (one
    /// record per turn-on), with its standard error for their number.
    BiasRepeatability,
    /// Warm-up time, s: from the start of a record made at turn-on until
    /// the `averaging_s` mean of the Earth-removed rate stays within
    /// `band` of its settled value (the mean of the record's last quarter).
    WarmUpTime,
    /// Tilt of the input axis towards the turning table axis, arcsec: the
    /// slope of the Earth-removed rate against the rate of an axis turning
    /// across the sensitive axis (records at that rate both ways).
    AxisMisalignment,
    /// Power the unit draws at steady state, W: the mean of the supply's
    /// readings (voltage times current) during the records.
    PowerSteady,
    /// Peak power the unit draws, W: the highest supply reading from the
    /// turn-on each record was made after to the record's end (the
    /// readings are taken fast for the first second after a turn-on).
    PowerPeak,
    /// Bias sensitivity to gravity along the sensitive axis, deg/h/g: the
    /// slope of the records' mean Earth-removed rates against the gravity
    /// on the axis in each (minus the sine of the axis's elevation: -1 g
    /// axis up), by least squares, with its standard error (IEEE Std 647's
    /// g-sensitive drift).
    GSensitivity,
    /// Spread of the bias between positions, deg/h: the largest minus the
    /// smallest of the records' mean Earth-removed rates.
    BiasSpread,
    /// Angle random walk N, deg/sqrt(h), from the Allan deviation of the
    /// records' Earth-removed rate (IEEE Std 952 Annex C); its upper bound
    /// from the curve where the curve does not resolve it.
    Arw,
    /// Bias instability B (the deviation's flicker floor / 0.664), deg/h,
    /// the same way.
    BiasInstability,
    /// Rate random walk K, deg/h/sqrt(h), the same way.
    RateRandomWalk,
}

/// `s` with `{label}` replaced by a repeat's position label.
fn with_label(s: &str, label: Option<&str>) -> String {
    match label {
        Some(l) => s.replace("{label}", l),
        None => s.to_owned(),
    }
}

impl Metric {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "bias_stability" => Self::BiasStability,
            "drift_pp" => Self::DriftPp,
            "compensated_drift_pp" => Self::CompensatedDriftPp,
            "compensated_drift_fit_residual_pp" => Self::CompensatedDriftFitResidualPp,
            "self_heating" => Self::SelfHeating,
            "mean_bias" => Self::MeanBias,
            "temperature_sensitivity" => Self::TemperatureSensitivity,
            "temperature_rate_sensitivity" => Self::TemperatureRateSensitivity,
            "scale_factor" => Self::ScaleFactor,
            "scale_factor_nonlinearity" => Self::ScaleFactorNonlinearity,
            "scale_factor_asymmetry" => Self::ScaleFactorAsymmetry,
            "scale_factor_temperature" => Self::ScaleFactorTemperature,
            "dead_band" => Self::DeadBand,
            "threshold" => Self::Threshold,
            "axis_misalignment" => Self::AxisMisalignment,
            "bias_repeatability" => Self::BiasRepeatability,
            "warm_up_time" => Self::WarmUpTime,
            "power_steady" => Self::PowerSteady,
            "power_peak" => Self::PowerPeak,
            "g_sensitivity" => Self::GSensitivity,
            "bias_spread" => Self::BiasSpread,
            "arw" => Self::Arw,
            "bias_instability" => Self::BiasInstability,
            "rate_random_walk" => Self::RateRandomWalk,
            _ => return None,
        })
    }

    fn needs_averaging(self) -> bool {
        matches!(
            self,
            Self::BiasStability
                | Self::DriftPp
                | Self::CompensatedDriftPp
                | Self::CompensatedDriftFitResidualPp
                | Self::WarmUpTime
        )
    }
}

/// A validated measurement.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Measure {
    /// Name in the report.
    pub name: String,
    /// Figure.
    pub metric: Metric,
    /// Record labels it is computed on.
    pub records: Vec<String>,
    /// Averaging time, s (0 where the metric has none).
    pub averaging_s: f64,
    /// The band of a warm-up time, deg/h (none for other metrics).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub band: Option<f64>,
    /// Lower limit.
    pub low: Option<f64>,
    /// Upper limit.
    pub high: Option<f64>,
    /// Unit.
    pub unit: String,
}

/// What a step does.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "action", rename_all = "snake_case")]
pub enum StepKind {
    /// New chamber set point and ramp; returns at once (the chamber ramps
    /// while the next steps run).
    Chamber {
        /// degC.
        set_c: f64,
        /// degC/min.
        ramp_c_per_min: f64,
    },
    /// Wait until the chamber is within `band_c` of its set point and the
    /// case temperature changes slower than `case_slope_c_per_min`, both
    /// for `hold_s`; error after `timeout_s`.
    Soak {
        /// degC.
        band_c: f64,
        /// degC/min.
        case_slope_c_per_min: f64,
        /// s.
        hold_s: f64,
        /// s.
        timeout_s: f64,
    },
    /// Move the table and wait until in position.
    Move {
        /// Table angles to go to.
        angles: TableAngles,
        /// The unit's orientation there.
        orientation: Orientation,
    },
    /// Switch the unit's supply output, and wait until it reads so.
    Power {
        /// On or off.
        on: bool,
        /// Voltage when on, V.
        volts: f64,
        /// Current limit when on, A.
        limit_a: f64,
        /// Switching on a unit found powered: switched off and rested
        /// this long first, s (none: the run refuses to go on).
        rest_if_on_s: Option<f64>,
    },
    /// Let time pass.
    Wait {
        /// s.
        duration_s: f64,
    },
    /// Record the gyro under `label`.
    Record {
        /// Label.
        label: String,
        /// s.
        duration_s: f64,
    },
    /// Turn an axis in rate mode at `rate_dps` and wait until it turns at
    /// that rate (0: at rest), then `settle_s` more.
    Turn {
        /// The inner axis (else the outer).
        inner: bool,
        /// deg/s.
        rate_dps: f64,
        /// s.
        settle_s: f64,
        /// Ramp acceleration, deg/s^2 (none: the table's own).
        acc_dps2: Option<f64>,
    },
    /// Compute and judge a figure.
    Measure(Measure),
    /// A note for the operator.
    Note {
        /// Text.
        text: String,
    },
    /// Operator confirmation (automatic on simulated benches).
    Prompt {
        /// Text.
        text: String,
    },
}

impl StepKind {
    /// The `action` of the procedure file that makes this step.
    pub fn action(&self) -> &'static str {
        match self {
            Self::Chamber { .. } => "chamber",
            Self::Soak { .. } => "soak",
            Self::Move { .. } => "move",
            Self::Power { .. } => "power",
            Self::Wait { .. } => "wait",
            Self::Record { .. } => "record",
            Self::Turn { .. } => "turn",
            Self::Measure(_) => "measure",
            Self::Note { .. } => "note",
            Self::Prompt { .. } => "prompt",
        }
    }
}

/// How long a supply output may take to read what a `power` step asked,
/// device time, s (ours: a bench supply settles in well under a second;
/// the rest is the link).
pub const POWER_TIMEOUT_S: f64 = 10.0;

/// One step with where it came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Step {
    /// Group.
    pub group: Group,
    /// Dotted key of the step in the file (`main.3`, `main.2.steps.1`).
    pub key: String,
    /// Line in the file.
    pub line: usize,
    /// What it does.
    #[serde(flatten)]
    pub kind: StepKind,
}

impl Step {
    /// The `/events` line that starts it: `step KEY (line N): description`
    /// (`cleanup KEY ...` in cleanup). Replay finds steps by this line.
    pub fn start_message(&self) -> String {
        let word = if self.group == Group::Cleanup {
            "cleanup"
        } else {
            "step"
        };
        format!(
            "{word} {} (line {}): {}",
            self.key,
            self.line,
            self.describe()
        )
    }

    /// A short human description.
    pub fn describe(&self) -> String {
        match &self.kind {
            StepKind::Chamber {
                set_c,
                ramp_c_per_min,
            } => {
                format!("chamber to {set_c:+.1} degC at {ramp_c_per_min} degC/min")
            }
            StepKind::Soak { band_c, hold_s, .. } => {
                format!("soak (within {band_c} degC, {hold_s:.0} s)")
            }
            StepKind::Move {
                angles,
                orientation,
            } => format!(
                "move to az {:.1} el {:.1} roll {:.1} (outer {:.2}, inner {:.2})",
                orientation.azimuth_deg,
                orientation.elevation_deg,
                orientation.roll_deg,
                angles.outer_deg,
                angles.inner_deg
            ),
            StepKind::Power {
                on: true,
                volts,
                limit_a,
                ..
            } if *volts > 0.0 => {
                format!("power the unit on at {volts} V (limit {limit_a} A)")
            }
            StepKind::Power { on: true, .. } => "the operator switches the unit on".to_owned(),
            StepKind::Power {
                on: false, volts, ..
            } if *volts > 0.0 => "power the unit off".to_owned(),
            StepKind::Power { on: false, .. } => "the operator switches the unit off".to_owned(),
            StepKind::Wait { duration_s } => format!("wait {duration_s:.0} s"),
            StepKind::Record { label, duration_s } => {
                format!("record {label} for {duration_s:.0} s")
            }
            StepKind::Turn {
                inner, rate_dps, ..
            } => {
                let axis = if *inner { "inner" } else { "outer" };
                if *rate_dps == 0.0 {
                    format!("bring the {axis} axis to rest")
                } else if rate_dps.abs() < 0.1 {
                    format!("turn the {axis} axis at {:+.2} deg/h", rate_dps * 3600.0)
                } else {
                    format!("turn the {axis} axis at {rate_dps:+} deg/s")
                }
            }
            StepKind::Measure(m) => format!("measure {}", m.name),
            StepKind::Note { text } => format!("note: {text}"),
            StepKind::Prompt { text } => format!("prompt: {text}"),
        }
    }
}

/// Procedure metadata.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Meta {
    /// Name.
    pub name: String,
    /// Description.
    pub description: String,
    /// Unit type.
    pub dut_type: String,
    /// Spec judged against.
    pub spec: String,
    /// The decision rule its figures are judged by.
    pub decision_rule: DecisionRule,
    /// Whether the file names its rule (a log of an earlier format that
    /// names none was judged by simple acceptance, and is replayed so).
    pub rule_named: bool,
}

/// A validated procedure.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Procedure {
    /// Metadata.
    pub meta: Meta,
    /// The file's text (logged with the run).
    #[serde(skip)]
    pub text: String,
    /// Setup steps.
    pub setup: Vec<Step>,
    /// Main steps.
    pub main: Vec<Step>,
    /// Cleanup steps.
    pub cleanup: Vec<Step>,
}

/// What validation checks steps against.
#[derive(Debug, Clone)]
pub struct Context<'a> {
    /// Bench limits and geometry.
    pub bench: &'a BenchLimits,
}

impl Procedure {
    /// Read and validate a procedure file against a bench.
    pub fn load(path: &Path, bench: &BenchLimits) -> Result<Self, ConfigError> {
        Self::from_source(&Source::read(path)?, bench)
    }

    /// Parse and validate procedure text against a bench.
    pub fn from_source(src: &Source, bench: &BenchLimits) -> Result<Self, ConfigError> {
        let raw: RawProcedure = src.parse()?;
        let mut v = Validator {
            src,
            c: Checker::new(src),
            bench,
            records: Labels::default(),
            measures: HashSet::new(),
        };
        let meta = Meta {
            name: raw.procedure.name.clone(),
            description: raw.procedure.description.clone(),
            dut_type: raw.procedure.dut_type.clone(),
            spec: raw.procedure.spec.clone(),
            decision_rule: match &raw.procedure.decision_rule {
                Some(rule) => DecisionRule::parse(rule, raw.procedure.guard_band_u)
                    .map_err(|e| src.invalid("procedure.decision_rule", e.to_string()))?,
                None if raw.procedure.guard_band_u.is_some() => {
                    return Err(src.invalid(
                        "procedure.guard_band_u",
                        "goes with decision_rule = \"guarded\"",
                    ));
                }
                None => DecisionRule::default(),
            },
            rule_named: raw.procedure.decision_rule.is_some(),
        };
        v.c.ensure(
            is_path_safe_name(&meta.name),
            "procedure.name",
            &format!(
                "{:?} cannot name a run directory: use 1 to 64 letters, digits, `-`, `_` or `.`, starting with a letter or digit",
                meta.name
            ),
        )?;
        let setup = v.group(Group::Setup, &raw.setup)?;
        let main = v.group(Group::Main, &raw.main)?;
        v.c.ensure(
            !main.is_empty(),
            "procedure",
            "needs at least one [[main]] step",
        )?;
        let cleanup = v.group(Group::Cleanup, &raw.cleanup)?;
        Ok(Self {
            meta,
            text: src.text.clone(),
            setup,
            main,
            cleanup,
        })
    }

    /// Every step in run order.
    pub fn steps(&self) -> impl Iterator<Item = &Step> {
        self.setup.iter().chain(&self.main).chain(&self.cleanup)
    }

    /// Every measurement.
    pub fn measures(&self) -> impl Iterator<Item = &Measure> {
        self.steps().filter_map(|s| match &s.kind {
            StepKind::Measure(m) => Some(m),
            _ => None,
        })
    }
}

struct Validator<'a> {
    src: &'a Source,
    c: Checker<'a>,
    bench: &'a BenchLimits,
    records: Labels,
    measures: HashSet<String>,
}

/// The record labels made so far: unique, in the order they are made.
#[derive(Default)]
struct Labels {
    set: HashSet<String>,
    order: Vec<String>,
}

impl Labels {
    /// Take `label` for a new record (the step's `key`): plain text, and
    /// not used before.
    fn claim(&mut self, c: &Checker<'_>, label: &str, key: &str) -> Result<(), ConfigError> {
        c.ensure(is_plain_text(label), key, PLAIN_TEXT)?;
        c.ensure(
            !self.set.contains(label),
            key,
            &format!("record {label:?} is already used; labels must be unique"),
        )?;
        self.set.insert(label.to_owned());
        self.order.push(label.to_owned());
        Ok(())
    }
}

impl Validator<'_> {
    fn group(&mut self, group: Group, raw: &[RawStep]) -> Result<Vec<Step>, ConfigError> {
        let mut out = Vec::new();
        for (i, step) in raw.iter().enumerate() {
            let key = format!("{}.{i}", group.key());
            self.step(group, &key, step, None, &mut out)?;
        }
        // A rate step that keeps turning hands the table to another rate
        // step, never to a move, a record at rest or the end of the group.
        // A rate step on the other axis would leave this one turning
        // through its record, the rest of the procedure and cleanup.
        for (i, s) in out.iter().enumerate() {
            let turning = match (i.checked_sub(1).map(|p| &out[p].kind), &s.kind) {
                (
                    Some(StepKind::Turn {
                        inner, rate_dps, ..
                    }),
                    StepKind::Record { .. },
                ) if *rate_dps != 0.0 => Some(*inner),
                _ => None,
            };
            let Some(inner) = turning else { continue };
            let next_turns_it = out.get(i + 1).is_some_and(
                |n| matches!(n.kind, StepKind::Turn { inner: next, .. } if next == inner),
            );
            if !next_turns_it {
                let key = StepKey::parse(&s.key).step();
                let axis = if inner { "inner" } else { "outer" };
                return Err(self.src.invalid(
                    &format!("{key}.keep_turning"),
                    format!(
                        "a rate step that keeps turning must be followed by another rate step on the same axis (the {axis} axis would still turn through what comes next)"
                    ),
                ));
            }
        }
        Ok(out)
    }

    /// A step duration: at least a second, at most [`MAX_STEP_S`].
    fn duration(&self, v: f64, key: &str) -> Result<f64, ConfigError> {
        self.c.ensure(
            v.is_finite() && (1.0..=MAX_STEP_S).contains(&v),
            key,
            &format!(
                "must be between 1 s and {MAX_STEP_S} s (7 days), got {}",
                crate::config::num(v)
            ),
        )?;
        Ok(v)
    }

    fn line(&self, key: &str) -> usize {
        self.src.locate(key).map_or(1, |(l, _)| l)
    }

    fn push(&self, out: &mut Vec<Step>, group: Group, key: &str, kind: StepKind) {
        out.push(Step {
            group,
            key: key.to_owned(),
            line: self.line(key),
            kind,
        });
    }

    /// A `chamber` step: its set point within the bench's chamber limits,
    /// its ramp within the chamber's capability.
    fn chamber_step(
        &self,
        key: &str,
        set_c: f64,
        ramp_c_per_min: f64,
    ) -> Result<StepKind, ConfigError> {
        let c = &self.c;
        let k = |field: &str| format!("{key}.{field}");
        let l = &self.bench.limits;
        c.within(set_c, l.chamber_min_c, l.chamber_max_c, &k("set_c"))
            .map_err(|_| {
                self.src.invalid(
                    &k("set_c"),
                    format!(
                        "{} degC is beyond the bench's chamber limits {}..{} degC",
                        crate::config::num(set_c),
                        l.chamber_min_c,
                        l.chamber_max_c
                    ),
                )
            })?;
        c.ensure(
            ramp_c_per_min.is_finite()
                && ramp_c_per_min >= MIN_RAMP_C_PER_MIN
                && ramp_c_per_min <= l.chamber_max_ramp_c_per_min,
            &k("ramp_c_per_min"),
            &format!(
                "{} degC/min is beyond the chamber's capability ({MIN_RAMP_C_PER_MIN} <= ramp <= {} degC/min)",
                crate::config::num(ramp_c_per_min),
                l.chamber_max_ramp_c_per_min
            ),
        )?;
        Ok(StepKind::Chamber {
            set_c,
            ramp_c_per_min,
        })
    }

    /// A `power` step: its rest only when switching on, its voltage and
    /// current limit within the bench's supply (none without one).
    fn power_step(
        &self,
        key: &str,
        on: bool,
        volts: Option<f64>,
        limit_a: Option<f64>,
        rest_if_on_s: Option<f64>,
    ) -> Result<StepKind, ConfigError> {
        let c = &self.c;
        let k = |field: &str| format!("{key}.{field}");
        if let Some(rest) = rest_if_on_s {
            c.ensure(
                on,
                &k("rest_if_on_s"),
                "is for a step that switches the unit on (on = true)",
            )?;
            self.duration(rest, &k("rest_if_on_s"))?;
        }
        // A bench without a supply: the operator switches the unit by
        // hand and confirms it (docs/procedures.md, "Power-on"); the
        // voltage is theirs to set (0 here).
        let (volts, limit_a) = match &self.bench.supply {
            None => {
                c.ensure(
                    volts.is_none() && limit_a.is_none(),
                    &k("volts"),
                    "a bench without a supply ([devices.supply]) has the unit switched by hand: its voltage and current limit are not the run's to set",
                )?;
                (0.0, 0.0)
            }
            Some(p) => {
                let volts = volts.unwrap_or(p.volts);
                let limit_a = limit_a.unwrap_or(p.limit_a);
                c.ensure(
                    volts.is_finite() && volts > 0.0 && volts <= p.max_volts,
                    &k("volts"),
                    &format!(
                        "{} V is beyond the bench's supply limit 0..{} V (devices.supply.max_volts)",
                        crate::config::num(volts),
                        p.max_volts
                    ),
                )?;
                c.ensure(
                    limit_a.is_finite() && limit_a > 0.0 && limit_a <= p.max_limit_a,
                    &k("limit_a"),
                    &format!(
                        "{} A is beyond the bench's supply limit 0..{} A (devices.supply.max_limit_a)",
                        crate::config::num(limit_a),
                        p.max_limit_a
                    ),
                )?;
                (volts, limit_a)
            }
        };
        Ok(StepKind::Power {
            on,
            volts,
            limit_a,
            rest_if_on_s,
        })
    }

    // One arm per step kind, each a short run of checks that name their
    // key; the long kinds have methods of their own.
    fn step(
        &mut self,
        group: Group,
        key: &str,
        step: &RawStep,
        label: Option<&str>,
        out: &mut Vec<Step>,
    ) -> Result<(), ConfigError> {
        let c = &self.c;
        let subst = |s: &str| with_label(s, label);
        let k = |field: &str| format!("{key}.{field}");
        let kind = match step {
            RawStep::Chamber {
                set_c,
                ramp_c_per_min,
            } => self.chamber_step(key, *set_c, *ramp_c_per_min)?,
            RawStep::Soak {
                band_c,
                case_slope_c_per_min,
                hold_s,
                timeout_s,
            } => {
                c.within(*band_c, 0.01, 20.0, &k("band_c"))?;
                c.within(
                    *case_slope_c_per_min,
                    1e-4,
                    10.0,
                    &k("case_slope_c_per_min"),
                )?;
                c.within(*hold_s, 0.0, MAX_STEP_S, &k("hold_s"))?;
                c.within(*timeout_s, 1.0, MAX_STEP_S, &k("timeout_s"))?;
                c.ensure(
                    timeout_s > hold_s,
                    &k("timeout_s"),
                    "must be longer than hold_s, s",
                )?;
                StepKind::Soak {
                    band_c: *band_c,
                    case_slope_c_per_min: *case_slope_c_per_min,
                    hold_s: *hold_s,
                    timeout_s: *timeout_s,
                }
            }
            RawStep::Move { orientation, table } => {
                let (angles, orientation) =
                    self.resolve(key, orientation.as_ref(), table.as_ref())?;
                StepKind::Move {
                    angles,
                    orientation,
                }
            }
            RawStep::Power {
                on,
                volts,
                limit_a,
                rest_if_on_s,
            } => self.power_step(key, *on, *volts, *limit_a, *rest_if_on_s)?,
            RawStep::Wait { duration_s } => StepKind::Wait {
                duration_s: self.duration(*duration_s, &k("duration_s"))?,
            },
            RawStep::Record {
                label: l,
                duration_s,
            } => {
                let l = subst(l);
                self.records.claim(c, &l, &k("label"))?;
                StepKind::Record {
                    label: l,
                    duration_s: self.duration(*duration_s, &k("duration_s"))?,
                }
            }
            RawStep::Measure { .. } => self.measure_step(key, step, label)?,
            RawStep::Rate { .. } => return self.rate_step(group, out, key, step, label),
            RawStep::Note { text } => StepKind::Note { text: subst(text) },
            RawStep::Prompt { text } => StepKind::Prompt { text: subst(text) },
            RawStep::Repeat { positions, steps } => {
                c.ensure(label.is_none(), key, "a repeat cannot hold another repeat")?;
                c.ensure(
                    !positions.is_empty(),
                    &k("positions"),
                    "must list at least one position",
                )?;
                for (p, pos) in positions.iter().enumerate() {
                    let pkey = format!("{key}.positions.{p}");
                    let (angles, orientation) = self.position(&pkey, pos)?;
                    self.push(
                        out,
                        group,
                        &pkey,
                        StepKind::Move {
                            angles,
                            orientation,
                        },
                    );
                    for (j, s) in steps.iter().enumerate() {
                        self.step(group, &format!("{key}.steps.{j}"), s, Some(&pos.label), out)?;
                    }
                }
                return Ok(());
            }
        };
        self.push(out, group, key, kind);
        Ok(())
    }

    /// A `measure` step's records: `PREFIX*` expanded to every earlier
    /// record whose label starts so, each one made by an earlier step.
    fn measured_records(
        &self,
        key: &str,
        records: &[String],
        label: Option<&str>,
    ) -> Result<Vec<String>, ConfigError> {
        let c = &self.c;
        let k = |field: &str| format!("{key}.{field}");
        let mut named: Vec<String> = Vec::new();
        for r in records.iter().map(|r| with_label(r, label)) {
            match r.strip_suffix('*') {
                Some(prefix) => {
                    let found: Vec<String> = self
                        .records
                        .order
                        .iter()
                        .filter(|l| l.starts_with(prefix))
                        .cloned()
                        .collect();
                    c.ensure(
                        !found.is_empty(),
                        &k("records"),
                        &format!("{r:?} matches no earlier record"),
                    )?;
                    named.extend(found);
                }
                None => named.push(r),
            }
        }
        c.ensure(
            !named.is_empty(),
            &k("records"),
            "must name at least one record",
        )?;
        for r in &named {
            c.ensure(
                self.records.set.contains(r),
                &k("records"),
                &format!("names record {r:?}, which no earlier record step makes"),
            )?;
        }
        Ok(named)
    }

    /// A `measure` step: the metric, its records (`PREFIX*` expanded), averaging, band and limits.
    fn measure_step(
        &mut self,
        key: &str,
        step: &RawStep,
        label: Option<&str>,
    ) -> Result<StepKind, ConfigError> {
        let c = &self.c;
        let subst = |s: &str| with_label(s, label);
        let k = |field: &str| format!("{key}.{field}");
        let RawStep::Measure {
            name,
            metric,
            records,
            averaging_s,
            band,
            low,
            high,
            unit,
        } = step
        else {
            return Err(self.src.invalid(key, "is not a measure step"));
        };
        let name = subst(name);
        c.ensure(is_plain_text(&name), &k("name"), PLAIN_TEXT)?;
        let metric = Metric::parse(metric).ok_or_else(|| {
            self.src.invalid(
                &k("metric"),
                format!(
                    "{metric:?} is not a metric; expected bias_stability, drift_pp, \
                     compensated_drift_pp, compensated_drift_fit_residual_pp, self_heating, mean_bias, \
                     temperature_sensitivity, temperature_rate_sensitivity, \
                     scale_factor, scale_factor_nonlinearity, scale_factor_asymmetry, \
                     scale_factor_temperature, dead_band, threshold, axis_misalignment, \
                     bias_repeatability, warm_up_time, power_steady or power_peak"
                ),
            )
        })?;
        c.ensure(
            !self.measures.contains(&name),
            &k("name"),
            &format!("measurement {name:?} is already used"),
        )?;
        self.measures.insert(name.clone());
        let records = self.measured_records(key, records, label)?;
        let averaging_s = match (metric.needs_averaging(), averaging_s) {
            (true, Some(a)) => c.within(*a, 0.01, MAX_STEP_S, &k("averaging_s"))?,
            (true, None) => {
                return Err(self
                    .src
                    .invalid(key, "needs averaging_s (s) for this metric"));
            }
            (false, _) => 0.0,
        };
        let band = match (metric == Metric::WarmUpTime, band) {
            (true, Some(b)) => Some(c.within(*b, 1e-6, 1e6, &k("band"))?),
            (true, None) => {
                return Err(self.src.invalid(
                    key,
                    "needs band (deg/h) for a warm-up time: how close to its settled value the averaged rate must stay",
                ));
            }
            (false, Some(_)) => {
                return Err(self.src.invalid(&k("band"), "is only for warm_up_time"));
            }
            (false, None) => None,
        };
        if metric == Metric::WarmUpTime {
            c.ensure(
                records.len() == 1,
                &k("records"),
                "must name one record, made from a turn-on",
            )?;
        }
        if metric == Metric::BiasRepeatability {
            c.ensure(
                records.len() >= 2,
                &k("records"),
                "must name two or more records, one after each turn-on",
            )?;
        }
        for (v, f) in [(low, "low"), (high, "high")] {
            if let Some(v) = v {
                c.finite(*v, &k(f))?;
            }
        }
        if let (Some(lo), Some(hi)) = (low, high) {
            c.ensure(lo <= hi, &k("low"), "must not be above high")?;
        }
        // The fit's own residual is informative, never judged: it takes
        // no limit; every other figure needs one.
        if metric == Metric::CompensatedDriftFitResidualPp {
            c.ensure(
                low.is_none() && high.is_none(),
                key,
                "compensated_drift_fit_residual_pp is informative (the fit's own residual): \
                 it takes no limit; judge compensated_drift_pp",
            )?;
        } else {
            c.ensure(
                low.is_some() || high.is_some(),
                key,
                "needs a limit: low, high or both",
            )?;
        }
        c.ensure(
            !unit.trim().is_empty(),
            &k("unit"),
            "must name the unit, e.g. \"deg/h\"",
        )?;
        Ok(StepKind::Measure(Measure {
            name,
            metric,
            records,
            averaging_s,
            band,
            low: *low,
            high: *high,
            unit: unit.clone(),
        }))
    }

    /// A `rate` step's timing: its record's length (a duration, or whole
    /// revolutions at the rate), its settling, and its ramps at the
    /// acceleration given, all within the bench's limits and a step's
    /// longest. Returns (record length, settling), s.
    fn rate_timing(
        &self,
        key: &str,
        rate_dps: f64,
        duration_s: Option<f64>,
        revolutions: Option<f64>,
        settle_s: Option<f64>,
        acc_dps2: Option<f64>,
    ) -> Result<(f64, f64), ConfigError> {
        let c = &self.c;
        let k = |field: &str| format!("{key}.{field}");
        let duration = match (duration_s, revolutions) {
            (Some(d), None) => self.duration(d, &k("duration_s"))?,
            (None, Some(n)) => {
                c.ensure(
                    n >= 1.0 && n.fract() == 0.0 && n <= 1e6,
                    &k("revolutions"),
                    "must be a whole number of revolutions, at least 1",
                )?;
                c.ensure(
                    rate_dps != 0.0,
                    &k("revolutions"),
                    "a rate of 0 deg/s makes no revolutions; give duration_s",
                )?;
                self.duration(n * 360.0 / rate_dps.abs(), &k("revolutions"))?
            }
            _ => {
                return Err(self
                    .src
                    .invalid(key, "needs exactly one of `duration_s` or `revolutions`"));
            }
        };
        let settle = settle_s.unwrap_or(2.0);
        c.within(settle, 0.0, 3600.0, &k("settle_s"))?;
        let mut ramp_s = 0.0;
        if let (Some(a), Some((_, max_acc))) = (acc_dps2, self.bench.limits.rate_mode()) {
            c.ensure(
                a.is_finite() && a > 0.0 && a <= max_acc,
                &k("acc_dps2"),
                &format!(
                    "{} deg/s^2 is beyond the table's rate-mode acceleration (0 < acc <= {max_acc} deg/s^2, limits.table_rate_mode_max_acc_dps2)",
                    crate::config::num(a)
                ),
            )?;
            // Up to the rate (from rest or another rate, at most
            // twice it) and back: bounded as a wait is.
            ramp_s = 2.0 * rate_dps.abs() / a;
            c.ensure(
                ramp_s <= MAX_STEP_S,
                &k("acc_dps2"),
                &format!(
                    "{} deg/s^2 ramps to {} deg/s in {} s, beyond {MAX_STEP_S} s (7 days); give a larger acceleration",
                    crate::config::num(a),
                    crate::config::num(rate_dps),
                    crate::config::num(ramp_s / 2.0)
                ),
            )?;
        }
        c.ensure(
            2.0 * ramp_s + settle + duration <= MAX_STEP_S,
            key,
            &format!(
                "takes {} s with its ramps, settling and record, beyond {MAX_STEP_S} s (7 days)",
                crate::config::num(2.0 * ramp_s + settle + duration)
            ),
        )?;
        Ok((duration, settle))
    }

    /// A `rate` step: the turn it starts, its settle and record, and the stop unless it keeps turning.
    fn rate_step(
        &mut self,
        group: Group,
        out: &mut Vec<Step>,
        key: &str,
        step: &RawStep,
        label: Option<&str>,
    ) -> Result<(), ConfigError> {
        let c = &self.c;
        let subst = |s: &str| with_label(s, label);
        let k = |field: &str| format!("{key}.{field}");
        let RawStep::Rate {
            label: l,
            rate_dps,
            rate_dph,
            axis,
            duration_s,
            revolutions,
            settle_s,
            acc_dps2,
            keep_turning,
        } = step
        else {
            return Err(self.src.invalid(key, "is not a rate step"));
        };
        let l = subst(l);
        self.records.claim(c, &l, &k("label"))?;
        let rate_dps = &match (rate_dps, rate_dph) {
            (Some(r), None) => *r,
            (None, Some(r)) => *r / 3600.0,
            _ => {
                return Err(self
                    .src
                    .invalid(key, "needs exactly one of `rate_dps` or `rate_dph`"));
            }
        };
        let rate_key = if rate_dph.is_some() {
            k("rate_dph")
        } else {
            k("rate_dps")
        };
        let inner = match axis.as_deref() {
            None | Some("inner") => true,
            Some("outer") => false,
            Some(other) => {
                return Err(self.src.invalid(
                    &k("axis"),
                    format!("{other:?} is not an axis; expected \"inner\" or \"outer\""),
                ));
            }
        };
        let Some((max_rate, _)) = self.bench.limits.rate_mode() else {
            return Err(self.src.invalid(
                &rate_key,
                "this bench's table has no rate mode: its bench file gives no limits.table_rate_mode_max_dps",
            ));
        };
        c.ensure(
            rate_dps.is_finite() && rate_dps.abs() <= max_rate,
            &rate_key,
            &format!(
                "{} deg/s is beyond the table's rate-mode limit of {max_rate} deg/s (limits.table_rate_mode_max_dps)",
                crate::config::num(*rate_dps)
            ),
        )?;
        let (duration, settle) = self.rate_timing(
            key,
            *rate_dps,
            *duration_s,
            *revolutions,
            *settle_s,
            *acc_dps2,
        )?;
        // Turn, record, come to rest: three plain steps (a record is
        // a record wherever it is taken: replay, resume and health
        // treat it as any other).
        let line = self.line(key);
        let mut steps = vec![
            (
                StepKey::of(key, KeyPart::Turn).to_string(),
                StepKind::Turn {
                    inner,
                    rate_dps: *rate_dps,
                    settle_s: settle,
                    acc_dps2: *acc_dps2,
                },
            ),
            (
                StepKey::of(key, KeyPart::RateRecord).to_string(),
                StepKind::Record {
                    label: l.clone(),
                    duration_s: duration,
                },
            ),
        ];
        if !keep_turning.unwrap_or(false) {
            steps.push((
                format!("{key}.rest"),
                StepKind::Turn {
                    inner,
                    rate_dps: 0.0,
                    settle_s: 0.0,
                    acc_dps2: *acc_dps2,
                },
            ));
        }
        for (sub, kind) in steps {
            out.push(Step {
                group,
                key: sub,
                line,
                kind,
            });
        }
        Ok(())
    }

    fn position(
        &self,
        key: &str,
        p: &RawPosition,
    ) -> Result<(TableAngles, Orientation), ConfigError> {
        self.c
            .ensure(is_plain_text(&p.label), &format!("{key}.label"), PLAIN_TEXT)?;
        self.resolve(key, p.orientation.as_ref(), p.table.as_ref())
    }

    /// Table angles and orientation for a move given either.
    fn resolve(
        &self,
        key: &str,
        orientation: Option<&Orientation>,
        table: Option<&TableAngles>,
    ) -> Result<(TableAngles, Orientation), ConfigError> {
        let g: &TableGeometry = &self.bench.geometry;
        let l = &self.bench.limits;
        // With the axis vertical, yaw and roll turn about the same line and
        // the Euler split of a pose is arbitrary: keep the one asked for.
        let (angles, asked, field) = match (orientation, table) {
            (Some(o), None) => {
                let a = g.angles_for(*o).map_err(|e| {
                    self.src
                        .invalid(&format!("{key}.orientation"), e.to_string())
                })?;
                (
                    fit_range(a, l.outer_range_deg, l.inner_range_deg),
                    Some(*o),
                    "orientation",
                )
            }
            (None, Some(t)) => (*t, None, "table"),
            _ => {
                return Err(self
                    .src
                    .invalid(key, "needs exactly one of `orientation` or `table`"));
            }
        };
        for (v, r, axis) in [
            (angles.outer_deg, l.outer_range_deg, "outer"),
            (angles.inner_deg, l.inner_range_deg, "inner"),
        ] {
            self.c.ensure(
                v.is_finite() && v >= r[0] && v <= r[1],
                &format!("{key}.{field}"),
                &format!(
                    "needs the {axis} axis at {v:.2} deg, outside the bench's travel {}..{} deg",
                    r[0], r[1]
                ),
            )?;
        }
        Ok((angles, asked.unwrap_or_else(|| g.orientation(angles))))
    }
}

/// What a label or measurement name must be: it is shown in reports,
/// stored in the results store and written in logs.
const PLAIN_TEXT: &str = "must be 1 to 128 characters, not blank, without control characters";

fn is_plain_text(s: &str) -> bool {
    !s.trim().is_empty() && s.chars().count() <= 128 && !s.chars().any(char::is_control)
}

/// The `[procedure] name` of a procedure's text, read without validating
/// it (to label a run whose procedure is known only as text).
pub fn raw_name(text: &str) -> Option<String> {
    let t: toml::Table = toml::from_str(text).ok()?;
    t.get("procedure")?.get("name")?.as_str().map(str::to_owned)
}

/// The decision rule a run of the procedure text `text` was judged by:
/// the rule it names, else the default (guarded), or simple acceptance
/// for a run `before_rules` (its log written before decision rules) (none:
/// the text is not a procedure, or names a rule this build does not know).
pub fn raw_rule(text: &str, before_rules: bool) -> Option<DecisionRule> {
    let t: toml::Table = toml::from_str(text).ok()?;
    let p = t.get("procedure")?;
    let band = p
        .get("guard_band_u")
        .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)));
    match p.get("decision_rule") {
        Some(rule) => DecisionRule::parse(rule.as_str()?, band).ok(),
        None if before_rules => Some(DecisionRule::Simple),
        None => Some(DecisionRule::default()),
    }
}

/// A name that is safe as one path component: no separator, no `..`, no
/// hidden file, nothing a shell or a file system treats specially.
pub fn is_path_safe_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphanumeric())
        && name.len() <= 64
        && chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// Bring each angle into its travel range by whole turns, where possible.
fn fit_range(a: TableAngles, outer: [f64; 2], inner: [f64; 2]) -> TableAngles {
    let fit = |v: f64, r: [f64; 2]| {
        [v, v - 360.0, v + 360.0]
            .into_iter()
            .find(|x| *x >= r[0] && *x <= r[1])
            .unwrap_or(v)
    };
    TableAngles {
        outer_deg: fit(a.outer_deg, outer),
        inner_deg: fit(a.inner_deg, inner),
    }
}
