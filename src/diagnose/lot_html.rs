//! `lot.html` and the lot's headline: what the bench shares (with its
//! seat and each unit's own value beside the lot's), what each unit owns,
//! the outlier with its evidence, how far the lot's gap shrinks, and the
//! files to act on.

use super::lot::{Lot, SharedEffect, UnitResult};
use crate::view::chart::{Band, Rule};
use crate::view::{Chart, Marker, Series, esc, p_value, page};

/// A list in words: `a`, `a and b`, `a, b and c`.
fn and_list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    }
}

/// The shared effects in words: `axis_misalignment (fixture, all 4
/// units)`.
fn shared_words(lot: &Lot) -> Vec<String> {
    let n = lot.units.len();
    lot.shared_effects
        .iter()
        .map(|s| {
            let who = if s.units.len() == n {
                format!("all {n} units")
            } else {
                and_list(&s.units)
            };
            format!("{} ({}, {who})", s.name, s.seat)
        })
        .collect()
}

/// Each unit's own effects in words: `U2: g_sensitivity`.
fn own_words(lot: &Lot) -> Vec<String> {
    lot.units
        .iter()
        .filter(|u| !u.effects.is_empty())
        .map(|u| {
            let names: Vec<String> = u.effects.iter().map(|a| a.name.clone()).collect();
            format!("{}: {}", u.serial, and_list(&names))
        })
        .collect()
}

/// The answer first: what the bench shares, how far the lot's gap
/// shrinks, what the units own, which unit is unlike the lot.
pub fn headline(lot: &Lot) -> String {
    let n = lot.units.len();
    let serials: Vec<String> = lot.units.iter().map(|u| u.serial.clone()).collect();
    let g = &lot.gap;
    let mut out = format!(
        "Lot of {n} {} units ({}). ",
        lot.dut_type,
        serials.join(", ")
    );
    let shared = shared_words(lot);
    let own = own_words(lot);
    if shared.is_empty() {
        out.push_str("The units share no effect: nothing points at the bench. ");
    } else {
        out.push_str(&format!(
            "The bench's: {}. Given to the bench, {} shrink{} the lot's held-out rate gap from {:.5} to {:.5} deg/h ({:.0} % smaller)",
            and_list(&shared),
            if shared.len() == 1 { "it" } else { "they" },
            if shared.len() == 1 { "s" } else { "" },
            g.gap_dph,
            g.after_shared_dph,
            100.0 * g.shrink_shared
        ));
        out.push_str(if own.is_empty() { ". " } else { "; " });
    }
    if own.is_empty() {
        out.push_str("No unit has an effect of its own. ");
    } else {
        out.push_str(&format!(
            "{}each unit's own ({}) take{} it to {:.5} deg/h ({:.0} % smaller in all). ",
            if shared.is_empty() {
                "Each unit's own effects "
            } else {
                ""
            },
            own.join("; "),
            if shared.is_empty() { "" } else { "s" },
            g.after_dph,
            100.0 * g.shrink
        ));
    }
    let outliers: Vec<&UnitResult> = lot.units.iter().filter(|u| u.outlier).collect();
    for u in &outliers {
        let why: Vec<String> = u.evidence.iter().map(|e| e.text.clone()).collect();
        out.push_str(&format!(
            "{} is unlike the lot: {}. ",
            u.serial,
            why.join("; ")
        ));
    }
    if outliers.is_empty() {
        out.push_str(&match &lot.no_outlier_because {
            Some(why) => format!("No outlier is named: {why}. "),
            None => "No unit is unlike the lot. ".into(),
        });
    }
    if let Some(i) = &lot.inconclusive {
        let r = &i.deciding_run;
        out.push_str(&format!(
            "Inconclusive for the lot: {} improves the pooled gap but misses a bar; {} ({}), run as a batch of these units, would decide. ",
            r.effect,
            r.what,
            r.power_phrase()
        ));
    }
    out.trim_end().to_owned()
}

/// A coefficient as the page shows it: a misalignment's in arcmin (its
/// coefficients are theta_z and -theta_y, rad), the rest as fitted.
fn shown(effect: &str, name: &str, v: f64) -> (f64, String) {
    if effect == "axis_misalignment" {
        let label = if name == "earth_y" {
            "theta_z, arcmin"
        } else {
            "-theta_y, arcmin"
        };
        (v.to_degrees() * 60.0, label.into())
    } else {
        (v, name.into())
    }
}

/// Each unit's own value of a shared effect's coefficient (fitted with
/// one set per unit, +-2 standard errors) against the lot's shared one
/// (its band +-2 standard errors).
fn agreement_charts(s: &SharedEffect, serials: &[String]) -> String {
    let mut out = String::new();
    for (name, &lot_value) in &s.parameters {
        if !s.uncertainties.contains_key(name) {
            continue;
        }
        let (v, label) = shown(&s.name, name, lot_value);
        let (lot_err, _) = shown(
            &s.name,
            name,
            s.uncertainties.get(name).copied().unwrap_or(0.0),
        );
        let mut points = Vec::new();
        let mut errors = Vec::new();
        for (k, serial) in serials.iter().enumerate() {
            let Some(u) = s.per_unit.iter().find(|u| &u.serial == serial) else {
                continue;
            };
            let (x, _) = shown(
                &s.name,
                name,
                u.parameters.get(name).copied().unwrap_or(f64::NAN),
            );
            let (e, _) = shown(
                &s.name,
                name,
                u.uncertainties.get(name).copied().unwrap_or(0.0),
            );
            points.push((k as f64, x));
            errors.push((k as f64, x - 2.0 * e.abs(), x + 2.0 * e.abs()));
        }
        out.push_str(
            &Chart::new(
                format!("{}: {label}, each unit's own against the lot's", s.name),
                "unit",
                &label,
            )
            .categories(serials.to_vec())
            .height(220)
            .band(Band {
                label: format!(
                    "the lot's shared value +-2 standard errors ({})",
                    s.units.len()
                ),
                y: (v - 2.0 * lot_err.abs(), v + 2.0 * lot_err.abs()),
                x: None,
            })
            .rule(Rule {
                label: "shared".into(),
                at: v,
                vertical: false,
            })
            .series(
                Series::points(
                    "each unit's own, +-2 standard errors",
                    points,
                    Marker::Circle,
                )
                .colour(0)
                .marker(Marker::Circle, 5)
                .errors(errors),
            )
            .render(),
        );
    }
    out
}

/// Each unit's held-out gap: its reference alone, the shared effects to
/// the bench, its own effects too, and the noise of its 60 s means.
fn gap_chart(lot: &Lot) -> String {
    let serials: Vec<String> = lot.units.iter().map(|u| u.serial.clone()).collect();
    let series = |label: &str, f: &dyn Fn(&UnitResult) -> f64, colour: usize, m: Marker| {
        Series::points(
            label,
            lot.units
                .iter()
                .enumerate()
                .map(|(k, u)| (k as f64, f(u)))
                .collect(),
            m,
        )
        .colour(colour)
        .marker(m, 5)
    };
    Chart::new("Held-out rate gap, unit by unit", "unit", "deg/h")
        .categories(serials)
        .height(260)
        .series(series("reference alone", &|u| u.gap_dph, 1, Marker::Square))
        .series(series(
            "shared effects given to the bench",
            &|u| u.gap_after_shared_dph,
            2,
            Marker::Triangle,
        ))
        .series(series(
            "each unit's own as well",
            &|u| u.gap_after_dph,
            0,
            Marker::Circle,
        ))
        .series(series(
            "noise of its 60 s means",
            &|u| u.noise_dph,
            6,
            Marker::Cross,
        ))
        .caption("A unit whose triangle stands far above its cross and above the other units' carries a gap the lot does not: it is set apart on its gap.")
        .render()
}

/// The shared effects' table rows.
fn shared_rows(lot: &Lot) -> String {
    if lot.shared_effects.is_empty() {
        return "<tr><td colspan=7>the units share no effect</td></tr>".into();
    }
    lot.shared_effects
        .iter()
        .map(|s| {
            let params: Vec<String> = s
                .parameters
                .iter()
                .map(|(k, v)| match s.uncertainties.get(k) {
                    Some(u) if u.is_finite() => format!("{k} = {v:.4e} &plusmn; {u:.1e}"),
                    _ => format!("{k} = {v:.4}"),
                })
                .collect();
            format!(
                "<tr><td>{}</td><td><b>{}</b></td><td>{}</td><td>{}</td><td class=num>{:.5} &rarr; {:.5}</td><td class=num>{:.0} %</td><td class=num>{} / {}</td></tr>\n<tr><td></td><td colspan=6 class=note>why there: {}</td></tr>\n",
                esc(&s.name),
                esc(&s.seat),
                esc(&s.units.join(", ")),
                params.join("<br>"),
                s.held_out_gap_before_dph,
                s.held_out_gap_after_dph,
                100.0 * s.shrink,
                p_value(s.p_value),
                p_value(s.agreement_p),
                esc(&s.seat_why)
            )
        })
        .collect()
}

/// The units' table rows.
fn unit_rows(lot: &Lot) -> String {
    lot.units
        .iter()
        .map(|u| {
            let own: Vec<String> = u
                .effects
                .iter()
                .map(|a| format!("{} ({:.0} %)", esc(&a.name), 100.0 * a.shrink))
                .collect();
            let evidence: Vec<String> = u
                .evidence
                .iter()
                .map(|e| format!("<li>{}: {}</li>", esc(&e.kind), esc(&e.text)))
                .collect();
            format!(
                "<tr{}><td><b>{}</b>{}</td><td>{}</td><td class=num>{:.5} &rarr; {:.5} &rarr; {:.5}</td><td class=num>{:.5}</td><td class=num>{:.3}</td><td>{}{}</td></tr>\n",
                if u.outlier { " class=fail" } else { "" },
                esc(&u.serial),
                if u.slot.is_empty() {
                    String::new()
                } else {
                    format!(" (slot {})", esc(&u.slot))
                },
                if own.is_empty() {
                    "none".into()
                } else {
                    own.join(", ")
                },
                u.gap_dph,
                u.gap_after_shared_dph,
                u.gap_after_dph,
                u.noise_dph,
                u.thermal_gap_c,
                if u.outlier { "<b>outlier</b>" } else { "" },
                if evidence.is_empty() {
                    String::new()
                } else {
                    format!("<ul>{}</ul>", evidence.join(""))
                }
            )
        })
        .collect()
}

/// The effects weighed, and how each was decided.
fn considered_rows(lot: &Lot) -> String {
    lot.considered
        .iter()
        .map(|c| {
            format!(
                "<tr><td>{}</td><td>{}</td><td>{}</td><td class=num>{:.0} %</td><td class=num>{}</td><td class=num>{}</td><td class=num>{:.3}</td></tr>",
                esc(&c.name),
                esc(&c.decision),
                esc(&c.named_alone_in.join(", ")),
                100.0 * c.improvement,
                p_value(c.p_value),
                p_value(c.agreement_p),
                c.shared_over_own
            )
        })
        .collect()
}

/// The page.
pub fn render(lot: &Lot) -> String {
    let serials: Vec<String> = lot.units.iter().map(|u| u.serial.clone()).collect();
    let charts: String = lot
        .shared_effects
        .iter()
        .map(|s| agreement_charts(s, &serials))
        .collect();
    let g = &lot.gap;
    let act = format!(
        "<ul><li><code>bench-correction.toml</code>: the shared effects, with their seat, as a twin's <code>[effects]</code>: correct the bench (or simulate it) with them, not the units' coefficients</li><li><code>units/SERIAL/twin-updated.toml</code>: each unit's twin with its fitted thermal network and its own effects alone</li><li><code>units/SERIAL/twin-on-this-bench.toml</code>: the same with the bench's shared effects (its runs diagnosed against it leave nothing to name)</li><li><code>units/SERIAL/diagnosis.json</code>, <code>diagnosis.html</code>: each unit's own diagnosis{}</li></ul>",
        if lot.inconclusive.is_some() {
            "</li><li><code>deciding-run.toml</code>: the run that would decide the lot's inconclusive candidate, to run as a batch of these units"
        } else {
            ""
        }
    );
    let body = format!(
        "<h1>Lot diagnosis</h1>\n<p class=headline>{headline}</p>\n<p class=note>{size} {protocol}.</p>\n<h2>The lot's gap</h2>\n<table><tr><th>held-out rate gap</th><th>deg/h</th><th>smaller by</th></tr><tr><td>each unit's reference alone</td><td class=num>{g0:.5}</td><td></td></tr><tr><td>shared effects given to the bench</td><td class=num>{g1:.5}</td><td class=num>{s1:.0} %</td></tr><tr><td>each unit's own effects as well</td><td class=num>{g2:.5}</td><td class=num>{s2:.0} %</td></tr></table>\n<h2>Shared effects: the bench's</h2>\n<table><tr><th>effect</th><th>seat</th><th>units</th><th>parameters (one set)</th><th>lot's gap without &rarr; with</th><th>shrink</th><th>p / agreement p</th></tr>\n{shared}</table>\n{charts}<h2>Units</h2>\n<table><tr><th>unit</th><th>own effects (shrink)</th><th>gap: reference &rarr; shared &rarr; own, deg/h</th><th>noise of 60 s means</th><th>thermal gap, degC</th><th>unlike the lot?</th></tr>\n{units}</table>\n{gap_chart}<h2>Every effect weighed</h2>\n<p class=note>Shared: the units' parameters agree (p of one set per unit over one shared set at or over {agree}) and one shared set is not worse held out (held-out sum of squares within {tie:.0} % of one set per unit's), and it passes the selection's bars. Shared by some: all units but one (that one's own set let free). The bench's Earth-rate error (<code>earth_rate_error</code>: the latitude or north the bench states off) is weighed first, on the units' references; the units agree on it when one set per unit is not better held out; an effect a unit named is then its own only where it still adds to it, and <em>explained_by_bench</em> where it does not.</p><table><tr><th>effect</th><th>decision</th><th>named alone in</th><th>one shared set removes</th><th>p</th><th>agreement p</th><th>shared / own, held out</th></tr>{considered}</table>\n<h2>Acting on it</h2>{act}\n",
        headline = esc(&headline(lot)),
        size = esc(&lot.lot_size),
        protocol = esc(&lot.protocol),
        g0 = g.gap_dph,
        g1 = g.after_shared_dph,
        s1 = 100.0 * g.shrink_shared,
        g2 = g.after_dph,
        s2 = 100.0 * g.shrink,
        shared = shared_rows(lot),
        units = unit_rows(lot),
        gap_chart = gap_chart(lot),
        agree = lot.lot_thresholds.agree_alpha,
        tie = 100.0 * lot.thresholds.tie,
        considered = considered_rows(lot),
    );
    page("Lot diagnosis", "", &body)
}
