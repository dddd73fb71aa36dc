//! A run as the diagnosis sees it: every 1 Hz interval with the
//! orientation, record and step it belongs to, read from the log.

use std::path::Path;

use nalgebra::Vector3;

use crate::analysis::series::Interval;
use crate::geometry::{Orientation, Site, gravity_ned_g};
use crate::runlog::meta::RunMeta;
use crate::runlog::replay::ReplayError;
use crate::runlog::schema::{RUN_META, Rate1Hz, TableState, topics};
use crate::runlog::{self, Item};

/// One 1 Hz interval with its context.
#[derive(Debug, Clone)]
pub struct Sample {
    /// The means.
    pub iv: Interval,
    /// Body orientation.
    pub orientation: Orientation,
    /// Record label.
    pub record: String,
    /// Procedure step key.
    pub step: String,
}

/// A run.
#[derive(Debug, Clone)]
pub struct RunData {
    /// File name.
    pub name: String,
    /// Where it ran.
    pub site: Site,
    /// The recorded (static) intervals, in time order.
    pub samples: Vec<Sample>,
}

impl Sample {
    /// Gravity in the body frame, g.
    pub fn gravity_body(&self) -> Vector3<f64> {
        self.orientation.rotation().inverse() * gravity_ned_g()
    }

    /// The Earth's magnetic field in the body frame, uT.
    pub fn magnetic_body(&self, site: &Site) -> Vector3<f64> {
        self.orientation.rotation().inverse() * site.magnetic_ned_ut()
    }

    /// The Earth rate in the body frame, deg/h.
    pub fn earth_rate_body(&self, site: &Site) -> Vector3<f64> {
        self.orientation.rotation().inverse() * site.earth_rate_ned_dph()
    }
}

/// Load a run's log (live, simulated or imported).
pub fn load(path: &Path) -> Result<RunData, ReplayError> {
    let log_err = |message: String| ReplayError::Log {
        path: path.display().to_string(),
        message,
    };
    let mut site: Option<Site> = None;
    let mut table: Option<TableState> = None;
    let mut samples = Vec::new();
    runlog::read(path, |item| {
        match item {
            Item::Meta { name, entries } if name == RUN_META => {
                let meta = RunMeta::from_entries(entries).map_err(|e| e.to_string())?;
                site = Some(
                    serde_json::from_str(&meta.site_json)
                        .map_err(|e| format!("the run metadata's site: {e}"))?,
                );
            }
            Item::Message { topic, data, .. } if topic == topics::TABLE => {
                table = Some(
                    serde_json::from_slice::<TableState>(data)
                        .map_err(|e| format!("{topic}: {e}"))?,
                );
            }
            Item::Message { topic, data, .. } if topic == topics::RATE_1HZ => {
                let r: Rate1Hz =
                    serde_json::from_slice(data).map_err(|e| format!("{topic}: {e}"))?;
                let Some(t) = &table else {
                    return Err("a 1 Hz interval before any table state".into());
                };
                let Some(record) = r.record.clone() else {
                    return Ok(());
                };
                samples.push(Sample {
                    iv: r.interval(),
                    orientation: Orientation::new(t.azimuth_deg, t.elevation_deg, t.roll_deg),
                    record,
                    step: t.step.clone(),
                });
            }
            _ => {}
        }
        Ok(())
    })?;
    let site = site.ok_or_else(|| log_err("no site in the run metadata".into()))?;
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
