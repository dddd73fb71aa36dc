//! `report.html`: one self-contained page, verdict first, charts drawn with
//! plotters into inline SVG (no scripts, no external files).

use plotters::prelude::*;

use super::Report;
use crate::analysis::figures::block_means;
use crate::analysis::model::{ModelKind, fit};
use crate::analysis::series::Interval;
use crate::procedure::Metric;
use crate::sequencer::Outcome;
use crate::sequencer::measure::{MeasureOutcome, Records};

const W: u32 = 900;
const H: u32 = 320;

pub(crate) fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The legend box every chart uses.
pub(crate) fn legend<'a, DB, CT>(
    c: &mut ChartContext<'a, DB, CT>,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB: DrawingBackend + 'a,
    DB::ErrorType: 'static,
    CT: CoordTranslate,
{
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// Draw into an SVG string; a drawing error becomes a note instead.
pub(crate) fn svg(
    draw: impl FnOnce(&mut String) -> Result<(), Box<dyn std::error::Error>>,
) -> String {
    let mut s = String::new();
    let drawn = draw(&mut s).map_err(|e| e.to_string());
    match drawn {
        Ok(()) => s,
        Err(e) => format!("<p class=note>chart not drawn: {}</p>", esc(&e)),
    }
}

/// Tick label of a category axis: `labels[i]` at x = i, nothing between.
pub(crate) fn label_at(labels: &[String], x: f64) -> String {
    let i = x.round();
    if (x - i).abs() < 0.01 && i >= 0.0 {
        labels.get(i as usize).cloned().unwrap_or_default()
    } else {
        String::new()
    }
}

pub(crate) fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = v
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(1e-6);
    (lo - pad, hi + pad)
}

/// Raw and compensated Earth-removed rate (60 s means) against time, over
/// the recorded (static) data: while the table moves, a 1 Hz reference
/// cannot follow it and the difference means nothing.
fn rate_chart(records: &Records, compensated: &[(f64, f64)]) -> String {
    let all: Vec<&Interval> = records
        .all
        .iter()
        .filter(|(recorded, _)| *recorded)
        .map(|(_, iv)| iv)
        .collect();
    let t: Vec<f64> = block_means(
        &all.iter().map(|i| i.time_s / 3600.0).collect::<Vec<_>>(),
        60,
    );
    let raw: Vec<f64> = block_means(&all.iter().map(|i| i.bias_dph()).collect::<Vec<_>>(), 60);
    let raw_pts: Vec<(f64, f64)> = t.iter().copied().zip(raw.iter().copied()).collect();
    svg(|s| {
        let root = SVGBackend::with_string(s, (W, H)).into_drawing_area();
        root.fill(&WHITE)?;
        let (x0, x1) = range(t.iter().copied());
        let (y0, y1) = range(raw.iter().copied().chain(compensated.iter().map(|p| p.1)));
        let mut c = ChartBuilder::on(&root)
            .caption("Rate, Earth rate removed (60 s means)", ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        c.configure_mesh()
            .x_desc("device time, h")
            .y_desc("deg/h")
            .draw()?;
        c.draw_series(LineSeries::new(raw_pts, &BLUE))?
            .label("raw")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLUE));
        if !compensated.is_empty() {
            c.draw_series(LineSeries::new(compensated.iter().copied(), &RED))?
                .label("model-4 compensated")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], RED));
        }
        legend(&mut c)?;
        root.present()?;
        Ok(())
    })
}

/// Chamber and gyro temperatures against time.
fn temperature_chart(records: &Records) -> String {
    let all: Vec<&Interval> = records.all.iter().map(|(_, iv)| iv).collect();
    let t = block_means(
        &all.iter().map(|i| i.time_s / 3600.0).collect::<Vec<_>>(),
        60,
    );
    let series: [(&str, RGBColor, Vec<f64>); 4] = [
        (
            "chamber",
            BLACK,
            block_means(&all.iter().map(|i| i.chamber_c).collect::<Vec<_>>(), 60),
        ),
        (
            "case",
            BLUE,
            block_means(&all.iter().map(|i| i.tcase_c).collect::<Vec<_>>(), 60),
        ),
        (
            "T1",
            RED,
            block_means(&all.iter().map(|i| i.t1_c).collect::<Vec<_>>(), 60),
        ),
        (
            "T2",
            GREEN,
            block_means(&all.iter().map(|i| i.t2_c).collect::<Vec<_>>(), 60),
        ),
    ];
    svg(|s| {
        let root = SVGBackend::with_string(s, (W, H)).into_drawing_area();
        root.fill(&WHITE)?;
        let (x0, x1) = range(t.iter().copied());
        let (y0, y1) = range(series.iter().flat_map(|(_, _, v)| v.iter().copied()));
        let mut c = ChartBuilder::on(&root)
            .caption("Temperatures (60 s means)", ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        c.configure_mesh()
            .x_desc("device time, h")
            .y_desc("degC")
            .draw()?;
        for (name, color, v) in &series {
            let color = *color;
            c.draw_series(LineSeries::new(
                t.iter().copied().zip(v.iter().copied()),
                color,
            ))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color));
        }
        legend(&mut c)?;
        root.present()?;
        Ok(())
    })
}

/// Bias stability per position against its limit.
fn position_chart(r: &Report) -> Option<String> {
    let pts: Vec<(String, f64, Option<f64>)> = r
        .measurements
        .iter()
        .filter(|m| m.metric == Metric::BiasStability)
        .filter_map(|m| Some((m.records.join("+"), m.value?, m.high)))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let spec = pts.iter().filter_map(|p| p.2).fold(f64::NAN, f64::max);
    Some(svg(|s| {
        let root = SVGBackend::with_string(s, (W, H)).into_drawing_area();
        root.fill(&WHITE)?;
        let ymax = pts.iter().map(|p| p.1).fold(spec.max(0.0), f64::max) * 1.2;
        let n = pts.len();
        let mut c = ChartBuilder::on(&root)
            .caption(
                "Bias stability per position (1-sigma of 100 s means) and the spec",
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), 0f64..ymax.max(1e-3))?;
        let labels: Vec<String> = pts.iter().map(|p| p.0.clone()).collect();
        c.configure_mesh()
            .x_labels(n)
            .x_label_formatter(&|x| label_at(&labels, *x))
            .y_desc("deg/h")
            .draw()?;
        c.draw_series(
            pts.iter()
                .enumerate()
                .map(|(i, p)| Circle::new((i as f64, p.1), 5, BLUE.filled())),
        )?;
        if spec.is_finite() {
            c.draw_series(LineSeries::new(
                vec![(-0.5, spec), (n as f64 - 0.5, spec)],
                RED.stroke_width(2),
            ))?
            .label(format!("spec {spec} deg/h"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], RED));
            legend(&mut c)?;
        }
        root.present()?;
        Ok(())
    }))
}

/// Allan deviation of the longest record judged for bias stability, with
/// its one-sigma intervals and the spec line.
fn allan_chart(r: &Report) -> Option<String> {
    let n = r.noise.as_ref()?;
    let dev: Vec<(f64, f64)> = n
        .tau_s
        .iter()
        .copied()
        .zip(n.adev_dph.iter().copied())
        .collect();
    let spec = r
        .measurements
        .iter()
        .filter(|m| m.metric == Metric::BiasStability)
        .filter_map(|m| m.high)
        .fold(f64::NAN, f64::max);
    Some(svg(|s| {
        let root = SVGBackend::with_string(s, (W, H)).into_drawing_area();
        root.fill(&WHITE)?;
        let (t0, t1) = (dev[0].0 / 1.2, dev[dev.len() - 1].0 * 1.2);
        let lo = n
            .lo_dph
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(f64::INFINITY, f64::min)
            .min(spec)
            * 0.5;
        let hi = n
            .hi_dph
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max)
            .max(spec)
            * 2.0;
        let mut c = ChartBuilder::on(&root)
            .caption(
                format!("Overlapping Allan deviation, record {}", n.record),
                ("sans-serif", 16),
            )
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(56)
            .build_cartesian_2d((t0..t1).log_scale(), (lo.max(1e-6)..hi).log_scale())?;
        c.configure_mesh()
            .x_desc("tau, s")
            .y_desc("deg/h")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.3}"))
            .draw()?;
        c.draw_series(LineSeries::new(dev.iter().copied(), &BLUE))?
            .label("ADEV, 1-sigma interval (Greenhall EDF)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLUE));
        c.draw_series(dev.iter().map(|&p| Circle::new(p, 3, BLUE.filled())))?;
        c.draw_series(
            n.tau_s
                .iter()
                .zip(n.lo_dph.iter().zip(&n.hi_dph))
                .filter(|(_, (l, h))| l.is_finite() && h.is_finite())
                .map(|(&t, (&l, &h))| PathElement::new(vec![(t, l), (t, h)], BLUE)),
        )?;
        if spec.is_finite() {
            c.draw_series(LineSeries::new(
                vec![(t0, spec), (t1, spec)],
                RED.stroke_width(2),
            ))?
            .label(format!("spec {spec} deg/h"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], RED));
        }
        legend(&mut c)?;
        root.present()?;
        Ok(())
    }))
}

/// The three "bias instability" figures, the judged one named.
fn noise_table(r: &Report) -> String {
    let Some(n) = &r.noise else {
        return String::new();
    };
    let f = |v: Option<f64>| v.map_or("n/a".to_owned(), |v| format!("{v:.4}"));
    format!(
        "<h2>Bias instability: three figures</h2>\n<p>Record {rec}. Judged: {judged}.</p>\n<table><tr><th>figure</th><th>deg/h</th><th></th></tr>\n<tr><td>bias stability, 1-sigma of {avg} s averages (GJB 2426A)</td><td class=num>{bs}</td><td>judged</td></tr>\n<tr><td>IEEE Std 952 coefficient B = ADEV floor / 0.664 (noise fit)</td><td class=num>{b}</td><td>shown</td></tr>\n<tr><td>raw ADEV minimum (at {tmin:.0} s)</td><td class=num>{min}</td><td>shown</td></tr></table>\n<p class=note>Noise fit on the same curve: ARW {arw:.5} deg/sqrt(h), rate random walk {rrw:.4} deg/h/sqrt(h) (from 1 Hz means).</p>\n",
        rec = esc(&n.record),
        judged = esc(&n.judged),
        avg = n.bias_stability_averaging_s,
        bs = f(n.bias_stability_dph),
        b = f(Some(n.ieee_b_dph)),
        min = f(Some(n.adev_min_dph)),
        tmin = n.adev_min_tau_s,
        arw = n.arw_deg_per_rt_h,
        rrw = n.rate_random_walk_dph_per_rt_h,
    )
}

/// Model-4 residual (60 s means, hours) over the records of the first
/// compensated-drift measurement, fitted on them.
fn compensated_series(r: &Report, records: &Records) -> Vec<(f64, f64)> {
    let Some(m) = r
        .measurements
        .iter()
        .find(|m| m.metric == Metric::CompensatedDriftPp)
    else {
        return Vec::new();
    };
    let series: Vec<Interval> = m
        .records
        .iter()
        .filter_map(|l| records.get(l))
        .flat_map(|s| s.iter().copied())
        .collect();
    let Ok(f) = fit(ModelKind::Model4, &series) else {
        return Vec::new();
    };
    let t = block_means(
        &series.iter().map(|i| i.time_s / 3600.0).collect::<Vec<_>>(),
        60,
    );
    let res = block_means(&f.residual(&series), 60);
    t.into_iter().zip(res).collect()
}

/// The whole page.
pub fn render_html(r: &Report, records: &Records) -> String {
    let (color, word) = match r.outcome {
        Outcome::Pass => ("#1b7f3b", "PASS"),
        Outcome::Fail => ("#b3261e", "FAIL"),
        Outcome::Error => ("#8a5a00", "ERROR"),
        Outcome::Aborted => ("#555555", "ABORTED"),
    };
    let mut rows = String::new();
    for m in &r.measurements {
        let ok = m.outcome == MeasureOutcome::Pass;
        rows.push_str(&format!(
            "<tr class={}><td>{}</td><td class=num>{}</td><td>{}</td><td class=num>{}</td><td class=num>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            if ok { "pass" } else { "fail" },
            esc(&m.name),
            m.value.map_or("n/a".into(), |v| format!("{v:.4}")),
            esc(&m.unit),
            m.low.map_or(String::new(), |v| v.to_string()),
            m.high.map_or(String::new(), |v| v.to_string()),
            m.outcome.as_str().to_uppercase(),
            esc(&m.step),
            esc(&m.note),
        ));
    }
    let error = r.error.as_ref().map_or(String::new(), |e| {
        format!(
            "<p class=error>Stopped in step <b>{}</b>{}: {}</p>",
            esc(&e.step),
            e.device
                .as_ref()
                .map_or(String::new(), |d| format!(" (device <b>{}</b>)", esc(d))),
            esc(&e.message)
        )
    });
    let mut charts = String::new();
    if !records.all.is_empty() {
        charts.push_str(&rate_chart(records, &compensated_series(r, records)));
        charts.push_str(&temperature_chart(records));
    }
    if let Some(c) = position_chart(r) {
        charts.push_str(&c);
    }
    if let Some(c) = allan_chart(r) {
        charts.push_str(&c);
    }
    let noise = noise_table(r);
    let l = &r.link;
    format!(
        r#"<!doctype html>
<html lang=en><head><meta charset=utf-8><title>{proc} {serial}: {word}</title>
<style>
body{{font-family:sans-serif;margin:2em;max-width:960px;color:#222}}
.verdict{{font-size:2.2em;font-weight:bold;color:#fff;background:{color};padding:.3em .6em;border-radius:.2em;display:inline-block}}
table{{border-collapse:collapse;margin:1em 0}} td,th{{border:1px solid #ccc;padding:.25em .5em;font-size:.9em}}
td.num{{text-align:right;font-family:monospace}} tr.fail td{{background:#fde7e6}} tr.pass td:nth-child(7){{color:#1b7f3b}}
.error{{background:#fff4e0;border-left:4px solid #8a5a00;padding:.5em}} .note{{color:#666}} svg{{display:block;margin:1em 0}}
</style></head><body>
<div class=verdict>{word}</div>
<h1>{proc} &mdash; {dut_type} {serial}</h1>
<p>Spec: {spec}<br>Started {start} &middot; {hours:.2} h of device time &middot; {frames} frames &middot; bench {bench}{seed} &middot; gyrobench {version}</p>
{error}
<h2>Measurements</h2>
<table><tr><th>name</th><th>value</th><th>unit</th><th>low</th><th>high</th><th>outcome</th><th>step</th><th>note</th></tr>
{rows}</table>
{noise}
<p class=note>Definitions: bias stability = 1-sigma of the averages over the averaging time of the Earth-removed rate; drift = peak-to-peak of the Earth-removed rate smoothed by a centred moving average of the averaging time; compensated = the same after the study's model 4; self-heating = mean of the first 120 s after power-on minus the mean of 1680..1800 s. See docs/figures.md.</p>
<h2>Charts</h2>
{charts}
<h2>Gyro link</h2>
<p>{lf} frames, {lost} lost, {crc} CRC errors, {res} resyncs, {dup} duplicates.{cleanup}</p>
</body></html>
"#,
        noise = noise,
        proc = esc(&r.procedure),
        serial = esc(&r.dut.serial),
        dut_type = esc(&r.dut.kind),
        spec = esc(&r.spec),
        start = esc(&r.start_time_utc),
        hours = r.device_time_s / 3600.0,
        frames = r.frames,
        bench = esc(&r.bench),
        seed = r.seed.map_or(String::new(), |s| format!(", seed {s}")),
        version = esc(&r.software_version),
        lf = l.frames,
        lost = l.lost_frames,
        crc = l.crc_errors,
        res = l.resyncs,
        dup = l.duplicates,
        cleanup = if r.cleanup_completed {
            ""
        } else {
            " <b>Cleanup did not complete: check the bench.</b>"
        },
    )
}
