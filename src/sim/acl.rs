//! The two-axis motion simulator speaking the ACL command language.

use std::sync::Arc;

use tokio::io::{AsyncRead, AsyncWrite};

use super::faults::Action;
use super::lines::serve_lines;
use super::{SharedBench, SimBench};
use crate::protocol::acl::{Axis, Command, ServoMode, parse_message, stb};
use crate::protocol::scpi::{NO_ERROR, ScpiError};
use crate::twin::AxisDemand;

/// Longest message accepted, bytes.
pub const MAX_LINE: usize = 1024;
/// Depth of the error queue (older errors are dropped, as SCPI does).
pub const ERROR_QUEUE_DEPTH: usize = 16;

fn idx(a: Axis) -> usize {
    match a {
        Axis::Outer => 0,
        Axis::Inner => 1,
    }
}

impl SimBench {
    fn acl_error(&mut self, e: ScpiError) {
        if self.table.errors.len() >= ERROR_QUEUE_DEPTH {
            self.table.errors.pop_front();
        }
        self.table.errors.push_back(e);
    }

    fn demand(&mut self, a: Axis, d: AxisDemand) {
        match a {
            Axis::Outer => self.demand_table(Some(d), None),
            Axis::Inner => self.demand_table(None, Some(d)),
        }
    }

    /// Execute one ACL message; the reply (query answers joined with `;`),
    /// if the message held queries.
    pub fn acl_message(&mut self, line: &str) -> Option<String> {
        let mut answers = Vec::new();
        for cmd in parse_message(line) {
            match cmd {
                Ok(c) => {
                    if let Some(a) = self.acl_command(c) {
                        answers.push(a);
                    }
                }
                Err(e) => self.acl_error(e),
            }
        }
        (!answers.is_empty()).then(|| answers.join(";"))
    }

    fn acl_command(&mut self, c: Command) -> Option<String> {
        let t = &self.table;
        let ready = |a: Axis| t.closed[idx(a)] && !t.tripped;
        match c {
            Command::Mode(a, m) => {
                if !ready(a) {
                    self.acl_error(ScpiError::SETTINGS_CONFLICT);
                    return None;
                }
                self.table.mode[idx(a)] = m;
                let pos = self.twin.axis(a == Axis::Inner).pos_deg;
                let d = match m {
                    ServoMode::Position => AxisDemand::Position(pos),
                    ServoMode::Rate => AxisDemand::Rate(0.0),
                    ServoMode::Stop => AxisDemand::Stop,
                };
                self.demand(a, d);
            }
            Command::DemandPosition(a, deg) => {
                if !ready(a) || t.mode[idx(a)] != ServoMode::Position {
                    self.acl_error(ScpiError::SETTINGS_CONFLICT);
                } else {
                    self.demand(a, AxisDemand::Position(deg));
                }
            }
            Command::DemandRate(a, r) => {
                let limit = self.twin.axis(a == Axis::Inner).rate_mode_limits().0;
                if !ready(a) || t.mode[idx(a)] != ServoMode::Rate {
                    self.acl_error(ScpiError::SETTINGS_CONFLICT);
                } else if r.abs() > limit {
                    self.acl_error(ScpiError::OUT_OF_RANGE);
                } else {
                    self.demand(a, AxisDemand::Rate(r));
                }
            }
            Command::ReadPosition(a) => {
                return Some(format!("{:.4}", self.twin.axis(a == Axis::Inner).pos_deg));
            }
            Command::ReadRate(a) => {
                return Some(format!("{:.4}", self.twin.axis(a == Axis::Inner).rate_dps));
            }
            Command::LimitRate(a, v) | Command::LimitAcc(a, v) => {
                let cfg = &self.twin.config().table;
                let (rate, acc) = self.twin.axis(a == Axis::Inner).limits();
                let (new, max) = match c {
                    Command::LimitRate(..) => ((v, acc), cfg.max_rate_dps),
                    _ => ((rate, v), cfg.max_acc_dps2),
                };
                if !(v > 0.0 && v <= max) {
                    self.acl_error(ScpiError::OUT_OF_RANGE);
                } else {
                    for t in self.twins_mut() {
                        t.set_axis_limits(a == Axis::Inner, new.0, new.1);
                    }
                }
            }
            Command::InterlockClose(a) => {
                if t.tripped {
                    self.acl_error(ScpiError::SETTINGS_CONFLICT);
                } else {
                    self.table.closed[idx(a)] = true;
                    self.table.mode[idx(a)] = ServoMode::Position;
                    let pos = self.twin.axis(a == Axis::Inner).pos_deg;
                    self.demand(a, AxisDemand::Position(pos));
                }
            }
            Command::InterlockOpen(a) => {
                self.demand(a, AxisDemand::Stop);
                self.table.closed[idx(a)] = false;
            }
            Command::InterlockReset => self.table.tripped = false,
            Command::StatusByte => {
                let mut s = 0u8;
                if self.table.tripped {
                    s |= stb::INTERLOCK;
                }
                if !self.table.errors.is_empty() {
                    s |= stb::ERROR_QUEUE;
                }
                return Some(s.to_string());
            }
            Command::Identify => return Some(super::identity::ACL_IDN.into()),
            Command::ClearStatus => self.table.errors.clear(),
            Command::ErrorQuery => {
                return Some(
                    self.table
                        .errors
                        .pop_front()
                        .map_or_else(|| NO_ERROR.to_owned(), |e| e.reply()),
                );
            }
        }
        None
    }
}

/// Serve the ACL language on one connection until it closes.
pub async fn serve_acl<S>(stream: S, bench: Arc<SharedBench>) -> std::io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    serve_lines(
        stream,
        bench,
        |f| &f.table,
        MAX_LINE,
        |bench, action, line| {
            let mut b = bench.lock();
            if action == Action::ErrorReply {
                // The instrument reports errors through its queue, never inline.
                b.acl_error(ScpiError::SETTINGS_CONFLICT);
            }
            b.acl_message(line)
                .map(|text| format!("{text}\n").into_bytes())
        },
    )
    .await
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::test_bench as bench;

    #[test]
    fn moves_with_its_limits_and_reports_position() {
        let mut b = bench();
        assert_eq!(
            b.acl_message(":R:P? 1;:R:P? 2").as_deref(),
            Some("90.0000;0.0000")
        );
        assert_eq!(b.acl_message(":M:P 1;:D:P 1,0"), None);
        b.advance_to(1.0);
        let mid: f64 = b
            .acl_message(":R:P? 1")
            .and_then(|s| s.parse().ok())
            .expect("number");
        assert!(mid < 90.0 && mid > 80.0, "{mid}");
        b.advance_to(30.0);
        assert_eq!(
            b.acl_message(":R:P? 1;:R:R? 1").as_deref(),
            Some("0.0000;0.0000")
        );
    }

    #[test]
    fn errors_go_to_the_queue_not_inline() {
        let mut b = bench();
        assert_eq!(b.acl_message(":NONSENSE 1"), None);
        assert_eq!(
            b.acl_message(":D:R 1,5"),
            None,
            "rate demand in position mode"
        );
        assert_eq!(b.acl_message("*STB?").as_deref(), Some("4"));
        assert_eq!(
            b.acl_message(":SYST:ERR?").as_deref(),
            Some("-113,\"Undefined header\"")
        );
        assert_eq!(
            b.acl_message(":SYST:ERR?").as_deref(),
            Some("-221,\"Settings conflict\"")
        );
        assert_eq!(b.acl_message(":SYST:ERR?").as_deref(), Some(NO_ERROR));
        // Rate mode turns up to its own limit (500 deg/s on the RL-16
        // bench), far beyond the positioning profile, and refuses more.
        b.acl_message(":M:R 2");
        b.acl_message(":D:R 2,500");
        assert_eq!(b.acl_message(":SYST:ERR?").as_deref(), Some(NO_ERROR));
        b.acl_message(":D:R 2,500.5");
        assert_eq!(
            b.acl_message(":SYST:ERR?").as_deref(),
            Some("-222,\"Data out of range\"")
        );
    }

    #[test]
    fn interlock_trip_stops_the_table_until_reset() {
        let mut b = bench();
        b.acl_message(":M:R 2;:D:R 2,10");
        b.advance_to(5.0);
        b.trip_interlock();
        assert_eq!(b.acl_message("*STB?").as_deref(), Some("1"));
        b.advance_to(10.0);
        assert_eq!(b.acl_message(":R:R? 2").as_deref(), Some("0.0000"));
        b.acl_message(":INT:CLOSE 2");
        assert_eq!(
            b.acl_message("*STB?").as_deref(),
            Some("5"),
            "close refused while tripped"
        );
        b.acl_message("*CLS;:INT:RESET;:INT:CLOSE 2");
        assert_eq!(b.acl_message("*STB?").as_deref(), Some("0"));
    }
}
