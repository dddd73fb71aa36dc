//! Import maps: how to read a lab's own CSV as interchange rows
//! (`gyrobench import FILE --map MAP.toml`, `docs/analysis.md`).
//!
//! Labs do not write the interchange CSV. A map says which column holds
//! what, and in which unit: the time (seconds since power-on in any unit,
//! or a date-time with its zone), the rate (deg/h, deg/s, rad/s, arcsec per
//! sample, or counts with a scale factor), the four temperatures (degC or
//! K), the orientation (columns, one fixed pose, or one pose per step), the
//! step (a label column, or boundaries by time), and optionally the table
//! angles. The file is read as a stream and reduced to 1 s means on the way
//! (a day of 100 Hz samples is never held whole); every bad cell is refused
//! with its file, line, column and what the map said it holds.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;

use super::interchange::{CsvError, Row};
use crate::config::{Checker, ConfigError, Source};
use crate::geometry::Orientation;

/// A column, by its header name or its 1-based number.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(untagged)]
pub enum Column {
    /// The name in the header row.
    Name(String),
    /// 1-based position.
    Number(usize),
}

impl std::fmt::Display for Column {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Name(n) => write!(f, "{n:?}"),
            Self::Number(i) => write!(f, "number {i}"),
        }
    }
}

/// `[file]`: how the text is laid out.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileLayout {
    /// Field separator, one ASCII character (default `,`; `"\t"` for tabs).
    #[serde(default = "comma")]
    pub delimiter: String,
    /// Lines starting with this ASCII character are skipped (none by default).
    #[serde(default)]
    pub comment: Option<String>,
    /// Lines to skip before the header row (a lab's preamble).
    #[serde(default)]
    pub skip_lines: usize,
}

fn comma() -> String {
    ",".into()
}

impl Default for FileLayout {
    fn default() -> Self {
        Self {
            delimiter: comma(),
            comment: None,
            skip_lines: 0,
        }
    }
}

/// How time is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeForm {
    /// A number: time since power-on in units of `scale_s` seconds.
    Seconds,
    /// A date-time with its zone (RFC 3339 / ISO 8601, or `format`).
    Datetime,
}

/// `[time]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeMap {
    /// The column.
    pub column: Column,
    /// `seconds` or `datetime`.
    pub form: TimeForm,
    /// Seconds per unit of a `seconds` column (1 for s, 0.001 for ms,
    /// 0.01 for a count of 10 ms samples).
    #[serde(default = "one")]
    pub scale_s: f64,
    /// Added to a `seconds` column, s (where its zero is not power-on).
    #[serde(default)]
    pub offset_s: f64,
    /// A `datetime` column's format (chrono's strftime, with its zone as
    /// `%z`); RFC 3339 when absent.
    #[serde(default)]
    pub format: Option<String>,
    /// When the unit was powered on (a date-time with zone); a `datetime`
    /// column counts from it (default: the first row's time).
    #[serde(default)]
    pub power_on: Option<String>,
}

fn one() -> f64 {
    1.0
}

/// The rate's unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
pub enum RateUnit {
    /// deg/h.
    #[serde(rename = "deg/h")]
    DegPerHour,
    /// deg/s.
    #[serde(rename = "deg/s")]
    DegPerSecond,
    /// rad/s.
    #[serde(rename = "rad/s")]
    RadPerSecond,
    /// The angle of one sample, arcsec (needs `sample_s`).
    #[serde(rename = "arcsec/sample")]
    ArcsecPerSample,
    /// Counts of one sample (needs `scale_arcsec` and `sample_s`).
    #[serde(rename = "counts")]
    Counts,
}

/// `[rate]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RateMap {
    /// The column.
    pub column: Column,
    /// Its unit.
    pub unit: RateUnit,
    /// Arcsec per count (`counts`).
    #[serde(default)]
    pub scale_arcsec: Option<f64>,
    /// The sample interval, s (`arcsec/sample`, `counts`).
    #[serde(default)]
    pub sample_s: Option<f64>,
    /// Earth rate included (the interchange CSV's convention); `false`
    /// is refused: the file must hold what the gyro measured.
    #[serde(default = "yes")]
    pub earth_rate_included: bool,
}

fn yes() -> bool {
    true
}

/// A temperature unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
pub enum TempUnit {
    /// Degrees Celsius.
    #[default]
    #[serde(rename = "degC")]
    Celsius,
    /// Kelvin.
    #[serde(rename = "K")]
    Kelvin,
}

/// `[temperatures]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TempMap {
    /// Their unit (default degC).
    #[serde(default)]
    pub unit: TempUnit,
    /// Block sensor 1.
    pub t1: Column,
    /// Block sensor 2.
    pub t2: Column,
    /// Housing.
    pub tcase: Column,
    /// Chamber air.
    pub chamber: Column,
}

/// Orientation columns, deg (NED yaw/pitch/roll).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OrientationColumns {
    /// Azimuth (yaw) of the sensitive axis.
    pub azimuth: Column,
    /// Elevation (pitch) of the sensitive axis.
    pub elevation: Column,
    /// Roll about the sensitive axis.
    pub roll: Column,
}

/// `[orientation]`: exactly one of its keys.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OrientationMap {
    /// From columns.
    #[serde(default)]
    pub columns: Option<OrientationColumns>,
    /// One pose for the whole file.
    #[serde(default)]
    pub fixed: Option<Orientation>,
    /// One pose per step label.
    #[serde(default)]
    pub by_step: Option<BTreeMap<String, Orientation>>,
}

/// One step boundary: rows from `from_s` on (until the next) belong to
/// `label`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Boundary {
    /// Time since power-on, s.
    pub from_s: f64,
    /// Step label.
    pub label: String,
}

/// `[step]`: exactly one of its keys.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepMap {
    /// A label column.
    #[serde(default)]
    pub column: Option<Column>,
    /// Boundaries by time, in increasing order.
    #[serde(default)]
    pub boundaries: Option<Vec<Boundary>>,
}

/// `[table]`: the table axis angles, deg, where the file has them.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableMap {
    /// Outer axis angle.
    pub outer: Column,
    /// Inner axis angle.
    pub inner: Column,
}

/// A whole import map.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportMap {
    /// Layout.
    #[serde(default)]
    pub file: FileLayout,
    /// Time.
    pub time: TimeMap,
    /// Rate.
    pub rate: RateMap,
    /// Temperatures.
    pub temperatures: TempMap,
    /// Orientation.
    pub orientation: OrientationMap,
    /// Steps.
    pub step: StepMap,
    /// Table angles, if in the file.
    #[serde(default)]
    pub table: Option<TableMap>,
    /// Where this map came from (for errors).
    #[serde(skip)]
    source: Option<Source>,
}

/// Parse a date-time with zone: RFC 3339, or `format`.
fn parse_datetime(
    s: &str,
    format: Option<&str>,
) -> Result<chrono::DateTime<chrono::FixedOffset>, String> {
    match format {
        Some(f) => chrono::DateTime::parse_from_str(s, f)
            .map_err(|e| format!("{s:?} is not a date-time in the form {f:?} ({e})")),
        None => chrono::DateTime::parse_from_rfc3339(s).map_err(|e| {
            format!("{s:?} is not an RFC 3339 date-time with its zone, like 2026-03-02T08:00:00.25+07:00 ({e}); give [time] format for another form")
        }),
    }
}

/// Read and check a map file.
pub fn load(path: &Path) -> Result<ImportMap, ConfigError> {
    from_source(Source::read(path)?)
}

/// Parse and check a map's text.
pub fn from_source(src: Source) -> Result<ImportMap, ConfigError> {
    let mut m: ImportMap = src.parse()?;
    let c = Checker::new(&src);
    let one_char = |v: &str, key: &str| {
        c.ensure(
            v.len() == 1 && v.is_ascii(),
            key,
            &format!("must be one ASCII character, got {v:?}"),
        )
    };
    one_char(&m.file.delimiter, "file.delimiter")?;
    if let Some(cm) = &m.file.comment {
        one_char(cm, "file.comment")?;
    }
    check_time(&c, &src, &m.time)?;
    check_rate(&c, &src, &m.rate)?;
    check_orientation(&c, &m.orientation)?;
    check_step(&c, &m.step)?;
    m.source = Some(src);
    Ok(m)
}

/// `[time]`: its scale and offset, and what goes with its form.
fn check_time(c: &Checker<'_>, src: &Source, t: &TimeMap) -> Result<(), ConfigError> {
    c.positive(t.scale_s, "time.scale_s")?;
    c.within(t.offset_s, -1e7, 1e7, "time.offset_s")?;
    match t.form {
        TimeForm::Seconds => {
            c.ensure(
                t.format.is_none() && t.power_on.is_none(),
                "time.form",
                "is `seconds`: `format` and `power_on` are for a `datetime` column",
            )?;
        }
        TimeForm::Datetime => {
            c.ensure(
                t.scale_s == 1.0 && t.offset_s == 0.0,
                "time.form",
                "is `datetime`: `scale_s` and `offset_s` are for a `seconds` column (give `power_on`)",
            )?;
            if let Some(p) = &t.power_on {
                parse_datetime(p, None).map_err(|e| src.invalid("time.power_on", e))?;
            }
        }
    }
    Ok(())
}

/// `[rate]`: Earth rate included, and what its unit needs.
fn check_rate(c: &Checker<'_>, src: &Source, r: &RateMap) -> Result<(), ConfigError> {
    c.ensure(
        r.earth_rate_included,
        "rate.earth_rate_included",
        "must be true: gyrobench takes the rate as measured, Earth rate included, and removes it from the orientation",
    )?;
    match r.unit {
        RateUnit::Counts | RateUnit::ArcsecPerSample => {
            let s = r.sample_s.ok_or_else(|| {
                src.invalid(
                    "rate.unit",
                    "is per sample: give `sample_s`, the sample interval in s",
                )
            })?;
            c.positive(s, "rate.sample_s")?;
            c.within(s, 1e-6, 1.0, "rate.sample_s")?;
        }
        _ => c.ensure(
            r.sample_s.is_none(),
            "rate.sample_s",
            "is only for a rate per sample (`arcsec/sample`, `counts`)",
        )?,
    }
    match (r.unit, r.scale_arcsec) {
        (RateUnit::Counts, Some(k)) => {
            c.positive(k, "rate.scale_arcsec")?;
        }
        (RateUnit::Counts, None) => {
            return Err(src.invalid(
                "rate.unit",
                "is `counts`: give `scale_arcsec`, the angle of one count in arcsec",
            ));
        }
        (_, Some(_)) => {
            return Err(src.invalid("rate.scale_arcsec", "is only for `counts`"));
        }
        (_, None) => {}
    }
    Ok(())
}

/// `[orientation]`: exactly one way to a pose, each pose within range.
fn check_orientation(c: &Checker<'_>, o: &OrientationMap) -> Result<(), ConfigError> {
    let given = [o.columns.is_some(), o.fixed.is_some(), o.by_step.is_some()];
    c.ensure(
        given.iter().filter(|g| **g).count() == 1,
        "orientation",
        "needs exactly one of `columns`, `fixed` or `by_step`",
    )?;
    if let Some(f) = &o.fixed {
        check_pose(c, f, "orientation.fixed")?;
    }
    if let Some(by) = &o.by_step {
        c.ensure(!by.is_empty(), "orientation.by_step", "names no step")?;
        for (label, p) in by {
            check_pose(c, p, &format!("orientation.by_step.{label}"))?;
        }
    }
    Ok(())
}

/// `[step]`: a column or boundaries, the boundaries in order and named.
fn check_step(c: &Checker<'_>, s: &StepMap) -> Result<(), ConfigError> {
    c.ensure(
        s.column.is_some() != s.boundaries.is_some(),
        "step",
        "needs exactly one of `column` or `boundaries`",
    )?;
    if let Some(b) = &s.boundaries {
        c.ensure(!b.is_empty(), "step.boundaries", "is empty")?;
        for (i, w) in b.windows(2).enumerate() {
            c.ensure(
                w[1].from_s > w[0].from_s,
                &format!("step.boundaries.{}.from_s", i + 1),
                "must be after the boundary before it",
            )?;
        }
        for (i, x) in b.iter().enumerate() {
            c.within(x.from_s, 0.0, 1e7, &format!("step.boundaries.{i}.from_s"))?;
            c.ensure(
                !x.label.trim().is_empty()
                    && x.label.chars().count() <= 64
                    && !x.label.chars().any(char::is_control),
                &format!("step.boundaries.{i}.label"),
                "must be 1 to 64 characters, none of them a control character",
            )?;
        }
    }
    Ok(())
}

fn check_pose(c: &Checker<'_>, o: &Orientation, key: &str) -> Result<(), ConfigError> {
    c.within(o.azimuth_deg, -720.0, 720.0, &format!("{key}.azimuth_deg"))?;
    c.within(
        o.elevation_deg,
        -90.0,
        90.0,
        &format!("{key}.elevation_deg"),
    )?;
    c.within(o.roll_deg, -720.0, 720.0, &format!("{key}.roll_deg"))?;
    Ok(())
}

/// Columns resolved to 0-based indices of the header.
#[derive(Debug)]
struct Resolved {
    time: usize,
    rate: usize,
    temps: [usize; 4],
    orientation: Option<[usize; 3]>,
    step: Option<usize>,
    table: Option<[usize; 2]>,
}

/// What a mapped file gave.
#[derive(Debug, Clone)]
pub struct Mapped {
    /// The rows, reduced to 1 s means where finer.
    pub rows: Vec<Row>,
    /// Rows read from the file.
    pub samples: usize,
    /// Power-on in UTC (RFC 3339), when the time column gives dates.
    pub power_on_utc: Option<String>,
}

impl ImportMap {
    fn src_name(&self) -> String {
        self.source
            .as_ref()
            .map_or_else(|| "the map".into(), |s| s.path.display().to_string())
    }

    fn invalid(&self, key: &str, message: String) -> ConfigError {
        match &self.source {
            Some(s) => s.invalid(key, message),
            None => Source::from_text("map", "").invalid(key, message),
        }
    }

    fn resolve(&self, header: &[String], file: &str) -> Result<Resolved, ConfigError> {
        let find = |c: &Column, key: &str| -> Result<usize, ConfigError> {
            let found = match c {
                Column::Name(n) => header.iter().position(|h| h == n),
                Column::Number(i) => (*i >= 1 && *i <= header.len()).then(|| i - 1),
            };
            found.ok_or_else(|| {
                self.invalid(
                    key,
                    format!(
                        "names column {c}, which {file}'s header does not have (its columns: {})",
                        header.join(", ")
                    ),
                )
            })
        };
        let t = &self.temperatures;
        Ok(Resolved {
            time: find(&self.time.column, "time.column")?,
            rate: find(&self.rate.column, "rate.column")?,
            temps: [
                find(&t.t1, "temperatures.t1")?,
                find(&t.t2, "temperatures.t2")?,
                find(&t.tcase, "temperatures.tcase")?,
                find(&t.chamber, "temperatures.chamber")?,
            ],
            orientation: match &self.orientation.columns {
                Some(o) => Some([
                    find(&o.azimuth, "orientation.columns.azimuth")?,
                    find(&o.elevation, "orientation.columns.elevation")?,
                    find(&o.roll, "orientation.columns.roll")?,
                ]),
                None => None,
            },
            step: match &self.step.column {
                Some(c) => Some(find(c, "step.column")?),
                None => None,
            },
            table: match &self.table {
                Some(t) => Some([
                    find(&t.outer, "table.outer")?,
                    find(&t.inner, "table.inner")?,
                ]),
                None => None,
            },
        })
    }

    /// Read the lab's file at `path` through this map.
    pub fn read(&self, path: &Path) -> Result<Mapped, MapError> {
        let name = path.display().to_string();
        let mut input = super::interchange::open_rows(path).map_err(MapError::Csv)?;
        self.parse(std::io::BufReader::new(&mut input), &name)
            .map_err(|e| super::interchange::overlong(&input, &name).map_or(e, MapError::Csv))
    }

    /// Read a lab's file from any reader; `name` labels errors.
    pub fn parse(&self, mut input: impl std::io::BufRead, name: &str) -> Result<Mapped, MapError> {
        let skipped = self.skip_preamble(&mut input, name)?;
        let mut rdr = self.csv_reader(input);
        let header: Vec<String> = rdr
            .headers()
            .map_err(|e| row_error(name, skipped + 1, format!("unreadable header: {e}")))?
            .iter()
            .map(str::to_owned)
            .collect();
        let cols = self.resolve(&header, name).map_err(MapError::Map)?;
        let mut out = super::interchange::OneHz::default();
        let mut prev_time: Option<f64> = None;
        let mut power_on = match &self.time.power_on {
            Some(p) => Some(
                parse_datetime(p, None)
                    .map_err(|e| MapError::Map(self.invalid("time.power_on", e)))?,
            ),
            None => None,
        };
        let mut samples = 0usize;
        let mut rec = csv::StringRecord::new();
        loop {
            let more = rdr.read_record(&mut rec).map_err(|e| {
                let line = e.position().map_or(0, csv::Position::line) + skipped;
                row_error(name, line, format!("unreadable row: {e}"))
            })?;
            if !more {
                break;
            }
            let cells = Cells {
                rec: &rec,
                header: &header,
                line: rec.position().map_or(0, csv::Position::line) + skipped,
                name,
            };
            let row = self.map_row(&cols, &cells, &mut power_on)?;
            row.check_after(prev_time).map_err(|m| {
                cells.error(format!(
                    "{m} (after the map's conversions; {})",
                    self.src_name()
                ))
            })?;
            prev_time = Some(row.time_s);
            samples += 1;
            out.push(row);
        }
        let rows = out.finish();
        if rows.is_empty() {
            return Err(row_error(
                name,
                skipped + 2,
                "no samples after the header".into(),
            ));
        }
        Ok(Mapped {
            rows,
            samples,
            power_on_utc: power_on.map(|p| p.with_timezone(&chrono::Utc).to_rfc3339()),
        })
    }

    /// Skip the preamble's `[file] skip_lines` lines; how many were skipped.
    fn skip_preamble(
        &self,
        input: &mut impl std::io::BufRead,
        name: &str,
    ) -> Result<u64, MapError> {
        let mut skipped = 0u64;
        for _ in 0..self.file.skip_lines {
            let mut l = Vec::new();
            let n = input
                .read_until(b'\n', &mut l)
                .map_err(|e| row_error(name, skipped + 1, format!("unreadable: {e}")))?;
            if n == 0 {
                return Err(row_error(
                    name,
                    skipped + 1,
                    format!(
                        "the file ends within the {} lines [file] skip_lines skips",
                        self.file.skip_lines
                    ),
                ));
            }
            skipped += 1;
        }
        Ok(skipped)
    }

    /// A CSV reader of the rest with the map's delimiter and comment.
    fn csv_reader<R: std::io::Read>(&self, input: R) -> csv::Reader<R> {
        let mut b = csv::ReaderBuilder::new();
        b.has_headers(true)
            .trim(csv::Trim::All)
            .delimiter(self.file.delimiter.as_bytes()[0]);
        if let Some(c) = &self.file.comment {
            b.comment(Some(c.as_bytes()[0]));
        }
        b.from_reader(input)
    }

    /// One row of the lab's file as an interchange row: its time, rate,
    /// temperatures, step, pose and table angles, in that order.
    fn map_row(
        &self,
        cols: &Resolved,
        c: &Cells<'_>,
        power_on: &mut Option<chrono::DateTime<chrono::FixedOffset>>,
    ) -> Result<Row, MapError> {
        let time_s = self.time_of(cols, c, power_on)?;
        let rate_dph = self.rate_dph(c.number(cols.rate, "rate")?);
        let mut temps = [0.0; 4];
        for (k, (t, what)) in temps
            .iter_mut()
            .zip(["t1", "t2", "tcase", "chamber"])
            .enumerate()
        {
            let v = c.number(cols.temps[k], what)?;
            *t = match self.temperatures.unit {
                TempUnit::Celsius => v,
                TempUnit::Kelvin => v - 273.15,
            };
        }
        let step = self.step_of(cols, c, time_s)?;
        let o = self.orientation_of(cols, c, &step)?;
        let (outer_deg, inner_deg) = match cols.table {
            Some([a, b]) => {
                let opt = |i: usize, what: &str| -> Result<Option<f64>, MapError> {
                    if c.cell(i).is_empty() {
                        Ok(None)
                    } else {
                        c.number(i, what).map(Some)
                    }
                };
                (opt(a, "outer table angle")?, opt(b, "inner table angle")?)
            }
            None => (None, None),
        };
        Ok(Row {
            time_s,
            rate_dph,
            t1_c: temps[0],
            t2_c: temps[1],
            tcase_c: temps[2],
            chamber_c: temps[3],
            azimuth_deg: o.azimuth_deg,
            elevation_deg: o.elevation_deg,
            roll_deg: o.roll_deg,
            step,
            outer_deg,
            inner_deg,
        })
    }

    /// A row's time since power-on, s: seconds scaled and offset, or a
    /// date and time less the power-on's (the first row's when the map
    /// gives none).
    fn time_of(
        &self,
        cols: &Resolved,
        c: &Cells<'_>,
        power_on: &mut Option<chrono::DateTime<chrono::FixedOffset>>,
    ) -> Result<f64, MapError> {
        Ok(match self.time.form {
            TimeForm::Seconds => {
                c.number(cols.time, "time")? * self.time.scale_s + self.time.offset_s
            }
            TimeForm::Datetime => {
                let t = parse_datetime(c.cell(cols.time), self.time.format.as_deref()).map_err(
                    |e| c.error(format!("column {:?} (time): {e}", c.cell_name(cols.time))),
                )?;
                let p0 = *power_on.get_or_insert(t);
                (t - p0)
                    .num_nanoseconds()
                    .map_or(f64::NAN, |ns| ns as f64 * 1e-9)
            }
        })
    }

    /// A rate in the map's unit, in deg/h.
    fn rate_dph(&self, raw: f64) -> f64 {
        match self.rate.unit {
            RateUnit::DegPerHour => raw,
            RateUnit::DegPerSecond => raw * 3600.0,
            RateUnit::RadPerSecond => raw.to_degrees() * 3600.0,
            // 1 arcsec/s is 1 deg/h.
            RateUnit::ArcsecPerSample => raw / self.rate.sample_s.unwrap_or(1.0),
            RateUnit::Counts => {
                raw * self.rate.scale_arcsec.unwrap_or(1.0) / self.rate.sample_s.unwrap_or(1.0)
            }
        }
    }

    /// A row's step: its column's, or the label of the last boundary at
    /// or before its time, or none.
    fn step_of(&self, cols: &Resolved, c: &Cells<'_>, time_s: f64) -> Result<String, MapError> {
        Ok(match (cols.step, &self.step.boundaries) {
            (Some(i), _) => c.cell(i).to_owned(),
            (None, Some(b)) => match b.iter().rev().find(|x| x.from_s <= time_s) {
                Some(x) => x.label.clone(),
                None => {
                    return Err(c.error(format!(
                        "time {time_s} s is before the first step boundary ({} s) of {}",
                        b[0].from_s,
                        self.src_name()
                    )));
                }
            },
            (None, None) => String::new(),
        })
    }

    /// A row's pose: its columns', the map's fixed one, or its step's.
    fn orientation_of(
        &self,
        cols: &Resolved,
        c: &Cells<'_>,
        step: &str,
    ) -> Result<Orientation, MapError> {
        Ok(match (&cols.orientation, &self.orientation) {
            (Some([a, e, r]), _) => Orientation::new(
                c.number(*a, "azimuth")?,
                c.number(*e, "elevation")?,
                c.number(*r, "roll")?,
            ),
            (None, OrientationMap { fixed: Some(f), .. }) => *f,
            (
                None,
                OrientationMap {
                    by_step: Some(by), ..
                },
            ) => *by.get(step).ok_or_else(|| {
                c.error(format!(
                    "step {step:?} has no pose in [orientation.by_step] of {} (it has {})",
                    self.src_name(),
                    by.keys()
                        .map(|k| format!("{k:?}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            })?,
            _ => Orientation::new(0.0, 0.0, 0.0),
        })
    }
}

/// A bad row of file `name` at `line`.
fn row_error(name: &str, line: u64, message: String) -> MapError {
    MapError::Csv(CsvError::Row {
        path: name.to_owned(),
        line,
        message,
    })
}

/// One record of the lab's file, with what its errors name.
struct Cells<'a> {
    rec: &'a csv::StringRecord,
    header: &'a [String],
    /// Its line in the file.
    line: u64,
    /// The file.
    name: &'a str,
}

impl Cells<'_> {
    /// Cell `i` (empty when the row is short).
    fn cell(&self, i: usize) -> &str {
        self.rec.get(i).unwrap_or("")
    }

    /// Column `i`'s header.
    fn cell_name(&self, i: usize) -> String {
        self.header.get(i).cloned().unwrap_or_default()
    }

    /// Cell `i` as a number; the error names the column and `what`.
    fn number(&self, i: usize, what: &str) -> Result<f64, MapError> {
        let v = self.cell(i);
        v.parse::<f64>().map_err(|_| {
            self.error(format!(
                "column {:?} ({what}): {v:?} is not a number",
                self.cell_name(i)
            ))
        })
    }

    /// An error at this row.
    fn error(&self, message: String) -> MapError {
        row_error(self.name, self.line, message)
    }
}

/// Why a mapped file cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// The map does not fit the file.
    #[error(transparent)]
    Map(#[from] ConfigError),
    /// A bad row.
    #[error(transparent)]
    Csv(#[from] CsvError),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(text: &str) -> Result<ImportMap, ConfigError> {
        from_source(Source::from_text("m.toml", text))
    }

    const TEMPS: &str = "[temperatures]\nt1 = \"a\"\nt2 = \"b\"\ntcase = \"c\"\nchamber = \"d\"\n";

    fn with(rate: &str, rest: &str) -> String {
        format!(
            "[time]\ncolumn = \"t\"\nform = \"seconds\"\n\n[rate]\ncolumn = \"r\"\n{rate}\n\n{TEMPS}\n{rest}"
        )
    }

    const FIXED: &str = "[orientation]\nfixed = { azimuth_deg = 90.0, elevation_deg = 0.0, roll_deg = 0.0 }\n[step]\nboundaries = [{ from_s = 0.0, label = \"a\" }, { from_s = 2.0, label = \"b\" }]\n";

    #[test]
    fn every_rate_unit_is_converted_to_deg_per_hour() {
        let w = 7.292_115e-5_f64;
        for (unit, cell, want) in [
            ("unit = \"deg/h\"", "15.041", 15.041),
            ("unit = \"deg/s\"", "0.5", 1800.0),
            ("unit = \"rad/s\"", &format!("{w}"), w.to_degrees() * 3600.0),
            // 0.15 arcsec in 10 ms is 15 arcsec/s, 15 deg/h.
            ("unit = \"arcsec/sample\"\nsample_s = 0.01", "0.15", 15.0),
            (
                "unit = \"counts\"\nscale_arcsec = 0.05\nsample_s = 0.01",
                "3",
                15.0,
            ),
        ] {
            let m = map(&with(unit, FIXED)).unwrap_or_else(|e| panic!("{unit}: {e}"));
            let text = format!("t,r,a,b,c,d\n0.25,{cell},20,20,20,20\n");
            let got = m.parse(text.as_bytes(), "f.csv").expect("parses");
            assert!(
                (got.rows[0].rate_dph - want).abs() < 1e-9 * want.abs().max(1.0),
                "{unit}: {}",
                got.rows[0].rate_dph
            );
        }
    }

    #[test]
    fn kelvin_dates_steps_and_poses_come_out_as_interchange_rows() {
        let text = "[file]\ndelimiter = \";\"\n[time]\ncolumn = 1\nform = \"datetime\"\n[rate]\ncolumn = \"r\"\nunit = \"deg/h\"\n[temperatures]\nunit = \"K\"\nt1 = \"a\"\nt2 = \"b\"\ntcase = \"c\"\nchamber = \"d\"\n[step]\ncolumn = \"s\"\n[orientation.by_step]\nup = { azimuth_deg = 0.0, elevation_deg = 90.0, roll_deg = 0.0 }\nnorth = { azimuth_deg = 0.0, elevation_deg = 0.0, roll_deg = 0.0 }\n";
        let m = map(text).expect("map");
        let csv = "when;r;a;b;c;d;s\n2026-03-02T08:00:00.5+07:00;12;293.15;294.15;295.15;296.15;up\n2026-03-02T01:00:01.5Z;9;293.15;293.15;293.15;293.15;north\n";
        let got = m.parse(csv.as_bytes(), "f.csv").expect("parses");
        assert_eq!(
            got.power_on_utc.as_deref(),
            Some("2026-03-02T01:00:00.500+00:00")
        );
        let r = &got.rows;
        assert_eq!(r.len(), 2);
        assert_eq!((r[0].time_s, r[1].time_s), (0.0, 1.0));
        assert!((r[0].t1_c - 20.0).abs() < 1e-9 && (r[0].chamber_c - 23.0).abs() < 1e-9);
        assert_eq!((r[0].elevation_deg, r[1].elevation_deg), (90.0, 0.0));
        assert_eq!(r[1].step, "north");
        // A step the map gives no pose is refused with its line.
        let bad = format!("{csv}2026-03-02T08:00:02.5+07:00;9;293.15;293.15;293.15;293.15;east\n");
        let e = m
            .parse(bad.as_bytes(), "f.csv")
            .expect_err("no pose")
            .to_string();
        assert!(e.starts_with("f.csv:4: step \"east\" has no pose"), "{e}");
    }

    #[test]
    fn samples_finer_than_a_second_are_averaged_per_second_and_step() {
        let m = map(&with(
            "unit = \"counts\"\nscale_arcsec = 0.01\nsample_s = 0.01",
            FIXED,
        ))
        .expect("map");
        let mut csv = String::from("t,r,a,b,c,d\n");
        for k in 0..400 {
            // Alternating 10 and 20 counts: 15 counts of 0.01 arcsec per 10 ms.
            csv.push_str(&format!(
                "{},{},20,20,20,{}\n",
                k as f64 * 0.01,
                10 + 10 * (k % 2),
                k / 100
            ));
        }
        let got = m.parse(csv.as_bytes(), "f.csv").expect("parses");
        assert_eq!(got.samples, 400);
        let times: Vec<f64> = got.rows.iter().map(|r| r.time_s).collect();
        assert_eq!(times, [0.5, 1.5, 2.5, 3.5]);
        for (i, r) in got.rows.iter().enumerate() {
            assert!((r.rate_dph - 15.0).abs() < 1e-9, "{r:?}");
            assert_eq!(r.chamber_c, i as f64);
            assert_eq!(r.step, if i < 2 { "a" } else { "b" });
        }
    }

    #[test]
    fn a_bad_map_or_cell_is_named_with_its_place() {
        for (text, want) in [
            (
                with("unit = \"counts\"\nsample_s = 0.01", FIXED),
                "m.toml:7:8: `rate.unit` is `counts`: give `scale_arcsec`",
            ),
            (
                with("unit = \"deg/s\"\nsample_s = 0.01", FIXED),
                "`rate.sample_s` is only for a rate per sample",
            ),
            (
                with(
                    "unit = \"deg/s\"",
                    "[step]\ncolumn = \"s\"\n[orientation]\n",
                ),
                "`orientation` needs exactly one of",
            ),
            (
                with(
                    "unit = \"deg/s\"",
                    "[orientation]\nfixed = { azimuth_deg = 0.0, elevation_deg = 95.0, roll_deg = 0.0 }\n[step]\ncolumn = \"s\"\n",
                ),
                "`orientation.fixed.elevation_deg`",
            ),
            (
                with("unit = \"deg/s\"\nearth_rate_included = false", FIXED),
                "`rate.earth_rate_included` must be true",
            ),
            (
                with(
                    "unit = \"deg/s\"",
                    "[orientation]\nfixed = { azimuth_deg = 0.0, elevation_deg = 0.0, roll_deg = 0.0 }\n[step]\nboundaries = [{ from_s = 5.0, label = \"a\" }, { from_s = 2.0, label = \"b\" }]\n",
                ),
                "`step.boundaries.1.from_s` must be after",
            ),
        ] {
            let e = map(&text).expect_err(want).to_string();
            assert!(e.contains(want), "{e}");
        }
        let m = map(&with("unit = \"deg/s\"", FIXED)).expect("map");
        for (csv, want) in [
            (
                "t,r,a,b,c\n",
                "m.toml:13:11: `temperatures.chamber` names column \"d\", which f.csv's header does not have (its columns: t, r, a, b, c)",
            ),
            (
                "t,r,a,b,c,d\n0,1,20,20,20,20\n1,x,20,20,20,20\n",
                "f.csv:3: column \"r\" (rate): \"x\" is not a number",
            ),
            (
                "t,r,a,b,c,d\n0,1,20,20,20,20\n0,1,20,20,20,20\n",
                "f.csv:3: field time_s: 0 does not follow 0",
            ),
            (
                "t,r,a,b,c,d\n0,1,20,20,20,900\n",
                "f.csv:2: field chamber_c: 900 is outside",
            ),
            ("t,r,a,b,c,d\n", "f.csv:2: no samples"),
        ] {
            let e = m
                .parse(csv.as_bytes(), "f.csv")
                .expect_err(want)
                .to_string();
            assert!(e.starts_with(want), "{e}");
        }
    }

    proptest::proptest! {
        /// Arbitrary text under a good map: rows or an error, never a panic.
        #[test]
        fn arbitrary_input_never_panics(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..2000)) {
            if let Ok(m) = map(&with("unit = \"counts\"\nscale_arcsec = 0.01\nsample_s = 0.01", FIXED)) {
                let _ = m.parse(bytes.as_slice(), "fuzz.csv");
                let mut text = b"t,r,a,b,c,d\n".to_vec();
                text.extend_from_slice(&bytes);
                let _ = m.parse(text.as_slice(), "fuzz.csv");
            }
        }
    }
}
