//! The Espec P300 / SCP-220 chamber simulator.

use std::sync::Arc;

use tokio::io::{AsyncRead, AsyncWrite};

use super::faults::Action;
use super::lines::serve_lines;
use super::{PASSIVE_DRIFT_C_PER_MIN, SharedBench, SimBench};
use crate::protocol::espec::{Mode, Request, fmt_temp, na, parse_request, reply_line};

/// Longest request line accepted, bytes.
pub const MAX_LINE: usize = 256;

impl SimBench {
    /// Answer one Espec request line (without terminator), as the
    /// instrument would.
    pub fn espec_reply(&mut self, line: &str) -> String {
        let rx = match parse_request(line) {
            Ok(rx) => rx,
            Err(reason) => return format!("NA:{reason}"),
        };
        let (air, _, _) = self.twin.chamber_state();
        match rx.request {
            Request::Temp => format!(
                "{},{},{},{}",
                fmt_temp(air),
                fmt_temp(self.chamber.set_point_c),
                fmt_temp(self.chamber.upper_c),
                fmt_temp(self.chamber.lower_c)
            ),
            Request::Mon => format!(
                "{},,{},{}",
                fmt_temp(air),
                self.chamber.mode.as_str(),
                self.chamber_alarms().len()
            ),
            Request::ModeQuery => self.chamber.mode.as_str().to_owned(),
            Request::Alarm => {
                let codes = self.chamber_alarms();
                let mut s = codes.len().to_string();
                for c in codes {
                    s.push_str(&format!(",{c}"));
                }
                s
            }
            Request::Type => super::identity::ESPEC_TYPE.to_owned(),
            Request::Rom => super::identity::ESPEC_ROM.to_owned(),
            Request::SetTemp(v) => {
                let cfg = &self.twin.config().chamber;
                if !(cfg.min_c..=cfg.max_c).contains(&v) {
                    return format!("NA:{}", na::OUT_OF_RANGE);
                }
                self.chamber.set_point_c = v;
                self.apply_chamber_mode();
                format!("OK:{}", rx.text)
            }
            Request::SetUpper(v) => {
                self.chamber.upper_c = v;
                format!("OK:{}", rx.text)
            }
            Request::SetLower(v) => {
                self.chamber.lower_c = v;
                format!("OK:{}", rx.text)
            }
            Request::SetMode(m) => {
                if m == Mode::Run {
                    // No program is stored in the simulator.
                    return format!("NA:{}", na::INVALID_REQ);
                }
                self.chamber.mode = m;
                self.apply_chamber_mode();
                format!("OK:{}", rx.text)
            }
            Request::Power(on) => {
                self.chamber.mode = if on { Mode::Standby } else { Mode::Off };
                self.apply_chamber_mode();
                format!("OK:{}", rx.text)
            }
        }
    }

    /// Drive the twin's air from the controller state: hold the set point
    /// at full speed in CONSTANT, drift to the room otherwise.
    pub(crate) fn apply_chamber_mode(&mut self) {
        let cfg = self.twin.config().chamber.clone();
        let (target, ramp) = match self.chamber.mode {
            Mode::Constant | Mode::Run => (self.chamber.set_point_c, cfg.max_ramp_c_per_min),
            Mode::Standby | Mode::Off => (
                cfg.initial_c,
                PASSIVE_DRIFT_C_PER_MIN.min(cfg.max_ramp_c_per_min),
            ),
        };
        // Both values are within the chamber's capability by construction.
        for t in self.twins_mut() {
            let _ = t.set_chamber(target, ramp);
        }
    }
}

/// Serve the Espec protocol on one connection until it closes.
pub async fn serve_espec<S>(stream: S, bench: Arc<SharedBench>) -> std::io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    serve_lines(
        stream,
        bench,
        |f| &f.chamber,
        MAX_LINE,
        |bench, action, line| {
            let reply = match action {
                Action::ErrorReply => "NA:CONT NOT READY-1".to_owned(),
                _ => bench.lock().espec_reply(line),
            };
            Some(reply_line(&reply))
        },
    )
    .await
}

#[cfg(test)]
mod tests {
    use crate::sim::test_bench as bench;

    #[test]
    fn answers_in_the_documented_formats() {
        let mut b = bench();
        assert_eq!(b.espec_reply("TEMP?"), "20.0,20.0,100.0,-60.0");
        assert_eq!(b.espec_reply("MON?"), "20.0,,CONSTANT,0");
        assert_eq!(b.espec_reply("MODE?"), "CONSTANT");
        assert_eq!(b.espec_reply("ALARM?"), "0");
        assert_eq!(b.espec_reply("TEMP, S-40.0"), "OK:TEMP, S-40.0");
        assert!(b.espec_reply("TEMP?").starts_with("20.0,-40.0,"));
        assert_eq!(b.espec_reply("TEMP, S900.0"), "NA:DATA OUT OF RANGE");
        assert_eq!(b.espec_reply("HELLO?"), "NA:CMD ERR");
        assert_eq!(b.espec_reply("MODE,STANDBY"), "OK:MODE,STANDBY");
        assert_eq!(b.espec_reply("MODE?"), "STANDBY");
    }

    #[test]
    fn the_air_follows_the_set_point_and_alarms_show() {
        let mut b = bench();
        b.espec_reply("TEMP, S50.0");
        b.espec_reply("TEMP, H30.0");
        b.advance_to(3600.0);
        let t = crate::protocol::espec::parse_temp(&b.espec_reply("TEMP?")).expect("valid reply");
        assert!((t.pv_c - 50.0).abs() < 0.1, "{t:?}");
        assert_eq!(b.espec_reply("ALARM?"), "1,1");
        b.raise_chamber_alarm(42);
        assert_eq!(b.espec_reply("ALARM?"), "2,42,1");
        assert!(b.espec_reply("MON?").ends_with(",2"));
    }
}
