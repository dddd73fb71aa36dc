//! `report.html`: one self-contained page, verdict first, then the figure
//! the unit is accepted on drawn against its limit, the measurements, the
//! nine positions, the rate-table figures, the noise figures and the run's
//! traces. Charts come from
//! the shared helper (`view::chart`); nothing is fetched, nothing runs.

use super::{Position, Report};
use crate::analysis::figures::{DriftTrace, block_means};
use crate::analysis::rate::{
    DEAD_BAND_SHARE, RatePoint, THRESHOLD_SHARE, Transfer, input_for_share, lock_in, locked_output,
};
use crate::analysis::series::Interval;
use crate::procedure::Metric;
use crate::sequencer::Outcome;
use crate::sequencer::measure::{MeasureOutcome, Records};
use crate::view::chart::{Band, Rule};
use crate::view::{Chart, Marker, Series, Stroke, esc, limit, num, page, utc_seconds};
use gyrobench_model::measurement::Measurement;

/// 60 s means against device time in hours.
fn means_h(iv: &[Interval], f: impl Fn(&Interval) -> f64) -> Vec<(f64, f64)> {
    let t = block_means(
        &iv.iter().map(|i| i.time_s / 3600.0).collect::<Vec<_>>(),
        60,
    );
    let v = block_means(&iv.iter().map(&f).collect::<Vec<_>>(), 60);
    t.into_iter().zip(v).collect()
}

/// [`means_h`] of each of `fs` over the run's intervals (those in a record
/// alone when `recorded`), read 60 at a time: a chart of a long run holds
/// its means, not its intervals. Also the number of intervals read.
fn run_means_h(
    records: &Records,
    recorded: bool,
    fs: &[fn(&Interval) -> f64],
) -> (usize, Vec<Vec<(f64, f64)>>) {
    let mut block = Vec::with_capacity(60);
    let mut out = vec![Vec::new(); fs.len()];
    let mut n = 0;
    records.for_each_interval(|rec, iv| {
        if recorded && !rec {
            return;
        }
        n += 1;
        block.push(iv);
        if block.len() == 60 {
            for (o, f) in out.iter_mut().zip(fs) {
                o.extend(means_h(&block, f));
            }
            block.clear();
        }
    });
    (n, out)
}

/// A trace's stretches as one series in hours (the gaps between
/// stretches break the line).
fn trace_h(t: &DriftTrace) -> Vec<(f64, f64)> {
    t.parts
        .iter()
        .flatten()
        .map(|&(s, v)| (s / 3600.0, v))
        .collect()
}

/// The headline: the compensated drift's smoothed residual on its own
/// scale, inside a band as tall as the limit centred on it (the trace
/// fits in the band exactly when the drift is within the limit), with the
/// highest and lowest points the peak-to-peak is taken between.
fn drift_chart(m: &Measurement) -> Option<String> {
    let t = m.trace.as_ref()?;
    let pts = trace_h(t);
    let (hi_t, hi) = (t.max.0 / 3600.0, t.max.1);
    let (lo_t, lo) = (t.min.0 / 3600.0, t.min.1);
    let mid = (hi + lo) / 2.0;
    let mut c = Chart::new(
        format!(
            "{}: {} {} peak to peak ({})",
            m.name,
            num(m.value, 4),
            m.unit,
            m.outcome.as_str().to_uppercase()
        ),
        "device time, h",
        &m.unit,
    )
    .series(
        Series::line(
            format!(
                "residual after model 4, {:.0} s centred moving average",
                m.averaging_s
            ),
            pts,
        )
        .colour(0)
        .width(2),
    )
    .series(
        Series::points(
            format!("highest {hi:+.4}"),
            vec![(hi_t, hi)],
            Marker::Triangle,
        )
        .colour(1)
        .marker(Marker::Triangle, 6),
    )
    .series(
        Series::points(
            format!("lowest {lo:+.4}"),
            vec![(lo_t, lo)],
            Marker::TriangleDown,
        )
        .colour(2)
        .marker(Marker::TriangleDown, 6),
    );
    if let Some(h) = m.high {
        c = c.band(Band {
            label: format!("limit: {h} {} peak to peak, centred on the trace", m.unit),
            y: (mid - h / 2.0, mid + h / 2.0),
            x: None,
        });
    }
    Some(
        c.caption(format!(
            "The drift is the highest minus the lowest point of this trace: {:.4} - ({:.4}) = {:.4} {}. {}",
            hi,
            lo,
            hi - lo,
            m.unit,
            sentence(&m.note)
        ))
        .render(),
    )
}

/// A note as a sentence (the chart escapes its caption).
fn sentence(s: &str) -> String {
    let s = s.trim();
    let mut c = s.chars();
    let s = match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect::<String>(),
        None => return String::new(),
    };
    if s.ends_with('.') { s } else { format!("{s}.") }
}

/// Raw Earth-removed rate (60 s means) over the recorded (static) data,
/// with the raw drift's smoothed trace. While the table moves a 1 Hz
/// reference cannot follow it, so those stretches are left out (and the
/// line breaks there).
fn rate_chart(r: &Report, records: &Records) -> Option<String> {
    let (n, mut means) = run_means_h(records, true, &[Interval::bias_dph]);
    if n < 120 {
        return None;
    }
    let mut c = Chart::new(
        "Rate, Earth rate removed (recorded data)",
        "device time, h",
        "deg/h",
    )
    .series(
        Series::line("60 s means", means.pop().unwrap_or_default())
            .colour(5)
            .width(1),
    );
    let raw = r
        .measurements
        .iter()
        .find(|m| m.metric == Metric::DriftPp && m.trace.is_some());
    if let Some((m, t)) = raw.and_then(|m| Some((m, m.trace.as_ref()?))) {
        c = c.series(
            Series::line(
                format!(
                    "{:.0} s moving average ({}: {} {})",
                    m.averaging_s,
                    m.name,
                    num(m.value, 4),
                    m.unit
                ),
                trace_h(t),
            )
            .colour(0)
            .stroke(Stroke::Dashed)
            .width(3),
        );
    }
    Some(c.render())
}

/// The turn-ons: the bias after each (the repeatability's points), the
/// warm-up curves overlaid from turn-on, and the current the unit drew.
/// Empty for a run without power steps or supply readings.
fn turn_on_section(r: &Report, records: &Records) -> String {
    let charts: String = [
        repeatability_chart(r, records),
        warm_up_chart(r, records),
        current_chart(records),
    ]
    .into_iter()
    .flatten()
    .collect();
    if charts.is_empty() {
        String::new()
    } else {
        format!("<h2>Turn-ons</h2>\n{charts}")
    }
}

/// The mean Earth-removed rate of each record a bias repeatability is
/// taken on, in turn-on order, with their mean and the 1-sigma band.
fn repeatability_chart(r: &Report, records: &Records) -> Option<String> {
    let m = r
        .measurements
        .iter()
        .find(|m| m.metric == Metric::BiasRepeatability)?;
    let (labels, means): (Vec<String>, Vec<f64>) = m
        .records
        .iter()
        .filter_map(|l| {
            let ivs = records.get(l).filter(|v| !v.is_empty())?;
            let b: Vec<f64> = ivs.iter().map(Interval::bias_dph).collect();
            Some((l.clone(), crate::analysis::figures::mean(&b)))
        })
        .unzip();
    if means.len() < 2 {
        return None;
    }
    let all = crate::analysis::figures::mean(&means);
    let n = means.len() as f64;
    let points = means
        .iter()
        .enumerate()
        .map(|(i, &b)| (i as f64, b))
        .collect();
    let mut c = Chart::new(
        format!(
            "{}: {} {} over {} turn-ons ({})",
            m.name,
            num(m.value, 4),
            m.unit,
            means.len(),
            m.outcome.as_str().to_uppercase()
        ),
        "turn-on (record)",
        "deg/h",
    )
    .categories(labels)
    .height(300)
    .series(
        Series::points("mean bias after the warm-up", points, Marker::Circle)
            .marker(Marker::Circle, 6)
            .colour(0),
    )
    .rule(Rule {
        label: format!("mean {all:+.4}"),
        at: all,
        vertical: false,
    });
    if let Some(s) = m.value {
        c = c.band(Band {
            label: format!("mean ± 1 sigma ({s:.4} deg/h)"),
            y: (all - s, all + s),
            x: Some((-0.5, n - 0.5)),
        });
    }
    Some(
        c.caption(format!(
            "Each point is one record's mean Earth-removed rate, made after its own turn-on and the same warm-up. The repeatability is their sample standard deviation{}.",
            m.std_error
                .map_or(String::new(), |e| format!(", known to ±{e:.4} deg/h for {} turn-ons", means.len()))
        ))
        .render(),
    )
}

/// Each warm-up record's moving mean from turn-on, overlaid, with the
/// time each warm-up figure found marked on its curve.
fn warm_up_chart(r: &Report, records: &Records) -> Option<String> {
    let warm: Vec<&Measurement> = r
        .measurements
        .iter()
        .filter(|m| m.metric == Metric::WarmUpTime)
        .collect();
    let first = warm.first()?;
    let mut c = Chart::new(
        format!(
            "Warm-up from each turn-on ({:.0} s moving means)",
            first.averaging_s
        ),
        "time from the record's start, min",
        "deg/h",
    );
    let mut marks = Vec::new();
    let mut drawn = 0;
    for (k, m) in warm.iter().enumerate() {
        let Some(ivs) = m.records.first().and_then(|l| records.get(l)) else {
            continue;
        };
        let (Some(a), Some(b)) = (ivs.first(), ivs.get(1)) else {
            continue;
        };
        let dt = b.time_s - a.time_s;
        let window = (m.averaging_s / dt).round().max(1.0) as usize;
        let bias: Vec<f64> = ivs.iter().map(Interval::bias_dph).collect();
        let means = crate::analysis::figures::moving_average(&bias, window);
        // A point every tenth of the window is plenty for the eye.
        let every = (window / 10).max(1);
        let pts: Vec<(f64, f64)> = means
            .iter()
            .enumerate()
            .step_by(every)
            .map(|(i, &v)| ((i + window) as f64 * dt / 60.0, v))
            .collect();
        if pts.is_empty() {
            continue;
        }
        if let Some(t) = m.value {
            let i = ((t / dt).round() as usize).saturating_sub(window);
            if let Some(&v) = means.get(i) {
                marks.push((t / 60.0, v));
            }
        }
        c = c.series(
            Series::line(m.records.first().cloned().unwrap_or_default(), pts)
                .colour(k)
                .width(1),
        );
        drawn += 1;
    }
    if drawn == 0 {
        return None;
    }
    if !marks.is_empty() {
        c = c.series(
            Series::points(
                "warm: the moving mean stays in its band from here",
                marks,
                Marker::Diamond,
            )
            .marker(Marker::Diamond, 5)
            .colour(7),
        );
    }
    Some(
        c.caption(format!(
            "{drawn} warm-ups, each from its own turn-on. A warm-up time is where its curve enters, for good, a band of ±{} deg/h around its settled value (the mean of the record's last quarter).",
            first.band.unwrap_or(0.0)
        ))
        .render(),
    )
}

/// The supply current against device time (60-reading means), with each
/// turn-on's highest reading; none for a run that switched nothing on
/// (the unit powered throughout: no turn-on to show).
fn current_chart(records: &Records) -> Option<String> {
    let n = records.power_len();
    if n < 2 {
        return None;
    }
    let block = if n > 2000 { 60 } else { 1 };
    // The readings are read in order, `block` at a time into a mean.
    let mut means: Vec<(f64, f64)> = Vec::new();
    let (mut t, mut a) = (Vec::with_capacity(block), Vec::with_capacity(block));
    // Each stretch with the output on that began with a turn-on (not
    // the run's start), and its highest reading.
    let mut peaks = Vec::new();
    let mut best: Option<(f64, f64)> = None;
    let mut was_off = false;
    records.for_each_power(|s| {
        t.push(s.t_s / 3600.0);
        a.push(s.a);
        if t.len() == block {
            means.extend(
                block_means(&t, block)
                    .into_iter()
                    .zip(block_means(&a, block)),
            );
            t.clear();
            a.clear();
        }
        if s.on && was_off {
            if best.is_none_or(|(_, a)| s.a > a) {
                best = Some((s.t_s / 3600.0, s.a));
            }
        } else if !s.on {
            was_off = true;
            peaks.extend(best.take());
        }
    });
    peaks.extend(best);
    if peaks.is_empty() {
        return None;
    }
    let top = peaks.iter().chain(&means).map(|p| p.1).fold(0.0, f64::max);
    let c = Chart::new("Supply current", "device time, h", "A")
        .y_range(0.0, 1.1 * top.max(0.01))
        .series(
            Series::line(
                if block > 1 {
                    "means of 60 readings"
                } else {
                    "readings"
                },
                means,
            )
            .colour(0)
            .width(1)
            .gap(None),
        )
        .series(
            Series::points("highest reading of each turn-on", peaks, Marker::Triangle)
                .marker(Marker::Triangle, 5)
                .colour(1),
        );
    Some(
        c.caption("The unit draws its current only while the supply's output is on; the highest reading of each turn-on is its inrush as read at 50 Hz in the turn-on's first second (the means smooth it away).")
            .render(),
    )
}

/// Chamber air and the gyro's sensors against time, each with its own
/// line style.
fn temperature_chart(records: &Records) -> Option<String> {
    let (n, means) = run_means_h(
        records,
        false,
        &[|i| i.chamber_c, |i| i.tcase_c, |i| i.t1_c, |i| i.t2_c],
    );
    if n < 120 {
        return None;
    }
    let [air, case, t1, t2] = <[Vec<(f64, f64)>; 4]>::try_from(means).unwrap_or_default();
    Some(
        Chart::new("Temperatures (60 s means)", "device time, h", "degC")
            .series(Series::line("chamber air", air).colour(6).width(2))
            .series(
                Series::line("case", case)
                    .colour(0)
                    .stroke(Stroke::Dashed)
                    .width(2),
            )
            .series(Series::line("block T1", t1).colour(1).width(2))
            .series(
                Series::line("block T2", t2)
                    .colour(2)
                    .stroke(Stroke::Dotted)
                    .width(3),
            )
            .render(),
    )
}

/// A measurement of `metric` on exactly the record `label`.
fn of_record<'a>(r: &'a Report, metric: Metric, label: &str) -> Option<&'a Measurement> {
    r.measurements
        .iter()
        .find(|m| m.metric == metric && m.records.len() == 1 && m.records[0] == label)
}

/// A position with its two figures.
struct Row<'a> {
    position: &'a Position,
    bias: Option<&'a Measurement>,
    stability: Option<&'a Measurement>,
}

/// One figure per position, against its limits (the first row's: a
/// procedure gives every position the same).
fn position_chart<'a>(
    title: &str,
    rows: &[Row<'a>],
    pick: impl Fn(&Row<'a>) -> Option<&'a Measurement>,
) -> String {
    let Some(first) = rows.iter().find_map(&pick) else {
        return String::new();
    };
    let labels: Vec<String> = rows.iter().map(|x| x.position.record.clone()).collect();
    let at = |pass: bool| -> Vec<(f64, f64)> {
        rows.iter()
            .enumerate()
            .filter_map(|(i, x)| {
                let m = pick(x)?;
                ((m.outcome == MeasureOutcome::Pass) == pass).then_some((i as f64, m.value?))
            })
            .collect()
    };
    let (good, bad) = (at(true), at(false));
    let mut c = Chart::new(title, "position (record)", &first.unit)
        .categories(labels.clone())
        .height(300)
        .series(
            Series::points("within its limits", good, Marker::Circle)
                .marker(Marker::Circle, 6)
                .colour(0),
        );
    if !bad.is_empty() {
        c = c.series(
            Series::points("outside its limits or not judged", bad, Marker::Cross)
                .marker(Marker::Cross, 8)
                .colour(1),
        );
    }
    let n = labels.len() as f64;
    match (first.low, first.high) {
        (lo, Some(hi)) => {
            c = c.band(Band {
                label: format!("limits {}..{} {}", limit(first.low), hi, first.unit),
                y: (lo.unwrap_or(0.0), hi),
                x: Some((-0.5, n - 0.5)),
            });
        }
        (Some(lo), None) => {
            c = c.rule(Rule {
                label: format!("low limit {lo}"),
                at: lo,
                vertical: false,
            });
        }
        (None, None) => {}
    }
    c.render()
}

/// The points of a rate measurement's records, in input order: those of
/// a scale-factor figure as it took them (in the angle domain), the
/// others' from their 1 Hz means.
fn rate_points(m: &Measurement, records: &Records) -> Vec<RatePoint> {
    let angle_domain = matches!(
        m.metric,
        Metric::ScaleFactor | Metric::ScaleFactorNonlinearity | Metric::ScaleFactorAsymmetry
    );
    let mut pts: Vec<RatePoint> = m
        .records
        .iter()
        .filter_map(|l| {
            if angle_domain {
                records.rate_point(l).map(|(p, _)| p)
            } else {
                RatePoint::of(&records.get(l)?)
            }
        })
        .collect();
    pts.sort_by(|a, b| a.input_dph.total_cmp(&b.input_dph));
    pts
}

/// The rate-table figures drawn: each record's residual from the transfer
/// fit in ppm (with its standard error and the nonlinearity limit), and
/// near zero the output against the input with the lock-in fit.
fn rate_table_charts(r: &Report, records: &Records) -> String {
    let transfer = r.measurements.iter().find(|m| {
        matches!(
            m.metric,
            Metric::ScaleFactorNonlinearity | Metric::ScaleFactor | Metric::ScaleFactorAsymmetry
        )
    });
    let band = r
        .measurements
        .iter()
        .find(|m| matches!(m.metric, Metric::DeadBand | Metric::Threshold));
    let out: String = [
        transfer.and_then(|m| transfer_chart(r, m, records)),
        band.and_then(|m| lock_in_chart(m, records)),
    ]
    .into_iter()
    .flatten()
    .collect();
    if out.is_empty() {
        out
    } else {
        format!("<h2>Rate table</h2>\n{out}")
    }
}

/// Each rate record's residual from the transfer fit of `m`'s records, in
/// ppm, with its standard error and the nonlinearity limit.
fn transfer_chart(r: &Report, m: &Measurement, records: &Records) -> Option<String> {
    let pts = rate_points(m, records);
    let t = Transfer::fit(&pts)?;
    let labels: Vec<String> = pts
        .iter()
        .map(|p| format!("{:+}", (p.input_dph / 3600.0 * 10.0).round() / 10.0))
        .collect();
    let resid: Vec<(f64, f64, f64)> = pts
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let net = (t.output_dph(p.input_dph) - t.bias_dph).abs().max(1e-12);
            let r = (p.output_dph - t.output_dph(p.input_dph)) / net * 1e6;
            let se = p.se_dph / net * 1e6;
            (i as f64, r, se)
        })
        .collect();
    let mut c = Chart::new(
        format!(
            "Scale-factor residuals: K+ {:.1} ppm, K- {:.1} ppm from nominal, bias {:.3} deg/h",
            (t.k_pos - 1.0) * 1e6,
            (t.k_neg - 1.0) * 1e6,
            t.bias_dph
        ),
        "input rate (table + Earth), deg/s",
        "residual, ppm of the output",
    )
    .categories(labels)
    .height(320)
    .series(
        Series::points(
            "record mean minus the transfer fit (one slope per direction), with its standard error",
            resid.iter().map(|(x, y, _)| (*x, *y)).collect(),
            Marker::Circle,
        )
        .marker(Marker::Circle, 6)
        .colour(0)
        .errors(resid.iter().map(|(x, y, e)| (*x, y - e, y + e)).collect()),
    );
    if let Some(nl) = r
        .measurements
        .iter()
        .find(|m| m.metric == Metric::ScaleFactorNonlinearity)
        && let Some(hi) = nl.high
    {
        c = c.band(Band {
            label: format!("nonlinearity limit +-{hi} ppm"),
            y: (-hi, hi),
            x: Some((-0.5, pts.len() as f64 - 0.5)),
        });
    }
    Some(c.render())
}

/// The output against the input near zero with the lock-in fit of `m`'s
/// records.
fn lock_in_chart(m: &Measurement, records: &Records) -> Option<String> {
    let pts = rate_points(m, records);
    let (b, l, _) = lock_in(&pts)?;
    let (lo, hi) = (
        pts.first().map_or(0.0, |p| p.input_dph),
        pts.last().map_or(0.0, |p| p.input_dph),
    );
    let curve: Vec<(f64, f64)> = (0..=400)
        .map(|i| {
            let x = lo + (hi - lo) * f64::from(i) / 400.0;
            (x, locked_output(x, b, l))
        })
        .collect();
    let c = Chart::new(
            format!(
                "Output near zero input: lock-in {l:.3} deg/h, dead band {:.3} deg/h, threshold {:.3} deg/h",
                input_for_share(l, DEAD_BAND_SHARE),
                input_for_share(l, THRESHOLD_SHARE)
            ),
            "input rate (table + Earth), deg/h",
            "output rate, deg/h",
        )
        .height(320)
        .series(
            Series::line(
                format!("no lock-in: output = input + bias ({b:.3} deg/h)"),
                vec![(lo, lo + b), (hi, hi + b)],
            )
            .colour(2)
            .stroke(Stroke::Dashed)
            .width(1),
        )
        .series(
            Series::line("lock-in fit (Adler equation)", curve)
                .colour(5)
                .width(2),
        )
        .series(
            Series::points(
                "record means",
                pts.iter().map(|p| (p.input_dph, p.output_dph)).collect(),
                Marker::Circle,
            )
            .marker(Marker::Circle, 6)
            .colour(0),
        );
    Some(c.render())
}

/// The positions: a table (the record, the position in the operator's
/// words, the table angles, bias and bias stability side by side) and a
/// chart of each figure against its limit band.
fn positions(r: &Report) -> String {
    let rows: Vec<Row<'_>> = r
        .positions
        .iter()
        .map(|p| Row {
            position: p,
            bias: of_record(r, Metric::MeanBias, &p.record),
            stability: of_record(r, Metric::BiasStability, &p.record),
        })
        .filter(|x| x.bias.is_some() || x.stability.is_some())
        .collect();
    if rows.len() < 2 {
        return String::new();
    }
    let cell = |m: Option<&Measurement>| {
        m.map_or("<td></td><td></td>".to_owned(), |m| {
            format!(
                "<td class=num>{}</td><td class=\"outcome {}\">{}</td>",
                num(m.value, 4),
                m.outcome.as_str(),
                m.outcome.as_str().to_uppercase()
            )
        })
    };
    let lim = |m: &Measurement| format!("{}..{} {}", limit(m.low), limit(m.high), m.unit);
    let bias = rows.iter().find_map(|x| x.bias);
    let stability = rows.iter().find_map(|x| x.stability);
    // A figure no position has (an imported run judges no mean bias) gets
    // no column and no limit (and `position_chart` draws no chart).
    let mut table = String::new();
    for x in &rows {
        let p = x.position;
        table.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td class=num>{}</td><td class=num>{}</td>{}{}</tr>\n",
            esc(&p.record),
            esc(&p.description),
            p.table
                .map_or("-".into(), |t| format!("{:.2}", t.outer_deg)),
            p.table
                .map_or("-".into(), |t| format!("{:.2}", t.inner_deg)),
            bias.map_or(String::new(), |_| cell(x.bias)),
            stability.map_or(String::new(), |_| cell(x.stability)),
        ));
    }
    let head = |m: Option<&Measurement>, name: &str| {
        m.map_or(String::new(), |m| {
            format!("<th>{name}, {}</th><th></th>", esc(&m.unit))
        })
    };
    let limits: Vec<String> = [(bias, "bias"), (stability, "bias stability")]
        .into_iter()
        .filter_map(|(m, name)| m.map(|m| format!("{name} {}", esc(&lim(m)))))
        .collect();
    format!(
        "<h2>Positions</h2>\n<table><tr><th>record</th><th>position</th><th>outer, deg</th><th>inner, deg</th>{bh}{sh}</tr>\n{table}</table>\n<p class=note>Limits: {limits}.</p>\n{c1}{c2}",
        bh = head(bias, "bias"),
        sh = head(stability, "bias stability"),
        limits = limits.join("; "),
        c1 = position_chart(
            "Bias stability per position, against its limit",
            &rows,
            |x| x.stability
        ),
        c2 = position_chart("Bias per position, against its limits", &rows, |x| x.bias),
    )
}

/// Allan deviation of the longest record judged for bias stability, with
/// its one-sigma intervals; the spec is drawn where it applies: at the
/// bias stability's averaging time, beside the judged figure.
fn allan_chart(r: &Report) -> Option<String> {
    let n = r.noise.as_ref()?;
    let dev: Vec<(f64, f64)> = n
        .tau_s
        .iter()
        .copied()
        .zip(n.adev_dph.iter().copied())
        .collect();
    let errors: Vec<(f64, f64, f64)> = n
        .tau_s
        .iter()
        .zip(n.lo_dph.iter().zip(&n.hi_dph))
        .filter(|(_, (l, h))| l.is_finite() && h.is_finite() && **l > 0.0)
        .map(|(&t, (&l, &h))| (t, l, h))
        .collect();
    let tau = n.bias_stability_averaging_s;
    let spec = r
        .measurements
        .iter()
        .filter(|m| m.metric == Metric::BiasStability && m.records.contains(&n.record))
        .find_map(|m| m.high);
    let mut c = Chart::new(
        format!("Overlapping Allan deviation, record {}", n.record),
        "averaging time tau, s",
        "deg/h",
    )
    .log_x()
    .log_y()
    .series(
        Series::line("ADEV with 1-sigma interval (Greenhall EDF)", dev)
            .colour(0)
            .marker(Marker::Circle, 3)
            .gap(None)
            .errors(errors),
    );
    if let Some(bs) = n.bias_stability_dph {
        c = c.series(
            Series::points(
                format!("bias stability judged: 1-sigma of {tau:.0} s means, {bs:.4}"),
                vec![(tau, bs)],
                Marker::Diamond,
            )
            .colour(2)
            .marker(Marker::Diamond, 7),
        );
    }
    if let Some(spec) = spec {
        c = c.series(
            Series::line(
                format!("spec {spec} deg/h, at tau = {tau:.0} s only"),
                vec![(tau / 1.6, spec), (tau * 1.6, spec)],
            )
            .colour(1)
            .width(4)
            .gap(None),
        );
    }
    Some(
        c.caption(format!(
            "The spec bounds the bias stability, the scatter of {tau:.0} s means; it says nothing about the curve at other averaging times."
        ))
        .render(),
    )
}

/// The three "bias instability" figures, the judged one named.
fn noise_table(r: &Report) -> String {
    let Some(n) = &r.noise else {
        return String::new();
    };
    format!(
        "<h2>Bias instability: three figures</h2>\n<p>Record {rec}. Judged: {judged}.</p>\n<table><tr><th>figure</th><th>deg/h</th><th></th></tr>\n<tr><td>bias stability, 1-sigma of {avg} s averages (GJB 2426A)</td><td class=num>{bs}</td><td>judged</td></tr>\n<tr><td>IEEE Std 952 coefficient B = ADEV floor / 0.664 (noise fit)</td><td class=num>{b}</td><td>shown</td></tr>\n<tr><td>raw ADEV minimum (at {tmin:.0} s)</td><td class=num>{min}</td><td>shown</td></tr></table>\n<p class=note>Noise fit on the same curve: ARW {arw}, rate random walk {rrw} (from 1 Hz means).</p>\n",
        rec = esc(&n.record),
        judged = esc(&n.judged),
        avg = n.bias_stability_averaging_s,
        bs = num(n.bias_stability_dph, 4),
        b = num(n.ieee_b_dph, 4),
        min = num(Some(n.adev_min_dph), 4),
        tmin = n.adev_min_tau_s,
        arw = resolved(n.arw_deg_per_rt_h, 5, "deg/sqrt(h)"),
        rrw = resolved(n.rate_random_walk_dph_per_rt_h, 4, "deg/h/sqrt(h)"),
    )
}

/// A fitted noise coefficient, or that the record does not resolve it.
fn resolved(v: Option<f64>, digits: usize, unit: &str) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.digits$} {unit}"),
        _ => "not resolved by this record".into(),
    }
}

/// A failed measurement with the limit it broke and by how much:
/// `x = 0.0712 deg/h against a limit of 0.05 deg/h, 0.0212 deg/h over it`.
pub fn outside_by(m: &Measurement) -> String {
    let v = m.value;
    let (limit_v, side) = match (v, m.low, m.high) {
        (Some(x), _, Some(h)) if x > h => (Some(h), "over"),
        (Some(x), Some(l), _) if x < l => (Some(l), "under"),
        _ => (None, ""),
    };
    match (v, limit_v) {
        (Some(x), Some(l)) => format!(
            "{} = {} {u} against a limit of {} {u}, {} {u} {side} it",
            m.name,
            num(Some(x), 4),
            limit(Some(l)),
            num(Some((x - l).abs()), 4),
            u = m.unit
        ),
        _ => format!(
            "{} = {} {} (limits {}..{})",
            m.name,
            num(v, 4),
            m.unit,
            limit(m.low),
            limit(m.high)
        ),
    }
}

/// One sentence under the verdict: what decided it.
fn headline(r: &Report) -> String {
    let total = r.measurements.len();
    let outside: Vec<&Measurement> = r
        .measurements
        .iter()
        .filter(|m| m.outcome == MeasureOutcome::Fail)
        .collect();
    let unjudged = r
        .measurements
        .iter()
        .filter(|m| m.outcome == MeasureOutcome::Error)
        .count();
    let key = r
        .measurements
        .iter()
        .find(|m| m.metric == Metric::CompensatedDriftPp && m.outcome != MeasureOutcome::Fail)
        .map(|m| {
            format!(
                " Compensated drift {} {} against a limit of {} {}.",
                num(m.value, 4),
                m.unit,
                limit(m.high),
                m.unit
            )
        })
        .unwrap_or_default();
    let s = match r.outcome {
        Outcome::Pass => format!("All {total} measurements within their limits.{key}"),
        Outcome::Fail => format!(
            "{} of {total} measurements outside their limits: {}.{key}",
            outside.len(),
            outside
                .iter()
                .map(|m| outside_by(m))
                .collect::<Vec<_>>()
                .join("; ")
        ),
        Outcome::Error => format!(
            "The run did not complete: {}{}",
            r.error.as_ref().map_or("see below".to_owned(), |e| format!(
                "{} (step {})",
                e.message, e.step
            )),
            if unjudged > 0 {
                format!("; {unjudged} measurement(s) not judged")
            } else {
                String::new()
            }
        ),
        Outcome::Aborted => {
            "The run was interrupted before its end; what was measured is below.".to_owned()
        }
        Outcome::ConditionalPass => format!(
            "No measurement outside its limits, but {} within its expanded uncertainty of one \
             (non-binary rule): a conditional pass.{key}",
            r.measurements
                .iter()
                .filter(|m| m.outcome == MeasureOutcome::ConditionalPass)
                .map(|m| m.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        Outcome::ConditionalFail => format!(
            "No measurement beyond its limits by more than its uncertainty, but {} outside one \
             (non-binary rule): a conditional fail.{key}",
            r.measurements
                .iter()
                .filter(|m| m.outcome == MeasureOutcome::ConditionalFail)
                .map(|m| m.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    esc(&s)
}

/// The first page's statement of how the unit was judged and by whom:
/// the unit, the operator, the decision rule in words, and the lines the
/// record is signed on.
fn judgement(r: &Report) -> String {
    let or_dash = |s: &str| {
        if s.is_empty() { "-".to_owned() } else { esc(s) }
    };
    format!(
        "<table class=record>\n<tr><th>unit</th><td>{} {}</td></tr>\n<tr><th>tested by</th><td>{} <span class=note>(operator), {}</span></td></tr>\n<tr><th>power-on</th><td>{}</td></tr>\n<tr><th>gyro status</th><td>{}</td></tr>\n<tr><th>decision rule</th><td><b>{}</b>{}: {}</td></tr>\n<tr><th>reviewed by</th><td class=sign>{}</td></tr>\n<tr><th>approved by</th><td class=sign>{}</td></tr>\n</table>\n",
        esc(&r.dut.kind),
        esc(&r.dut.serial),
        or_dash(&r.operator),
        esc(&utc_seconds(&r.start_time_utc)),
        esc(&r.power_on.words),
        esc(&r.gyro_status.words),
        esc(&r.decision_rule.short()),
        if r.decision_rule.named {
            " (named by the procedure)"
        } else {
            " (the default)"
        },
        esc(&r.decision_rule.statement),
        signed(r, "reviewed"),
        signed(r, "approved"),
    )
}

/// The signatures of `role` in words (blank for a pen on a printed copy).
fn signed(r: &Report, role: &str) -> String {
    r.signatures
        .iter()
        .filter(|s| s.role == role)
        .map(|s| {
            format!(
                "{} <span class=note>{} (log sha256 {}){}</span>",
                esc(&s.by),
                esc(&s.signed_utc),
                esc(s.log_sha256.get(..12).unwrap_or(&s.log_sha256)),
                if s.note.is_empty() {
                    String::new()
                } else {
                    format!(": {}", esc(&s.note))
                }
            )
        })
        .collect::<Vec<_>>()
        .join("<br>")
}

/// A figure's expanded uncertainty with its coverage factor, its standard
/// error where it has no budget, or a dash (its reason on hover).
fn uncertainty_cell(m: &Measurement) -> String {
    match (&m.uncertainty, m.std_error) {
        _ if m.value.is_none() => "-".to_owned(),
        (Some(u), _) => format!(
            "{} <span class=note>(k={:.2})</span>",
            num(Some(u.expanded), 4),
            u.k
        ),
        (None, Some(se)) => format!("{} <span class=note>(1 s.e.)</span>", num(Some(se), 4)),
        (None, None) => format!(
            "<span title=\"{}\">-</span>",
            esc(m.uncertainty_reason.as_deref().unwrap_or("not formed"))
        ),
    }
}

/// The distance to the nearer limit, and in expanded uncertainties.
fn margin_cell(m: &Measurement) -> String {
    match (m.margin, m.margin_u) {
        (Some(d), Some(k)) => format!("{} <span class=note>({k:.1} U)</span>", num(Some(d), 4)),
        (Some(d), None) => num(Some(d), 4),
        _ => "-".to_owned(),
    }
}

/// The row under a figure with its note and noise floor, across the
/// table (none when it has neither).
fn note_row(m: &Measurement, class: &str) -> String {
    let floor = m.noise_floor.map(|f| {
        format!(
            "noise floor {} {} (a perfectly compensated unit with this run's noise)",
            num(Some(f), 4),
            esc(&m.unit)
        )
    });
    let text: Vec<String> = (!m.note.is_empty())
        .then(|| esc(&m.note))
        .into_iter()
        .chain(floor)
        .collect();
    if text.is_empty() {
        String::new()
    } else {
        format!(
            "<tr class={class}><td></td><td colspan=8 class=note>{}</td></tr>\n",
            text.join("; ")
        )
    }
}

/// The measurements table's rows.
fn measurement_rows(r: &Report) -> String {
    let mut rows = String::new();
    for m in &r.measurements {
        let class = m.outcome.as_str();
        let informative = m.low.is_none() && m.high.is_none();
        rows.push_str(&format!(
            "<tr class={class}><td>{}<br><span class=note>step {}</span></td><td class=num>{}</td><td class=num>{}</td><td>{}</td><td class=num>{}</td><td class=num>{}</td><td class=num>{}</td><td class=num>{}</td><td class=\"outcome {class}\">{}</td></tr>\n{}",
            esc(&m.name),
            esc(&m.step),
            num(m.value, 4),
            uncertainty_cell(m),
            esc(&m.unit),
            limit(m.low),
            limit(m.high),
            m.guard_band.map_or("-".to_owned(), |w| num(Some(w), 4)),
            margin_cell(m),
            if informative {
                "informative".to_owned()
            } else {
                m.outcome.word().to_owned()
            },
            note_row(m, class),
        ));
    }
    rows
}

/// Where and why the run stopped, for a run that stopped in error.
fn stopped_box(r: &Report) -> String {
    r.error.as_ref().map_or(String::new(), |e| {
        format!(
            "<p class=box>Stopped in step <b>{}</b>{}: {}</p>\n",
            esc(&e.step),
            e.device
                .as_ref()
                .map_or(String::new(), |d| format!(" (device <b>{}</b>)", esc(d))),
            esc(&e.message)
        )
    })
}

/// The state the run left the bench in, as read back.
fn bench_left_line(r: &Report) -> String {
    match &r.bench_left {
        Some(b) => format!(
            "<p class={}><b>Bench left:</b> {}</p>\n",
            if b.verified && r.cleanup_completed {
                "ok"
            } else {
                "box"
            },
            esc(&b.summary)
        ),
        None if !r.cleanup_completed => {
            "<p class=box><b>Cleanup did not complete: check the bench.</b></p>\n".to_owned()
        }
        None => String::new(),
    }
}

/// The box naming the instruments past their calibration's due date.
fn overdue_box(r: &Report) -> String {
    if r.calibration_overdue.is_empty() {
        String::new()
    } else {
        format!(
            "<p class=box><b>{} calibration OVERDUE</b>: {}. The figures stand as measured; the record shows the instrument past its due date.</p>\n",
            esc(&r.calibration_overdue.join(" and ")),
            esc(&r
                .instruments
                .iter()
                .filter(|i| i.calibration_overdue)
                .map(crate::bench::Instrument::describe)
                .collect::<Vec<_>>()
                .join("; "))
        )
    }
}

/// The whole page.
pub fn render_html(r: &Report, records: &Records) -> String {
    let faults_before = records.read_faults();
    let colour = match r.outcome {
        Outcome::Pass => "var(--pass)",
        Outcome::Fail | Outcome::ConditionalFail => "var(--fail)",
        Outcome::Error => "var(--error)",
        Outcome::Aborted | Outcome::ConditionalPass => "var(--aborted)",
    };
    let word = super::outcome_word(r.outcome);
    let rows = measurement_rows(r);
    let error = stopped_box(r);
    let bench_left = bench_left_line(r);
    let headline_chart = r
        .measurements
        .iter()
        .find(|m| m.metric == Metric::CompensatedDriftPp)
        .and_then(drift_chart)
        .unwrap_or_default();
    let traces: String = [rate_chart(r, records), temperature_chart(records)]
        .into_iter()
        .flatten()
        .collect();
    let l = &r.link;
    let overdue = overdue_box(r);
    let mut body = format!(
        r#"<div class=verdict style="background:{colour}">{word}</div>{overdue_tag}
<h1>{proc} &mdash; {dut_type} {serial}</h1>
<p class=headline>{headline}</p>
{judgement}{overdue}{error}{bench_left}<p class=note>Spec: {spec}<br>Started {start} &middot; {hours:.2} h of device time &middot; {frames} frames &middot; bench {bench}{seed} &middot; gyrobench {version}</p>
{headline_chart}
<h2>Measurements</h2>
<table><tr><th>name</th><th>value</th><th>U</th><th>unit</th><th>low</th><th>high</th><th>guard band</th><th>margin</th><th>outcome</th></tr>
{rows}</table>
<p class=note>U: the expanded uncertainty (coverage factor k for 95 % from the budget's degrees of freedom; docs/figures.md gives each figure's budget). Guard band: how far the decision rule moved the limits inward. Margin: the distance to the nearer limit (negative outside it), and in units of U.</p>
<p class=note>Definitions: bias stability = 1-sigma of the averages over the averaging time of the Earth-removed rate; drift = peak-to-peak of the Earth-removed rate smoothed by a centred moving average of the averaging time; compensated = the same after the study's model 4; self-heating = mean of the first 120 s after power-on minus the mean of 1680..1800 s; scale factor, nonlinearity and asymmetry = the fit of output against input rate with one slope per direction; dead band and threshold = the inputs giving 10 % and 50 % of the expected output in a lock-in fit; axis misalignment = the slope of the Earth-removed rate against the rate of a table axis turning across the input axis, as an angle (&plusmn; one standard error). See docs/figures.md.</p>
{record}{positions}{rate_table}{turn_ons}{noise}{allan}
<h2>Traces</h2>
{traces}
<h2>Gyro link</h2>
<p>{lf} frames, {lost} lost, {crc} CRC errors, {res} resyncs, {dup} duplicates.</p>
"#,
        headline = headline(r),
        judgement = judgement(r),
        positions = positions(r),
        rate_table = rate_table_charts(r, records),
        turn_ons = turn_on_section(r, records),
        noise = noise_table(r),
        allan = allan_chart(r).unwrap_or_default(),
        proc = esc(&r.procedure),
        serial = esc(&r.dut.serial),
        dut_type = esc(&r.dut.kind),
        spec = esc(&r.spec),
        start = esc(&utc_seconds(&r.start_time_utc)),
        hours = r.device_time_s / 3600.0,
        frames = r.frames,
        bench = esc(&r.bench),
        seed = r.seed.map_or(String::new(), |s| format!(", seed {s}")),
        version = esc(&software(r)),
        overdue_tag = if r.calibration_overdue.is_empty() {
            ""
        } else {
            " <span class=verdict style=\"background:var(--error);font-size:1.2rem\">CALIBRATION OVERDUE</span>"
        },
        record = record(r),
        lf = l.frames,
        lost = l.lost_frames,
        crc = l.crc_errors,
        res = l.resyncs,
        dup = l.duplicates,
    );
    // The charts were drawn from the records' temporary file: say when
    // part of it could not be read back.
    if let Some(why) = records.read_faults().since(&faults_before) {
        body.insert_str(
            0,
            &format!(
                "<p class=box><b>Charts incomplete:</b> {}; the figures stand as judged during the run.</p>\n",
                esc(&why)
            ),
        );
    }
    page(
        &format!("{} {}: {word}", r.procedure, r.dut.serial),
        &print_margins(r),
        &body,
    )
}

/// `0.1.0 (1a2b3c4d5e6f)`, or the version alone for a log that names no
/// revision.
fn software(r: &Report) -> String {
    if r.software_revision.is_empty() {
        r.software_version.clone()
    } else {
        format!("{} ({})", r.software_version, r.software_revision)
    }
}

/// The run's record: who ran it where, with which instruments and
/// coefficients.
fn record(r: &Report) -> String {
    let or_dash = |s: &str| {
        if s.is_empty() { "-".to_owned() } else { esc(s) }
    };
    let mut rows = format!(
        "<tr><th>unit</th><td>{} {}{}</td></tr>\n<tr><th>run id</th><td><code>{}</code></td></tr>\n<tr><th>operator</th><td>{}</td></tr>\n<tr><th>bench</th><td>{} ({}) on {}{}</td></tr>\n<tr><th>software</th><td>gyrobench {}</td></tr>\n<tr><th>coefficients</th><td>{}</td></tr>\n",
        esc(&r.dut.kind),
        esc(&r.dut.serial),
        if r.slot.is_empty() {
            String::new()
        } else {
            format!(", slot {}", esc(&r.slot))
        },
        or_dash(&r.run_id),
        if r.operator.is_empty() {
            "not given".to_owned()
        } else {
            esc(&r.operator)
        },
        or_dash(&r.bench_id),
        esc(&r.bench),
        or_dash(&r.host),
        if !r.station.is_empty() && r.station != r.host {
            format!(", station {}", esc(&r.station))
        } else {
            String::new()
        },
        esc(&software(r)),
        esc(&r.coefficients.describe()),
    );
    for i in &r.instruments {
        let id = match (&i.identity, &i.identity_error) {
            (Some(id), _) => id.describe(),
            (None, Some(e)) => format!("did not identify itself: {e}"),
            (None, None) => "did not identify itself".into(),
        };
        let due = match (&i.calibration_due, i.calibration_overdue) {
            (Some(d), true) => format!("<b>calibration OVERDUE since {}</b>", esc(d)),
            (Some(d), false) => format!("calibration due {}", esc(d)),
            (None, _) => "no calibration due date in the bench file".into(),
        };
        rows.push_str(&format!(
            "<tr><th>{}</th><td>{} <span class=note>({})</span><br>{due}</td></tr>\n",
            esc(&i.role),
            esc(&id),
            esc(&i.spec),
        ));
    }
    format!("<h2>Record</h2>\n<table class=record>\n{rows}</table>\n")
}

/// A CSS string: quoted, with what would end it or the style element
/// escaped.
fn css_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' | '\\' => {
                out.push('\\');
                out.push(c);
            }
            '<' => out.push_str("\\3c "),
            '>' => out.push_str("\\3e "),
            c if c.is_control() => {}
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// Printed, every A4 page names the unit and the run and says which page
/// of how many it is.
fn print_margins(r: &Report) -> String {
    let who = format!(
        "{} {} \u{b7} {} \u{b7} run {}",
        r.dut.kind,
        r.dut.serial,
        r.procedure,
        if r.run_id.is_empty() {
            "-"
        } else {
            r.run_id.get(..12).unwrap_or(&r.run_id)
        }
    );
    format!(
        "@media print{{@page{{@top-left{{content:{};font:8pt system-ui,sans-serif;color:#555}}\
         @top-right{{content:{} counter(page) \" of \" counter(pages);font:8pt system-ui,sans-serif;color:#555}}\
         @bottom-left{{content:{};font:8pt system-ui,sans-serif;color:#555}}}}}}",
        css_string(&who),
        css_string(&format!(
            "{} {} \u{b7} page ",
            r.outcome_word(),
            r.dut.serial
        )),
        css_string(&format!("run id {}", r.run_id)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(value: f64, low: Option<f64>, high: Option<f64>) -> Measurement {
        Measurement {
            name: "compensated_drift_pp_dph".into(),
            value: Some(value),
            unit: "deg/h".into(),
            low,
            high,
            outcome: MeasureOutcome::Fail,
            step: "main.3".into(),
            metric: Metric::CompensatedDriftPp,
            averaging_s: 600.0,
            records: Vec::new(),
            note: String::new(),
            std_error: None,
            uncertainty: None,
            uncertainty_reason: None,
            guard_band: None,
            margin: None,
            margin_u: None,
            noise_floor: None,
            trace: None,
            band: None,
        }
    }

    #[test]
    fn a_failure_names_the_limit_it_broke_and_by_how_much() {
        assert_eq!(
            outside_by(&m(0.0712, None, Some(0.05))),
            "compensated_drift_pp_dph = 0.0712 deg/h against a limit of 0.05 deg/h, 0.0212 deg/h over it"
        );
        let under = outside_by(&m(-6.5, Some(-5.0), Some(5.0)));
        assert!(
            under.ends_with("against a limit of -5 deg/h, 1.5000 deg/h under it"),
            "{under}"
        );
    }
}
