//! Gyro frames reduced to fixed-interval means (1 Hz by default): the
//! working series of every figure and fit.

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

/// One frame's worth of input to a [`Decimator`].
#[derive(Debug, Clone, Copy)]
pub struct FrameInput {
    /// End of the frame, s since power-on.
    pub time_s: f64,
    /// Angle measured over the frame, arcsec.
    pub angle_arcsec: f64,
    /// Frame length, s.
    pub dt_s: f64,
    /// Predicted kinematic rate during the frame, deg/h.
    pub reference_dph: f64,
    /// Sensor readings, degC.
    pub t1_c: f64,
    /// Block sensor 2, degC.
    pub t2_c: f64,
    /// Case sensor, degC.
    pub tcase_c: f64,
    /// Chamber air, degC.
    pub chamber_c: f64,
}

/// Streams frames into fixed-length interval means; memory is constant.
#[derive(Debug, Clone)]
pub struct Decimator {
    interval_s: f64,
    start_s: Option<f64>,
    acc: Acc,
}

#[derive(Debug, Clone, Default)]
struct Acc {
    angle: f64,
    dt: f64,
    reference: f64,
    t1: f64,
    t2: f64,
    tcase: f64,
    chamber: f64,
    n: u32,
}

impl Decimator {
    /// Intervals of `interval_s` seconds.
    pub fn new(interval_s: f64) -> Self {
        Self {
            interval_s,
            start_s: None,
            acc: Acc::default(),
        }
    }

    /// Add one frame; returns a finished interval when this frame closes one.
    #[inline]
    pub fn push(&mut self, f: &FrameInput) -> Option<Interval> {
        let start = *self.start_s.get_or_insert(f.time_s - f.dt_s);
        let a = &mut self.acc;
        a.angle += f.angle_arcsec;
        a.dt += f.dt_s;
        a.reference += f.reference_dph * f.dt_s;
        a.t1 += f.t1_c;
        a.t2 += f.t2_c;
        a.tcase += f.tcase_c;
        a.chamber += f.chamber_c;
        a.n += 1;
        if f.time_s - start >= self.interval_s - 1e-9 {
            let out = self.finish_interval(start);
            self.start_s = Some(f.time_s);
            out
        } else {
            None
        }
    }

    /// Close a partial last interval, if any frames are pending.
    pub fn flush(&mut self) -> Option<Interval> {
        let start = self.start_s?;
        self.finish_interval(start)
    }

    fn finish_interval(&mut self, start: f64) -> Option<Interval> {
        let a = std::mem::take(&mut self.acc);
        if a.n == 0 || a.dt <= 0.0 {
            return None;
        }
        let n = f64::from(a.n);
        Some(Interval {
            time_s: start + 0.5 * a.dt,
            rate_dph: a.angle / a.dt,
            reference_dph: a.reference / a.dt,
            t1_c: a.t1 / n,
            t2_c: a.t2 / n,
            tcase_c: a.tcase / n,
            chamber_c: a.chamber / n,
            frames: a.n,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimator_averages_rate_and_temperatures() {
        let mut d = Decimator::new(1.0);
        let mut out = Vec::new();
        for i in 1..=800 {
            let f = FrameInput {
                time_s: f64::from(i) / 400.0,
                angle_arcsec: 15.0 / 400.0,
                dt_s: 1.0 / 400.0,
                reference_dph: 10.0,
                t1_c: if i % 2 == 0 { 20.0 } else { 21.0 },
                t2_c: 19.0,
                tcase_c: 18.0,
                chamber_c: 17.0,
            };
            out.extend(d.push(&f));
        }
        assert_eq!(out.len(), 2);
        for iv in &out {
            assert_eq!(iv.frames, 400);
            assert!((iv.rate_dph - 15.0).abs() < 1e-9);
            assert!((iv.bias_dph() - 5.0).abs() < 1e-9);
            assert!((iv.t1_c - 20.5).abs() < 1e-12);
        }
        assert!((out[1].time_s - 1.5).abs() < 1e-9);
        assert!(d.flush().is_none());
    }
}
