//! Programmable DC supply driver (SCPI over a raw socket or serial).
//!
//! Every setting is followed, in the same message, by `SYST:ERR?`: a
//! setting the supply refused is never taken for done, and the error the
//! supply queued (its number and text) is what the caller sees. The error
//! queue is emptied when the driver identifies the supply.

use async_trait::async_trait;

use super::link::{LineLink, Verdict};
use super::{DeviceError, Identity, PowerSupply, SupplyReading};
use crate::protocol::scpi::{parse_bool_reply, parse_error_reply, parse_number_reply};
use crate::protocol::supply::{self, Command, Dialect};

/// Plausible readings, V and A; anything else is a fault of the link.
const PLAUSIBLE: std::ops::RangeInclusive<f64> = -1000.0..=1000.0;

/// A supply of `dialect` on a line link.
#[derive(Debug)]
pub struct ScpiSupply {
    link: LineLink,
    dialect: Dialect,
}

/// Commands in one message, each from the root (`;:`): SCPI reads a
/// header after a bare `;` from the branch of the one before, and
/// `INST:NSEL 2;VOLT 15` would be `INST:VOLT`.
fn message(cmds: &[Command], dialect: Dialect) -> Vec<u8> {
    let mut s = cmds
        .iter()
        .map(|c| c.text(dialect))
        .collect::<Vec<_>>()
        .join(";:");
    s.push('\n');
    s.into_bytes()
}

impl ScpiSupply {
    /// A driver over `link`.
    pub fn new(link: LineLink, dialect: Dialect) -> Self {
        Self { link, dialect }
    }

    /// The dialect it speaks (the tests read it).
    #[cfg(test)]
    pub fn dialect(&self) -> Dialect {
        self.dialect
    }

    /// Send settings followed by `SYST:ERR?`; an error in the queue is a
    /// refusal naming the supply's error (and any after it).
    async fn set(&mut self, cmds: &[Command]) -> Result<(), DeviceError> {
        let mut all = cmds.to_vec();
        all.push(Command::ErrorQuery);
        let first = self
            .link
            .transact(&message(&all, self.dialect), error_verdict)
            .await?;
        let Some(first) = first else {
            return Ok(());
        };
        let mut errors = vec![first];
        // The rest of the queue, so the next setting starts clean (at most
        // the queue's depth).
        for _ in 0..crate::protocol::scpi::ErrorQueue::DEPTH {
            match self
                .link
                .transact(
                    &message(&[Command::ErrorQuery], self.dialect),
                    error_verdict,
                )
                .await?
            {
                Some(e) => errors.push(e),
                None => break,
            }
        }
        Err(DeviceError::Refused {
            device: self.link.device().to_owned(),
            request: String::from_utf8_lossy(&message(cmds, self.dialect))
                .trim_end()
                .to_owned(),
            reason: errors.join("; "),
        })
    }

    /// Ask queries in one message; their answers, one per query.
    async fn ask(&mut self, cmds: &[Command]) -> Result<Vec<String>, DeviceError> {
        let n = cmds.iter().filter(|c| c.is_query()).count();
        self.link
            .transact(&message(cmds, self.dialect), move |line| {
                let v: Vec<String> = line.trim().split(';').map(str::to_owned).collect();
                if v.len() == n {
                    Verdict::Ok(v)
                } else {
                    Verdict::Malformed(format!("expected {n} answers joined by ';', got {line:?}"))
                }
            })
            .await
    }

    fn number(&self, what: &'static str, s: &str) -> Result<f64, DeviceError> {
        let v = parse_number_reply(s).ok_or_else(|| DeviceError::Malformed {
            device: self.link.device().to_owned(),
            request: what.to_owned(),
            detail: format!("{s:?} is not a number"),
            attempts: 1,
        })?;
        if PLAUSIBLE.contains(&v) {
            Ok(v)
        } else {
            Err(DeviceError::OutOfRange {
                device: self.link.device().to_owned(),
                what,
                value: v,
                range: "-1000..1000",
            })
        }
    }

    fn flag(&self, what: &'static str, s: &str) -> Result<bool, DeviceError> {
        parse_bool_reply(s).ok_or_else(|| DeviceError::Malformed {
            device: self.link.device().to_owned(),
            request: what.to_owned(),
            detail: format!("{s:?} is not 1/0, ON/OFF or YES/NO"),
            attempts: 1,
        })
    }
}

/// `SYST:ERR?`'s answer: none for no error, else `-222 Data out of range`.
fn error_verdict(line: &str) -> Verdict<Option<String>> {
    match parse_error_reply(line) {
        Some((0, _)) => Verdict::Ok(None),
        Some((code, text)) => Verdict::Ok(Some(format!("{code} {text}"))),
        None => Verdict::Malformed(format!("expected `<number>,\"<text>\"`, got {line:?}")),
    }
}

#[async_trait]
impl PowerSupply for ScpiSupply {
    fn name(&self) -> &str {
        self.link.device()
    }

    async fn identify(&mut self) -> Result<Identity, DeviceError> {
        self.link
            .send(&message(&[Command::ClearStatus], self.dialect))
            .await?;
        let idn = self.ask(&[Command::Identify]).await?;
        Ok(supply::parse_identity(&idn.join(";")))
    }

    async fn configure(
        &mut self,
        channel: u8,
        volts: f64,
        limit_a: f64,
        protection: bool,
    ) -> Result<(), DeviceError> {
        let mut cmds = vec![Command::Select(channel)];
        cmds.extend(supply::configure(self.dialect, volts, limit_a, protection));
        self.set(&cmds).await
    }

    async fn output(&mut self, channel: u8, on: bool) -> Result<(), DeviceError> {
        self.set(&[Command::Select(channel), Command::Output(on)])
            .await
    }

    async fn read(&mut self, channel: u8) -> Result<SupplyReading, DeviceError> {
        let a = self
            .ask(&[
                Command::Select(channel),
                Command::VoltageQuery,
                Command::CurrentQuery,
                Command::MeasureVoltage,
                Command::MeasureCurrent,
                Command::OutputQuery,
                Command::Tripped,
            ])
            .await?;
        Ok(SupplyReading {
            set_v: self.number("voltage setting", &a[0])?,
            limit_a: self.number("current limit", &a[1])?,
            v: self.number("measured voltage", &a[2])?,
            a: self.number("measured current", &a[3])?,
            on: self.flag("output state", &a[4])?,
            tripped: self.flag("protection state", &a[5])?,
        })
    }

    async fn clear_trip(&mut self, channel: u8) -> Result<(), DeviceError> {
        self.set(&[Command::Select(channel), Command::ClearProtection])
            .await
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use tokio_test::io::Builder;

    use super::*;
    use crate::driver::RetryPolicy;

    fn driver(mock: tokio_test::io::Mock, dialect: Dialect) -> ScpiSupply {
        let policy = RetryPolicy {
            timeout: Duration::from_millis(200),
            attempts: 1,
            reconnect_window: Duration::ZERO,
        };
        ScpiSupply::new(
            LineLink::new("supply", Box::new(mock), None, policy),
            dialect,
        )
    }

    #[tokio::test]
    async fn every_setting_reads_the_error_queue_in_the_same_message() {
        let mock = Builder::new()
            .write(b"INST:NSEL 2;:VOLT 15.0000;:CURR 1.0000;:CURR:PROT:STAT ON;:SYST:ERR?\n")
            .read(b"+0,\"No error\"\n")
            .write(b"INST:NSEL 2;:OUTP ON;:SYST:ERR?\n")
            .read(b"0,\"No error\"\n")
            .build();
        let mut s = driver(mock, Dialect::KeysightE36300);
        s.configure(2, 15.0, 1.0, true).await.expect("accepted");
        s.output(2, true).await.expect("accepted");
    }

    #[tokio::test]
    async fn a_refused_setting_names_the_supply_s_errors() {
        let mock = Builder::new()
            .write(b"INST:NSEL 1;:VOLT 30.0000;:CURR 1.0000;:CURR:PROT 1.0000;:CURR:PROT:STAT OFF;:SYST:ERR?\n")
            .read(b"-222,\"Data out of range\"\n")
            .write(b"SYST:ERR?\n")
            .read(b"0,\"No error\"\n")
            .build();
        let mut s = driver(mock, Dialect::RigolDp800);
        let e = s.configure(1, 30.0, 1.0, false).await.expect_err("refused");
        let text = e.to_string();
        assert!(text.contains("-222 Data out of range"), "{text}");
        assert!(text.contains("VOLT 30.0000"), "{text}");
    }

    #[tokio::test]
    async fn a_reading_understands_both_makers_words() {
        let mock = Builder::new()
            .write(b"INST:NSEL 2;:VOLT?;:CURR?;:MEAS:VOLT?;:MEAS:CURR?;:OUTP?;:CURR:PROT:TRIP?\n")
            .read(b"15.0000;1.0000;14.9990;0.5500;ON;NO\n")
            .build();
        let mut s = driver(mock, Dialect::RigolDp800);
        let r = s.read(2).await.expect("a reading");
        assert_eq!(
            r,
            SupplyReading {
                set_v: 15.0,
                limit_a: 1.0,
                v: 14.999,
                a: 0.55,
                on: true,
                tripped: false
            }
        );
    }
}
