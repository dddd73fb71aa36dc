//! Two-axis motion simulator driver (ACL language over serial or TCP).
//!
//! Set commands have no reply; after each, the driver reads the status byte
//! and, when the error queue holds something, the error, so that a refused
//! demand is never taken for done.

use async_trait::async_trait;

use super::link::{LineLink, Verdict};
use super::{DeviceError, Identity, MotionTable, TableReading};
use crate::geometry::TableAngles;
use crate::protocol::acl::{self, Axis, Command, ServoMode, stb};

/// An ACL motion simulator on a line link.
#[derive(Debug)]
pub struct AclTable {
    link: LineLink,
}

impl AclTable {
    /// A driver over `link`.
    pub fn new(link: LineLink) -> Self {
        Self { link }
    }

    async fn numbers(&mut self, cmds: &[Command]) -> Result<Vec<f64>, DeviceError> {
        let n = cmds.len();
        self.link
            .transact(&acl::encode(cmds), move |line| {
                match acl::parse_numbers(line, n) {
                    Some(v) => Verdict::Ok(v),
                    None => Verdict::Malformed(format!(
                        "expected {n} numbers joined by ';', got {line:?}"
                    )),
                }
            })
            .await
    }

    /// Send commands, then check the status byte and error queue.
    pub async fn command(&mut self, cmds: &[Command]) -> Result<(), DeviceError> {
        self.link.send(&acl::encode(cmds)).await?;
        let status = self.numbers(&[Command::StatusByte]).await?[0] as u8;
        if status & stb::INTERLOCK != 0 {
            return Err(DeviceError::Interlock {
                device: self.link.device().to_owned(),
            });
        }
        if status & stb::ERROR_QUEUE != 0 {
            let err = self
                .link
                .transact(&acl::encode(&[Command::ErrorQuery]), |l| {
                    Verdict::Ok(l.to_owned())
                })
                .await?;
            return Err(DeviceError::Refused {
                device: self.link.device().to_owned(),
                request: String::from_utf8_lossy(&acl::encode(cmds))
                    .trim_end()
                    .to_owned(),
                reason: err,
            });
        }
        Ok(())
    }

    /// Close both interlocks (servo on), after resetting a tripped system.
    pub async fn servo_on(&mut self) -> Result<(), DeviceError> {
        self.command(&[
            Command::ClearStatus,
            Command::InterlockReset,
            Command::InterlockClose(Axis::Outer),
            Command::InterlockClose(Axis::Inner),
        ])
        .await
    }
}

#[async_trait]
impl MotionTable for AclTable {
    fn name(&self) -> &str {
        self.link.device()
    }

    async fn read(&mut self) -> Result<TableReading, DeviceError> {
        let v = self
            .numbers(&[
                Command::ReadPosition(Axis::Outer),
                Command::ReadPosition(Axis::Inner),
                Command::ReadRate(Axis::Outer),
                Command::ReadRate(Axis::Inner),
            ])
            .await?;
        Ok(TableReading {
            angles: TableAngles {
                outer_deg: v[0],
                inner_deg: v[1],
            },
            rates: TableAngles {
                outer_deg: v[2],
                inner_deg: v[3],
            },
        })
    }

    async fn move_to(&mut self, a: TableAngles) -> Result<(), DeviceError> {
        self.command(&[
            Command::Mode(Axis::Outer, ServoMode::Position),
            Command::Mode(Axis::Inner, ServoMode::Position),
            Command::DemandPosition(Axis::Outer, a.outer_deg),
            Command::DemandPosition(Axis::Inner, a.inner_deg),
        ])
        .await
    }

    async fn rate(&mut self, inner: bool, rate_dps: f64) -> Result<(), DeviceError> {
        let ax = if inner { Axis::Inner } else { Axis::Outer };
        self.command(&[
            Command::Mode(ax, ServoMode::Rate),
            Command::DemandRate(ax, rate_dps),
        ])
        .await
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        self.command(&[
            Command::Mode(Axis::Outer, ServoMode::Stop),
            Command::Mode(Axis::Inner, ServoMode::Stop),
        ])
        .await
    }

    async fn identify(&mut self) -> Result<Identity, DeviceError> {
        let reply = self
            .link
            .transact(&acl::encode(&[Command::Identify]), |l| {
                Verdict::Ok(l.to_owned())
            })
            .await?;
        Ok(acl::parse_identity(&reply))
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use tokio_test::io::Builder;

    use super::*;
    use crate::driver::RetryPolicy;

    fn driver(mock: tokio_test::io::Mock) -> AclTable {
        let policy = RetryPolicy {
            timeout: Duration::from_millis(200),
            attempts: 1,
            reconnect_window: Duration::ZERO,
        };
        AclTable::new(LineLink::new("table", Box::new(mock), None, policy))
    }

    #[tokio::test]
    async fn exact_bytes_of_a_move_and_a_read() {
        let mock = Builder::new()
            .write(b":M:P 1;:M:P 2;:D:P 1,90.0000;:D:P 2,180.0000\n")
            .write(b"*STB?\n")
            .read(b"0\n")
            .write(b":R:P? 1;:R:P? 2;:R:R? 1;:R:R? 2\n")
            .read(b"45.5000;180.0000;10.0000;0.0000\n")
            .build();
        let mut d = driver(mock);
        d.move_to(TableAngles {
            outer_deg: 90.0,
            inner_deg: 180.0,
        })
        .await
        .expect("move accepted");
        let r = d.read().await.expect("reading");
        assert_eq!(r.angles.outer_deg, 45.5);
        assert_eq!(r.rates.outer_deg, 10.0);
    }

    #[tokio::test]
    async fn a_refused_demand_surfaces_the_queued_error() {
        let mock = Builder::new()
            .write(b":M:R 2;:D:R 2,900.000000\n")
            .write(b"*STB?\n")
            .read(b"4\n")
            .write(b":SYST:ERR?\n")
            .read(b"-222,\"Data out of range\"\n")
            .build();
        let err = driver(mock).rate(true, 900.0).await.expect_err("refused");
        assert!(
            err.to_string().contains("-222,\"Data out of range\""),
            "{err}"
        );
    }

    #[tokio::test]
    async fn a_tripped_interlock_is_an_interlock_error() {
        let mock = Builder::new()
            .write(b":M:O 1;:M:O 2\n")
            .write(b"*STB?\n")
            .read(b"1\n")
            .build();
        let err = driver(mock).stop().await.expect_err("tripped");
        assert!(matches!(err, DeviceError::Interlock { .. }));
    }
}
