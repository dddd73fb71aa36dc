//! The study's shipped procedures whose texts the diagnosis and the
//! self-checks run (this package's `procedures/*.toml`, embedded as
//! shipped), and how a procedure names a rate step's record.

/// The study's thermal cycle, as shipped.
pub const THERMAL_CYCLE_TOML: &str = include_str!("../procedures/thermal_cycle.toml");
/// The study's orientation run, as shipped.
pub const ORIENTATION_TOML: &str = include_str!("../procedures/orientation.toml");
/// The study's thermal cycle with the axis horizontal north, for a lab
/// near the equator ([`crate::geometry::TableGeometry::north`]), as shipped.
pub const THERMAL_CYCLE_NORTH_TOML: &str = include_str!("../procedures/thermal_cycle_north.toml");
/// The orientation run with its rolls and tilt about north, as shipped.
pub const ORIENTATION_NORTH_TOML: &str = include_str!("../procedures/orientation_north.toml");
/// The run that separates what those two cannot (thermal lag,
/// scale-factor drift), as shipped.
pub const SEPARATING_TOML: &str = include_str!("../procedures/separating.toml");

/// Every procedure the package ships, by file name (`procedures/`).
pub const SHIPPED: [(&str, &str); 13] = [
    (
        "acceptance.toml",
        include_str!("../procedures/acceptance.toml"),
    ),
    (
        "bias_repeatability.toml",
        include_str!("../procedures/bias_repeatability.toml"),
    ),
    (
        "dead_band.toml",
        include_str!("../procedures/dead_band.toml"),
    ),
    (
        "misalignment.toml",
        include_str!("../procedures/misalignment.toml"),
    ),
    ("noise.toml", include_str!("../procedures/noise.toml")),
    ("orientation.toml", ORIENTATION_TOML),
    ("orientation_north.toml", ORIENTATION_NORTH_TOML),
    (
        "rate_transfer.toml",
        include_str!("../procedures/rate_transfer.toml"),
    ),
    (
        "rate_transfer_temperatures.toml",
        include_str!("../procedures/rate_transfer_temperatures.toml"),
    ),
    ("separating.toml", SEPARATING_TOML),
    ("smoke.toml", include_str!("../procedures/smoke.toml")),
    ("thermal_cycle.toml", THERMAL_CYCLE_TOML),
    ("thermal_cycle_north.toml", THERMAL_CYCLE_NORTH_TOML),
];
