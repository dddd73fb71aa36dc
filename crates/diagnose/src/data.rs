//! A run as the diagnosis sees it: every 1 Hz interval with the
//! orientation, record and step it belongs to (the controller reads them
//! from a log).

use nalgebra::Vector3;

use crate::analysis::series::Interval;
use crate::geometry::{Orientation, Site, gravity_ned_g};
use gyrobench_model::procedure::StepKeyBuf;

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
    pub step: StepKeyBuf,
    /// The table's angular velocity in the body frame, deg/h (zero at
    /// rest; a rate record's turning, which a misaligned axis reads a
    /// share of).
    pub table_rate_body_dph: Vector3<f64>,
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

    /// The body's whole angular velocity, Earth and table, in the body
    /// frame, deg/h.
    pub fn inertial_rate_body(&self, site: &Site) -> Vector3<f64> {
        self.earth_rate_body(site) + self.table_rate_body_dph
    }
}

/// Turning between consecutive 1 Hz intervals beyond which the table was
/// moving, deg (ours: far above an encoder's jitter, far below a move).
pub const MOVING_DEG: f64 = 0.05;
