//! ACL-style command language of the two-axis motion simulator
//! (Acutronic-like, SCPI-like): `:` descends the tree, `;` chains commands
//! in one servo frame, messages end with LF (CR LF accepted). Long or short
//! forms: `:Demand:Position` = `:DEM:POS` = `:D:P`. The first argument is the
//! axis (1 = outer, 2 = inner). Set commands do not answer; errors go to the
//! error queue (`:SYST:ERR?`) and show in the status byte (`*STB?`).

/// Table axis: 1 = outer, 2 = inner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// Axis 1.
    Outer,
    /// Axis 2.
    Inner,
}

impl Axis {
    /// Wire number of the axis.
    pub fn number(self) -> u8 {
        match self {
            Self::Outer => 1,
            Self::Inner => 2,
        }
    }

    fn from_number(n: f64) -> Option<Self> {
        if n == 1.0 {
            Some(Self::Outer)
        } else if n == 2.0 {
            Some(Self::Inner)
        } else {
            None
        }
    }
}

/// Servo mode of an axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServoMode {
    /// Hold / go to the position demand.
    Position,
    /// Follow the rate demand.
    Rate,
    /// Controlled stop.
    Stop,
}

/// One command of a message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// `:M:P|R|O <ax>`.
    Mode(Axis, ServoMode),
    /// `:D:P <ax>,<deg>`.
    DemandPosition(Axis, f64),
    /// `:D:R <ax>,<deg/s>`.
    DemandRate(Axis, f64),
    /// `:R:P? <ax>`, deg.
    ReadPosition(Axis),
    /// `:R:R? <ax>`, deg/s.
    ReadRate(Axis),
    /// `:LIM:RATE <ax>,<deg/s>`.
    LimitRate(Axis, f64),
    /// `:LIM:ACC <ax>,<deg/s^2>`.
    LimitAcc(Axis, f64),
    /// `:INT:CLOSE <ax>`: servo on.
    InterlockClose(Axis),
    /// `:INT:OPEN <ax>`: orderly shutdown of the axis.
    InterlockOpen(Axis),
    /// `:INT:RESET`: clear a tripped system interlock.
    InterlockReset,
    /// `*STB?`.
    StatusByte,
    /// `*IDN?`.
    Identify,
    /// `*CLS`: clear status and error queue.
    ClearStatus,
    /// `:SYST:ERR?`: oldest queued error.
    ErrorQuery,
}

impl Command {
    /// The command in short form, as the driver sends it.
    pub fn text(&self) -> String {
        let ax = |a: &Axis| a.number();
        match self {
            Self::Mode(a, ServoMode::Position) => format!(":M:P {}", ax(a)),
            Self::Mode(a, ServoMode::Rate) => format!(":M:R {}", ax(a)),
            Self::Mode(a, ServoMode::Stop) => format!(":M:O {}", ax(a)),
            Self::DemandPosition(a, v) => format!(":D:P {},{v:.4}", ax(a)),
            Self::DemandRate(a, v) => format!(":D:R {},{v:.6}", ax(a)),
            Self::ReadPosition(a) => format!(":R:P? {}", ax(a)),
            Self::ReadRate(a) => format!(":R:R? {}", ax(a)),
            Self::LimitRate(a, v) => format!(":LIM:RATE {},{v:.4}", ax(a)),
            Self::LimitAcc(a, v) => format!(":LIM:ACC {},{v:.4}", ax(a)),
            Self::InterlockClose(a) => format!(":INT:CLOSE {}", ax(a)),
            Self::InterlockOpen(a) => format!(":INT:OPEN {}", ax(a)),
            Self::InterlockReset => ":INT:RESET".into(),
            Self::StatusByte => "*STB?".into(),
            Self::Identify => "*IDN?".into(),
            Self::ClearStatus => "*CLS".into(),
            Self::ErrorQuery => ":SYST:ERR?".into(),
        }
    }

    /// True if the instrument answers this command.
    pub fn is_query(&self) -> bool {
        matches!(
            self,
            Self::ReadPosition(_)
                | Self::ReadRate(_)
                | Self::StatusByte
                | Self::Identify
                | Self::ErrorQuery
        )
    }
}

/// A message: commands chained with `;`, LF-terminated.
pub fn encode(commands: &[Command]) -> Vec<u8> {
    let mut s = commands
        .iter()
        .map(Command::text)
        .collect::<Vec<_>>()
        .join(";");
    s.push('\n');
    s.into_bytes()
}

use super::scpi::ScpiError;

/// Status byte bits.
pub mod stb {
    /// A system interlock is tripped.
    pub const INTERLOCK: u8 = 1 << 0;
    /// The error queue is not empty.
    pub const ERROR_QUEUE: u8 = 1 << 2;
}

const TREE: &[(&str, &[&str])] = &[
    ("MODE", &["POSITION", "RATE", "OFF"]),
    ("DEMAND", &["POSITION", "RATE"]),
    ("READ", &["POSITION", "RATE"]),
    ("LIMIT", &["RATE", "ACCELERATION"]),
    ("INTERLOCK", &["CLOSE", "OPEN", "RESET"]),
    ("SYSTEM", &["ERROR"]),
];

/// Long name of the node `token` abbreviates among `names`.
fn resolve<'a>(token: &str, names: &[&'a str]) -> Option<&'a str> {
    let t = token.to_ascii_uppercase();
    if t.is_empty() {
        return None;
    }
    names.iter().copied().find(|n| n.starts_with(t.as_str()))
}

/// Parse one received message into its commands; each failing command
/// gives the error to queue. Relative headers after `;` continue from the
/// previous command's branch, as in SCPI.
pub fn parse_message(line: &str) -> Vec<Result<Command, ScpiError>> {
    let line = line.trim_end_matches(['\r', '\n']);
    let mut branch: Option<&'static str> = None;
    line.split(';')
        .map(str::trim)
        .filter(|c| !c.is_empty())
        .map(|c| parse_one(c, &mut branch))
        .collect()
}

fn parse_one(cmd: &str, branch: &mut Option<&'static str>) -> Result<Command, ScpiError> {
    let (header, args) = match cmd.split_once(char::is_whitespace) {
        Some((h, a)) => (h, a.trim()),
        None => (cmd, ""),
    };
    let upper = header.to_ascii_uppercase();
    match upper.as_str() {
        "*STB?" => return Ok(Command::StatusByte),
        "*IDN?" => return Ok(Command::Identify),
        "*CLS" => return Ok(Command::ClearStatus),
        _ => {}
    }
    let query = upper.ends_with('?');
    let (root, node) = header_node(upper.trim_end_matches('?'), branch)?;

    let nums: Vec<&str> = if args.is_empty() {
        Vec::new()
    } else {
        args.split(',').map(str::trim).collect()
    };
    let num = |i: usize| -> Result<f64, ScpiError> {
        let s = nums.get(i).ok_or(ScpiError::MISSING_PARAMETER)?;
        let v: f64 = s.parse().map_err(|_| ScpiError::DATA_TYPE)?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(ScpiError::DATA_TYPE)
        }
    };
    let axis = || Axis::from_number(num(0)?).ok_or(ScpiError::OUT_OF_RANGE);
    let expect_query = |want: bool| {
        if query == want {
            Ok(())
        } else {
            Err(ScpiError::UNDEFINED_HEADER)
        }
    };
    match (root, node) {
        ("MODE", m) => {
            expect_query(false)?;
            let mode = match m {
                "POSITION" => ServoMode::Position,
                "RATE" => ServoMode::Rate,
                _ => ServoMode::Stop,
            };
            Ok(Command::Mode(axis()?, mode))
        }
        ("DEMAND", "POSITION") => {
            expect_query(false)?;
            Ok(Command::DemandPosition(axis()?, num(1)?))
        }
        ("DEMAND", _) => {
            expect_query(false)?;
            Ok(Command::DemandRate(axis()?, num(1)?))
        }
        ("READ", "POSITION") => {
            expect_query(true)?;
            Ok(Command::ReadPosition(axis()?))
        }
        ("READ", _) => {
            expect_query(true)?;
            Ok(Command::ReadRate(axis()?))
        }
        ("LIMIT", "RATE") => {
            expect_query(false)?;
            Ok(Command::LimitRate(axis()?, num(1)?))
        }
        ("LIMIT", _) => {
            expect_query(false)?;
            Ok(Command::LimitAcc(axis()?, num(1)?))
        }
        ("INTERLOCK", "CLOSE") => Ok(Command::InterlockClose(axis()?)),
        ("INTERLOCK", "OPEN") => Ok(Command::InterlockOpen(axis()?)),
        ("INTERLOCK", _) => Ok(Command::InterlockReset),
        ("SYSTEM", _) => {
            expect_query(true)?;
            Ok(Command::ErrorQuery)
        }
        _ => Err(ScpiError::UNDEFINED_HEADER),
    }
}

/// The subsystem and node a header's `path` names (its query mark taken
/// off): `:ROOT:LEAF` or `ROOT:LEAF` from the tree's top, a lone `LEAF` in
/// the `branch` the message's last command left (SCPI's compound rule),
/// each in short or long form. The branch moves to the root found.
fn header_node(
    path: &str,
    branch: &mut Option<&'static str>,
) -> Result<(&'static str, &'static str), ScpiError> {
    let (absolute, path) = match path.strip_prefix(':') {
        Some(p) => (true, p),
        None => (false, path),
    };
    let parts: Vec<&str> = path.split(':').collect();
    let (root, leaf) = match (parts.as_slice(), absolute, *branch) {
        ([r, l], _, _) => {
            let t = r.to_ascii_uppercase();
            let root = TREE
                .iter()
                .find(|(n, _)| !t.is_empty() && n.starts_with(t.as_str()))
                .ok_or(ScpiError::UNDEFINED_HEADER)?;
            (root, *l)
        }
        ([l], false, Some(b)) => (
            TREE.iter()
                .find(|(n, _)| *n == b)
                .ok_or(ScpiError::UNDEFINED_HEADER)?,
            *l,
        ),
        _ => return Err(ScpiError::UNDEFINED_HEADER),
    };
    let node = resolve(leaf, root.1).ok_or(ScpiError::UNDEFINED_HEADER)?;
    *branch = Some(root.0);
    Ok((root.0, node))
}

/// Split a compound reply (`a;b;c`) into numbers.
pub fn parse_numbers(reply: &str, expected: usize) -> Option<Vec<f64>> {
    let v: Vec<f64> = reply
        .trim()
        .split(';')
        .map(|s| s.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<_>>()?;
    (v.len() == expected).then_some(v)
}

/// The identity in an `*IDN?` reply: `maker,model,serial,firmware` (the
/// IEEE 488.2 form; missing fields are none).
pub fn parse_identity(reply: &str) -> super::Identity {
    let mut f = reply.trim().splitn(4, ',').map(super::clean_field);
    super::Identity {
        manufacturer: f.next().flatten(),
        model: f.next().flatten(),
        serial: f.next().flatten(),
        firmware: f.next().flatten(),
        raw: reply.trim().to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(line: &str) -> Vec<Command> {
        parse_message(line)
            .into_iter()
            .collect::<Result<_, _>>()
            .expect("valid message")
    }

    #[test]
    fn long_and_short_forms_are_the_same_command() {
        let want = vec![Command::DemandPosition(Axis::Outer, 90.0)];
        for form in [
            ":Demand:Position 1,90",
            ":DEM:POS 1,90",
            ":D:P 1,90.0",
            ":d:p 1, 90\r\n",
        ] {
            assert_eq!(ok(form), want, "{form}");
        }
    }

    #[test]
    fn chains_and_relative_headers() {
        assert_eq!(
            ok(":M:P 2;:D:P 2,45.5;:R:P? 1;R? 2"),
            vec![
                Command::Mode(Axis::Inner, ServoMode::Position),
                Command::DemandPosition(Axis::Inner, 45.5),
                Command::ReadPosition(Axis::Outer),
                Command::ReadRate(Axis::Inner),
            ]
        );
    }

    #[test]
    fn errors_are_scpi_codes() {
        let e = |s: &str| parse_message(s).remove(0).expect_err("must fail");
        assert_eq!(e(":FOO:BAR 1"), ScpiError::UNDEFINED_HEADER);
        assert_eq!(e(":D:P 3,10"), ScpiError::OUT_OF_RANGE);
        assert_eq!(e(":D:P 1"), ScpiError::MISSING_PARAMETER);
        assert_eq!(e(":D:P 1,abc"), ScpiError::DATA_TYPE);
        assert_eq!(
            e(":R:P 1"),
            ScpiError::UNDEFINED_HEADER,
            "a read must be a query"
        );
    }

    #[test]
    fn encode_round_trips_through_the_parser() {
        let cmds = [
            Command::Mode(Axis::Outer, ServoMode::Rate),
            Command::DemandRate(Axis::Outer, -5.25),
            Command::LimitAcc(Axis::Inner, 10.0),
            Command::InterlockClose(Axis::Inner),
            Command::InterlockReset,
            Command::ErrorQuery,
            Command::StatusByte,
        ];
        let bytes = encode(&cmds);
        assert_eq!(bytes.last(), Some(&b'\n'));
        let text = String::from_utf8(bytes).expect("ascii");
        assert_eq!(ok(&text), cmds.to_vec());
    }

    #[test]
    fn compound_replies_parse() {
        assert_eq!(parse_numbers("12.5;-3.25", 2), Some(vec![12.5, -3.25]));
        assert_eq!(parse_numbers("12.5", 2), None);
        assert_eq!(parse_numbers("x", 1), None);
    }

    proptest::proptest! {
        #[test]
        fn parser_never_panics(s in "\\PC*") {
            let _ = parse_message(&s);
            let _ = parse_numbers(&s, 2);
        }
    }

    #[test]
    fn an_idn_reply_gives_maker_model_serial_and_firmware() {
        let id = parse_identity("ACUTRONIC,AC2247,SN 1234,FW 3.2.1\r");
        assert_eq!(id.manufacturer.as_deref(), Some("ACUTRONIC"));
        assert_eq!(id.model.as_deref(), Some("AC2247"));
        assert_eq!(id.serial.as_deref(), Some("SN 1234"));
        assert_eq!(id.firmware.as_deref(), Some("FW 3.2.1"));
        // Fields a unit leaves at 0 or out are none; control characters go.
        let id = parse_identity("Maker,Model\u{1b}[2J,0");
        assert_eq!(id.model.as_deref(), Some("Model[2J"));
        assert_eq!((id.serial, id.firmware), (None, None));
    }
}
