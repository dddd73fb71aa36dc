//! The trend chart page: a measurement's values across units in the order
//! their runs started, with the limits (one self-contained page, plotters
//! SVG, no scripts).

use super::query::Trend;
use crate::view::chart::Rule;
use crate::view::{Chart, Marker, Series, esc, page};

/// The page of `t`, with `points` (start time, serial, value, outcome),
/// oldest first. Values are plotted in run order (an individuals chart):
/// runs a second apart and runs a month apart are each a point of their own.
pub fn trend_page(t: &Trend, points: &[(String, String, f64, String)]) -> String {
    let at = |pass: bool| -> Vec<(f64, f64)> {
        points
            .iter()
            .enumerate()
            .filter(|(_, p)| (p.3 == "pass") == pass)
            .map(|(i, p)| ((i + 1) as f64, p.2))
            .collect()
    };
    let day = |p: Option<&(String, String, f64, String)>| {
        p.map_or(String::new(), |p| p.0.chars().take(10).collect())
    };
    let x_desc = format!(
        "runs in the order they started, oldest first ({} to {})",
        day(points.first()),
        day(points.last())
    );
    // Points small enough that thousands stay points.
    let dot = match points.len() {
        0..=100 => 5,
        101..=1000 => 3,
        _ => 2,
    };
    let mut c = Chart::new(format!("{} ({})", t.name, t.unit), &x_desc, &t.unit)
        .integer_x()
        .series(
            Series::points("pass", at(true), Marker::Circle)
                .marker(Marker::Circle, dot)
                .colour(0),
        )
        .series(
            Series::points("fail or error", at(false), Marker::Cross)
                .marker(Marker::Cross, dot + 2)
                .colour(1),
        );
    for (v, name) in [(t.low, "low limit"), (t.high, "high limit")] {
        if let Some(v) = v {
            c = c.rule(Rule {
                label: format!("{name} {v}"),
                at: v,
                vertical: false,
            });
        }
    }
    let chart = c.render();
    let f = |v: Option<f64>, d: usize| v.map_or("-".into(), |v| format!("{v:.d$}"));
    let body = format!(
        r#"<h1>{name}</h1>
<table><tr><th>values</th><th>judged</th><th>mean</th><th>sigma</th><th>min</th><th>max</th><th>limits</th><th>yield</th><th>Cpk</th></tr>
<tr><td class=num>{count}</td><td class=num>{judged}</td><td class=num>{mean}</td><td class=num>{sigma}</td><td class=num>{min}</td><td class=num>{max}</td><td class=num>{lo}..{hi}</td><td class=num>{yield_}</td><td class=num>{cpk}</td></tr></table>
{chart}
<p class=note>{shown} value(s) shown (at most the 5,000 newest), each run's latest part; units: {unit}.</p>
"#,
        name = esc(&t.name),
        unit = esc(&t.unit),
        count = t.count,
        judged = t.judged,
        mean = f(t.mean, 4),
        sigma = f(t.sigma, 4),
        min = f(t.min, 4),
        max = f(t.max, 4),
        lo = t.low.map_or(String::new(), |v| v.to_string()),
        hi = t.high.map_or(String::new(), |v| v.to_string()),
        yield_ = t
            .yield_fraction
            .map_or("-".into(), |y| format!("{:.1} %", 100.0 * y)),
        cpk = f(t.cpk, 2),
        shown = points.len(),
    );
    page(&format!("{}: trend", t.name), "", &body)
}
