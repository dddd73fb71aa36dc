//! `diagnosis.html`: the layers' gaps, where the gap lies, the accepted
//! effects before and after, the rate and thermal residuals against time
//! (segments marked on the rate's), the residual per position, and the
//! residual's Allan deviation against the noise floor.

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::Diagnosis;
use super::engine::AVERAGING_S;
use crate::analysis::allan::{oadev, octave_factors};
use crate::report::html::{esc, label_at, legend, range, svg};

const W: u32 = 900;
const H: u32 = 300;

/// Residual 60 s means of one run: (t h, reference, final).
fn run_series(d: &Diagnosis, run: usize) -> Vec<(f64, f64, f64)> {
    let Some((base, fin)) = &d.fits else {
        return Vec::new();
    };
    let Some(data) = &d.data else {
        return Vec::new();
    };
    let rows: Vec<usize> = (0..data.run_of.len())
        .filter(|&i| data.run_of[i] == run)
        .collect();
    rows.chunks(AVERAGING_S)
        .map(|c| {
            let n = c.len() as f64;
            let t = c.iter().map(|&i| data.time_s[i]).sum::<f64>() / n / 3600.0;
            let a = c.iter().map(|&i| base.held_out[i]).sum::<f64>() / n;
            let b = c.iter().map(|&i| fin.held_out[i]).sum::<f64>() / n;
            (t, a, b)
        })
        .collect()
}

type TimeChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A chart against time since power-on (h) over `t` and `y`, its series
/// added by `draw`, with a legend.
fn time_chart(
    caption: &str,
    unit: &str,
    (t0, t1): (f64, f64),
    (y0, y1): (f64, f64),
    draw: impl FnOnce(&mut TimeChart<'_, '_>) -> Result<(), Box<dyn std::error::Error>>,
) -> String {
    svg(|out| {
        let root = SVGBackend::with_string(out, (W, H)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut c = ChartBuilder::on(&root)
            .caption(caption, ("sans-serif", 15))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(56)
            .build_cartesian_2d(t0..t1, y0..y1)?;
        c.configure_mesh()
            .x_desc("time since power-on, h")
            .y_desc(unit)
            .draw()?;
        draw(&mut c)?;
        legend(&mut c)?;
        root.present()?;
        Ok(())
    })
}

fn residual_chart(d: &Diagnosis, run: usize) -> String {
    let s = run_series(d, run);
    if s.len() < 2 {
        return String::new();
    }
    let name = d.runs.get(run).cloned().unwrap_or_default();
    let marks: Vec<f64> = d
        .r#where
        .iter()
        .filter(|g| g.run == name)
        .map(|g| g.start_s / 3600.0)
        .collect();
    let (y0, y1) = range(s.iter().flat_map(|p| [p.1, p.2]));
    time_chart(
        &format!("Rate residual, held out (60 s means): {name}"),
        "deg/h",
        range(s.iter().map(|p| p.0)),
        (y0, y1),
        |c| {
            for m in marks {
                c.draw_series(LineSeries::new(vec![(m, y0), (m, y1)], BLACK.mix(0.15)))?;
            }
            c.draw_series(LineSeries::new(s.iter().map(|p| (p.0, p.1)), RED))?
                .label("reference simulator")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], RED));
            c.draw_series(LineSeries::new(s.iter().map(|p| (p.0, p.2)), BLUE))?
                .label("with the accepted effects")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLUE));
            Ok(())
        },
    )
}

/// Thermal residual of one run against time: T1, T2, TK.
fn thermal_chart(d: &Diagnosis, run: usize) -> String {
    let Some(s) = d.layers.thermal.series.get(run).filter(|s| s.len() >= 2) else {
        return String::new();
    };
    let name = d.runs.get(run).cloned().unwrap_or_default();
    time_chart(
        &format!("Thermal residual, measured - simulated (60 s means): {name}"),
        "degC",
        range(s.iter().map(|p| p.0 / 3600.0)),
        range(s.iter().flat_map(|p| p.1)),
        |c| {
            for (k, (label, colour)) in [("T1", RED), ("T2", BLUE), ("TK", BLACK)]
                .into_iter()
                .enumerate()
            {
                c.draw_series(LineSeries::new(
                    s.iter().map(|p| (p.0 / 3600.0, p.1[k])),
                    colour,
                ))?
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour));
            }
            Ok(())
        },
    )
}

/// Mean held-out rate residual at one body orientation.
struct Position {
    /// (azimuth, elevation, roll), deg.
    angles: [f64; 3],
    seconds: usize,
    /// Reference simulator, deg/h.
    reference: f64,
    /// With the accepted effects, deg/h.
    accepted: f64,
}

/// The residual per position, in the order the runs visit them.
fn per_position(d: &Diagnosis) -> Vec<Position> {
    let (Some((base, fin)), Some(data)) = (&d.fits, &d.data) else {
        return Vec::new();
    };
    let key = |o: &[f64; 3]| o.map(|v| (v * 10.0).round() as i64);
    let mut keys: Vec<[i64; 3]> = Vec::new();
    let mut out: Vec<Position> = Vec::new();
    for (i, o) in data.orientation.iter().enumerate() {
        let k = key(o);
        let at = keys.iter().position(|x| *x == k).unwrap_or_else(|| {
            keys.push(k);
            out.push(Position {
                angles: *o,
                seconds: 0,
                reference: 0.0,
                accepted: 0.0,
            });
            out.len() - 1
        });
        let p = &mut out[at];
        p.seconds += 1;
        p.reference += base.held_out[i];
        p.accepted += fin.held_out[i];
    }
    for p in &mut out {
        p.reference /= p.seconds as f64;
        p.accepted /= p.seconds as f64;
    }
    out
}

/// "az/el/roll" in whole degrees (no "-0").
fn angles(o: &[f64; 3]) -> String {
    let [a, e, r] = o.map(|v| v.round() + 0.0);
    format!("{a:.0}/{e:.0}/{r:.0}")
}

fn position_chart(rows: &[Position]) -> String {
    if rows.len() < 2 {
        return String::new();
    }
    let labels: Vec<String> = rows.iter().map(|p| angles(&p.angles)).collect();
    svg(|out| {
        let root = SVGBackend::with_string(out, (W, H)).into_drawing_area();
        root.fill(&WHITE)?;
        let (y0, y1) = range(rows.iter().flat_map(|r| [r.reference, r.accepted, 0.0]));
        let n = rows.len() as f64;
        let mut c = ChartBuilder::on(&root)
            .caption(
                "Mean held-out rate residual per position (az/el/roll, deg)",
                ("sans-serif", 15),
            )
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(-0.5..n - 0.5, y0..y1)?;
        c.configure_mesh()
            .x_labels(rows.len())
            .x_label_formatter(&|x| label_at(&labels, *x))
            .y_desc("deg/h")
            .draw()?;
        c.draw_series(
            rows.iter()
                .enumerate()
                .map(|(i, r)| Circle::new((i as f64 - 0.1, r.reference), 4, RED.filled())),
        )?
        .label("reference simulator")
        .legend(|(x, y)| Circle::new((x + 8, y), 4, RED.filled()));
        c.draw_series(
            rows.iter()
                .enumerate()
                .map(|(i, r)| Circle::new((i as f64 + 0.1, r.accepted), 4, BLUE.filled())),
        )?
        .label("with the accepted effects")
        .legend(|(x, y)| Circle::new((x + 8, y), 4, BLUE.filled()));
        legend(&mut c)?;
        root.present()?;
        Ok(())
    })
}

/// ADEV of the final in-sample residual of the longest run, with the white
/// noise floor extrapolated from its 1 s value (a residual at the noise
/// floor follows the line; a gap lifts it at the taus where it lives).
fn allan_chart(d: &Diagnosis) -> String {
    let (Some((_, fin)), Some(data)) = (&d.fits, &d.data) else {
        return String::new();
    };
    let Some(run) =
        (0..d.runs.len()).max_by_key(|&r| data.run_of.iter().filter(|&&x| x == r).count())
    else {
        return String::new();
    };
    let r: Vec<f64> = (0..data.run_of.len())
        .filter(|&i| data.run_of[i] == run)
        .map(|i| fin.residual[i])
        .collect();
    let dev = oadev(&r, 1.0, &octave_factors(r.len()));
    if dev.len() < 3 {
        return String::new();
    }
    let floor = dev[0].1;
    svg(|out| {
        let root = SVGBackend::with_string(out, (W, H)).into_drawing_area();
        root.fill(&WHITE)?;
        let (t0, t1) = (dev[0].0, dev[dev.len() - 1].0);
        let lo = dev
            .iter()
            .map(|p| p.1)
            .fold(f64::INFINITY, f64::min)
            .min(floor / t1.sqrt())
            * 0.5;
        let hi = dev.iter().map(|p| p.1).fold(0.0, f64::max) * 2.0;
        let mut c = ChartBuilder::on(&root)
            .caption(
                format!("Residual Allan deviation: {}", d.runs[run]),
                ("sans-serif", 15),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(56)
            .build_cartesian_2d((t0..t1).log_scale(), (lo.max(1e-9)..hi).log_scale())?;
        c.configure_mesh()
            .x_desc("tau, s")
            .y_desc("deg/h")
            .y_label_formatter(&|v| format!("{v:.4}"))
            .draw()?;
        c.draw_series(LineSeries::new(dev.iter().copied(), BLUE))?
            .label("residual after the accepted effects")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLUE));
        c.draw_series(LineSeries::new(
            vec![(t0, floor), (t1, floor / (t1 / t0).sqrt())],
            BLACK.mix(0.5),
        ))?
        .label("white-noise floor from tau = 1 s")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.mix(0.5)));
        legend(&mut c)?;
        root.present()?;
        Ok(())
    })
}

/// The page.
pub fn render(d: &Diagnosis) -> String {
    let mut effects = String::new();
    for e in &d.effects {
        let params: Vec<String> = e
            .parameters
            .iter()
            .map(|(k, v)| match e.uncertainties.get(k) {
                Some(u) if u.is_finite() => format!("{k} = {v:.4e} &plusmn; {u:.1e}"),
                _ => format!("{k} = {v:.4}"),
            })
            .collect();
        effects.push_str(&format!(
            "<tr><td>{}</td><td class=num>{:.5}</td><td class=num>{:.5}</td><td class=num>{:.0} %</td><td class=num>{:.1e}</td><td>{}</td></tr>\n",
            esc(&e.name),
            e.held_out_gap_before_dph,
            e.held_out_gap_after_dph,
            100.0 * e.shrink,
            e.p_value,
            params.join("<br>")
        ));
    }
    if effects.is_empty() {
        effects = "<tr><td colspan=6>no effect is significant</td></tr>".into();
    }
    let mut where_ = String::new();
    for s in d.r#where.iter().take(12) {
        where_.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td class=num>{:.0}..{:.0}</td><td>{}</td><td class=num>{:.1}</td><td class=num>{:.0}/{:.0}/{:.0}</td><td class=num>{:.5}</td><td class=num>{:.0} %</td></tr>\n",
            esc(&s.run), esc(&s.record), esc(&s.step), s.start_s, s.end_s, s.regime, s.temperature_c,
            s.orientation_deg[0], s.orientation_deg[1], s.orientation_deg[2], s.rms_dph, 100.0 * s.share
        ));
    }
    let confounded: String = d
        .confounded
        .iter()
        .map(|c| {
            format!(
                "<li>{} and {}: separate with {}</li>",
                esc(&c.effects[0]),
                esc(&c.effects[1]),
                esc(&c.separate_with)
            )
        })
        .collect();
    let candidates: String = d
        .candidates
        .iter()
        .map(|c| {
            format!(
                "<tr><td>{}</td><td class=num>{:.5}</td><td class=num>{:.1e}</td></tr>",
                esc(&c.name),
                c.held_out_gap_dph,
                c.p_value
            )
        })
        .collect();
    let positions = per_position(d);
    let position_rows: String = positions
        .iter()
        .map(|p| {
            format!(
                "<tr><td class=num>{}</td><td class=num>{}</td><td class=num>{:+.5}</td><td class=num>{:+.5}</td></tr>",
                angles(&p.angles),
                p.seconds,
                p.reference,
                p.accepted
            )
        })
        .collect();
    let charts: String = (0..d.runs.len())
        .map(|r| residual_chart(d, r) + &thermal_chart(d, r))
        .collect::<String>()
        + &position_chart(&positions)
        + &allan_chart(d);
    let u = &d.unexplained;
    format!(
        "<!doctype html>\n<html lang=en><head><meta charset=utf-8><title>Diagnosis</title><style>body{{font-family:sans-serif;margin:2em;max-width:1000px}} table{{border-collapse:collapse;margin:1em 0}} td,th{{border:1px solid #ccc;padding:.25em .5em;font-size:.85em}} td.num{{text-align:right;font-family:monospace}} svg{{display:block;margin:1em 0}}</style></head><body>\n<h1>Sim-to-real diagnosis</h1>\n<p>Runs: {runs}. {protocol}.</p>\n<h2>Layers</h2>\n<table><tr><th>layer</th><th>held-out gap</th><th>reference</th></tr><tr><td>thermal</td><td class=num>{tg:.4} degC</td><td>{tref}</td></tr><tr><td>rate</td><td class=num>{rg:.5} deg/h &rarr; {ra:.5} deg/h</td><td>{rref}</td></tr></table>\n<h2>Accepted effects</h2>\n<table><tr><th>effect</th><th>gap before</th><th>gap after</th><th>shrink</th><th>p</th><th>parameters</th></tr>\n{effects}</table>\n<h2>Confounded</h2><ul>{confounded}</ul>\n<h2>Unexplained</h2><p>Held-out gap {ug:.5} deg/h{period}.</p>\n<h2>Where the gap lies (reference simulator)</h2>\n<table><tr><th>run</th><th>record</th><th>step</th><th>s</th><th>regime</th><th>TK degC</th><th>az/el/roll</th><th>RMS deg/h</th><th>share</th></tr>\n{where_}</table>\n<h2>Residual per position</h2>\n<table><tr><th>az/el/roll, deg</th><th>seconds</th><th>mean, reference (deg/h)</th><th>mean, with the accepted effects</th></tr>{position_rows}</table>\n<h2>Candidates against the reference</h2><table><tr><th>effect</th><th>held-out gap</th><th>p</th></tr>{candidates}</table>\n<h2>Charts</h2>{charts}\n</body></html>\n",
        runs = esc(&d.runs.join(", ")),
        protocol = esc(&d.protocol),
        tg = d.layers.thermal.gap_c,
        tref = esc(&d.layers.thermal.reference),
        rg = d.layers.rate.gap_dph,
        ra = d.layers.rate.gap_after_dph,
        rref = esc(&d.layers.rate.reference.join(", ")),
        ug = u.gap_dph,
        period = u.period_s.map_or(String::new(), |p| format!(
            "; periodic, period {p:.0} s ({:.0} % of its variance)",
            100.0 * u.periodic_fraction
        )),
    )
}
