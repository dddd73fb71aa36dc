//! The unit under test as the record names it: its serial number (one rule
//! for every entry point: `run --dut`, `import --dut`, the station) and the
//! serial a simulated run is recorded under when none is given.

/// Longest serial number accepted, characters (a barcode on a housing is
/// far shorter; a longer one is a mis-scan or a paste).
pub const SERIAL_MAX_CHARS: usize = 64;

/// The serial a run on the embedded simulated bench is recorded under when
/// no `--dut` is given. It names no unit: a real bench refuses it, so no
/// hardware run can be filed under it by mistake.
pub const SIMULATED_SERIAL: &str = "SIMULATED";

/// The serial an imported run is recorded under when neither `--dut` nor
/// the export's sidecar names its unit. It names no unit, as
/// [`SIMULATED_SERIAL`] does: the file's name is not a serial.
pub const UNNAMED_SERIAL: &str = "UNNAMED";

/// Why a serial number is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SerialError {
    /// Nothing (or only blanks) was given.
    #[error("the serial number is empty; scan or type the unit's serial")]
    Empty,
    /// Longer than [`SERIAL_MAX_CHARS`].
    #[error("the serial number has {chars} characters; at most {SERIAL_MAX_CHARS} are accepted")]
    TooLong {
        /// Its length, characters.
        chars: usize,
    },
    /// A character a terminal, a report or an XML file cannot show as it is.
    #[error(
        "the serial number holds {what} (U+{code:04X}) at character {at}; a serial is printable text"
    )]
    Unprintable {
        /// Control or format character.
        what: &'static str,
        /// Its code point.
        code: u32,
        /// Where, counted from 1.
        at: usize,
    },
    /// Blanks around it (a scanner's trailing space files a second unit).
    #[error("the serial number {0:?} starts or ends with a blank; give it without")]
    Padded(String),
}

/// Unicode format characters (category Cf) that can disguise a serial:
/// bidirectional overrides and isolates, zero-width characters, the byte
/// order mark, the soft hyphen, invisible operators.
fn is_format(c: char) -> bool {
    matches!(
        c,
        '\u{00AD}'
            | '\u{0600}'..='\u{0605}'
            | '\u{061C}'
            | '\u{06DD}'
            | '\u{070F}'
            | '\u{180E}'
            | '\u{200B}'..='\u{200F}'
            | '\u{202A}'..='\u{202E}'
            | '\u{2060}'..='\u{2064}'
            | '\u{2066}'..='\u{206F}'
            | '\u{FEFF}'
            | '\u{FFF9}'..='\u{FFFB}'
            | '\u{E0001}'
            | '\u{E0020}'..='\u{E007F}'
    )
}

/// Check a serial number: 1 to [`SERIAL_MAX_CHARS`] characters, no
/// control or Unicode format characters, no blanks around it.
pub fn check_serial(s: &str) -> Result<&str, SerialError> {
    if s.trim().is_empty() {
        return Err(SerialError::Empty);
    }
    let chars = s.chars().count();
    if chars > SERIAL_MAX_CHARS {
        return Err(SerialError::TooLong { chars });
    }
    for (i, c) in s.chars().enumerate() {
        let what = if c.is_control() {
            "a control character"
        } else if is_format(c) {
            "an invisible formatting character"
        } else {
            continue;
        };
        return Err(SerialError::Unprintable {
            what,
            code: u32::from(c),
            at: i + 1,
        });
    }
    if s.trim() != s {
        return Err(SerialError::Padded(s.to_owned()));
    }
    Ok(s)
}

/// Why a unit type is refused: the serial's rule, said of a type.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{}", type_words(.0))]
pub struct TypeError(pub SerialError);

fn type_words(e: &SerialError) -> String {
    match e {
        SerialError::Empty => {
            "the unit type is empty; give it as the unit's own runs record it (RL-16)".into()
        }
        e => e
            .to_string()
            .replace("the serial number", "the unit type")
            .replace("a serial is", "a unit type is"),
    }
}

/// Check a unit type given on the command line: 1 to
/// [`SERIAL_MAX_CHARS`] printable characters, no blanks around it (the
/// serial's rule).
pub fn check_type(t: &str) -> Result<&str, TypeError> {
    check_serial(t).map_err(TypeError)
}

/// Longest operator name accepted, characters.
pub const OPERATOR_MAX_CHARS: usize = 64;

/// Check an operator's name: empty is allowed (not given); otherwise the
/// serial's rule, at most [`OPERATOR_MAX_CHARS`].
pub fn check_operator(s: &str) -> Result<&str, SerialError> {
    if s.is_empty() {
        return Ok(s);
    }
    check_serial(s)
}

/// A serial as a file name's part: characters a file system or a shell
/// would take amiss become `_`.
pub fn file_safe(serial: &str) -> String {
    serial
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// A batch's unit's report files' name without the extension:
/// `report-SERIAL` (the serial [`file_safe`]).
pub fn report_name(serial: &str) -> String {
    format!("report-{}", file_safe(serial))
}

/// Whether two serials' report files would be one file: their
/// [`report_name`]s are equal, or differ only in letter case (one file on
/// a case-insensitive file system, a Windows or macOS share).
pub fn same_report_file(a: &str, b: &str) -> bool {
    report_name(a).eq_ignore_ascii_case(&report_name(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serials_that_a_report_or_a_terminal_cannot_show_are_refused() {
        assert_eq!(check_serial("RL16-0042"), Ok("RL16-0042"));
        assert_eq!(check_serial("Серія 7"), Ok("Серія 7"));
        assert_eq!(check_serial(""), Err(SerialError::Empty));
        assert_eq!(check_serial("  "), Err(SerialError::Empty));
        assert!(matches!(
            check_serial(&"X".repeat(65)),
            Err(SerialError::TooLong { chars: 65 })
        ));
        assert!(check_serial(&"X".repeat(64)).is_ok());
        for (bad, code) in [
            ("RL16\n0042", 0x0a),
            ("RL16\u{1b}[31m", 0x1b),
            ("RL16\u{202E}2400", 0x202e),
            ("RL16\u{200B}0042", 0x200b),
            ("\u{FEFF}RL16", 0xfeff),
        ] {
            match check_serial(bad) {
                Err(SerialError::Unprintable { code: c, .. }) => assert_eq!(c, code, "{bad:?}"),
                other => panic!("{bad:?}: {other:?}"),
            }
        }
        assert!(matches!(
            check_serial("RL16-0042 "),
            Err(SerialError::Padded(_))
        ));
        let msg = check_serial("A\u{202E}B").unwrap_err().to_string();
        assert!(
            msg.contains("U+202E") && msg.contains("character 2"),
            "{msg}"
        );
    }

    #[test]
    fn serials_that_differ_only_in_case_or_unsafe_characters_share_a_report_file() {
        assert!(same_report_file("s1", "S1"));
        assert!(same_report_file("RL16-0042a", "rl16-0042A"));
        assert!(same_report_file("A/1", "a:1"), "both report-a_1");
        assert!(!same_report_file("S1", "S2"));
        assert!(!same_report_file("S-1", "S_1"));
    }

    #[test]
    fn an_operator_may_be_left_out_but_not_be_anything() {
        assert_eq!(check_operator(""), Ok(""));
        assert_eq!(check_operator("J. Doe"), Ok("J. Doe"));
        assert!(check_operator(&"x".repeat(1_000_000)).is_err());
        assert!(check_operator("a\u{7}b").is_err());
    }
}
