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

/// `[step]`: exactly one of `column` or `boundaries`, and optionally
/// `record`.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepMap {
    /// A label column.
    #[serde(default)]
    pub column: Option<Column>,
    /// Boundaries by time, in increasing order.
    #[serde(default)]
    pub boundaries: Option<Vec<Boundary>>,
    /// A column naming the record each row was recorded in (the interchange
    /// CSV's `record`); an empty cell is a row taken outside any record (a
    /// move, a wait, a soak). Without it, records are found as an import of
    /// the interchange CSV without its `record` column finds them.
    #[serde(default)]
    pub record: Option<Column>,
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
    // From a count of nanoseconds to one of days: a scale outside that
    // makes every sample collapse into one second, or the run outlast
    // any run.
    c.ensure(
        (1e-9..=86400.0).contains(&t.scale_s),
        "time.scale_s",
        &format!(
            "is {} s per unit of the time column: give the seconds one unit stands for, from 1e-9 (a count of ns) to 86400 (a count of days); beyond that every sample falls within one second, or a run outlasts any run",
            crate::config::num(t.scale_s)
        ),
    )?;
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
    record: Option<usize>,
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

    /// Every column the map reads, with the key that names it, in the
    /// map's order.
    fn roles(&self) -> Vec<(&'static str, &Column)> {
        let t = &self.temperatures;
        let mut roles = vec![
            ("time.column", &self.time.column),
            ("rate.column", &self.rate.column),
            ("temperatures.t1", &t.t1),
            ("temperatures.t2", &t.t2),
            ("temperatures.tcase", &t.tcase),
            ("temperatures.chamber", &t.chamber),
        ];
        if let Some(o) = &self.orientation.columns {
            roles.push(("orientation.columns.azimuth", &o.azimuth));
            roles.push(("orientation.columns.elevation", &o.elevation));
            roles.push(("orientation.columns.roll", &o.roll));
        }
        if let Some(c) = &self.step.column {
            roles.push(("step.column", c));
        }
        if let Some(c) = &self.step.record {
            roles.push(("step.record", c));
        }
        if let Some(t) = &self.table {
            roles.push(("table.outer", &t.outer));
            roles.push(("table.inner", &t.inner));
        }
        roles
    }

    /// The map's columns as indices of `header`; a column the header lacks,
    /// or one column given two roles (by name or number), is refused at
    /// the map's key.
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
        let mut taken: BTreeMap<usize, &str> = BTreeMap::new();
        for (key, c) in self.roles() {
            let i = find(c, key)?;
            if let Some(first) = taken.insert(i, key) {
                return Err(self.invalid(
                    key,
                    format!(
                        "names column {:?} of {file}, which `{first}` already reads: one column serves one role; give `{key}` its own column",
                        header[i]
                    ),
                ));
            }
        }
        let t = &self.temperatures;
        let pair =
            |a: &Column, ka: &str, b: &Column, kb: &str| -> Result<[usize; 2], ConfigError> {
                Ok([find(a, ka)?, find(b, kb)?])
            };
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
            step: self
                .step
                .column
                .as_ref()
                .map(|c| find(c, "step.column"))
                .transpose()?,
            record: self
                .step
                .record
                .as_ref()
                .map(|c| find(c, "step.record"))
                .transpose()?,
            table: self
                .table
                .as_ref()
                .map(|t| pair(&t.outer, "table.outer", &t.inner, "table.inner"))
                .transpose()?,
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
        let mut dates = Dates {
            power_on: match &self.time.power_on {
                Some(p) => Some(
                    parse_datetime(p, None)
                        .map_err(|e| MapError::Map(self.invalid("time.power_on", e)))?,
                ),
                None => None,
            },
            first: None,
        };
        let mut samples = 0usize;
        let mut second: (f64, usize) = (f64::NAN, 0);
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
            let row = self.map_row(&cols, &cells, &mut dates)?;
            row.check_after(prev_time).map_err(|m| {
                cells.error(format!(
                    "{m} (after the map's conversions; {})",
                    self.src_name()
                ))
            })?;
            // Samples that collapse into one second (a wrong scale) are
            // refused rather than averaged away unseen.
            let s = row.time_s.floor();
            second = if s == second.0 {
                (s, second.1 + 1)
            } else {
                (s, 1)
            };
            if second.1 > MAX_SAMPLES_PER_S {
                return Err(cells.error(self.too_dense(&cols, &header, s)));
            }
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
            power_on_utc: dates
                .power_on
                .map(|p| p.with_timezone(&chrono::Utc).to_rfc3339()),
        })
    }

    /// Where a key of the map is, `m.toml:5:11`, for a message about a row.
    fn key_place(&self, key: &str) -> String {
        let at = self.source.as_ref().and_then(|s| s.locate(key));
        match at {
            Some((line, col)) => format!("{}:{line}:{col}", self.src_name()),
            None => self.src_name(),
        }
    }

    /// Why more than [`MAX_SAMPLES_PER_S`] samples in second `s` are
    /// refused, naming the map's line that made them so dense.
    fn too_dense(&self, cols: &Resolved, header: &[String], s: f64) -> String {
        let column = header.get(cols.time).cloned().unwrap_or_default();
        let why = match self.time.form {
            TimeForm::Seconds => {
                let key = if self
                    .source
                    .as_ref()
                    .and_then(|m| m.locate("time.scale_s"))
                    .is_some()
                {
                    "time.scale_s"
                } else {
                    "time.column"
                };
                format!(
                    "column {column:?} read as {} s per unit (`time.scale_s`, {}) puts them there; check `time.scale_s`, the seconds one unit of the column stands for",
                    crate::config::num(self.time.scale_s),
                    self.key_place(key)
                )
            }
            TimeForm::Datetime => format!(
                "column {column:?} (`time.column`, {}) gives them times that close together",
                self.key_place("time.column")
            ),
        };
        format!(
            "more than {MAX_SAMPLES_PER_S} samples fall within one second ({} to {} s since power-on), more than any gyro output gyrobench reads; {why}",
            crate::config::num(s),
            crate::config::num(s + 1.0)
        )
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
    fn map_row(&self, cols: &Resolved, c: &Cells<'_>, dates: &mut Dates) -> Result<Row, MapError> {
        let time_s = self.time_of(cols, c, dates)?;
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
            record: cols.record.map(|i| c.cell(i).to_owned()),
        })
    }

    /// A row's time since power-on, s: seconds scaled and offset, or a
    /// date and time less the power-on's (the first row's when the map
    /// gives none). A date-time that is before the power-on, or further
    /// after it than a run can last, is refused naming both and the data's
    /// first time.
    fn time_of(&self, cols: &Resolved, c: &Cells<'_>, dates: &mut Dates) -> Result<f64, MapError> {
        Ok(match self.time.form {
            TimeForm::Seconds => {
                c.number(cols.time, "time")? * self.time.scale_s + self.time.offset_s
            }
            TimeForm::Datetime => {
                let t = parse_datetime(c.cell(cols.time), self.time.format.as_deref()).map_err(
                    |e| c.error(format!("column {:?} (time): {e}", c.cell_name(cols.time))),
                )?;
                let first = *dates.first.get_or_insert(t);
                let p0 = *dates.power_on.get_or_insert(t);
                let since = (t - p0).num_nanoseconds().map(|ns| ns as f64 * 1e-9);
                let (lo, hi) = super::interchange::TIME_RANGE_S;
                match since {
                    Some(v) if (lo..=hi).contains(&v) => v,
                    _ => {
                        return Err(c.error(self.far_from_power_on(
                            &c.cell_name(cols.time),
                            t,
                            p0,
                            first,
                            since,
                        )));
                    }
                }
            }
        })
    }

    /// Why the date-time `t` cannot be read as time since the power-on
    /// `p0`, in an operator's words (`since`: how far after it, s, when
    /// that fits in a number).
    fn far_from_power_on(
        &self,
        column: &str,
        t: chrono::DateTime<chrono::FixedOffset>,
        p0: chrono::DateTime<chrono::FixedOffset>,
        first: chrono::DateTime<chrono::FixedOffset>,
        since: Option<f64>,
    ) -> String {
        let rfc = |d: chrono::DateTime<chrono::FixedOffset>| d.to_rfc3339();
        let how = match since {
            Some(v) if v < 0.0 => format!("{} before", span_words(-v)),
            Some(v) => format!("{} after", span_words(v)),
            None if t < p0 => "more than 290 years before".to_owned(),
            None => "more than 290 years after".to_owned(),
        };
        let limit = span_words(super::interchange::TIME_RANGE_S.1);
        match &self.time.power_on {
            Some(_) => format!(
                "column {column:?} (time): {} is {how} the power-on {} (`time.power_on`, {}); the data's first time is {}: give the power-on of this run, at or before the data's first time and at most {limit} before its last",
                rfc(t),
                rfc(p0),
                self.key_place("time.power_on"),
                rfc(first)
            ),
            None => format!(
                "column {column:?} (time): {} is {how} the data's first time {}, which stands for the power-on (no `time.power_on` in {}); a run gyrobench imports lasts at most {limit}: split the file, or check the column's dates",
                rfc(t),
                rfc(first),
                self.src_name()
            ),
        }
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

/// Most samples one second of a lab's file may hold (10 kHz: more than any
/// laser gyro's output a lab logs; a file denser than that has a time
/// column read at the wrong scale).
pub const MAX_SAMPLES_PER_S: usize = 10_000;

/// The power-on a `datetime` column counts from, and the data's first
/// time, as the file is read.
struct Dates {
    /// Given by the map, else the first row's time once read.
    power_on: Option<chrono::DateTime<chrono::FixedOffset>>,
    /// The first row's time.
    first: Option<chrono::DateTime<chrono::FixedOffset>>,
}

/// A span of time in the words an operator reads: `40 s`, `12 min`,
/// `5 h`, `3 days`, `101 years`.
fn span_words(s: f64) -> String {
    let (v, unit) = if s < 120.0 {
        (s, "s")
    } else if s < 7200.0 {
        (s / 60.0, "min")
    } else if s < 2.0 * 86400.0 {
        (s / 3600.0, "h")
    } else if s < 2.0 * 365.25 * 86400.0 {
        (s / 86400.0, "days")
    } else {
        (s / (365.25 * 86400.0), "years")
    };
    format!("{v:.0} {unit}")
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
mod tests;
