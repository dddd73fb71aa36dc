//! The study's figures straight from a twin: the shipped thermal-cycle
//! procedure run by the sequencer on the embedded bench, with the model
//! comparison (1, 3, 4) the acceptance report does not show, and the 1 Hz
//! series as an interchange CSV.
//!
//! The cycle itself is defined once, in `procedures/thermal_cycle.toml`.

use std::sync::Arc;

use serde::Serialize;

use crate::analysis::model::FitError;
use crate::analysis::series::Interval;
use crate::analysis::study::{ThermalFigures, self_heating_dph, thermal_figures};
use crate::bench::BenchConfig;
use crate::clock::Pacing;
use crate::config::{ConfigError, Source};
use crate::geometry::{Orientation, TableAngles, TableGeometry};
use crate::procedure::Procedure;
use crate::sequencer::{self, BenchState, Event, Observer, Quiet, RunError, Tick};
use crate::twin::TwinConfig;
use nalgebra::Vector3;

/// The study's procedures the diagnosis repeats as a deciding run, as
/// shipped (kept in `gyrobench-twin` so the diagnosis crate has them).
pub use gyrobench_model::procedures::{
    ORIENTATION_NORTH_TOML, ORIENTATION_TOML, SEPARATING_TOML, THERMAL_CYCLE_NORTH_TOML,
    THERMAL_CYCLE_TOML,
};
/// The run that separates an axis misalignment from g- and magnetic
/// sensitivity (the outer axis turning both ways), as shipped.
pub const MISALIGNMENT_TOML: &str = include_str!("../procedures/misalignment.toml");
/// The rate transfer at three temperatures: the run that measures the
/// scale factor's temperature coefficient directly, as shipped.
pub const RATE_TEMPERATURES_TOML: &str =
    include_str!("../procedures/rate_transfer_temperatures.toml");

/// A shipped procedure by its path under the project (`procedures/...`),
/// for the runs the diagnosis names; none when it is not one of these.
pub fn shipped_procedure(path: &str) -> Option<&'static str> {
    Some(match path {
        "procedures/thermal_cycle.toml" => THERMAL_CYCLE_TOML,
        "procedures/orientation.toml" => ORIENTATION_TOML,
        "procedures/thermal_cycle_north.toml" => THERMAL_CYCLE_NORTH_TOML,
        "procedures/orientation_north.toml" => ORIENTATION_NORTH_TOML,
        "procedures/separating.toml" => SEPARATING_TOML,
        "procedures/misalignment.toml" => MISALIGNMENT_TOML,
        "procedures/rate_transfer_temperatures.toml" => RATE_TEMPERATURES_TOML,
        _ => return None,
    })
}

/// One recorded 1 Hz interval with its record label and the orientation.
#[derive(Debug, Clone)]
pub struct Sample {
    /// The interval means.
    pub interval: Interval,
    /// Record it belongs to.
    pub record: String,
    /// Body orientation: at the end of the interval, or at its middle
    /// while the table turns.
    pub orientation: Orientation,
    /// Key of the procedure step it was recorded in.
    pub step: String,
    /// The table's angular velocity in the body frame at the end of the
    /// interval, deg/h (zero at rest).
    pub table_rate_body_dph: Vector3<f64>,
}

/// Keeps the recorded intervals with their orientation (no log file).
#[derive(Debug)]
struct Collect {
    geometry: TableGeometry,
    orientation: Option<Orientation>,
    table_rate_body_dph: Vector3<f64>,
    /// The last tick's end while the table turned: time, angles, rates.
    turning: Option<(f64, TableAngles, TableAngles)>,
    step: String,
    samples: Vec<Sample>,
}

impl Collect {
    fn new(geometry: TableGeometry) -> Self {
        Self {
            geometry,
            orientation: None,
            table_rate_body_dph: Vector3::zeros(),
            turning: None,
            step: String::new(),
            samples: Vec::new(),
        }
    }
}

impl Collect {
    /// A tick: the pose and table rate its interval is read in.
    fn tick(&mut self, tick: &Tick, step: &str) {
        self.orientation = tick.state.as_ref().map(|s: &BenchState| s.orientation);
        if let Some(s) = &tick.state {
            self.table_rate_body_dph = self
                .geometry
                .table_rate_body_dph(s.table.angles, s.table.rates);
            self.turning = (s.table.rates != TableAngles::default()).then_some((
                s.t_s,
                s.table.angles,
                s.table.rates,
            ));
        }
        step.clone_into(&mut self.step);
    }

    /// The first unit's interval in a record, with its pose.
    fn interval(&mut self, iv: &Interval, record: Option<&str>) {
        // While the table turns, the pose at the interval's middle, which
        // its mean reads gravity and the field at (the state is its end's).
        let orientation = match self.turning {
            Some((t_s, angles, rates)) => {
                let lead_s = t_s - iv.time_s;
                Some(self.geometry.orientation(TableAngles {
                    outer_deg: angles.outer_deg - rates.outer_deg * lead_s,
                    inner_deg: angles.inner_deg - rates.inner_deg * lead_s,
                }))
            }
            None => self.orientation,
        };
        if let (Some(record), Some(orientation)) = (record, orientation) {
            self.samples.push(Sample {
                interval: *iv,
                record: record.to_owned(),
                orientation,
                step: self.step.clone(),
                table_rate_body_dph: self.table_rate_body_dph,
            });
        }
    }
}

/// A study takes the first unit's intervals in records, with the pose of
/// the ticks before them; the rest it lets go.
impl Observer for Collect {
    fn observe(&mut self, event: &Event<'_>) -> std::io::Result<()> {
        match *event {
            Event::Tick { tick, step, .. } => self.tick(tick, step),
            Event::Interval {
                slot: 0,
                iv,
                record,
            } => self.interval(iv, record),
            _ => {}
        }
        Ok(())
    }
}

/// The interchange CSV (`docs/diagnosis` format): one row per recorded 1 Hz
/// interval, Earth rate included in `rate_dph`, `step` = the record label.
pub fn interchange_csv(samples: &[Sample]) -> String {
    let mut out = String::from(
        "time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n",
    );
    for s in samples {
        let (iv, o) = (&s.interval, &s.orientation);
        out.push_str(&format!(
            "{:.3},{:.6},{:.4},{:.4},{:.4},{:.3},{:.4},{:.4},{:.4},{}\n",
            iv.time_s,
            iv.rate_dph,
            iv.t1_c,
            iv.t2_c,
            iv.tcase_c,
            iv.chamber_c,
            o.azimuth_deg,
            o.elevation_deg,
            o.roll_deg,
            s.record
        ));
    }
    out
}

/// What `gyrobench twin study` reports.
#[derive(Debug, Clone, Serialize)]
pub struct StudyReport {
    /// Seed of the run.
    pub seed: u64,
    /// Hours of device time simulated.
    pub device_hours: f64,
    /// Frames produced.
    pub frames: u64,
    /// Self-heating transient over the first half hour at +20 degC, deg/h.
    pub self_heating_dph: Option<f64>,
    /// Raw and compensated thermal-cycle figures.
    pub thermal: ThermalFigures,
}

/// Why the study could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The shipped procedure does not fit the embedded bench.
    #[error(transparent)]
    Procedure(#[from] ConfigError),
    /// The run stopped (the procedure's name, why).
    #[error("{0} stopped in step {step}: {message}", step = .1.step, message = .1.message)]
    Run(String, RunError),
    /// The compensation fit failed.
    #[error(transparent)]
    Fit(#[from] FitError),
}

/// The embedded bench where the twin `cfg` stands: its site, its table.
fn bench_of(cfg: &TwinConfig) -> BenchConfig {
    let mut b = BenchConfig::embedded();
    b.site = cfg.site;
    b.table.geometry = cfg.table.geometry;
    b
}

/// Run a procedure (`text`, labelled `name`) on a twin built from `cfg`,
/// keeping the recorded 1 Hz samples with their orientation (no log).
pub fn simulate(
    text: &str,
    name: &str,
    cfg: &TwinConfig,
    seed: u64,
) -> Result<(crate::sequencer::RunResult, Vec<Sample>), StudyError> {
    let bench_cfg = bench_of(cfg);
    let procedure = Procedure::from_source(
        &Source::from_text(name, text),
        &bench_cfg.procedure_limits(),
    )?;
    run_on_twin(&procedure, &bench_cfg, name, cfg, seed)
}

/// [`simulate`] for the recorded samples alone: the procedure's measure
/// steps (which take no device time) are left out, so no figure is
/// computed that nobody reads (the self-checks run thousands of runs).
pub fn simulate_samples(
    text: &str,
    name: &str,
    cfg: &TwinConfig,
    seed: u64,
) -> Result<Vec<Sample>, StudyError> {
    let bench_cfg = bench_of(cfg);
    let mut procedure = Procedure::from_source(
        &Source::from_text(name, text),
        &bench_cfg.procedure_limits(),
    )?;
    for steps in [
        &mut procedure.setup,
        &mut procedure.main,
        &mut procedure.cleanup,
    ] {
        steps.retain(|s| !matches!(s.kind, crate::procedure::StepKind::Measure(_)));
    }
    Ok(run_on_twin(&procedure, &bench_cfg, name, cfg, seed)?.1)
}

fn run_on_twin(
    procedure: &Procedure,
    bench_cfg: &BenchConfig,
    name: &str,
    cfg: &TwinConfig,
    seed: u64,
) -> Result<(crate::sequencer::RunResult, Vec<Sample>), StudyError> {
    let mut bench = crate::session::embedded_bench(
        cfg,
        seed,
        Pacing::Max,
        &[],
        bench_cfg.limits.clone(),
        bench_cfg.devices.supply.as_ref(),
    );
    let opts = crate::session::options(procedure, bench_cfg, None, Arc::default(), None);
    let mut sink = Collect::new(bench_cfg.table.geometry);
    // No timers or I/O are awaited on the embedded bench: a plain executor will do.
    let rt = tokio::runtime::Builder::new_current_thread()
        .build()
        .map_err(|e| {
            StudyError::Run(
                name.to_owned(),
                RunError {
                    device: None,
                    step: "start".into(),
                    message: e.to_string(),
                },
            )
        })?;
    let result = rt.block_on(sequencer::run(
        procedure, &mut bench, &mut sink, &mut Quiet, &opts,
    ));
    if let Some(e) = result.error.clone() {
        return Err(StudyError::Run(name.to_owned(), e));
    }
    Ok((result, sink.samples))
}

/// Run the shipped thermal cycle on a twin built from `cfg` and compute the
/// figures; also returns the recorded 1 Hz samples.
pub fn run_study(cfg: &TwinConfig, seed: u64) -> Result<(StudyReport, Vec<Sample>), StudyError> {
    let (result, samples) = simulate(
        THERMAL_CYCLE_TOML,
        "procedures/thermal_cycle.toml",
        cfg,
        seed,
    )?;
    let sink = Collect {
        samples,
        ..Collect::new(cfg.table.geometry)
    };
    let series: Vec<Interval> = sink.samples.iter().map(|s| s.interval).collect();
    let report = StudyReport {
        seed,
        device_hours: result.device_time_s / 3600.0,
        frames: result.frames,
        self_heating_dph: self_heating_dph(&series),
        thermal: thermal_figures(&series)?,
    };
    Ok((report, sink.samples))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turning_records_bias_carries_no_trace_of_the_turning_earth_rate() {
        // The misalignment run near the equator on a table turned north:
        // the outer axis (east) turns the sensitive axis through north,
        // up, south and down at 5 deg/s, and the Earth rate on it with
        // it. Each 1 Hz mean's reference must be the interval's mean: the
        // value at its end is half a second of the turn ahead, a 0.65
        // deg/h sinusoid in the bias at the revolution's period.
        let mut cfg = TwinConfig::default_rl16();
        cfg.table.geometry = crate::geometry::TableGeometry::north();
        cfg.site.latitude_deg = 1.35;
        let samples = simulate_samples(MISALIGNMENT_TOML, "misalignment", &cfg, 7).unwrap();
        // Per record, the bias against the axis's north and down
        // components (the lag's sign turns with the direction: records
        // are fitted one by one).
        let mut records: Vec<&str> = samples.iter().map(|s| s.record.as_str()).collect();
        records.dedup();
        assert_eq!(records.len(), 8, "{records:?}");
        for r in records {
            let of: Vec<&Sample> = samples.iter().filter(|s| s.record == r).collect();
            let n = of.len() as f64;
            let x = |s: &Sample| {
                let a = s.orientation.sensitive_axis_ned();
                nalgebra::Vector2::new(a.x, a.z)
            };
            let xm = of.iter().map(|s| x(s)).sum::<nalgebra::Vector2<f64>>() / n;
            let ym = of.iter().map(|s| s.interval.bias_dph()).sum::<f64>() / n;
            let (mut g, mut h) = (nalgebra::Matrix2::zeros(), nalgebra::Vector2::zeros());
            for s in &of {
                let (dx, dy) = (x(s) - xm, s.interval.bias_dph() - ym);
                g += dx * dx.transpose();
                h += dx * dy;
            }
            let c = g.try_inverse().unwrap() * h;
            // The 1 Hz noise leaves about 0.04 deg/h on each coefficient
            // of a record.
            assert!(
                c.norm() < 0.2,
                "{r}: the bias follows the turning axis: {c}"
            );
        }
    }
}
