//! The bench limits, enforced in one place below the sequencer: every
//! chamber and table command of any [`BenchIo`] passes through [`Guarded`],
//! which refuses what the bench file's `[limits]` forbid before a byte is
//! sent.

use async_trait::async_trait;

use super::{BenchIo, Tick};
use crate::bench::Limits;
use crate::driver::DeviceError;
use crate::geometry::TableAngles;
use crate::protocol::frame::LinkStats;

/// A bench whose commands are checked against the limits.
#[derive(Debug)]
pub struct Guarded<B> {
    inner: B,
    limits: Limits,
    /// Highest voltage and current limit a power command may ask.
    supply_max: Option<(f64, f64)>,
}

impl<B: BenchIo> Guarded<B> {
    /// Guard `inner` with `limits`.
    pub fn new(inner: B, limits: Limits) -> Self {
        Self {
            inner,
            limits,
            supply_max: None,
        }
    }

    /// The same guard around the bench `f` makes of the guarded one.
    #[must_use]
    pub fn map_inner(mut self, f: impl FnOnce(B) -> B) -> Self {
        self.inner = f(self.inner);
        self
    }

    /// Refuse power commands beyond the supply's `max_volts` and
    /// `max_limit_a` from the bench file.
    #[must_use]
    pub fn with_supply(mut self, supply: Option<&crate::bench::SupplyDevice>) -> Self {
        self.supply_max = supply.map(|p| (p.max_volts(), p.max_limit_a()));
        self
    }

    fn refuse(device: &str, request: String, reason: String) -> DeviceError {
        DeviceError::Refused {
            device: device.to_owned(),
            request,
            reason: format!("beyond the bench limits: {reason}"),
        }
    }
}

#[async_trait]
impl<B: BenchIo> BenchIo for Guarded<B> {
    fn now_s(&self) -> f64 {
        self.inner.now_s()
    }

    fn is_simulated(&self) -> bool {
        self.inner.is_simulated()
    }

    fn power_by_hand(&mut self, on: bool) {
        self.inner.power_by_hand(on);
    }

    fn frame_dt_s(&self) -> f64 {
        self.inner.frame_dt_s()
    }

    fn record_edge_s(&self) -> f64 {
        self.inner.record_edge_s()
    }

    fn lsb_arcsec(&self) -> f64 {
        self.inner.lsb_arcsec()
    }

    fn temp_lsb_c(&self) -> f64 {
        self.inner.temp_lsb_c()
    }

    async fn set_chamber(&mut self, set_c: f64, ramp_c_per_min: f64) -> Result<(), DeviceError> {
        let l = &self.limits;
        let request = format!("set point {set_c} degC at {ramp_c_per_min} degC/min");
        if !(set_c.is_finite() && (l.chamber_min_c..=l.chamber_max_c).contains(&set_c)) {
            let why = format!(
                "set point outside {}..{} degC",
                l.chamber_min_c, l.chamber_max_c
            );
            return Err(Self::refuse("chamber", request, why));
        }
        if !(ramp_c_per_min.is_finite()
            && ramp_c_per_min > 0.0
            && ramp_c_per_min <= l.chamber_max_ramp_c_per_min)
        {
            let why = format!(
                "ramp not within 0..{} degC/min",
                l.chamber_max_ramp_c_per_min
            );
            return Err(Self::refuse("chamber", request, why));
        }
        self.inner.set_chamber(set_c, ramp_c_per_min).await
    }

    async fn move_table(&mut self, a: TableAngles) -> Result<(), DeviceError> {
        let l = &self.limits;
        for (v, r, axis) in [
            (a.outer_deg, l.outer_range_deg, "outer"),
            (a.inner_deg, l.inner_range_deg, "inner"),
        ] {
            if !(v.is_finite() && v >= r[0] && v <= r[1]) {
                let request = format!("move to outer {} / inner {} deg", a.outer_deg, a.inner_deg);
                let why = format!("{axis} axis outside {}..{} deg", r[0], r[1]);
                return Err(Self::refuse("table", request, why));
            }
        }
        self.inner.move_table(a).await
    }

    async fn rotate_table(&mut self, inner: bool, rate_dps: f64) -> Result<(), DeviceError> {
        let axis = if inner { "inner" } else { "outer" };
        let request = format!("turn the {axis} axis at {rate_dps} deg/s");
        match self.limits.rate_mode() {
            None => Err(Self::refuse(
                "table",
                request,
                "the bench file gives the table no rate mode (limits.table_rate_mode_max_dps)"
                    .into(),
            )),
            Some((max, _)) if !(rate_dps.is_finite() && rate_dps.abs() <= max) => {
                Err(Self::refuse(
                    "table",
                    request,
                    format!("beyond the rate-mode limit {max} deg/s"),
                ))
            }
            Some(_) => self.inner.rotate_table(inner, rate_dps).await,
        }
    }

    async fn safe_state(&mut self) -> Result<(), DeviceError> {
        self.inner.safe_state().await
    }

    async fn set_power(&mut self, on: bool, volts: f64, limit_a: f64) -> Result<(), DeviceError> {
        let request = if on {
            format!("output on at {volts} V, limit {limit_a} A")
        } else {
            "output off".to_owned()
        };
        let Some((max_v, max_a)) = self.supply_max else {
            return Err(Self::refuse(
                "supply",
                request,
                "the bench file names no supply ([devices.supply])".into(),
            ));
        };
        if on {
            if !(volts.is_finite() && volts > 0.0 && volts <= max_v) {
                let why = format!("voltage not within 0..{max_v} V (devices.supply.max_volts)");
                return Err(Self::refuse("supply", request, why));
            }
            if !(limit_a.is_finite() && limit_a > 0.0 && limit_a <= max_a) {
                let why =
                    format!("current limit not within 0..{max_a} A (devices.supply.max_limit_a)");
                return Err(Self::refuse("supply", request, why));
            }
        }
        self.inner.set_power(on, volts, limit_a).await
    }

    async fn read_power(&mut self) -> Result<Option<crate::driver::SupplyReading>, DeviceError> {
        self.inner.read_power().await
    }

    async fn advance(&mut self, t_s: f64, tick: &mut Tick) -> Result<(), DeviceError> {
        self.inner.advance(t_s, tick).await
    }

    fn link_stats(&self) -> LinkStats {
        self.inner.link_stats()
    }

    fn units(&self) -> usize {
        self.inner.units()
    }

    fn status_bits(&self, slot: usize) -> crate::protocol::frame::StatusBits {
        self.inner.status_bits(slot)
    }

    fn slot_link_stats(&self, slot: usize) -> LinkStats {
        self.inner.slot_link_stats(slot)
    }

    fn take_unit_faults(&mut self) -> Vec<(usize, String)> {
        self.inner.take_unit_faults()
    }

    fn pending_s(&self) -> f64 {
        self.inner.pending_s()
    }

    async fn read_back(
        &mut self,
    ) -> Result<(crate::driver::ChamberReading, crate::driver::TableReading), DeviceError> {
        self.inner.read_back().await
    }

    async fn idle(
        &mut self,
        t_s: f64,
    ) -> Result<(crate::driver::ChamberReading, crate::driver::TableReading), DeviceError> {
        self.inner.idle(t_s).await
    }

    async fn identify(&mut self) -> super::Identities {
        self.inner.identify().await
    }

    fn link_watch(&self) -> Option<std::sync::Arc<crate::driver::LinkWatch>> {
        self.inner.link_watch()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::bench::BenchConfig;
    use crate::clock::{Pacing, VirtualClock};
    use crate::sequencer::embedded::EmbeddedBench;
    use crate::twin::TwinConfig;

    fn guarded() -> Guarded<EmbeddedBench> {
        let clock = Arc::new(VirtualClock::new(Pacing::Max));
        let bench = EmbeddedBench::new(TwinConfig::default_rl16(), 1, clock);
        Guarded::new(bench, BenchConfig::embedded().limits)
    }

    #[tokio::test]
    async fn chamber_commands_beyond_the_limits_never_reach_the_chamber() {
        let mut b = guarded();
        // The twin's chamber could do +100 degC and 5 degC/min; the bench forbids it.
        for (sp, ramp) in [
            (100.0, 1.0),
            (-60.0, 1.0),
            (20.0, 4.0),
            (20.0, 0.0),
            (f64::NAN, 1.0),
        ] {
            let err = b
                .set_chamber(sp, ramp)
                .await
                .expect_err("beyond the limits");
            assert!(err.to_string().contains("beyond the bench limits"), "{err}");
        }
        let mut tick = Tick::default();
        b.advance(600.0, &mut tick).await.expect("advance");
        let st = tick.state.expect("state");
        assert_eq!(st.chamber.set_point_c, 20.0, "nothing was sent");
        b.set_chamber(50.0, 1.0).await.expect("within limits");
    }

    #[tokio::test]
    async fn table_moves_beyond_the_travel_are_refused() {
        let mut b = guarded();
        let err = b
            .move_table(TableAngles {
                outer_deg: 190.0,
                inner_deg: 0.0,
            })
            .await
            .expect_err("outer beyond its travel");
        assert!(err.to_string().contains("outer axis outside"), "{err}");
        let mut tick = Tick::default();
        b.advance(30.0, &mut tick).await.expect("advance");
        assert_eq!(
            tick.state.expect("state").commanded.outer_deg,
            90.0,
            "nothing was sent"
        );
    }
}
