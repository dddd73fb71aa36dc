//! The 1 Hz record store and the figures `measure` steps compute on it.

use std::collections::BTreeMap;
use std::ops::Range;

use gyrobench_model::measurement::Measurement;

use super::BenchState;
use super::compensated::{Residual, compensated_drift};
use super::events::{PowerOn, PowerOnSource};
use super::health::{RecordHealth, Runs};
use super::spill::{Row, Spill, bytes_at, f64_at};
use super::uncertainty::Known;
use crate::analysis::figures::{DriftTrace, bias_stability, drift_trace, mean, std_dev};
use crate::analysis::model::{self, ModelKind};
use crate::analysis::rate::angle::{Revolutions, TablePose};
use crate::analysis::rate::{self, Figure, RatePoint};
use crate::analysis::series::Interval;
use crate::analysis::study::{self_heating, sensitivity_fit};
use crate::analysis::uncertainty::{Contribution, Uncertainty};
use crate::procedure::{DecisionRule, Measure, Metric};
use crate::protocol::frame::StatusBits;
use crate::typeb::TypeB;

/// 1 Hz intervals of the whole run, and by record label.
///
/// The intervals and supply readings are filed in a [`Spill`]: a run holds
/// a constant amount of memory however long it is, and a clone (a unit's
/// result, a resumed run's earlier part) shares what is filed.
#[derive(Debug, Clone, Default)]
pub struct Records {
    /// Every interval of the run, and whether it belongs to a record
    /// (the table at rest); labels are in `by_label`.
    all: Spill<(bool, Interval)>,
    /// Each record's intervals: indices in `all`.
    by_label: BTreeMap<String, Vec<Range<u64>>>,
    /// Labels in the order they were recorded.
    pub order: Vec<String>,
    /// Whether each record's frames can be judged (records with frames).
    health: BTreeMap<String, RecordHealth>,
    /// The part of the run (power-on) each record was taken in.
    part_of: BTreeMap<String, u32>,
    /// The part records start in now (0 until set: the first).
    part: u32,
    /// Sums of the table's axis rates (outer, inner, deg/s) over each
    /// record's intervals, and their number.
    turning: BTreeMap<String, (f64, f64, u64)>,
    /// Each record's ticks over the table's revolutions (the angle
    /// domain), with the LSB of its counts, arcsec.
    revolutions: BTreeMap<String, (Revolutions, f64)>,
    /// The table at the end of the last tick that made an interval (none
    /// when its angles were not known).
    last_pose: Option<TablePose>,
    /// Every reading of the unit's supply, in the order the bench took
    /// them (benches with a supply).
    power: Spill<PowerSample>,
    /// The index in `power` of the last reading with the output off.
    last_off: Option<u64>,
    /// For each record: the index in `power` of the first reading after
    /// the turn-on before it, and of the record's first and last readings.
    power_of: BTreeMap<String, (u64, u64, u64)>,
    /// Every power-on the run knows of, with the part it was in.
    power_ons: Vec<(u32, PowerOn)>,
    /// Sums of the gravity along the axis (g) over each record's
    /// intervals, and their number.
    axis_gravity: BTreeMap<String, (f64, u64)>,
    /// What the unit's status word means ([`StatusBits`]).
    status_bits: StatusBits,
    /// Whether the path-length control was in lock at the last frame
    /// that said (none after a tick without frames: the unit off or
    /// silent, whose next lock is an acquisition, not a reset).
    lock_last: Option<bool>,
    /// The intervals of each record dropped because their frames' status
    /// said the unit was not fit.
    dropped: BTreeMap<String, Dropped>,
    /// Every reset of the path-length control (a mode hop): the device
    /// time of the tick it fell in, and the record then under way.
    hops: Vec<(f64, Option<String>)>,
}

/// A record's intervals left out of its figures because a frame of each
/// said the unit was not fit (`docs/figures.md`, "Status bits").
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Dropped {
    /// Intervals dropped.
    pub intervals: u64,
    /// Device time they span, s.
    pub s: f64,
    /// The fitness bits their frames lacked (OR of all).
    pub missing: u16,
}

/// What the time since power-on of a figure's records rests on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerBasis {
    /// Device time of the power-on the first of the records follows, s
    /// since its part started (0 when none is known).
    pub t_s: f64,
    /// How it is known.
    pub source: PowerOnSource,
}

impl PowerBasis {
    /// In words, for a figure's note.
    pub fn describe(&self) -> String {
        match self.source {
            PowerOnSource::Assumed => {
                "time since power-on taken from the start of the run: no power-on was recorded"
                    .to_owned()
            }
            s => format!(
                "time since the power-on at {:.1} s of device time ({})",
                self.t_s,
                s.describe()
            ),
        }
    }
}

impl Row for (bool, Interval) {
    const SIZE: usize = 7 * 8 + 4 + 1;

    fn encode(&self, out: &mut Vec<u8>) {
        let (in_record, iv) = self;
        for v in [
            iv.time_s,
            iv.rate_dph,
            iv.reference_dph,
            iv.t1_c,
            iv.t2_c,
            iv.tcase_c,
            iv.chamber_c,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&iv.frames.to_le_bytes());
        out.push(u8::from(*in_record));
    }

    fn decode(b: &[u8]) -> Self {
        let f = |i: usize| f64_at(b, i * 8);
        let iv = Interval {
            time_s: f(0),
            rate_dph: f(1),
            reference_dph: f(2),
            t1_c: f(3),
            t2_c: f(4),
            tcase_c: f(5),
            chamber_c: f(6),
            frames: u32::from_le_bytes(bytes_at(b, 56)),
        };
        (b.get(60) == Some(&1), iv)
    }
}

impl Row for PowerSample {
    const SIZE: usize = 3 * 8 + 1;

    fn encode(&self, out: &mut Vec<u8>) {
        for v in [self.t_s, self.v, self.a] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.push(u8::from(self.on));
    }

    fn decode(b: &[u8]) -> Self {
        Self {
            t_s: f64_at(b, 0),
            v: f64_at(b, 8),
            a: f64_at(b, 16),
            on: b.get(24) == Some(&1),
        }
    }
}

/// Failed reads of each of a store's files, with the last one's reason.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadFaults([(u64, Option<String>); 2]);

impl ReadFaults {
    /// Why reads failed after `before` was taken (the reason of a file
    /// whose count rose), or none.
    pub fn since(&self, before: &ReadFaults) -> Option<String> {
        self.0
            .iter()
            .zip(&before.0)
            .find(|(now, then)| now.0 > then.0)
            .map(|(now, _)| now.1.clone().unwrap_or_default())
    }

    /// Why reads failed at all, or none.
    pub fn any(&self) -> Option<String> {
        self.since(&Self::default())
    }
}

/// One reading of the unit's supply output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerSample {
    /// Device time of the reading, s.
    pub t_s: f64,
    /// Voltage measured at the output, V.
    pub v: f64,
    /// Current measured, A.
    pub a: f64,
    /// Output switched on.
    pub on: bool,
}

impl PowerSample {
    /// The sample of a reading taken at `t_s`.
    pub fn of(t_s: f64, r: &crate::driver::SupplyReading) -> Self {
        Self {
            t_s,
            v: r.v,
            a: r.a,
            on: r.on,
        }
    }

    /// Power delivered, W.
    pub fn w(&self) -> f64 {
        self.v * self.a
    }
}

impl Records {
    /// A record starts.
    pub fn start(&mut self, label: &str) {
        self.by_label.entry(label.to_owned()).or_default();
        self.order.push(label.to_owned());
        self.part_of.insert(label.to_owned(), self.part.max(1));
    }

    /// Records from here on are taken in part `part` of the run (a new
    /// power-on after a resume).
    pub fn set_part(&mut self, part: u32) {
        self.part = part;
    }

    /// The intervals of `labels`, grouped by the part of the run they were
    /// taken in (in part order; one group for a run never resumed): one
    /// series, and the length of each part's stretch of it (none empty).
    pub fn by_part(&self, labels: &[String]) -> (Vec<Interval>, Vec<usize>) {
        let mut parts: BTreeMap<u32, Vec<&Range<u64>>> = BTreeMap::new();
        for l in labels {
            if let Some(ranges) = self.by_label.get(l) {
                let part = self.part_of.get(l).copied().unwrap_or(1);
                parts.entry(part).or_default().extend(ranges);
            }
        }
        let rows = |r: &Range<u64>| (r.end - r.start) as usize;
        let total = parts.values().flatten().map(|r| rows(r)).sum();
        let mut series = Vec::with_capacity(total);
        let mut lens = Vec::new();
        for ranges in parts.values() {
            let before = series.len();
            for r in ranges {
                self.all.for_each((*r).clone(), |(_, iv)| series.push(iv));
            }
            if series.len() > before {
                lens.push(series.len() - before);
            }
        }
        (series, lens)
    }

    /// The unit was switched on (in the part records start in now).
    pub fn power_on(&mut self, on: PowerOn) {
        self.power_ons.push((self.part.max(1), on));
    }

    /// Every power-on recorded, with its part.
    pub fn power_ons(&self) -> &[(u32, PowerOn)] {
        &self.power_ons
    }

    /// [`Records::by_part`] with each interval's time counted from the
    /// power-on before it in its part (from the part's start when none
    /// was recorded), and what the first part's time rests on: the
    /// figures that count from power-on (self-heating, model 4's warm-up).
    pub fn by_part_since_power_on(
        &self,
        labels: &[String],
    ) -> (Vec<Interval>, Vec<usize>, PowerBasis) {
        let mut parts: BTreeMap<u32, Vec<&Range<u64>>> = BTreeMap::new();
        for l in labels {
            if let Some(ranges) = self.by_label.get(l) {
                let part = self.part_of.get(l).copied().unwrap_or(1);
                parts.entry(part).or_default().extend(ranges);
            }
        }
        let mut series = Vec::new();
        let mut lens = Vec::new();
        let mut basis = None;
        for (&part, ranges) in &parts {
            let ons: Vec<(f64, PowerOnSource)> = self
                .power_ons
                .iter()
                .filter(|(p, _)| *p == part)
                .map(|(_, on)| (on.t_s, on.source))
                .collect();
            let before = series.len();
            for r in ranges {
                self.all.for_each((*r).clone(), |(_, mut iv)| {
                    let on = ons
                        .iter()
                        .rev()
                        .find(|(t, _)| *t <= iv.time_s)
                        .copied()
                        .unwrap_or((0.0, PowerOnSource::Assumed));
                    basis.get_or_insert(PowerBasis {
                        t_s: on.0,
                        source: on.1,
                    });
                    iv.time_s -= on.0;
                    series.push(iv);
                });
            }
            if series.len() > before {
                lens.push(series.len() - before);
            }
        }
        let basis = basis.unwrap_or(PowerBasis {
            t_s: 0.0,
            source: PowerOnSource::Assumed,
        });
        (series, lens, basis)
    }

    /// A record of frames starts: its health is watched from here; its
    /// ends may fall `edge_s` off its frames' ([`RecordHealth::new`]).
    pub fn start_frames(&mut self, label: &str, duration_s: f64, edge_s: f64) {
        self.start(label);
        self.health
            .insert(label.to_owned(), RecordHealth::new(duration_s, edge_s));
    }

    /// Forget what a record holds (it is recorded again from its start).
    pub fn discard(&mut self, label: &str) {
        if let Some(v) = self.by_label.get_mut(label) {
            v.clear();
        }
        self.health.remove(label);
        self.turning.remove(label);
        self.revolutions.remove(label);
        self.power_of.remove(label);
        self.dropped.remove(label);
        self.hops.retain(|(_, r)| r.as_deref() != Some(label));
    }

    /// What the unit's status word means: the bench's frame layout's
    /// [`StatusBits`] (the documented frame's until set).
    pub fn set_status_bits(&mut self, bits: StatusBits) {
        self.status_bits = bits;
    }

    /// What the unit's status word means.
    pub fn status_bits(&self) -> StatusBits {
        self.status_bits
    }

    /// The intervals dropped from each record (the unit not fit), by label.
    pub fn dropped(&self) -> &BTreeMap<String, Dropped> {
        &self.dropped
    }

    /// Every reset of the path-length control the frames showed (mode
    /// hops): device time, and the record under way.
    pub fn hops(&self) -> &[(f64, Option<String>)] {
        &self.hops
    }

    /// What the status bits took from `labels`, in words for a figure's
    /// note (none when they took nothing and saw no mode hop).
    pub fn status_note(&self, labels: &[String]) -> Option<String> {
        let mut d = Dropped::default();
        for l in labels {
            if let Some(x) = self.dropped.get(l) {
                d.intervals += x.intervals;
                d.s += x.s;
                d.missing |= x.missing;
            }
        }
        let hops = self
            .hops
            .iter()
            .filter(|(_, r)| r.as_ref().is_some_and(|r| labels.contains(r)))
            .count();
        let mut said = Vec::new();
        if d.intervals > 0 {
            said.push(format!(
                "{:.0} s of its records left out, the unit not fit ({})",
                d.s,
                self.status_bits.unfit_words(!d.missing).join(", ")
            ));
        }
        if hops > 0 {
            said.push(format!(
                "{hops} mode hop{} (path-length control reset) during its records",
                if hops == 1 { "" } else { "s" }
            ));
        }
        (!said.is_empty()).then(|| said.join("; "))
    }

    /// File a reading of the supply; `record` is the record whose
    /// interval the same tick made (none for a tick without frames).
    pub fn push_power(&mut self, p: PowerSample, record: Option<&str>) {
        let i = self.power.push(p);
        if let Some(label) = record {
            let turn_on = self.last_off.map_or(0, |off| off + 1);
            self.power_of
                .entry(label.to_owned())
                .and_modify(|r| r.2 = i)
                .or_insert((turn_on, i, i));
        }
        if !p.on {
            self.last_off = Some(i);
        }
    }

    /// The supply readings taken during a record.
    pub fn power_during(&self, label: &str) -> Vec<PowerSample> {
        self.power_of
            .get(label)
            .map(|&(_, a, b)| self.power.get(a..b + 1))
            .unwrap_or_default()
    }

    /// The supply readings from the turn-on a record was made after to
    /// the record's end: back from its first reading to the last reading
    /// with the output off (or the run's first reading).
    pub fn power_from_turn_on(&self, label: &str) -> Vec<PowerSample> {
        self.power_of
            .get(label)
            .map(|&(from, _, b)| self.power.get(from..b + 1))
            .unwrap_or_default()
    }

    /// The health of a record of frames.
    pub fn health(&self, label: &str) -> Option<&RecordHealth> {
        self.health.get(label)
    }

    /// The gyro link's figures over a record, at its end.
    pub fn set_link(&mut self, label: &str, link: crate::protocol::frame::LinkStats) {
        if let Some(h) = self.health.get_mut(label) {
            h.link = Some(link);
        }
    }

    /// Why the data of `labels` cannot be judged, or none.
    pub fn problem(&self, labels: &[String]) -> Option<String> {
        labels.iter().find_map(|l| {
            self.health
                .get(l)
                .and_then(RecordHealth::problem)
                .map(|p| format!("record {l}: {p}"))
        })
    }

    /// Intervals of one record.
    pub fn get(&self, label: &str) -> Option<Vec<Interval>> {
        let ranges = self.by_label.get(label)?;
        let mut out = Vec::with_capacity(self.len_of(label).unwrap_or(0) as usize);
        for r in ranges {
            self.all.for_each(r.clone(), |(_, iv)| out.push(iv));
        }
        Some(out)
    }

    /// The number of intervals of one record.
    pub fn len_of(&self, label: &str) -> Option<u64> {
        let ranges = self.by_label.get(label)?;
        Some(ranges.iter().map(|r| r.end - r.start).sum())
    }

    /// Reads of the store's temporary files (the intervals' and the supply
    /// readings') that failed so far: what a figure or chart was made from
    /// is whole when [`ReadFaults::since`] the start of it says nothing.
    pub fn read_faults(&self) -> ReadFaults {
        ReadFaults([self.all.read_faults(), self.power.read_faults()])
    }

    /// Why the store keeps its rows in memory, once it does (its temporary
    /// file could not be made or written: nothing is lost).
    pub fn write_fault(&self) -> Option<String> {
        self.all.write_fault().or_else(|| self.power.write_fault())
    }

    /// The number of supply readings.
    pub fn power_len(&self) -> u64 {
        self.power.len()
    }

    /// Hand every supply reading to `f` in order (without holding them
    /// all in memory).
    pub fn for_each_power(&self, f: impl FnMut(PowerSample)) {
        self.power.for_each(0..self.power.len(), f);
    }

    /// Every interval of the run, and whether it belongs to a record.
    pub fn all(&self) -> Vec<(bool, Interval)> {
        self.all.all()
    }

    /// Hand every interval of the run to `f` in order, with whether it
    /// belongs to a record (without holding them all in memory).
    pub fn for_each_interval(&self, mut f: impl FnMut(bool, Interval)) {
        self.all.for_each(0..self.all.len(), |(rec, iv)| f(rec, iv));
    }

    /// The number of intervals of the run.
    pub fn intervals(&self) -> u64 {
        self.all.len()
    }

    /// Reduce a tick to its interval mean and file it; returns it.
    pub fn push_tick(
        &mut self,
        frames: &[super::FrameRecord],
        state: &BenchState,
        record: Option<&str>,
        frame_dt_s: f64,
        lsb_arcsec: f64,
        temp_lsb_c: f64,
    ) -> Option<Interval> {
        let mut sums = TickSums::default();
        for f in frames {
            sums.add(f.counts, f.temps_raw);
            sums.add_status(f.status, &self.status_bits);
        }
        let at = IntervalState {
            t_s: state.t_s,
            reference_dph: state.reference_dph,
            chamber_c: state.chamber.air_c,
            table_rates_dps: (state.table.rates.outer_deg, state.table.rates.inner_deg),
            table_angles: Some(state.table.angles),
            axis_gravity_g: -state.orientation.elevation_deg.to_radians().sin(),
        };
        self.push_sums(&sums, &at, record, frame_dt_s, lsb_arcsec, temp_lsb_c)
    }

    /// File the interval of a tick's frames (live or replayed) under
    /// `record`, and count them into its health; returns the interval.
    pub fn push_sums(
        &mut self,
        sums: &TickSums,
        at: &IntervalState,
        record: Option<&str>,
        frame_dt_s: f64,
        lsb_arcsec: f64,
        temp_lsb_c: f64,
    ) -> Option<Interval> {
        if let (Some(label), Some(extremes)) = (record, sums.extremes)
            && let Some(h) = self.health.get_mut(label)
        {
            h.add(sums.n, extremes, &sums.runs, frame_dt_s, lsb_arcsec);
        }
        self.count_hops(sums, at.t_s, record);
        let iv = sums.interval(at, frame_dt_s, lsb_arcsec, temp_lsb_c)?;
        // A frame the unit said it was not fit for spoils its interval:
        // the interval is kept in the run's series but not in its record.
        let filed = if sums.unfit > 0 {
            if let Some(label) = record {
                let d = self.dropped.entry(label.to_owned()).or_default();
                d.intervals += 1;
                d.s += sums.n as f64 * frame_dt_s;
                d.missing |= sums.unfit_missing;
                // Its counts are not the angle turned: the record's
                // revolutions start again after it.
                self.revolutions.remove(label);
            }
            None
        } else {
            record
        };
        if let Some(label) = filed {
            let t = self.turning.entry(label.to_owned()).or_default();
            t.0 += at.table_rates_dps.0;
            t.1 += at.table_rates_dps.1;
            t.2 += 1;
            let g = self.axis_gravity.entry(label.to_owned()).or_default();
            g.0 += at.axis_gravity_g;
            g.1 += 1;
        }
        self.count_revolutions(sums, at, filed, frame_dt_s, lsb_arcsec);
        self.push(iv, filed);
        Some(iv)
    }

    /// Count the path-length control's resets among a tick's frames: each
    /// fall from in lock to out of it, across ticks too, but not across a
    /// tick without frames (the unit off: its next lock is an acquisition).
    fn count_hops(&mut self, sums: &TickSums, t_s: f64, record: Option<&str>) {
        if sums.n == 0 {
            self.lock_last = None;
            return;
        }
        let across = self.lock_last == Some(true) && sums.lock_first == Some(false);
        for _ in 0..sums.lock_falls + u32::from(across) {
            self.hops.push((t_s, record.map(str::to_owned)));
        }
        if sums.lock_last.is_some() {
            self.lock_last = sums.lock_last;
        }
    }

    /// Add a tick that made an interval to its record's revolutions. A
    /// record starts from the table at the end of the tick before its
    /// first, when that tick made an interval too (its end is this one's
    /// start: the time between them is what this tick's frames span, to
    /// half of it); else from its first tick's end. The live run and
    /// replay file the same ticks with the same logged poses here, so the
    /// two agree bit for bit.
    fn count_revolutions(
        &mut self,
        sums: &TickSums,
        at: &IntervalState,
        record: Option<&str>,
        frame_dt_s: f64,
        lsb_arcsec: f64,
    ) {
        let pose = at.table_angles.map(|a| TablePose {
            t_s: at.t_s,
            angles_deg: [a.outer_deg, a.inner_deg],
            rates_dps: [at.table_rates_dps.0, at.table_rates_dps.1],
        });
        let before = self.last_pose.take();
        self.last_pose = pose;
        let (Some(label), Some(pose)) = (record, pose) else {
            return;
        };
        match self.revolutions.get_mut(label) {
            Some((r, _)) => r.add(pose, sums.counts, at.reference_dph),
            None => {
                let spans = sums.n as f64 * frame_dt_s;
                let start = before.filter(|b| {
                    let gap = pose.t_s - b.t_s;
                    gap > 0.0 && gap <= 1.5 * spans
                });
                let r = match start {
                    Some(b) => {
                        let mut r = Revolutions::new(b);
                        r.add(pose, sums.counts, at.reference_dph);
                        r
                    }
                    None => Revolutions::new(pose),
                };
                self.revolutions.insert(label.to_owned(), (r, lsb_arcsec));
            }
        }
    }

    /// A record's point of the rate transfer and how it was taken: in
    /// the angle domain, over the record's whole revolutions of the table
    /// ([`Revolutions`], `docs/figures.md`), when it holds one and the
    /// bench latches its table's angles on the unit's frames (its frames
    /// are made on the run's own clock: a record's `edge_s` of 0, the
    /// embedded bench); else its 1 Hz means as they are (counts over
    /// frames at the nominal frame period). None for a record without
    /// intervals.
    pub fn rate_point(&self, label: &str) -> Option<(RatePoint, Taken)> {
        let p = RatePoint::of(&self.get(label)?)?;
        if self.health.get(label).is_some_and(|h| h.edge_s > 0.0) {
            return Some((p, Taken::NotLatched));
        }
        Some(
            match self
                .revolutions
                .get(label)
                .and_then(|(r, lsb)| r.span(*lsb))
            {
                Some(span) => (p.over_revolutions(&span), Taken::Revolutions(span.turns)),
                None => (p, Taken::NoWholeTurn),
            },
        )
    }

    /// Mean gravity along the sensitive axis during a record, g (none for
    /// a record without frames).
    pub fn axis_gravity_g(&self, label: &str) -> Option<f64> {
        let &(sum, n) = self.axis_gravity.get(label)?;
        (n > 0).then(|| sum / n as f64)
    }

    /// Mean rate of the table axis that turned during a record, deg/s
    /// (the faster of the two; none for a record without frames).
    pub fn turn_rate_dps(&self, label: &str) -> Option<f64> {
        let &(outer, inner, n) = self.turning.get(label)?;
        if n == 0 {
            return None;
        }
        let (outer, inner) = (outer / n as f64, inner / n as f64);
        Some(if outer.abs() >= inner.abs() {
            outer
        } else {
            inner
        })
    }

    /// File an interval under `record` (and in the whole run).
    pub fn push(&mut self, iv: Interval, record: Option<&str>) {
        let i = self.all.push((record.is_some(), iv));
        if let Some(label) = record {
            let ranges = self.by_label.entry(label.to_owned()).or_default();
            match ranges.last_mut() {
                Some(r) if r.end == i => r.end += 1,
                _ => ranges.push(i..i + 1),
            }
        }
    }
}

/// How a record's point of the rate transfer was taken
/// ([`Records::rate_point`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Taken {
    /// In the angle domain, over this many whole revolutions.
    Revolutions(u32),
    /// Over time: the record holds no whole revolution of the table.
    NoWholeTurn,
    /// Over time: the bench's table angles are read on the host's clock,
    /// not latched on the unit's frames.
    NotLatched,
}

/// Integer sums of one tick's frames (exact, in any order).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TickSums {
    /// Frames.
    pub n: u64,
    /// Sum of delta-angle counts.
    pub counts: i64,
    /// Sums of the raw T1, T2, TK readings.
    pub temps: [i64; 3],
    /// Smallest and largest count (none without frames).
    pub extremes: Option<(i32, i32)>,
    /// Runs of identical consecutive counts.
    pub runs: Runs,
    /// Frames whose status said the unit was not fit.
    pub unfit: u64,
    /// The fitness bits those frames lacked (OR of all).
    pub unfit_missing: u16,
    /// Whether the path-length control was in lock at the tick's first
    /// and last frames (none: the unit does not report it).
    pub lock_first: Option<bool>,
    /// See `lock_first`.
    pub lock_last: Option<bool>,
    /// Falls of the lock between the tick's frames.
    pub lock_falls: u32,
}

/// The bench state an interval is stamped with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntervalState {
    /// Device time at the end of the tick, s.
    pub t_s: f64,
    /// Earth (+ table) rate on the axis, deg/h.
    pub reference_dph: f64,
    /// Chamber air, degC.
    pub chamber_c: f64,
    /// Table axis rates (outer, inner), deg/s.
    pub table_rates_dps: (f64, f64),
    /// Table axis angles, deg (none when the log does not know them).
    pub table_angles: Option<crate::geometry::TableAngles>,
    /// Gravity along the sensitive axis, g (minus the sine of its
    /// elevation: -1 axis up, 0 horizontal, 1 axis down; the twin's
    /// `g_sensitivity` convention).
    pub axis_gravity_g: f64,
}

impl TickSums {
    /// Add one frame.
    pub fn add(&mut self, counts: i32, temps_raw: [i16; 3]) {
        self.n += 1;
        self.counts += i64::from(counts);
        self.runs.push(counts);
        self.extremes = Some(self.extremes.map_or((counts, counts), |(lo, hi)| {
            (lo.min(counts), hi.max(counts))
        }));
        for (acc, r) in self.temps.iter_mut().zip(temps_raw) {
            *acc += i64::from(r);
        }
    }

    /// Add one frame's status word, read by `bits`.
    pub fn add_status(&mut self, status: u16, bits: &StatusBits) {
        if !bits.fit(status) {
            self.unfit += 1;
            self.unfit_missing |= bits.fit_mask & !status;
        }
        if let Some(locked) = bits.path_length_locked(status) {
            if self.lock_last == Some(true) && !locked {
                self.lock_falls += 1;
            }
            self.lock_first.get_or_insert(locked);
            self.lock_last = Some(locked);
        }
    }

    /// The interval mean these frames make (none without frames). The
    /// live run and replay both reduce ticks here, so they agree bit for bit.
    pub fn interval(
        &self,
        at: &IntervalState,
        frame_dt_s: f64,
        lsb_arcsec: f64,
        temp_lsb_c: f64,
    ) -> Option<Interval> {
        if self.n == 0 {
            return None;
        }
        let n = self.n as f64;
        let span = n * frame_dt_s;
        let temp = |i: usize| self.temps[i] as f64 / n * temp_lsb_c;
        Some(Interval {
            time_s: at.t_s - span / 2.0,
            rate_dph: self.counts as f64 * lsb_arcsec / span,
            reference_dph: at.reference_dph,
            t1_c: temp(0),
            t2_c: temp(1),
            tcase_c: temp(2),
            chamber_c: at.chamber_c,
            frames: u32::try_from(self.n).unwrap_or(u32::MAX),
        })
    }
}

/// Verdict of one measurement (the vocabulary crate's).
pub use gyrobench_model::outcome::MeasureOutcome;

/// What a run's figures are judged by: the procedure's decision rule and
/// the bench's declared Type B contributions.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Judging {
    /// The decision rule.
    pub rule: DecisionRule,
    /// The bench's own contributions (`[uncertainty]`).
    pub typeb: TypeB,
    /// A log of a format before decision rules (2 or older), replayed as it
    /// was judged: by its limits alone, the compensated drift on model 4
    /// fitted to its own records.
    pub legacy: bool,
}

impl Judging {
    /// The judging of `p` on `bench`, for a log of `format`.
    pub fn new(
        p: &crate::procedure::Procedure,
        bench: &crate::bench::BenchConfig,
        format: u32,
    ) -> Self {
        Self {
            rule: Self::rule_for(p, format),
            typeb: bench.uncertainty.clone(),
            legacy: format < crate::runlog::schema::FORMAT_JUDGED,
        }
    }

    /// The rule a run of `p` logged in `format` is judged by: the one it
    /// names, else the default; simple acceptance for a log written before
    /// decision rules, as it was judged then.
    pub fn rule_for(p: &crate::procedure::Procedure, format: u32) -> DecisionRule {
        if format < crate::runlog::schema::FORMAT_JUDGED && !p.meta.rule_named {
            DecisionRule::Simple
        } else {
            p.meta.decision_rule
        }
    }
}

/// Compute a measure on the records; `coeffs` compensate when given; the
/// value judged as `judging` says, with its uncertainty.
///
/// Figures over records of several parts of a resumed run (several
/// power-ons) give each part its own constant, as each has its own
/// turn-on bias: the compensation and sensitivity fits have one offset per
/// part, and drifts are smoothed within a part, never across the break.
/// For a run never resumed this is the single-part figure.
pub fn compute(
    m: &Measure,
    records: &Records,
    coeffs: Option<&crate::coeffs::Compensation>,
    step: &str,
    judging: &Judging,
) -> Measurement {
    let faults_before = records.read_faults();
    // The parts are slices of the one series (one copy in memory).
    // The figures that count from power-on take each interval's time
    // since the power-on before it; the rest, device time.
    let since_on = matches!(
        m.metric,
        Metric::SelfHeating | Metric::CompensatedDriftPp | Metric::CompensatedDriftFitResidualPp
    );
    let (series, lens, basis) = if since_on {
        let (s, l, b) = records.by_part_since_power_on(&m.records);
        (s, l, Some(b))
    } else {
        let (s, l) = records.by_part(&m.records);
        (s, l, None)
    };
    let part_refs = split_parts(&series, &lens);
    let bias: Vec<f64> = series.iter().map(Interval::bias_dph).collect();
    // Averages over device time: as many intervals as span it (1 s each
    // at a 1 Hz tick; longer where the host polls slower).
    let cadence = crate::analysis::study::cadence_s(&series);
    let window = crate::analysis::study::intervals_for(m.averaging_s, cadence);
    let c = match m.metric {
        Metric::ScaleFactor
        | Metric::ScaleFactorNonlinearity
        | Metric::ScaleFactorAsymmetry
        | Metric::ScaleFactorTemperature
        | Metric::DeadBand
        | Metric::Threshold
        | Metric::AxisMisalignment => rate_figure(m, records),
        Metric::BiasStability => Computed::value(Some(bias_stability(&bias, window))),
        Metric::DriftPp => drift(&part_refs, window),
        Metric::MeanBias => Computed::value(Some(mean(&bias))),
        Metric::BiasRepeatability => repeatability(m, records),
        Metric::WarmUpTime => warm_up(m, &series, &bias),
        Metric::PowerSteady | Metric::PowerPeak => power(m, records),
        Metric::GSensitivity | Metric::BiasSpread => positions(m, records),
        Metric::Arw | Metric::BiasInstability | Metric::RateRandomWalk => {
            noise_term(m, &bias, cadence)
        }
        Metric::SelfHeating => match self_heating(&series) {
            Ok(v) => Computed::value(Some(v.abs())),
            Err(why) => Computed {
                note: format!("not computable: {why}"),
                ..Computed::default()
            },
        },
        Metric::TemperatureSensitivity | Metric::TemperatureRateSensitivity => {
            sensitivity(m.metric, &part_refs)
        }
        Metric::CompensatedDriftPp if judging.legacy => {
            let mut c = drift_of(compensated_drift(
                coeffs,
                &part_refs,
                window,
                if coeffs.is_some() {
                    Residual::HeldOut
                } else {
                    Residual::InSample
                },
            ));
            if coeffs.is_none() {
                "model 4 fitted on these records (no --coeffs given)".clone_into(&mut c.note);
            }
            c
        }
        Metric::CompensatedDriftPp => drift_of(compensated_drift(
            coeffs,
            &part_refs,
            window,
            Residual::HeldOut,
        )),
        Metric::CompensatedDriftFitResidualPp => drift_of(compensated_drift(
            None,
            &part_refs,
            window,
            Residual::InSample,
        )),
    };
    let Computed {
        value,
        note,
        std_error,
        trace,
        known,
        noise_floor,
    } = c;
    let value = value.filter(|v| v.is_finite());
    let mut note = said_of(note, value, m, &series, basis, records);
    let uncertainty = match value {
        Some(v) => {
            super::uncertainty::of(m.metric, v, &series, m.averaging_s, &known, &judging.typeb)
        }
        None => Err(super::uncertainty::NoUncertainty::NoValue),
    };
    let (uncertainty, uncertainty_reason) = match uncertainty {
        Ok(u) => (Some(u), None),
        Err(why) => (None, Some(why.to_string())),
    };
    let judged = judge(
        m,
        value,
        uncertainty.as_ref(),
        judging,
        &mut note,
        uncertainty_reason.as_deref(),
    );
    // Rows this measure's reads could not get back: its data are not whole.
    let unread = records.read_faults().since(&faults_before);
    let outcome = match unread.or_else(|| records.problem(&m.records)) {
        Some(p) => {
            note = format!("not judged: {p}");
            MeasureOutcome::Error
        }
        None => judged.outcome,
    };
    Measurement {
        name: m.name.clone(),
        value,
        unit: m.unit.clone(),
        low: m.low,
        high: m.high,
        outcome,
        step: step.to_owned(),
        metric: m.metric,
        averaging_s: m.averaging_s,
        records: m.records.clone(),
        note,
        std_error,
        uncertainty,
        uncertainty_reason,
        guard_band: judged.guard_band,
        margin: judged.margin,
        margin_u: judged.margin_u,
        noise_floor,
        trace,
        band: m.band,
    }
}

/// `series` cut into consecutive parts of `lens` intervals (slices of
/// the one series: one copy in memory).
fn split_parts<'a>(series: &'a [Interval], lens: &[usize]) -> Vec<&'a [Interval]> {
    let mut rest = series;
    lens.iter()
        .map(|&n| {
            let (part, after) = rest.split_at(n.min(rest.len()));
            rest = after;
            part
        })
        .collect()
}

/// A figure's note with what else it rests on said: the power-on its
/// time counts from (a figure that counts from power-on), why it has no
/// value when its computation said nothing, and what the unit's status
/// bits took from its records.
fn said_of(
    note: String,
    value: Option<f64>,
    m: &Measure,
    series: &[Interval],
    basis: Option<PowerBasis>,
    records: &Records,
) -> String {
    let mut said: Vec<String> = Some(note).filter(|n| !n.is_empty()).into_iter().collect();
    if let Some(b) = basis
        && (value.is_some() || b.source == PowerOnSource::Assumed)
    {
        said.push(b.describe());
    }
    if value.is_none() && said.is_empty() {
        said.push(format!(
            "not computable: the records hold {:.0} s of data, too little for this figure{}",
            crate::analysis::study::covered_s(&series.iter().map(|i| i.time_s).collect::<Vec<_>>()),
            if m.averaging_s > 0.0 {
                format!(" over {} s averages", m.averaging_s)
            } else {
                String::new()
            }
        ));
    }
    said.extend(records.status_note(&m.records));
    said.join("; ")
}

/// A value judged: its outcome, the guard band applied, its margin.
struct Judged {
    outcome: MeasureOutcome,
    guard_band: Option<f64>,
    margin: Option<f64>,
    margin_u: Option<f64>,
}

/// Judge `value` against `m`'s limits by `judging`'s rule; a figure with
/// limits but no uncertainty is judged by its limits alone, and `note`
/// says so.
fn judge(
    m: &Measure,
    value: Option<f64>,
    u: Option<&Uncertainty>,
    judging: &Judging,
    note: &mut String,
    no_u: Option<&str>,
) -> Judged {
    let limited = m.low.is_some() || m.high.is_some();
    let expanded = u.map(|u| u.expanded);
    let Some(v) = value else {
        return Judged {
            outcome: MeasureOutcome::Fail,
            guard_band: None,
            margin: None,
            margin_u: None,
        };
    };
    if limited && expanded.is_none() && judging.rule != DecisionRule::Simple {
        let why = no_u.unwrap_or("its uncertainty could not be formed");
        let said = format!("judged by its limits alone (no guard band): {why}");
        if note.is_empty() {
            *note = said;
        } else {
            note.push_str("; ");
            note.push_str(&said);
        }
    }
    let margin = limited.then(|| {
        let lo = m.low.map_or(f64::INFINITY, |lo| v - lo);
        let hi = m.high.map_or(f64::INFINITY, |hi| hi - v);
        lo.min(hi)
    });
    Judged {
        outcome: MeasureOutcome::of(judging.rule.judge(v, m.low, m.high, expanded)),
        guard_band: expanded
            .filter(|_| limited)
            .and_then(|u| judging.rule.guard_band(u)),
        margin,
        margin_u: margin
            .zip(expanded.filter(|u| *u > 0.0))
            .map(|(m, u)| m / u),
    }
}

/// A compensated drift as a computed figure.
fn drift_of(d: super::compensated::Drift) -> Computed {
    Computed {
        value: d.value,
        note: d.note,
        std_error: None,
        trace: d.trace,
        known: Known {
            noise_series: Some(d.residual),
            ..Known::default()
        },
        noise_floor: d.noise_floor,
    }
}

/// The temperature or temperature-rate sensitivity, with its fit's
/// standard error.
fn sensitivity(metric: Metric, parts: &[&[Interval]]) -> Computed {
    let Some(f) = sensitivity_fit(parts) else {
        return Computed::default();
    };
    let (value, se) = if metric == Metric::TemperatureSensitivity {
        (f.a, f.se_a)
    } else {
        (f.b, f.se_b)
    };
    Computed {
        value: Some(value),
        known: Known {
            type_a: vec![Contribution::type_a(
                "fit: the coefficient's standard error",
                se,
                f.dof,
                "least squares with one constant per power-on; sigma^2 (X'X)^-1, \
                 inflated for the residual's lag-1 autocorrelation",
            )],
            ..Known::default()
        },
        ..Computed::default()
    }
}

/// A figure as computed, before it is judged.
#[derive(Debug, Default)]
struct Computed {
    value: Option<f64>,
    /// How it was obtained, or why it is missing.
    note: String,
    std_error: Option<f64>,
    trace: Option<DriftTrace>,
    /// What its uncertainty budget needs from the computation.
    known: Known,
    /// A compensated drift's noise floor, deg/h.
    noise_floor: Option<f64>,
}

impl Computed {
    fn value(value: Option<f64>) -> Self {
        Self {
            value,
            ..Self::default()
        }
    }

    /// A figure with its standard error (from `points` records, fitted
    /// with three coefficients or fewer), or why there is none.
    fn figure(f: Option<Figure>, what: &str, points: usize) -> Self {
        match f {
            Some(f) => Self {
                value: Some(f.value),
                std_error: f.std_error,
                known: Known {
                    type_a: f
                        .std_error
                        .map(|se| {
                            Contribution::type_a(
                                "fit: the figure's standard error",
                                se,
                                points.saturating_sub(3).max(1) as f64,
                                format!("{points} records, the fit's covariance"),
                            )
                        })
                        .into_iter()
                        .collect(),
                    ..Known::default()
                },
                ..Self::default()
            },
            None => Self {
                note: format!("not computable: {what}"),
                ..Self::default()
            },
        }
    }
}

/// The rate-table figures, on the named records' rate points: the
/// scale-factor figures on each record's point in the angle domain
/// ([`Records::rate_point`]), the others on its 1 Hz means.
fn rate_figure(m: &Measure, records: &Records) -> Computed {
    if matches!(
        m.metric,
        Metric::ScaleFactor
            | Metric::ScaleFactorNonlinearity
            | Metric::ScaleFactorAsymmetry
            | Metric::ScaleFactorTemperature
    ) {
        return scale_factor_figure(m, records);
    }
    let points: Vec<RatePoint> = m
        .records
        .iter()
        .filter_map(|l| records.get(l))
        .filter_map(|ivs| RatePoint::of(&ivs))
        .collect();
    let n = points.len();
    const SMALL: &str = "needs four or more records at small input rates";
    match m.metric {
        Metric::DeadBand => {
            Computed::figure(rate::band_dph(&points, rate::DEAD_BAND_SHARE), SMALL, n)
        }
        Metric::Threshold => {
            Computed::figure(rate::band_dph(&points, rate::THRESHOLD_SHARE), SMALL, n)
        }
        _ => {
            let turning: Vec<(f64, RatePoint)> = m
                .records
                .iter()
                .filter_map(|l| {
                    let p = RatePoint::of(&records.get(l)?)?;
                    Some((records.turn_rate_dps(l)? * 3600.0, p))
                })
                .collect();
            let n = turning.len();
            Computed::figure(
                rate::misalignment_arcsec(&turning),
                "needs three or more records of frames with a table axis turning both ways",
                n,
            )
        }
    }
}

/// The scale factor, its nonlinearity, asymmetry and temperature
/// coefficient on the records' points in the angle domain. A record that
/// holds no whole revolution of the table (a slow rate over a short
/// record) gives its 1 Hz means instead, and the note says how many did:
/// its point carries the unit's frame clock, and the budget then takes
/// the declared clock as before (`docs/figures.md`).
fn scale_factor_figure(m: &Measure, records: &Records) -> Computed {
    let taken: Vec<(RatePoint, Taken)> = m
        .records
        .iter()
        .filter_map(|l| records.rate_point(l))
        .collect();
    let points: Vec<RatePoint> = taken.iter().map(|(p, _)| *p).collect();
    let n = points.len();
    const RATES: &str =
        "needs rate records at three or more input rates (four when they turn both ways)";
    let mut c = match m.metric {
        Metric::ScaleFactorNonlinearity => {
            Computed::figure(rate::nonlinearity_ppm(&points), RATES, n)
        }
        Metric::ScaleFactorAsymmetry => Computed::figure(
            rate::asymmetry_ppm(&points),
            "needs rate records in both directions, four or more",
            n,
        ),
        Metric::ScaleFactorTemperature => Computed::figure(
            rate::temperature_coefficient_ppm_per_c(&points),
            "needs rate records at block temperatures at least 1 degC apart",
            n,
        ),
        _ => Computed::figure(rate::scale_factor_ppm(&points), RATES, n),
    };
    let count = |t: Taken| taken.iter().filter(|(_, k)| *k == t).count();
    let (short, polled) = (count(Taken::NoWholeTurn), count(Taken::NotLatched));
    const OVER_TIME: &str = "their 1 Hz means (counts over frames at the nominal frame period)";
    if c.value.is_some() {
        c.note = match (short, polled) {
            (0, 0) => String::new(),
            (0, _) => format!(
                "the bench reads its table on its own clock, not latched on the unit's frames: \
                 the points of the {n} records are {OVER_TIME}"
            ),
            (k, _) => format!(
                "{k} of {n} records held no whole revolution of the table: their points are {OVER_TIME}"
            ),
        };
    }
    let turns = |(_, k): &(RatePoint, Taken)| match k {
        Taken::Revolutions(n) => Some(*n),
        _ => None,
    };
    c.known.revolutions = if short + polled == 0 {
        taken.iter().filter_map(turns).min()
    } else {
        None
    };
    c
}

/// Peak-to-peak of the smoothed Earth-removed rate. The turn-on bias
/// differs between power-ons: over several parts each is shifted by its
/// offset from the first, as the model-4 fit with one offset per part
/// estimates it.
fn drift(parts: &[&[Interval]], window: usize) -> Computed {
    if parts.len() <= 1 {
        let series = parts.first().copied().unwrap_or_default();
        let bias = series.iter().map(Interval::bias_dph).collect();
        let trace = drift_trace(&[(times(series), bias)], window);
        return Computed {
            value: trace.as_ref().map(DriftTrace::pp),
            trace,
            ..Computed::default()
        };
    }
    match model::fit_runs(ModelKind::Model4, parts) {
        Ok(f) => {
            let shifted: Vec<(Vec<f64>, Vec<f64>)> = parts
                .iter()
                .zip(&f.offsets)
                .map(|(p, o)| {
                    (
                        times(p),
                        p.iter()
                            .map(|iv| iv.bias_dph() - (o - f.offsets[0]))
                            .collect(),
                    )
                })
                .collect();
            let trace = drift_trace(&shifted, window);
            Computed {
                value: trace.as_ref().map(DriftTrace::pp),
                note: format!(
                    "{} parts (power-ons) of a resumed run; turn-on offsets from the model-4 fit removed",
                    parts.len()
                ),
                trace,
                ..Computed::default()
            }
        }
        Err(e) => Computed {
            note: format!("cannot separate the parts' turn-on offsets: {e}"),
            ..Computed::default()
        },
    }
}

/// Bias repeatability: the spread of the records' mean biases, one
/// record per turn-on.
fn repeatability(m: &Measure, records: &Records) -> Computed {
    let means: Vec<f64> = m
        .records
        .iter()
        .filter_map(|l| records.get(l))
        .map(|r| mean(&r.iter().map(Interval::bias_dph).collect::<Vec<_>>()))
        .collect();
    let mut c = Computed::figure(
        crate::analysis::figures::repeatability(&means).map(|(value, e)| Figure {
            value,
            std_error: Some(e),
        }),
        "needs two or more records with data, one after each turn-on",
        means.len(),
    );
    if c.value.is_some() {
        c.note = format!("{} turn-ons", means.len());
        // A standard deviation of n turn-ons: n - 1 degrees of freedom.
        for line in &mut c.known.type_a {
            line.source = "the spread of the turn-ons' biases".into();
            line.dof = Some(means.len().saturating_sub(1).max(1) as f64);
            line.basis = format!("{} turn-ons: s / sqrt(2 (n - 1)) (GUM E.4.3)", means.len());
        }
    }
    c
}

/// Warm-up time over a record made from turn-on: its uncertainty is the
/// noise of an averaging window's mean over the transient's slope where
/// it settles (how far the crossing moves for one standard deviation of
/// the mean), plus the 1 s reading.
fn warm_up(m: &Measure, series: &[Interval], bias: &[f64]) -> Computed {
    let dt = match series {
        [a, b, ..] => b.time_s - a.time_s,
        _ => 1.0,
    };
    let window = (m.averaging_s / dt).round().max(1.0) as usize;
    let t = crate::analysis::figures::warm_up_time(bias, dt, window, m.band.unwrap_or(0.0));
    let mut type_a = Vec::new();
    if let (Some(t), Some((sigma, edf))) = (t, super::uncertainty::noise_of_means(bias, window)) {
        let smooth = crate::analysis::figures::moving_average(bias, window);
        // The moving mean ending at t: index t/dt - window.
        let at = ((t / dt).round() as usize).saturating_sub(window);
        let slope = match (
            smooth.get(at.saturating_sub(window / 2)),
            smooth.get(at + window / 2),
        ) {
            (Some(a), Some(b)) if window > 1 => (b - a) / (window as f64 * dt),
            _ => f64::NAN,
        };
        if slope.is_finite() && slope != 0.0 {
            type_a.push(Contribution::type_a(
                "noise of the mean where it settles, over the transient's slope",
                sigma / slope.abs(),
                edf,
                format!(
                    "{sigma:.5} deg/h ({} s means) / {:.3e} deg/h per s",
                    m.averaging_s,
                    slope.abs()
                ),
            ));
        }
        type_a.push(Contribution::type_a(
            "the 1 s reading",
            dt / 12f64.sqrt(),
            1e9,
            "a 1 s interval: 1/sqrt(12) s",
        ));
    }
    Computed {
        value: t,
        note: if t.is_none() {
            format!(
                "not computable: needs four averaging times ({} s) of data after turn-on, \
                 the last of them within {} of the settled value",
                4.0 * m.averaging_s,
                m.band.unwrap_or(0.0)
            )
        } else {
            String::new()
        },
        known: Known {
            type_a,
            ..Known::default()
        },
        ..Computed::default()
    }
}

/// A noise term of the Allan deviation of the records' Earth-removed rate
/// (IEEE Std 952 Annex C): the fitted term where the curve resolves it,
/// with its standard error (half the relative error of its coefficient);
/// where it does not, the term's upper bound from the curve itself (at no
/// averaging time may the term alone exceed the one-sigma upper bound of
/// the deviation there), said in the note: a figure judged on its bound
/// passes only when even the bound is inside the limit.
fn noise_term(m: &Measure, bias: &[f64], cadence_s: f64) -> Computed {
    use crate::analysis::allan::{Resolved, Taus, analyse, floor_per_b};
    let a = analyse(bias, cadence_s, Taus::Octave);
    if a.points.len() < 3 {
        return Computed {
            note: format!(
                "not computable: {:.0} s of data give {} averaging times; the noise terms need three or more",
                bias.len() as f64 * cadence_s,
                a.points.len()
            ),
            ..Computed::default()
        };
    }
    let (i, name) = match m.metric {
        Metric::Arw => (1, "angle random walk"),
        Metric::BiasInstability => (2, "bias instability"),
        _ => (3, "rate random walk"),
    };
    // The deviation one unit of the term gives at tau (s).
    let shape = |tau: f64| match i {
        1 => 60.0 / tau.sqrt(),
        2 => floor_per_b(),
        _ => (tau / (3.0 * 3600.0)).sqrt(),
    };
    let fitted = [
        a.noise.quantization_arcsec,
        a.noise.arw_deg_per_rt_h,
        a.noise.bias_instability_dph,
        a.noise.rate_random_walk_dph_per_rt_h,
    ][i];
    let dof = a.points.len().saturating_sub(4).max(1) as f64;
    match a.noise.resolved[i] {
        Resolved::Yes { z } if z > 0.0 => {
            let se = fitted / (2.0 * z);
            Computed {
                value: Some(fitted),
                std_error: Some(se),
                note: format!(
                    "{name} resolved by the Allan deviation, {z:.1} standard errors from zero"
                ),
                known: Known {
                    type_a: vec![Contribution::type_a(
                        "fit: the term's standard error",
                        se,
                        dof,
                        format!(
                            "{} averaging times, the weighted fit's covariance (IEEE Std 952 C)",
                            a.points.len()
                        ),
                    )],
                    ..Known::default()
                },
                ..Computed::default()
            }
        }
        r => {
            let (bound, tau) = a
                .points
                .iter()
                .map(|p| (p.hi / shape(p.tau_s), p.tau_s))
                .min_by(|x, y| x.0.total_cmp(&y.0))
                .unwrap_or((f64::NAN, 0.0));
            Computed {
                value: Some(bound),
                note: format!(
                    "{name} not resolved by this record ({}): judged on its upper bound, the one-sigma \
                     upper bound of the Allan deviation at {tau:.0} s taken as this term alone",
                    r.reason().unwrap_or_default()
                ),
                known: Known {
                    type_a: vec![Contribution::type_a(
                        "bound: the deviation's one-sigma upper bound already in the value",
                        0.0,
                        dof,
                        "an upper bound, not an estimate".to_owned(),
                    )],
                    ..Known::default()
                },
                ..Computed::default()
            }
        }
    }
}
/// The positions' figures: each record's mean Earth-removed rate, with
/// its standard error (100 s block means), against the gravity along the
/// axis in it; the g-sensitivity is their least-squares slope,
/// the spread their range.
fn positions(m: &Measure, records: &Records) -> Computed {
    let mut pts: Vec<(String, f64, f64, f64, usize)> = Vec::new();
    for label in &m.records {
        let (Some(series), Some(g)) = (records.get(label), records.axis_gravity_g(label)) else {
            continue;
        };
        let bias: Vec<f64> = series.iter().map(Interval::bias_dph).collect();
        let block = crate::analysis::study::intervals_for(
            100.0,
            crate::analysis::study::cadence_s(&series),
        );
        let blocks: Vec<f64> = bias.chunks_exact(block).map(mean).collect();
        if blocks.len() < 2 {
            continue;
        }
        let se = std_dev(&blocks) / (blocks.len() as f64).sqrt();
        pts.push((label.clone(), g, mean(&bias), se, blocks.len()));
    }
    let n = pts.len();
    if m.metric == Metric::GSensitivity {
        let gs: Vec<f64> = pts.iter().map(|p| p.1).collect();
        let gm = mean(&gs);
        let sxx: f64 = gs.iter().map(|g| (g - gm).powi(2)).sum();
        if n < 3 || sxx < 0.1 {
            return Computed {
                note: format!(
                    "not computable: needs three or more records of 200 s or more in positions \
                     whose axis sees different gravity (up, horizontal, tilted); {n} usable, \
                     the force on the axis spread {sxx:.2} g^2 about its mean"
                ),
                ..Computed::default()
            };
        }
        let bm = mean(&pts.iter().map(|p| p.2).collect::<Vec<_>>());
        let slope = pts.iter().map(|p| (p.1 - gm) * (p.2 - bm)).sum::<f64>() / sxx;
        let rss: f64 = pts
            .iter()
            .map(|p| (p.2 - bm - slope * (p.1 - gm)).powi(2))
            .sum();
        let se = (rss / (n - 2) as f64 / sxx).sqrt();
        return Computed {
            value: Some(slope),
            std_error: Some(se),
            known: Known {
                type_a: vec![Contribution::type_a(
                    "fit: the slope's standard error",
                    se,
                    (n - 2) as f64,
                    format!("{n} positions, the scatter about the line"),
                )],
                ..Known::default()
            },
            ..Computed::default()
        };
    }
    let lo = pts.iter().min_by(|a, b| a.2.total_cmp(&b.2));
    let hi = pts.iter().max_by(|a, b| a.2.total_cmp(&b.2));
    let (Some(lo), Some(hi)) = (lo, hi) else {
        return Computed {
            note: "not computable: needs two or more records of 200 s or more".to_owned(),
            ..Computed::default()
        };
    };
    if n < 2 {
        return Computed {
            note: format!("not computable: needs two or more records of 200 s or more; {n} usable"),
            ..Computed::default()
        };
    }
    let se = lo.3.hypot(hi.3);
    Computed {
        value: Some(hi.2 - lo.2),
        std_error: Some(se),
        note: format!("highest {}, lowest {}", hi.0, lo.0),
        known: Known {
            type_a: vec![Contribution::type_a(
                "noise of the two extreme positions' means",
                se,
                (lo.4.min(hi.4) as f64 - 1.0).max(1.0),
                "100 s block means of each: s / sqrt(n), in quadrature",
            )],
            ..Known::default()
        },
        ..Computed::default()
    }
}
/// Steady power (the mean of the readings during the records) or peak
/// power (the highest from each record's turn-on to its end).
fn power(m: &Measure, records: &Records) -> Computed {
    let readings: Vec<PowerSample> = m
        .records
        .iter()
        .flat_map(|l| {
            if m.metric == Metric::PowerPeak {
                records.power_from_turn_on(l)
            } else {
                records.power_during(l)
            }
        })
        .filter(|p| p.on)
        .collect();
    let watts: Vec<f64> = readings.iter().map(PowerSample::w).collect();
    let n = watts.len();
    let mut known = Known::default();
    let (value, note) = if readings.is_empty() {
        (
            None,
            "not computable: no supply readings with the output on during the records (a bench with [devices.supply])".to_owned(),
        )
    } else if m.metric == Metric::PowerPeak {
        let peak = readings
            .iter()
            .copied()
            .max_by(|a, b| a.w().total_cmp(&b.w()))
            .unwrap_or(readings[0]);
        known.supply = Some((peak.v, peak.a));
        (
            Some(peak.w()),
            format!("highest of {n} supply readings from turn-on"),
        )
    } else {
        known.supply = Some((
            mean(&readings.iter().map(|p| p.v).collect::<Vec<_>>()),
            mean(&readings.iter().map(|p| p.a).collect::<Vec<_>>()),
        ));
        if n >= 2 {
            known.type_a.push(Contribution::type_a(
                "the scatter of the readings",
                crate::analysis::figures::std_dev(&watts) / (n as f64).sqrt(),
                (n - 1) as f64,
                format!("{n} readings: s / sqrt(n)"),
            ));
        }
        (Some(mean(&watts)), format!("mean of {n} supply readings"))
    };
    Computed {
        value,
        note,
        known,
        ..Computed::default()
    }
}

fn times(series: &[Interval]) -> Vec<f64> {
    series.iter().map(|i| i.time_s).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::driver::{ChamberMode, ChamberReading, TableReading};
    use crate::geometry::{Orientation, TableAngles};
    use crate::sequencer::{FrameRecord, Tick};

    #[test]
    fn a_measurement_outcome_has_one_word_in_json_text_and_the_store() {
        for o in [
            MeasureOutcome::Pass,
            MeasureOutcome::Fail,
            MeasureOutcome::Error,
        ] {
            let json = serde_json::to_string(&o).expect("JSON");
            assert_eq!(json, format!("\"{}\"", o.as_str()));
            assert_eq!(serde_json::from_str::<MeasureOutcome>(&json).ok(), Some(o));
            assert_eq!(MeasureOutcome::parse(o.as_str()), Some(o));
        }
        assert_eq!(MeasureOutcome::parse("PASS"), None);
    }

    #[test]
    fn a_records_power_runs_from_the_turn_on_before_it_to_its_end() {
        let mut r = Records::default();
        let p = |t_s: f64, a: f64, on: bool| PowerSample {
            t_s,
            v: if on { 15.0 } else { 0.0 },
            a,
            on,
        };
        // A first turn-on, its record, off; a second turn-on and record.
        r.push_power(p(0.0, 1.0, true), None);
        r.push_power(p(1.0, 0.5, true), Some("a"));
        r.push_power(p(2.0, 0.0, false), None);
        r.push_power(p(3.0, 0.9, true), None);
        r.push_power(p(4.0, 0.6, true), None);
        r.push_power(p(5.0, 0.5, true), Some("b"));
        r.push_power(p(6.0, 0.5, true), Some("b"));
        let times = |s: Vec<PowerSample>| s.iter().map(|p| p.t_s).collect::<Vec<_>>();
        assert_eq!(times(r.power_during("b")), [5.0, 6.0]);
        assert_eq!(times(r.power_from_turn_on("b")), [3.0, 4.0, 5.0, 6.0]);
        assert_eq!(times(r.power_from_turn_on("a")), [0.0, 1.0]);
        assert!(r.power_during("c").is_empty());
        let m = |metric, records: &[&str]| Measure {
            name: "p".into(),
            metric,
            records: records.iter().map(|l| (*l).to_owned()).collect(),
            averaging_s: 0.0,
            band: None,
            low: None,
            high: Some(100.0),
            unit: "W".into(),
        };
        let steady = compute(
            &m(Metric::PowerSteady, &["b"]),
            &r,
            None,
            "s",
            &Judging::default(),
        );
        assert_eq!(steady.value, Some(7.5));
        let peak = compute(
            &m(Metric::PowerPeak, &["a", "b"]),
            &r,
            None,
            "s",
            &Judging::default(),
        );
        assert_eq!(peak.value, Some(15.0));
        let none = compute(
            &m(Metric::PowerPeak, &["c"]),
            &r,
            None,
            "s",
            &Judging::default(),
        );
        assert_eq!((none.value, none.outcome), (None, MeasureOutcome::Fail));
    }

    #[test]
    fn a_tick_becomes_one_interval_of_means_and_is_filed_under_its_record() {
        let frames: Vec<FrameRecord> = (0..400)
            .map(|i| FrameRecord {
                seq: (i % 256) as u8,
                counts: if i % 2 == 0 { 1 } else { 2 },
                temps_raw: [if i % 2 == 0 { 2000 } else { 2100 }, 1900, 1800],
                status: 0x000F,
            })
            .collect();
        let tick = Tick {
            t0_s: 10.0025,
            frames,
            state: None,
            slots: Vec::new(),
        };
        let state = BenchState {
            t_s: 11.0,
            chamber: ChamberReading {
                air_c: 17.0,
                set_point_c: 17.0,
                mode: ChamberMode::Constant,
                alarms: Vec::new(),
            },
            table: TableReading {
                angles: TableAngles::default(),
                rates: TableAngles::default(),
            },
            commanded: TableAngles::default(),
            orientation: Orientation::new(0.0, 90.0, 0.0),
            reference_dph: 10.0,
            in_position: true,
            power: None,
        };
        let mut r = Records::default();
        r.start("up");
        let iv = r
            .push_tick(&tick.frames, &state, Some("up"), 1.0 / 400.0, 0.1, 0.01)
            .expect("an interval");
        // 600 counts of 0.1 arcsec in 1 s = 60 arcsec/s = 60 deg/h.
        assert!((iv.rate_dph - 60.0).abs() < 1e-9, "{iv:?}");
        assert!((iv.bias_dph() - 50.0).abs() < 1e-9);
        assert!((iv.t1_c - 20.5).abs() < 1e-12 && (iv.tcase_c - 18.0).abs() < 1e-12);
        assert!((iv.time_s - 10.5).abs() < 1e-9);
        assert_eq!(iv.frames, 400);
        assert_eq!(r.len_of("up"), Some(1));
        assert!(r.push_tick(&[], &state, None, 0.0025, 0.1, 0.01).is_none());
        assert_eq!(r.all.len(), 1);
    }

    /// A tick with a frame the unit said it was not fit for is kept in the
    /// run but not in its record; the path-length control's falls are
    /// counted within and across ticks, not across a tick without frames
    /// (the unit off: its next lock is an acquisition).
    #[test]
    fn unfit_ticks_are_left_out_and_lock_falls_counted() {
        let tick = |statuses: &[u16]| -> Vec<FrameRecord> {
            statuses
                .iter()
                .map(|&status| FrameRecord {
                    counts: 4,
                    status,
                    ..FrameRecord::default()
                })
                .collect()
        };
        let state = |t_s: f64| BenchState {
            t_s,
            chamber: ChamberReading {
                air_c: 20.0,
                set_point_c: 20.0,
                mode: ChamberMode::Constant,
                alarms: Vec::new(),
            },
            table: TableReading {
                angles: TableAngles::default(),
                rates: TableAngles::default(),
            },
            commanded: TableAngles::default(),
            orientation: Orientation::new(0.0, 90.0, 0.0),
            reference_dph: 10.0,
            in_position: true,
            power: None,
        };
        let (ok, unlocked, dark) = (0x000F, 0x000B, 0x000E);
        let mut r = Records::default();
        r.start("soak");
        let push = |r: &mut Records, t: f64, f: &[u16]| {
            r.push_tick(&tick(f), &state(t), Some("soak"), 0.25, 0.1, 0.01)
        };
        push(&mut r, 1.0, &[ok, ok, ok, ok]);
        // A fall within the tick, and the tick left out.
        push(&mut r, 2.0, &[ok, unlocked, unlocked, ok]);
        // A fall across ticks: the last frame locked, the next not.
        push(&mut r, 3.0, &[ok, ok, ok, ok]);
        push(&mut r, 4.0, &[unlocked, ok, ok, ok]);
        // Not lasing: left out, no fall.
        push(&mut r, 5.0, &[dark, ok, ok, ok]);
        // The unit off (a tick without frames), then acquiring its lock.
        push(&mut r, 6.0, &[]);
        push(&mut r, 7.0, &[unlocked, unlocked, ok, ok]);
        push(&mut r, 8.0, &[ok, ok, ok, ok]);
        assert_eq!(r.len_of("soak"), Some(3), "only the fit ticks are filed");
        assert_eq!(r.intervals(), 7, "the run keeps every tick with frames");
        let d = r.dropped()["soak"];
        assert_eq!(d.intervals, 4);
        assert!((d.s - 4.0).abs() < 1e-12, "{d:?}");
        assert_eq!(r.hops().len(), 2, "{:?}", r.hops());
        let note = r.status_note(&["soak".into()]).expect("a note");
        assert!(
            note.contains("4 s") && note.contains("out of lock") && note.contains("not lasing"),
            "{note}"
        );
        assert!(note.contains("2 mode hops"), "{note}");
        // A unit whose status word says nothing: every tick is used.
        let mut quiet = Records::default();
        quiet.set_status_bits(crate::protocol::frame::StatusBits {
            fit_mask: 0,
            path_length_lock_bit: None,
        });
        quiet.start("soak");
        push(&mut quiet, 1.0, &[0, 0, 0, 0]);
        assert_eq!(quiet.len_of("soak"), Some(1));
        assert!(quiet.status_note(&["soak".into()]).is_none());
    }

    /// A record longer than the store keeps in memory, a resumed run's
    /// copy that discards and records again, and the two read back as
    /// they were filed.
    #[test]
    fn records_longer_than_memory_holds_read_back_as_filed_in_each_copy() {
        let iv = |t: f64| Interval {
            time_s: t,
            rate_dph: 15.0 + t * 1e-6,
            reference_dph: 9.7,
            t1_c: 20.0 + t * 1e-4,
            t2_c: 20.5,
            tcase_c: 21.0,
            chamber_c: -40.0,
            frames: 400,
        };
        let mut r = Records::default();
        r.start("soak");
        let n = 10_000;
        for k in 0..n {
            r.push(iv(f64::from(k)), Some("soak"));
        }
        r.push(iv(-1.0), None);
        r.start("after");
        r.push(iv(1e6), Some("after"));
        let soak = r.get("soak").expect("filed");
        assert_eq!(soak.len(), 10_000);
        assert!(soak.iter().enumerate().all(|(k, v)| *v == iv(k as f64)));
        assert_eq!(r.len_of("soak"), Some(10_000));
        assert_eq!(r.intervals(), 10_002);
        let mut seen = 0;
        r.for_each_interval(|rec, v| {
            assert_eq!(rec, v.time_s >= 0.0, "interval {seen}");
            seen += 1;
        });
        assert_eq!(seen, 10_002);

        // A resume: the copy takes "after" again in part 2.
        let mut resumed = r.clone();
        resumed.discard("after");
        resumed.set_part(2);
        resumed.start("after");
        resumed.push(iv(2e6), Some("after"));
        r.push(iv(3e6), Some("after"));
        assert_eq!(resumed.get("after"), Some(vec![iv(2e6)]));
        assert_eq!(r.get("after"), Some(vec![iv(1e6), iv(3e6)]));
        let (series, lens) = resumed.by_part(&["soak".into(), "after".into()]);
        assert_eq!(lens, [10_000, 1]);
        assert_eq!(series.last(), Some(&iv(2e6)));
        assert_eq!(resumed.get("soak"), Some(soak));
        assert!(resumed.problem(&["soak".into()]).is_none());
    }

    /// Rows the temporary file cannot give back make the measure that read
    /// them an error, not a figure on part of its record; a measure whose
    /// rows were all in memory is judged as before.
    #[test]
    fn a_measure_whose_rows_cannot_be_read_back_is_not_judged() {
        let mut r = Records::default();
        r.start("long");
        for k in 0..5000 {
            let iv = Interval {
                time_s: f64::from(k),
                rate_dph: 10.0 + f64::from(k % 7) * 0.01,
                reference_dph: 9.7,
                t1_c: 20.0,
                t2_c: 20.0,
                tcase_c: 20.0,
                chamber_c: 20.0,
                frames: 400,
            };
            r.push(iv, Some("long"));
        }
        r.start("short");
        r.push(Interval::default(), Some("short"));
        let m = |label: &str| Measure {
            name: "bias".into(),
            metric: Metric::MeanBias,
            records: vec![label.to_owned()],
            averaging_s: 1.0,
            band: None,
            low: None,
            high: Some(100.0),
            unit: "deg/h".into(),
        };
        assert_eq!(
            compute(&m("long"), &r, None, "s", &Judging::default()).outcome,
            MeasureOutcome::Pass
        );
        r.all.lose_file();
        let lost = compute(&m("long"), &r, None, "s", &Judging::default());
        assert_eq!(lost.outcome, MeasureOutcome::Error, "{}", lost.note);
        assert!(
            lost.note.contains("could not be read back"),
            "{}",
            lost.note
        );
        // The short record sits in the memory tail: still judged.
        let short = compute(&m("short"), &r, None, "s", &Judging::default());
        assert_eq!(short.outcome, MeasureOutcome::Pass, "{}", short.note);
    }
}
