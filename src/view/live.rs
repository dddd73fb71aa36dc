//! A unit's drift as the live displays show it (the progress line of
//! `run`, the station's read-out, chart and batch tiles): the mean
//! Earth-removed rate over the last [`WINDOW_S`] of the record being
//! taken (or of the latest record, once it ended), named with its window
//! and its record. Never one 1 s sample, which is a few of the gyro's
//! counts (0.152, 0.402, 0.652 deg/h), nor a second outside a record: a
//! slew's seconds read thousands of deg/h and waits are not measured.

use std::collections::VecDeque;

use serde::Serialize;

/// The window a drift averages, s of device time.
pub const WINDOW_S: f64 = 60.0;

/// A unit's drift as shown (serialised with these names in the station's
/// state).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Drift {
    /// Mean rate with the Earth rate removed, deg/h.
    pub mean_dph: f64,
    /// The 1 s intervals it averages: [`WINDOW_S`] worth once the record
    /// is that long, fewer at its start.
    pub seconds: u32,
    /// The record's label.
    pub record: String,
    /// True while the record is being taken; false once it ended (the
    /// bench moving or soaking, the next record not begun).
    pub recording: bool,
    /// The window in words, for a page to show as it is: `mean of the
    /// last 60 s of record up`, `mean of 12 s of record up so far`, `mean
    /// of the last 60 s of record up (ended)`.
    pub window: String,
}

impl Drift {
    /// `+0.402 deg/h, mean of the last 60 s of record up`.
    pub fn render(&self) -> String {
        format!("{:+.3} deg/h, {}", self.mean_dph, self.window)
    }
}

/// The words of a window of `seconds` of `record`.
fn window_words(seconds: u32, record: &str, recording: bool) -> String {
    let ended = if recording { "" } else { " (ended)" };
    if f64::from(seconds) >= WINDOW_S {
        format!("mean of the last {seconds} s of record {record}{ended}")
    } else if recording {
        format!("mean of {seconds} s of record {record} so far")
    } else {
        format!("mean of the {seconds} s of record {record}{ended}")
    }
}

/// The seconds a unit's drift is taken from, told every 1 s interval.
#[derive(Debug, Clone, Default)]
pub struct DriftWindow {
    /// The record being taken, or the latest one.
    record: Option<String>,
    /// Whether `record` is being taken now.
    recording: bool,
    /// Its last seconds: (interval centre s, Earth-removed rate deg/h).
    seconds: VecDeque<(f64, f64)>,
}

impl DriftWindow {
    /// One 1 s interval: centred at `time_s`, Earth-removed rate
    /// `bias_dph`, in `record` (none: outside every record). A record
    /// begun (or one taken again after a break) starts the window afresh;
    /// a second with no finite rate is left out.
    pub fn push(&mut self, time_s: f64, bias_dph: f64, record: Option<&str>) {
        let Some(record) = record else {
            self.recording = false;
            return;
        };
        if !self.recording || self.record.as_deref() != Some(record) {
            self.seconds.clear();
            self.record = Some(record.to_owned());
            self.recording = true;
        }
        if !(time_s.is_finite() && bias_dph.is_finite()) {
            return;
        }
        self.seconds.push_back((time_s, bias_dph));
        while self
            .seconds
            .front()
            .is_some_and(|(t, _)| time_s - t >= WINDOW_S - 0.5)
        {
            self.seconds.pop_front();
        }
    }

    /// The drift now: none before the first second of a record.
    pub fn drift(&self) -> Option<Drift> {
        let record = self.record.clone()?;
        if self.seconds.is_empty() {
            return None;
        }
        let n = self.seconds.len();
        let mean_dph = self.seconds.iter().map(|(_, r)| r).sum::<f64>() / n as f64;
        let seconds = u32::try_from(n).unwrap_or(u32::MAX);
        Some(Drift {
            mean_dph,
            seconds,
            window: window_words(seconds, &record, self.recording),
            record,
            recording: self.recording,
        })
    }

    /// The mean over a whole window, once the record has been taken that
    /// long (a chart's mean line: no line from a record's first seconds).
    pub fn full_mean_dph(&self) -> Option<f64> {
        let d = self.drift()?;
        (d.recording && f64::from(d.seconds) >= WINDOW_S).then_some(d.mean_dph)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seconds of a record, a slew between records (thousands of deg/h)
    /// and the next record: the drift is the record's, never a slew's, and
    /// starts afresh with each record.
    #[test]
    fn the_drift_is_the_records_mean_over_its_last_minute() {
        let mut w = DriftWindow::default();
        assert_eq!(w.drift(), None, "nothing before a record");
        w.push(0.5, 4700.0, None);
        assert_eq!(w.drift(), None, "a slew is no record");
        for k in 0..100 {
            // Quantized seconds: 0.152 and 0.652 in turn, mean 0.402.
            let r = if k % 2 == 0 { 0.152 } else { 0.652 };
            w.push(1.5 + f64::from(k), r, Some("up"));
        }
        let d = w.drift().expect("a drift");
        assert_eq!((d.seconds, d.recording), (60, true));
        assert!((d.mean_dph - 0.402).abs() < 1e-12, "{d:?}");
        assert_eq!(d.window, "mean of the last 60 s of record up");
        assert_eq!(
            d.render(),
            "+0.402 deg/h, mean of the last 60 s of record up"
        );
        assert_eq!(w.full_mean_dph(), Some(d.mean_dph));
        // The slew after it: the last record's drift, said ended.
        for k in 0..5 {
            w.push(101.5 + f64::from(k), -4700.0, None);
        }
        let ended = w.drift().expect("the last record's");
        assert_eq!(ended.mean_dph, d.mean_dph);
        assert_eq!(ended.window, "mean of the last 60 s of record up (ended)");
        assert_eq!(w.full_mean_dph(), None);
        // The next record starts afresh.
        w.push(106.5, 1.0, Some("east"));
        w.push(107.5, 2.0, Some("east"));
        let east = w.drift().expect("east");
        assert_eq!((east.mean_dph, east.seconds), (1.5, 2));
        assert_eq!(east.window, "mean of 2 s of record east so far");
        assert_eq!(w.full_mean_dph(), None);
    }

    /// Back-to-back records (a thermal cycle's segments) each have their
    /// own window; a second missing from a record is not counted.
    #[test]
    fn back_to_back_records_and_gaps() {
        let mut w = DriftWindow::default();
        for k in 0..30 {
            w.push(f64::from(k), 1.0, Some("ramp"));
        }
        w.push(30.0, 3.0, Some("soak"));
        assert_eq!(w.drift().map(|d| (d.mean_dph, d.seconds)), Some((3.0, 1)));
        // 100 s later in the same record (a gap in the frames): the window
        // holds the last 60 s of device time, not 60 intervals.
        w.push(130.0, 5.0, Some("soak"));
        assert_eq!(w.drift().map(|d| (d.mean_dph, d.seconds)), Some((5.0, 1)));
        w.push(131.0, f64::NAN, Some("soak"));
        assert_eq!(w.drift().map(|d| d.seconds), Some(1));
    }
}
