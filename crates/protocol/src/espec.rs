//! Espec P300 / SCP-220 ASCII protocol: lines ending in CR LF both ways.
//!
//! The host side builds request lines and parses replies; the instrument
//! side (the simulator) parses request lines and formats replies. On RS-485
//! a request carries an `<address>,` prefix.

use std::fmt::Write as _;

/// Operating mode of the chamber controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Controller off.
    Off,
    /// Powered, not controlling.
    Standby,
    /// Holding the constant set point.
    Constant,
    /// Running a program.
    Run,
}

impl Mode {
    /// The protocol's word for the mode.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Off => "OFF",
            Self::Standby => "STANDBY",
            Self::Constant => "CONSTANT",
            Self::Run => "RUN",
        }
    }

    fn parse(s: &str) -> Option<Self> {
        match s.trim().to_ascii_uppercase().as_str() {
            "OFF" => Some(Self::Off),
            "STANDBY" => Some(Self::Standby),
            "CONSTANT" => Some(Self::Constant),
            "RUN" => Some(Self::Run),
            _ => None,
        }
    }
}

/// A request, as the host sends it.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// `TEMP?`: pv, sp, upper and lower alarm limits.
    Temp,
    /// `MON?`: temperature, humidity, mode, alarm count.
    Mon,
    /// `MODE?`.
    ModeQuery,
    /// `ALARM?`: count and codes.
    Alarm,
    /// `TYPE?`: controller type.
    Type,
    /// `ROM?`: firmware version.
    Rom,
    /// `TEMP, S<v>`: constant set point, degC.
    SetTemp(f64),
    /// `TEMP, H<v>`: upper alarm limit, degC.
    SetUpper(f64),
    /// `TEMP, L<v>`: lower alarm limit, degC.
    SetLower(f64),
    /// `MODE,<mode>`.
    SetMode(Mode),
    /// `POWER,ON` / `POWER,OFF`.
    Power(bool),
}

impl Request {
    /// The request line without terminator or address.
    pub fn text(&self) -> String {
        match self {
            Self::Temp => "TEMP?".into(),
            Self::Mon => "MON?".into(),
            Self::ModeQuery => "MODE?".into(),
            Self::Alarm => "ALARM?".into(),
            Self::Type => "TYPE?".into(),
            Self::Rom => "ROM?".into(),
            Self::SetTemp(v) => format!("TEMP, S{v:.1}"),
            Self::SetUpper(v) => format!("TEMP, H{v:.1}"),
            Self::SetLower(v) => format!("TEMP, L{v:.1}"),
            Self::SetMode(m) => format!("MODE,{}", m.as_str()),
            Self::Power(on) => format!("POWER,{}", if *on { "ON" } else { "OFF" }),
        }
    }

    /// The bytes on the wire, with the RS-485 address prefix when given.
    pub fn encode(&self, address: Option<u8>) -> Vec<u8> {
        let mut s = String::new();
        if let Some(a) = address {
            let _ = write!(s, "{a},");
        }
        s.push_str(&self.text());
        s.push_str("\r\n");
        s.into_bytes()
    }

    /// True for set commands, which answer `OK:<echo>`.
    pub fn is_set(&self) -> bool {
        matches!(
            self,
            Self::SetTemp(_)
                | Self::SetUpper(_)
                | Self::SetLower(_)
                | Self::SetMode(_)
                | Self::Power(_)
        )
    }
}

/// Why a reply cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplyError {
    /// The instrument refused the request.
    #[error("refused: NA:{0}")]
    Refused(String),
    /// The reply does not have the expected form.
    #[error("malformed reply {reply:?}: expected {expected}")]
    Malformed {
        /// The reply as received.
        reply: String,
        /// What was expected.
        expected: &'static str,
    },
}

fn malformed(reply: &str, expected: &'static str) -> ReplyError {
    ReplyError::Malformed {
        reply: reply.to_owned(),
        expected,
    }
}

fn refusal(reply: &str) -> Option<ReplyError> {
    reply
        .trim()
        .strip_prefix("NA:")
        .map(|r| ReplyError::Refused(r.trim().to_owned()))
}

fn number(s: &str, reply: &str, expected: &'static str) -> Result<f64, ReplyError> {
    let v: f64 = s.trim().parse().map_err(|_| malformed(reply, expected))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(malformed(reply, expected))
    }
}

/// Reply to `TEMP?`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TempReply {
    /// Measured temperature, degC.
    pub pv_c: f64,
    /// Set point, degC.
    pub sp_c: f64,
    /// Upper alarm limit, degC.
    pub upper_c: f64,
    /// Lower alarm limit, degC.
    pub lower_c: f64,
}

/// Parse a `TEMP?` reply: `pv,sp,upper,lower`.
pub fn parse_temp(reply: &str) -> Result<TempReply, ReplyError> {
    if let Some(e) = refusal(reply) {
        return Err(e);
    }
    const EXPECTED: &str = "four numbers `pv,sp,upper,lower`";
    let f: Vec<&str> = reply.trim().split(',').collect();
    let [pv, sp, up, lo] = f.as_slice() else {
        return Err(malformed(reply, EXPECTED));
    };
    Ok(TempReply {
        pv_c: number(pv, reply, EXPECTED)?,
        sp_c: number(sp, reply, EXPECTED)?,
        upper_c: number(up, reply, EXPECTED)?,
        lower_c: number(lo, reply, EXPECTED)?,
    })
}

/// Reply to `MON?`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonReply {
    /// Temperature, degC.
    pub temp_c: f64,
    /// Relative humidity, % (none if not fitted).
    pub humidity_pct: Option<f64>,
    /// Operating mode.
    pub mode: Mode,
    /// Number of active alarms.
    pub alarms: u32,
}

/// Parse a `MON?` reply: `temp,humi,mode,alarm_count`.
pub fn parse_mon(reply: &str) -> Result<MonReply, ReplyError> {
    if let Some(e) = refusal(reply) {
        return Err(e);
    }
    const EXPECTED: &str = "`temp,humidity,mode,alarm_count`";
    let f: Vec<&str> = reply.trim().split(',').collect();
    let [t, h, m, a] = f.as_slice() else {
        return Err(malformed(reply, EXPECTED));
    };
    Ok(MonReply {
        temp_c: number(t, reply, EXPECTED)?,
        humidity_pct: if h.trim().is_empty() {
            None
        } else {
            Some(number(h, reply, EXPECTED)?)
        },
        mode: Mode::parse(m).ok_or_else(|| malformed(reply, EXPECTED))?,
        alarms: a.trim().parse().map_err(|_| malformed(reply, EXPECTED))?,
    })
}

/// Parse a `MODE?` reply.
pub fn parse_mode(reply: &str) -> Result<Mode, ReplyError> {
    if let Some(e) = refusal(reply) {
        return Err(e);
    }
    Mode::parse(reply).ok_or_else(|| malformed(reply, "OFF, STANDBY, CONSTANT or RUN"))
}

/// Parse an `ALARM?` reply: `n[,code1,code2...]`, giving the codes.
pub fn parse_alarm(reply: &str) -> Result<Vec<u16>, ReplyError> {
    if let Some(e) = refusal(reply) {
        return Err(e);
    }
    const EXPECTED: &str = "`n[,code1,...]` with n codes";
    let mut f = reply.trim().split(',');
    let n: usize = f
        .next()
        .and_then(|s| s.trim().parse().ok())
        .ok_or_else(|| malformed(reply, EXPECTED))?;
    let codes: Vec<u16> = f
        .map(|s| s.trim().parse().map_err(|_| malformed(reply, EXPECTED)))
        .collect::<Result<_, _>>()?;
    if codes.len() != n {
        return Err(malformed(reply, EXPECTED));
    }
    Ok(codes)
}

/// Check the answer to a set command: `OK:<echo>`.
pub fn parse_ack(request: &Request, reply: &str) -> Result<(), ReplyError> {
    if let Some(e) = refusal(reply) {
        return Err(e);
    }
    let echo = reply
        .trim()
        .strip_prefix("OK:")
        .ok_or_else(|| malformed(reply, "`OK:<echo of the command>`"))?;
    let norm = |s: &str| {
        s.split_whitespace()
            .collect::<String>()
            .to_ascii_uppercase()
    };
    if norm(echo) == norm(&request.text()) {
        Ok(())
    } else {
        Err(malformed(reply, "`OK:` echoing the command sent"))
    }
}

// ---- The instrument side ----

/// Refusal reasons, as the instrument words them after `NA:`.
pub mod na {
    /// Unknown command.
    pub const CMD_ERR: &str = "CMD ERR";
    /// Wrong address.
    pub const ADDR_ERR: &str = "ADDR ERR";
    /// Bad parameter.
    pub const PARA_ERR: &str = "PARA ERR";
    /// Value beyond the instrument's range.
    pub const OUT_OF_RANGE: &str = "DATA OUT OF RANGE";
    /// Request not valid in this state.
    pub const INVALID_REQ: &str = "INVALID REQ";
}

/// A request line as the instrument receives it.
#[derive(Debug, Clone, PartialEq)]
pub struct Received {
    /// RS-485 address, if prefixed.
    pub address: Option<u8>,
    /// The request.
    pub request: Request,
    /// The request text as received (for the `OK:` echo).
    pub text: String,
}

/// Parse one received line (terminator already stripped). Errors are the
/// `NA:` reason to answer with.
pub fn parse_request(line: &str) -> Result<Received, &'static str> {
    let line = line.trim_end_matches(['\r', '\n']).trim();
    let (address, body) = match line.split_once(',') {
        Some((a, rest)) if !a.is_empty() && a.bytes().all(|b| b.is_ascii_digit()) => (
            Some(a.parse::<u8>().map_err(|_| na::ADDR_ERR)?),
            rest.trim(),
        ),
        _ => (None, line),
    };
    let upper = body.to_ascii_uppercase();
    let (head, arg) = match upper.split_once(',') {
        Some((h, a)) => (h.trim(), Some(a.trim())),
        None => (upper.trim(), None),
    };
    let request = match (head, arg) {
        ("TEMP?", None) => Request::Temp,
        ("MON?", None) => Request::Mon,
        ("MODE?", None) => Request::ModeQuery,
        ("ALARM?", None) => Request::Alarm,
        ("TYPE?", None) => Request::Type,
        ("ROM?", None) => Request::Rom,
        ("TEMP", Some(a)) => {
            let mut chars = a.chars();
            let kind = chars.next().ok_or(na::PARA_ERR)?;
            let v: f64 = chars.as_str().trim().parse().map_err(|_| na::PARA_ERR)?;
            if !v.is_finite() {
                return Err(na::PARA_ERR);
            }
            match kind {
                'S' => Request::SetTemp(v),
                'H' => Request::SetUpper(v),
                'L' => Request::SetLower(v),
                _ => return Err(na::PARA_ERR),
            }
        }
        ("MODE", Some(a)) => Request::SetMode(Mode::parse(a).ok_or(na::PARA_ERR)?),
        ("POWER", Some("ON")) => Request::Power(true),
        ("POWER", Some("OFF")) => Request::Power(false),
        ("POWER", Some(_)) => return Err(na::PARA_ERR),
        _ => return Err(na::CMD_ERR),
    };
    Ok(Received {
        address,
        request,
        text: body.to_owned(),
    })
}

/// Format a reply line with its terminator.
pub fn reply_line(body: &str) -> Vec<u8> {
    let mut v = body.as_bytes().to_vec();
    v.extend_from_slice(b"\r\n");
    v
}

/// Format a temperature field as the instrument does (one decimal).
pub fn fmt_temp(v: f64) -> String {
    format!("{v:.1}")
}

/// The text of a reply to `TYPE?` or `ROM?` (a refusal is an error).
pub fn parse_text(reply: &str) -> Result<String, ReplyError> {
    match refusal(reply) {
        Some(e) => Err(e),
        None => Ok(reply.trim().to_owned()),
    }
}

/// The identity in the replies to `TYPE?` (the controller type) and
/// `ROM?` (its firmware); the controller reports no serial number.
pub fn parse_identity(type_reply: &str, rom_reply: &str) -> super::Identity {
    super::Identity {
        manufacturer: Some("Espec".into()),
        model: super::clean_field(type_reply),
        serial: None,
        firmware: super::clean_field(rom_reply),
        raw: format!("TYPE? {} | ROM? {}", type_reply.trim(), rom_reply.trim()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_encode_as_documented() {
        assert_eq!(Request::Temp.encode(None), b"TEMP?\r\n");
        assert_eq!(Request::SetTemp(25.0).encode(None), b"TEMP, S25.0\r\n");
        assert_eq!(
            Request::SetTemp(-40.0).encode(Some(1)),
            b"1,TEMP, S-40.0\r\n"
        );
        assert_eq!(
            Request::SetMode(Mode::Constant).encode(None),
            b"MODE,CONSTANT\r\n"
        );
        assert_eq!(Request::Power(false).encode(None), b"POWER,OFF\r\n");
    }

    #[test]
    fn replies_parse_and_bad_ones_are_refused() {
        let t = parse_temp("23.5,25.0,100.0,-45.0").expect("valid");
        assert_eq!(
            (t.pv_c, t.sp_c, t.upper_c, t.lower_c),
            (23.5, 25.0, 100.0, -45.0)
        );
        assert!(matches!(
            parse_temp("23.5,25.0"),
            Err(ReplyError::Malformed { .. })
        ));
        assert!(matches!(
            parse_temp("23.5,x,1,2"),
            Err(ReplyError::Malformed { .. })
        ));
        assert!(matches!(
            parse_temp("NaN,1,1,1"),
            Err(ReplyError::Malformed { .. })
        ));
        assert_eq!(
            parse_temp("NA:CONT NOT READY-1"),
            Err(ReplyError::Refused("CONT NOT READY-1".into()))
        );
        let m = parse_mon("23.5,,CONSTANT,0").expect("valid");
        assert_eq!(
            (m.humidity_pct, m.mode, m.alarms),
            (None, Mode::Constant, 0)
        );
        assert_eq!(parse_alarm("2,3,15"), Ok(vec![3, 15]));
        assert!(parse_alarm("2,3").is_err());
        assert_eq!(parse_mode("STANDBY"), Ok(Mode::Standby));
        let set = Request::SetTemp(25.0);
        assert_eq!(parse_ack(&set, "OK:TEMP, S25.0"), Ok(()));
        assert!(parse_ack(&set, "OK:TEMP, S26.0").is_err());
        assert_eq!(
            parse_ack(&set, "NA:DATA OUT OF RANGE"),
            Err(ReplyError::Refused("DATA OUT OF RANGE".into()))
        );
    }

    #[test]
    fn instrument_side_parses_requests_with_and_without_address() {
        let r = parse_request("1,TEMP, S25.0\r\n").expect("valid");
        assert_eq!((r.address, r.request), (Some(1), Request::SetTemp(25.0)));
        assert_eq!(r.text, "TEMP, S25.0");
        assert_eq!(
            parse_request("mode,standby").map(|r| r.request),
            Ok(Request::SetMode(Mode::Standby))
        );
        assert_eq!(parse_request("FOO?"), Err(na::CMD_ERR));
        assert_eq!(parse_request("TEMP, Sabc"), Err(na::PARA_ERR));
        assert_eq!(parse_request("MODE,DANCE"), Err(na::PARA_ERR));
        assert_eq!(parse_request("999,TEMP?"), Err(na::ADDR_ERR));
        assert_eq!(parse_request(""), Err(na::CMD_ERR));
    }

    proptest::proptest! {
        #[test]
        fn parsers_never_panic(s in "\\PC*") {
            let _ = parse_temp(&s);
            let _ = parse_mon(&s);
            let _ = parse_alarm(&s);
            let _ = parse_mode(&s);
            let _ = parse_ack(&Request::Temp, &s);
            let _ = parse_request(&s);
        }
    }

    #[test]
    fn type_and_rom_give_the_controller_and_its_firmware_and_a_refusal_is_an_error() {
        let id = parse_identity("SCP-220,TEMP", "P-300 Ver 1.05");
        assert_eq!(id.manufacturer.as_deref(), Some("Espec"));
        assert_eq!(id.model.as_deref(), Some("SCP-220,TEMP"));
        assert_eq!(id.firmware.as_deref(), Some("P-300 Ver 1.05"));
        assert_eq!(id.serial, None);
        assert_eq!(
            parse_text("NA:CMD ERR"),
            Err(ReplyError::Refused("CMD ERR".into()))
        );
    }
}
