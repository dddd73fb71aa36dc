//! Programmable DC power supplies over SCPI: LF-terminated lines, `;`
//! chains commands, headers in short or long form, any case.
//!
//! The reference is Keysight's E36300 series (E36312A); Rigol's DP800
//! series (DP832) is the second [`Dialect`]. Both select the channel with
//! `INSTrument:NSELect` and then set, switch and measure the selected one
//! with the same headers. They differ in:
//!
//! | | Keysight E36300 | Rigol DP800 |
//! |---|---|---|
//! | over-current protection | trips when the output stays in current limit for its delay (`CURR:PROT:STAT ON`) | trips at once when the current reaches its own level (`CURR:PROT <A>`, `CURR:PROT:STAT ON`): the level must clear the turn-on inrush |
//! | tripped? | `CURR:PROT:TRIP?` gives `1`/`0` | `CURR:PROT:TRIP?` gives `YES`/`NO` |
//! | clear a trip | `OUTP:PROT:CLE` | `CURR:PROT:CLE` |
//! | numbers in replies | `+5.00000000E+00` | `5.000` |
//! | `OUTP?` | `1`/`0` | `ON`/`OFF` |
//! | a channel named in the command | an SCPI channel list as the last argument: `VOLT 5,(@2)`, `MEAS:VOLT? (@1:3)`, `OUTP ON,(@1,2)`; a query answers one value per channel, in the list's order, `,` between | `MEAS:VOLT? CH2`, `MEAS:CURR? CH2`, `OUTP CH2,ON`, `OUTP? CH2`, and `SOURce2:VOLT 5` (the channel as the header's suffix) |
//!
//! R&S HMP supplies share the selection and setting headers but protect
//! with an electronic fuse (`FUSE:STAT`, `FUSE:TRIP?`); they are not
//! supported here.

use super::scpi::{
    Node, Numeric, ScpiError, header_matches, node, opt, parse_bool_arg, parse_numeric,
    split_command,
};

/// Which maker's command set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Dialect {
    /// Keysight E36300 series (the reference).
    #[default]
    KeysightE36300,
    /// Rigol DP800 series.
    RigolDp800,
}

impl Dialect {
    /// The bench file's word for it.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::KeysightE36300 => "keysight-e36300",
            Self::RigolDp800 => "rigol-dp800",
        }
    }

    /// Every dialect, for error messages.
    pub const ALL: [Self; 2] = [Self::KeysightE36300, Self::RigolDp800];
}

/// What one output of a supply can deliver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rating {
    /// Highest voltage setting, V.
    pub max_v: f64,
    /// Highest current limit, A.
    pub max_a: f64,
}

/// The outputs of the model each dialect's simulator imitates: an
/// E36312A (6 V 5 A, 25 V 1 A, 25 V 1 A) or a DP832 (30 V 3 A, 30 V 3 A,
/// 5 V 3 A).
pub fn ratings(dialect: Dialect) -> [Rating; 3] {
    let r = |max_v, max_a| Rating { max_v, max_a };
    match dialect {
        Dialect::KeysightE36300 => [r(6.0, 5.0), r(25.0, 1.0), r(25.0, 1.0)],
        Dialect::RigolDp800 => [r(30.0, 3.0), r(30.0, 3.0), r(5.0, 3.0)],
    }
}

/// One command, host side or as the instrument parsed it. Channel-bound
/// commands act on the channel `Select` chose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// `*IDN?`.
    Identify,
    /// `*RST`: outputs off, settings to their reset values.
    Reset,
    /// `*CLS`: empty the error queue.
    ClearStatus,
    /// `*OPC?`: answers 1 once earlier commands are done.
    OperationComplete,
    /// `INST:NSEL <n>` (also `INST CH<n>`).
    Select(u8),
    /// `INST:NSEL?`.
    SelectQuery,
    /// `VOLT <V>`: the voltage setting.
    Voltage(Numeric),
    /// `VOLT?`.
    VoltageQuery,
    /// `CURR <A>`: the current limit.
    Current(Numeric),
    /// `CURR?`.
    CurrentQuery,
    /// `OUTP ON|OFF`.
    Output(bool),
    /// `OUTP?`.
    OutputQuery,
    /// `MEAS:VOLT?`: the voltage at the output, V.
    MeasureVoltage,
    /// `MEAS:CURR?`: the current through it, A.
    MeasureCurrent,
    /// `CURR:PROT:STAT ON|OFF`: over-current protection on or off.
    Protection(bool),
    /// `CURR:PROT:STAT?`.
    ProtectionQuery,
    /// `CURR:PROT <A>`: the trip level (Rigol only).
    ProtectionLevel(Numeric),
    /// `CURR:PROT?` (Rigol only).
    ProtectionLevelQuery,
    /// `CURR:PROT:TRIP?`: has the protection tripped?
    Tripped,
    /// `OUTP:PROT:CLE` (Keysight) or `CURR:PROT:CLE` (Rigol).
    ClearProtection,
    /// `SYST:ERR?`: the oldest error.
    ErrorQuery,
    /// `SYST:REM`: remote mode, needed before commands over serial.
    Remote,
}

/// Most channels one channel list may name (`(@1:16)`).
pub const MAX_LISTED: usize = 16;

/// The channels a command names for itself (1-based, in the order given;
/// a channel may come twice): an SCPI channel list (Keysight) or a Rigol
/// channel argument or header suffix. A command naming none acts on the
/// channel `INST:NSEL` selected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channels {
    list: [u8; MAX_LISTED],
    len: usize,
}

impl Channels {
    /// One channel.
    pub fn one(n: u8) -> Self {
        let mut list = [0; MAX_LISTED];
        list[0] = n;
        Self { list, len: 1 }
    }

    /// The channels, in order.
    pub fn iter(&self) -> impl Iterator<Item = u8> + '_ {
        self.list[..self.len].iter().copied()
    }

    fn push(&mut self, n: u8) -> Result<(), ScpiError> {
        // More channels than any supply has: a list of nonsense.
        let slot = self.list.get_mut(self.len).ok_or(ScpiError::OUT_OF_RANGE)?;
        *slot = n;
        self.len += 1;
        Ok(())
    }
}

/// A command as the instrument parsed it, with the channels it names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Addressed {
    /// What to do.
    pub command: Command,
    /// On which channels (none: the selected one).
    pub channels: Option<Channels>,
}

impl From<Command> for Addressed {
    fn from(command: Command) -> Self {
        Self {
            command,
            channels: None,
        }
    }
}

/// An SCPI channel list, `(@1)`, `(@1,2)`, `(@1:3)`, `(@3:1)` (a range
/// either way), or their mix `(@1,2:3)`; blanks allowed around the
/// parts. A malformed list is a data type error (-104), a channel 0 or
/// beyond 255 or a list of more than [`MAX_LISTED`] out of range (-222).
pub fn parse_channel_list(arg: &str) -> Result<Channels, ScpiError> {
    let inner = arg
        .trim()
        .strip_prefix('(')
        .and_then(|a| a.strip_suffix(')'))
        .map(str::trim)
        .and_then(|a| a.strip_prefix('@'))
        .ok_or(ScpiError::DATA_TYPE)?;
    let mut out = Channels {
        list: [0; MAX_LISTED],
        len: 0,
    };
    for item in inner.split(',') {
        let number = |s: &str| -> Result<u8, ScpiError> {
            let s = s.trim();
            if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
                return Err(ScpiError::DATA_TYPE);
            }
            match s.parse::<u32>() {
                Ok(n @ 1..=255) => Ok(n as u8),
                _ => Err(ScpiError::OUT_OF_RANGE),
            }
        };
        match item.split_once(':') {
            Some((a, b)) => {
                let (a, b) = (number(a)?, number(b)?);
                if a <= b {
                    for n in a..=b {
                        out.push(n)?;
                    }
                } else {
                    for n in (b..=a).rev() {
                        out.push(n)?;
                    }
                }
            }
            None => out.push(number(item)?)?,
        }
    }
    Ok(out)
}

fn num_text(n: Numeric) -> String {
    match n {
        Numeric::Value(v) => format!("{v:.4}"),
        Numeric::Min => "MIN".into(),
        Numeric::Max => "MAX".into(),
    }
}

impl Command {
    /// The command in short form, as the driver sends it to `dialect`.
    pub fn text(&self, dialect: Dialect) -> String {
        let on = |b: &bool| if *b { "ON" } else { "OFF" };
        match self {
            Self::Identify => "*IDN?".into(),
            Self::Reset => "*RST".into(),
            Self::ClearStatus => "*CLS".into(),
            Self::OperationComplete => "*OPC?".into(),
            Self::Select(n) => format!("INST:NSEL {n}"),
            Self::SelectQuery => "INST:NSEL?".into(),
            Self::Voltage(v) => format!("VOLT {}", num_text(*v)),
            Self::VoltageQuery => "VOLT?".into(),
            Self::Current(v) => format!("CURR {}", num_text(*v)),
            Self::CurrentQuery => "CURR?".into(),
            Self::Output(b) => format!("OUTP {}", on(b)),
            Self::OutputQuery => "OUTP?".into(),
            Self::MeasureVoltage => "MEAS:VOLT?".into(),
            Self::MeasureCurrent => "MEAS:CURR?".into(),
            Self::Protection(b) => format!("CURR:PROT:STAT {}", on(b)),
            Self::ProtectionQuery => "CURR:PROT:STAT?".into(),
            Self::ProtectionLevel(v) => format!("CURR:PROT {}", num_text(*v)),
            Self::ProtectionLevelQuery => "CURR:PROT?".into(),
            Self::Tripped => "CURR:PROT:TRIP?".into(),
            Self::ClearProtection => match dialect {
                Dialect::KeysightE36300 => "OUTP:PROT:CLE".into(),
                Dialect::RigolDp800 => "CURR:PROT:CLE".into(),
            },
            Self::ErrorQuery => "SYST:ERR?".into(),
            Self::Remote => "SYST:REM".into(),
        }
    }

    /// True if the instrument answers it.
    pub fn is_query(&self) -> bool {
        matches!(
            self,
            Self::Identify
                | Self::OperationComplete
                | Self::SelectQuery
                | Self::VoltageQuery
                | Self::CurrentQuery
                | Self::OutputQuery
                | Self::MeasureVoltage
                | Self::MeasureCurrent
                | Self::ProtectionQuery
                | Self::ProtectionLevelQuery
                | Self::Tripped
                | Self::ErrorQuery
        )
    }

    /// The line on the wire (one command: from the root).
    pub fn encode(&self, dialect: Dialect) -> Vec<u8> {
        let mut s = self.text(dialect);
        s.push('\n');
        s.into_bytes()
    }
}

/// The settings that configure the selected channel: voltage, current
/// limit, over-current protection. A Rigol trips at its own level: the
/// limit itself, so that it trips when the output is held at the limit, as
/// a Keysight does.
pub fn configure(dialect: Dialect, volts: f64, limit_a: f64, protection: bool) -> Vec<Command> {
    let mut cmds = vec![
        Command::Voltage(Numeric::Value(volts)),
        Command::Current(Numeric::Value(limit_a)),
    ];
    if dialect == Dialect::RigolDp800 {
        cmds.push(Command::ProtectionLevel(Numeric::Value(limit_a)));
    }
    cmds.push(Command::Protection(protection));
    cmds
}

const SOURCE_VOLTAGE: &[Node] = &[
    opt("SOURce"),
    node("VOLTage"),
    opt("LEVel"),
    opt("IMMediate"),
    opt("AMPLitude"),
];
const SOURCE_CURRENT: &[Node] = &[
    opt("SOURce"),
    node("CURRent"),
    opt("LEVel"),
    opt("IMMediate"),
    opt("AMPLitude"),
];
const PROT_STATE: &[Node] = &[
    opt("SOURce"),
    node("CURRent"),
    node("PROTection"),
    node("STATe"),
];
const PROT_LEVEL: &[Node] = &[
    opt("SOURce"),
    node("CURRent"),
    node("PROTection"),
    opt("LEVel"),
];
const PROT_TRIPPED: &[Node] = &[
    opt("SOURce"),
    node("CURRent"),
    node("PROTection"),
    node("TRIPped"),
];
const PROT_CLEAR_RIGOL: &[Node] = &[
    opt("SOURce"),
    node("CURRent"),
    node("PROTection"),
    node("CLEar"),
];
const PROT_CLEAR_KEYSIGHT: &[Node] = &[node("OUTPut"), node("PROTection"), node("CLEar")];
const OUTPUT: &[Node] = &[node("OUTPut"), opt("STATe")];
const MEAS_VOLTAGE: &[Node] = &[node("MEASure"), opt("SCALar"), node("VOLTage"), opt("DC")];
const MEAS_CURRENT: &[Node] = &[node("MEASure"), opt("SCALar"), node("CURRent"), opt("DC")];
const INST_NSELECT: &[Node] = &[node("INSTrument"), node("NSELect")];
const INST_SELECT: &[Node] = &[node("INSTrument"), opt("SELect")];
const SYST_ERROR: &[Node] = &[node("SYSTem"), node("ERRor"), opt("NEXT")];
const SYST_REMOTE: &[Node] = &[node("SYSTem"), node("REMote")];

const VOLTS: &[(&str, f64)] = &[("V", 1.0), ("MV", 1e-3)];
const AMPS: &[(&str, f64)] = &[("A", 1.0), ("MA", 1e-3)];

/// Parse one received message into its commands, each with the channels
/// it names; each failing command gives the error the instrument queues.
/// SCPI's path rule holds: a message starts at the root; after a `;` a
/// header continues from the branch of the one before (`SOUR:VOLT 5;CURR
/// 1` sets `SOUR:CURR`) unless it starts with `:`; common commands
/// (`*CLS`) leave the branch as it is.
pub fn parse_message(line: &str, dialect: Dialect) -> Vec<Result<Addressed, ScpiError>> {
    let mut branch: Vec<String> = Vec::new();
    line.trim_end_matches(['\r', '\n'])
        .split(';')
        .filter(|c| !c.trim().is_empty())
        .map(|c| {
            let mut s = split_command(c)?;
            if !s.common {
                if !s.absolute {
                    s.parts = branch.iter().cloned().chain(s.parts).collect();
                }
                branch = s.parts[..s.parts.len() - 1].to_vec();
            }
            parse_one(&s, dialect)
        })
        .collect()
}

/// One command with the channels it names: a Keysight channel list as
/// its last argument, a Rigol channel argument or `SOURce<n>` suffix, on
/// the commands that take one.
fn parse_one(s: &super::scpi::Split<'_>, dialect: Dialect) -> Result<Addressed, ScpiError> {
    let mut s = s.clone();
    let mut channels = None;
    if !s.common {
        match dialect {
            Dialect::KeysightE36300 => {
                if let Some(last) = s.args.last().filter(|a| a.starts_with('(')) {
                    channels = Some(parse_channel_list(last)?);
                    s.args.pop();
                }
            }
            Dialect::RigolDp800 => channels = rigol_channel(&mut s)?,
        }
    }
    let command = parse_bare(&s, dialect)?;
    if channels.is_some() && !takes_channels(&command, dialect) {
        return Err(ScpiError::PARAMETER_NOT_ALLOWED);
    }
    Ok(Addressed { command, channels })
}

/// The commands that act on the channels they name (the E36300's that
/// take a channel list; the DP800's that take a channel argument or a
/// `SOURce<n>` header).
fn takes_channels(c: &Command, dialect: Dialect) -> bool {
    use Command as C;
    match dialect {
        Dialect::KeysightE36300 => matches!(
            c,
            C::Voltage(_)
                | C::VoltageQuery
                | C::Current(_)
                | C::CurrentQuery
                | C::Output(_)
                | C::OutputQuery
                | C::MeasureVoltage
                | C::MeasureCurrent
                | C::Protection(_)
                | C::ProtectionQuery
                | C::Tripped
                | C::ClearProtection
        ),
        Dialect::RigolDp800 => matches!(
            c,
            C::Voltage(_)
                | C::VoltageQuery
                | C::Current(_)
                | C::CurrentQuery
                | C::Output(_)
                | C::OutputQuery
                | C::MeasureVoltage
                | C::MeasureCurrent
                | C::Protection(_)
                | C::ProtectionQuery
                | C::ProtectionLevel(_)
                | C::ProtectionLevelQuery
                | C::Tripped
                | C::ClearProtection
        ),
    }
}

/// A DP800's channel: `SOURce2:...` (the suffix taken off the header), or
/// a `CH<n>` argument first (`OUTP CH2,ON`, `MEAS:VOLT? CH2`, taken off
/// the arguments).
fn rigol_channel(s: &mut super::scpi::Split<'_>) -> Result<Option<Channels>, ScpiError> {
    if let Some(first) = s.parts.first_mut() {
        let digits = first.trim_start_matches(|c: char| c.is_ascii_alphabetic());
        let word = &first[..first.len() - digits.len()];
        if !digits.is_empty() && matches!(word, "SOUR" | "SOURCE") {
            let n = channel_number(digits).map_err(|_| ScpiError::UNDEFINED_HEADER)?;
            *first = word.to_owned();
            return Ok(Some(Channels::one(n)));
        }
    }
    let is_output = header_matches(
        &s.parts.iter().map(String::as_str).collect::<Vec<_>>(),
        OUTPUT,
    );
    let is_measure = {
        let parts: Vec<&str> = s.parts.iter().map(String::as_str).collect();
        header_matches(&parts, MEAS_VOLTAGE) || header_matches(&parts, MEAS_CURRENT)
    };
    if !(is_output || is_measure) {
        return Ok(None);
    }
    let named = s
        .args
        .first()
        .is_some_and(|a| a.trim().to_ascii_uppercase().starts_with("CH"));
    // `OUTP CH2,ON`, `OUTP? CH2`, `MEAS:VOLT? CH2`; `OUTP ON` alone names none.
    if named && (s.query || s.args.len() == 2) {
        let n = channel_name(s.args.remove(0))?;
        return Ok(Some(Channels::one(n)));
    }
    Ok(None)
}

fn parse_bare(s: &super::scpi::Split<'_>, dialect: Dialect) -> Result<Command, ScpiError> {
    let parts: Vec<&str> = s.parts.iter().map(String::as_str).collect();
    let args = s.args.as_slice();
    // A set command takes exactly one argument, a query none.
    let one = || match args {
        [] => Err(ScpiError::MISSING_PARAMETER),
        [a] => Ok(*a),
        _ => Err(ScpiError::PARAMETER_NOT_ALLOWED),
    };
    let none = |c: Command| {
        if args.is_empty() {
            Ok(c)
        } else {
            Err(ScpiError::PARAMETER_NOT_ALLOWED)
        }
    };
    if s.common {
        return match (parts.as_slice(), s.query) {
            (["IDN"], true) => none(Command::Identify),
            (["RST"], false) => none(Command::Reset),
            (["CLS"], false) => none(Command::ClearStatus),
            (["OPC"], true) => none(Command::OperationComplete),
            _ => Err(ScpiError::UNDEFINED_HEADER),
        };
    }
    let is = |pattern: &[Node]| header_matches(&parts, pattern);
    let rigol = dialect == Dialect::RigolDp800;
    // Longer headers first: `CURR:PROT` must not be read as `CURR`.
    if is(PROT_STATE) {
        return if s.query {
            none(Command::ProtectionQuery)
        } else {
            parse_bool_arg(one()?).map(Command::Protection)
        };
    }
    if is(PROT_TRIPPED) && s.query {
        return none(Command::Tripped);
    }
    if (is(PROT_CLEAR_RIGOL) && rigol || is(PROT_CLEAR_KEYSIGHT) && !rigol) && !s.query {
        return none(Command::ClearProtection);
    }
    if is(PROT_LEVEL) && rigol {
        return if s.query {
            none(Command::ProtectionLevelQuery)
        } else {
            parse_numeric(one()?, AMPS).map(Command::ProtectionLevel)
        };
    }
    if is(SOURCE_VOLTAGE) {
        return if s.query {
            none(Command::VoltageQuery)
        } else {
            parse_numeric(one()?, VOLTS).map(Command::Voltage)
        };
    }
    if is(SOURCE_CURRENT) {
        return if s.query {
            none(Command::CurrentQuery)
        } else {
            parse_numeric(one()?, AMPS).map(Command::Current)
        };
    }
    if is(OUTPUT) {
        return if s.query {
            none(Command::OutputQuery)
        } else {
            parse_bool_arg(one()?).map(Command::Output)
        };
    }
    if is(MEAS_VOLTAGE) && s.query {
        return none(Command::MeasureVoltage);
    }
    if is(MEAS_CURRENT) && s.query {
        return none(Command::MeasureCurrent);
    }
    if is(INST_NSELECT) {
        return if s.query {
            none(Command::SelectQuery)
        } else {
            channel_number(one()?).map(Command::Select)
        };
    }
    if is(INST_SELECT) {
        return if s.query {
            none(Command::SelectQuery)
        } else {
            channel_name(one()?).map(Command::Select)
        };
    }
    if is(SYST_ERROR) && s.query {
        return none(Command::ErrorQuery);
    }
    if is(SYST_REMOTE) && !s.query {
        return none(Command::Remote);
    }
    Err(ScpiError::UNDEFINED_HEADER)
}

fn channel_number(arg: &str) -> Result<u8, ScpiError> {
    let v: f64 = arg.trim().parse().map_err(|_| ScpiError::DATA_TYPE)?;
    if v.fract() != 0.0 || !(1.0..=255.0).contains(&v) {
        return Err(ScpiError::OUT_OF_RANGE);
    }
    Ok(v as u8)
}

/// `CH2` (both makers) or `OUTP2`/`OUT2`.
fn channel_name(arg: &str) -> Result<u8, ScpiError> {
    let a = arg.trim().to_ascii_uppercase();
    let digits = ["CH", "OUTPUT", "OUTP", "OUT"]
        .iter()
        .find_map(|p| a.strip_prefix(p))
        .ok_or(ScpiError::ILLEGAL_PARAMETER)?;
    channel_number(digits).map_err(|_| ScpiError::ILLEGAL_PARAMETER)
}

/// The identity in an `*IDN?` reply (`maker,model,serial,firmware`).
pub fn parse_identity(reply: &str) -> super::Identity {
    super::acl::parse_identity(reply)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(line: &str, d: Dialect) -> Vec<Command> {
        at(line, d).into_iter().map(|(c, _)| c).collect()
    }

    /// Each command with the channels it names (empty: the selected one).
    fn at(line: &str, d: Dialect) -> Vec<(Command, Vec<u8>)> {
        parse_message(line, d)
            .into_iter()
            .map(|r| {
                r.map(|a| {
                    let chans = a.channels.map_or_else(Vec::new, |c| c.iter().collect());
                    (a.command, chans)
                })
            })
            .collect::<Result<_, _>>()
            .expect("valid message")
    }

    fn err(line: &str, d: Dialect) -> ScpiError {
        parse_message(line, d).remove(0).expect_err("must fail")
    }

    const K: Dialect = Dialect::KeysightE36300;
    const R: Dialect = Dialect::RigolDp800;

    #[test]
    fn long_and_short_forms_are_the_same_command() {
        for form in [
            "VOLT 15",
            ":SOURce:VOLTage:LEVel:IMMediate:AMPLitude 15.0",
            "sour:volt 15V",
            "VOLT 15000 mV",
        ] {
            assert_eq!(
                ok(form, K),
                [Command::Voltage(Numeric::Value(15.0))],
                "{form}"
            );
        }
        assert_eq!(
            ok("INST:NSEL 2;:INST CH3;:INSTrument:SELect OUT1", K),
            [Command::Select(2), Command::Select(3), Command::Select(1)]
        );
        assert_eq!(
            ok("MEAS:VOLT?;:MEASure:SCALar:CURRent:DC?", R),
            [Command::MeasureVoltage, Command::MeasureCurrent]
        );
    }

    #[test]
    fn after_a_semicolon_a_header_continues_from_the_branch_before() {
        // SCPI's path rule: relative to the previous header's branch.
        assert_eq!(
            ok("SOUR:VOLT 5;CURR 1;*CLS;VOLT?", K),
            [
                Command::Voltage(Numeric::Value(5.0)),
                Command::Current(Numeric::Value(1.0)),
                Command::ClearStatus,
                Command::VoltageQuery
            ]
        );
        assert_eq!(
            ok("CURR:PROT:STAT ON;TRIP?", K),
            [Command::Protection(true), Command::Tripped]
        );
        assert_eq!(
            ok("MEAS:VOLT?;CURR?", K),
            [Command::MeasureVoltage, Command::MeasureCurrent]
        );
        // `INST:VOLT` is no command: a leading colon is needed.
        let r = parse_message("INST:NSEL 2;VOLT 5", K);
        assert_eq!(r[1], Err(ScpiError::UNDEFINED_HEADER));
        assert_eq!(
            ok("INST:NSEL 2;:VOLT 5", K),
            [Command::Select(2), Command::Voltage(Numeric::Value(5.0))]
        );
    }

    #[test]
    fn what_the_driver_sends_parses_back_in_its_dialect() {
        for d in Dialect::ALL {
            let mut cmds = vec![
                Command::Identify,
                Command::Reset,
                Command::ClearStatus,
                Command::OperationComplete,
                Command::Select(2),
                Command::SelectQuery,
                Command::Voltage(Numeric::Value(15.25)),
                Command::VoltageQuery,
                Command::Current(Numeric::Max),
                Command::CurrentQuery,
                Command::Output(true),
                Command::OutputQuery,
                Command::MeasureVoltage,
                Command::MeasureCurrent,
                Command::Protection(false),
                Command::ProtectionQuery,
                Command::Tripped,
                Command::ClearProtection,
                Command::ErrorQuery,
                Command::Remote,
            ];
            if d == R {
                cmds.push(Command::ProtectionLevel(Numeric::Value(1.2)));
                cmds.push(Command::ProtectionLevelQuery);
            }
            for c in cmds {
                let text = String::from_utf8(c.encode(d)).expect("ascii");
                assert_eq!(ok(&text, d), [c], "{text:?} in {d:?}");
            }
        }
    }

    #[test]
    fn each_maker_keeps_its_own_headers() {
        assert_eq!(ok("OUTP:PROT:CLE", K), [Command::ClearProtection]);
        assert_eq!(err("OUTP:PROT:CLE", R), ScpiError::UNDEFINED_HEADER);
        assert_eq!(ok("CURR:PROT:CLE", R), [Command::ClearProtection]);
        assert_eq!(err("CURR:PROT:CLE", K), ScpiError::UNDEFINED_HEADER);
        assert_eq!(err("CURR:PROT 1.5", K), ScpiError::UNDEFINED_HEADER);
    }

    #[test]
    fn errors_are_scpi_codes() {
        assert_eq!(err("VOLTS 5", K), ScpiError::UNDEFINED_HEADER);
        assert_eq!(err("VOLT", K), ScpiError::MISSING_PARAMETER);
        assert_eq!(err("VOLT five", K), ScpiError::DATA_TYPE);
        assert_eq!(err("VOLT 5 A", K), ScpiError::INVALID_SUFFIX);
        assert_eq!(err("VOLT 5,6", K), ScpiError::PARAMETER_NOT_ALLOWED);
        assert_eq!(err("OUTP MAYBE", K), ScpiError::ILLEGAL_PARAMETER);
        assert_eq!(err("INST:NSEL 0", K), ScpiError::OUT_OF_RANGE);
        assert_eq!(err("INST CHX", K), ScpiError::ILLEGAL_PARAMETER);
        assert_eq!(err("MEAS:VOLT", K), ScpiError::UNDEFINED_HEADER);
        assert_eq!(err("*IDN", K), ScpiError::UNDEFINED_HEADER);
        assert_eq!(err("VO$T 1", K), ScpiError::SYNTAX);
    }

    #[test]
    fn channel_lists_are_read_as_the_e36300_manual_writes_them() {
        let list = |a: &str| parse_channel_list(a).map(|c| c.iter().collect::<Vec<u8>>());
        assert_eq!(list("(@1)"), Ok(vec![1]));
        assert_eq!(list("(@1,2)"), Ok(vec![1, 2]));
        assert_eq!(list("(@1:3)"), Ok(vec![1, 2, 3]));
        assert_eq!(list("(@3:1)"), Ok(vec![3, 2, 1]));
        assert_eq!(list(" ( @ 1 , 2:3 ) "), Ok(vec![1, 2, 3]));
        assert_eq!(list("(@2,2)"), Ok(vec![2, 2]));
        for bad in ["(@)", "(@1,)", "(@x)", "(@1:)", "@1", "(1)", "(@1", "(@-1)"] {
            assert_eq!(list(bad), Err(ScpiError::DATA_TYPE), "{bad}");
        }
        for far in ["(@0)", "(@256)", "(@1:17)", "(@99999999999)"] {
            assert_eq!(list(far), Err(ScpiError::OUT_OF_RANGE), "{far}");
        }
    }

    #[test]
    fn a_keysight_command_names_its_channels_in_a_list_as_its_last_argument() {
        assert_eq!(
            at("MEAS:VOLT? (@2)", K),
            [(Command::MeasureVoltage, vec![2])]
        );
        assert_eq!(
            at("VOLT 5,(@1,3);CURR 0.5, (@1:3);:OUTP ON,(@2)", K),
            [
                (Command::Voltage(Numeric::Value(5.0)), vec![1, 3]),
                (Command::Current(Numeric::Value(0.5)), vec![1, 2, 3]),
                (Command::Output(true), vec![2]),
            ]
        );
        assert_eq!(
            at(
                "OUTP? (@1,2);:CURR:PROT:TRIP? (@2);:OUTP:PROT:CLE (@2);:MEAS:CURR?",
                K
            ),
            [
                (Command::OutputQuery, vec![1, 2]),
                (Command::Tripped, vec![2]),
                (Command::ClearProtection, vec![2]),
                (Command::MeasureCurrent, vec![]),
            ]
        );
        // A command that takes no list, or a list where a value belongs.
        assert_eq!(err("SYST:ERR? (@1)", K), ScpiError::PARAMETER_NOT_ALLOWED);
        assert_eq!(err("INST:NSEL 2,(@1)", K), ScpiError::PARAMETER_NOT_ALLOWED);
        assert_eq!(err("*IDN? (@1)", K), ScpiError::PARAMETER_NOT_ALLOWED);
        assert_eq!(err("VOLT (@1)", K), ScpiError::MISSING_PARAMETER);
        assert_eq!(err("MEAS:VOLT? (@1:x)", K), ScpiError::DATA_TYPE);
        // A Keysight has no channel as a header suffix.
        assert_eq!(err("SOUR2:VOLT 5", K), ScpiError::UNDEFINED_HEADER);
    }

    #[test]
    fn a_rigol_names_its_channel_as_that_instrument_does() {
        assert_eq!(
            at("MEAS:VOLT? CH2;CURR? CH3", R),
            [
                (Command::MeasureVoltage, vec![2]),
                (Command::MeasureCurrent, vec![3])
            ]
        );
        assert_eq!(
            at("OUTP CH2,ON;:OUTP? CH2;:OUTP OFF", R),
            [
                (Command::Output(true), vec![2]),
                (Command::OutputQuery, vec![2]),
                (Command::Output(false), vec![]),
            ]
        );
        // The suffix stays with the branch: `CURR` after `SOUR2:VOLT` is SOUR2's.
        assert_eq!(
            at("SOUR2:VOLT 5;CURR 1;:SOURce3:CURR:PROT:STAT ON", R),
            [
                (Command::Voltage(Numeric::Value(5.0)), vec![2]),
                (Command::Current(Numeric::Value(1.0)), vec![2]),
                (Command::Protection(true), vec![3]),
            ]
        );
        assert_eq!(err("MEAS:VOLT? (@2)", R), ScpiError::PARAMETER_NOT_ALLOWED);
        assert_eq!(err("OUTP? CHX", R), ScpiError::ILLEGAL_PARAMETER);
        assert_eq!(err("SOUR0:VOLT 5", R), ScpiError::UNDEFINED_HEADER);
    }

    proptest::proptest! {
        #[test]
        fn the_parser_never_panics(s in "\\PC*") {
            for d in Dialect::ALL {
                let _ = parse_message(&s, d);
            }
            let _ = parse_channel_list(&s);
        }

        /// Any list of channels written as a channel list reads back.
        #[test]
        fn written_channel_lists_read_back(chans in proptest::collection::vec(1u8..=255, 1..=MAX_LISTED)) {
            let text = format!(
                "(@{})",
                chans.iter().map(u8::to_string).collect::<Vec<_>>().join(",")
            );
            let got: Vec<u8> = parse_channel_list(&text).expect("a list").iter().collect();
            proptest::prop_assert_eq!(got, chans);
        }
    }
}
