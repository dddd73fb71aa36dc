//! The trend chart page: a measurement's values across units in the order
//! their runs started, with the limits, the capability indices, and a
//! table of every value with its unit, run and report (one self-contained
//! page, plotters SVG, no scripts).

use std::path::Path;

use super::query::{Trend, TrendPoint};
use crate::sequencer::measure::MeasureOutcome;
use crate::view::chart::{Link, Rule};
use crate::view::{Chart, Marker, Series, esc, page};

/// The report of the run a point came from, as a link from a page in
/// `page_dir`: relative when the report sits below it, else a file URL.
/// A batch's unit has its own report beside the log, named as the batch
/// names it (`report-SERIAL.html`); a single unit's is `report.html`.
pub fn report_link(p: &TrendPoint, page_dir: &Path) -> Option<String> {
    let name = if p.slot.is_empty() {
        "report".to_owned()
    } else {
        crate::unit::report_name(&p.serial)
    };
    let report = Path::new(&p.log_path)
        .parent()?
        .join(format!("{name}.html"));
    let abs_page = std::path::absolute(page_dir).ok()?;
    Some(match report.strip_prefix(&abs_page) {
        Ok(rel) => rel.display().to_string(),
        Err(_) => format!("file://{}", report.display()),
    })
}

/// The day of an RFC 3339 time, or `undated`.
fn day(t: &str) -> String {
    let d: String = t.chars().take(10).collect();
    if d.len() == 10 { d } else { "undated".into() }
}

/// The page of `t`, with `points` oldest first; `link` gives each point's
/// report. Values are plotted in run order (an individuals chart): runs a
/// second apart and runs a month apart are each a point of their own, and
/// the point's number is its row in the table below.
pub fn trend_page(
    t: &Trend,
    points: &[TrendPoint],
    link: &dyn Fn(&TrendPoint) -> Option<String>,
) -> String {
    let mut c = values_chart(t, points);
    let mut rows = String::new();
    for (i, p) in points.iter().enumerate() {
        let href = link(p);
        c = c.link(Link {
            x: (i + 1) as f64,
            y: p.value,
            title: point_title(t, i, p),
            href: href.clone(),
        });
        rows.push_str(&table_row(i, p, href));
    }
    let chart = c.render();
    let body = page_body(t, points.len(), &chart, &rows);
    page(
        &format!("{}: trend", t.name),
        "td.nw{white-space:nowrap}",
        &body,
    )
}

/// The chart of the values in run order, passes and the rest apart, with
/// the limits as rules (the points' links are added by the caller).
fn values_chart(t: &Trend, points: &[TrendPoint]) -> Chart {
    let at = |pass: bool| -> Vec<(f64, f64)> {
        points
            .iter()
            .enumerate()
            .filter(|(_, p)| (p.outcome == MeasureOutcome::Pass) == pass)
            .map(|(i, p)| ((i + 1) as f64, p.value))
            .collect()
    };
    let x_desc = match (points.first(), points.last()) {
        (Some(a), Some(b)) => format!(
            "runs in the order they started, oldest first ({} to {})",
            day(&a.started_utc),
            day(&b.started_utc)
        ),
        _ => "runs in the order they started".into(),
    };
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
    c
}

/// What a point (the `i`th, from 0) says when the pointer is over it.
fn point_title(t: &Trend, i: usize, p: &TrendPoint) -> String {
    format!(
        "#{} {} run {} ({}): {} {} {}",
        i + 1,
        p.serial,
        short(&p.run),
        day(&p.started_utc),
        crate::view::num(Some(p.value), 4),
        t.unit,
        outcome_word(p)
    )
}

/// The row of the values table for the `i`th point (from 0), with a link
/// to its report when `href` has one.
fn table_row(i: usize, p: &TrendPoint, href: Option<String>) -> String {
    let report = href.map_or("-".into(), |h| {
        format!("<a href=\"{}\">report</a>", esc(&h))
    });
    format!(
        "<tr class={o}><td class=num>{n}</td><td class=nw>{serial}</td><td><code>{run}</code></td><td class=nw>{start}</td><td class=num>{v}</td><td class=\"outcome {o}\">{word}</td><td>{report}</td></tr>\n",
        n = i + 1,
        serial = esc(&p.serial),
        run = esc(&p.run),
        start = esc(&crate::view::utc_seconds(&p.started_utc)),
        v = crate::view::num(Some(p.value), 4),
        o = p.outcome.as_str(),
        word = esc(&outcome_word(p)),
    )
}

/// The page's body: the summary and capability tables, the chart, and the
/// values table (`rows`) of the `shown` points.
fn page_body(t: &Trend, shown: usize, chart: &str, rows: &str) -> String {
    let f = |v: Option<f64>, d: usize| v.map_or("-".into(), |v| format!("{v:.d$}"));
    format!(
        r#"<h1>{name}</h1>
<table><tr><th>values</th><th>judged</th><th>mean</th><th>sigma</th><th>min</th><th>max</th><th>limits</th><th>yield</th></tr>
<tr><td class=num>{count}</td><td class=num>{judged}</td><td class=num>{mean}</td><td class=num>{sigma}</td><td class=num>{min}</td><td class=num>{max}</td><td class=num>{lo}..{hi}</td><td class=num>{yield_}</td></tr></table>
<table><tr><th></th><th>upper</th><th>lower</th><th>index</th><th>sigma</th></tr>
<tr><td>capability (run to run)</td><td class=num>Cpu {cpu}</td><td class=num>Cpl {cpl}</td><td class=num>Cpk {cpk}</td><td class=num>{sw} (moving ranges / 1.128)</td></tr>
<tr><td>performance (all data)</td><td class=num>Ppu {ppu}</td><td class=num>Ppl {ppl}</td><td class=num>Ppk {ppk}</td><td class=num>{sigma} (sample)</td></tr>
{percentile}</table>
<p class=note>{caveat}A figure with one limit is judged on that side alone: Cpk is then Cpu (or Cpl), Ppk is Ppu (or Ppl). Definitions in docs/results.md.</p>
{chart}
<p class=note>{shown} value(s) shown (at most the 5,000 newest), each run's latest part; units: {unit}. Point over a dot to see its unit and run; click it for the run's report.</p>
<h2>Values</h2>
<table><tr><th>#</th><th>unit</th><th>run</th><th>started (UTC)</th><th>value</th><th>outcome</th><th>report</th></tr>
{rows}</table>
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
        cpu = f(t.within.upper, 2),
        cpl = f(t.within.lower, 2),
        cpk = f(t.within.k, 2),
        sw = f(t.sigma_within, 4),
        ppu = f(t.overall.upper, 2),
        ppl = f(t.overall.lower, 2),
        ppk = f(t.overall.k, 2),
        caveat = esc(&t.caveat()).replace('\n', "<br>"),
        percentile = t.percentile.map_or(String::new(), |p| format!(
            "<tr><td>performance by percentiles ({}, ISO 22514-2){}</td><td class=num>Ppu {}</td><td class=num>Ppl {}</td><td class=num>Ppk {}</td><td class=num>X50 {} X99.865 {}</td></tr>",
            p.model,
            if p.preferred { ": <b>the one to read</b>" } else { "" },
            f(p.upper, 2),
            f(p.lower, 2),
            f(p.k, 2),
            f(Some(p.x_50), 4),
            f(Some(p.x_99865), 4),
        )),
    )
}

/// `PASS`, `FAIL`, or `PASS (reference)` for an imported run's figure.
fn outcome_word(p: &TrendPoint) -> String {
    let w = p.outcome.as_str().to_uppercase();
    if p.reference {
        format!("{w} (reference: imported)")
    } else {
        w
    }
}

/// The first 12 characters of a run key (its run id's start).
fn short(run: &str) -> &str {
    run.get(..12).unwrap_or(run)
}
