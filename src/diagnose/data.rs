//! A run as the diagnosis sees it ([`RunData`], the `gyrobench-diagnose`
//! crate's), read from a log.

use std::path::Path;

use nalgebra::Vector3;

use crate::geometry::{Orientation, Site, TableAngles, TableGeometry};
use crate::procedure::StepKeyBuf;
use crate::runlog::meta::RunMeta;
use crate::runlog::replay::{LoggedError, ReplayError, logged_bench};
use crate::runlog::schema::{RUN_META, Rate1Hz, TableState, topics};
use crate::runlog::{self, Item};

pub use gyrobench_diagnose::data::{MOVING_DEG, RunData, Sample};
use gyrobench_diagnose::lot::LotUnit;

/// The samples taken while the table was still: a sample whose orientation
/// differs from a neighbour's by more than [`MOVING_DEG`] was taken during
/// a move (its 1 Hz means mix positions, and the Earth-rate reference of
/// one orientation does not hold), unless its step turns the table on
/// purpose (a rate record). A live run records nothing while moving; an
/// imported one may have its moves in a record (the interchange CSV labels
/// them with the step that made them).
fn without_moves(samples: Vec<Sample>) -> Vec<Sample> {
    let turn = |a: &Orientation, b: &Orientation| {
        [
            a.azimuth_deg - b.azimuth_deg,
            a.elevation_deg - b.elevation_deg,
            a.roll_deg - b.roll_deg,
        ]
        .iter()
        .map(|d| (d + 180.0).rem_euclid(360.0) - 180.0)
        .fold(0.0, |m: f64, d| m.max(d.abs()))
    };
    // Neighbours a second apart (a live run's records are apart by the
    // move between them, which is not in them).
    let apart = |a: &Sample, b: &Sample| {
        turn(&a.orientation, &b.orientation) > MOVING_DEG
            && (a.iv.time_s - b.iv.time_s).abs() <= 1.5
    };
    let moving: Vec<bool> = (0..samples.len())
        .map(|i| {
            let prev = i
                .checked_sub(1)
                .is_some_and(|j| apart(&samples[i], &samples[j]));
            let next = samples.get(i + 1).is_some_and(|n| apart(&samples[i], n));
            (prev || next) && !samples[i].step.as_key().is_rate_record()
        })
        .collect();
    samples
        .into_iter()
        .zip(moving)
        .filter_map(|(s, m)| (!m).then_some(s))
        .collect()
}

/// Load a run's log (live, simulated or imported).
pub fn load(path: &Path) -> Result<RunData, ReplayError> {
    load_unit(path, None)
}

/// Load unit `unit` (a serial) of a batch's log as that unit's run
/// (`runlog::view`; none: the log as written).
pub fn load_unit(path: &Path, unit: Option<&str>) -> Result<RunData, ReplayError> {
    let log_err = |message: String| ReplayError::Log {
        path: path.display().to_string(),
        message,
    };
    let mut reading = Reading::default();
    let read = runlog::view::read_unit(path, unit, runlog::refusing(|item| reading.take(item)))?;
    // A read stopped on purpose (`--unit` naming a unit the log lacks)
    // says why.
    if let (Some(why), true, Some(_)) = (&read.stopped, reading.site.is_none(), unit) {
        return Err(log_err(why.clone()));
    }
    reading.into_run(path)
}

/// Load units `serials` of a batch's log, each as its own run, from one
/// pass over the log (`runlog::view::read_units`).
pub fn load_units(path: &Path, serials: &[String]) -> Result<Vec<RunData>, ReplayError> {
    let mut readings: Vec<Reading> = serials.iter().map(|_| Reading::default()).collect();
    let read = runlog::view::read_units(path, serials, |k, item| match readings[k].take(item) {
        Ok(()) => std::ops::ControlFlow::Continue(()),
        Err(why) => std::ops::ControlFlow::Break(runlog::Stop::Refused(why)),
    })?;
    if let (Some(why), true) = (&read.stopped, readings.iter().any(|r| r.site.is_none())) {
        return Err(ReplayError::Log {
            path: path.display().to_string(),
            message: why.clone(),
        });
    }
    readings.into_iter().map(|r| r.into_run(path)).collect()
}

impl Reading {
    /// The run read: its samples on the logged bench, those taken while
    /// the table moved left out.
    fn into_run(self, path: &Path) -> Result<RunData, ReplayError> {
        let log_err = |message: String| ReplayError::Log {
            path: path.display().to_string(),
            message,
        };
        let Self {
            site,
            geometry,
            samples,
            ..
        } = self;
        let site = site.ok_or_else(|| log_err("no site in the run metadata".into()))?;
        let samples = samples
            .into_iter()
            .map(|s| s.on_the_bench(geometry.as_ref()).map_err(log_err))
            .collect::<Result<Vec<_>, _>>()?;
        let samples = without_moves(samples);
        if samples.len() < 60 {
            return Err(log_err(
                "fewer than 60 recorded seconds: nothing to diagnose".into(),
            ));
        }
        Ok(RunData {
            name: path.display().to_string(),
            site,
            samples,
        })
    }
}

/// The units of a set of logs, each with its runs (`diagnose --lot`): a
/// batch's log gives each of its units a run, and the logs of one unit
/// are that unit's runs (grouped by serial, in the order first met; a
/// run of a batch's unit named `LOG (SERIAL)`). A unit whose logs give it
/// two types is refused here, naming both logs.
pub fn load_lot(paths: &[std::path::PathBuf]) -> Result<Vec<LotUnit>, ReplayError> {
    // The logs read two at a time (each read is one thread's work), then
    // grouped in the order given.
    let read = gyrobench_analysis::par::two_at_a_time(paths, |_, path| log_units(path));
    let mut units: Vec<LotUnit> = Vec::new();
    for (path, read) in paths.iter().zip(read) {
        let (held, runs) = read?;
        let log_err = |message: String| ReplayError::Log {
            path: path.display().to_string(),
            message,
        };
        let several = held.len() > 1;
        for ((slot, serial, dut_type), mut run) in held.into_iter().zip(runs) {
            if several {
                run.name = format!("{} ({serial})", path.display());
            }
            match units.iter_mut().find(|u| u.serial == serial) {
                Some(u) if u.dut_type != dut_type => {
                    return Err(log_err(format!(
                        "unit {serial} is of type {dut_type} here and of type {} in {}: one unit has one type; check the serials",
                        u.dut_type,
                        u.runs.first().map_or("", |r| r.name.as_str())
                    )));
                }
                Some(u) => u.runs.push(run),
                None => units.push(LotUnit {
                    serial,
                    dut_type,
                    slot,
                    runs: vec![run],
                }),
            }
        }
    }
    Ok(units)
}

/// A log's units (slot, serial, type; one, unslotted, for a log of one
/// unit) and each one's run.
type LogUnits = (Vec<(String, String, String)>, Vec<RunData>);

/// The units a log holds and their runs (`load_lot`).
fn log_units(path: &Path) -> Result<LogUnits, ReplayError> {
    let meta = crate::runlog::meta::read_run_meta(path)?;
    if meta.units.is_empty() {
        let held = vec![(String::new(), meta.dut_serial, meta.dut_type)];
        return Ok((held, vec![load_unit(path, None)?]));
    }
    let held: Vec<(String, String, String)> = meta
        .units
        .iter()
        .map(|u| (u.slot.clone(), u.serial.clone(), u.dut_type.clone()))
        .collect();
    let serials: Vec<String> = held.iter().map(|h| h.1.clone()).collect();
    Ok((held, load_units(path, &serials)?))
}

/// A recorded sample as read, before the logged bench is known.
struct ReadSample {
    sample: Sample,
    /// The table's angles it was taken at (when logged).
    angles: Option<TableAngles>,
    /// The table's axis rates it was taken at.
    rates: TableAngles,
    /// How far the table state's time leads the interval's middle, s.
    lead_s: f64,
}

impl ReadSample {
    /// The sample with the table's turning as a body rate, on the logged
    /// bench's table `geometry` (needed only when the table turned), or
    /// why it cannot be had.
    fn on_the_bench(
        self,
        geometry: Option<&Result<TableGeometry, LoggedError>>,
    ) -> Result<Sample, String> {
        let Self {
            sample: mut s,
            angles,
            rates,
            lead_s,
        } = self;
        if rates.outer_deg != 0.0 || rates.inner_deg != 0.0 {
            let g = match geometry {
                Some(Ok(g)) => g,
                Some(Err(e)) => {
                    return Err(format!("record {:?} turns the table: {e}", s.record));
                }
                None => {
                    return Err(format!(
                        "record {:?} turns the table, and the run metadata has no bench",
                        s.record
                    ));
                }
            };
            let Some(angles) = angles else {
                return Err(format!(
                    "record {:?} turns the table, and the log has no table angles to say how",
                    s.record
                ));
            };
            s.table_rate_body_dph = g.table_rate_body_dph(angles, rates);
            // The pose at the interval's middle, which its mean reads
            // gravity and the field at (the state is its end's).
            s.orientation = g.orientation(TableAngles {
                outer_deg: angles.outer_deg - rates.outer_deg * lead_s,
                inner_deg: angles.inner_deg - rates.inner_deg * lead_s,
            });
        }
        Ok(s)
    }
}

/// What a log's items have told so far.
#[derive(Default)]
struct Reading {
    site: Option<Site>,
    /// The logged bench's table geometry, needed only for a turning record.
    geometry: Option<Result<TableGeometry, LoggedError>>,
    table: Option<TableState>,
    /// Each recorded sample with the table's angles and rates it was taken
    /// at (turned into a body rate once the logged bench is known).
    samples: Vec<ReadSample>,
}

impl Reading {
    /// Take the log's next item: the run metadata, a table state, or a
    /// 1 Hz interval (kept when recorded).
    fn take(&mut self, item: Item<'_>) -> Result<(), String> {
        match item {
            Item::Meta { name, entries } if name == RUN_META => {
                let meta = RunMeta::from_entries(entries).map_err(|e| e.to_string())?;
                self.site = Some(
                    serde_json::from_str(&meta.site_json)
                        .map_err(|e| format!("the run metadata's site: {e}"))?,
                );
                // A batch's unit sits on its slot's mount.
                let mount = meta.unit().and_then(|u| u.mount);
                self.geometry = Some(logged_bench(&meta).map(|b| b.geometry_with(mount)));
            }
            Item::Message { topic, data, .. } if topic == topics::TABLE => {
                self.table = Some(
                    serde_json::from_slice::<TableState>(data)
                        .map_err(|e| format!("{topic}: {e}"))?,
                );
            }
            Item::Message { topic, data, .. } if topic == topics::RATE_1HZ => {
                self.interval(topic, data)?;
            }
            _ => {}
        }
        Ok(())
    }

    /// Take a 1 Hz interval (on `topic`): a recorded one is kept with the
    /// table state before it.
    fn interval(&mut self, topic: &str, data: &[u8]) -> Result<(), String> {
        let r: Rate1Hz = serde_json::from_slice(data).map_err(|e| format!("{topic}: {e}"))?;
        let Some(t) = &self.table else {
            return Err("a 1 Hz interval before any table state".into());
        };
        let Some(record) = r.record.clone() else {
            return Ok(());
        };
        self.samples.push(ReadSample {
            sample: Sample {
                iv: r.interval(),
                orientation: Orientation::new(t.azimuth_deg, t.elevation_deg, t.roll_deg),
                record,
                step: StepKeyBuf::parse(&t.step),
                table_rate_body_dph: Vector3::zeros(),
            },
            angles: t
                .outer_deg
                .zip(t.inner_deg)
                .map(|(outer_deg, inner_deg)| TableAngles {
                    outer_deg,
                    inner_deg,
                }),
            rates: TableAngles {
                outer_deg: t.outer_rate_dps,
                inner_deg: t.inner_rate_dps,
            },
            lead_s: t.t_s - r.t_s,
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::series::Interval;

    fn sample(t: f64, roll: f64, record: &str, step: &str) -> Sample {
        Sample {
            iv: Interval {
                time_s: t,
                ..Interval::default()
            },
            orientation: Orientation::new(0.0, 90.0, roll),
            record: record.into(),
            step: step.into(),
            table_rate_body_dph: Vector3::zeros(),
        }
    }

    #[test]
    fn a_move_inside_a_record_is_left_out_and_records_apart_are_kept() {
        let mut s = Vec::new();
        // Still at -90, a move to 0 in 1 Hz rows (an imported run's), still
        // at 0 (encoder jitter of 0.001 deg), then a record 30 s later at
        // 180 (a live run's: the move is not in the log), and a turning
        // rate record.
        for k in 0..10 {
            s.push(sample(f64::from(k), -90.0, "a", "main.1"));
        }
        for (k, roll) in [-85.0, -50.0, -10.0].into_iter().enumerate() {
            s.push(sample(10.0 + k as f64, roll, "main.2", "main.2"));
        }
        for k in 0..10 {
            let jitter = 0.001 * f64::from(k % 2);
            s.push(sample(13.0 + f64::from(k), jitter, "b", "main.3"));
        }
        for k in 0..10 {
            s.push(sample(53.0 + f64::from(k), 180.0, "c", "main.4"));
        }
        for k in 0..10 {
            let t = 70.0 + f64::from(k);
            s.push(sample(t, 10.0 * t, "d", "main.5.record"));
        }
        let kept = without_moves(s);
        let count = |r: &str| kept.iter().filter(|x| x.record == r).count();
        // The last row still at -90 sees the move begin; the first at 0
        // sees it end: both mix positions in their 1 Hz means.
        assert_eq!(count("a"), 9);
        assert_eq!(count("main.2"), 0);
        assert_eq!(count("b"), 9);
        assert_eq!(count("c"), 10);
        assert_eq!(count("d"), 10);
    }
}
