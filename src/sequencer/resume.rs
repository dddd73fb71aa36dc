//! Where an interrupted run picks up, and what brings the bench back to
//! the conditions the steps from there need (`docs/procedures.md`, "What a
//! resume retakes").
//!
//! A procedure is a chain of thermal segments, each from a chamber step to
//! the next. Records taken while the chamber ramped or settled (no soak
//! step between the segment's chamber step and them) measure the unit's
//! response to that change: they cannot be continued after a break, so
//! the segment is taken again from its chamber step. Before it, the bench
//! is brought back to where the previous segment left it:
//!
//! - the table to its last position;
//! - the chamber to the previous segment's set point, at its ramp rate,
//!   until the air is there (bounded by the time to cross the
//!   procedure's temperature range at that rate);
//! - then, when that segment had a soak step, that soak with its own
//!   criteria: the procedure's own word for "settled"; when it had none,
//!   a dwell at the set point as long as the procedure held it there.
//!
//! Nothing before the interrupted segment is taken again.

use super::measure::Records;
use crate::procedure::{Procedure, Step, StepKind};
use gyrobench_model::measurement::Measurement;

/// Where a resumed run picks up, and what the earlier parts left.
#[derive(Debug, Clone, Default)]
pub struct Resume {
    /// Index, in setup + main run order, of the first step to run
    /// ([`resume_plan`]).
    pub start_at: usize,
    /// Steps the earlier parts completed.
    pub completed: usize,
    /// Which part this is (2 for the first resume).
    pub part: u32,
    /// Records of the earlier parts ([`Resume::trim`]med).
    pub records: Records,
    /// Measurements the earlier parts made (trimmed).
    pub measurements: Vec<Measurement>,
    /// Frames of the earlier parts.
    pub frames: u64,
    /// Device time of the earlier parts, s.
    pub device_time_s: f64,
    /// A batch's other units: what the earlier parts left of each (in
    /// unit order).
    pub others: Vec<UnitResume>,
}

/// What the earlier parts of a batch left of one more unit.
#[derive(Debug, Clone, Default)]
pub struct UnitResume {
    /// Its records ([`Resume::trim`]med).
    pub records: Records,
    /// Its measurements (trimmed).
    pub measurements: Vec<Measurement>,
    /// Its frames.
    pub frames: u64,
}

/// Room temperature a chamber starts from, degC (a procedure's first
/// segment ramps from it).
pub const ROOM_C: f64 = 20.0;

/// Air within this of the set point counts as arrived, degC.
pub const ARRIVED_BAND_C: f64 = 1.0;

/// Margin on every restore timeout, s.
pub const RESTORE_MARGIN_S: f64 = 3600.0;

/// Where a resume picks up after `completed` steps (setup + main, run
/// order), and the steps that first bring the bench back, each with the
/// run-order index of the step it stands for.
pub fn resume_plan(p: &Procedure, completed: usize) -> (usize, Vec<(usize, Step)>) {
    let steps: Vec<&Step> = p.setup.iter().chain(&p.main).collect();
    let completed = completed.min(steps.len());
    let is_chamber = |s: &&Step| matches!(s.kind, StepKind::Chamber { .. });
    let is_soak = |s: &&Step| matches!(s.kind, StepKind::Soak { .. });
    let last_chamber_before = |end: usize| steps[..end].iter().rposition(is_chamber);

    // The step cut short opens a new segment when it is a chamber step:
    // nothing of that segment was done, and the one before ended whole.
    let mut start_at = completed;
    let cut_short = steps.get(completed);
    if cut_short.is_some_and(|s| !is_chamber(s))
        && let Some(c) = last_chamber_before(completed)
        && !steps[c + 1..completed].iter().any(is_soak)
        && steps[c + 1..=completed]
            .iter()
            .any(|s| matches!(s.kind, StepKind::Record { .. }))
    {
        start_at = c;
    }

    // A record taken while the table turns starts again with its turn.
    if start_at > 0
        && steps
            .get(start_at)
            .is_some_and(|s| matches!(s.kind, StepKind::Record { .. }))
        && matches!(steps[start_at - 1].kind, StepKind::Turn { rate_dps, .. } if rate_dps != 0.0)
    {
        start_at -= 1;
    }

    // A turn-on whose records the break reached is taken again from the
    // turn-on (a record right after it, a warm-up, counts from turn-on), and
    // with the time off before it when that is where the procedure put it
    // (a cool-down: the turn-on is a cold one). The safe state switched the
    // unit off anyway. The turn-on's records are those that follow it with
    // nothing but measures, waits and notes between: a thermal run's later
    // records (after a chamber step) are a segment of their own, resumed
    // on a new power-on of their part, as model 4 counts them.
    let is_power = |s: &&Step| matches!(s.kind, StepKind::Power { .. });
    let turn_on_end = |pw: usize| {
        steps[pw + 1..]
            .iter()
            .position(|s| {
                !matches!(
                    s.kind,
                    StepKind::Record { .. }
                        | StepKind::Measure(_)
                        | StepKind::Wait { .. }
                        | StepKind::Note { .. }
                )
            })
            .map_or(steps.len(), |i| pw + 1 + i)
    };
    if let Some(pw) = steps[..completed].iter().rposition(is_power)
        && matches!(steps[pw].kind, StepKind::Power { on: true, .. })
        && pw < start_at
        && completed < steps.len()
        && completed < turn_on_end(pw)
        && steps[pw + 1..=completed]
            .iter()
            .any(|s| matches!(s.kind, StepKind::Record { .. }))
    {
        start_at = pw;
        if let Some(off) = steps[..pw].iter().rposition(is_power)
            && matches!(steps[off].kind, StepKind::Power { on: false, .. })
            && steps[off + 1..pw].iter().all(|s| {
                matches!(
                    s.kind,
                    StepKind::Wait { .. } | StepKind::Move { .. } | StepKind::Note { .. }
                )
            })
        {
            start_at = off;
        }
    }
    // On the way to a turn-on (in its cool-down, the move before it, the
    // turn-on itself): from the power-off, so the cool-down is whole and
    // the turn-on cold, whatever the bench did with the power meanwhile.
    let idle = |s: &&Step| {
        matches!(
            s.kind,
            StepKind::Wait { .. } | StepKind::Move { .. } | StepKind::Note { .. }
        )
    };
    let next_on = steps[completed.min(steps.len())..]
        .iter()
        .position(|s| !idle(s))
        .map(|i| completed + i)
        .filter(|&i| matches!(steps[i].kind, StepKind::Power { on: true, .. }));
    if next_on.is_some()
        && let Some(off) = steps[..completed].iter().rposition(is_power)
        && matches!(steps[off].kind, StepKind::Power { on: false, .. })
        && steps[off + 1..completed].iter().all(idle)
    {
        start_at = start_at.min(off);
    }
    // The unit's power as the last power step before the resume point left
    // it: a switch-on first (a soak reads the unit's case sensor, which an
    // unpowered unit does not send, and the part's records count from that
    // power-on), a switch-off last.
    let power = steps[..start_at]
        .iter()
        .rposition(is_power)
        .map(|pw| (pw, steps[pw].clone()));
    let (start_at, mut restore) = restore_conditions(&steps, start_at);
    match power {
        Some(on) if matches!(on.1.kind, StepKind::Power { on: true, .. }) => {
            restore.insert(0, on);
        }
        off => restore.extend(off),
    }
    (start_at, restore)
}

/// The steps that bring the bench back to the table pose and chamber
/// condition a resume at `start_at` needs.
fn restore_conditions(steps: &[&Step], start_at: usize) -> (usize, Vec<(usize, Step)>) {
    let is_chamber = |s: &&Step| matches!(s.kind, StepKind::Chamber { .. });
    let is_soak = |s: &&Step| matches!(s.kind, StepKind::Soak { .. });
    let last_chamber_before = |end: usize| steps[..end].iter().rposition(is_chamber);
    let mut restore: Vec<(usize, Step)> = Vec::new();
    if let Some(m) = steps[..start_at]
        .iter()
        .rposition(|s| matches!(s.kind, StepKind::Move { .. }))
    {
        restore.push((m, steps[m].clone()));
    }
    let Some(pc) = last_chamber_before(start_at) else {
        return (start_at, restore);
    };
    let StepKind::Chamber {
        set_c,
        ramp_c_per_min,
    } = steps[pc].kind
    else {
        return (start_at, restore);
    };
    restore.push((pc, steps[pc].clone()));
    let derived = |suffix: &str, kind: StepKind| Step {
        group: steps[pc].group,
        key: format!("{}.{suffix}", steps[pc].key),
        line: steps[pc].line,
        kind,
    };
    // Until the air is at the set point, from wherever the chamber is in
    // the procedure's range.
    let (lo, hi) = steps
        .iter()
        .filter_map(|s| match s.kind {
            StepKind::Chamber { set_c, .. } => Some(set_c),
            _ => None,
        })
        .fold((ROOM_C, ROOM_C), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let travel_s = 60.0 * (hi - lo) / ramp_c_per_min;
    restore.push((
        pc,
        derived(
            "resume_arrive",
            StepKind::Soak {
                band_c: ARRIVED_BAND_C,
                // Air only: the case is the dwell's or the soak's business.
                case_slope_c_per_min: f64::INFINITY,
                hold_s: 60.0,
                timeout_s: travel_s + RESTORE_MARGIN_S,
            },
        ),
    ));
    let segment = &steps[pc + 1..start_at];
    match segment
        .iter()
        .rev()
        .find(|s| is_soak(s))
        .map(|s| s.kind.clone())
    {
        Some(StepKind::Soak {
            band_c,
            case_slope_c_per_min,
            hold_s,
            timeout_s,
        }) => restore.push((
            pc,
            derived(
                "resume_soak",
                StepKind::Soak {
                    band_c,
                    case_slope_c_per_min,
                    hold_s,
                    timeout_s: timeout_s + RESTORE_MARGIN_S,
                },
            ),
        )),
        _ => {
            let before = last_chamber_before(pc).map_or(ROOM_C, |b| match steps[b].kind {
                StepKind::Chamber { set_c, .. } => set_c,
                _ => ROOM_C,
            });
            let held_s = held_s(segment, 60.0 * (set_c - before).abs() / ramp_c_per_min);
            if held_s >= 1.0 {
                restore.push((
                    pc,
                    derived("resume_dwell", StepKind::Wait { duration_s: held_s }),
                ));
            }
        }
    }
    (start_at, restore)
}

/// How long a segment without a soak held its set point, s: its waits
/// and records less the ramp into it (`ramp_s` from the set point before).
fn held_s(segment: &[&Step], ramp_s: f64) -> f64 {
    segment
        .iter()
        .map(|s| match s.kind {
            StepKind::Wait { duration_s } | StepKind::Record { duration_s, .. } => duration_s,
            _ => 0.0,
        })
        .sum::<f64>()
        - ramp_s
}

/// What a resume after `completed` steps retakes, in the words every
/// place uses (`run --resume`, the station, the log): steps are counted
/// as the progress counts them, `[n/N]` over the procedure's setup, main
/// and cleanup steps, from 1.
pub fn describe_resume(p: &Procedure, completed: usize) -> String {
    let (start_at, restore) = resume_plan(p, completed);
    let total = p.steps().count();
    let retaken = if start_at < completed {
        format!(
            "; steps {} to {} are taken again: the break cut their thermal segment, which is retaken whole",
            start_at + 1,
            completed
        )
    } else {
        String::new()
    };
    let next = p.steps().nth(start_at).map_or("cleanup".to_owned(), |s| {
        format!("step {} of {total} ({})", start_at + 1, s.describe())
    });
    let first = if restore.is_empty() {
        "nothing to restore first".to_owned()
    } else {
        format!(
            "first the bench is restored in {} step(s): {}",
            restore.len(),
            restore
                .iter()
                .map(|(_, s)| s.describe())
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    format!(
        "{completed} of {total} steps were done before the break{retaken}; going on at {next}; {first}"
    )
}

impl Resume {
    /// What the earlier parts leave for a resume at `start_at`: records and
    /// measurements of the steps before it; records that will be taken
    /// again are emptied.
    pub fn trim(
        p: &Procedure,
        start_at: usize,
        records: &mut Records,
        measurements: &mut Vec<Measurement>,
    ) {
        let steps: Vec<&Step> = p.setup.iter().chain(&p.main).collect();
        let kept = steps
            .iter()
            .take(start_at)
            .filter(|s| matches!(s.kind, StepKind::Measure(_)))
            .count();
        measurements.truncate(kept);
        for s in steps.iter().skip(start_at) {
            if let StepKind::Record { label, .. } = &s.kind {
                records.discard(label);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::BenchConfig;
    use crate::config::Source;

    fn acceptance() -> Procedure {
        Procedure::from_source(
            &Source::from_text(
                "acceptance.toml",
                include_str!("../../procedures/acceptance.toml"),
            ),
            &BenchConfig::embedded().procedure_limits(),
        )
        .expect("loads")
    }

    fn index(p: &Procedure, key: &str) -> usize {
        p.setup
            .iter()
            .chain(&p.main)
            .position(|s| s.key == key)
            .expect(key)
    }

    fn kinds(r: &[(usize, Step)]) -> Vec<String> {
        r.iter().map(|(_, s)| s.key.clone()).collect()
    }

    #[test]
    fn a_break_in_the_ramp_back_retakes_its_segment_after_restoring_the_cold_soak() {
        let p = acceptance();
        // Killed in ramp_back (main.9): its segment starts at main.8
        // (chamber +20); the -40 degC of main.5 is restored, held as long
        // as soak_cold held it (ramp_to_cold is the 90 min ramp from +50).
        let (start, restore) = resume_plan(&p, index(&p, "main.9"));
        assert_eq!(start, index(&p, "main.8"));
        assert_eq!(
            kinds(&restore),
            [
                "main.0",
                "setup.0",
                "main.5",
                "main.5.resume_arrive",
                "main.5.resume_dwell"
            ],
            "the switch-on first: a soak reads the unit's case sensor"
        );
        let StepKind::Wait { duration_s } = restore[4].1.kind else {
            panic!("a dwell")
        };
        assert_eq!(duration_s, 10_800.0 - 5_400.0);
        let StepKind::Soak { timeout_s, .. } = restore[3].1.kind else {
            panic!("arrive")
        };
        assert!(timeout_s >= 90.0 * 60.0, "{timeout_s}");
    }

    #[test]
    fn a_break_on_a_chamber_step_rolls_back_nothing() {
        let p = acceptance();
        // A second resume after a failed restore: completed = main.8.
        let (start, _) = resume_plan(&p, index(&p, "main.8"));
        assert_eq!(start, index(&p, "main.8"), "soak_cold is not taken again");
    }

    #[test]
    fn a_break_after_a_soak_resumes_at_the_step_with_that_soak_as_the_restore() {
        let p = acceptance();
        // az090's record: a soak stands between main.8 and it.
        let at = p
            .main
            .iter()
            .position(|s| matches!(&s.kind, StepKind::Record { label, .. } if label == "az090"))
            .expect("az090")
            + p.setup.len();
        let (start, restore) = resume_plan(&p, at);
        assert_eq!(start, at);
        assert!(
            matches!(restore[0].1.kind, StepKind::Power { on: true, .. }),
            "the acceptance's switch-on restored first"
        );
        let last = &restore.last().expect("restore").1;
        assert!(last.key.ends_with("resume_soak"), "{}", last.key);
        let StepKind::Soak {
            case_slope_c_per_min,
            ..
        } = last.kind
        else {
            panic!("soak")
        };
        assert_eq!(case_slope_c_per_min, 0.02, "the procedure's own criteria");
    }

    fn turn_ons() -> Procedure {
        Procedure::from_source(
            &Source::from_text(
                "bias_repeatability.toml",
                include_str!("../../procedures/bias_repeatability.toml"),
            ),
            &BenchConfig::embedded().procedure_limits(),
        )
        .expect("loads")
    }

    #[test]
    fn a_break_in_a_turn_on_retakes_it_from_the_cool_down_before_it() {
        let p = turn_ons();
        // Each cycle: the move to its position, then power on, warm-up
        // record, its measure, bias record, power off, the cool-down.
        let cycle = |c: usize, i: usize| index(&p, &format!("main.0.positions.{c}")) + 1 + i;
        for cut in [1, 3] {
            let (start, restore) = resume_plan(&p, cycle(1, cut));
            assert_eq!(
                start,
                cycle(0, 4),
                "cut at step {cut} of c2: c1's power-off and cool-down first"
            );
            assert_eq!(
                restore.first().map(|(i, _)| *i),
                Some(cycle(0, 0)),
                "c1 switched the unit on last: restored first, before the soak reads its case"
            );
        }
        // In the cool-down, the move after it or the turn-on: from the
        // power-off, the cool-down whole.
        for at in [cycle(1, 5), cycle(2, 0) - 1, cycle(2, 0)] {
            let (start, restore) = resume_plan(&p, at);
            assert_eq!(start, cycle(1, 4), "break at {at}");
            assert!(matches!(
                restore.first().map(|(_, s)| &s.kind),
                Some(StepKind::Power { on: true, .. })
            ));
        }
        // In the setup's cool-down: from its power-off.
        let setup_off = index(&p, "setup.3");
        assert_eq!(resume_plan(&p, setup_off + 1).0, setup_off);
    }

    #[test]
    fn a_break_in_the_first_segment_restarts_it_from_power_on() {
        let p = acceptance();
        let (start, restore) = resume_plan(&p, index(&p, "main.1"));
        assert_eq!(start, index(&p, "setup.1"));
        assert_eq!(kinds(&restore), ["setup.0"]);
    }
}
