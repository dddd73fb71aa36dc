//! What a person looks at: the page skeleton every HTML output shares
//! (report, diagnosis, calibration, self-check, trend), the one chart
//! helper they draw with, and the small formatting rules they agree on.
//!
//! Pages are self-contained (inline SVG and CSS, no scripts, nothing
//! fetched), readable on a laptop and printable on A4.

pub mod chart;
pub mod live;
mod page;

pub use chart::{Chart, Marker, Series, Stroke};
pub use page::page;

/// Escape text for HTML element content and attribute values.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&#39;")
}

/// Text as a terminal or an XML file can hold it: control characters and
/// invisible formatting characters (bidirectional overrides, zero-width
/// marks) written as `\u{1b}`, so a stored value can neither move the
/// cursor nor disguise itself.
pub fn printable(s: &str) -> std::borrow::Cow<'_, str> {
    let bad = |c: char| {
        c.is_control()
            || matches!(c, '\u{00AD}' | '\u{200B}'..='\u{200F}' | '\u{202A}'..='\u{202E}'
                | '\u{2060}'..='\u{206F}' | '\u{FEFF}' | '\u{FFFE}' | '\u{FFFF}')
    };
    if !s.chars().any(bad) {
        return std::borrow::Cow::Borrowed(s);
    }
    std::borrow::Cow::Owned(
        s.chars()
            .map(|c| {
                if bad(c) {
                    format!("\\u{{{:x}}}", u32::from(c))
                } else {
                    c.to_string()
                }
            })
            .collect(),
    )
}

/// A p-value as a reader takes it: three decimals, `< 0.001` below that
/// (never `0.0e0`), `n/a` when it could not be computed.
pub fn p_value(p: f64) -> String {
    if !p.is_finite() {
        "n/a".into()
    } else if p < 0.001 {
        "< 0.001".into()
    } else {
        format!("{p:.3}")
    }
}

/// `= 0.012` or `< 0.001`: a p-value after the letter p.
pub fn p_phrase(p: f64) -> String {
    let v = p_value(p);
    if v.starts_with('<') {
        v
    } else {
        format!("= {v}")
    }
}

/// An RFC 3339 time to the second, in UTC (`2026-11-30 08:47:03 UTC`);
/// text that is not one is returned as it is.
pub fn utc_seconds(rfc3339: &str) -> String {
    chrono::DateTime::parse_from_rfc3339(rfc3339).map_or_else(
        |_| rfc3339.to_owned(),
        |t| {
            t.with_timezone(&chrono::Utc)
                .format("%Y-%m-%d %H:%M:%S UTC")
                .to_string()
        },
    )
}

/// A value with `digits` decimals, `n/a` when missing or not finite.
pub fn num(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.digits$}"),
        _ => "n/a".into(),
    }
}

/// A limit as the procedure wrote it (`0.05`, not `0.050000`), empty when
/// there is none.
pub fn limit(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| v.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn p_values_never_read_as_zero() {
        assert_eq!(p_value(0.0), "< 0.001");
        assert_eq!(p_value(2e-9), "< 0.001");
        assert_eq!(p_value(0.0123), "0.012");
        assert_eq!(p_value(f64::NAN), "n/a");
        assert_eq!(p_phrase(0.0), "< 0.001");
        assert_eq!(p_phrase(0.02), "= 0.020");
    }

    #[test]
    fn start_times_drop_the_nanoseconds() {
        assert_eq!(
            utc_seconds("2026-11-30T08:47:03.866528760+00:00"),
            "2026-11-30 08:47:03 UTC"
        );
        assert_eq!(
            utc_seconds("2026-11-30T09:47:03+01:00"),
            "2026-11-30 08:47:03 UTC"
        );
        assert_eq!(utc_seconds("yesterday"), "yesterday");
    }

    #[test]
    fn text_is_escaped_for_elements_and_attributes() {
        assert_eq!(
            esc("<b a=\"x\" b='y'>&"),
            "&lt;b a=&quot;x&quot; b=&#39;y&#39;&gt;&amp;"
        );
    }
}
