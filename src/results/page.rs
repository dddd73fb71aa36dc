//! The trend chart page: a measurement's values across units in the order
//! their runs started, with the limits (one self-contained page, plotters
//! SVG, no scripts).

use plotters::prelude::*;

use super::query::Trend;
use crate::report::html::{esc, legend, svg};

/// The page of `t`, with `points` (start time, serial, value, outcome),
/// oldest first. Values are plotted in run order (an individuals chart):
/// runs a second apart and runs a month apart are each a point of their own.
pub fn trend_page(t: &Trend, points: &[(String, String, f64, String)]) -> String {
    let xy: Vec<(f64, f64, bool)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| ((i + 1) as f64, p.2, p.3 == "pass"))
        .collect();
    let day = |p: Option<&(String, String, f64, String)>| {
        p.map_or(String::new(), |p| p.0.chars().take(10).collect())
    };
    let x_desc = format!(
        "runs in the order they started, oldest first ({} to {})",
        day(points.first()),
        day(points.last())
    );
    // Points small enough that thousands stay points.
    let dot = match xy.len() {
        0..=100 => 4,
        101..=1000 => 2,
        _ => 1,
    };
    let chart = svg(|s| {
        let root = SVGBackend::with_string(s, (900, 360)).into_drawing_area();
        root.fill(&WHITE)?;
        let (x0, x1) = xy
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p.0), b.max(p.0))
            });
        let lims = [t.low, t.high];
        let (y0, y1) = xy
            .iter()
            .map(|p| p.1)
            .chain(lims.iter().flatten().copied())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        let pad = ((y1 - y0) * 0.1).max(1e-9);
        let xpad = ((x1 - x0) * 0.02).max(0.5);
        let mut c = ChartBuilder::on(&root)
            .caption(format!("{} ({})", t.name, t.unit), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(64)
            .build_cartesian_2d((x0 - xpad)..(x1 + xpad), (y0 - pad)..(y1 + pad))?;
        c.configure_mesh()
            .x_desc(x_desc.as_str())
            // Runs are whole numbers: ticks between them stay unlabelled.
            .x_label_formatter(&|v| {
                if (v - v.round()).abs() < 1e-6 {
                    format!("{v:.0}")
                } else {
                    String::new()
                }
            })
            .y_desc(t.unit.as_str())
            .label_style(("sans-serif", 14))
            .draw()?;
        c.draw_series(
            xy.iter()
                .filter(|p| p.2)
                .map(|p| Circle::new((p.0, p.1), dot, BLUE.filled())),
        )?
        .label("pass")
        .legend(|(x, y)| Circle::new((x + 8, y), 3, BLUE.filled()));
        c.draw_series(
            xy.iter()
                .filter(|p| !p.2)
                .map(|p| TriangleMarker::new((p.0, p.1), dot + 2, RED.filled())),
        )?
        .label("fail or error")
        .legend(|(x, y)| TriangleMarker::new((x + 8, y), 5, RED.filled()));
        for (v, name) in [(t.low, "low limit"), (t.high, "high limit")] {
            if let Some(v) = v {
                c.draw_series(LineSeries::new(
                    vec![(x0 - xpad, v), (x1 + xpad, v)],
                    BLACK.stroke_width(2),
                ))?
                .label(format!("{name} {v}"))
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK));
            }
        }
        legend(&mut c)?;
        root.present()?;
        Ok(())
    });
    let f = |v: Option<f64>, d: usize| v.map_or("-".into(), |v| format!("{v:.d$}"));
    format!(
        r#"<!doctype html>
<html lang=en><head><meta charset=utf-8><title>{name}: trend</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:960px;color:#222}}
table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;padding:.25em .6em}} td{{text-align:right;font-family:monospace}}</style>
</head><body>
<h1>{name}</h1>
<table><tr><th>values</th><th>judged</th><th>mean</th><th>sigma</th><th>min</th><th>max</th><th>limits</th><th>yield</th><th>Cpk</th></tr>
<tr><td>{count}</td><td>{judged}</td><td>{mean}</td><td>{sigma}</td><td>{min}</td><td>{max}</td><td>{lo}..{hi}</td><td>{yield_}</td><td>{cpk}</td></tr></table>
{chart}
<p>{shown} value(s) shown (at most the 5,000 newest), each run's latest part; units: {unit}.</p>
</body></html>
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
    )
}
