//! Stage one: serde structs that mirror the procedure TOML one-to-one.

use serde::Deserialize;

use crate::geometry::{Orientation, TableAngles};

/// A whole procedure file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawProcedure {
    /// Metadata.
    pub procedure: RawMeta,
    /// Steps that bring the bench to its starting state.
    #[serde(default)]
    pub setup: Vec<RawStep>,
    /// The measurement itself.
    #[serde(default)]
    pub main: Vec<RawStep>,
    /// Steps that always run once setup has started (safe state).
    #[serde(default)]
    pub cleanup: Vec<RawStep>,
}

/// `[procedure]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMeta {
    /// Procedure name.
    pub name: String,
    /// What it is for.
    #[serde(default)]
    pub description: String,
    /// Type of unit it tests (e.g. `RL-16`).
    pub dut_type: String,
    /// The specification it judges against, e.g. `0.05 deg/h bias stability`.
    #[serde(default)]
    pub spec: String,
    /// How its figures are judged: `simple`, `guarded` (the default) or
    /// `non_binary` (`procedure::rule`).
    #[serde(default)]
    pub decision_rule: Option<String>,
    /// A guarded rule's guard band, as a multiple of the expanded
    /// uncertainty (default 1).
    #[serde(default)]
    pub guard_band_u: Option<f64>,
}

/// A position of a `repeat` step.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPosition {
    /// Label substituted for `{label}` in the repeated steps.
    pub label: String,
    /// Orientation of the unit (azimuth, elevation, roll).
    pub orientation: Option<Orientation>,
    /// Or table angles directly.
    pub table: Option<TableAngles>,
}

/// One step; `action` says which fields apply.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "action", rename_all = "snake_case", deny_unknown_fields)]
pub enum RawStep {
    /// Chamber set point, reached at `ramp_c_per_min`.
    Chamber {
        /// Set point, degC.
        set_c: f64,
        /// Ramp, degC/min.
        ramp_c_per_min: f64,
    },
    /// Wait for thermal soak.
    Soak {
        /// Chamber air within this of its set point, degC.
        band_c: f64,
        /// Case temperature slope below this, degC/min.
        case_slope_c_per_min: f64,
        /// Both conditions held this long, s.
        hold_s: f64,
        /// Give up (error) after this long, s.
        timeout_s: f64,
    },
    /// Move the table.
    Move {
        /// By orientation of the unit.
        orientation: Option<Orientation>,
        /// Or by table angles.
        table: Option<TableAngles>,
    },
    /// Switch the unit's supply output on or off.
    Power {
        /// On (true) or off.
        on: bool,
        /// Voltage, V (default: the bench's `devices.supply.volts`).
        volts: Option<f64>,
        /// Current limit, A (default: the bench's `devices.supply.limit_a`).
        limit_a: Option<f64>,
        /// A switch-on that finds the unit already powered switches it
        /// off and lets it rest this long first, s (absent: the run
        /// refuses to go on, since the figures after it count from it).
        rest_if_on_s: Option<f64>,
    },
    /// Let time pass.
    Wait {
        /// s.
        duration_s: f64,
    },
    /// Record the gyro under a label.
    Record {
        /// Label (measurements refer to it).
        label: String,
        /// s.
        duration_s: f64,
    },
    /// Turn an axis at a rate (rate mode) and record the gyro over it:
    /// ramp to the rate, settle, record for a duration or a whole number
    /// of revolutions, ramp back to rest.
    Rate {
        /// Label of the record (measurements refer to it).
        label: String,
        /// Axis rate, deg/s (the sign is the direction).
        rate_dps: Option<f64>,
        /// Or in deg/h (small rates).
        rate_dph: Option<f64>,
        /// `inner` (default: the axis the gyro's sensitive axis lies on)
        /// or `outer`.
        axis: Option<String>,
        /// Record this long, s.
        duration_s: Option<f64>,
        /// Or this many whole revolutions.
        revolutions: Option<f64>,
        /// Time at the rate before the record starts, s (default 2).
        settle_s: Option<f64>,
        /// Ramp to the rate at this acceleration, deg/s^2 (default: as
        /// fast as the table's rate mode allows).
        acc_dps2: Option<f64>,
        /// Keep turning after the record: the next step, another `rate`,
        /// ramps from this rate to its own (default false: come to rest).
        keep_turning: Option<bool>,
    },
    /// Compute a figure and judge it against limits.
    Measure {
        /// Name in the report (e.g. `bias_stability_dph:az000`).
        name: String,
        /// Which figure (see `docs/procedures.md`).
        metric: String,
        /// Records it is computed on.
        records: Vec<String>,
        /// Averaging time, s.
        averaging_s: Option<f64>,
        /// Band the averaged rate must stay within (warm-up time), deg/h.
        band: Option<f64>,
        /// Lower limit.
        low: Option<f64>,
        /// Upper limit.
        high: Option<f64>,
        /// Unit of the value and limits.
        unit: String,
    },
    /// A note for the operator (logged, shown).
    Note {
        /// Text.
        text: String,
    },
    /// Ask the operator to confirm before going on.
    Prompt {
        /// Text.
        text: String,
    },
    /// Run `steps` once per position, `{label}` replaced by its label.
    Repeat {
        /// Positions.
        positions: Vec<RawPosition>,
        /// Steps run at each position (after moving there).
        steps: Vec<RawStep>,
    },
}
