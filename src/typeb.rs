//! The bench's own uncertainties (`[uncertainty]` in a bench file): the
//! Type B contributions a lab declares for its table, its alignment, its
//! site, its temperature sensors, its clocks and its supply, each with
//! where it comes from (a certificate, a datasheet, an alignment record).
//! Every judged figure's budget takes the ones that reach it
//! (`sequencer::uncertainty`, `docs/figures.md`).
//!
//! An entry gives one of: `u` (a standard uncertainty), `half_width` (the
//! bound of a rectangular distribution: `u = a / sqrt(3)`), or `expanded`
//! with its `k` (a certificate's `U`: `u = U / k`).

use serde::{Deserialize, Serialize};

use crate::analysis::uncertainty::rectangular;
use crate::config::{Checker, ConfigError};

/// One declared contribution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Declared {
    /// A standard uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u: Option<f64>,
    /// The half-width of a rectangular distribution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_width: Option<f64>,
    /// An expanded uncertainty, with its coverage factor `k`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expanded: Option<f64>,
    /// The coverage factor of `expanded`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k: Option<f64>,
    /// Where it comes from (a certificate's number, a datasheet, a record).
    pub source: String,
}

impl Declared {
    /// The standard uncertainty it declares, in its key's unit.
    pub fn standard(&self) -> f64 {
        match (self.u, self.half_width, self.expanded, self.k) {
            (Some(u), _, _, _) => u,
            (_, Some(a), _, _) => rectangular(a),
            (_, _, Some(e), Some(k)) => e / k,
            _ => 0.0,
        }
    }

    /// How it was turned into a standard uncertainty, with its source.
    pub fn basis(&self) -> String {
        let how = match (self.u, self.half_width, self.expanded, self.k) {
            (Some(u), _, _, _) => format!("standard uncertainty {u}"),
            (_, Some(a), _, _) => format!("rectangular, half-width {a}: a/sqrt(3)"),
            (_, _, Some(e), Some(k)) => format!("expanded {e} at k = {k}: U/k"),
            _ => "none".to_owned(),
        };
        format!("{how} ({})", self.source)
    }

    fn validate(&self, c: &Checker, key: &str) -> Result<(), ConfigError> {
        let given = [self.u, self.half_width, self.expanded]
            .iter()
            .filter(|v| v.is_some())
            .count();
        c.ensure(
            given == 1,
            key,
            "give exactly one of u (a standard uncertainty), half_width (a rectangular bound) or expanded with k",
        )?;
        for (v, what) in [
            (self.u, "u"),
            (self.half_width, "half_width"),
            (self.expanded, "expanded"),
        ] {
            if let Some(v) = v {
                c.within(v, 0.0, 1e6, &format!("{key}.{what}"))?;
            }
        }
        match (self.expanded, self.k) {
            (Some(_), Some(k)) => {
                c.within(k, 1.0, 10.0, &format!("{key}.k"))?;
            }
            (Some(_), None) => c.ensure(false, key, "an expanded uncertainty needs its k")?,
            (None, Some(_)) => c.ensure(false, key, "k goes with expanded")?,
            (None, None) => {}
        }
        c.ensure(
            !self.source.trim().is_empty() && self.source.len() <= 200,
            &format!("{key}.source"),
            "say where the value comes from (a certificate, a datasheet, a record), at most 200 characters",
        )
    }
}

/// `[uncertainty]`: the bench's declared Type B contributions. A key left
/// out is a contribution the lab has not declared: a budget it would
/// reach says so.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TypeB {
    /// Accuracy of the table's rate in rate mode, ppm of the rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_rate_ppm: Option<Declared>,
    /// Accuracy of the table's angle (its encoder), arcsec.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_angle_arcsec: Option<Declared>,
    /// How well the table's reference azimuth points north, arcsec.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub north_alignment_arcsec: Option<Declared>,
    /// How level the table's axes are, arcsec.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub level_arcsec: Option<Declared>,
    /// The site's latitude, deg.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latitude_deg: Option<Declared>,
    /// The chamber's air temperature against its set point, degC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chamber_temperature_c: Option<Declared>,
    /// The unit's temperature sensors, degC.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_temperature_c: Option<Declared>,
    /// The bench PC's clock (durations, tick times), ppm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bench_clock_ppm: Option<Declared>,
    /// The unit's frame clock (the period rates are formed over), ppm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit_clock_ppm: Option<Declared>,
    /// The supply's voltage reading, V.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply_volts: Option<Declared>,
    /// The supply's current reading, A.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply_amps: Option<Declared>,
}

/// One of the bench's declared contributions by what it bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// `table_rate_ppm`.
    TableRate,
    /// `table_angle_arcsec`.
    TableAngle,
    /// `north_alignment_arcsec`.
    NorthAlignment,
    /// `level_arcsec`.
    Level,
    /// `latitude_deg`.
    Latitude,
    /// `chamber_temperature_c`.
    ChamberTemperature,
    /// `sensor_temperature_c`.
    SensorTemperature,
    /// `bench_clock_ppm`.
    BenchClock,
    /// `unit_clock_ppm`.
    UnitClock,
    /// `supply_volts`.
    SupplyVolts,
    /// `supply_amps`.
    SupplyAmps,
}

impl Source {
    /// Its key in `[uncertainty]`.
    pub fn key(self) -> &'static str {
        match self {
            Self::TableRate => "table_rate_ppm",
            Self::TableAngle => "table_angle_arcsec",
            Self::NorthAlignment => "north_alignment_arcsec",
            Self::Level => "level_arcsec",
            Self::Latitude => "latitude_deg",
            Self::ChamberTemperature => "chamber_temperature_c",
            Self::SensorTemperature => "sensor_temperature_c",
            Self::BenchClock => "bench_clock_ppm",
            Self::UnitClock => "unit_clock_ppm",
            Self::SupplyVolts => "supply_volts",
            Self::SupplyAmps => "supply_amps",
        }
    }

    /// In words, for a budget's line.
    pub fn words(self) -> &'static str {
        match self {
            Self::TableRate => "table rate accuracy",
            Self::TableAngle => "table angle accuracy",
            Self::NorthAlignment => "north alignment of the table",
            Self::Level => "level of the table",
            Self::Latitude => "site latitude",
            Self::ChamberTemperature => "chamber temperature accuracy",
            Self::SensorTemperature => "unit temperature sensors' accuracy",
            Self::BenchClock => "bench PC clock",
            Self::UnitClock => "unit frame clock",
            Self::SupplyVolts => "supply voltage reading",
            Self::SupplyAmps => "supply current reading",
        }
    }
}

impl TypeB {
    /// True when the bench declares nothing.
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// The declared entry for `s`, if the bench declares it.
    pub fn get(&self, s: Source) -> Option<&Declared> {
        match s {
            Source::TableRate => self.table_rate_ppm.as_ref(),
            Source::TableAngle => self.table_angle_arcsec.as_ref(),
            Source::NorthAlignment => self.north_alignment_arcsec.as_ref(),
            Source::Level => self.level_arcsec.as_ref(),
            Source::Latitude => self.latitude_deg.as_ref(),
            Source::ChamberTemperature => self.chamber_temperature_c.as_ref(),
            Source::SensorTemperature => self.sensor_temperature_c.as_ref(),
            Source::BenchClock => self.bench_clock_ppm.as_ref(),
            Source::UnitClock => self.unit_clock_ppm.as_ref(),
            Source::SupplyVolts => self.supply_volts.as_ref(),
            Source::SupplyAmps => self.supply_amps.as_ref(),
        }
    }

    /// Check every entry given (`[uncertainty].KEY`).
    pub fn validate(&self, c: &Checker) -> Result<(), ConfigError> {
        for s in [
            Source::TableRate,
            Source::TableAngle,
            Source::NorthAlignment,
            Source::Level,
            Source::Latitude,
            Source::ChamberTemperature,
            Source::SensorTemperature,
            Source::BenchClock,
            Source::UnitClock,
            Source::SupplyVolts,
            Source::SupplyAmps,
        ] {
            if let Some(d) = self.get(s) {
                d.validate(c, &format!("uncertainty.{}", s.key()))?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Source as Text;

    fn parse(text: &str) -> Result<TypeB, ConfigError> {
        #[derive(Deserialize)]
        struct Wrap {
            uncertainty: TypeB,
        }
        let src = Text::from_text("b.toml", text);
        let w: Wrap = src.parse()?;
        w.uncertainty.validate(&Checker::new(&src))?;
        Ok(w.uncertainty)
    }

    #[test]
    fn each_form_gives_its_standard_uncertainty() {
        let t = parse(
            "[uncertainty]\ntable_rate_ppm = { half_width = 3.0, source = \"cert 17\" }\n\
             latitude_deg = { u = 0.001, source = \"survey\" }\n\
             level_arcsec = { expanded = 10.0, k = 2.0, source = \"record\" }\n",
        )
        .expect("valid");
        let rate = t.get(Source::TableRate).expect("declared");
        assert!((rate.standard() - 3.0 / 3f64.sqrt()).abs() < 1e-12);
        assert!(rate.basis().contains("cert 17"));
        assert_eq!(t.get(Source::Latitude).map(Declared::standard), Some(0.001));
        assert_eq!(t.get(Source::Level).map(Declared::standard), Some(5.0));
        assert!(t.get(Source::UnitClock).is_none());
    }

    #[test]
    fn a_bad_entry_is_refused_at_its_key() {
        for (text, says) in [
            (
                "table_rate_ppm = { u = 1.0, half_width = 2.0, source = \"x\" }",
                "uncertainty.table_rate_ppm",
            ),
            (
                "table_rate_ppm = { expanded = 2.0, source = \"x\" }",
                "needs its k",
            ),
            (
                "table_rate_ppm = { u = -1.0, source = \"x\" }",
                "table_rate_ppm.u",
            ),
            (
                "table_rate_ppm = { u = 1.0, source = \"\" }",
                "where the value comes from",
            ),
            (
                "table_rate_pmm = { u = 1.0, source = \"x\" }",
                "unknown field",
            ),
        ] {
            let e = parse(&format!("[uncertainty]\n{text}\n")).expect_err(text);
            assert!(e.to_string().contains(says), "{text}: {e}");
        }
    }
}
