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

/// A stretch of identical counts this long (s) is a stuck output (ours):
/// a working laser gyro's output moves by a count within seconds, from
/// the Earth rate and its own bias alone (the RL-16 at its 0.25 arcsec
/// count: about 40 counts a second axis up, 2 a second axis east), and
/// its angle random walk moves it even at zero rate.
pub const STUCK_AFTER_S: f64 = 5.0;
/// The same for a stretch of small counts, [`SMALL_COUNTS`] or fewer a
/// frame (ours): near zero input (a position where the bias cancels the
/// Earth rate), or an input of nearly a whole number of counts a frame
/// (at 100 frames a second and 0.25 arcsec a count, one count a frame is
/// 7 deg/h: the Earth rate's range), a quiet gyro's angle random walk
/// takes its time to move a count: at 0.001 deg/sqrt(h), about 17 s for one
/// sigma; a minute of the same count is still a frozen output.
pub const STUCK_AT_ZERO_AFTER_S: f64 = 60.0;
/// Counts a frame up to which a stretch waits [`STUCK_AT_ZERO_AFTER_S`].
pub const SMALL_COUNTS: i32 = 2;

/// Runs of identical consecutive counts, mergeable tick by tick: what a
/// frozen output leaves behind, however short the record's other part.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Runs {
    /// Frames seen.
    pub n: u64,
    /// First count.
    pub first: i32,
    /// Last count.
    pub last: i32,
    /// Length of the run the frames start with.
    pub prefix: u64,
    /// Length of the run they end with.
    pub suffix: u64,
    /// Longest run, and its count.
    pub longest: (u64, i32),
}

impl Runs {
    /// One more frame (on every frame of a run: kept to a few compares).
    pub fn push(&mut self, v: i32) {
        if self.n == 0 {
            *self = Self {
                n: 1,
                first: v,
                last: v,
                prefix: 1,
                suffix: 1,
                longest: (1, v),
            };
            return;
        }
        if v == self.last {
            if self.prefix == self.n {
                self.prefix += 1;
            }
            self.suffix += 1;
            if self.suffix > self.longest.0 {
                self.longest = (self.suffix, v);
            }
        } else {
            self.last = v;
            self.suffix = 1;
        }
        self.n += 1;
    }

    /// The frames of `b` follow these.
    pub fn merge(&mut self, b: &Self) {
        if b.n == 0 {
            return;
        }
        if self.n == 0 {
            *self = *b;
            return;
        }
        let joins = self.last == b.first;
        let joined = if joins { self.suffix + b.prefix } else { 0 };
        let mut longest = if b.longest.0 > self.longest.0 {
            b.longest
        } else {
            self.longest
        };
        if joined > longest.0 {
            longest = (joined, self.last);
        }
        let prefix = if joins && self.prefix == self.n {
            self.n + b.prefix
        } else {
            self.prefix
        };
        let suffix = if joins && b.suffix == b.n {
            b.n + self.suffix
        } else {
            b.suffix
        };
        *self = Self {
            n: self.n + b.n,
            first: self.first,
            last: b.last,
            prefix,
            suffix,
            longest,
        };
    }
}

/// What a record's frames and link were like.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RecordHealth {
    /// Length of the record, s.
    pub duration_s: f64,
    /// Device time by which the record's ends may fall off its frames', s
    /// (the frames of that much time at each end may be in a neighbour).
    #[serde(default)]
    pub edge_s: f64,
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
    /// Runs of identical counts.
    #[serde(default)]
    pub runs: Runs,
    /// The gyro link's figures over the record (none on a bench whose link
    /// cannot fail, or in a log of the first format).
    pub link: Option<LinkStats>,
}

impl RecordHealth {
    /// A record of `duration_s` whose ends may fall `edge_s` off its
    /// frames' (a served bench's delivery delay, in device time).
    pub fn new(duration_s: f64, edge_s: f64) -> Self {
        Self {
            duration_s,
            edge_s,
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
    /// `min` and `max` with `runs` of identical ones, `lsb_arcsec` each.
    pub fn add(
        &mut self,
        n: u64,
        (min, max): (i32, i32),
        runs: &Runs,
        frame_dt_s: f64,
        lsb_arcsec: f64,
    ) {
        if n == 0 {
            return;
        }
        self.frames += n;
        self.runs.merge(runs);
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
        // Frames a late delivery moved across the record's ends are not
        // lost (they are in the step beside it); frames lost on the way
        // show as gaps of the sequence counter, judged below.
        let edges = if self.frame_dt_s > 0.0 {
            2.0 * self.edge_s / self.frame_dt_s
        } else {
            0.0
        };
        let short = expected.saturating_sub(self.frames);
        if short as f64 > allowed + edges {
            return Some(format!(
                "{} of {expected} frames received ({:.2} % missing); check the gyro's data cable",
                self.frames,
                100.0 * short as f64 / expected.max(1) as f64
            ));
        }
        // A tick takes every frame the link holds: far more than the record
        // lasts means the host fell behind the gyro, and frames from before
        // the record (another rate, a move) were counted in it.
        let over = self.frames.saturating_sub(expected);
        let slack = (0.05 * expected as f64).max(2.0 / self.frame_dt_s.max(1e-9));
        if expected > 0 && over as f64 > slack {
            return Some(format!(
                "{} frames for a record of {expected}: the host fell behind the gyro and frames from before the record were counted in it; run with fewer programs beside it",
                self.frames
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
        let (len, value) = self.runs.longest;
        // Zero counts frame after frame is a ring laser locked in (an
        // input inside its lock-in band: the beams lock and it sends
        // nothing), which the dead-band test measures: not a fault.
        if value == 0 {
            return None;
        }
        let stuck_s = len as f64 * self.frame_dt_s;
        let after = if value.abs() <= SMALL_COUNTS {
            STUCK_AT_ZERO_AFTER_S
        } else {
            STUCK_AFTER_S
        };
        (stuck_s >= after && len >= 2).then(|| {
            format!(
                "the output read {value} counts in every frame for {stuck_s:.0} s ({len} frames): it is stuck"
            )
        })
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

    /// `n` frames cycling through -3..=4.
    fn varied(n: u64) -> Runs {
        let mut r = Runs::default();
        for i in 0..n {
            r.push((i % 8) as i32 - 3);
        }
        r
    }

    fn stuck(n: u64, v: i32) -> Runs {
        let mut r = Runs::default();
        for _ in 0..n {
            r.push(v);
        }
        r
    }

    fn healthy() -> RecordHealth {
        let mut h = RecordHealth::new(100.0, 0.0);
        h.add(40_000, (-3, 4), &varied(40_000), 0.0025, 0.25);
        h
    }

    #[test]
    fn a_sound_record_has_no_problem() {
        assert_eq!(healthy().problem(), None);
    }

    #[test]
    fn lost_frames_corruption_stuck_and_saturated_outputs_are_named() {
        let mut short = RecordHealth::new(100.0, 0.0);
        short.add(39_000, (-3, 4), &varied(39_000), 0.0025, 0.25);
        assert!(short.problem().expect("short").contains("missing"));

        // On a bench served at 30x, 50 ms of wall-time delay is 1.5 s of
        // device time at each end: 186 frames short of 72,000 moved into
        // the next step, not lost; 1,500 short are lost.
        let served = |frames: u64| {
            let mut h = RecordHealth::new(180.0, 0.05 * 30.0);
            h.add(frames, (-3, 4), &varied(frames), 0.0025, 0.25);
            h.problem()
        };
        assert_eq!(served(71_814), None);
        assert!(served(70_500).expect("lost").contains("missing"));
        let mut paced = RecordHealth::new(180.0, 0.0);
        paced.add(71_814, (-3, 4), &varied(71_814), 0.0025, 0.25);
        assert!(paced.problem().expect("short").contains("missing"));

        // 100 s at 400 Hz holds 40,000 frames; 60,000 is a backlog from
        // before the record (the host fell behind), a few more is not.
        let mut over = RecordHealth::new(100.0, 0.0);
        over.add(60_000, (-3, 4), &varied(60_000), 0.0025, 0.25);
        assert!(over.problem().expect("overfull").contains("fell behind"));
        let mut edge = RecordHealth::new(100.0, 0.0);
        edge.add(40_600, (-3, 4), &varied(40_600), 0.0025, 0.25);
        assert_eq!(edge.problem(), None);

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

        // Stuck for the last 130 s of a 300 s record, tick by tick.
        let mut part = RecordHealth::new(300.0, 0.0);
        for _ in 0..170 {
            part.add(400, (-3, 4), &varied(400), 0.0025, 0.25);
        }
        for _ in 0..130 {
            part.add(400, (7, 7), &stuck(400, 7), 0.0025, 0.25);
        }
        let why = part.problem().expect("stuck");
        assert!(
            why.contains("read 7 counts") && why.contains("130 s"),
            "{why}"
        );
        // Shorter than that: a stretch an output can have.
        let mut brief = RecordHealth::new(300.0, 0.0);
        brief.add(400, (-3, 4), &varied(400), 0.0025, 0.25);
        brief.add(1_600, (0, 0), &stuck(1_600, 0), 0.0025, 0.25);
        brief.add(400, (-3, 4), &varied(400), 0.0025, 0.25);
        assert!(!brief.problem().is_some_and(|p| p.contains("stuck")));
        // One count a frame for 20 s: a quiet gyro at a whole count a
        // frame; for 70 s: frozen. Zeros, however long: locked in (the
        // dead band), not stuck.
        for (value, zeros_s, frozen) in [
            (0, 20u64, false),
            (0, 70, false),
            (-1, 20, false),
            (-1, 70, true),
        ] {
            let mut quiet = RecordHealth::new(100.0, 0.0);
            quiet.add(400, (-1, 1), &varied(400), 0.0025, 0.25);
            let n = zeros_s * 400;
            quiet.add(n, (value, value), &stuck(n, value), 0.0025, 0.25);
            quiet.add(
                40_000 - 400 - n,
                (-1, 1),
                &varied(40_000 - 400 - n),
                0.0025,
                0.25,
            );
            assert_eq!(quiet.problem().is_some_and(|p| p.contains("stuck")), frozen);
        }

        let mut pinned = RecordHealth::new(100.0, 0.0);
        pinned.add(40_000, (0, i32::MAX), &varied(40_000), 0.0025, 0.25);
        assert!(pinned.problem().expect("saturated").contains("saturated"));
    }

    #[test]
    fn runs_merge_across_ticks_as_one_sequence_would() {
        let seq: Vec<i32> = [1, 1, 2, 2, 2, 2, 3, 2, 2, 2].into_iter().collect();
        let mut whole = Runs::default();
        seq.iter().for_each(|v| whole.push(*v));
        for cut in 0..seq.len() {
            let (mut a, mut b) = (Runs::default(), Runs::default());
            seq[..cut].iter().for_each(|v| a.push(*v));
            seq[cut..].iter().for_each(|v| b.push(*v));
            a.merge(&b);
            assert_eq!(a, whole, "cut at {cut}");
        }
        assert_eq!(whole.longest, (4, 2));
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
