//! A lot's diagnosis (`docs/diagnosis.md`, "Lots"): the runs of several
//! units of one type at one site (a batch's, or units run one after
//! another on the same bench), each unit diagnosed alone, then all of them
//! fitted together and scored held out (blocked cross-validation over
//! every unit's records): which effects the lot shares (one set of
//! parameters for every unit that shows it: the bench's, with the part of
//! the bench it likely sits in), which are each unit's own, which unit is
//! unlike the others, and how far the lot's gap shrinks once the shared
//! effects go to the bench and the own ones to the units.
//!
//! - `weigh`: shared or own, effect by effect, and the effects only the
//!   lot's pooled runs show;
//! - `evidence`: what makes a unit the outlier, and each shared effect's
//!   seat;
//! - `act`: the bench's correction and each unit's twin.

mod act;
mod evidence;
mod weigh;

use std::collections::BTreeMap;

use serde::Serialize;

use crate::data::RunData;
use crate::engine::{AVERAGING_S, Data, Scored, score};
use crate::geometry::Site;
use crate::library::{Effect, Param, Term, Units};
use crate::{
    Accepted, Confounded, Diagnosis, FittedEffect, Inconclusive, Options, THRESHOLDS, Thresholds,
    diagnose,
};
pub use evidence::{Evidence, seat};

/// One unit of a lot: its serial, type, slot and runs.
#[derive(Debug, Clone)]
pub struct LotUnit {
    /// Serial number.
    pub serial: String,
    /// Unit type (every unit of a lot has the same).
    pub dut_type: String,
    /// Its slot on a batch's fixture (empty: a bench of one unit).
    pub slot: String,
    /// Its runs.
    pub runs: Vec<RunData>,
}

/// Why a set of units is not a lot.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LotError {
    /// Fewer than two units.
    #[error(
        "a lot diagnosis needs the runs of two or more units, and these hold {units}: diagnose one unit's runs without --lot"
    )]
    TooFew {
        /// Units given.
        units: usize,
    },
    /// More units than a term's unit set holds.
    #[error(
        "a lot diagnosis takes at most {max} units, and these hold {units}: diagnose them as several lots"
    )]
    TooMany {
        /// Units given.
        units: usize,
        /// The most a lot takes.
        max: usize,
    },
    /// One serial twice.
    #[error("unit {serial} is given twice: give each unit once, with all its runs")]
    Twice {
        /// The serial.
        serial: String,
    },
    /// A unit without runs.
    #[error("unit {serial} has no run to diagnose")]
    NoRuns {
        /// The serial.
        serial: String,
    },
    /// Units of several types.
    #[error(
        "the units are of {} types ({}): a lot is of one type (an effect the units share is the bench's only when they are alike); diagnose each type's units as a lot of their own",
        types.len(),
        types.join("; ")
    )]
    SeveralTypes {
        /// Each type with its serials, `TYPE: A, B`.
        types: Vec<String>,
    },
    /// Runs made at several sites.
    #[error(
        "the runs were made at {} sites ({}): a lot shares one bench, and an effect the units share means nothing across sites (their Earth rate, gravity and field differ); diagnose each site's units as a lot of their own, or correct the site in the runs that state it wrong",
        sites.len(),
        sites.join("; ")
    )]
    SeveralSites {
        /// Each site with the runs made there.
        sites: Vec<String>,
    },
}

/// The lot's own decision bars, beside the selection's [`Thresholds`]
/// (`lot.json` carries both).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LotThresholds {
    /// The units' parameters of an effect agree when letting each unit
    /// have its own does not improve on one shared set at this level (a
    /// nested F-test on the held-out folds' in-sample residuals, as the
    /// selection's; not corrected for the effects weighed: the test that
    /// must see a difference is kept sensitive).
    pub agree_alpha: f64,
    /// A unit's gap is unlike the lot's when, with the shared effects
    /// given to the bench, it stands this many times above the noise of
    /// its 60 s means and what it holds beyond that noise (deg/h) stands
    /// this many times above the median of the other units' (ours: the
    /// factor the single-unit headline calls "at the noise"; measured on
    /// null lots by the lot self-check).
    pub outlier_gap_ratio: f64,
    /// Runs whose sites differ by more than this in latitude or longitude,
    /// deg, are at different sites (ours: about 1 km).
    pub site_deg: f64,
    /// ... or by more than this in height, m.
    pub site_height_m: f64,
    /// ... or by more than this in any component of the magnetic field, uT.
    pub site_field_ut: f64,
}

/// The lot's bars.
pub const LOT_THRESHOLDS: LotThresholds = LotThresholds {
    agree_alpha: 0.05,
    outlier_gap_ratio: 1.5,
    site_deg: 0.01,
    site_height_m: 100.0,
    site_field_ut: 1.0,
};

/// The lot's held-out rate gap, deg/h: with each unit's reference alone,
/// with the shared effects given to the bench, and with each unit's own
/// effects given to it as well.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct LotGap {
    /// Each unit's reference alone.
    pub gap_dph: f64,
    /// The shared effects added (the bench's).
    pub after_shared_dph: f64,
    /// The units' own effects added too (and the disturbances outside the
    /// library each unit's diagnosis held).
    pub after_dph: f64,
    /// 1 - after_shared / gap.
    pub shrink_shared: f64,
    /// 1 - after / gap.
    pub shrink: f64,
}

/// An effect the lot shares.
#[derive(Debug, Clone, Serialize)]
pub struct SharedEffect {
    /// Library name.
    pub name: String,
    /// One set for every unit in `units` (coefficients and the nonlinear
    /// parameter), fitted on all their runs together.
    pub parameters: BTreeMap<String, f64>,
    /// Standard errors of the coefficients.
    pub uncertainties: BTreeMap<String, f64>,
    /// The temperature a memory effect acts on (`case`, `block`, `mean`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temperature: Option<String>,
    /// The serials it holds for.
    pub units: Vec<String>,
    /// Where it likely sits: `fixture`, `table`, `site` or `type`.
    pub seat: String,
    /// Why there, and what would tell.
    pub seat_why: String,
    /// The lot's held-out gap without it and with it, deg/h.
    pub held_out_gap_before_dph: f64,
    /// With it.
    pub held_out_gap_after_dph: f64,
    /// 1 - after / before.
    pub shrink: f64,
    /// p-value of the shared term over the lot's model without it.
    pub p_value: f64,
    /// p-value of each unit having its own parameters over one shared set
    /// (the units agree when it is at or over `agree_alpha`).
    pub agreement_p: f64,
    /// Serials whose own diagnosis named it (none: the pooled runs alone
    /// show it).
    pub named_alone_in: Vec<String>,
    /// Each unit's own parameters at the shared nonlinear parameter
    /// (fitted with one set per unit), for the comparison.
    pub per_unit: Vec<UnitValue>,
    /// The shared effect as fitted, typed (what `parameters` reads, and
    /// what the bench's correction and the units' twins are built from).
    #[serde(skip)]
    pub fitted: Option<FittedEffect>,
}

/// One unit's parameters of an effect, fitted with one set per unit.
#[derive(Debug, Clone, Serialize)]
pub struct UnitValue {
    /// Serial.
    pub serial: String,
    /// Coefficients.
    pub parameters: BTreeMap<String, f64>,
    /// Their standard errors.
    pub uncertainties: BTreeMap<String, f64>,
}

/// One unit of the lot's result.
#[derive(Debug, Clone, Serialize)]
pub struct UnitResult {
    /// Serial.
    pub serial: String,
    /// Its slot (empty: a bench of one unit).
    pub slot: String,
    /// Its runs.
    pub runs: Vec<String>,
    /// Its own effects (those the lot does not share with it), as its
    /// `diagnosis.json` lists them.
    pub effects: Vec<Accepted>,
    /// Unlike the lot (`evidence` says why).
    pub outlier: bool,
    /// What sets it apart from the lot (also when it is not flagged: a
    /// lot too small, or too many units apart, to name one).
    pub evidence: Vec<Evidence>,
    /// Its held-out rate gap in the lot's fits, deg/h: its reference
    /// alone, with the shared effects, with its own effects as well.
    pub gap_dph: f64,
    /// With the shared effects.
    pub gap_after_shared_dph: f64,
    /// With its own as well.
    pub gap_after_dph: f64,
    /// The noise of its residual's 60 s means (its Allan deviation at
    /// 60 s), deg/h: the gap no model gets under.
    pub noise_dph: f64,
    /// Its thermal layer's held-out gap, degC, and the sensors' floor.
    pub thermal_gap_c: f64,
    /// The floor.
    pub thermal_noise_floor_c: f64,
    /// Pairs its own runs cannot tell apart.
    pub confounded: Vec<Confounded>,
    /// Its own diagnosis's inconclusive step (the run that would decide is
    /// in its directory).
    pub inconclusive: Option<Inconclusive>,
}

/// An effect weighed for the lot, and the decision.
#[derive(Debug, Clone, Serialize)]
pub struct Considered {
    /// Library name.
    pub name: String,
    /// `shared` (by every unit), `shared_by_some` (all but one),
    /// `own` (each unit that named it), `explained_by_bench` (every unit
    /// that named it holds no more of it once the bench's Earth-rate
    /// error, or the effects the lot shares, are given to the bench), or
    /// `not_in_lot`.
    pub decision: String,
    /// Serials whose own diagnosis named it.
    pub named_alone_in: Vec<String>,
    /// Of those, the serials where it adds nothing once the bench's
    /// Earth-rate error or the lot's shared effects are the bench's (it
    /// is not theirs: left out of their `effects`).
    pub explained_by_bench_in: Vec<String>,
    /// p-value of one shared set over the lot's model without it.
    pub p_value: f64,
    /// Share of the lot's held-out sum of squares one shared set removes.
    pub improvement: f64,
    /// p-value of one set per unit over one shared set.
    pub agreement_p: f64,
    /// Held-out sum of squares of one shared set over that of one set per
    /// unit (at most 1 + `tie`: not worse held out).
    pub shared_over_own: f64,
}

/// `lot.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Lot {
    /// The units' type.
    pub dut_type: String,
    /// Where every run was made.
    pub site: Site,
    /// How the held-out figures were made.
    pub protocol: String,
    /// The selection's bars (each unit's and the pooled candidates').
    pub thresholds: Thresholds,
    /// The lot's own bars.
    pub lot_thresholds: LotThresholds,
    /// What a lot of this size can and cannot tell.
    pub lot_size: String,
    /// The lot's held-out rate gap and how far it shrinks.
    pub gap: LotGap,
    /// Effects the lot shares, strongest first.
    pub shared_effects: Vec<SharedEffect>,
    /// Every unit.
    pub units: Vec<UnitResult>,
    /// Serials flagged as unlike the lot.
    pub outliers: Vec<String>,
    /// Why none is flagged, when units differ but no outlier can be named.
    pub no_outlier_because: Option<String>,
    /// Every effect weighed.
    pub considered: Vec<Considered>,
    /// The pooled runs' best candidate when it improves the lot's gap but
    /// misses a bar (the deciding run: run it as a batch of these units).
    pub inconclusive: Option<Inconclusive>,
    /// The deciding run as a procedure file.
    #[serde(skip)]
    pub deciding_procedure: Option<String>,
    /// Each unit's own diagnosis, in the units' order (for its files).
    #[serde(skip)]
    pub diagnoses: Vec<Diagnosis>,
}

/// The units' type and site, or why they are not a lot.
fn check(units: &[LotUnit]) -> Result<(String, Site), LotError> {
    if units.len() < 2 {
        return Err(LotError::TooFew { units: units.len() });
    }
    if units.len() > Units::MAX {
        return Err(LotError::TooMany {
            units: units.len(),
            max: Units::MAX,
        });
    }
    for (k, u) in units.iter().enumerate() {
        if units[..k].iter().any(|v| v.serial == u.serial) {
            return Err(LotError::Twice {
                serial: u.serial.clone(),
            });
        }
        if u.runs.is_empty() {
            return Err(LotError::NoRuns {
                serial: u.serial.clone(),
            });
        }
    }
    let mut types: Vec<(String, Vec<&str>)> = Vec::new();
    for u in units {
        match types.iter_mut().find(|(t, _)| *t == u.dut_type) {
            Some((_, serials)) => serials.push(&u.serial),
            None => types.push((u.dut_type.clone(), vec![&u.serial])),
        }
    }
    if types.len() > 1 {
        return Err(LotError::SeveralTypes {
            types: types
                .iter()
                .map(|(t, s)| format!("{t}: {}", s.join(", ")))
                .collect(),
        });
    }
    let mut sites: Vec<(Site, Vec<String>)> = Vec::new();
    for u in units {
        for r in &u.runs {
            let at = format!("{} of {}", r.name, u.serial);
            match sites.iter_mut().find(|(s, _)| same_site(s, &r.site)) {
                Some((_, runs)) => runs.push(at),
                None => sites.push((r.site, vec![at])),
            }
        }
    }
    if sites.len() > 1 {
        return Err(LotError::SeveralSites {
            sites: sites
                .iter()
                .map(|(s, runs)| {
                    format!(
                        "latitude {:.4} deg, longitude {:.4} deg, {:.0} m, field [{:.1}, {:.1}, {:.1}] uT: {}",
                        s.latitude_deg,
                        s.longitude_deg,
                        s.height_m,
                        s.magnetic_field_ned_ut[0],
                        s.magnetic_field_ned_ut[1],
                        s.magnetic_field_ned_ut[2],
                        runs.join(", ")
                    )
                })
                .collect(),
        });
    }
    let site = sites.first().map_or(units[0].runs[0].site, |s| s.0);
    Ok((types.swap_remove(0).0, site))
}

/// Whether two sites are one, within [`LOT_THRESHOLDS`].
fn same_site(a: &Site, b: &Site) -> bool {
    let t = LOT_THRESHOLDS;
    (a.latitude_deg - b.latitude_deg).abs() <= t.site_deg
        && (a.longitude_deg - b.longitude_deg).abs() <= t.site_deg
        && (a.height_m - b.height_m).abs() <= t.site_height_m
        && a.magnetic_field_ned_ut
            .iter()
            .zip(&b.magnetic_field_ned_ut)
            .all(|(x, y)| (x - y).abs() <= t.site_field_ut)
}

/// The lot's runs stacked, unit after unit, as the engine fits them.
pub(crate) struct Stack<'a> {
    /// Every run, each of one unit.
    pub data: Data<'a>,
    /// Units.
    pub units: usize,
    /// Per unit: its first row and first run in the stack.
    first_row: Vec<usize>,
    first_run: Vec<usize>,
}

impl<'a> Stack<'a> {
    /// `runs` with the unit of each.
    fn new(runs: &'a [RunData], unit_of_run: Vec<usize>) -> Option<Self> {
        let units = unit_of_run.iter().max().map_or(0, |u| u + 1);
        let (mut first_row, mut first_run) = (vec![0; units], vec![0; units]);
        let mut row = 0;
        let mut seen = vec![false; units];
        for (r, (run, &u)) in runs.iter().zip(&unit_of_run).enumerate() {
            if !seen[u] {
                seen[u] = true;
                first_row[u] = row;
                first_run[u] = r;
            }
            row += run.samples.len();
        }
        let data = Data::new(runs).with_units(unit_of_run)?;
        Some(Self {
            data,
            units,
            first_row,
            first_run,
        })
    }

    /// Unit `u`'s model (from its own diagnosis) as terms of the lot: in
    /// `u` alone, a disturbance's row or run moved to `u`'s place.
    pub fn own_terms(&self, u: usize, model: &[Term]) -> Vec<Term> {
        let (row0, run0) = (self.first_row[u], self.first_run[u]);
        model
            .iter()
            .map(|t| {
                let param = match t.param {
                    Param::Row(k) => Param::Row(k + row0),
                    Param::Run(r) => Param::Run(r + run0),
                    Param::Periodic { run, period_s } => Param::Periodic {
                        run: run + run0,
                        period_s,
                    },
                    p => p,
                };
                Term::in_units(t.effect, param, Units::one(u))
            })
            .collect()
    }

    /// The unit of fold `k`.
    fn unit_of_fold(&self, k: usize) -> usize {
        self.data
            .folds
            .get(k)
            .and_then(|f| self.data.unit_of_run.get(f.run))
            .copied()
            .unwrap_or(0)
    }

    /// The held-out sum of squares of the folds of `units` in `s`.
    pub fn units_sse(&self, s: &Scored, units: Units) -> f64 {
        (0..s.fold_sse.len())
            .filter(|&k| units.holds(self.unit_of_fold(k)))
            .map(|k| s.fold_sse[k])
            .sum()
    }

    /// Unit `u`'s held-out gap in `s` (RMS of its folds' held-out 60 s
    /// means), deg/h.
    pub fn unit_gap(&self, s: &Scored, u: usize) -> f64 {
        let (mut sse, mut n) = (0.0, 0);
        for k in 0..s.fold_sse.len() {
            if self.unit_of_fold(k) == u {
                sse += s.fold_sse[k];
                n += s.fold_blocks[k];
            }
        }
        (sse / n.max(1) as f64).sqrt()
    }

    /// The noise of unit `u`'s 60 s means in `s`'s in-sample residual:
    /// its Allan deviation at 60 s, over its runs, deg/h.
    fn unit_noise(&self, s: &Scored, u: usize) -> f64 {
        let (mut ss, mut w) = (0.0, 0.0);
        let mut at = 0;
        for (r, run) in self.data.runs.iter().enumerate() {
            let n = run.samples.len();
            if self.data.unit_of_run[r] == u {
                let dev =
                    crate::analysis::allan::oadev(&s.residual[at..at + n], 1.0, &[AVERAGING_S]);
                if let Some(&(_, a)) = dev.first() {
                    ss += a * a * n as f64;
                    w += n as f64;
                }
            }
            at += n;
        }
        if w > 0.0 { (ss / w).sqrt() } else { f64::NAN }
    }
}

/// Each unit's own diagnosis, two units at a time (a diagnosis runs its
/// thermal layer beside its rate layer already).
fn diagnose_each(runs: &[RunData], spans: &[(usize, usize)], opts: &Options) -> Vec<Diagnosis> {
    gyrobench_analysis::par::two_at_a_time(spans, |_, &(a, b)| diagnose(&runs[a..b], opts))
}

/// What a lot of `n` units can and cannot tell.
fn lot_size(n: usize) -> String {
    match n {
        2 => "A lot of two: an effect both units show with parameters that agree is shared (the bench's); when the two differ, which of them is unlike the lot cannot be told, so no outlier is named, only what differs.".into(),
        3 => "A lot of three: a shared effect of all three rests on three units; one of two (the third unlike them) rests on two. An outlier is named only when the other two agree and it alone differs; a unit whose value lies between theirs cannot be told from the spread.".into(),
        _ => format!(
            "A lot of {n}: an effect is shared when all {n} units' parameters agree, or all but one's (that one is then the outlier); at most {} unit(s) can be named outliers (fewer than half: the lot is the rest).",
            (n - 1) / 2
        ),
    }
}

/// Diagnose a lot: every unit alone, then together (`docs/diagnosis.md`,
/// "Lots"). Fails when `units` are not a lot (fewer than two, of several
/// types, at several sites, a serial twice, a unit without runs).
pub fn diagnose_lot(units: Vec<LotUnit>, opts: &Options) -> Result<Lot, LotError> {
    let (dut_type, site) = check(&units)?;
    let n = units.len();
    let mut runs = Vec::new();
    let mut spans = Vec::new();
    let mut unit_of_run = Vec::new();
    let mut meta = Vec::new();
    for (u, unit) in units.into_iter().enumerate() {
        let start = runs.len();
        let names: Vec<String> = unit.runs.iter().map(|r| r.name.clone()).collect();
        unit_of_run.extend(std::iter::repeat_n(u, unit.runs.len()));
        runs.extend(unit.runs);
        spans.push((start, runs.len()));
        meta.push((unit.serial, unit.slot, names));
    }
    let diagnoses = diagnose_each(&runs, &spans, opts);
    let stack = Stack::new(&runs, unit_of_run).ok_or(LotError::TooMany {
        units: n,
        max: Units::MAX,
    })?;
    let serials: Vec<String> = meta.iter().map(|m| m.0.clone()).collect();
    let settled = weigh::settle(&stack, &diagnoses, &serials);
    Ok(assemble(&stack, settled, diagnoses, meta, (dut_type, site)))
}

/// The lot's result from its settled model.
fn assemble(
    stack: &Stack<'_>,
    settled: weigh::Settled,
    diagnoses: Vec<Diagnosis>,
    meta: Vec<(String, String, Vec<String>)>,
    (dut_type, site): (String, Site),
) -> Lot {
    let n = stack.units;
    let serials: Vec<String> = meta.iter().map(|m| m.0.clone()).collect();
    // Each unit's reference as the lot's final model holds it (model 4's
    // warm-up time constant chosen with the unit's named effects, the
    // disturbances outside the library its diagnosis held: nuisances, as
    // a run's offset is): the lot's gaps are read from fits that differ
    // only by the effects. From the unit's own reference fit instead (its
    // warm-up bent to hold some of a bench fault), a unit's gap with the
    // shared effects stood up to 1.6 times its gap in the final fit,
    // though the final fit added nothing of that unit's, and the unit was
    // set apart on its gap.
    let reference: Vec<Term> = settled
        .model
        .iter()
        .copied()
        .filter(|t| {
            let shared = settled.shared.iter().any(|s| s.term == *t);
            let own = (0..n)
                .any(|u| t.units == Units::one(u) && named(&diagnoses[u]).contains(&t.effect));
            !shared && !own
        })
        .collect();
    let s_ref = score(&stack.data, &reference);
    let mut with_shared = reference.clone();
    with_shared.extend(settled.shared.iter().map(|s| s.term));
    let s_shared = score(&stack.data, &with_shared);
    let s_final = score(&stack.data, &settled.model);
    let mut shared_effects: Vec<SharedEffect> = settled
        .shared
        .iter()
        .map(|f| f.report(stack, &settled.model, &s_final, &serials))
        .collect();
    shared_effects.sort_by(|a, b| b.shrink.total_cmp(&a.shrink));
    let mut units: Vec<UnitResult> = meta
        .into_iter()
        .enumerate()
        .map(|(u, (serial, slot, runs))| {
            let d = &diagnoses[u];
            let own: Vec<Accepted> = d
                .effects
                .iter()
                .filter(|a| {
                    !settled
                        .shared
                        .iter()
                        .any(|s| s.term.effect.name() == a.name && s.term.units.holds(u))
                        && !settled
                            .explained
                            .iter()
                            .any(|&(x, e)| x == u && e.name() == a.name)
                })
                .cloned()
                .collect();
            UnitResult {
                serial,
                slot,
                runs,
                effects: own,
                outlier: false,
                evidence: Vec::new(),
                gap_dph: stack.unit_gap(&s_ref, u),
                gap_after_shared_dph: stack.unit_gap(&s_shared, u),
                gap_after_dph: stack.unit_gap(&s_final, u),
                noise_dph: stack.unit_noise(&s_final, u),
                thermal_gap_c: d.layers.thermal.gap_c,
                thermal_noise_floor_c: d.layers.thermal.noise_floor_c,
                confounded: d.confounded.clone(),
                inconclusive: d.inconclusive.clone(),
            }
        })
        .collect();
    let (outliers, no_outlier_because) = evidence::judge(&mut units, &settled.differs);
    let gap = LotGap {
        gap_dph: s_ref.gap(),
        after_shared_dph: s_shared.gap(),
        after_dph: s_final.gap(),
        shrink_shared: shrink(s_ref.gap(), s_shared.gap()),
        shrink: shrink(s_ref.gap(), s_final.gap()),
    };
    Lot {
        dut_type,
        site,
        protocol: format!(
            "Each unit diagnosed alone; then every unit's runs fitted together, each unit's reference and own effects its own, blocked cross-validation over every unit's records ({} folds over {} run(s) of {n} units), scores on 60 s means; a per-run offset is a nuisance",
            stack.data.folds.len(),
            stack.data.runs.len()
        ),
        thresholds: THRESHOLDS,
        lot_thresholds: LOT_THRESHOLDS,
        lot_size: lot_size(n),
        gap,
        shared_effects,
        units,
        outliers,
        no_outlier_because,
        considered: settled.considered,
        inconclusive: settled.inconclusive,
        deciding_procedure: settled.deciding_procedure,
        diagnoses,
    }
}

/// 1 - after / before, within 0..1.
fn shrink(before: f64, after: f64) -> f64 {
    if before > 0.0 {
        (1.0 - after / before).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Term `k` of `s`'s model as the report gives it: its coefficients, their
/// standard errors, the nonlinear parameter among the coefficients, and
/// the temperature a memory effect acts on.
pub(crate) fn term_values(
    s: &Scored,
    k: usize,
) -> (BTreeMap<String, f64>, BTreeMap<String, f64>, Option<String>) {
    FittedEffect::of(s, k).map_or_else(
        || (BTreeMap::new(), BTreeMap::new(), None),
        |f| {
            (
                f.parameters(),
                f.uncertainties(),
                f.temperature().map(|x| x.name().to_owned()),
            )
        },
    )
}

/// The effects a unit's diagnosis named.
pub(crate) fn named(d: &Diagnosis) -> Vec<Effect> {
    d.effects
        .iter()
        .filter_map(|a| Effect::from_name(&a.name))
        .collect()
}

#[cfg(test)]
mod tests;
