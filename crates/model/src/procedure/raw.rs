//! Stage one: serde structs that mirror the procedure TOML one-to-one.

use serde::{Deserialize, Serialize};

use crate::geometry::{Orientation, TableAngles};

/// A whole procedure file. Serialised ([`RawProcedure::to_toml`]) it is
/// a procedure file again: a procedure made by the program (a deciding
/// run, an imported run's) is built as this value, never as text.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawProcedure {
    /// Metadata.
    pub procedure: RawMeta,
    /// Steps that bring the bench to its starting state.
    #[serde(default)]
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub setup: Vec<RawStep>,
    /// The measurement itself.
    #[serde(default)]
    pub main: Vec<RawStep>,
    /// Steps that always run once setup has started (safe state).
    #[serde(default)]
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cleanup: Vec<RawStep>,
}

/// `[procedure]`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawMeta {
    /// Procedure name.
    pub name: String,
    /// What it is for.
    #[serde(default)]
    #[serde(skip_serializing_if = "String::is_empty")]
    pub description: String,
    /// Type of unit it tests (e.g. `RL-16`).
    pub dut_type: String,
    /// The specification it judges against, e.g. `0.05 deg/h bias stability`.
    #[serde(default)]
    #[serde(skip_serializing_if = "String::is_empty")]
    pub spec: String,
    /// How its figures are judged: `simple`, `guarded` (the default) or
    /// `non_binary` (`procedure::rule`).
    #[serde(default)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decision_rule: Option<String>,
    /// A guarded rule's guard band, as a multiple of the expanded
    /// uncertainty (default 1).
    #[serde(default)]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub guard_band_u: Option<f64>,
}

/// A position of a `repeat` step.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawPosition {
    /// Label substituted for `{label}` in the repeated steps.
    pub label: String,
    /// Orientation of the unit (azimuth, elevation, roll).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation: Option<Orientation>,
    /// Or table angles directly.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub table: Option<TableAngles>,
}

/// One step; `action` says which fields apply.
#[derive(Debug, Clone, Serialize, Deserialize)]
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
        #[serde(skip_serializing_if = "Option::is_none")]
        orientation: Option<Orientation>,
        /// Or by table angles.
        #[serde(skip_serializing_if = "Option::is_none")]
        table: Option<TableAngles>,
    },
    /// Switch the unit's supply output on or off.
    Power {
        /// On (true) or off.
        on: bool,
        /// Voltage, V (default: the bench's `devices.supply.volts`).
        #[serde(skip_serializing_if = "Option::is_none")]
        volts: Option<f64>,
        /// Current limit, A (default: the bench's `devices.supply.limit_a`).
        #[serde(skip_serializing_if = "Option::is_none")]
        limit_a: Option<f64>,
        /// A switch-on that finds the unit already powered switches it
        /// off and lets it rest this long first, s (absent: the run
        /// refuses to go on, since the figures after it count from it).
        #[serde(skip_serializing_if = "Option::is_none")]
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
        #[serde(skip_serializing_if = "Option::is_none")]
        rate_dps: Option<f64>,
        /// Or in deg/h (small rates).
        #[serde(skip_serializing_if = "Option::is_none")]
        rate_dph: Option<f64>,
        /// `inner` (default: the axis the gyro's sensitive axis lies on)
        /// or `outer`.
        #[serde(skip_serializing_if = "Option::is_none")]
        axis: Option<String>,
        /// Record this long, s.
        #[serde(skip_serializing_if = "Option::is_none")]
        duration_s: Option<f64>,
        /// Or this many whole revolutions.
        #[serde(skip_serializing_if = "Option::is_none")]
        revolutions: Option<f64>,
        /// Time at the rate before the record starts, s (default 2).
        #[serde(skip_serializing_if = "Option::is_none")]
        settle_s: Option<f64>,
        /// Ramp to the rate at this acceleration, deg/s^2 (default: as
        /// fast as the table's rate mode allows).
        #[serde(skip_serializing_if = "Option::is_none")]
        acc_dps2: Option<f64>,
        /// Keep turning after the record: the next step, another `rate`,
        /// ramps from this rate to its own (default false: come to rest).
        #[serde(skip_serializing_if = "Option::is_none")]
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
        #[serde(skip_serializing_if = "Option::is_none")]
        averaging_s: Option<f64>,
        /// Band the averaged rate must stay within (warm-up time), deg/h.
        #[serde(skip_serializing_if = "Option::is_none")]
        band: Option<f64>,
        /// Lower limit.
        #[serde(skip_serializing_if = "Option::is_none")]
        low: Option<f64>,
        /// Upper limit.
        #[serde(skip_serializing_if = "Option::is_none")]
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

impl RawProcedure {
    /// Read from procedure text (stage one alone: the values unchecked;
    /// `Procedure::from_source` checks them against a bench).
    pub fn from_toml(text: &str) -> Result<Self, toml::de::Error> {
        toml::from_str(text)
    }

    /// As procedure text, `header` (comment lines, each `# `-prefixed
    /// here) above it.
    pub fn to_toml(&self, header: &[&str]) -> Result<String, toml::ser::Error> {
        let mut out: String = header.iter().map(|l| format!("# {l}\n")).collect();
        if !out.is_empty() {
            out.push('\n');
        }
        out.push_str(&toml::to_string(self)?);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every shipped procedure read as its raw value and written back is
    /// the same value: reading the written text again writes the same
    /// text, and every step, limit and label survives (a written file
    /// holds every key the shipped one does that is not a default).
    #[test]
    fn a_procedure_written_from_its_value_reads_back_as_the_same_value() {
        for (name, text) in crate::procedures::SHIPPED {
            let raw = RawProcedure::from_toml(text).unwrap_or_else(|e| panic!("{name}: {e}"));
            let written = raw
                .to_toml(&["made here"])
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert!(written.starts_with("# made here\n\n"), "{name}");
            let again = RawProcedure::from_toml(&written).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(
                again.to_toml(&["made here"]).ok().as_deref(),
                Some(written.as_str()),
                "{name}"
            );
            let steps = |r: &RawProcedure| r.setup.len() + r.main.len() + r.cleanup.len();
            assert_eq!(steps(&again), steps(&raw), "{name}");
            assert_eq!(again.procedure.name, raw.procedure.name, "{name}");
        }
    }
}
