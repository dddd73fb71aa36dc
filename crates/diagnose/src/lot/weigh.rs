//! Shared or own: each effect a unit named alone is fitted over the whole
//! lot three ways (in no unit, one set shared by every unit, one set per
//! unit), all scored held out; then the effects no unit named alone are
//! tried as shared on the pooled runs.
//!
//! An effect is **shared** when the units' parameters agree (one set per
//! unit does not improve on one shared set, at `agree_alpha`), one shared
//! set is not worse held out than one per unit (within `tie`), and the
//! shared set passes the selection's bars over the lot's model without
//! the effect (significance at `alpha` / candidates, `min_gain`). In a lot
//! of three or more, an effect all but one unit share (the one's own
//! parameters let free) is **shared by the rest**, and that unit's
//! difference is outlier evidence. Otherwise it is each naming unit's
//! **own**, where the lot shares an effect only if that unit's term still
//! passes the bars over everything else the lot holds.
//!
//! The bench's own effects ([`BENCH`]: the Earth rate it subtracts off by
//! a fixed vector) come first: one unit's diagnosis cannot name them, and
//! takes what they add for effects of its own (a latitude stated wrong
//! reads as a scale-factor drift, coefficients unlike from unit to unit).
//! So the bench's vector is weighed on the units' references alone; when
//! the lot shares it, each effect a unit named is weighed over it, and a
//! unit keeps an own effect only where it still passes the bars over the
//! bench's vector (`explained_by_bench` otherwise). The bench's vector is
//! kept only when it still passes them over everything the units keep.

use std::collections::BTreeMap;

use super::{Considered, LOT_THRESHOLDS, SharedEffect, Stack, UnitValue, term_values};
use crate::engine::{Scored, identifiable, improvement, score, with_best_parameter_in};
use crate::library::{BENCH, Effect, LIBRARY, Param, Term, Units};
use crate::{Diagnosis, Inconclusive, THRESHOLDS};

/// A shared effect found: its term (in the units that share it) and the
/// evidence it rests on.
#[derive(Debug, Clone)]
pub(super) struct Found {
    /// The term, in the units sharing it.
    pub term: Term,
    /// p-value of the shared term over the lot's model without it.
    pub p_value: f64,
    /// p-value of one set per unit over the shared set.
    pub agreement_p: f64,
    /// Units that named it alone.
    pub named_alone: Vec<usize>,
    /// Each unit's own parameters at the shared nonlinear parameter.
    pub per_unit: Vec<UnitValue>,
}

/// A unit whose parameters of an effect the rest of the lot shares
/// differ from theirs.
#[derive(Debug, Clone)]
pub(crate) struct Differs {
    /// The unit.
    pub unit: usize,
    /// The effect.
    pub effect: Effect,
    /// p-value of its own set over sharing the lot's.
    pub p_value: f64,
    /// Its coefficients, and the lot's.
    pub value: BTreeMap<String, f64>,
    /// The lot's.
    pub lot: BTreeMap<String, f64>,
    /// The largest difference in units of its standard error, and the
    /// coefficient.
    pub z: (f64, String),
}

/// The lot's model once every effect is weighed.
#[derive(Debug)]
pub(super) struct Settled {
    /// Every unit's reference and own effects, and the shared effects.
    pub model: Vec<Term>,
    /// The shared effects.
    pub shared: Vec<Found>,
    /// Every effect weighed.
    pub considered: Vec<Considered>,
    /// Units unlike the rest on a shared effect.
    pub differs: Vec<Differs>,
    /// The pooled runs' best candidate that misses a bar.
    pub inconclusive: Option<Inconclusive>,
    /// Its deciding run.
    pub deciding_procedure: Option<String>,
    /// Effects a unit named alone that the bench's vector or the lot's
    /// shared effects explain (unit, effect): not the unit's.
    pub explained: Vec<(usize, Effect)>,
}

impl Settled {
    fn new() -> Self {
        Self {
            model: Vec::new(),
            shared: Vec::new(),
            considered: Vec::new(),
            differs: Vec::new(),
            inconclusive: None,
            deciding_procedure: None,
            explained: Vec::new(),
        }
    }

    /// Take effect weighed `w`: its model, decision, finding.
    fn take(&mut self, w: Weighed) -> Vec<Term> {
        self.considered.push(w.considered);
        self.shared.extend(w.found);
        self.differs.extend(w.differs);
        self.explained.extend(w.explained);
        w.model
    }
}

/// One effect weighed: the model after the decision.
struct Weighed {
    model: Vec<Term>,
    considered: Considered,
    found: Option<Found>,
    differs: Option<Differs>,
    /// Units whose own term of it the lot's shared effects explain.
    explained: Vec<(usize, Effect)>,
}

/// The bars an effect's fits are held to.
struct Bars {
    /// The selection's significance bar: `alpha` / candidates.
    level: f64,
}

impl Bars {
    /// A shared set over `base` passes the selection's bars.
    fn present(&self, gain: f64, p: f64, base: &Scored) -> bool {
        p < self.level && gain > THRESHOLDS.min_gain * base.sse()
    }

    /// A unit's own term (in `units`) still passes the bars: `with` (the
    /// lot's fit holding it) over `base` (the same without it), its
    /// improvement significant and a `min_gain` share of that unit's sum
    /// of squares.
    fn own_holds(&self, stack: &Stack<'_>, base: &Scored, with: &Scored, units: Units) -> bool {
        let p = improvement(base, with).1;
        let before = stack.units_sse(base, units);
        let gain = before - stack.units_sse(with, units);
        p < self.level && gain > THRESHOLDS.min_gain * before
    }

    /// One shared set `shared` is as good as one set per unit `own`: the
    /// own sets do not improve on it significantly, and it is not worse
    /// held out (within `tie`).
    fn agree(shared: &Scored, own: &Scored) -> (bool, f64, f64) {
        let p = improvement(shared, own).1;
        let ratio = shared.sse() / own.sse().max(f64::MIN_POSITIVE);
        (
            p >= LOT_THRESHOLDS.agree_alpha && ratio <= 1.0 + THRESHOLDS.tie,
            p,
            ratio,
        )
    }
}

/// Every unit's final model (its reference, named effects and held
/// disturbances) as the lot's.
fn units_model(stack: &Stack<'_>, diagnoses: &[Diagnosis]) -> Vec<Term> {
    (0..stack.units)
        .flat_map(|u| {
            let model = diagnoses[u]
                .fits
                .as_ref()
                .map_or(&[][..], |f| &f.1.model[..]);
            stack.own_terms(u, model)
        })
        .collect()
}

/// Weigh every effect a unit named alone, then the others on the pooled
/// runs (`serials` name the units in the report); the bench's own
/// effects first, when the lot shares one.
pub(super) fn settle(stack: &Stack<'_>, diagnoses: &[Diagnosis], serials: &[String]) -> Settled {
    let n = stack.units;
    let model = units_model(stack, diagnoses);
    let in_reference: Vec<Effect> = diagnoses
        .iter()
        .filter_map(|d| d.fits.as_ref())
        .flat_map(|f| f.0.model.iter().map(|t| t.effect))
        .collect();
    let candidates: Vec<Effect> = LIBRARY
        .iter()
        .copied()
        .filter(|e| !in_reference.contains(e))
        .collect();
    let bench: Vec<Effect> = BENCH
        .iter()
        .copied()
        .filter(|&e| !in_reference.contains(&e) && identifiable(&stack.data, e, Param::None))
        .collect();
    let bars = Bars {
        level: THRESHOLDS.alpha / (candidates.len() + bench.len()).max(1) as f64,
    };
    let mut named: Vec<(Effect, Vec<usize>)> = candidates
        .iter()
        .filter_map(|&e| {
            let units: Vec<usize> = (0..n)
                .filter(|&u| super::named(&diagnoses[u]).contains(&e))
                .collect();
            (!units.is_empty()).then_some((e, units))
        })
        .collect();
    // The effect most units named first: it is the likeliest shared one,
    // and the others are weighed over it.
    named.sort_by_key(|(_, us)| std::cmp::Reverse(us.len()));
    let remaining = |found: &[Effect]| -> Vec<Effect> {
        candidates
            .iter()
            .copied()
            .filter(|&e| {
                !named.iter().any(|(x, _)| *x == e) && identifiable(&stack.data, e, e.grid()[0])
            })
            .chain(bench.iter().copied())
            .filter(|e| !found.contains(e))
            .collect()
    };
    let route = Route {
        stack,
        named: &named,
        bars: &bars,
        serials,
    };
    for &e in &bench {
        if let Some(mut settled) = route.bench_first(&model, e) {
            settled.model = pooled(
                stack,
                settled.model.clone(),
                remaining(&[e]),
                &bars,
                serials,
                &mut settled,
            );
            return settled;
        }
    }
    let mut settled = Settled::new();
    let mut model = model;
    for (e, named_in) in &named {
        model = settled.take(weigh(stack, &model, *e, named_in, &bars, serials));
    }
    settled.model = pooled(stack, model, remaining(&[]), &bars, serials, &mut settled);
    settled
}

/// What the weighing of a lot goes by.
struct Route<'a, 's> {
    stack: &'a Stack<'s>,
    /// The effects units named alone, with the units that named each.
    named: &'a [(Effect, Vec<usize>)],
    bars: &'a Bars,
    serials: &'a [String],
}

impl Route<'_, '_> {
    /// The lot with the bench's effect `e` (every unit alike) weighed on
    /// the units' references (`model` less every effect a unit named),
    /// then each named effect over it: `None` when the lot does not share
    /// `e`, or it no longer passes the bars once the units keep what is
    /// theirs.
    fn bench_first(&self, model: &[Term], e: Effect) -> Option<Settled> {
        let (stack, bars, serials) = (self.stack, self.bars, self.serials);
        let is_named = |t: &Term| {
            self.named
                .iter()
                .any(|(x, us)| *x == t.effect && us.iter().any(|&u| t.units == Units::one(u)))
        };
        if !model.iter().any(is_named) {
            // Nothing of the units' to take its place: the pooled runs
            // weigh it as any other.
            return None;
        }
        let reference: Vec<Term> = model.iter().copied().filter(|t| !is_named(t)).collect();
        let w = weigh(stack, &reference, e, &[], bars, serials);
        if w.found.as_ref().is_none_or(|f| f.term.units != Units::ALL) {
            return None;
        }
        let vector = Term::new(e, Param::None);
        let mut settled = Settled::new();
        let mut lot = settled.take(w);
        for (x, named_in) in self.named {
            let w = weigh(stack, &lot, *x, named_in, bars, serials);
            if w.found.is_some() {
                lot = settled.take(w);
                continue;
            }
            let mut considered = w.considered;
            let base = score(&stack.data, &lot);
            let mut kept = Vec::new();
            for &u in named_in {
                let Some(own) = model
                    .iter()
                    .copied()
                    .find(|t| t.effect == *x && t.units == Units::one(u))
                else {
                    continue;
                };
                let with: Vec<Term> = lot.iter().copied().chain([own]).collect();
                let s = score(&stack.data, &with);
                if bars.own_holds(stack, &base, &s, own.units) {
                    kept.push(own);
                } else {
                    settled.explained.push((u, *x));
                    considered.explained_by_bench_in.push(serials[u].clone());
                }
            }
            if kept.is_empty() {
                considered.decision = "explained_by_bench".into();
            }
            lot.extend(kept);
            settled.considered.push(considered);
        }
        let without: Vec<Term> = lot.iter().copied().filter(|t| *t != vector).collect();
        let (s0, s1) = (score(&stack.data, &without), score(&stack.data, &lot));
        let (gain, p) = improvement(&s0, &s1);
        if !bars.present(gain, p, &s0) {
            return None;
        }
        settled.model = lot;
        Some(settled)
    }
}

/// The effects no unit named alone, tried as one set shared by every
/// unit over the lot's model (forward, as a unit's selection, at most
/// `max_effects` shared in all); the best that passes the bars is weighed
/// as any other. When none passes, the best that improves the lot's gap
/// but misses a bar is the lot's inconclusive candidate.
fn pooled(
    stack: &Stack<'_>,
    mut model: Vec<Term>,
    mut remaining: Vec<Effect>,
    bars: &Bars,
    serials: &[String],
    settled: &mut Settled,
) -> Vec<Term> {
    let data = &stack.data;
    while !remaining.is_empty() && settled.shared.len() < THRESHOLDS.max_effects {
        let current = score(data, &model);
        let tried = crate::each_against(data, &remaining, &current, &[]);
        let best = tried
            .iter()
            .filter(|t| bars.present(t.gain, t.p, &current))
            .max_by(|a, b| a.gain.total_cmp(&b.gain))
            .map(|t| t.effect);
        let Some(e) = best else {
            if let Some((i, text)) =
                crate::inconclusive(data, &remaining, &tried, &current, bars.level, &[], 0)
            {
                settled.inconclusive = Some(i);
                settled.deciding_procedure = text;
            }
            break;
        };
        model = settled.take(weigh(stack, &model, e, &[], bars, serials));
        remaining.retain(|&x| x != e);
    }
    model
}

/// Weigh effect `e` over the lot's `model` (in which the units of
/// `named_in` hold it as their own): shared by every unit, by all but
/// one, or each naming unit's own.
fn weigh(
    stack: &Stack<'_>,
    model: &[Term],
    e: Effect,
    named_in: &[usize],
    bars: &Bars,
    serials: &[String],
) -> Weighed {
    let (data, n) = (&stack.data, stack.units);
    let without: Vec<Term> = model.iter().copied().filter(|t| t.effect != e).collect();
    // Two at a time: the lot without the effect beside the search of its
    // shared parameter, then the shared and the per-unit sets' scores.
    let (s0, shared_model) = std::thread::scope(|s| {
        let s0 = s.spawn(|| score(data, &without));
        let shared = with_best_parameter_in(data, &without, e, Units::ALL, &[]);
        (joined(s0), shared)
    });
    let p = shared_model.last().map_or(Param::None, |t| t.param);
    let own_model: Vec<Term> = without
        .iter()
        .copied()
        .chain((0..n).map(|u| Term::in_units(e, p, Units::one(u))))
        .collect();
    let (s_shared, s_own) = std::thread::scope(|s| {
        let shared = s.spawn(|| score(data, &shared_model));
        let own = score(data, &own_model);
        (joined(shared), own)
    });
    let (gain, p_shared) = improvement(&s0, &s_shared);
    let (agree, agreement_p, ratio) = Bars::agree(&s_shared, &s_own);
    // The bench's own effect is one vector for every unit by what it is
    // (what the bench states about where it is): the per-unit sets only
    // guard against a unit's own effect taken for it, and the units agree
    // on it when one set per unit predicts no better held out (within
    // `tie`). The in-sample F-test is left to the units' effects, where it
    // tells a fixture's from each unit's own: on a lot whose latitude was
    // stated 2.2 deg wrong it set apart units whose estimates were 0.56 to
    // 0.70 deg/h of a 0.59 deg/h error, each unit's slow noise between
    // positions moving its own.
    let agree = agree || (BENCH.contains(&e) && ratio <= 1.0 + THRESHOLDS.tie);
    let per_unit: Vec<UnitValue> = (0..n)
        .map(|u| {
            let (parameters, uncertainties, _) = term_values(&s_own, without.len() + u);
            UnitValue {
                serial: serials[u].clone(),
                parameters,
                uncertainties,
            }
        })
        .collect();
    let mut considered = Considered {
        name: e.name().into(),
        decision: String::new(),
        named_alone_in: named_in.iter().map(|&u| serials[u].clone()).collect(),
        explained_by_bench_in: Vec::new(),
        p_value: p_shared,
        improvement: gain / s0.sse().max(f64::MIN_POSITIVE),
        agreement_p,
        shared_over_own: ratio,
    };
    if n >= 2 && agree && bars.present(gain, p_shared, &s0) {
        considered.decision = "shared".into();
        return Weighed {
            model: shared_model,
            considered,
            found: Some(Found {
                term: Term::in_units(e, p, Units::ALL),
                p_value: p_shared,
                agreement_p,
                named_alone: named_in.to_vec(),
                per_unit,
            }),
            differs: None,
            explained: Vec::new(),
        };
    }
    if n >= 3
        && let Some(w) = all_but_one(stack, &without, (e, p), (&s_shared, &s_own), bars)
    {
        considered.decision = "shared_by_some".into();
        let rest = w.rest;
        return Weighed {
            model: w.model,
            considered,
            found: Some(Found {
                term: Term::in_units(e, p, rest),
                p_value: w.p_rest,
                agreement_p: w.agreement_p,
                named_alone: named_in
                    .iter()
                    .copied()
                    .filter(|&u| rest.holds(u))
                    .collect(),
                per_unit,
            }),
            differs: Some(w.differs),
            explained: Vec::new(),
        };
    }
    let (model, explained) = own_over_the_lot(stack, model, e, named_in, bars);
    considered
        .explained_by_bench_in
        .extend(explained.iter().map(|&(u, _)| serials[u].clone()));
    considered.decision = if named_in.is_empty() {
        "not_in_lot".into()
    } else if explained.len() == named_in.len() {
        "explained_by_bench".into()
    } else {
        "own".into()
    };
    Weighed {
        model,
        considered,
        found: None,
        differs: None,
        explained,
    }
}

/// Each naming unit's own term of `e` in `model`, where the lot shares
/// an effect: kept only where it still passes the bars over everything
/// else the lot holds, as over the bench's Earth-rate error
/// ([`Route::bench_first`]). A unit alone takes part of a fixture's tilt
/// for an effect of its own that the tilt explains once the lot shares it
/// (at low latitude, a magnetic sensitivity: both project a northward
/// vector). The model with the terms kept, and the (unit, effect) left out.
fn own_over_the_lot(
    stack: &Stack<'_>,
    model: &[Term],
    e: Effect,
    named_in: &[usize],
    bars: &Bars,
) -> (Vec<Term>, Vec<(usize, Effect)>) {
    let mut model = model.to_vec();
    let mut explained = Vec::new();
    let lot_shares = model
        .iter()
        .filter(|t| t.effect != e)
        .any(|t| (0..stack.units).filter(|&u| t.units.holds(u)).count() > 1);
    for &u in named_in.iter().filter(|_| lot_shares) {
        let Some(own) = model
            .iter()
            .copied()
            .find(|t| t.effect == e && t.units == Units::one(u))
        else {
            continue;
        };
        let rest: Vec<Term> = model.iter().copied().filter(|t| *t != own).collect();
        let (base, with) = (score(&stack.data, &rest), score(&stack.data, &model));
        if !bars.own_holds(stack, &base, &with, own.units) {
            model = rest;
            explained.push((u, e));
        }
    }
    (model, explained)
}

/// An effect all units but one share.
struct AllButOne {
    model: Vec<Term>,
    rest: Units,
    p_rest: f64,
    agreement_p: f64,
    differs: Differs,
}

/// The unit whose own set of `e` (at `p`) leaves the others sharing one
/// set best (held out), when they then agree and their shared set passes
/// the bars over the model where only that unit has `e`. `fits` are the
/// lot's fits with one shared set and one set per unit.
fn all_but_one(
    stack: &Stack<'_>,
    without: &[Term],
    (e, p): (Effect, Param),
    (s_shared, s_own): (&Scored, &Scored),
    bars: &Bars,
) -> Option<AllButOne> {
    let (data, n) = (&stack.data, stack.units);
    let model_without = |v: usize| -> Vec<Term> {
        let rest = Units::of((0..n).filter(|&u| u != v));
        without
            .iter()
            .copied()
            .chain([
                Term::in_units(e, p, rest),
                Term::in_units(e, p, Units::one(v)),
            ])
            .collect()
    };
    let units: Vec<usize> = (0..n).collect();
    let (v, s_rest) =
        gyrobench_analysis::par::two_at_a_time(&units, |_, &v| (v, score(data, &model_without(v))))
            .into_iter()
            .min_by(|a, b| a.1.sse().total_cmp(&b.1.sse()))?;
    let (agree, agreement_p, _) = Bars::agree(&s_rest, s_own);
    let only_v: Vec<Term> = without
        .iter()
        .copied()
        .chain([Term::in_units(e, p, Units::one(v))])
        .collect();
    let s_only_v = score(data, &only_v);
    let (gain_rest, p_rest) = improvement(&s_only_v, &s_rest);
    if !(agree && bars.present(gain_rest, p_rest, &s_only_v)) {
        return None;
    }
    let (lot, lot_err, _) = term_values(&s_rest, without.len());
    let (value, value_err, _) = term_values(&s_rest, without.len() + 1);
    let z = e
        .terms()
        .iter()
        .map(|&k| {
            let d = value.get(k).copied().unwrap_or(0.0) - lot.get(k).copied().unwrap_or(0.0);
            let se = value_err
                .get(k)
                .copied()
                .unwrap_or(f64::NAN)
                .hypot(lot_err.get(k).copied().unwrap_or(0.0));
            (d / se, k.to_owned())
        })
        .max_by(|a, b| a.0.abs().total_cmp(&b.0.abs()))
        .unwrap_or((f64::NAN, String::new()));
    let coefficients = |m: BTreeMap<String, f64>| -> BTreeMap<String, f64> {
        m.into_iter()
            .filter(|(k, _)| e.terms().contains(&k.as_str()))
            .collect()
    };
    Some(AllButOne {
        model: model_without(v),
        rest: Units::of((0..n).filter(|&u| u != v)),
        p_rest,
        agreement_p,
        differs: Differs {
            unit: v,
            effect: e,
            p_value: improvement(s_shared, &s_rest).1,
            value: coefficients(value),
            lot: coefficients(lot),
            z,
        },
    })
}

impl Found {
    /// The shared effect as `lot.json` gives it, fitted in the lot's final
    /// `model` (scored `fin`).
    pub(super) fn report(
        &self,
        stack: &Stack<'_>,
        model: &[Term],
        fin: &Scored,
        serials: &[String],
    ) -> SharedEffect {
        let k = model.iter().position(|t| *t == self.term);
        let (parameters, uncertainties, temperature) = k.map_or_else(
            || (BTreeMap::new(), BTreeMap::new(), None),
            |k| term_values(fin, k),
        );
        let before = k.map_or(fin.gap(), |k| {
            let mut m = model.to_vec();
            m.remove(k);
            score(&stack.data, &m).gap()
        });
        let after = fin.gap();
        let fitted = k.and_then(|k| crate::FittedEffect::of(fin, k));
        let latitude = stack.data.runs.first().map_or(0.0, |r| r.site.latitude_deg);
        let (seat, seat_why) = super::seat(self.term.effect, &parameters, latitude);
        let holds = |u: usize| self.term.units.holds(u);
        SharedEffect {
            name: self.term.effect.name().into(),
            parameters,
            uncertainties,
            temperature,
            units: (0..stack.units)
                .filter(|&u| holds(u))
                .map(|u| serials[u].clone())
                .collect(),
            seat: seat.into(),
            seat_why,
            held_out_gap_before_dph: before,
            held_out_gap_after_dph: after,
            shrink: super::shrink(before, after),
            p_value: self.p_value,
            agreement_p: self.agreement_p,
            named_alone_in: self
                .named_alone
                .iter()
                .map(|&u| serials[u].clone())
                .collect(),
            per_unit: self.per_unit.clone(),
            fitted,
        }
    }
}

/// A scoped thread's result; its panic raised again here.
fn joined<T>(h: std::thread::ScopedJoinHandle<'_, T>) -> T {
    h.join().unwrap_or_else(|p| std::panic::resume_unwind(p))
}
