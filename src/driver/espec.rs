//! Espec P300 / SCP-220 chamber driver (ASCII over serial or TCP).

use async_trait::async_trait;

use super::link::{LineLink, Verdict};
use super::{Chamber, ChamberMode, ChamberReading, DeviceError, Identity};
use crate::protocol::espec::{self, Mode, ReplyError, Request};

/// Plausible chamber air temperatures, degC; anything else is a fault.
pub const PLAUSIBLE_C: std::ops::RangeInclusive<f64> = -100.0..=300.0;

/// An Espec controller on a line link.
#[derive(Debug)]
pub struct EspecChamber {
    link: LineLink,
    address: Option<u8>,
}

fn verdict<T>(r: Result<T, ReplyError>) -> Verdict<T> {
    match r {
        Ok(v) => Verdict::Ok(v),
        Err(ReplyError::Refused(reason)) => Verdict::Refused(format!("NA:{reason}")),
        Err(e @ ReplyError::Malformed { .. }) => Verdict::Malformed(e.to_string()),
    }
}

impl EspecChamber {
    /// A driver over `link`; `address` for RS-485 multidrop.
    pub fn new(link: LineLink, address: Option<u8>) -> Self {
        Self { link, address }
    }

    /// The link (for its counters, which the tests read).
    #[cfg(test)]
    pub fn link(&self) -> &LineLink {
        &self.link
    }

    async fn ask<T>(
        &mut self,
        req: Request,
        parse: fn(&str) -> Result<T, ReplyError>,
    ) -> Result<T, DeviceError> {
        let bytes = req.encode(self.address);
        self.link
            .transact(&bytes, |line| verdict(parse(line)))
            .await
    }

    async fn set(&mut self, req: Request) -> Result<(), DeviceError> {
        let bytes = req.encode(self.address);
        let r = req.clone();
        self.link
            .transact(&bytes, move |line| verdict(espec::parse_ack(&r, line)))
            .await
    }

    fn check_temp(&self, what: &'static str, value: f64) -> Result<f64, DeviceError> {
        if PLAUSIBLE_C.contains(&value) {
            Ok(value)
        } else {
            Err(DeviceError::OutOfRange {
                device: self.link.device().to_owned(),
                what,
                value,
                range: "-100..300 degC",
            })
        }
    }
}

#[async_trait]
impl Chamber for EspecChamber {
    fn name(&self) -> &str {
        self.link.device()
    }

    async fn read(&mut self) -> Result<ChamberReading, DeviceError> {
        let t = self.ask(Request::Temp, espec::parse_temp).await?;
        let mon = self.ask(Request::Mon, espec::parse_mon).await?;
        let alarms = if mon.alarms > 0 {
            self.ask(Request::Alarm, espec::parse_alarm).await?
        } else {
            Vec::new()
        };
        Ok(ChamberReading {
            air_c: self.check_temp("air temperature", t.pv_c)?,
            set_point_c: self.check_temp("set point", t.sp_c)?,
            mode: match mon.mode {
                Mode::Off => ChamberMode::Off,
                Mode::Standby => ChamberMode::Standby,
                Mode::Constant | Mode::Run => ChamberMode::Constant,
            },
            alarms,
        })
    }

    async fn set_point(&mut self, temp_c: f64) -> Result<(), DeviceError> {
        self.set(Request::SetTemp(temp_c)).await
    }

    async fn set_mode(&mut self, mode: ChamberMode) -> Result<(), DeviceError> {
        self.set(Request::SetMode(match mode {
            ChamberMode::Off => Mode::Off,
            ChamberMode::Standby => Mode::Standby,
            ChamberMode::Constant => Mode::Constant,
        }))
        .await
    }

    async fn identify(&mut self) -> Result<Identity, DeviceError> {
        let kind = self.ask(Request::Type, espec::parse_text).await?;
        let rom = self.ask(Request::Rom, espec::parse_text).await?;
        Ok(espec::parse_identity(&kind, &rom))
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use tokio_test::io::Builder;

    use super::*;
    use crate::driver::RetryPolicy;

    fn driver(mock: tokio_test::io::Mock, attempts: u32) -> EspecChamber {
        let policy = RetryPolicy {
            timeout: Duration::from_millis(200),
            attempts,
            reconnect_window: Duration::ZERO,
        };
        EspecChamber::new(LineLink::new("chamber", Box::new(mock), None, policy), None)
    }

    #[tokio::test]
    async fn exact_bytes_of_a_reading() {
        let mock = Builder::new()
            .write(b"TEMP?\r\n")
            .read(b"23.5,25.0,100.0,-45.0\r\n")
            .write(b"MON?\r\n")
            .read(b"23.5,,CONSTANT,1\r\n")
            .write(b"ALARM?\r\n")
            .read(b"1,7\r\n")
            .build();
        let r = driver(mock, 1).read().await.expect("reading");
        assert_eq!(
            r,
            ChamberReading {
                air_c: 23.5,
                set_point_c: 25.0,
                mode: ChamberMode::Constant,
                alarms: vec![7]
            }
        );
    }

    #[tokio::test]
    async fn exact_bytes_of_set_commands() {
        let mock = Builder::new()
            .write(b"TEMP, S-40.0\r\n")
            .read(b"OK:TEMP, S-40.0\r\n")
            .write(b"MODE,STANDBY\r\n")
            .read(b"OK:MODE,STANDBY\r\n")
            .build();
        let mut d = driver(mock, 1);
        d.set_point(-40.0).await.expect("set point");
        d.set_mode(ChamberMode::Standby).await.expect("mode");
    }

    #[tokio::test]
    async fn a_garbled_reply_is_retried_then_accepted() {
        let mock = Builder::new()
            .write(b"TEMP, S25.0\r\n")
            .read(b"O?:TEMP, S25.0\r\n")
            .write(b"TEMP, S25.0\r\n")
            .read(b"OK:TEMP, S25.0\r\n")
            .build();
        let mut d = driver(mock, 2);
        d.set_point(25.0).await.expect("second attempt succeeds");
        assert_eq!(d.link().counters().retries, 1);
    }

    #[tokio::test]
    async fn refusal_is_not_retried_and_names_the_device() {
        let mock = Builder::new()
            .write(b"TEMP, S200.0\r\n")
            .read(b"NA:DATA OUT OF RANGE\r\n")
            .build();
        let err = driver(mock, 3).set_point(200.0).await.expect_err("refused");
        let msg = err.to_string();
        assert!(
            msg.starts_with("chamber: refused `TEMP, S200.0`: NA:DATA OUT OF RANGE"),
            "{msg}"
        );
    }

    #[tokio::test]
    async fn an_implausible_temperature_is_an_error() {
        let mock = Builder::new()
            .write(b"TEMP?\r\n")
            .read(b"999.0,25.0,100.0,-45.0\r\n")
            .write(b"MON?\r\n")
            .read(b"999.0,,CONSTANT,0\r\n")
            .build();
        let err = driver(mock, 1).read().await.expect_err("out of range");
        assert!(
            matches!(err, DeviceError::OutOfRange { value: 999.0, .. }),
            "{err}"
        );
    }
}
