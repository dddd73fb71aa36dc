//! The one chart helper of every page: a chart described as data (series,
//! limit bands, rules, notes), drawn by plotters into inline SVG.
//!
//! The rules it keeps so that no page has to remember them:
//! - the legend sits below the plot area, never on the data;
//! - colours from the Okabe-Ito palette (told apart with the common colour
//!   vision deficiencies and in grey print), and every series also has its
//!   own line style or marker, so it is told apart without colour at all;
//! - lines break where the data have a gap (a record's end, a move)
//!   instead of joining across it;
//! - tick labels of 14 px on a 960 px chart that scales to the column.

use plotters::coord::Shift;
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::esc;

/// Okabe & Ito (2008), "Color Universal Design": blue, vermillion, bluish
/// green, reddish purple, orange, sky blue, black.
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
];

/// Limits and rules are drawn in this dark grey, data never are.
const LIMIT: RGBColor = RGBColor(60, 60, 60);

const W: u32 = 960;
const PLOT_H: u32 = 360;
const FONT: &str = "sans-serif";
// plotters' SVG writes a font size of size / 1.24: these give 14, 15, 17
// and 14 px text.
const TICK_PX: u32 = 17;
const LABEL_PX: u32 = 19;
const TITLE_PX: u32 = 21;
const LEGEND_PX: u32 = 17;
const LEGEND_ROW: u32 = 24;

/// How a series' line is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stroke {
    /// A continuous line.
    Solid,
    /// Long dashes.
    Dashed,
    /// Short dashes, close together.
    Dotted,
    /// Markers only.
    None,
}

/// The marker at each point of a series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    /// No marker.
    None,
    /// Filled circle.
    Circle,
    /// Filled square.
    Square,
    /// Filled triangle, point up.
    Triangle,
    /// Filled triangle, point down.
    TriangleDown,
    /// Filled diamond.
    Diamond,
    /// A cross (x).
    Cross,
}

/// One series of points.
#[derive(Debug, Clone)]
pub struct Series {
    label: String,
    points: Vec<(f64, f64)>,
    colour: Option<RGBColor>,
    stroke: Stroke,
    width: u32,
    marker: Marker,
    marker_px: i32,
    gap: Option<f64>,
    errors: Vec<(f64, f64, f64)>,
}

impl Series {
    /// A line through `points` (in x order), broken at gaps wider than
    /// three times the median spacing.
    pub fn line(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        let gap = median_step(&points).map(|s| 3.0 * s);
        Self {
            label: label.into(),
            points,
            colour: None,
            stroke: Stroke::Solid,
            width: 2,
            marker: Marker::None,
            marker_px: 4,
            gap,
            errors: Vec::new(),
        }
    }

    /// Markers only.
    pub fn points(label: impl Into<String>, points: Vec<(f64, f64)>, marker: Marker) -> Self {
        Self {
            stroke: Stroke::None,
            marker,
            gap: None,
            ..Self::line(label, points)
        }
    }

    /// Colour from the palette (index wraps).
    pub fn colour(mut self, i: usize) -> Self {
        self.colour = Some(PALETTE[i % PALETTE.len()]);
        self
    }

    /// Line style.
    pub fn stroke(mut self, s: Stroke) -> Self {
        self.stroke = s;
        self
    }

    /// Line width, px.
    pub fn width(mut self, w: u32) -> Self {
        self.width = w;
        self
    }

    /// Marker at each point, of `px` radius.
    pub fn marker(mut self, m: Marker, px: i32) -> Self {
        self.marker = m;
        self.marker_px = px;
        self
    }

    /// Break the line where x steps by more than `gap` (None: never).
    pub fn gap(mut self, gap: Option<f64>) -> Self {
        self.gap = gap;
        self
    }

    /// Vertical error bars: (x, low, high).
    pub fn errors(mut self, e: Vec<(f64, f64, f64)>) -> Self {
        self.errors = e;
        self
    }

    /// The stretches drawn as one line each.
    fn segments(&self) -> Vec<&[(f64, f64)]> {
        let mut out = Vec::new();
        let mut start = 0;
        for i in 1..self.points.len() {
            let step = self.points[i].0 - self.points[i - 1].0;
            if self.gap.is_some_and(|g| step > g) {
                out.push(&self.points[start..i]);
                start = i;
            }
        }
        if start < self.points.len() {
            out.push(&self.points[start..]);
        }
        out
    }
}

fn median_step(points: &[(f64, f64)]) -> Option<f64> {
    let mut steps: Vec<f64> = points
        .windows(2)
        .map(|w| w[1].0 - w[0].0)
        .filter(|s| s.is_finite() && *s > 0.0)
        .collect();
    if steps.is_empty() {
        return None;
    }
    steps.sort_by(f64::total_cmp);
    Some(steps[steps.len() / 2])
}

/// A horizontal band between two values (a limit band), over the whole
/// x range or part of it.
#[derive(Debug, Clone)]
pub struct Band {
    /// Legend text.
    pub label: String,
    /// Lower and upper edge.
    pub y: (f64, f64),
    /// Where it applies on x (None: everywhere).
    pub x: Option<(f64, f64)>,
}

/// A straight line across the plot with its text beside it.
#[derive(Debug, Clone)]
pub struct Rule {
    /// Text drawn at the line.
    pub label: String,
    /// Where it is.
    pub at: f64,
    /// A vertical line at x = `at` (else horizontal at y = `at`).
    pub vertical: bool,
}

/// An axis: its title, scale and range.
#[derive(Debug, Clone, Default)]
pub struct Axis {
    label: String,
    log: bool,
    range: Option<(f64, f64)>,
    categories: Vec<String>,
    decimals: Option<usize>,
    integers: bool,
}

/// A chart.
#[derive(Debug, Clone, Default)]
pub struct Chart {
    links: Vec<Link>,
    title: String,
    x: Axis,
    y: Axis,
    series: Vec<Series>,
    bands: Vec<Band>,
    rules: Vec<Rule>,
    notes: Vec<(f64, f64, String)>,
    caption: String,
    height: Option<u32>,
}

impl Chart {
    /// A chart titled `title` with axis titles (units included).
    pub fn new(title: impl Into<String>, x: &str, y: &str) -> Self {
        Self {
            title: title.into(),
            x: Axis {
                label: x.into(),
                ..Axis::default()
            },
            y: Axis {
                label: y.into(),
                ..Axis::default()
            },
            ..Self::default()
        }
    }

    /// Logarithmic x axis.
    pub fn log_x(mut self) -> Self {
        self.x.log = true;
        self
    }

    /// Logarithmic y axis.
    pub fn log_y(mut self) -> Self {
        self.y.log = true;
        self
    }

    /// Categories on x: `names[i]` labels x = i.
    pub fn categories(mut self, names: Vec<String>) -> Self {
        self.x.range = Some((-0.5, names.len() as f64 - 0.5));
        self.x.categories = names;
        self
    }

    /// Fixed x range.
    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x.range = Some((lo, hi));
        self
    }

    /// Fixed y range.
    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y.range = Some((lo, hi));
        self
    }

    /// Whole numbers on x (runs, counts): ticks between them unlabelled.
    pub fn integer_x(mut self) -> Self {
        self.x.integers = true;
        self
    }

    /// Decimals of the y tick labels (default: plotters' choice).
    pub fn y_decimals(mut self, d: usize) -> Self {
        self.y.decimals = Some(d);
        self
    }

    /// Plot height in px (default 360).
    pub fn height(mut self, h: u32) -> Self {
        self.height = Some(h);
        self
    }

    /// Add a series; without a colour of its own it takes the next one of
    /// the palette.
    pub fn series(mut self, mut s: Series) -> Self {
        if s.colour.is_none() {
            s.colour = Some(PALETTE[self.series.len() % PALETTE.len()]);
        }
        self.series.push(s);
        self
    }

    /// Add a limit band.
    pub fn band(mut self, b: Band) -> Self {
        self.bands.push(b);
        self
    }

    /// Add a rule.
    pub fn rule(mut self, r: Rule) -> Self {
        self.rules.push(r);
        self
    }

    /// Text at a point of the data.
    pub fn note(mut self, x: f64, y: f64, text: impl Into<String>) -> Self {
        self.notes.push((x, y, text.into()));
        self
    }

    /// A point that names itself when hovered (and opens `href` when
    /// clicked): an invisible target over a point drawn by a series.
    pub fn link(mut self, l: Link) -> Self {
        self.links.push(l);
        self
    }

    /// A sentence under the chart.
    pub fn caption(mut self, text: impl Into<String>) -> Self {
        self.caption = text.into();
        self
    }

    /// Everything the legend lists: series, then bands, then rules.
    fn legend_items(&self) -> Vec<(String, LegendKey)> {
        let mut items: Vec<(String, LegendKey)> = self
            .series
            .iter()
            .filter(|s| !s.label.is_empty())
            .map(|s| (s.label.clone(), LegendKey::Series(s.clone())))
            .collect();
        items.extend(
            self.bands
                .iter()
                .filter(|b| !b.label.is_empty())
                .map(|b| (b.label.clone(), LegendKey::Band)),
        );
        items
    }

    /// Legend rows: items laid out left to right, wrapped at the width.
    fn legend_rows(&self) -> Vec<Vec<(String, LegendKey, i32)>> {
        let mut rows: Vec<Vec<(String, LegendKey, i32)>> = vec![Vec::new()];
        let mut x = 70;
        for (text, key) in self.legend_items() {
            let w = 44 + (text.chars().count() as f64 * LEGEND_PX as f64 * 0.46) as i32 + 22;
            if x + w > W as i32 - 10 && x > 70 {
                rows.push(Vec::new());
                x = 70;
            }
            if let Some(row) = rows.last_mut() {
                row.push((text, key, x));
            }
            x += w;
        }
        rows.retain(|r| !r.is_empty());
        rows
    }

    /// The x and y ranges: fixed ones, else the data, bands and rules
    /// with a margin.
    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let xs = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .chain(
                self.bands
                    .iter()
                    .filter_map(|b| b.x)
                    .flat_map(|(a, b)| [a, b]),
            )
            .chain(self.rules.iter().filter(|r| r.vertical).map(|r| r.at));
        let ys = self
            .series
            .iter()
            .flat_map(|s| {
                s.points
                    .iter()
                    .map(|p| p.1)
                    .chain(s.errors.iter().flat_map(|e| [e.1, e.2]))
            })
            .chain(self.bands.iter().flat_map(|b| [b.y.0, b.y.1]))
            .chain(self.rules.iter().filter(|r| !r.vertical).map(|r| r.at))
            .chain(self.notes.iter().map(|n| n.1));
        let x = self.x.range.unwrap_or_else(|| padded(xs, self.x.log, 0.02));
        let y = self.y.range.unwrap_or_else(|| padded(ys, self.y.log, 0.08));
        (x, y)
    }

    /// The chart as an SVG figure (with its caption), or a note saying why
    /// it could not be drawn.
    pub fn render(&self) -> String {
        let rows = self.legend_rows();
        let plot_h = self.height.unwrap_or(PLOT_H);
        let legend_h = rows.len() as u32 * LEGEND_ROW + if rows.is_empty() { 0 } else { 8 };
        let mut svg = String::new();
        let mut targets: Vec<(i32, i32)> = Vec::new();
        let drawn = {
            let root =
                SVGBackend::with_string(&mut svg, (W, plot_h + legend_h)).into_drawing_area();
            let (plot, legend) = root.split_vertically(plot_h);
            let ((x0, x1), (y0, y1)) = self.ranges();
            let at = &mut targets;
            let r = match (self.x.log, self.y.log) {
                (false, false) => self.plot(&plot, lin(x0, x1), lin(y0, y1), at),
                (true, false) => self.plot(&plot, log(x0, x1), lin(y0, y1), at),
                (false, true) => self.plot(&plot, lin(x0, x1), log(y0, y1), at),
                (true, true) => self.plot(&plot, log(x0, x1), log(y0, y1), at),
            };
            r.and_then(|()| draw_legend(&legend, &rows))
                .and_then(|()| root.present().map_err(Into::into))
                .map_err(|e| e.to_string())
        };
        let caption = if self.caption.is_empty() {
            String::new()
        } else {
            format!("<figcaption>{}</figcaption>", esc(&self.caption))
        };
        if let Some(end) = svg.rfind("</svg>") {
            let mut hover = String::new();
            for (l, (px, py)) in self.links.iter().zip(&targets) {
                let target = format!(
                    "<circle cx=\"{px}\" cy=\"{py}\" r=\"7\" fill=\"transparent\"><title>{}</title></circle>",
                    esc(&l.title)
                );
                match &l.href {
                    Some(h) => hover.push_str(&format!("<a href=\"{}\">{target}</a>", esc(h))),
                    None => hover.push_str(&target),
                }
            }
            svg.insert_str(end, &hover);
        }
        match drawn {
            Ok(()) => format!("<figure>{svg}{caption}</figure>\n"),
            Err(e) => format!(
                "<p class=note>chart \"{}\" not drawn: {}</p>\n",
                esc(&self.title),
                esc(&e)
            ),
        }
    }

    fn plot<X, Y>(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        x: X,
        y: Y,
        targets: &mut Vec<(i32, i32)>,
    ) -> Drawn
    where
        X: Ranged<ValueType = f64> + ValueFormatter<f64>,
        Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        area.fill(&WHITE)?;
        let (xr, yr) = (x.range(), y.range());
        let mut c = ChartBuilder::on(area)
            .caption(&self.title, (FONT, TITLE_PX))
            .margin(10)
            .margin_right(24)
            .x_label_area_size(46)
            .y_label_area_size(78)
            .build_cartesian_2d(x, y)?;
        let cats = &self.x.categories;
        // A log axis is labelled below, by hand: plotters' labels stay empty.
        let x_fmt = |v: &f64| {
            if self.x.log || (self.x.integers && (v - v.round()).abs() > 1e-6) {
                String::new()
            } else if cats.is_empty() {
                tick(*v)
            } else {
                label_at(cats, *v)
            }
        };
        let y_fmt = |v: &f64| match (self.y.log, self.y.decimals) {
            (true, _) => String::new(),
            (false, Some(d)) => format!("{v:.d$}"),
            (false, None) => tick(*v),
        };
        let mut mesh = c.configure_mesh();
        mesh.x_desc(self.x.label.as_str())
            .y_desc(self.y.label.as_str())
            .label_style((FONT, TICK_PX))
            .axis_desc_style((FONT, LABEL_PX))
            .light_line_style::<ShapeStyle>(if self.x.log || self.y.log {
                // Log axes have light lines at every 1..9 x 10^k already.
                TRANSPARENT.into()
            } else {
                RGBColor(238, 238, 238).into()
            })
            .bold_line_style(RGBColor(215, 215, 215))
            .x_label_formatter(&x_fmt)
            .y_label_formatter(&y_fmt);
        if !cats.is_empty() {
            mesh.x_labels(cats.len()).disable_x_mesh();
        }
        // A log axis gets its grid and labels here (below): plotters starts
        // its key points at the first whole decade, so a range within one
        // decade, or its part below the first, would go unlabelled.
        if self.x.log {
            mesh.x_labels(0);
        }
        if self.y.log {
            mesh.y_labels(0);
        }
        mesh.draw()?;
        self.log_grid(&mut c, area, (xr.start, xr.end), (yr.start, yr.end))?;
        self.limits(&mut c, (xr.start, xr.end), (yr.start, yr.end))?;
        for s in &self.series {
            draw_series(&mut c, s)?;
        }
        for (x, y, text) in &self.notes {
            c.draw_series(std::iter::once(
                EmptyElement::at((*x, *y)) + Text::new(text.clone(), (6, -18), (FONT, TICK_PX)),
            ))?;
        }
        targets.extend(self.links.iter().map(|l| c.backend_coord(&(l.x, l.y))));
        Ok(())
    }
    /// The grid lines and labels of a log axis, every 1..9 x 10^k, the
    /// decades labelled (plotters starts its key points at the first whole
    /// decade, so a range within one would go unlabelled).
    fn log_grid<X, Y>(
        &self,
        c: &mut ChartContext<'_, SVGBackend<'_>, Cartesian2d<X, Y>>,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        xr: (f64, f64),
        yr: (f64, f64),
    ) -> Drawn
    where
        X: Ranged<ValueType = f64>,
        Y: Ranged<ValueType = f64>,
    {
        let label = TextStyle::from((FONT, TICK_PX).into_font());
        if self.y.log {
            for (v, major) in log_ticks(yr.0, yr.1) {
                c.draw_series(std::iter::once(PathElement::new(
                    vec![(xr.0, v), (xr.1, v)],
                    grey(major).stroke_width(1),
                )))?;
                if major {
                    let (px, py) = c.backend_coord(&(xr.0, v));
                    area.draw(&Text::new(
                        tick(v),
                        (px - 6, py),
                        label.pos(Pos::new(HPos::Right, VPos::Center)),
                    ))?;
                }
            }
        }
        if self.x.log {
            for (v, major) in log_ticks(xr.0, xr.1) {
                c.draw_series(std::iter::once(PathElement::new(
                    vec![(v, yr.0), (v, yr.1)],
                    grey(major).stroke_width(1),
                )))?;
                if major {
                    let (px, py) = c.backend_coord(&(v, yr.0));
                    area.draw(&Text::new(
                        tick(v),
                        (px, py + 6),
                        label.pos(Pos::new(HPos::Center, VPos::Top)),
                    ))?;
                }
            }
        }
        Ok(())
    }

    /// The limits: shaded bands with dashed edges, then dashed rules with
    /// their labels.
    fn limits<X, Y>(
        &self,
        c: &mut ChartContext<'_, SVGBackend<'_>, Cartesian2d<X, Y>>,
        xr: (f64, f64),
        yr: (f64, f64),
    ) -> Drawn
    where
        X: Ranged<ValueType = f64>,
        Y: Ranged<ValueType = f64>,
    {
        for b in &self.bands {
            let (bx0, bx1) = b.x.unwrap_or(xr);
            c.draw_series(std::iter::once(Rectangle::new(
                [(bx0, b.y.0), (bx1, b.y.1)],
                LIMIT.mix(0.10).filled(),
            )))?;
            for edge in [b.y.0, b.y.1] {
                c.draw_series(DashedLineSeries::new(
                    [(bx0, edge), (bx1, edge)],
                    6,
                    4,
                    LIMIT.stroke_width(1),
                ))?;
            }
        }
        for r in &self.rules {
            let (a, b) = if r.vertical {
                ((r.at, yr.0), (r.at, yr.1))
            } else {
                ((xr.0, r.at), (xr.1, r.at))
            };
            c.draw_series(DashedLineSeries::new([a, b], 8, 5, LIMIT.stroke_width(2)))?;
            let at = if r.vertical { b } else { (xr.0, r.at) };
            let offset = if r.vertical { (6, 4) } else { (6, -20) };
            c.draw_series(std::iter::once(
                EmptyElement::at(at) + Text::new(r.label.clone(), offset, (FONT, TICK_PX)),
            ))?;
        }
        Ok(())
    }
}

/// A point of a chart that names itself (see [`Chart::link`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Link {
    /// Where, in data units.
    pub x: f64,
    /// Where, in data units.
    pub y: f64,
    /// What a pointer over it shows.
    pub title: String,
    /// What a click opens.
    pub href: Option<String>,
}

type Drawn = Result<(), Box<dyn std::error::Error>>;

fn lin(a: f64, b: f64) -> RangedCoordf64 {
    (a..b).into()
}

fn log(a: f64, b: f64) -> plotters::coord::combinators::LogCoord<f64> {
    (a.max(1e-12)..b.max(a.max(1e-12) * 10.0))
        .log_scale()
        .into()
}

fn draw_series<X, Y>(
    c: &mut ChartContext<'_, SVGBackend<'_>, Cartesian2d<X, Y>>,
    s: &Series,
) -> Drawn
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let colour = s.colour.unwrap_or(PALETTE[0]);
    let style = colour.stroke_width(s.width);
    for seg in s.segments() {
        let seg = seg.iter().copied();
        match s.stroke {
            Stroke::Solid => {
                c.draw_series(LineSeries::new(seg, style))?;
            }
            Stroke::Dashed => {
                c.draw_series(DashedLineSeries::new(seg, 9, 5, style))?;
            }
            Stroke::Dotted => {
                c.draw_series(DashedLineSeries::new(seg, 2, 4, style))?;
            }
            Stroke::None => {}
        }
    }
    for &(x, lo, hi) in &s.errors {
        c.draw_series(std::iter::once(PathElement::new(
            vec![(x, lo), (x, hi)],
            colour.stroke_width(1),
        )))?;
    }
    if s.marker != Marker::None {
        let glyph = shape(s.marker, s.marker_px);
        c.draw_series(
            s.points
                .iter()
                .map(|&p| EmptyElement::at(p) + Polygon::new(glyph.clone(), colour.filled())),
        )?;
    }
    Ok(())
}

/// A marker's outline in pixels around its point (so it keeps its size
/// whatever the scale).
fn shape(m: Marker, px: i32) -> Vec<(i32, i32)> {
    let r = px;
    let shape: Vec<(i32, i32)> = match m {
        Marker::Circle | Marker::None => (0..12)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 12.0;
                (
                    (r as f64 * a.cos()).round() as i32,
                    (r as f64 * a.sin()).round() as i32,
                )
            })
            .collect(),
        Marker::Square => vec![(-r, -r), (r, -r), (r, r), (-r, r)],
        Marker::Triangle => vec![(0, -r - 1), (r + 1, r), (-r - 1, r)],
        Marker::TriangleDown => vec![(0, r + 1), (r + 1, -r), (-r - 1, -r)],
        Marker::Diamond => vec![(0, -r - 1), (r + 1, 0), (0, r + 1), (-r - 1, 0)],
        Marker::Cross => {
            let t = (r / 3).max(1);
            vec![
                (-r, -r + t),
                (-r + t, -r),
                (0, -t),
                (r - t, -r),
                (r, -r + t),
                (t, 0),
                (r, r - t),
                (r - t, r),
                (0, t),
                (-r + t, r),
                (-r, r - t),
                (-t, 0),
            ]
        }
    };
    shape
}

#[derive(Debug, Clone)]
enum LegendKey {
    Series(Series),
    Band,
}

fn draw_legend(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    rows: &[Vec<(String, LegendKey, i32)>],
) -> Drawn {
    for (i, row) in rows.iter().enumerate() {
        let y = 4 + i as i32 * LEGEND_ROW as i32 + LEGEND_ROW as i32 / 2;
        for (text, key, x) in row {
            let (x0, x1) = (*x, *x + 34);
            match key {
                LegendKey::Series(s) => {
                    let colour = s.colour.unwrap_or(PALETTE[0]);
                    let style = colour.stroke_width(s.width);
                    match s.stroke {
                        Stroke::Solid => {
                            area.draw(&PathElement::new(vec![(x0, y), (x1, y)], style))?;
                        }
                        Stroke::Dashed | Stroke::Dotted => {
                            let (on, off) = if s.stroke == Stroke::Dashed {
                                (9, 5)
                            } else {
                                (2, 4)
                            };
                            let mut a = x0;
                            while a < x1 {
                                area.draw(&PathElement::new(
                                    vec![(a, y), ((a + on).min(x1), y)],
                                    style,
                                ))?;
                                a += on + off;
                            }
                        }
                        Stroke::None => {}
                    }
                    if s.marker != Marker::None {
                        area.draw(
                            &(EmptyElement::at((x0 + 17, y))
                                + Polygon::new(shape(s.marker, s.marker_px), colour.filled())),
                        )?;
                    }
                }
                LegendKey::Band => {
                    area.draw(&Rectangle::new(
                        [(x0, y - 7), (x1, y + 7)],
                        LIMIT.mix(0.10).filled(),
                    ))?;
                    area.draw(&Rectangle::new([(x0, y - 7), (x1, y + 7)], LIMIT))?;
                }
            }
            area.draw(&Text::new(
                text.clone(),
                (x1 + 8, y - LEGEND_PX as i32 / 2 - 1),
                (FONT, LEGEND_PX),
            ))?;
        }
    }
    Ok(())
}

/// A range around finite values with a margin; on a log axis only the
/// positive ones, and the margin is a factor.
fn padded(v: impl Iterator<Item = f64>, log: bool, margin: f64) -> (f64, f64) {
    let (lo, hi) = v
        .filter(|x| x.is_finite() && (!log || *x > 0.0))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
    if !lo.is_finite() {
        return if log { (1.0, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        return (lo / 1.25, hi * 1.25);
    }
    let pad = ((hi - lo) * margin)
        .max(hi.abs().max(lo.abs()) * 1e-3)
        .max(1e-9);
    (lo - pad, hi + pad)
}

/// `labels[i]` at x = i, nothing between.
fn label_at(labels: &[String], x: f64) -> String {
    let i = x.round();
    if (x - i).abs() < 0.01 && i >= 0.0 {
        labels.get(i as usize).cloned().unwrap_or_default()
    } else {
        String::new()
    }
}

/// A linear tick: as few digits as show it (no `0.30000000000000004`).
fn tick(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    let d = if a >= 100.0 {
        0
    } else if a >= 1.0 {
        2
    } else {
        (-(a.log10().floor()) as usize + 2).min(8)
    };
    let s = format!("{v:.d$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

/// A grid line's grey: darker for a labelled one.
fn grey(major: bool) -> RGBColor {
    let g = if major { 215 } else { 238 };
    RGBColor(g, g, g)
}

/// Grid values of a log axis over `lo..hi`: every 1..9 x 10^k, the 1, 2
/// and 5 ones major (labelled); when the range holds fewer than two of
/// those, every one is.
fn log_ticks(lo: f64, hi: f64) -> Vec<(f64, bool)> {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi {
        for m in 1..=9 {
            let v = decade * f64::from(m);
            if v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9) {
                out.push((v, matches!(m, 1 | 2 | 5)));
            }
        }
        decade *= 10.0;
    }
    if out.iter().filter(|t| t.1).count() < 2 {
        for t in &mut out {
            t.1 = true;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_break_at_gaps_and_only_there() {
        let mut pts: Vec<(f64, f64)> = (0..10).map(|i| (i as f64, 0.0)).collect();
        pts.extend((30..40).map(|i| (i as f64, 1.0)));
        let s = Series::line("x", pts);
        let segs = s.segments();
        assert_eq!(segs.len(), 2);
        assert_eq!(segs[0].len(), 10);
        assert_eq!(segs[1][0].0, 30.0);
        let whole = Series::line("x", (0..10).map(|i| (i as f64, 0.0)).collect());
        assert_eq!(whole.segments().len(), 1);
    }

    #[test]
    fn the_legend_is_below_the_plot_area() {
        let c = Chart::new("t", "x", "y")
            .series(Series::line("first series", vec![(0.0, 0.0), (1.0, 1.0)]))
            .series(Series::points("second", vec![(0.5, 0.5)], Marker::Diamond));
        let svg = c.render();
        assert!(svg.starts_with("<figure><svg"), "{}", &svg[..80]);
        // The SVG is taller than the plot area by the legend row, and the
        // legend's text is drawn there.
        assert!(svg.contains(&format!("viewBox=\"0 0 {W} {}\"", PLOT_H + LEGEND_ROW + 8)));
        let at = svg.find(">\nfirst series\n<").expect("legend text");
        let y: f64 = svg[..at]
            .rsplit(" y=\"")
            .next()
            .and_then(|t| t.split('"').next())
            .and_then(|t| t.parse().ok())
            .expect("y of the legend text");
        assert!(y > PLOT_H as f64, "legend at y = {y}");
    }

    #[test]
    fn series_differ_by_more_than_colour() {
        let c = Chart::new("t", "x", "y")
            .series(Series::line("a", vec![(0.0, 0.0), (1.0, 1.0)]))
            .series(Series::line("b", vec![(0.0, 1.0), (1.0, 0.0)]).stroke(Stroke::Dashed));
        let colours: Vec<RGBColor> = c.series.iter().filter_map(|s| s.colour).collect();
        assert_ne!(colours[0], colours[1]);
        assert_ne!(c.series[0].stroke, c.series[1].stroke);
    }

    #[test]
    fn ticks_are_short() {
        assert_eq!(tick(0.30000000000000004), "0.3");
        assert_eq!(tick(-0.0), "0");
        assert_eq!(tick(0.025), "0.025");
        assert_eq!(tick(250.0), "250");
        assert_eq!(tick(1.5), "1.5");
        let t = log_ticks(0.027, 0.82);
        let major: Vec<f64> = t.iter().filter(|t| t.1).map(|t| t.0).collect();
        assert_eq!(major.len(), 4, "{major:?}");
        assert!((major[0] - 0.05).abs() < 1e-12 && (major[3] - 0.5).abs() < 1e-12);
        assert!(t.iter().any(|t| (t.0 - 0.03).abs() < 1e-12 && !t.1));
        // Within one span of no 1, 2 or 5: every grid value is labelled.
        assert!(log_ticks(0.3, 0.45).iter().all(|t| t.1));
    }
}
