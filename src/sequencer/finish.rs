//! The end of a run on the bench: the state the bench is left in, read
//! back and compared with what the end of the run asked for (the last
//! cleanup commands, or the bench's safe state), in words for the report.

use super::{BenchIo, BenchLeft};
use crate::driver::{ChamberMode, ChamberReading, DeviceError, SupplyReading, TableReading};
use crate::geometry::TableAngles;

/// Air temperature below which a chamber is not opened: water condenses
/// on a unit taken out below the room's dew point (lab practice; 10 degC
/// covers a lab at 25 degC and 50 % relative humidity).
pub const COLD_BELOW_C: f64 = 10.0;

/// A set point read back within this of the one asked for is the same, degC.
pub const SET_POINT_TOLERANCE_C: f64 = 0.05;

/// An axis slower than this is at rest, deg/s.
pub const AT_REST_DPS: f64 = 0.01;

/// What the chamber was last asked to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChamberEnd {
    /// Hold this set point (a chamber step), degC.
    Constant(f64),
    /// Stand by (the safe state).
    Standby,
}

/// What the end of the run asks of the bench.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Expected {
    /// The chamber's last command (none: never commanded).
    pub chamber: Option<ChamberEnd>,
    /// Where the table was last sent (none: at rest anywhere).
    pub table: Option<TableAngles>,
    /// What the supply's output was last asked to be (a run starts it on;
    /// none: nothing known, nothing checked).
    pub power_on: Option<bool>,
    /// The bench's safe state leaves the supply's output on.
    pub supply_safe_on: bool,
    /// The safe state was applied after the last command.
    pub safe_state: bool,
    /// Devices whose cleanup steps were skipped (they failed during the
    /// run and stay in their safe state).
    pub skipped: Vec<String>,
}

impl Expected {
    /// A chamber step was carried out.
    pub fn chamber_set(&mut self, set_c: f64) {
        self.chamber = Some(ChamberEnd::Constant(set_c));
        self.safe_state = false;
    }

    /// A move was carried out.
    pub fn table_moved(&mut self, angles: TableAngles) {
        self.table = Some(angles);
        self.safe_state = false;
    }

    /// A power step was carried out.
    pub fn power_set(&mut self, on: bool) {
        self.power_on = Some(on);
        self.safe_state = false;
    }

    /// The safe state was applied: chamber standing by, table stopped
    /// wherever it was, the supply's output off (unless the bench's safe
    /// state leaves it on).
    pub fn safe(&mut self) {
        self.chamber = Some(ChamberEnd::Standby);
        self.table = None;
        if !self.supply_safe_on {
            self.power_on = Some(false);
        }
        self.safe_state = true;
    }
}

fn mode_word(m: ChamberMode) -> &'static str {
    match m {
        ChamberMode::Off => "off",
        ChamberMode::Standby => "in standby",
        ChamberMode::Constant => "constant",
    }
}

/// Compare what was read back with what was asked; the mismatches in words.
fn mismatches(
    c: &ChamberReading,
    t: &TableReading,
    expected: &Expected,
    in_position_deg: f64,
) -> Vec<String> {
    let mut bad = Vec::new();
    match expected.chamber {
        Some(ChamberEnd::Constant(sp))
            if c.mode != ChamberMode::Constant
                || (c.set_point_c - sp).abs() > SET_POINT_TOLERANCE_C =>
        {
            bad.push(format!(
                "the chamber was asked to hold {sp:+.2} degC but is {} at {:+.2} degC",
                mode_word(c.mode),
                c.set_point_c
            ));
        }
        Some(ChamberEnd::Standby) if c.mode == ChamberMode::Constant => {
            bad.push(format!(
                "the chamber was asked to stand by but holds {:+.2} degC",
                c.set_point_c
            ));
        }
        _ => {}
    }
    let rest = t.rates.outer_deg.abs() <= AT_REST_DPS && t.rates.inner_deg.abs() <= AT_REST_DPS;
    if !rest {
        bad.push(format!(
            "the table still turns (outer {:.3}, inner {:.3} deg/s)",
            t.rates.outer_deg, t.rates.inner_deg
        ));
    }
    if let Some(a) = expected.table {
        let err = |x: f64, y: f64| crate::geometry::wrap_deg(x - y).abs();
        if err(t.angles.outer_deg, a.outer_deg) > in_position_deg
            || err(t.angles.inner_deg, a.inner_deg) > in_position_deg
        {
            bad.push(format!(
                "the table was sent to outer {:.2} / inner {:.2} deg but is at {:.2} / {:.2}",
                a.outer_deg, a.inner_deg, t.angles.outer_deg, t.angles.inner_deg
            ));
        }
    }
    bad
}

/// Read the bench back and say whether it is in the state `expected`.
pub async fn bench_left(
    bench: &mut dyn BenchIo,
    expected: &Expected,
    in_position_deg: f64,
) -> BenchLeft {
    let intended = if expected.safe_state {
        "safe_state"
    } else {
        "cleanup"
    };
    let (c, t) = match bench.read_back().await {
        Ok(v) => v,
        Err(e) => return unreadable(intended, &e),
    };
    let mut bad = mismatches(&c, &t, expected, in_position_deg);
    let power = bench.read_power().await;
    let supply = supply_words(&power, expected, &mut bad);
    let at_rest = t.rates.outer_deg.abs() <= AT_REST_DPS && t.rates.inner_deg.abs() <= AT_REST_DPS;
    let table = format!(
        "table {} at outer {:.2} / inner {:.2} deg",
        if at_rest { "at rest" } else { "moving" },
        t.angles.outer_deg,
        t.angles.inner_deg
    );
    let chamber = chamber_words(&c);
    let devices = match supply {
        Some(s) => format!("{chamber}, {table}, {s}"),
        None => format!("{chamber}, {table}"),
    };
    let mut summary = if bad.is_empty() {
        format!("{devices}: {}, read back", what_was_asked(expected))
    } else {
        format!(
            "NOT as asked: {}; check the bench before anyone opens the chamber or touches the fixture",
            bad.join("; ")
        )
    };
    summary.push_str(&cautions(&c, &power));
    BenchLeft {
        intended: intended.into(),
        chamber_mode: c.mode.as_str().into(),
        chamber_set_point_c: Some(c.set_point_c),
        chamber_air_c: Some(c.air_c),
        table_deg: Some([t.angles.outer_deg, t.angles.inner_deg]),
        table_at_rest: Some(at_rest),
        supply_on: power.as_ref().ok().and_then(|p| p.map(|p| p.on)),
        supply_v: power.as_ref().ok().and_then(|p| p.map(|p| p.v)),
        supply_a: power.as_ref().ok().and_then(|p| p.map(|p| p.a)),
        verified: bad.is_empty(),
        summary,
    }
}

/// What is left to say of a bench that could not be read back.
fn unreadable(intended: &str, e: &DeviceError) -> BenchLeft {
    BenchLeft {
        intended: intended.into(),
        chamber_mode: "unknown".into(),
        chamber_set_point_c: None,
        chamber_air_c: None,
        table_deg: None,
        table_at_rest: None,
        supply_on: None,
        supply_v: None,
        supply_a: None,
        verified: false,
        summary: format!(
            "UNKNOWN: the bench could not be read back ({e}); check the chamber and the table before anyone opens the chamber or touches the fixture"
        ),
    }
}

/// The supply, when the bench has one, in words; an output not as asked,
/// or a supply that could not be read, goes to `bad`.
fn supply_words(
    power: &Result<Option<SupplyReading>, DeviceError>,
    expected: &Expected,
    bad: &mut Vec<String>,
) -> Option<String> {
    match power {
        Ok(Some(p)) => {
            if let Some(want) = expected.power_on
                && p.on != want
            {
                bad.push(format!(
                    "the supply was asked to switch the unit's power {} but its output is {} ({:.2} V, {:.3} A)",
                    if want { "on" } else { "off" },
                    if p.on { "on" } else { "off" },
                    p.v,
                    p.a
                ));
            }
            Some(if p.on {
                format!("unit powered at {:.2} V, {:.3} A", p.v, p.a)
            } else if p.tripped {
                format!("supply output off, its protection tripped ({:.2} V)", p.v)
            } else {
                format!("supply output off ({:.2} V)", p.v)
            })
        }
        Ok(None) => None,
        Err(e) => {
            bad.push(format!(
                "the supply could not be read back ({e}); check the unit's power at the supply"
            ));
            None
        }
    }
}

/// The chamber as read back, in words.
fn chamber_words(c: &ChamberReading) -> String {
    match c.mode {
        ChamberMode::Constant if (c.air_c - c.set_point_c).abs() > 1.0 => format!(
            "chamber on its way to {:+.1} degC (air {:+.1} degC now)",
            c.set_point_c, c.air_c
        ),
        ChamberMode::Constant => format!(
            "chamber holding {:+.1} degC (air {:+.1} degC)",
            c.set_point_c, c.air_c
        ),
        m => format!("chamber {} (air {:+.1} degC)", mode_word(m), c.air_c),
    }
}

/// What the end of the run asked the bench for, in words.
fn what_was_asked(expected: &Expected) -> String {
    if expected.safe_state {
        "the bench's safe state".to_owned()
    } else if expected.skipped.is_empty() {
        "as cleanup left it".to_owned()
    } else {
        format!(
            "as cleanup left it, except the {} (its cleanup was skipped; it stays in its safe state)",
            expected.skipped.join(" and the ")
        )
    }
}

/// What a person must mind before touching the bench: the chamber's
/// alarms, a tripped supply, a cold chamber ("; ..." each, or nothing).
fn cautions(c: &ChamberReading, power: &Result<Option<SupplyReading>, DeviceError>) -> String {
    let mut summary = String::new();
    if !c.alarms.is_empty() {
        summary.push_str(&format!(
            "; the chamber shows alarms {:?}: clear their cause at its panel",
            c.alarms
        ));
    }
    if let Ok(Some(p)) = &power
        && p.tripped
    {
        summary.push_str(
            "; the supply's over-current protection tripped: find what drew the current before clearing it and powering the unit again",
        );
    }
    if c.air_c < COLD_BELOW_C && c.mode != ChamberMode::Constant {
        summary.push_str(&format!(
            "; the chamber is cold (air {:+.1} degC): let it warm above the room's dew point before opening it",
            c.air_c
        ));
    }
    summary
}
