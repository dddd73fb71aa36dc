//! Which unit is unlike the lot, on what evidence, and where a shared
//! effect likely sits.
//!
//! A unit is set apart by its gap (with the shared effects given to the
//! bench, its held-out gap stands above `outlier_gap_ratio` times the
//! noise of its 60 s means, and what it holds beyond that noise stands
//! that many times above the median of the other units'), by its own
//! parameters of an effect the rest share, by an own
//! effect fewer than half the units show, or by a thermal layer that
//! misses where the others' match. It is flagged an outlier only in a lot
//! of three or more, and only when fewer than half the units are set
//! apart (medians and majorities: one odd unit cannot drag the lot's
//! figure with it).

use std::collections::BTreeMap;

use serde::Serialize;

use super::weigh::Differs;
use super::{LOT_THRESHOLDS, UnitResult};
use crate::geometry::EARTH_RATE_DPH;
use crate::library::Effect;

/// Above this held-out thermal gap (or twice the sensors' floor) a unit's
/// thermal layer misses (as the single-unit headline's, degC).
const THERMAL_GAP_C: f64 = 0.05;

/// One thing that sets a unit apart from the lot.
#[derive(Debug, Clone, Serialize)]
pub struct Evidence {
    /// `gap`, `shared_effect_differs`, `own_effect` or `thermal`.
    pub kind: String,
    /// The effect it is about (none for a gap or the thermal layer).
    pub effect: Option<String>,
    /// In words.
    pub text: String,
    /// The unit's figure: its gap over its noise (`gap`), the largest
    /// difference of its coefficients from the lot's in standard errors
    /// (`shared_effect_differs`), the units that show the effect
    /// (`own_effect`), its thermal gap over its limit (`thermal`).
    pub value: f64,
    /// The lot's: the other units' median (`gap`, `thermal`), 0, or the
    /// units in the lot (`own_effect`).
    pub lot_value: f64,
    /// The p-value it rests on, where there is one.
    pub p_value: Option<f64>,
}

/// The median of `v` (NaN when empty).
fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// The median of every value of `v` but the `u`-th.
fn median_of_others(v: &[f64], u: usize) -> f64 {
    median(
        v.iter()
            .enumerate()
            .filter(|&(k, _)| k != u)
            .map(|(_, x)| *x)
            .collect(),
    )
}

/// Each value against the median of the others': the indices of those
/// above `bar` in their own right and `bar` times above that median.
fn above_the_rest(v: &[f64], bar: f64) -> Vec<(usize, f64)> {
    (0..v.len())
        .filter_map(|u| {
            let others = median_of_others(v, u);
            (v[u] > bar && v[u] > bar * others).then_some((u, others))
        })
        .collect()
}

/// The units whose gap sets them apart, each with its gap over its noise,
/// the other units' median of that, its gap beyond its noise (deg/h,
/// `sqrt(gap^2 - noise^2)`) and the others' median of that. A gap beyond
/// the noise is compared, not the ratio: a residual every unit shares (a
/// bench effect the library does not hold whole) is the same in each, and
/// over the noise it would set the quietest unit apart.
fn gap_apart(units: &[UnitResult], bar: f64) -> Vec<(usize, [f64; 4])> {
    let ratios: Vec<f64> = units
        .iter()
        .map(|u| u.gap_after_shared_dph / u.noise_dph)
        .collect();
    let beyond: Vec<f64> = units
        .iter()
        .map(|u| {
            (u.gap_after_shared_dph.powi(2) - u.noise_dph.powi(2))
                .max(0.0)
                .sqrt()
        })
        .collect();
    (0..units.len())
        .filter_map(|u| {
            let others = median_of_others(&beyond, u);
            (ratios[u] > bar && beyond[u] > bar * others).then(|| {
                (
                    u,
                    [ratios[u], median_of_others(&ratios, u), beyond[u], others],
                )
            })
        })
        .collect()
}

/// Gather every unit's evidence, and flag the outliers: their serials,
/// or why none is flagged when some units are set apart.
pub(super) fn judge(
    units: &mut [UnitResult],
    differs: &[Differs],
) -> (Vec<String>, Option<String>) {
    let n = units.len();
    for (u, [ratio, others, beyond, others_beyond]) in
        gap_apart(units, LOT_THRESHOLDS.outlier_gap_ratio)
    {
        units[u].evidence.push(Evidence {
            kind: "gap".into(),
            effect: None,
            text: format!(
                "with the shared effects given to the bench its held-out gap is {:.5} deg/h, {ratio:.2} times the noise of its 60 s means (a median of {others:.2} times for the other units); beyond its noise it holds {beyond:.5} deg/h, against a median of {others_beyond:.5} deg/h for the others",
                units[u].gap_after_shared_dph
            ),
            value: ratio,
            lot_value: others,
            p_value: None,
        });
    }
    for d in differs {
        units[d.unit].evidence.push(Evidence {
            kind: "shared_effect_differs".into(),
            effect: Some(d.effect.name().into()),
            text: format!(
                "the other units share {} and its own differs (p {:.2e}): {} against the lot's {} ({} off by {:.1} standard errors)",
                d.effect.name(),
                d.p_value,
                coefficients(d.effect, &d.value),
                coefficients(d.effect, &d.lot),
                coefficient(d.effect, &d.z.1, 0.0)
                    .split(" = ")
                    .next()
                    .unwrap_or_default(),
                d.z.0.abs()
            ),
            value: d.z.0.abs(),
            lot_value: 0.0,
            p_value: Some(d.p_value),
        });
    }
    own_effects(units);
    thermal(units);
    let apart: Vec<usize> = (0..n).filter(|&u| !units[u].evidence.is_empty()).collect();
    if apart.is_empty() {
        return (Vec::new(), None);
    }
    let names = |us: &[usize]| {
        us.iter()
            .map(|&u| units[u].serial.clone())
            .collect::<Vec<_>>()
    };
    if n < 3 {
        return (
            Vec::new(),
            Some(format!(
                "a lot of two cannot tell which unit is unlike the lot: {} differs from the other (its evidence is listed), and either could be the odd one",
                names(&apart).join(" and ")
            )),
        );
    }
    if apart.len() > (n - 1) / 2 {
        return (
            Vec::new(),
            Some(format!(
                "{} of the {n} units are set apart ({}): a lot most of whose units differ has no single outlier; see each unit's evidence",
                apart.len(),
                names(&apart).join(", ")
            )),
        );
    }
    let flagged = names(&apart);
    for &u in &apart {
        units[u].outlier = true;
    }
    (flagged, None)
}

/// An own effect fewer than half the units show sets each of them apart.
fn own_effects(units: &mut [UnitResult]) {
    let n = units.len();
    if n < 3 {
        return;
    }
    let showing = |units: &[UnitResult], name: &str| {
        units
            .iter()
            .filter(|u| u.effects.iter().any(|a| a.name == name))
            .count()
    };
    for u in 0..n {
        let found: Vec<(String, usize, f64)> = units[u]
            .effects
            .iter()
            .map(|a| (a.name.clone(), showing(units, &a.name), a.p_value))
            .filter(|(_, k, _)| *k <= (n - 1) / 2)
            .collect();
        for (name, k, p) in found {
            units[u].evidence.push(Evidence {
                kind: "own_effect".into(),
                effect: Some(name.clone()),
                text: format!(
                    "{name} is its own: {k} of the {n} units show it (named in its own diagnosis, p {p:.2e})"
                ),
                value: k as f64,
                lot_value: n as f64,
                p_value: Some(p),
            });
        }
    }
}

/// A thermal layer that misses where the other units' match: the unit's
/// chamber slot (its air), or its own thermal path.
fn thermal(units: &mut [UnitResult]) {
    let over: Vec<f64> = units
        .iter()
        .map(|u| u.thermal_gap_c / THERMAL_GAP_C.max(2.0 * u.thermal_noise_floor_c))
        .collect();
    for (u, others) in above_the_rest(&over, 1.0) {
        if others > 1.0 {
            continue;
        }
        units[u].evidence.push(Evidence {
            kind: "thermal".into(),
            effect: None,
            text: format!(
                "its thermal layer misses ({:.3} degC held out, {:.1} times its limit) where the other units' match (median {:.1} times): its chamber slot's air, or its own thermal path, differs",
                units[u].thermal_gap_c, over[u], others
            ),
            value: over[u],
            lot_value: others,
            p_value: None,
        });
    }
}

/// A coefficient in words: a misalignment's in arcmin (its coefficients
/// are theta_z and -theta_y, rad), the rest as fitted.
fn coefficient(e: Effect, k: &str, v: f64) -> String {
    match (e, k) {
        (Effect::AxisMisalignment, "earth_y") => {
            format!("theta_z = {:.2} arcmin", v.to_degrees() * 60.0)
        }
        (Effect::AxisMisalignment, "earth_z") => {
            format!("-theta_y = {:.2} arcmin", v.to_degrees() * 60.0)
        }
        _ => format!("{k} = {v:.3e}"),
    }
}

/// Coefficients in words.
fn coefficients(e: Effect, m: &BTreeMap<String, f64>) -> String {
    m.iter()
        .map(|(k, v)| coefficient(e, k, *v))
        .collect::<Vec<_>>()
        .join(", ")
}

/// What an Earth-rate error is in the bench's words, at latitude
/// `latitude_deg` (the one the runs state): the latitude it states off
/// (its part across the Earth rate in the north-down plane: the Earth
/// rate turns by `15.04 deg/h` a radian of latitude) and the north its
/// table states off (its east part: an axis turned by `psi` about down
/// reads `-psi 15.04 cos lat` east).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EarthRateError {
    /// The latitude the runs state minus the one the units sense, deg.
    pub latitude_deg: f64,
    /// The table's azimuths as stated minus as they are, deg (or an
    /// east-west tilt of its axis; see `seat`).
    pub north_deg: f64,
}

impl EarthRateError {
    /// From the fitted `latitude_dph` and `east_dph`.
    pub fn of(parameters: &BTreeMap<String, f64>, latitude_deg: f64) -> Self {
        let get = |k: &str| parameters.get(k).copied().unwrap_or(0.0);
        let cos = latitude_deg.to_radians().cos().abs().max(1e-3);
        Self {
            // The units sense Omega(true), the bench subtracts
            // Omega(stated): the error is dOmega/dlat (true - stated).
            latitude_deg: -(get("latitude_dph") / EARTH_RATE_DPH).to_degrees(),
            north_deg: (get("east_dph") / (EARTH_RATE_DPH * cos)).to_degrees(),
        }
    }
}

/// Where an effect every unit of a lot shows alike likely sits, and why:
/// `fixture`, `table`, `site` or `type` (ours, from the geometry of
/// `docs/physics.md`); `latitude_deg` is the one the lot's runs state.
pub fn seat(
    e: Effect,
    parameters: &BTreeMap<String, f64>,
    latitude_deg: f64,
) -> (&'static str, String) {
    let along_axis = |names: [&str; 3]| {
        let v = names.map(|k| parameters.get(k).copied().unwrap_or(0.0).abs());
        v[0] >= v[1].max(v[2])
    };
    match e {
        Effect::EarthRateError => {
            let x = EarthRateError::of(parameters, latitude_deg);
            let get = |k: &str| parameters.get(k).copied().unwrap_or(0.0).abs();
            if get("latitude_dph") >= get("east_dph") {
                (
                    "site",
                    format!(
                        "every unit reads the same vector fixed in north-east-down along its sensitive axis, mostly in the north-down plane across the Earth rate: the Earth rate the bench subtracts is that of a latitude {:.2} deg off the true one (the runs state {:.4} deg; the units sense about {:.4} deg), or the table's axis is tilted north-south by as much. Check the site file's latitude, then the table's level; correct the bench, not the units' coefficients",
                        x.latitude_deg,
                        latitude_deg,
                        latitude_deg - x.latitude_deg
                    ),
                )
            } else {
                (
                    "table",
                    format!(
                        "every unit reads the same vector fixed in north-east-down along its sensitive axis, mostly east: the table's north reference is off by about {:.2} deg (every azimuth turned alike), or its axis is tilted east-west. Check the table's azimuth alignment against true north, then its level; correct the bench, not the units' coefficients",
                        x.north_deg
                    ),
                )
            }
        }
        Effect::AxisMisalignment => (
            "fixture",
            "every unit's sensitive axis is off by the same angles in its own frame: the mount they sit in (the fixture, or the table's inner axis) tilts them alike. Check the fixture's seating and the table's alignment before changing any unit's coefficients; the same units in another fixture, or a unit turned in its slot, would tell".into(),
        ),
        Effect::GSensitivity | Effect::MagneticSensitivity
            if along_axis(if e == Effect::GSensitivity {
                ["x_dph_per_g", "y_dph_per_g", "z_dph_per_g"]
            } else {
                ["x_dph_per_ut", "y_dph_per_ut", "z_dph_per_ut"]
            }) =>
        (
            "table",
            format!(
                "every unit reads the same share of a vector fixed on the bench, mostly along its sensitive axis: a table axis off its stated direction (or the site's latitude or north stated wrong) moves the Earth rate the bench subtracts by a fixed vector in the north-down plane, which reads as a {} along the axis in every unit alike. Check the table's level and the site file; a unit of another type on the same bench would tell the bench from the type",
                e.name()
            ),
        ),
        Effect::GSensitivity | Effect::MagneticSensitivity => (
            if e == Effect::MagneticSensitivity {
                "site"
            } else {
                "type"
            },
            format!(
                "every unit shows the same {} across its axis: the units' common design{}; units of another type on this bench, or these units on another bench, would tell",
                e.name(),
                if e == Effect::MagneticSensitivity {
                    ", or a field on the bench itself (a magnetised table or chamber part every slot sits near)"
                } else {
                    ""
                }
            ),
        ),
        Effect::Hysteresis | Effect::ThermalLag => (
            "fixture",
            format!(
                "every unit's bias follows its temperature history the same way ({}): the fixture's mounting stress as it warms and cools acts on every unit it holds alike; or the units' common design. The same units in another fixture would tell",
                e.name()
            ),
        ),
        _ => (
            "type",
            format!(
                "no part of the bench makes a {} alike in every unit: the units' common design is the likeliest seat",
                e.name()
            ),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit with held-out gap `gap` over noise `noise`, deg/h, and a
    /// thermal layer that matches.
    fn unit(serial: &str, gap: f64, noise: f64) -> UnitResult {
        UnitResult {
            serial: serial.into(),
            slot: String::new(),
            runs: Vec::new(),
            effects: Vec::new(),
            outlier: false,
            evidence: Vec::new(),
            gap_dph: gap,
            gap_after_shared_dph: gap,
            gap_after_dph: gap,
            noise_dph: noise,
            thermal_gap_c: 0.01,
            thermal_noise_floor_c: 0.01,
            confounded: Vec::new(),
            inconclusive: None,
        }
    }

    #[test]
    fn a_residual_every_unit_shares_sets_no_unit_apart() {
        // 0.02 deg/h left in every unit over noises of 0.01, 0.02, 0.03:
        // over its noise the quietest stands 2.2 times, the others 1.4
        // and 1.2, yet each holds the same beyond it.
        let r: f64 = 0.02;
        let mut units: Vec<UnitResult> = [0.01_f64, 0.02, 0.03]
            .iter()
            .enumerate()
            .map(|(k, &n)| unit(&format!("U{k}"), r.hypot(n), n))
            .collect();
        let (flagged, why) = judge(&mut units, &[]);
        assert!(flagged.is_empty(), "{:?}", units[0].evidence);
        assert!(why.is_none());
    }

    #[test]
    fn a_unit_with_a_gap_of_its_own_is_the_outlier() {
        let mut units = vec![
            unit("U0", 0.0105, 0.01),
            unit("U1", 0.0210, 0.02),
            unit("U2", 0.0300, 0.01),
            unit("U3", 0.0110, 0.01),
        ];
        let (flagged, _) = judge(&mut units, &[]);
        assert_eq!(flagged, ["U2"]);
        assert!(units[2].outlier);
        let e = &units[2].evidence[0];
        assert_eq!(e.kind, "gap");
        assert!((e.value - 3.0).abs() < 1e-9, "{e:?}");
        assert!(e.text.contains("0.02828 deg/h"), "{}", e.text);
    }
}
