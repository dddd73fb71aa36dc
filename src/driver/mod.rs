//! Device drivers, built on an already-open transport.
//!
//! Small traits (`Chamber`, `MotionTable`) over the instruments; the gyro
//! link is a reader of frames. Transient faults (a missed or garbled reply,
//! a dropped connection) are retried a bounded number of times; persistent
//! ones end in a [`DeviceError`] that names the device, what failed and
//! what to check.

// The drivers are the crate's own: the sequencer, the bench file and the
// station reach the devices through the traits below and
// `bench::open_bench`.
pub(crate) mod acl;
pub(crate) mod espec;
pub(crate) mod gyro;
pub(crate) mod link;
#[cfg(test)]
mod sim_tests;
pub(crate) mod supply;
pub(crate) mod watlow;

pub use link::{LinkNotice, LinkWatch};

use std::time::Duration;

use async_trait::async_trait;

use crate::geometry::TableAngles;
pub use crate::protocol::Identity;

/// A device failure the caller cannot retry away.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// No (usable) reply within the timeout, after every attempt.
    #[error(
        "{device}: no reply to `{request}` within {timeout_s} s ({attempts} attempts); \
         check the cable or network, the address and the baud rate in bench.toml"
    )]
    Timeout {
        /// Device name from the bench file.
        device: String,
        /// What was sent.
        request: String,
        /// Per-attempt timeout, s.
        timeout_s: f64,
        /// Attempts made.
        attempts: u32,
    },
    /// The instrument refused the request.
    #[error(
        "{device}: refused `{request}`: {reason}; check the value against the instrument's limits"
    )]
    Refused {
        /// Device name.
        device: String,
        /// What was sent.
        request: String,
        /// The instrument's reason.
        reason: String,
    },
    /// Replies kept arriving in a form the protocol does not allow.
    #[error(
        "{device}: unusable reply to `{request}` ({attempts} attempts): {detail}; \
         check the protocol selected in bench.toml and the line for noise"
    )]
    Malformed {
        /// Device name.
        device: String,
        /// What was sent.
        request: String,
        /// What was wrong with the last reply.
        detail: String,
        /// Attempts made.
        attempts: u32,
    },
    /// A value outside what the device can physically report.
    #[error(
        "{device}: {what} = {value} is out of range ({range}); the device or its link is faulty"
    )]
    OutOfRange {
        /// Device name.
        device: String,
        /// Which value.
        what: &'static str,
        /// The value reported.
        value: f64,
        /// The plausible range.
        range: &'static str,
    },
    /// The device's spec could not be opened when the bench came up.
    #[error(
        "{device}: cannot open {spec}: {cause}; check that the device is on and \
         `devices.{device}.spec` in the bench file"
    )]
    Open {
        /// Device name.
        device: String,
        /// Its spec from the bench file (`tcp://...`, `serial://...`).
        spec: String,
        /// Why.
        cause: std::io::Error,
    },
    /// The link could not be (re)opened.
    #[error(
        "{device}: cannot open the link: {cause}; check that the device is on and the spec in bench.toml"
    )]
    Connect {
        /// Device name.
        device: String,
        /// Why.
        cause: std::io::Error,
    },
    /// The chamber reports alarms.
    #[error(
        "{device}: alarm {codes:?}; see the chamber's panel and clear the cause before resuming"
    )]
    Alarm {
        /// Device name.
        device: String,
        /// Alarm codes.
        codes: Vec<u16>,
    },
    /// The motion simulator's interlock tripped.
    #[error(
        "{device}: system interlock tripped; check the table's emergency stop and doors, then reset"
    )]
    Interlock {
        /// Device name.
        device: String,
    },
    /// The link dropped and could not be reopened within the window.
    #[error(
        "{device}: the link dropped and could not be reopened within {window_s} s \
         ({attempts} attempts, the last: {cause}); check the network (switch, cable) \
         and that the device is on; the window is reconnect_window_s in bench.toml"
    )]
    Unreachable {
        /// Device name.
        device: String,
        /// How long reconnecting was tried, s.
        window_s: f64,
        /// Attempts made.
        attempts: u32,
        /// The last attempt's failure.
        cause: std::io::Error,
    },
    /// The link was down when the run was already stopping (interrupted,
    /// or another device lost): tried once, not waited for.
    #[error(
        "{device}: the link is down ({cause}) and the run is stopping ({why}): \
         not waited for; check the device and its network before anyone opens the chamber \
         or touches the fixture"
    )]
    GaveUp {
        /// Device name.
        device: String,
        /// Why the run is stopping.
        why: String,
        /// The attempt's failure.
        cause: std::io::Error,
    },
    /// The supply's over-current protection switched the unit's power off.
    #[error(
        "{device}: the over-current protection tripped (current limit {limit_a} A): the unit's power is off; \
         find what drew the current (a shorted cable, a faulty unit) before powering it again"
    )]
    Overcurrent {
        /// Device name.
        device: String,
        /// The current limit in force, A.
        limit_a: f64,
    },
    /// The gyro sent nothing usable for longer than the link timeout.
    #[error(
        "{device}: no valid frame for {timeout_s} s; check the gyro's power and the data cable"
    )]
    Silent {
        /// Device name.
        device: String,
        /// Timeout, s.
        timeout_s: f64,
    },
}

/// Bounded retry of a request/reply exchange.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RetryPolicy {
    /// Time to wait for each reply.
    pub timeout: Duration,
    /// Attempts before giving up (at least 1).
    pub attempts: u32,
    /// How long a dropped link is reopened, with backoff, before the
    /// device is declared unreachable.
    pub reconnect_window: Duration,
}

/// Default reconnect window: long enough for a managed switch to reboot
/// (one to three minutes), short enough that a dead device is reported
/// while the operator is still near.
pub const RECONNECT_WINDOW: Duration = Duration::from_secs(180);

impl Default for RetryPolicy {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(1000),
            attempts: 3,
            reconnect_window: RECONNECT_WINDOW,
        }
    }
}

/// Controller mode of a chamber.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChamberMode {
    /// Off.
    Off,
    /// Powered, not controlling (the safe state).
    Standby,
    /// Holding the set point.
    Constant,
}

impl ChamberMode {
    /// `off`, `standby` or `constant` (as logged).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Standby => "standby",
            Self::Constant => "constant",
        }
    }
}

/// What a chamber reports.
#[derive(Debug, Clone, PartialEq)]
pub struct ChamberReading {
    /// Air temperature, degC.
    pub air_c: f64,
    /// Set point, degC.
    pub set_point_c: f64,
    /// Mode.
    pub mode: ChamberMode,
    /// Active alarm codes (empty when none).
    pub alarms: Vec<u16>,
}

/// A climatic chamber.
#[async_trait]
pub trait Chamber: Send {
    /// Name of the device (from the bench file).
    fn name(&self) -> &str;
    /// Read temperature, set point, mode and alarms.
    async fn read(&mut self) -> Result<ChamberReading, DeviceError>;
    /// Set the constant set point, degC.
    async fn set_point(&mut self, temp_c: f64) -> Result<(), DeviceError>;
    /// Change the controller mode.
    async fn set_mode(&mut self, mode: ChamberMode) -> Result<(), DeviceError>;
    /// Ask the controller what it is (model, firmware; its serial where
    /// the protocol reports one).
    async fn identify(&mut self) -> Result<Identity, DeviceError>;
}

/// What a supply channel reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupplyReading {
    /// Voltage setting, V.
    pub set_v: f64,
    /// Current limit, A.
    pub limit_a: f64,
    /// Voltage measured at the output, V.
    pub v: f64,
    /// Current measured through it, A.
    pub a: f64,
    /// Output switched on.
    pub on: bool,
    /// Over-current protection tripped (the output is then off).
    pub tripped: bool,
}

/// A programmable DC power supply; channels are numbered from 1.
#[async_trait]
pub trait PowerSupply: Send {
    /// Name of the device (from the bench file).
    fn name(&self) -> &str;
    /// Ask the supply what it is.
    async fn identify(&mut self) -> Result<Identity, DeviceError>;
    /// Set a channel's voltage and current limit, its over-current
    /// protection on or off (leaves the output as it is).
    async fn configure(
        &mut self,
        channel: u8,
        volts: f64,
        limit_a: f64,
        protection: bool,
    ) -> Result<(), DeviceError>;
    /// Switch a channel's output on or off.
    async fn output(&mut self, channel: u8, on: bool) -> Result<(), DeviceError>;
    /// Read a channel's settings, measurements and state.
    async fn read(&mut self, channel: u8) -> Result<SupplyReading, DeviceError>;
    /// Clear a tripped protection (the output stays off).
    async fn clear_trip(&mut self, channel: u8) -> Result<(), DeviceError>;
}

/// Ramps a chamber whose controller has no ramp of its own by stepping its
/// constant set point: `due` says which set point to send now, if any.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SetPointRamp {
    from_c: f64,
    to_c: f64,
    rate_c_per_s: f64,
    start_s: f64,
    sent_c: Option<f64>,
}

impl SetPointRamp {
    /// Smallest set-point change worth sending, degC.
    pub const STEP_C: f64 = 0.05;

    /// A ramp from `from_c` to `to_c` at `rate_c_per_min`, starting at `now_s`.
    pub fn new(from_c: f64, to_c: f64, rate_c_per_min: f64, now_s: f64) -> Self {
        Self {
            from_c,
            to_c,
            rate_c_per_s: rate_c_per_min / 60.0,
            start_s: now_s,
            sent_c: None,
        }
    }

    /// The ramped set point at `t_s`, degC.
    pub fn at(&self, t_s: f64) -> f64 {
        let d = self.to_c - self.from_c;
        let moved = (self.rate_c_per_s * (t_s - self.start_s)).clamp(0.0, d.abs());
        self.from_c + moved * d.signum()
    }

    /// The set point to send at `t_s`, if it moved by at least [`Self::STEP_C`]
    /// since the last one sent (or reached the target); marks it sent.
    pub fn due(&mut self, t_s: f64) -> Option<f64> {
        let sp = self.at(t_s);
        let send = match self.sent_c {
            None => true,
            Some(last) => {
                (sp - last).abs() >= Self::STEP_C || (sp == self.to_c && last != self.to_c)
            }
        };
        send.then(|| {
            self.sent_c = Some(sp);
            sp
        })
    }

    /// True once the target has been sent.
    pub fn done(&self) -> bool {
        self.sent_c == Some(self.to_c)
    }

    /// Time until the target is sent, from `t_s`, s (0 once sent).
    pub fn remaining_s(&self, t_s: f64) -> f64 {
        if self.done() {
            return 0.0;
        }
        let total = (self.to_c - self.from_c).abs() / self.rate_c_per_s.max(f64::MIN_POSITIVE);
        // At least a tick: the target goes out on the next one.
        (self.start_s + total - t_s).max(1.0)
    }
}

/// What a motion simulator reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableReading {
    /// Axis angles, deg.
    pub angles: TableAngles,
    /// Axis rates, deg/s.
    pub rates: TableAngles,
}

/// A two-axis motion simulator.
#[async_trait]
pub trait MotionTable: Send {
    /// Name of the device.
    fn name(&self) -> &str;
    /// Read both axes.
    async fn read(&mut self) -> Result<TableReading, DeviceError>;
    /// Put both axes in position mode and go to `angles`.
    async fn move_to(&mut self, angles: TableAngles) -> Result<(), DeviceError>;
    /// Turn an axis (false = outer, true = inner) at a constant rate, deg/s.
    async fn rate(&mut self, inner: bool, rate_dps: f64) -> Result<(), DeviceError>;
    /// Controlled stop of both axes (the safe state).
    async fn stop(&mut self) -> Result<(), DeviceError>;
    /// Ask the controller what it is (`*IDN?`).
    async fn identify(&mut self) -> Result<Identity, DeviceError>;
}

/// Decides "in position": every axis within `tolerance_deg` of the target
/// and slower than `rate_tolerance_dps`, continuously for `settle_s`.
#[derive(Debug, Clone)]
pub struct InPosition {
    /// Angle tolerance, deg.
    pub tolerance_deg: f64,
    /// Rate tolerance, deg/s.
    pub rate_tolerance_dps: f64,
    /// Settle time, s.
    pub settle_s: f64,
    since: Option<f64>,
}

impl InPosition {
    /// A tracker with the given tolerances.
    pub fn new(tolerance_deg: f64, rate_tolerance_dps: f64, settle_s: f64) -> Self {
        Self {
            tolerance_deg,
            rate_tolerance_dps,
            settle_s,
            since: None,
        }
    }

    /// Feed a reading taken at `t_s`; true once settled on `target`.
    pub fn update(&mut self, r: &TableReading, target: TableAngles, t_s: f64) -> bool {
        let err = |a: f64, b: f64| crate::geometry::wrap_deg(a - b).abs();
        let within = err(r.angles.outer_deg, target.outer_deg) <= self.tolerance_deg
            && err(r.angles.inner_deg, target.inner_deg) <= self.tolerance_deg
            && r.rates.outer_deg.abs() <= self.rate_tolerance_dps
            && r.rates.inner_deg.abs() <= self.rate_tolerance_dps;
        if !within {
            self.since = None;
            return false;
        }
        t_s - *self.since.get_or_insert(t_s) >= self.settle_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_point_ramp_steps_at_the_rate_and_ends_on_the_target() {
        let mut r = SetPointRamp::new(20.0, 50.0, 1.0, 100.0);
        assert_eq!(r.due(100.0), Some(20.0));
        assert_eq!(r.due(101.0), None, "1/60 degC is below the step");
        assert_eq!(r.due(103.0), Some(20.05));
        assert!((r.at(100.0 + 900.0) - 35.0).abs() < 1e-12);
        assert_eq!(r.due(100.0 + 1800.0), Some(50.0));
        assert!(r.done());
        assert_eq!(r.due(100.0 + 4000.0), None);
        let down = SetPointRamp::new(20.0, -40.0, 2.0, 0.0);
        assert!((down.at(600.0) - 0.0).abs() < 1e-12);
    }

    #[test]
    fn in_position_needs_the_settle_time() {
        let target = TableAngles {
            outer_deg: 90.0,
            inner_deg: 0.0,
        };
        let at = |o: f64, rate: f64| TableReading {
            angles: TableAngles {
                outer_deg: o,
                inner_deg: 359.999,
            },
            rates: TableAngles {
                outer_deg: rate,
                inner_deg: 0.0,
            },
        };
        let mut ip = InPosition::new(0.01, 0.01, 2.0);
        assert!(!ip.update(&at(89.5, 0.0), target, 0.0));
        assert!(!ip.update(&at(90.001, 0.0), target, 1.0));
        assert!(!ip.update(&at(90.001, 0.5), target, 2.0), "still moving");
        assert!(!ip.update(&at(90.001, 0.0), target, 3.0));
        assert!(ip.update(&at(90.0, 0.0), target, 5.0));
    }
}
