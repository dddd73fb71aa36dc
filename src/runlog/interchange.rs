//! The interchange CSV of runs recorded elsewhere (`docs/analysis.md`,
//! from the diagnosis notes): a header row, then one row per sample,
//!
//! `time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step`
//!
//! time in s since power-on (gaps allowed, never backwards), rate in deg/h
//! with Earth rate included, temperatures in degC, orientation as NED
//! yaw/pitch/roll in degrees, and the label of the step the sample belongs
//! to. Read with the `csv` crate; every bad row is refused with its line.

use std::path::Path;

use serde::Deserialize;

use crate::config::num;

/// The header, exactly.
pub const HEADER: [&str; 10] = [
    "time_s",
    "rate_dph",
    "t1_c",
    "t2_c",
    "tcase_c",
    "chamber_c",
    "azimuth_deg",
    "elevation_deg",
    "roll_deg",
    "step",
];

/// Optional columns after the ten: the table's axis angles at the row, deg,
/// when the run was made on a two-axis table and they are known (both or
/// neither; an empty cell is a row whose angles are not known).
pub const TABLE_COLUMNS: [&str; 2] = ["outer_deg", "inner_deg"];

/// Optional column after the ten (and the table's): the label of the
/// record the row was recorded in, empty for a row taken outside any
/// record (a move, a wait, a soak). `export` writes it; without it,
/// `import` finds the records from the step labels.
pub const RECORD_COLUMN: &str = "record";

/// Table angles a row may have, deg (ten turns either way, as a bench's
/// table range).
pub const TABLE_RANGE_DEG: (f64, f64) = (-3600.0, 3600.0);

/// Time since power-on a row may have, s (from power-on to 115 days).
pub const TIME_RANGE_S: (f64, f64) = (0.0, 1e7);
/// Rate a row may have, deg/h (1000 deg/s either way: beyond any laser
/// gyro's input range).
pub const RATE_RANGE_DPH: (f64, f64) = (-3.6e6, 3.6e6);
/// Temperature a row may have, degC (well outside any chamber's range).
pub const TEMP_RANGE_C: (f64, f64) = (-100.0, 200.0);
/// Azimuth and roll a row may have, deg (two turns either way).
pub const ANGLE_RANGE_DEG: (f64, f64) = (-720.0, 720.0);

/// One sample.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct Row {
    /// s since power-on.
    pub time_s: f64,
    /// Measured rate, Earth rate included, deg/h.
    pub rate_dph: f64,
    /// Block sensor 1, degC.
    pub t1_c: f64,
    /// Block sensor 2, degC.
    pub t2_c: f64,
    /// Case sensor, degC.
    pub tcase_c: f64,
    /// Chamber air, degC.
    pub chamber_c: f64,
    /// Yaw of the body in NED, deg.
    pub azimuth_deg: f64,
    /// Pitch (elevation of the sensitive axis), deg.
    pub elevation_deg: f64,
    /// Roll about the sensitive axis, deg.
    pub roll_deg: f64,
    /// Step label.
    pub step: String,
    /// Outer table axis angle, deg, where known.
    #[serde(default)]
    pub outer_deg: Option<f64>,
    /// Inner table axis angle, deg, where known.
    #[serde(default)]
    pub inner_deg: Option<f64>,
    /// The record the row was recorded in: `Some("")` for a row taken
    /// outside any record, none when the file does not say (no `record`
    /// column).
    #[serde(default)]
    pub record: Option<String>,
}

impl Row {
    /// The orientation of the body.
    pub fn orientation(&self) -> crate::geometry::Orientation {
        crate::geometry::Orientation::new(self.azimuth_deg, self.elevation_deg, self.roll_deg)
    }

    /// The table angles, when the row has both.
    pub fn table_angles(&self) -> Option<crate::geometry::TableAngles> {
        Some(crate::geometry::TableAngles {
            outer_deg: self.outer_deg?,
            inner_deg: self.inner_deg?,
        })
    }

    /// What is wrong with this row after `prev`, naming the field: a
    /// value that is not finite or outside what a gyro run can record, a
    /// time that does not increase, one table angle without the other.
    pub fn check(&self, prev: Option<&Row>) -> Result<(), RowError> {
        self.check_after(prev.map(|p| p.time_s))
    }

    /// [`Row::check`] after a row at `prev_time_s`.
    pub fn check_after(&self, prev_time_s: Option<f64>) -> Result<(), RowError> {
        let mut fields = vec![
            (self.time_s, "time_s", TIME_RANGE_S),
            (self.rate_dph, "rate_dph", RATE_RANGE_DPH),
            (self.t1_c, "t1_c", TEMP_RANGE_C),
            (self.t2_c, "t2_c", TEMP_RANGE_C),
            (self.tcase_c, "tcase_c", TEMP_RANGE_C),
            (self.chamber_c, "chamber_c", TEMP_RANGE_C),
            (self.azimuth_deg, "azimuth_deg", ANGLE_RANGE_DEG),
            (self.elevation_deg, "elevation_deg", (-90.0, 90.0)),
            (self.roll_deg, "roll_deg", ANGLE_RANGE_DEG),
        ];
        fields.extend(self.outer_deg.map(|v| (v, "outer_deg", TABLE_RANGE_DEG)));
        fields.extend(self.inner_deg.map(|v| (v, "inner_deg", TABLE_RANGE_DEG)));
        for (value, field, (lo, hi)) in fields {
            if !value.is_finite() {
                return Err(RowError::NotFinite { field, value });
            }
            if !(lo..=hi).contains(&value) {
                return Err(RowError::OutOfRange {
                    field,
                    value,
                    range: (lo, hi),
                });
            }
        }
        if self.outer_deg.is_some() != self.inner_deg.is_some() {
            let (field, other) = if self.outer_deg.is_none() {
                ("outer_deg", "inner_deg")
            } else {
                ("inner_deg", "outer_deg")
            };
            return Err(RowError::OneTableAngle { field, other });
        }
        if let Some(prev_s) = prev_time_s
            && self.time_s <= prev_s
        {
            return Err(RowError::TimeNotIncreasing {
                time_s: self.time_s,
                prev_s,
            });
        }
        Ok(())
    }
}

/// What is wrong with one row of the interchange CSV (its file and line
/// are the caller's to add).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RowError {
    /// A value that is not a number (NaN, infinite).
    #[error("field {field}: {value} is not a finite number")]
    NotFinite {
        /// The column.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A value beyond what a gyro run can record.
    #[error(
        "field {field}: {} is outside {}..{}, beyond what a gyro run can record",
        num(*.value),
        num(.range.0),
        num(.range.1)
    )]
    OutOfRange {
        /// The column.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What the column can hold.
        range: (f64, f64),
    },
    /// One table angle given without the other.
    #[error("field {field}: empty while {other} has a value (give both table angles or neither)")]
    OneTableAngle {
        /// The empty one.
        field: &'static str,
        /// The one given.
        other: &'static str,
    },
    /// A time at or before the row before it.
    #[error("field time_s: {time_s} does not follow {prev_s} (time must increase)")]
    TimeNotIncreasing {
        /// This row's time, s.
        time_s: f64,
        /// The row before's, s.
        prev_s: f64,
    },
}

/// What is wrong with a CSV, and where.
#[derive(Debug, thiserror::Error)]
pub enum CsvError {
    /// Cannot read the file.
    #[error("{path}: {cause}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        #[source]
        cause: std::io::Error,
    },
    /// Not a regular file, or not readable (`config::open_file`).
    #[error(transparent)]
    File(#[from] crate::config::InputError),
    /// A bad header or row.
    #[error("{path}:{line}: {message}")]
    Row {
        /// File.
        path: String,
        /// 1-based line.
        line: u64,
        /// What is wrong.
        message: String,
    },
}

/// The most one line of a CSV may hold, bytes: a row of a lab's file is
/// a few hundred; a longer line is a file of another kind, and reading
/// stops there rather than hold it.
pub const MAX_LINE_BYTES: usize = 1 << 20;

/// A CSV file opened for reading: a regular file (a FIFO or a device is
/// refused by name, never waited on or read), its lines at most
/// [`MAX_LINE_BYTES`] (the file itself may be of any length).
pub fn open_rows(path: &Path) -> Result<crate::config::LinesOfAtMost<std::fs::File>, CsvError> {
    let file = crate::config::open_file(path)?;
    Ok(crate::config::LinesOfAtMost::new(file, MAX_LINE_BYTES))
}

/// The error of a read of `input` that stopped at a line longer than
/// [`MAX_LINE_BYTES`], with its line; `name` labels it.
pub fn overlong<R>(input: &crate::config::LinesOfAtMost<R>, name: &str) -> Option<CsvError> {
    input.overlong().map(|e| CsvError::Row {
        path: name.to_owned(),
        line: e.line,
        message: format!(
            "the line is longer than {} bytes; a CSV row is far shorter: is it the right file?",
            e.max
        ),
    })
}

/// Read and check a whole interchange CSV ([`open_rows`]).
pub fn read(path: &Path) -> Result<Vec<Row>, CsvError> {
    let name = path.display().to_string();
    let mut input = open_rows(path)?;
    parse(&mut input, &name).map_err(|e| overlong(&input, &name).unwrap_or(e))
}

/// Parse interchange CSV from any reader; `name` labels errors.
pub fn parse(input: impl std::io::Read, name: &str) -> Result<Vec<Row>, CsvError> {
    let err = |line: u64, message: String| CsvError::Row {
        path: name.to_owned(),
        line,
        message,
    };
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_reader(input);
    let header = rdr
        .headers()
        .map_err(|e| err(1, format!("unreadable header: {e}")))?
        .clone();
    let got: Vec<&str> = header.iter().collect();
    let has_record = check_header(&got).map_err(|m| err(1, m))?;
    let mut rows: Vec<Row> = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map_or(0, csv::Position::line);
            err(line, format!("unreadable row: {e}"))
        })?;
        let line = rec.position().map_or(0, csv::Position::line);
        let row: Row = rec.deserialize(Some(&header)).map_err(|e| {
            let message = match e.kind() {
                csv::ErrorKind::Deserialize { err: d, .. } => {
                    let field = d
                        .field()
                        .and_then(|i| got.get(i as usize))
                        .map_or(String::new(), |h| format!("field {h}: "));
                    format!("{field}{}", d.kind())
                }
                _ => e.to_string(),
            };
            err(line, message)
        })?;
        let mut row = row;
        if has_record && row.record.is_none() {
            row.record = Some(String::new());
        }
        row.check(rows.last())
            .map_err(|m| err(line, m.to_string()))?;
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(err(2, "no samples after the header".into()));
    }
    Ok(rows)
}

/// Check a header: the ten columns in order, then any of the optional
/// ones (`outer_deg,inner_deg` together, `record`), each once. Whether it
/// has the `record` column.
fn check_header(got: &[&str]) -> Result<bool, String> {
    let wrong = || {
        format!(
            "the header must be `{}`, then optionally `{}` (where the table angles are known) and `{RECORD_COLUMN}` (which rows were recorded); found `{}`",
            HEADER.join(","),
            TABLE_COLUMNS.join(","),
            got.join(",")
        )
    };
    if got.len() < HEADER.len() || got[..HEADER.len()] != HEADER {
        return Err(wrong());
    }
    let rest = &got[HEADER.len()..];
    let known = |c: &&str| TABLE_COLUMNS.contains(c) || *c == RECORD_COLUMN;
    let once = rest
        .iter()
        .all(|c| rest.iter().filter(|d| *d == c).count() == 1);
    let table = rest.iter().filter(|c| TABLE_COLUMNS.contains(c)).count();
    if !rest.iter().all(known) || !once || table == 1 {
        return Err(wrong());
    }
    Ok(rest.contains(&RECORD_COLUMN))
}

/// 1 s means built row by row: rows of one whole second of `time_s` and
/// one step are averaged (rate and temperatures; the time becomes the
/// second's centre; orientation, angles and step are the first row's); a
/// second with a single row keeps it as it is. Nothing but the current
/// second is held, so a file of 100 Hz samples is reduced as it is read.
#[derive(Debug, Default)]
pub struct OneHz {
    out: Vec<Row>,
    acc: Option<(Row, usize)>,
}

impl OneHz {
    /// Take the next row (in time order).
    pub fn push(&mut self, r: Row) {
        if let Some((a, n)) = &mut self.acc {
            if r.time_s.floor() == a.time_s.floor() && r.step == a.step && r.record == a.record {
                a.rate_dph += r.rate_dph;
                a.t1_c += r.t1_c;
                a.t2_c += r.t2_c;
                a.tcase_c += r.tcase_c;
                a.chamber_c += r.chamber_c;
                *n += 1;
                return;
            }
            self.flush();
        }
        self.acc = Some((r, 1));
    }

    fn flush(&mut self) {
        if let Some((mut a, n)) = self.acc.take() {
            if n > 1 {
                let k = n as f64;
                a.time_s = a.time_s.floor() + 0.5;
                a.rate_dph /= k;
                a.t1_c /= k;
                a.t2_c /= k;
                a.tcase_c /= k;
                a.chamber_c /= k;
            }
            self.out.push(a);
        }
    }

    /// The 1 s rows.
    pub fn finish(mut self) -> Vec<Row> {
        self.flush();
        self.out
    }
}

/// The longest stretch of evenly spaced samples (no gap over 1.5 sample
/// times), as (first index, length, sample time s).
pub fn longest_even_run(rows: &[Row]) -> (usize, usize, f64) {
    if rows.len() < 2 {
        return (0, rows.len(), 1.0);
    }
    let mut dts: Vec<f64> = rows.windows(2).map(|w| w[1].time_s - w[0].time_s).collect();
    dts.sort_by(f64::total_cmp);
    let dt = dts[dts.len() / 2];
    let (mut best, mut start) = ((0, 1), 0);
    for i in 1..rows.len() {
        if rows[i].time_s - rows[i - 1].time_s > 1.5 * dt {
            start = i;
        }
        if i + 1 - start > best.1 {
            best = (start, i + 1 - start);
        }
    }
    (best.0, best.1, dt)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str =
        "time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n";

    proptest::proptest! {
        /// Arbitrary bytes, and arbitrary text after a good header: an
        /// error or rows, never a panic.
        #[test]
        fn arbitrary_input_never_panics(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..2000)) {
            let _ = parse(bytes.as_slice(), "fuzz.csv");
            let mut text = HEAD.as_bytes().to_vec();
            text.extend_from_slice(&bytes);
            let _ = parse(text.as_slice(), "fuzz.csv");
        }

        /// Well-formed rows always parse back to the same numbers.
        #[test]
        fn written_rows_parse_back(
            rows in proptest::collection::vec((-1e6f64..1e6, -40.0f64..60.0, -90.0f64..90.0, "[a-z_0-9]{1,12}"), 1..50)
        ) {
            let mut text = HEAD.to_owned();
            for (i, (rate, t, el, step)) in rows.iter().enumerate() {
                text.push_str(&format!("{},{rate},{t},{t},{t},{t},0,{el},0,{step}\n", i as f64 + 0.5));
            }
            let got = parse(text.as_bytes(), "p.csv").expect("well-formed rows parse");
            proptest::prop_assert_eq!(got.len(), rows.len());
            for (g, (rate, t, el, step)) in got.iter().zip(&rows) {
                proptest::prop_assert_eq!(g.rate_dph, *rate);
                proptest::prop_assert_eq!(g.tcase_c, *t);
                proptest::prop_assert_eq!(g.elevation_deg, *el);
                proptest::prop_assert_eq!(&g.step, step);
            }
        }
    }

    #[test]
    fn good_rows_parse_and_the_longest_even_stretch_is_found() {
        let text = format!(
            "{HEAD}0.5,12.1,20,20,20,20,0,90,0,a\n1.5,12.2,20,20,20,20,0,90,0,a\n2.5,12.0,20,20,20,20,0,90,0,a\n10.5,1,20,20,20,20,90,0,0,b\n"
        );
        let rows = parse(text.as_bytes(), "t.csv").expect("parses");
        assert_eq!(rows.len(), 4);
        assert_eq!(rows[3].step, "b");
        assert_eq!(longest_even_run(&rows), (0, 3, 1.0));
    }

    #[test]
    fn bad_rows_are_refused_with_their_line_and_field() {
        for (body, want) in [
            ("0.5,abc,20,20,20,20,0,90,0,a\n", "t.csv:2: field rate_dph"),
            (
                "0.5,1,20,20,20,20,0,90,0,a\n0.5,1,20,20,20,20,0,90,0,a\n",
                "t.csv:3: field time_s",
            ),
            (
                "0.5,1,20,20,20,20,0,91,0,a\n",
                "t.csv:2: field elevation_deg",
            ),
            ("0.5,1,20,20,20,20,0,90\n", "t.csv:2:"),
            ("0.5,NaN,20,20,20,20,0,90,0,a\n", "t.csv:2: field rate_dph"),
            (
                "0.5,1e308,20,20,20,20,0,90,0,a\n",
                "t.csv:2: field rate_dph",
            ),
            ("-3,1,20,20,20,20,0,90,0,a\n", "t.csv:2: field time_s"),
            ("0.5,1,20,20,20,900,0,90,0,a\n", "t.csv:2: field chamber_c"),
            ("", "t.csv:2: no samples"),
        ] {
            let e = parse(format!("{HEAD}{body}").as_bytes(), "t.csv")
                .expect_err(body)
                .to_string();
            assert!(e.starts_with(want), "{body}: {e}");
        }
        let e = parse("time,rate\n1,2\n".as_bytes(), "t.csv")
            .expect_err("header")
            .to_string();
        assert!(e.starts_with("t.csv:1: the header must be"), "{e}");
    }
}
