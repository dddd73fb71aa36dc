//! What SCPI instruments share (IEEE 488.2 and SCPI-1999): the error
//! queue's numbers and texts, headers in short or long form, and the
//! common forms of numeric and boolean arguments and replies.

/// SCPI-style error, as queued by the instrument.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScpiError {
    /// Negative SCPI error number.
    pub code: i16,
    /// Standard text.
    pub text: &'static str,
}

impl ScpiError {
    /// -102: the message does not follow the syntax (a stray character).
    pub const SYNTAX: Self = Self {
        code: -102,
        text: "Syntax error",
    };
    /// -104: an argument is not of the type the command takes.
    pub const DATA_TYPE: Self = Self {
        code: -104,
        text: "Data type error",
    };
    /// -108: more arguments than the command takes.
    pub const PARAMETER_NOT_ALLOWED: Self = Self {
        code: -108,
        text: "Parameter not allowed",
    };
    /// -109: a required argument is missing.
    pub const MISSING_PARAMETER: Self = Self {
        code: -109,
        text: "Missing parameter",
    };
    /// -113: the header is not a command of this instrument.
    pub const UNDEFINED_HEADER: Self = Self {
        code: -113,
        text: "Undefined header",
    };
    /// -131: a unit suffix the command does not take.
    pub const INVALID_SUFFIX: Self = Self {
        code: -131,
        text: "Invalid suffix",
    };
    /// -221: the command conflicts with the state (interlock open, wrong mode).
    pub const SETTINGS_CONFLICT: Self = Self {
        code: -221,
        text: "Settings conflict",
    };
    /// -222: an argument is outside its range (bad axis, beyond a limit).
    pub const OUT_OF_RANGE: Self = Self {
        code: -222,
        text: "Data out of range",
    };
    /// -224: a word argument the command does not know.
    pub const ILLEGAL_PARAMETER: Self = Self {
        code: -224,
        text: "Illegal parameter value",
    };
    /// -350: errors were lost because the queue was full.
    pub const QUEUE_OVERFLOW: Self = Self {
        code: -350,
        text: "Queue overflow",
    };

    /// The `:SYST:ERR?` answer for this error.
    pub fn reply(&self) -> String {
        format!("{},\"{}\"", self.code, self.text)
    }
}

/// `:SYST:ERR?` answer when the queue is empty.
pub const NO_ERROR: &str = "0,\"No error\"";

/// An instrument's error queue: the oldest error is read first; when it is
/// full the newest entry becomes -350 and later errors are lost (SCPI-1999
/// 21.8.2).
#[derive(Debug, Clone, Default)]
pub struct ErrorQueue {
    queue: std::collections::VecDeque<ScpiError>,
}

impl ErrorQueue {
    /// Entries kept (the E36300's 20), the last of them -350 once an
    /// error found the queue full.
    pub const DEPTH: usize = 20;

    /// Queue an error; when the queue is full its newest entry becomes
    /// -350 instead.
    pub fn push(&mut self, e: ScpiError) {
        if self.queue.len() < Self::DEPTH {
            self.queue.push_back(e);
        } else if let Some(last) = self.queue.back_mut() {
            *last = ScpiError::QUEUE_OVERFLOW;
        }
    }

    /// The oldest error, removed; none when empty.
    pub fn pop(&mut self) -> Option<ScpiError> {
        self.queue.pop_front()
    }

    /// True when no error waits.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// Empty the queue (`*CLS`).
    pub fn clear(&mut self) {
        self.queue.clear();
    }
}

/// One node of a header: its long form with the short form in capitals
/// (`VOLTage`), and whether it may be left out (`[:LEVel]`).
#[derive(Debug, Clone, Copy)]
pub struct Node {
    /// Long form; its capital letters are the short form.
    pub name: &'static str,
    /// `[...]` in the manual: may be left out.
    pub optional: bool,
}

/// A node that must be given.
pub const fn node(name: &'static str) -> Node {
    Node {
        name,
        optional: false,
    }
}

/// A node that may be left out.
pub const fn opt(name: &'static str) -> Node {
    Node {
        name,
        optional: true,
    }
}

impl Node {
    /// True if `token` (already upper case) is this node's short or long
    /// form: SCPI accepts exactly these two, not other abbreviations.
    fn matches(&self, token: &str) -> bool {
        let long = self.name.to_ascii_uppercase();
        let short: String = self
            .name
            .chars()
            .filter(|c| c.is_ascii_uppercase())
            .collect();
        !token.is_empty() && (token == long || token == short)
    }
}

/// True if the header's parts (upper case, without `?` and leading `:`)
/// spell `pattern`, optional nodes left out or given.
pub fn header_matches(parts: &[&str], pattern: &[Node]) -> bool {
    match (parts.split_first(), pattern.split_first()) {
        (None, None) => true,
        (None, Some(_)) => pattern.iter().all(|n| n.optional),
        (Some(_), None) => false,
        (Some((t, rest)), Some((n, pat_rest))) => {
            (n.matches(t) && header_matches(rest, pat_rest))
                || (n.optional && header_matches(parts, pat_rest))
        }
    }
}

/// A command split into its header and arguments: `VOLT 5.0, (@1)` gives
/// the parts `["VOLT"]`, no query, and the arguments `["5.0", "(@1)"]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Split<'a> {
    /// Header nodes, upper case, without the leading `:` and the `?`.
    pub parts: Vec<String>,
    /// Ends in `?`.
    pub query: bool,
    /// Common command (`*IDN?`): the header starts with `*`.
    pub common: bool,
    /// The header starts with `:`: from the root, whatever came before.
    pub absolute: bool,
    /// Arguments, trimmed, split at commas outside parentheses.
    pub args: Vec<&'a str>,
}

/// Split one command of a message (the text between `;`).
pub fn split_command(cmd: &str) -> Result<Split<'_>, ScpiError> {
    let cmd = cmd.trim();
    let (header, args) = match cmd.split_once(|c: char| c.is_ascii_whitespace()) {
        Some((h, a)) => (h, a.trim()),
        None => (cmd, ""),
    };
    let query = header.ends_with('?');
    let h = header.trim_end_matches('?');
    let common = h.starts_with('*');
    let absolute = h.starts_with(':');
    let h = h.strip_prefix(':').unwrap_or(h);
    let h = h.strip_prefix('*').unwrap_or(h);
    if h.is_empty()
        || !h
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == ':' || c == '_')
    {
        return Err(ScpiError::SYNTAX);
    }
    let parts: Vec<String> = h.split(':').map(str::to_ascii_uppercase).collect();
    if parts.iter().any(String::is_empty) {
        return Err(ScpiError::SYNTAX);
    }
    Ok(Split {
        parts,
        query,
        common,
        absolute,
        args: split_args(args),
    })
}

fn split_args(s: &str) -> Vec<&str> {
    if s.is_empty() {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut depth = 0i32;
    let mut start = 0;
    for (i, c) in s.char_indices() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            ',' if depth <= 0 => {
                out.push(s[start..i].trim());
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(s[start..].trim());
    out
}

/// A numeric argument: a decimal number (NRf), or `MIN`/`MAX`, with an
/// optional unit suffix among `units` (`V`, `MV`, ...), each with its
/// multiplier.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Numeric {
    /// A value, in the base unit.
    Value(f64),
    /// `MINimum`.
    Min,
    /// `MAXimum`.
    Max,
}

/// Parse a numeric argument; `units` pairs an upper-case suffix with its
/// multiplier (`("MV", 1e-3)`).
pub fn parse_numeric(arg: &str, units: &[(&str, f64)]) -> Result<Numeric, ScpiError> {
    let a = arg.trim().to_ascii_uppercase();
    if a.is_empty() {
        return Err(ScpiError::MISSING_PARAMETER);
    }
    if node("MINimum").matches(&a) {
        return Ok(Numeric::Min);
    }
    if node("MAXimum").matches(&a) {
        return Ok(Numeric::Max);
    }
    let end = a
        .find(|c: char| !(c.is_ascii_digit() || matches!(c, '+' | '-' | '.' | 'E')))
        .unwrap_or(a.len());
    // `E` belongs to the number only when an exponent follows it.
    let (num, suffix) = match a[..end].rfind('E') {
        Some(i) if i + 1 == end => (&a[..i], a[i..].trim()),
        _ => (&a[..end], a[end..].trim()),
    };
    let v: f64 = num.parse().map_err(|_| ScpiError::DATA_TYPE)?;
    if !v.is_finite() {
        return Err(ScpiError::DATA_TYPE);
    }
    if suffix.is_empty() {
        return Ok(Numeric::Value(v));
    }
    units
        .iter()
        .find(|(u, _)| *u == suffix)
        .map(|(_, k)| Numeric::Value(v * k))
        .ok_or(ScpiError::INVALID_SUFFIX)
}

/// A boolean argument: `ON`, `OFF`, `1`, `0`.
pub fn parse_bool_arg(arg: &str) -> Result<bool, ScpiError> {
    match arg.trim().to_ascii_uppercase().as_str() {
        "" => Err(ScpiError::MISSING_PARAMETER),
        "ON" | "1" => Ok(true),
        "OFF" | "0" => Ok(false),
        _ => Err(ScpiError::ILLEGAL_PARAMETER),
    }
}

/// A boolean reply in any of the forms instruments use: `1`/`0`,
/// `ON`/`OFF`, `YES`/`NO`.
pub fn parse_bool_reply(reply: &str) -> Option<bool> {
    match reply.trim().to_ascii_uppercase().as_str() {
        "1" | "ON" | "YES" | "+1" => Some(true),
        "0" | "OFF" | "NO" | "+0" => Some(false),
        _ => None,
    }
}

/// A number reply (`+5.00000000E+00`, `5.000`); none unless finite.
pub fn parse_number_reply(reply: &str) -> Option<f64> {
    reply
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|v: &f64| v.is_finite())
}

/// A `SYST:ERR?` reply: the number and the text (`-222,"Data out of
/// range"`, `+0,"No error"`); none unless of that form.
pub fn parse_error_reply(reply: &str) -> Option<(i32, String)> {
    let (code, text) = reply.trim().split_once(',')?;
    let code: i32 = code.trim().parse().ok()?;
    let text = text.trim().trim_matches('"').to_owned();
    Some((code, text))
}

/// A number as Keysight instruments send it: `+5.00000000E+00`.
pub fn format_nr3(v: f64) -> String {
    let s = format!("{:.8E}", v.abs());
    let (mantissa, exp) = s.split_once('E').unwrap_or((&s, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let sign = if v < 0.0 { '-' } else { '+' };
    let esign = if exp < 0 { '-' } else { '+' };
    format!("{sign}{mantissa}E{esign}{:02}", exp.abs())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SOURCE_VOLTAGE: &[Node] = &[
        opt("SOURce"),
        node("VOLTage"),
        opt("LEVel"),
        opt("IMMediate"),
        opt("AMPLitude"),
    ];

    fn parts(h: &str) -> Vec<String> {
        split_command(h).expect("valid").parts
    }

    fn matches(h: &str, pattern: &[Node]) -> bool {
        let p = parts(h);
        let p: Vec<&str> = p.iter().map(String::as_str).collect();
        header_matches(&p, pattern)
    }

    #[test]
    fn short_and_long_forms_and_optional_nodes() {
        for h in [
            "VOLT",
            "volt",
            ":VOLTage",
            "SOUR:VOLT",
            "SOURCE:VOLTAGE:LEVEL:IMMEDIATE:AMPLITUDE",
            "VOLT:AMPL",
            "volt:lev:imm",
        ] {
            assert!(matches(h, SOURCE_VOLTAGE), "{h}");
        }
        for h in ["VOL", "VOLTS", "SOUR", "VOLT:LEV:LEV", "CURR"] {
            assert!(!matches(h, SOURCE_VOLTAGE), "{h}");
        }
    }

    #[test]
    fn commands_split_into_header_and_arguments() {
        let s = split_command("  VOLT:PROT 5.5, (@1,2) ").expect("valid");
        assert_eq!(s.parts, ["VOLT", "PROT"]);
        assert!(!s.query && !s.common);
        assert_eq!(s.args, ["5.5", "(@1,2)"]);
        assert!(split_command(":VOLT 1").expect("valid").absolute);
        let s = split_command("*IDN?").expect("valid");
        assert!(s.query && s.common && !s.absolute);
        assert_eq!(s.parts, ["IDN"]);
        assert_eq!(split_command("VOLT::X"), Err(ScpiError::SYNTAX));
        assert_eq!(split_command("VO#LT 1"), Err(ScpiError::SYNTAX));
    }

    #[test]
    fn numbers_words_and_suffixes() {
        let units = [("V", 1.0), ("MV", 1e-3)];
        assert_eq!(parse_numeric("5", &units), Ok(Numeric::Value(5.0)));
        assert_eq!(parse_numeric("1.5E+1", &units), Ok(Numeric::Value(15.0)));
        assert_eq!(parse_numeric("250 mV", &units), Ok(Numeric::Value(0.25)));
        assert_eq!(parse_numeric("12V", &units), Ok(Numeric::Value(12.0)));
        assert_eq!(parse_numeric("max", &units), Ok(Numeric::Max));
        assert_eq!(parse_numeric("MINIMUM", &units), Ok(Numeric::Min));
        assert_eq!(parse_numeric("5 A", &units), Err(ScpiError::INVALID_SUFFIX));
        assert_eq!(parse_numeric("five", &units), Err(ScpiError::DATA_TYPE));
        assert_eq!(parse_numeric("", &units), Err(ScpiError::MISSING_PARAMETER));
        assert_eq!(parse_bool_arg("on"), Ok(true));
        assert_eq!(parse_bool_arg("0"), Ok(false));
        assert_eq!(parse_bool_arg("maybe"), Err(ScpiError::ILLEGAL_PARAMETER));
        assert_eq!(parse_bool_reply("YES\n"), Some(true));
        assert_eq!(parse_bool_reply("0"), Some(false));
    }

    #[test]
    fn keysight_numbers_and_error_replies() {
        assert_eq!(format_nr3(5.0), "+5.00000000E+00");
        assert_eq!(format_nr3(-0.0125), "-1.25000000E-02");
        assert_eq!(format_nr3(0.0), "+0.00000000E+00");
        assert_eq!(parse_number_reply("+1.50000000E+01"), Some(15.0));
        assert_eq!(
            parse_error_reply("-222,\"Data out of range\""),
            Some((-222, "Data out of range".to_owned()))
        );
        assert_eq!(
            parse_error_reply("+0,\"No error\""),
            Some((0, "No error".into()))
        );
        assert_eq!(parse_error_reply("garbage"), None);
    }

    #[test]
    fn a_full_queue_ends_in_an_overflow_and_drops_the_rest() {
        let mut q = ErrorQueue::default();
        for _ in 0..30 {
            q.push(ScpiError::UNDEFINED_HEADER);
        }
        let mut seen = Vec::new();
        while let Some(e) = q.pop() {
            seen.push(e);
        }
        assert_eq!(seen.len(), ErrorQueue::DEPTH);
        assert_eq!(seen.last(), Some(&ScpiError::QUEUE_OVERFLOW));
        assert!(q.is_empty());
        // Exactly full: every error kept; room again after a read.
        for _ in 0..ErrorQueue::DEPTH {
            q.push(ScpiError::SYNTAX);
        }
        assert_eq!(q.pop(), Some(ScpiError::SYNTAX));
        q.push(ScpiError::OUT_OF_RANGE);
        let rest: Vec<_> = std::iter::from_fn(|| q.pop()).collect();
        assert_eq!(rest.len(), ErrorQueue::DEPTH);
        assert_eq!(rest.last(), Some(&ScpiError::OUT_OF_RANGE), "no overflow");
    }

    proptest::proptest! {
        #[test]
        fn parsing_never_panics(s in "\\PC*") {
            if let Ok(c) = split_command(&s) {
                for a in c.args {
                    let _ = parse_numeric(a, &[("V", 1.0)]);
                    let _ = parse_bool_arg(a);
                }
            }
            let _ = parse_error_reply(&s);
            let _ = parse_number_reply(&s);
        }
    }
}
