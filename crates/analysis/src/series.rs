//! The 1 Hz interval means that every figure and fit works on (frames are
//! reduced to them by the sequencer's record store, one per tick).

/// Mean values over one interval.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Interval {
    /// Centre of the interval, s since power-on.
    pub time_s: f64,
    /// Mean measured rate over the interval (Earth rate included), deg/h.
    pub rate_dph: f64,
    /// Mean Earth (+ table) rate the orientation predicts, deg/h.
    pub reference_dph: f64,
    /// Block sensor 1, degC.
    pub t1_c: f64,
    /// Block sensor 2, degC.
    pub t2_c: f64,
    /// Case sensor, degC.
    pub tcase_c: f64,
    /// Chamber air, degC.
    pub chamber_c: f64,
    /// Frames that went into this interval.
    pub frames: u32,
}

impl Interval {
    /// Measured rate minus the kinematic reference, deg/h.
    pub fn bias_dph(&self) -> f64 {
        self.rate_dph - self.reference_dph
    }

    /// Block gradient T1 - T2, degC.
    pub fn gradient_c(&self) -> f64 {
        self.t1_c - self.t2_c
    }
}
