//! A rate record in the angle domain (IEEE Std 647's scale factor by the
//! rate-table method: output counts per input angle over whole
//! revolutions). The gyro's counts are taken over a whole number of the
//! table's revolutions, latched on the table's own angle; the input is
//! that angle plus what the Earth turned the sensitive axis by over the
//! same span. Neither the unit's frame clock (which times its frames) nor
//! the bench's (which stamps the ticks) enters the ratio: see
//! `docs/figures.md`, "Rate records in the angle domain".
//!
//! Ticks come one at a time and the record is kept in constant memory:
//! per axis, its angle travelled so far and the span up to the last whole
//! revolution crossed.

/// Revolutions within this of a whole number count as that number, turns
/// (a thousandth: 0.36 deg). A record of `n` revolutions on a bench whose
/// host clock and table clock differ by tens of ppm ends a few hundredths
/// of a degree short of `n` turns; its last crossing is then found a
/// little past its last tick, along that tick's turn.
pub const WHOLE_TURN_TOLERANCE: f64 = 1e-3;

/// The table as a tick's end found it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TablePose {
    /// Device time, s (the bench's clock).
    pub t_s: f64,
    /// Axis angles read (outer, inner), deg; an axis may read its angle
    /// within one turn.
    pub angles_deg: [f64; 2],
    /// Axis rates read (outer, inner), deg/s.
    pub rates_dps: [f64; 2],
}

/// The running sums of a record from its start, up to some point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Sums {
    /// Delta-angle counts (fractional at an interpolated crossing).
    counts: f64,
    /// Device time since the start, s.
    span_s: f64,
    /// The reference (Earth + table rate on the axis) integrated over
    /// device time, deg/h s.
    reference: f64,
}

/// One table axis over the record.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Axis {
    /// Angle travelled, from the angles read, unwrapped, signed, deg.
    travelled_deg: f64,
    /// The axis's rate reading integrated over device time, deg.
    by_rate_deg: f64,
    /// At the last whole revolution crossed: its number, the sums and the
    /// rate-integrated angle there.
    whole: Option<(u32, Sums, f64)>,
}

/// A record's ticks reduced to the span over its whole revolutions.
#[derive(Debug, Clone, PartialEq)]
pub struct Revolutions {
    last: TablePose,
    sums: Sums,
    axes: [Axis; 2],
}

/// A record over its whole revolutions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AngleSpan {
    /// The axis that turned: 0 outer, 1 inner.
    pub axis: usize,
    /// Whole revolutions of that axis, and the direction (+1 or -1) the
    /// angle travelled.
    pub turns: u32,
    /// +1 or -1: the direction of the travel.
    pub sign: f64,
    /// The gyro's angle over the span, arcsec (its counts times the LSB).
    pub gyro_arcsec: f64,
    /// The span on the bench's clock, s.
    pub bench_s: f64,
    /// The span on the table's clock, s: the angle travelled over the
    /// mean rate the table read.
    pub table_s: f64,
    /// The mean reference over the span (Earth + table rate on the
    /// sensitive axis), deg/h.
    pub input_dph: f64,
}

impl AngleSpan {
    /// The gyro's angle over the span per hour of the table's clock,
    /// deg/h: with [`AngleSpan::input_dph`], a point whose ratio is counts
    /// per angle (`gyro / (turns 360 + Earth angle)`): neither clock's error
    /// is in it beyond the Earth and bias terms' share (`docs/figures.md`).
    pub fn output_dph(&self) -> f64 {
        // arcsec / s is deg / h.
        self.gyro_arcsec / self.table_s
    }
}

/// `read` (the change of an angle read within one turn) made whole with
/// the turns `expected` (from the rate) says, deg.
fn unwrap(read: f64, expected: f64) -> f64 {
    read + 360.0 * ((expected - read) / 360.0).round()
}

impl Revolutions {
    /// A record starting with the table at `start`.
    pub fn new(start: TablePose) -> Self {
        Self {
            last: start,
            sums: Sums::default(),
            axes: [Axis::default(); 2],
        }
    }

    /// Add a tick that ended at `end`, in which the gyro sent `counts` and
    /// the mean reference on its axis was `reference_dph`. A tick not
    /// after the last one is left out.
    pub fn add(&mut self, end: TablePose, counts: i64, reference_dph: f64) {
        let dt = end.t_s - self.last.t_s;
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        let counts = counts as f64;
        let before = self.sums;
        let after = Sums {
            counts: before.counts + counts,
            span_s: before.span_s + dt,
            reference: before.reference + reference_dph * dt,
        };
        for (k, axis) in self.axes.iter_mut().enumerate() {
            let by_rate = 0.5 * (self.last.rates_dps[k] + end.rates_dps[k]) * dt;
            let turned = unwrap(end.angles_deg[k] - self.last.angles_deg[k], by_rate);
            let (from, to) = (
                axis.travelled_deg.abs(),
                (axis.travelled_deg + turned).abs(),
            );
            let n = ((to / 360.0) + WHOLE_TURN_TOLERANCE).floor();
            let at_deg = n * 360.0;
            if n >= 1.0 && at_deg > from && to > from {
                // The crossing within the tick (or just past its end),
                // by angle: the gyro's counts and the time go evenly with
                // the table's angle over one tick at a steady rate.
                let f = (at_deg - from) / (to - from);
                let at = Sums {
                    counts: before.counts + f * counts,
                    span_s: before.span_s + f * dt,
                    reference: before.reference + f * reference_dph * dt,
                };
                axis.whole = Some((n as u32, at, axis.by_rate_deg + f * by_rate));
            }
            axis.travelled_deg += turned;
            axis.by_rate_deg += by_rate;
        }
        self.sums = after;
        self.last = end;
    }

    /// The span over the whole revolutions of the axis that made the
    /// most (none when neither made one, or the table read no rate).
    pub fn span(&self, lsb_arcsec: f64) -> Option<AngleSpan> {
        let (axis, (turns, at, by_rate)) = self
            .axes
            .iter()
            .enumerate()
            .filter_map(|(k, a)| a.whole.map(|w| (k, w)))
            .max_by_key(|(_, w)| w.0)?;
        let angle = f64::from(turns) * 360.0;
        if at.span_s <= 0.0 || by_rate == 0.0 || by_rate.is_nan() {
            return None;
        }
        Some(AngleSpan {
            axis,
            turns,
            sign: self.axes[axis].travelled_deg.signum(),
            gyro_arcsec: at.counts * lsb_arcsec,
            bench_s: at.span_s,
            table_s: at.span_s * angle / by_rate.abs(),
            input_dph: at.reference / at.span_s,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LSB: f64 = 0.25;

    /// A record of `ticks` 1 s ticks of the inner axis at `rate_dps` from
    /// angle 10 deg, read within one turn, with `earth_dph` on the axis
    /// and a gyro of scale factor `k` and bias `bias_dph` whose counts
    /// come off a frame clock `clock_ppm` fast, reduced at the nominal
    /// period `frame_dt_s`. Returns the span and the time-domain point
    /// (input, output) as the 1 Hz means would give it.
    fn record(
        rate_dps: f64,
        ticks: usize,
        earth_dph: f64,
        k: f64,
        bias_dph: f64,
        clock_ppm: f64,
    ) -> (Option<AngleSpan>, (f64, f64)) {
        let frame_dt_s = 1.0 / 400.0;
        let wrap = |a: f64| (a + 180.0).rem_euclid(360.0) - 180.0;
        let pose = |t: f64| TablePose {
            t_s: 100.0 + t,
            angles_deg: [90.0, wrap(10.0 + rate_dps * t)],
            rates_dps: [0.0, rate_dps],
        };
        let mut r = Revolutions::new(pose(0.0));
        let input = rate_dps * 3600.0 + earth_dph;
        let (mut residual, mut counts_all, mut frames_all) = (0.0, 0i64, 0.0);
        for i in 1..=ticks {
            // The gyro's angle over the tick, as whole counts.
            residual += (k * input + bias_dph) * 1.0;
            let counts = (residual / LSB).floor();
            residual -= counts * LSB;
            counts_all += counts as i64;
            frames_all += 400.0 * (1.0 + clock_ppm * 1e-6);
            r.add(pose(i as f64), counts as i64, input);
        }
        let time_output = counts_all as f64 * LSB / (frames_all * frame_dt_s);
        (r.span(LSB), (input, time_output))
    }

    #[test]
    fn whole_revolutions_are_found_through_angles_read_within_one_turn() {
        // 200 deg/s for 144 s: 80 turns, 200 deg a tick (past the half
        // turn a wrap alone cannot tell).
        let (span, _) = record(200.0, 144, 11.6, 1.0, 0.0, 0.0);
        let s = span.expect("80 turns");
        assert_eq!((s.axis, s.turns, s.sign), (1, 80, 1.0));
        assert!((s.bench_s - 144.0).abs() < 1e-9, "{s:?}");
        assert!((s.table_s - 144.0).abs() < 1e-9, "{s:?}");
        // Turning the other way, 2 turns at 1 deg/s.
        let (span, _) = record(-1.0, 720, 11.6, 1.0, 0.0, 0.0);
        let s = span.expect("2 turns");
        assert_eq!((s.turns, s.sign), (2, -1.0));
        // Short of a turn: none.
        assert!(record(1.0, 300, 11.6, 1.0, 0.0, 0.0).0.is_none());
    }

    #[test]
    fn a_span_past_the_last_tick_is_interpolated_by_angle() {
        // 7 deg/s for 110 s: 770 deg, the second turn crossed at 102.86 s.
        let (span, _) = record(7.0, 110, 0.0, 1.0, 0.0, 0.0);
        let s = span.expect("2 turns");
        assert_eq!(s.turns, 2);
        assert!((s.bench_s - 720.0 / 7.0).abs() < 1e-9, "{s:?}");
        // The gyro's angle over it is the table's (to the count).
        assert!((s.gyro_arcsec - 720.0 * 3600.0).abs() <= LSB, "{s:?}");
    }

    #[test]
    fn the_frame_clock_drops_out_and_the_earth_angle_stays_in() {
        // A scale factor 30 ppm high, a bias of 0.8 deg/h, 11.6 deg/h of
        // Earth rate on the axis; the frame clock 50 ppm fast.
        let k = 1.0 + 30e-6;
        for (rate, ticks) in [(1.0, 720), (-1.0, 720), (20.0, 180), (-200.0, 144)] {
            let (span, (input, time_output)) = record(rate, ticks, 11.6, k, 0.8, 50.0);
            let s = span.expect("whole turns");
            assert!((s.input_dph / input - 1.0).abs() < 1e-12, "{s:?}");
            let angle = s.output_dph() - 0.8;
            let sf = (angle / input - 1.0) * 1e6;
            // To the count left in the quantizer: 0.25 arcsec of two turns
            // is 0.1 ppm.
            assert!(
                (sf - 30.0).abs() < 0.15,
                "{rate} deg/s: {sf} ppm in the angle domain"
            );
            // The counts over frames at the nominal period read 50 ppm low
            let sf_time = ((time_output - 0.8) / input - 1.0) * 1e6;
            assert!(
                (sf_time - (30.0 - 50.0)).abs() < 0.15,
                "{rate} deg/s: {sf_time}"
            );
            // The Earth's share of the input: thousands of ppm at 1 deg/s,
            // left out it would read as a scale-factor error.
            let earth_ppm = 11.6 / (rate * 3600.0) * 1e6;
            let without = ((s.gyro_arcsec / 3600.0 - 0.8 * s.table_s / 3600.0)
                / (s.sign * f64::from(s.turns) * 360.0)
                - 1.0)
                * 1e6;
            let expected = ((1.0 + 30e-6) * (1.0 + earth_ppm * 1e-6) - 1.0) * 1e6;
            assert!(
                (without - expected).abs() < 0.15,
                "{rate} deg/s: {without} ppm without the Earth's {earth_ppm}"
            );
        }
    }

    #[test]
    fn a_table_clock_off_the_bench_s_does_not_move_the_ratio() {
        // The table's rate reads 100 ppm high (its clock slow against the
        // bench's): the angle is the encoder's, the time the bench's.
        let rate = 5.0;
        let read = rate * (1.0 + 100e-6);
        let pose = |t: f64| TablePose {
            t_s: t,
            angles_deg: [90.0, (rate * t + 180.0).rem_euclid(360.0) - 180.0],
            rates_dps: [0.0, read],
        };
        let earth = 11.6;
        let mut r = Revolutions::new(pose(0.0));
        let reference = read * 3600.0 + earth;
        let truth = rate * 3600.0 + earth;
        let mut residual = 0.0;
        for i in 1..=300 {
            residual += truth;
            let counts = (residual / LSB).floor();
            residual -= counts * LSB;
            r.add(pose(f64::from(i)), counts as i64, reference);
        }
        let s = r.span(LSB).expect("4 turns");
        assert_eq!(s.turns, 4);
        let sf = (s.output_dph() / s.input_dph - 1.0) * 1e6;
        // What is left is the clock's share of the Earth term: 100 ppm of
        // 11.6 / 18000.
        assert!(sf.abs() < 0.1, "{sf} ppm");
    }
}
