//! The Watlow F4T chamber controller as a Modbus TCP server (tokio-modbus).
//!
//! Faults: no reply (the request is swallowed and the client times out)
//! and error replies (Modbus exception "server device busy").

use std::future::{Ready, ready};
use std::sync::Arc;

use tokio_modbus::{ExceptionCode, Request, Response};

use super::faults::Action;
use super::{SharedBench, SimBench};
use crate::protocol::espec::Mode;
use crate::protocol::watlow::{self as w, encode_f32, mode, profile};

impl SimBench {
    fn watlow_register(&self, addr: u16) -> Option<u16> {
        let (air, _, working) = self.twin.chamber_state();
        let cfg = &self.twin.config().chamber;
        let float = |base: u16, v: f64| -> Option<u16> {
            (addr == base || addr == base + 1)
                .then(|| encode_f32(v as f32)[usize::from(addr - base)])
        };
        float(w::PV, air)
            .or_else(|| float(w::SET_POINT, self.chamber.set_point_c))
            .or_else(|| float(w::CURRENT_SET_POINT, working))
            .or_else(|| float(w::SP_RANGE_LOW, cfg.min_c))
            .or_else(|| float(w::SP_RANGE_HIGH, cfg.max_c))
            .or_else(|| {
                (addr == w::CONTROL_MODE).then_some(match self.chamber.mode {
                    Mode::Constant | Mode::Run => mode::AUTO,
                    Mode::Standby | Mode::Off => mode::OFF,
                })
            })
            .or_else(|| (addr == w::PROFILE_STATE).then_some(profile::OFF))
            .or_else(|| {
                let i = addr.checked_sub(w::PART_NUMBER)?;
                (i < w::PART_NUMBER_LEN).then(|| {
                    w::encode_string(
                        super::identity::WATLOW_PART_NUMBER,
                        usize::from(w::PART_NUMBER_LEN),
                    )[usize::from(i)]
                })
            })
    }

    /// Read `count` holding registers from `addr`.
    pub fn watlow_read(&self, addr: u16, count: u16) -> Result<Vec<u16>, ExceptionCode> {
        if count == 0 || count > 125 {
            return Err(ExceptionCode::IllegalDataValue);
        }
        (0..count)
            .map(|i| {
                addr.checked_add(i)
                    .and_then(|a| self.watlow_register(a))
                    .ok_or(ExceptionCode::IllegalDataAddress)
            })
            .collect()
    }

    /// Write holding registers from `addr`.
    pub fn watlow_write(&mut self, addr: u16, words: &[u16]) -> Result<(), ExceptionCode> {
        match (addr, words) {
            (w::SET_POINT, [_, _]) => {
                let v = f64::from(w::decode_f32(words).ok_or(ExceptionCode::IllegalDataValue)?);
                let cfg = &self.twin.config().chamber;
                if !(cfg.min_c..=cfg.max_c).contains(&v) {
                    return Err(ExceptionCode::IllegalDataValue);
                }
                self.chamber.set_point_c = v;
                self.apply_chamber_mode();
                Ok(())
            }
            (w::CONTROL_MODE, [m]) => {
                self.chamber.mode = match *m {
                    mode::AUTO => Mode::Constant,
                    mode::OFF => Mode::Off,
                    mode::MANUAL => Mode::Standby,
                    _ => return Err(ExceptionCode::IllegalDataValue),
                };
                self.apply_chamber_mode();
                Ok(())
            }
            _ if self.watlow_register(addr).is_some() => Err(ExceptionCode::IllegalFunction),
            _ => Err(ExceptionCode::IllegalDataAddress),
        }
    }
}

/// One Modbus connection's view of the bench.
#[derive(Debug, Clone)]
pub struct WatlowService {
    bench: Arc<SharedBench>,
}

impl WatlowService {
    /// Serve `bench`.
    pub fn new(bench: Arc<SharedBench>) -> Self {
        Self { bench }
    }

    fn answer(&self, req: Request<'static>) -> Result<Option<Response>, ExceptionCode> {
        match self.bench.faults.chamber.next_action() {
            Action::NoReply | Action::Disconnect => return Ok(None),
            Action::ErrorReply => return Err(ExceptionCode::ServerDeviceBusy),
            Action::Normal | Action::Garble => {}
        }
        let mut b = self.bench.lock();
        let resp = match req {
            Request::ReadHoldingRegisters(a, n) => {
                Response::ReadHoldingRegisters(b.watlow_read(a, n)?)
            }
            Request::WriteSingleRegister(a, v) => {
                b.watlow_write(a, &[v])?;
                Response::WriteSingleRegister(a, v)
            }
            Request::WriteMultipleRegisters(a, words) => {
                b.watlow_write(a, &words)?;
                Response::WriteMultipleRegisters(a, words.len() as u16)
            }
            _ => return Err(ExceptionCode::IllegalFunction),
        };
        Ok(Some(resp))
    }
}

impl tokio_modbus::server::Service for WatlowService {
    type Request = Request<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = Ready<Result<Self::Response, Self::Exception>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        ready(self.answer(req))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::test_bench;

    #[test]
    fn registers_hold_the_chamber_state() {
        let mut b = test_bench();
        let pv = b.watlow_read(w::PV, 2).expect("readable");
        assert_eq!(w::decode_f32(&pv), Some(20.0));
        b.watlow_write(w::SET_POINT, &encode_f32(-40.0))
            .expect("writable");
        assert_eq!(
            w::decode_f32(&b.watlow_read(w::SET_POINT, 2).expect("readable")),
            Some(-40.0)
        );
        assert_eq!(b.watlow_read(w::CONTROL_MODE, 1), Ok(vec![mode::AUTO]));
        assert_eq!(
            b.watlow_read(1000, 2),
            Err(ExceptionCode::IllegalDataAddress)
        );
        assert_eq!(
            b.watlow_write(w::SET_POINT, &encode_f32(900.0)),
            Err(ExceptionCode::IllegalDataValue)
        );
        assert_eq!(
            b.watlow_write(w::PV, &[0, 0]),
            Err(ExceptionCode::IllegalFunction)
        );
        b.advance_to(3600.0);
        let pv = w::decode_f32(&b.watlow_read(w::PV, 2).expect("readable")).expect("finite");
        assert!((pv + 40.0).abs() < 0.1, "{pv}");
    }
}
