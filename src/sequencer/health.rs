//! Whether a record's data can be judged at all: the gyro link delivered
//! it (no more than a trace of frames lost or corrupted) and the output is
//! plausible for a laser gyro (it changes, it is not pinned at a limit).
//! A measurement on a record that fails here is not judged: its outcome is
//! `error` with the reason, never a PASS or FAIL on bad data.
//!
//! The live run and replay feed the same figures (frame counts and
//! extremes from the frames, the link's figures over the record from the
//! `/steps` end event), so both reach the same judgement.

use serde::{Deserialize, Serialize};

use crate::protocol::frame::LinkStats;

/// Largest share of a record's frames that may be lost, corrupted or
/// duplicated before the record is not judged (ours: a tenth of a percent,
/// far above a sound link's zero and far below what moves a figure).
pub const MAX_LINK_LOSS: f64 = 1e-3;

/// Fastest rate a laser gyro's output can plausibly show, deg/h (1000
/// deg/s; the RL-16's input range is a fraction of it). A frame beyond it
/// is a saturated or garbled output.
pub const MAX_PLAUSIBLE_RATE_DPH: f64 = 3.6e6;

/// What a record's frames and link were like.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RecordHealth {
    /// Length of the record, s.
    pub duration_s: f64,
    /// Frame period, s (from its frames).
    pub frame_dt_s: f64,
    /// Frames received during the record.
    pub frames: u64,
    /// Smallest delta-angle count of any frame.
    pub min_counts: Option<i32>,
    /// Largest delta-angle count of any frame.
    pub max_counts: Option<i32>,
    /// Rate of the largest count in magnitude, deg/h.
    pub max_abs_rate_dph: f64,
    /// The gyro link's figures over the record (none on a bench whose link
    /// cannot fail, or in a log of the first format).
    pub link: Option<LinkStats>,
}

impl RecordHealth {
    /// A record of `duration_s`.
    pub fn new(duration_s: f64) -> Self {
        Self {
            duration_s,
            ..Self::default()
        }
    }

    /// Frames the record should hold (duration / frame period).
    pub fn expected_frames(&self) -> u64 {
        if self.frame_dt_s > 0.0 {
            (self.duration_s / self.frame_dt_s).round().max(0.0) as u64
        } else {
            0
        }
    }

    /// Frames of one tick: `n` of them at `frame_dt_s`, counts between
    /// `min` and `max`, `lsb_arcsec` each.
    pub fn add(&mut self, n: u64, min: i32, max: i32, frame_dt_s: f64, lsb_arcsec: f64) {
        if n == 0 {
            return;
        }
        self.frames += n;
        self.frame_dt_s = frame_dt_s;
        // arcsec per second is deg/h.
        let counts_to_dph = lsb_arcsec / frame_dt_s;
        self.min_counts = Some(self.min_counts.map_or(min, |m| m.min(min)));
        self.max_counts = Some(self.max_counts.map_or(max, |m| m.max(max)));
        let rate = f64::from(min.unsigned_abs().max(max.unsigned_abs())) * counts_to_dph;
        self.max_abs_rate_dph = self.max_abs_rate_dph.max(rate);
    }

    /// Why the record cannot be judged, or none.
    pub fn problem(&self) -> Option<String> {
        if self.frames == 0 {
            return Some("no gyro frame was received".into());
        }
        let expected = self.expected_frames();
        let allowed = (MAX_LINK_LOSS * expected as f64).max(2.0);
        let short = expected.saturating_sub(self.frames);
        if short as f64 > allowed {
            return Some(format!(
                "{} of {expected} frames received ({:.2} % missing); check the gyro's data cable",
                self.frames,
                100.0 * short as f64 / expected.max(1) as f64
            ));
        }
        if let Some(l) = &self.link {
            let bad = l.crc_errors + l.lost_frames + l.duplicates;
            if bad as f64 > allowed {
                return Some(format!(
                    "the gyro link lost or corrupted {bad} frames over the record ({} CRC errors, {} lost, {} duplicated, {} reconnects); check the gyro's data cable",
                    l.crc_errors, l.lost_frames, l.duplicates, l.reconnects
                ));
            }
        }
        if self.max_abs_rate_dph > MAX_PLAUSIBLE_RATE_DPH {
            return Some(format!(
                "frames at {:.0} deg/s, beyond any laser gyro's range: a saturated or garbled output",
                self.max_abs_rate_dph / 3600.0
            ));
        }
        match (self.min_counts, self.max_counts) {
            (Some(lo), Some(hi)) if lo == hi && self.frames >= 2 => Some(format!(
                "every one of its {} frames reads {lo} counts: the output is stuck",
                self.frames
            )),
            _ => None,
        }
    }
}

/// The link figures of one stretch: `end` less `start`.
pub fn link_delta(start: &LinkStats, end: &LinkStats) -> LinkStats {
    LinkStats {
        bytes: end.bytes.saturating_sub(start.bytes),
        frames: end.frames.saturating_sub(start.frames),
        resyncs: end.resyncs.saturating_sub(start.resyncs),
        skipped_bytes: end.skipped_bytes.saturating_sub(start.skipped_bytes),
        crc_errors: end.crc_errors.saturating_sub(start.crc_errors),
        lost_frames: end.lost_frames.saturating_sub(start.lost_frames),
        duplicates: end.duplicates.saturating_sub(start.duplicates),
        reconnects: end.reconnects.saturating_sub(start.reconnects),
        longest_gap_ms: end.longest_gap_ms,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn healthy() -> RecordHealth {
        let mut h = RecordHealth::new(100.0);
        h.add(40_000, -3, 4, 0.0025, 0.25);
        h
    }

    #[test]
    fn a_sound_record_has_no_problem() {
        assert_eq!(healthy().problem(), None);
    }

    #[test]
    fn lost_frames_corruption_stuck_and_saturated_outputs_are_named() {
        let mut short = RecordHealth::new(100.0);
        short.add(39_000, -3, 4, 0.0025, 0.25);
        assert!(short.problem().expect("short").contains("missing"));

        let mut corrupt = healthy();
        corrupt.link = Some(LinkStats {
            crc_errors: 300,
            lost_frames: 200,
            ..LinkStats::default()
        });
        assert!(
            corrupt
                .problem()
                .expect("corrupt")
                .contains("300 CRC errors")
        );

        let mut stuck = RecordHealth::new(100.0);
        stuck.add(40_000, 7, 7, 0.0025, 0.25);
        assert!(stuck.problem().expect("stuck").contains("stuck"));

        let mut pinned = RecordHealth::new(100.0);
        pinned.add(40_000, 0, i32::MAX, 0.0025, 0.25);
        assert!(pinned.problem().expect("saturated").contains("saturated"));
    }

    #[test]
    fn a_trace_of_link_trouble_is_tolerated() {
        let mut h = healthy();
        h.link = Some(LinkStats {
            crc_errors: 10,
            lost_frames: 10,
            ..LinkStats::default()
        });
        assert_eq!(h.problem(), None, "20 of 40,000 frames");
    }
}
