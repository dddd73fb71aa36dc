//! What a procedure is checked against: the bench's `[limits]` and the
//! few facts of its devices a step depends on (the table's geometry and
//! settling, the supply's set values and its limits), without the rest
//! of the bench's configuration (its endpoints, its protocols). The
//! controller's bench file reads `[limits]` as [`Limits`] and hands a
//! procedure its [`BenchLimits`].

use serde::{Deserialize, Serialize};

use crate::geometry::TableGeometry;

/// `[limits]`: what the bench must never be driven beyond.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Lowest chamber set point, degC.
    pub chamber_min_c: f64,
    /// Highest chamber set point, degC.
    pub chamber_max_c: f64,
    /// Fastest chamber ramp, degC/min.
    pub chamber_max_ramp_c_per_min: f64,
    /// Outer axis travel, deg (`[min, max]`).
    pub outer_range_deg: [f64; 2],
    /// Inner axis travel, deg (`[min, max]`).
    pub inner_range_deg: [f64; 2],
    /// Fastest axis rate, deg/s.
    pub table_max_rate_dps: f64,
    /// Largest axis acceleration, deg/s^2.
    pub table_max_acc_dps2: f64,
    /// Fastest rate a `rate` step may ask of an axis in rate mode, deg/s
    /// (none: the table has no rate mode, or no slip rings for continuous
    /// turns, and `rate` steps are refused).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_rate_mode_max_dps: Option<f64>,
    /// Largest acceleration of an axis in rate mode, deg/s^2 (default:
    /// `table_max_acc_dps2`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_rate_mode_max_acc_dps2: Option<f64>,
    /// Hottest the gyro (any sensor) may get, degC.
    pub dut_max_c: f64,
}

impl Limits {
    /// Rate-mode rate and acceleration limits, if the table has a rate mode.
    pub fn rate_mode(&self) -> Option<(f64, f64)> {
        self.table_rate_mode_max_dps.map(|r| {
            (
                r,
                self.table_rate_mode_max_acc_dps2
                    .unwrap_or(self.table_max_acc_dps2),
            )
        })
    }
}

/// A bench's supply, as a procedure's `power` step needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupplyLimits {
    /// The unit's supply voltage, V (a step's default).
    pub volts: f64,
    /// Its current limit, A (a step's default).
    pub limit_a: f64,
    /// The most voltage a step may set, V (`devices.supply.max_volts`).
    pub max_volts: f64,
    /// The highest current limit a step may set, A
    /// (`devices.supply.max_limit_a`).
    pub max_limit_a: f64,
}

/// What a procedure is validated against and its duration estimated on.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchLimits {
    /// `[limits]`.
    pub limits: Limits,
    /// How the table turns the unit (positions are checked reachable).
    pub geometry: TableGeometry,
    /// The table's settling after a move, s.
    pub table_settle_s: f64,
    /// The supply, if the bench has one (without, the unit is switched by
    /// hand).
    pub supply: Option<SupplyLimits>,
}
