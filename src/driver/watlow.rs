//! Watlow F4T chamber driver over Modbus TCP (tokio-modbus client).
//!
//! The F4T's constant set point has no ramp of its own here: ramps are made
//! by the caller stepping the set point (see the sequencer).

use async_trait::async_trait;
use tokio_modbus::client::{Context, Reader, Writer};
use tokio_modbus::{ExceptionCode, Slave};

use super::link::{Attempts, Connector, LinkCounters, LinkWatch, Try, open_once};
use super::{Chamber, ChamberMode, ChamberReading, DeviceError, Identity, RetryPolicy};
use crate::protocol::watlow::{self as w, decode_f32, encode_f32, mode};
use crate::transport::BoxTransport;

/// One Modbus operation.
#[derive(Debug, Clone)]
enum Op {
    Read(u16, u16),
    Write(u16, Vec<u16>),
}

impl std::fmt::Display for Op {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Op::Read(a, n) => write!(f, "read {n} registers at {a}"),
            Op::Write(a, v) => write!(f, "write {v:?} at {a}"),
        }
    }
}

/// An F4T on a Modbus TCP connection.
pub struct WatlowChamber {
    device: String,
    ctx: Option<Context>,
    connector: Option<Connector>,
    policy: RetryPolicy,
    counters: LinkCounters,
    watch: Option<std::sync::Arc<LinkWatch>>,
}

impl std::fmt::Debug for WatlowChamber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WatlowChamber")
            .field("device", &self.device)
            .field("counters", &self.counters)
            .finish_non_exhaustive()
    }
}

impl WatlowChamber {
    /// A driver over an open transport; `connector` reopens it after a drop.
    pub fn new(
        device: &str,
        transport: BoxTransport,
        connector: Option<Connector>,
        policy: RetryPolicy,
    ) -> Self {
        Self {
            device: device.to_owned(),
            ctx: Some(tokio_modbus::client::tcp::attach_slave(transport, Slave(1))),
            connector,
            policy,
            counters: LinkCounters::default(),
            watch: None,
        }
    }

    /// Tell the bench's `watch` of drops, returns and a loss.
    pub fn with_watch(mut self, watch: std::sync::Arc<LinkWatch>) -> Self {
        self.watch = Some(watch);
        self
    }

    /// Transient trouble so far (the tests read it).
    #[cfg(test)]
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    async fn op(&mut self, op: Op) -> Result<Vec<u16>, DeviceError> {
        let request = op.to_string();
        let device = self.device.clone();
        let policy = self.policy;
        let mut a = Attempts::new(&device, &policy).watched(self.watch.clone());
        while a.left() {
            if a.retrying() {
                self.counters.retries += 1;
            }
            let t = self.try_once(&op, &mut a).await?;
            if let Some(words) = a.judge(t, &request).await? {
                return Ok(words);
            }
        }
        Err(a.spent(request))
    }

    /// One try of `op` on the Modbus session, reopened first if it was
    /// dropped (a broken or late session is dropped: the next try opens a
    /// fresh one).
    async fn try_once(
        &mut self,
        op: &Op,
        a: &mut Attempts<'_>,
    ) -> Result<Try<Vec<u16>>, DeviceError> {
        if self.ctx.is_none() {
            match open_once(&self.device, self.connector.as_ref()).await? {
                Ok(t) => {
                    a.drops.reopened(&self.device);
                    self.counters.reconnects += 1;
                    self.ctx = Some(tokio_modbus::client::tcp::attach_slave(t, Slave(1)));
                }
                // Not reopened: a drop to wait out, like a broken session.
                Err(e) => return Ok(Try::Broken(e)),
            }
        }
        let Some(ctx) = self.ctx.as_mut() else {
            return Ok(Try::Late);
        };
        let call = async {
            match op {
                Op::Read(a, n) => ctx.read_holding_registers(*a, *n).await,
                Op::Write(a, v) if v.len() == 1 => ctx
                    .write_single_register(*a, v[0])
                    .await
                    .map(|r| r.map(|()| Vec::new())),
                Op::Write(a, v) => ctx
                    .write_multiple_registers(*a, v)
                    .await
                    .map(|r| r.map(|()| Vec::new())),
            }
        };
        Ok(
            match tokio::time::timeout(self.policy.timeout, call).await {
                Ok(Ok(Ok(words))) => Try::Done(words),
                Ok(Ok(Err(ExceptionCode::ServerDeviceBusy | ExceptionCode::Acknowledge))) => {
                    Try::Again(None)
                }
                Ok(Ok(Err(e))) => Try::Refused(format!("Modbus exception {e:?}")),
                // A broken session is reopened (with backoff, within the
                // reconnect window); a late one too, and counts as an attempt.
                Ok(Err(e)) => {
                    self.ctx = None;
                    Try::Broken(std::io::Error::other(e))
                }
                Err(_) => {
                    self.ctx = None;
                    Try::Late
                }
            },
        )
    }

    async fn read_f32(&mut self, addr: u16, what: &'static str) -> Result<f64, DeviceError> {
        let words = self.op(Op::Read(addr, 2)).await?;
        let v = decode_f32(&words).map(f64::from);
        match v {
            Some(v) if super::espec::PLAUSIBLE_C.contains(&v) => Ok(v),
            _ => Err(DeviceError::OutOfRange {
                device: self.device.clone(),
                what,
                value: v.unwrap_or(f64::NAN),
                range: "-100..300 degC, finite float32",
            }),
        }
    }
}

#[async_trait]
impl Chamber for WatlowChamber {
    fn name(&self) -> &str {
        &self.device
    }

    async fn read(&mut self) -> Result<ChamberReading, DeviceError> {
        let air_c = self.read_f32(w::PV, "process value").await?;
        let set_point_c = self.read_f32(w::SET_POINT, "set point").await?;
        let m = self.op(Op::Read(w::CONTROL_MODE, 1)).await?;
        // The F4T has no standby: a loop that is off (or in open-loop
        // manual) is not controlling, which is what standby means here.
        let mode = match m.first().copied() {
            Some(mode::AUTO) => ChamberMode::Constant,
            Some(mode::OFF | mode::MANUAL) => ChamberMode::Standby,
            other => {
                return Err(DeviceError::OutOfRange {
                    device: self.device.clone(),
                    what: "control mode",
                    value: other.map_or(f64::NAN, f64::from),
                    range: "62 off, 10 auto, 54 manual",
                });
            }
        };
        Ok(ChamberReading {
            air_c,
            set_point_c,
            mode,
            alarms: Vec::new(),
        })
    }

    async fn set_point(&mut self, temp_c: f64) -> Result<(), DeviceError> {
        self.op(Op::Write(w::SET_POINT, encode_f32(temp_c as f32).to_vec()))
            .await
            .map(drop)
    }

    async fn set_mode(&mut self, m: ChamberMode) -> Result<(), DeviceError> {
        let v = match m {
            ChamberMode::Off | ChamberMode::Standby => mode::OFF,
            ChamberMode::Constant => mode::AUTO,
        };
        self.op(Op::Write(w::CONTROL_MODE, vec![v])).await.map(drop)
    }

    async fn identify(&mut self) -> Result<Identity, DeviceError> {
        let words = self
            .op(Op::Read(w::PART_NUMBER, w::PART_NUMBER_LEN))
            .await?;
        Ok(w::parse_identity(&words))
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use tokio_test::io::Builder;

    use super::*;

    /// MBAP header + PDU of a request or response.
    fn adu(tid: u16, pdu: &[u8]) -> Vec<u8> {
        let mut v = tid.to_be_bytes().to_vec();
        v.extend_from_slice(&[0, 0]);
        v.extend_from_slice(&(pdu.len() as u16 + 1).to_be_bytes());
        v.push(1);
        v.extend_from_slice(pdu);
        v
    }

    #[tokio::test]
    async fn exact_bytes_of_reading_the_process_value_and_writing_the_set_point() {
        // PV 20.0 = 0x41A00000: registers [0x0000, 0x41A0], low word first.
        let mock = Builder::new()
            .write(&adu(0, &[0x03, 0x0B, 0x04, 0x00, 0x02]))
            .read(&adu(0, &[0x03, 0x04, 0x00, 0x00, 0x41, 0xA0]))
            .write(&adu(
                1,
                &[0x10, 0x0A, 0xDE, 0x00, 0x02, 0x04, 0x00, 0x00, 0xC2, 0x20],
            ))
            .read(&adu(1, &[0x10, 0x0A, 0xDE, 0x00, 0x02]))
            .build();
        let policy = RetryPolicy {
            timeout: Duration::from_millis(500),
            attempts: 1,
            reconnect_window: Duration::ZERO,
        };
        let mut c = WatlowChamber::new("chamber", Box::new(mock), None, policy);
        assert_eq!(c.read_f32(w::PV, "process value").await.expect("PV"), 20.0);
        // -40.0 = 0xC2200000.
        c.set_point(-40.0).await.expect("set point written");
    }
}
