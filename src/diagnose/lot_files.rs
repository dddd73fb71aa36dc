//! What `diagnose --lot` writes besides `lot.json` and `lot.html`, as
//! text: the bench's correction (`bench-correction.toml`) and where each
//! unit's files go (`units/SERIAL/`).

use std::collections::BTreeMap;

use serde::Serialize;

use super::lot::Lot;
use crate::twin::config::EffectsConfig;

/// `bench-correction.toml`: each shared effect with its seat, and all of
/// them as a twin's `[effects]`.
#[derive(Debug, Serialize)]
struct BenchCorrection<'a> {
    shared: Vec<Entry<'a>>,
    effects: EffectsConfig,
}

/// One shared effect of the correction.
#[derive(Debug, Serialize)]
struct Entry<'a> {
    name: &'a str,
    seat: &'a str,
    units: &'a [String],
    shrink: f64,
    why: &'a str,
    parameters: &'a BTreeMap<String, f64>,
}

/// The bench's correction as TOML: the shared effects (name, seat,
/// units, shrink, why there, parameters) and the same as a twin's
/// `[effects]`, to put in a simulation of this bench; headed by what it
/// is and what not to do with it.
pub fn bench_correction(lot: &Lot) -> Result<String, toml::ser::Error> {
    let serials: Vec<&str> = lot.units.iter().map(|u| u.serial.as_str()).collect();
    let text = toml::to_string(&BenchCorrection {
        shared: lot
            .shared_effects
            .iter()
            .map(|s| Entry {
                name: &s.name,
                seat: &s.seat,
                units: &s.units,
                shrink: s.shrink,
                why: &s.seat_why,
                parameters: &s.parameters,
            })
            .collect(),
        effects: lot.bench_effects(),
    })?;
    let none = if lot.shared_effects.is_empty() {
        "# The units share no effect: there is nothing to correct on the bench.\n"
    } else {
        ""
    };
    Ok(format!(
        "# The bench's correction, from gyrobench diagnose --lot of {}: the effects\n# every unit listed shows with the same parameters, with where they likely\n# sit. Correct the bench (the seat), not the units' coefficients: given to\n# each unit they would hide a bench fault in every unit. [effects] holds them\n# as a twin takes them, for a simulation of this bench (each unit's\n# units/SERIAL/twin-on-this-bench.toml has them already).\n{none}{text}",
        serials.join(", ")
    ))
}

/// The directory of unit `serial`'s files, below the lot's.
pub fn unit_dir(serial: &str) -> std::path::PathBuf {
    std::path::Path::new("units").join(crate::unit::file_safe(serial))
}
