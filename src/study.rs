//! The study's experiments run directly on the twin: chamber and table
//! profiles, frames reduced to 1 Hz, and the study's figures.
//!
//! This is the main job until the sequencer drives the same experiments from
//! TOML procedures; the figure definitions live in `analysis::study`.

use serde::Serialize;

use crate::analysis::model::FitError;
use crate::analysis::series::{Decimator, FrameInput, Interval};
use crate::analysis::study::{ThermalFigures, self_heating_dph, thermal_figures};
use crate::geometry::{Orientation, TableAngles};
use crate::twin::{ChamberLimit, Twin, TwinConfig};

/// One segment of a profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Label of the segment (the procedure step it stands for).
    pub label: String,
    /// New chamber set point and ramp (degC, degC/min), if any.
    pub chamber: Option<(f64, f64)>,
    /// New table position, if any.
    pub table: Option<TableAngles>,
    /// How long to run after issuing the commands, s.
    pub duration_s: f64,
}

fn seg(
    label: &str,
    chamber: Option<(f64, f64)>,
    table: Option<TableAngles>,
    minutes: f64,
) -> Segment {
    Segment {
        label: label.to_owned(),
        chamber,
        table,
        duration_s: minutes * 60.0,
    }
}

/// Axis up on the study table (outer 90 deg).
pub const AXIS_UP: TableAngles = TableAngles {
    outer_deg: 90.0,
    inner_deg: 0.0,
};

/// The study's -40..+50 degC cycle at 1 degC/min, axis up: half an hour of
/// self-heating at a stable +20 degC after power-on, up to +50, down to -40,
/// back to +20, with soaks (6.5 h in all).
pub fn thermal_cycle() -> Vec<Segment> {
    vec![
        seg("self_heating", Some((20.0, 1.0)), Some(AXIS_UP), 30.0),
        seg("ramp_to_hot", Some((50.0, 1.0)), None, 30.0),
        seg("soak_hot", None, None, 60.0),
        seg("ramp_to_cold", Some((-40.0, 1.0)), None, 90.0),
        seg("soak_cold", None, None, 90.0),
        seg("ramp_back", Some((20.0, 1.0)), None, 60.0),
        seg("soak_end", None, None, 30.0),
    ]
}

/// A profile's 1 Hz series and the segment of each interval.
#[derive(Debug, Clone)]
pub struct ProfileRun {
    /// 1 Hz means, Earth (+ table) rate as reference.
    pub intervals: Vec<Interval>,
    /// Index into the profile of the segment each interval ended in.
    pub segment: Vec<usize>,
    /// Body orientation at the end of each interval.
    pub orientation: Vec<Orientation>,
    /// Frames the gyro sent.
    pub frames: u64,
}

/// Run `profile` on `twin` from power-on, reducing frames to 1 Hz.
pub fn run_profile(twin: &mut Twin, profile: &[Segment]) -> Result<ProfileRun, ChamberLimit> {
    let site = twin.config().site;
    let geometry = twin.config().table.geometry;
    let lsb = twin.config().gyro.lsb_arcsec;
    let dt = twin.frame_dt_s();
    let mut dec = Decimator::new(1.0);
    let mut out = ProfileRun {
        intervals: Vec::new(),
        segment: Vec::new(),
        orientation: Vec::new(),
        frames: 0,
    };
    let mut end_s = twin.time_s();
    let mut reference = geometry.kinematic_rate_dph(&site, twin.table_angles(), twin.table_rates());
    for (k, s) in profile.iter().enumerate() {
        if let Some((set_c, ramp)) = s.chamber {
            twin.set_chamber(set_c, ramp)?;
        }
        if let Some(angles) = s.table {
            twin.move_table(angles);
        }
        end_s += s.duration_s;
        twin.run_until(end_s, |tw, g| {
            if tw.table_moving() {
                reference = geometry.kinematic_rate_dph(&site, tw.table_angles(), tw.table_rates());
            }
            out.frames += 1;
            let air = tw.chamber_state().0;
            let frame = FrameInput {
                time_s: g.index as f64 * dt,
                angle_arcsec: f64::from(g.delta_counts) * lsb,
                dt_s: dt,
                reference_dph: reference,
                t1_c: g.t1_c,
                t2_c: g.t2_c,
                tcase_c: g.tcase_c,
                chamber_c: air,
            };
            if let Some(iv) = dec.push(&frame) {
                out.intervals.push(iv);
                out.segment.push(k);
                out.orientation.push(tw.orientation());
            }
        });
    }
    Ok(out)
}

/// The interchange CSV of a profile run (`docs/interchange.md`): one row per
/// 1 Hz interval, Earth rate included in `rate_dph`.
pub fn interchange_csv(run: &ProfileRun, profile: &[Segment]) -> String {
    let mut out = String::from(
        "time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n",
    );
    for ((iv, &k), o) in run.intervals.iter().zip(&run.segment).zip(&run.orientation) {
        let label = profile.get(k).map_or("", |s| s.label.as_str());
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
            label
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
    /// The profile asked the chamber for what it cannot do.
    #[error(transparent)]
    Chamber(#[from] ChamberLimit),
    /// The compensation fit failed.
    #[error(transparent)]
    Fit(#[from] FitError),
}

/// Run the thermal cycle on a twin built from `cfg` and compute the figures.
pub fn run_study(cfg: &TwinConfig, seed: u64) -> Result<(StudyReport, ProfileRun), StudyError> {
    let mut twin = Twin::new(cfg.clone(), seed);
    let run = run_profile(&mut twin, &thermal_cycle())?;
    let report = StudyReport {
        seed,
        device_hours: twin.time_s() / 3600.0,
        frames: run.frames,
        self_heating_dph: self_heating_dph(&run.intervals),
        thermal: thermal_figures(&run.intervals)?,
    };
    Ok((report, run))
}
