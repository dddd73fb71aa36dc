//! Loading TOML files in two stages, with errors that point into the file.
//!
//! Stage one deserializes raw structs that mirror the file one-to-one
//! (`deny_unknown_fields`); stage two validates values and builds typed,
//! checked configuration. Both stages report `file:line:column` and the key.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use gyrobench_analysis::compensation::Model4;
use serde::de::DeserializeOwned;
use toml::de::{DeTable, DeValue};

mod input;
pub use input::{InputError, LineTooLong, LinesOfAtMost, open_file, read_at_most};

/// What went wrong reading a configuration file, and where.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read at all.
    #[error("cannot read {path}: {cause}; check the path")]
    Read {
        path: PathBuf,
        #[source]
        cause: std::io::Error,
    },
    /// The path names a FIFO, a device, a directory or a socket.
    #[error(
        "{path} is {kind}, not a regular file; a configuration file is read from a file only: \
         give the path of one"
    )]
    NotAFile {
        path: PathBuf,
        /// What it is ("a FIFO (named pipe)", "a character device", ...).
        kind: &'static str,
    },
    /// The text is not valid TOML, or does not match the expected structure
    /// (unknown key, wrong type, missing field).
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        column: usize,
        message: String,
    },
    /// A value has the right type but is not acceptable.
    #[error("{path}:{line}:{column}: `{key}` {message}")]
    Invalid {
        path: PathBuf,
        line: usize,
        column: usize,
        key: String,
        message: String,
    },
}

impl ConfigError {
    /// The 1-based line the error points at.
    pub fn line(&self) -> Option<usize> {
        match self {
            Self::Read { .. } | Self::NotAFile { .. } => None,
            Self::Parse { line, .. } | Self::Invalid { line, .. } => Some(*line),
        }
    }
}

/// A TOML document kept beside its path, so that validation can point back
/// into the text.
#[derive(Debug, Clone)]
pub struct Source {
    /// Where the text came from (shown in errors).
    pub path: PathBuf,
    /// The whole text.
    pub text: String,
    /// Where every dotted key sits, built once on the first lookup (so
    /// validating N steps costs one parse, not N).
    index: OnceLock<KeyIndex>,
}

/// Byte offsets of every dotted key of a document, and of its line starts.
#[derive(Debug, Clone, Default)]
struct KeyIndex {
    keys: HashMap<String, usize>,
    line_starts: Vec<usize>,
}

impl KeyIndex {
    fn build(text: &str) -> Self {
        let mut keys = HashMap::new();
        if let Ok(doc) = DeTable::parse(text) {
            walk_table(doc.get_ref(), "", &mut keys);
        }
        let line_starts = std::iter::once(0)
            .chain(text.match_indices('\n').map(|(i, _)| i + 1))
            .collect();
        Self { keys, line_starts }
    }

    /// 1-based line and column of a byte offset, by binary search.
    fn line_col(&self, text: &str, offset: usize) -> (usize, usize) {
        let offset = offset.min(text.len());
        let line = self.line_starts.partition_point(|&s| s <= offset).max(1);
        let start = self.line_starts[line - 1];
        let column = text.get(start..offset).map_or(1, |t| t.chars().count() + 1);
        (line, column)
    }
}

fn is_container(v: &DeValue<'_>) -> bool {
    matches!(v, DeValue::Table(_) | DeValue::Array(_))
}

fn join(prefix: &str, part: &str) -> String {
    if prefix.is_empty() {
        part.to_owned()
    } else {
        format!("{prefix}.{part}")
    }
}

/// A table's keys: at the key for a table or array (an error about it
/// points at its header), at the value for anything else.
fn walk_table(t: &DeTable<'_>, prefix: &str, keys: &mut HashMap<String, usize>) {
    for (k, v) in t {
        let path = join(prefix, k.get_ref());
        let at = if is_container(v.get_ref()) {
            k.span().start
        } else {
            v.span().start
        };
        keys.insert(path.clone(), at);
        walk_value(v.get_ref(), &path, keys);
    }
}

fn walk_value(v: &DeValue<'_>, path: &str, keys: &mut HashMap<String, usize>) {
    match v {
        DeValue::Table(t) => walk_table(t, path, keys),
        DeValue::Array(a) => {
            for (i, e) in a.iter().enumerate() {
                let p = join(path, &i.to_string());
                keys.insert(p.clone(), e.span().start);
                walk_value(e.get_ref(), &p, keys);
            }
        }
        _ => {}
    }
}

/// The largest configuration file read (procedure, bench, twin, site,
/// coefficient set), bytes: the shipped ones are a few kilobytes; a larger
/// file is a mistake or an attack (a procedure of 51 MB once took 3.1 GB
/// of memory to check).
pub const MAX_FILE_BYTES: u64 = 1 << 20;

impl Source {
    /// Read a file from disk: a regular file only (a FIFO, a device, a
    /// directory are refused by name, without waiting on them), at most
    /// [`MAX_FILE_BYTES`] of it (the read stops one byte past, whatever
    /// the file's size says).
    pub fn read(path: &Path) -> Result<Self, ConfigError> {
        let parse = |message: String| ConfigError::Parse {
            path: path.to_owned(),
            line: 1,
            column: 1,
            message,
        };
        let bytes = read_at_most(path, MAX_FILE_BYTES).map_err(|e| match e {
            InputError::Io { path, cause } => ConfigError::Read { path, cause },
            InputError::NotAFile { path, kind } => ConfigError::NotAFile { path, kind },
            InputError::TooLarge { .. } => parse(format!(
                "the file {}; a configuration file is at most {MAX_FILE_BYTES} bytes (1 MiB)",
                std::fs::metadata(path)
                    .ok()
                    .filter(|m| m.len() > MAX_FILE_BYTES)
                    .map_or_else(
                        || format!("holds more than {MAX_FILE_BYTES} bytes"),
                        |m| format!("is {} bytes", m.len())
                    )
            )),
        })?;
        let text = String::from_utf8(bytes)
            .map_err(|_| parse("the file is not UTF-8 text; expected a TOML file".into()))?;
        Ok(Self {
            path: path.to_owned(),
            text,
            index: OnceLock::new(),
        })
    }

    /// Wrap text that did not come from disk (embedded defaults, tests).
    pub fn from_text(name: &str, text: &str) -> Self {
        Self {
            path: PathBuf::from(name),
            text: text.to_owned(),
            index: OnceLock::new(),
        }
    }

    /// Stage one: deserialize the raw structure.
    pub fn parse<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        toml::from_str(&self.text).map_err(|e| {
            let message = e.message().trim();
            let (at, key) = e.span().map_or((0, None), |s| self.refine(s, message));
            let (line, column) = line_col(&self.text, at);
            ConfigError::Parse {
                path: self.path.clone(),
                line,
                column,
                message: match key {
                    Some(k) if !message.contains(&format!("`{k}`")) => format!("`{k}`: {message}"),
                    _ => message.to_owned(),
                },
            }
        })
    }

    /// Where in `span` an error really is, and the key it is about: serde
    /// reports an unknown key, or a value of the wrong type, of an
    /// internally tagged table (a procedure step) at the whole table; the
    /// key's own line inside it is more use to the reader.
    fn refine(&self, span: std::ops::Range<usize>, message: &str) -> (usize, Option<String>) {
        // The span may cover only the table's header: search on from it.
        let Some(region) = self.text.get(span.start..) else {
            return (span.start, None);
        };
        let unknown = message
            .strip_prefix("unknown field `")
            .and_then(|m| m.split('`').next());
        let wrong = wrong_type_literals(message);
        let mut offset = span.start;
        for line in region.split_inclusive('\n') {
            let t = line.trim_start();
            if let Some((k, v)) = t.split_once('=') {
                let (k, v) = (k.trim(), strip_comment(v).trim());
                let hit = match unknown {
                    Some(key) => k == key,
                    None => !wrong.is_empty() && wrong.iter().any(|w| w == v),
                };
                if hit {
                    return (offset + (line.len() - t.len()), Some(k.to_owned()));
                }
            }
            offset += line.len();
        }
        (span.start, None)
    }

    /// An error about the value at dotted `key` (e.g. `thermal.tau_case_s`,
    /// `table.geometry.outer_axis_ned`), located in the text when present,
    /// else at its nearest enclosing table.
    pub fn invalid(&self, key: &str, message: impl Into<String>) -> ConfigError {
        let (line, column) = self.locate(key).unwrap_or((1, 1));
        ConfigError::Invalid {
            path: self.path.clone(),
            line,
            column,
            key: key.to_owned(),
            message: message.into(),
        }
    }

    /// Line and column (1-based) of the value at a dotted key path; numeric
    /// parts index arrays (`main.3.set_c` = key `set_c` of the fourth
    /// `[[main]]` table). Falls back to the deepest part found.
    pub fn locate(&self, key: &str) -> Option<(usize, usize)> {
        let index = self.index.get_or_init(|| KeyIndex::build(&self.text));
        let mut k = key;
        loop {
            if let Some(&at) = index.keys.get(k) {
                return Some(index.line_col(&self.text, at));
            }
            k = &k[..k.rfind('.')?];
        }
    }
}

/// The ways a value that serde calls the wrong type can be written in
/// TOML (`invalid type: string "30", expected f64` -> `"30"`, `'30'`);
/// none for other messages or values not written as a scalar.
fn wrong_type_literals(message: &str) -> Vec<String> {
    let Some(rest) = message.strip_prefix("invalid type: ") else {
        return Vec::new();
    };
    let rest = rest.split(", expected").next().unwrap_or(rest);
    if let Some(q) = rest.strip_prefix("string ") {
        let inner = q.trim().trim_matches('"');
        return vec![format!("\"{inner}\""), format!("'{inner}'")];
    }
    for kind in ["integer ", "floating point ", "boolean "] {
        if let Some(v) = rest.strip_prefix(kind) {
            return vec![v.trim().trim_matches('`').to_owned()];
        }
    }
    Vec::new()
}

/// A TOML value without a comment after it (a `#` outside quotes).
fn strip_comment(v: &str) -> &str {
    let mut quote: Option<char> = None;
    for (i, c) in v.char_indices() {
        match (quote, c) {
            (None, '"' | '\'') => quote = Some(c),
            (Some(q), c) if c == q => quote = None,
            (None, '#') => return &v[..i],
            _ => {}
        }
    }
    v
}

/// 1-based line and column of a byte offset.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text.as_bytes()[..offset];
    let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
    let line_start = before
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |p| p + 1);
    let column = text[line_start..offset].chars().count() + 1;
    (line, column)
}

/// A number as an error message shows it: plain when it reads well,
/// in exponent form when it is huge or tiny (`1e300`, not 301 digits).
pub fn num(v: f64) -> String {
    let a = v.abs();
    if v.is_finite() && a != 0.0 && !(1e-4..1e9).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// Collects validation checks; the first failure wins.
#[derive(Debug)]
pub struct Checker<'a> {
    source: &'a Source,
}

impl<'a> Checker<'a> {
    /// Checks against one source file.
    pub fn new(source: &'a Source) -> Self {
        Self { source }
    }

    /// Fail with `message` at `key` unless `ok`.
    pub fn ensure(&self, ok: bool, key: &str, message: &str) -> Result<(), ConfigError> {
        if ok {
            Ok(())
        } else {
            Err(self.source.invalid(key, message))
        }
    }

    /// A finite value strictly above zero.
    pub fn positive(&self, value: f64, key: &str) -> Result<f64, ConfigError> {
        self.ensure(
            value.is_finite() && value > 0.0,
            key,
            &format!("must be a finite number above zero, got {}", num(value)),
        )?;
        Ok(value)
    }

    /// A finite value at or above zero.
    pub fn non_negative(&self, value: f64, key: &str) -> Result<f64, ConfigError> {
        self.ensure(
            value.is_finite() && value >= 0.0,
            key,
            &format!(
                "must be a finite number at or above zero, got {}",
                num(value)
            ),
        )?;
        Ok(value)
    }

    /// A finite value within `[lo, hi]`.
    pub fn within(&self, value: f64, lo: f64, hi: f64, key: &str) -> Result<f64, ConfigError> {
        self.ensure(
            value.is_finite() && (lo..=hi).contains(&value),
            key,
            &format!(
                "must be between {} and {}, got {}",
                num(lo),
                num(hi),
                num(value)
            ),
        )?;
        Ok(value)
    }

    /// Any finite value.
    pub fn finite(&self, value: f64, key: &str) -> Result<f64, ConfigError> {
        self.ensure(
            value.is_finite(),
            key,
            &format!("must be a finite number, got {}", num(value)),
        )?;
        Ok(value)
    }

    /// A direction: three finite components, not all (nearly) zero.
    pub fn direction(&self, v: &[f64; 3], key: &str) -> Result<(), ConfigError> {
        let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        self.ensure(
            n.is_finite() && n > 1e-6,
            key,
            "must be a non-zero direction",
        )
    }

    /// The values of a model 4 read from a file (a coefficient set's
    /// `[model4]`, the twin's `[bias]`): finite, tau_w > 0; errors name
    /// `section.key` and its line.
    pub fn model4(&self, m: &Model4, section: &str) -> Result<(), ConfigError> {
        for (v, k) in [
            (m.k1_dph_per_c, "k1_dph_per_c"),
            (m.k2_dph_per_c2, "k2_dph_per_c2"),
            (m.k3_dph_per_c_per_s, "k3_dph_per_c_per_s"),
            (m.k4_dph_per_c, "k4_dph_per_c"),
            (m.k5_dph, "k5_dph"),
            (m.offset_dph, "offset_dph"),
        ] {
            self.finite(v, &format!("{section}.{k}"))?;
        }
        self.positive(m.warmup_tau_s, &format!("{section}.warmup_tau_s"))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[expect(dead_code, reason = "fields exist to be deserialized")]
    struct Raw {
        a: Inner,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[expect(dead_code, reason = "fields exist to be deserialized")]
    struct Inner {
        x: f64,
    }

    #[test]
    fn unknown_key_points_at_its_line() {
        let src = Source::from_text("t.toml", "[a]\nx = 1.0\ny = 2.0\n");
        let err = src.parse::<Raw>().expect_err("unknown key must be refused");
        assert_eq!(err.line(), Some(3));
        assert!(err.to_string().contains("unknown field `y`"), "{err}");
        assert!(err.to_string().starts_with("t.toml:3:"), "{err}");
    }

    #[test]
    fn missing_field_is_named() {
        let src = Source::from_text("t.toml", "[a]\n");
        let err = src
            .parse::<Raw>()
            .expect_err("missing field must be refused");
        assert!(err.to_string().contains("missing field `x`"), "{err}");
    }

    #[test]
    fn invalid_value_is_located_by_dotted_key() {
        let src = Source::from_text("t.toml", "# c\n[a]\n\nx = -1.0\n");
        let err = Checker::new(&src)
            .positive(-1.0, "a.x")
            .expect_err("negative must be refused");
        assert_eq!(err.line(), Some(4));
        assert!(err.to_string().contains("`a.x` must be"), "{err}");
        assert!(err.to_string().contains("t.toml:4:5"), "{err}");
    }

    #[test]
    fn locate_walks_arrays_of_tables() {
        let src = Source::from_text("p.toml", "[[main]]\na = 1\n\n[[main]]\na = 2\nb = 3\n");
        assert_eq!(src.locate("main.1.b"), Some((6, 5)));
        assert_eq!(src.locate("main.1"), Some((4, 1)));
        assert_eq!(
            src.locate("main.7.b"),
            Some((1, 3)),
            "falls back to the deepest part found"
        );
    }

    #[test]
    fn line_col_counts_from_one() {
        assert_eq!(line_col("ab\ncd", 0), (1, 1));
        assert_eq!(line_col("ab\ncd", 4), (2, 2));
    }

    #[test]
    fn a_file_larger_than_a_configuration_is_refused_unread() {
        let dir = tempfile::tempdir().expect("temp dir");
        let big = dir.path().join("big.toml");
        let line = "# padding padding padding padding padding padding padding\n";
        let text = line.repeat((MAX_FILE_BYTES as usize) / line.len() + 1);
        std::fs::write(&big, text).expect("write");
        let err = Source::read(&big).expect_err("too large");
        assert!(err.to_string().contains("at most 1048576 bytes"), "{err}");
        let small = dir.path().join("small.toml");
        std::fs::write(&small, "a = 1\n").expect("write");
        assert!(Source::read(&small).is_ok());
    }
}
