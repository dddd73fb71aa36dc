//! `[thermal.effects]`: what a unit's thermal physics may hold beyond the
//! network the study describes, each off by default. The diagnosis's
//! thermal layer names these when the network form alone cannot follow a
//! unit's runs, and writes them here in `twin-updated.toml`
//! (`docs/twin.md`, `docs/diagnosis.md`).

use serde::{Deserialize, Serialize};

use gyrobench_model::config::{Checker, ConfigError};

/// The thermal effects (`docs/twin.md`, "`[thermal.effects]`").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ThermalEffects {
    /// Each sensor's own lag behind the node it sits on (T1, T2, TK), s:
    /// the reading follows the node through a first-order lag (a sensor
    /// bonded through a thick adhesive or sheath); 0 = none.
    pub sensor_lag_s: [f64; 3],
    /// Each sensor's gain error (T1, T2, TK): it reads `(1 + e) T +
    /// offset` (a sensor off its calibration curve); 0 = none.
    pub sensor_gain_error: [f64; 3],
    /// Each block's conductance to the case changes with the orientation:
    /// times `1 + k |g . a|` (k for block 1, block 2), `a` =
    /// `orientation_axis_body` (convection inside the housing along
    /// another line than the sensors'); 0 = none.
    pub orientation_coupling: [f64; 2],
    /// The body axis the orientation coupling follows (any non-zero
    /// direction; normalised).
    pub orientation_axis_body: [f64; 3],
    /// A path from the air straight to block 1 and to block 2, its time
    /// constant, s (a side of the unit in the air stream: the air's
    /// changes open a gradient across the unit); 0 = none.
    pub air_path_tau_s: [f64; 2],
    /// The case's conductance to the air (through the mount, when there
    /// is one) changes with the chamber's air temperature: times `1 + c
    /// (T_air - 20 degC)`, never below a twentieth (natural convection and
    /// radiation grow with temperature), per degC; 0 = none.
    pub case_conductance_per_c: f64,
}

impl Default for ThermalEffects {
    fn default() -> Self {
        Self {
            sensor_lag_s: [0.0; 3],
            sensor_gain_error: [0.0; 3],
            orientation_coupling: [0.0; 2],
            orientation_axis_body: [1.0, 0.0, 0.0],
            air_path_tau_s: [0.0; 2],
            case_conductance_per_c: 0.0,
        }
    }
}

/// The reference temperature of `case_conductance_per_c`, degC.
pub const CONDUCTANCE_REFERENCE_C: f64 = 20.0;
/// The least the case's conductance may fall to, as a share of its value
/// at the reference (ours: a conductance never vanishes).
pub const CONDUCTANCE_FLOOR: f64 = 0.05;

impl ThermalEffects {
    /// None of the effects acts (the file then leaves the table out).
    pub fn is_none(&self) -> bool {
        self.sensor_lag_s == [0.0; 3]
            && self.sensor_gain_error == [0.0; 3]
            && self.orientation_coupling == [0.0; 2]
            && self.air_path_tau_s == [0.0; 2]
            && self.case_conductance_per_c == 0.0
    }

    /// The orientation coupling's axis as a unit vector.
    pub fn orientation_axis(&self) -> nalgebra::Vector3<f64> {
        let a = nalgebra::Vector3::from(self.orientation_axis_body);
        let n = a.norm();
        if n > 0.0 {
            a / n
        } else {
            nalgebra::Vector3::x()
        }
    }

    /// The factor on each block's conductance to the case with `gravity_body_g`
    /// (g, body frame).
    pub fn block_conductance(&self, gravity_body_g: &nalgebra::Vector3<f64>) -> [f64; 2] {
        let c = gravity_body_g.dot(&self.orientation_axis()).abs();
        self.orientation_coupling
            .map(|k| (1.0 + k * c).max(CONDUCTANCE_FLOOR))
    }

    /// The factor on the case's conductance to the air with the chamber's
    /// air at `air_c`.
    pub fn case_conductance(&self, air_c: f64) -> f64 {
        (1.0 + self.case_conductance_per_c * (air_c - CONDUCTANCE_REFERENCE_C))
            .max(CONDUCTANCE_FLOOR)
    }

    /// `[thermal.effects]`: lags and time constants not negative, gains
    /// within a fifth or so of a sensor, factors a gyro's housing can have.
    pub(crate) fn validate(&self, c: &Checker<'_>) -> Result<(), ConfigError> {
        for (k, v) in self.sensor_lag_s.iter().enumerate() {
            c.within(*v, 0.0, 1e5, &format!("thermal.effects.sensor_lag_s[{k}]"))?;
        }
        for (k, v) in self.sensor_gain_error.iter().enumerate() {
            c.within(
                *v,
                -0.5,
                0.5,
                &format!("thermal.effects.sensor_gain_error[{k}]"),
            )?;
        }
        for (k, v) in self.orientation_coupling.iter().enumerate() {
            c.within(
                *v,
                -0.95,
                20.0,
                &format!("thermal.effects.orientation_coupling[{k}]"),
            )?;
        }
        c.direction(
            &self.orientation_axis_body,
            "thermal.effects.orientation_axis_body",
        )?;
        for (k, v) in self.air_path_tau_s.iter().enumerate() {
            c.within(
                *v,
                0.0,
                1e8,
                &format!("thermal.effects.air_path_tau_s[{k}]"),
            )?;
        }
        c.within(
            self.case_conductance_per_c,
            -0.1,
            0.1,
            "thermal.effects.case_conductance_per_c",
        )?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::twin::config::{DEFAULT_TWIN_TOML, TwinConfig};
    use gyrobench_model::config::Source;

    const TABLE: &str = "\n[thermal.effects]\nsensor_lag_s = [0.0, 45.0, 0.0]\n\
        sensor_gain_error = [0.0, 0.0, 0.01]\norientation_coupling = [0.3, 0.0]\n\
        orientation_axis_body = [1.0, 0.0, 0.0]\nair_path_tau_s = [0.0, 4000.0]\n\
        case_conductance_per_c = 0.004\n\n[gyro]";

    fn with_table(table: &str) -> Result<TwinConfig, ConfigError> {
        let text = DEFAULT_TWIN_TOML.replacen("\n[gyro]", table, 1);
        TwinConfig::from_source(&Source::from_text("t.toml", &text))
    }

    /// The table is read, written back the same (a fitted twin's effects
    /// survive `twin-updated.toml`), and left out of a file whose effects
    /// are all off (the default file reads as before).
    #[test]
    fn the_table_is_read_and_written_and_absent_when_off() {
        let cfg = with_table(TABLE).expect("a valid table");
        let fx = &cfg.thermal.effects;
        assert_eq!(fx.sensor_lag_s, [0.0, 45.0, 0.0]);
        assert_eq!(fx.air_path_tau_s, [0.0, 4000.0]);
        assert!(!fx.is_none());
        let text = cfg.to_toml().expect("renders");
        assert!(text.contains("[thermal.effects]"), "{text}");
        let back = TwinConfig::from_source(&Source::from_text("b", &text)).expect("loads");
        assert_eq!(back, cfg);
        let plain = TwinConfig::default_rl16();
        assert!(plain.thermal.effects.is_none());
        assert!(
            !plain
                .to_toml()
                .expect("renders")
                .contains("effects]\nsensor_lag")
        );
    }

    /// A value no sensor or housing has is refused with its dotted key.
    #[test]
    fn an_impossible_value_is_refused_by_its_key() {
        for (bad, key) in [
            (
                "sensor_lag_s = [0.0, -45.0, 0.0]",
                "thermal.effects.sensor_lag_s[1]",
            ),
            (
                "orientation_coupling = [-1.0, 0.0]",
                "thermal.effects.orientation_coupling[0]",
            ),
            (
                "orientation_axis_body = [0.0, 0.0, 0.0]",
                "thermal.effects.orientation_axis_body",
            ),
        ] {
            let table = format!("\n[thermal.effects]\n{bad}\n\n[gyro]");
            let err = with_table(&table).expect_err(bad).to_string();
            assert!(err.contains(&format!("`{key}`")), "{bad}: {err}");
        }
        let err = with_table("\n[thermal.effects]\nsensor_lag = 3.0\n\n[gyro]")
            .expect_err("an unknown key")
            .to_string();
        assert!(err.contains("unknown field `sensor_lag`"), "{err}");
    }
}
