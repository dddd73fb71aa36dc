//! Device time a procedure will take, step by step, before anything moves.

use super::{Procedure, Step, StepKind};
use crate::geometry::TableAngles;
use crate::limits::BenchLimits;

/// Room temperature the chamber is assumed to start from, degC (ours).
pub const START_C: f64 = 20.0;

/// Estimated device time of one step, s: exact where the step fixes it,
/// a range where it waits for the physics (soak).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// Shortest, s.
    pub min_s: f64,
    /// Longest, s (the timeout for a soak).
    pub max_s: f64,
}

/// Time for an axis to travel `d` deg from rest to rest, s.
pub fn travel_s(d: f64, rate: f64, acc: f64) -> f64 {
    let d = d.abs();
    if d * acc >= rate * rate {
        d / rate + rate / acc
    } else {
        2.0 * (d / acc).sqrt()
    }
}

/// Device time the whole procedure needs at least, s (progress bars, the
/// station's offer).
pub fn min_total_s(p: &Procedure, bench: &BenchLimits) -> f64 {
    estimate(p, bench).iter().map(|(_, e)| e.min_s).sum()
}

/// Per-step estimates in run order (setup, main, cleanup). The table is
/// assumed to start at (0, 0) and the chamber at [`START_C`].
pub fn estimate<'p>(p: &'p Procedure, bench: &BenchLimits) -> Vec<(&'p Step, Estimate)> {
    let l = &bench.limits;
    let settle = bench.table_settle_s;
    let mut table = TableAngles::default();
    let mut chamber_c = START_C;
    let mut ramp_left_s = 0.0_f64;
    let mut turning_dps = 0.0_f64;
    let mut out = Vec::new();
    for s in p.steps() {
        let (lo, hi) = match &s.kind {
            StepKind::Chamber {
                set_c,
                ramp_c_per_min,
            } => {
                ramp_left_s = (set_c - chamber_c).abs() / ramp_c_per_min * 60.0;
                chamber_c = *set_c;
                (0.0, 0.0)
            }
            StepKind::Soak {
                hold_s, timeout_s, ..
            } => (ramp_left_s + hold_s, *timeout_s),
            // A second or two to read the output at its new state.
            StepKind::Power { .. } => (1.0, super::POWER_TIMEOUT_S),
            StepKind::Move { angles, .. } => {
                let t = travel_s(
                    angles.outer_deg - table.outer_deg,
                    l.table_max_rate_dps,
                    l.table_max_acc_dps2,
                )
                .max(travel_s(
                    angles.inner_deg - table.inner_deg,
                    l.table_max_rate_dps,
                    l.table_max_acc_dps2,
                )) + settle;
                table = *angles;
                (t, t)
            }
            StepKind::Turn {
                rate_dps,
                settle_s,
                acc_dps2,
                ..
            } => {
                let acc = acc_dps2
                    .or(l.rate_mode().map(|(_, a)| a))
                    .unwrap_or(l.table_max_acc_dps2);
                let t = (rate_dps - turning_dps).abs() / acc + settle_s;
                turning_dps = *rate_dps;
                (t, t)
            }
            StepKind::Wait { duration_s } | StepKind::Record { duration_s, .. } => {
                (*duration_s, *duration_s)
            }
            StepKind::Measure(_) | StepKind::Note { .. } | StepKind::Prompt { .. } => (0.0, 0.0),
        };
        ramp_left_s = (ramp_left_s - lo).max(0.0);
        out.push((
            s,
            Estimate {
                min_s: lo,
                max_s: hi,
            },
        ));
    }
    out
}
