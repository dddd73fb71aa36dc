//! The embedded simulated bench: the twin itself behind [`BenchIo`], on
//! virtual time (as fast as the machine allows, or paced at a speed
//! factor). Faults can be scheduled to test failure handling end to end.

use std::sync::Arc;

use async_trait::async_trait;

use super::{BenchIo, BenchState, FrameRecord, SlotTick, Tick};
use crate::bench::{SupplyDevice, SupplySafe};
use crate::clock::{Clock, VirtualClock};
use crate::driver::{ChamberMode, ChamberReading, DeviceError, TableReading};
use crate::geometry::{Site, TableAngles, TableGeometry};
use crate::protocol::frame::LinkStats;
use crate::protocol::supply::{Command, configure};
use crate::sim::PASSIVE_DRIFT_C_PER_MIN;
use crate::sim::supply::Supply;
use crate::twin::{AxisDemand, GyroSample, Twin, TwinConfig};

/// The errors a supply queued as the refusal of `request`; none: done.
fn refused_by_supply(request: &str, errors: Vec<String>) -> Result<(), DeviceError> {
    if errors.is_empty() {
        Ok(())
    } else {
        Err(DeviceError::Refused {
            device: "supply".into(),
            request: request.to_owned(),
            reason: errors.join("; "),
        })
    }
}

/// Temperature resolution of the frames, degC (the documented layout).
pub const TEMP_LSB_C: f64 = 0.01;

/// The faults the embedded bench plays: the one fault model, shared with
/// the served simulators (`sim serve --inject`).
pub use crate::sim::faults::Fault;

/// A frame as the twin's gyro sends it, with `counts` (a fault may replace
/// the sample's own).
fn frame_of(g: &GyroSample, counts: i32) -> FrameRecord {
    let raw = |t: f64| (t / TEMP_LSB_C).round() as i16;
    FrameRecord {
        seq: (g.index % 256) as u8,
        counts,
        temps_raw: [raw(g.t1_c), raw(g.t2_c), raw(g.tcase_c)],
        status: g.status,
    }
}

/// The twin as a bench.
#[derive(Debug)]
pub struct EmbeddedBench {
    twin: Twin,
    clock: Arc<VirtualClock>,
    site: Site,
    geometry: TableGeometry,
    commanded: TableAngles,
    mode: ChamberMode,
    faults: Vec<(f64, Fault)>,
    frames: u64,
    crc_errors: u64,
    supply: Option<EmbeddedSupply>,
    /// A batch's other units, each its own twin in the same chamber air
    /// on the same table (slots after the first, in the bench's order).
    slots: Vec<SlotTwin>,
}

/// One more unit of a batch: its own twin (parameters, seed, noise) on its
/// own mount, given every chamber and table command the first is given.
/// The twins' chamber air and table follow the same deterministic models
/// from the same commands, so they share one air and one table; a test
/// holds them to that.
#[derive(Debug)]
struct SlotTwin {
    twin: Twin,
    geometry: TableGeometry,
    frames: u64,
}

/// The simulated supply powering the unit, with the bench file's settings.
#[derive(Debug)]
struct EmbeddedSupply {
    sim: Supply,
    cfg: SupplyDevice,
    shorted: bool,
}

impl EmbeddedBench {
    /// A bench around a fresh twin (gyro powered at t = 0), paced by `clock`.
    pub fn new(cfg: TwinConfig, seed: u64, clock: Arc<VirtualClock>) -> Self {
        let commanded = cfg.table.initial;
        Self {
            site: cfg.site,
            geometry: cfg.table.geometry,
            twin: Twin::new(cfg, seed),
            clock,
            commanded,
            mode: ChamberMode::Constant,
            faults: Vec::new(),
            frames: 0,
            crc_errors: 0,
            supply: None,
            slots: Vec::new(),
        }
    }

    /// Add a batch's next unit: `cfg`'s twin seeded `seed`, mounted as
    /// `cfg.table.geometry` says, in this bench's chamber on its table.
    pub fn with_slot(mut self, cfg: TwinConfig, seed: u64) -> Self {
        let geometry = cfg.table.geometry;
        let mut twin = Twin::new(cfg, seed);
        if !self.twin.is_powered() {
            twin.power_off();
        }
        self.slots.push(SlotTwin {
            twin,
            geometry,
            frames: 0,
        });
        self
    }

    /// Every twin: the first unit's, then the batch's others.
    fn twins(&mut self) -> impl Iterator<Item = &mut Twin> {
        std::iter::once(&mut self.twin).chain(self.slots.iter_mut().map(|s| &mut s.twin))
    }

    /// Power the unit from a simulated supply as the bench file describes
    /// it: wired at its voltage and limit, the output off until the run
    /// switches it on (the unit off, as on a bench before its run).
    pub fn with_supply(mut self, cfg: &SupplyDevice) -> Self {
        let sim = Supply::wired(
            cfg.protocol,
            cfg.channel,
            cfg.volts,
            cfg.limit_a,
            cfg.protection,
        );
        if !sim.unit_powered() {
            self.twin.power_off();
        }
        self.supply = Some(EmbeddedSupply {
            sim,
            cfg: cfg.clone(),
            shorted: false,
        });
        self
    }

    /// Run the twin to `t_s`, switching it on and off where the supply's
    /// output brings the unit's power or takes it away.
    fn run_to(&mut self, t_s: f64, mut on_frame: impl FnMut(&GyroSample)) {
        if let Some(p) = self.supply.as_mut() {
            if !p.shorted
                && self
                    .faults
                    .iter()
                    .any(|(t, f)| *f == Fault::SupplyOvercurrent && self.twin.time_s() >= *t)
            {
                p.shorted = true;
                p.sim.load.0.steady_a *= 3.0;
            }
            p.sim.ignores_off |= self
                .faults
                .iter()
                .any(|(t, f)| *f == Fault::SupplyIgnoresOff && self.twin.time_s() >= *t);
            self.twin.set_powered(p.sim.unit_powered());
            while let Some(t_change) = p.sim.advance_until_change(t_s) {
                self.twin.run_until(t_change, |_, g| on_frame(g));
                self.twin.set_powered(p.sim.unit_powered());
            }
        }
        self.twin.run_until(t_s, |_, g| on_frame(g));
    }

    /// Run a batch's other twins to `t_s` (the first is run by
    /// [`EmbeddedBench::run_to`]), each slot's frames into `ticks`, and
    /// each one's pose: its orientation and the mean reference over the
    /// tick from `from` (the table's angles and rates at its start).
    fn run_slots(
        &mut self,
        t_s: f64,
        from: (f64, TableAngles, TableAngles),
        ticks: &mut Vec<SlotTick>,
    ) {
        ticks.resize_with(self.slots.len(), SlotTick::default);
        let lost = self
            .active(Fault::UnitLost)
            .then(|| self.slots.len().saturating_sub(1));
        for (k, (slot, tick)) in self.slots.iter_mut().zip(ticks.iter_mut()).enumerate() {
            tick.frames.clear();
            let frames = &mut tick.frames;
            let sends = lost != Some(k);
            slot.twin.run_until(t_s, |_, g| {
                if sends {
                    frames.push(frame_of(g, g.delta_counts));
                }
            });
            slot.frames += frames.len() as u64;
            let (angles, rates) = (slot.twin.table_angles(), slot.twin.table_rates());
            tick.orientation = slot.geometry.orientation(angles);
            tick.reference_dph = slot.geometry.mean_kinematic_rate_dph(
                &self.site,
                (from.1, from.2),
                (angles, rates),
                slot.twin.time_s() - from.0,
            );
        }
    }

    /// Play `fault` from device time `at_s` on.
    pub fn schedule(&mut self, at_s: f64, fault: Fault) {
        self.faults.push((at_s, fault));
    }

    fn active(&self, f: Fault) -> bool {
        let now = self.twin.time_s();
        self.faults.iter().any(|(t, g)| *g == f && now >= *t)
    }

    /// The faults of `devices` that are playing now, as their errors.
    fn check(&self, devices: &[&str]) -> Result<(), DeviceError> {
        let on = |d: &str| devices.contains(&d);
        if on("chamber") && self.active(Fault::ChamberSilent) {
            return Err(DeviceError::Timeout {
                device: "chamber".into(),
                request: "TEMP?".into(),
                timeout_s: 1.0,
                attempts: 3,
            });
        }
        if on("table") && self.active(Fault::TableInterlock) {
            return Err(DeviceError::Interlock {
                device: "table".into(),
            });
        }
        if on("gyro") && self.active(Fault::GyroSilent) {
            return Err(DeviceError::Silent {
                device: "gyro".into(),
                timeout_s: 1.0,
            });
        }
        Ok(())
    }

    fn state(&self) -> BenchState {
        let (air, target, _) = self.twin.chamber_state();
        // The table's encoder latched by the unit's frame strobe: its
        // angles where the tick's last frame ended (the tick's end itself
        // when the frames end with the periods), so that a record's
        // counts and its table angles end together.
        let angles = self.twin.frame_table_angles();
        let rates = self.twin.table_rates();
        BenchState {
            t_s: self.twin.time_s(),
            chamber: ChamberReading {
                air_c: air,
                set_point_c: target,
                mode: self.mode,
                alarms: if self.active(Fault::ChamberAlarm) {
                    vec![crate::sim::alarm::INJECTED]
                } else {
                    Vec::new()
                },
            },
            table: TableReading { angles, rates },
            commanded: self.commanded,
            orientation: self.geometry.orientation(angles),
            reference_dph: self.geometry.kinematic_rate_dph(&self.site, angles, rates),
            in_position: !self.twin.table_moving(),
            power: self.power(),
        }
    }

    fn power(&self) -> Option<crate::driver::SupplyReading> {
        self.supply
            .as_ref()
            .and_then(|p| p.sim.reading(p.cfg.channel))
    }
}

#[async_trait]
impl BenchIo for EmbeddedBench {
    fn now_s(&self) -> f64 {
        self.twin.time_s()
    }

    fn is_simulated(&self) -> bool {
        true
    }

    fn power_by_hand(&mut self, on: bool) {
        // A bench with a supply powers its units through it alone.
        if self.supply.is_none() {
            self.twins().for_each(|t| t.set_powered(on));
        }
    }

    fn frame_dt_s(&self) -> f64 {
        self.twin.frame_dt_s()
    }

    /// Frames are made on the run's own clock: a record holds exactly its own.
    fn record_edge_s(&self) -> f64 {
        0.0
    }

    fn lsb_arcsec(&self) -> f64 {
        self.twin.config().gyro.lsb_arcsec
    }

    fn temp_lsb_c(&self) -> f64 {
        TEMP_LSB_C
    }

    async fn set_chamber(&mut self, set_c: f64, ramp_c_per_min: f64) -> Result<(), DeviceError> {
        self.check(&["chamber"])?;
        for twin in self.twins() {
            twin.set_chamber(set_c, ramp_c_per_min)
                .map_err(|e| DeviceError::Refused {
                    device: "chamber".into(),
                    request: format!("set point {set_c} degC at {ramp_c_per_min} degC/min"),
                    reason: e.to_string(),
                })?;
        }
        self.mode = ChamberMode::Constant;
        Ok(())
    }

    async fn move_table(&mut self, angles: TableAngles) -> Result<(), DeviceError> {
        self.check(&["table"])?;
        self.commanded = angles;
        for twin in self.twins() {
            twin.move_table(angles);
        }
        Ok(())
    }

    async fn rotate_table(&mut self, inner: bool, rate_dps: f64) -> Result<(), DeviceError> {
        self.check(&["table"])?;
        let d = Some(AxisDemand::Rate(rate_dps));
        for twin in self.twins() {
            if inner {
                twin.demand_table(None, d);
            } else {
                twin.demand_table(d, None);
            }
        }
        Ok(())
    }

    async fn safe_state(&mut self) -> Result<(), DeviceError> {
        // An interlocked table is stopped already; a silent chamber cannot
        // be told anything.
        for twin in self.twins() {
            twin.demand_table(Some(AxisDemand::Stop), Some(AxisDemand::Stop));
        }
        let supply = match self.supply.as_mut() {
            Some(p) if p.cfg.safe_state == SupplySafe::Off => {
                let errors = p.sim.program(p.cfg.channel, &[Command::Output(false)]);
                refused_by_supply("output off", errors)
            }
            _ => Ok(()),
        };
        self.check(&["chamber"])?;
        let room = self.twin.config().chamber.initial_c;
        for twin in self.twins() {
            twin.set_chamber(room, PASSIVE_DRIFT_C_PER_MIN)
                .map_err(|e| DeviceError::Refused {
                    device: "chamber".into(),
                    request: "standby".into(),
                    reason: e.to_string(),
                })?;
        }
        self.mode = ChamberMode::Standby;
        supply
    }

    async fn set_power(&mut self, on: bool, volts: f64, limit_a: f64) -> Result<(), DeviceError> {
        let Some(p) = self.supply.as_mut() else {
            return Err(DeviceError::Refused {
                device: "supply".into(),
                request: "power".into(),
                reason: "the embedded bench has no supply".into(),
            });
        };
        let cmds = if on {
            let mut c = configure(p.cfg.protocol, volts, limit_a, p.cfg.protection);
            c.push(Command::Output(true));
            c
        } else {
            vec![Command::Output(false)]
        };
        let request = if on {
            format!("output on at {volts} V, limit {limit_a} A")
        } else {
            "output off".to_owned()
        };
        let errors = p.sim.program(p.cfg.channel, &cmds);
        refused_by_supply(&request, errors)
    }

    async fn read_power(&mut self) -> Result<Option<crate::driver::SupplyReading>, DeviceError> {
        Ok(self.power())
    }

    async fn idle(&mut self, t_s: f64) -> Result<(ChamberReading, TableReading), DeviceError> {
        // A tripped interlock stops the table, it does not blind it.
        self.check(&["chamber"])?;
        // Paced: wait on the runtime's timer, never block its thread.
        if let Some(wait) = self.clock.wall_wait(t_s) {
            tokio::time::sleep(wait).await;
        }
        self.clock.sleep_until(t_s);
        self.run_to(t_s, |_| {});
        for slot in &mut self.slots {
            slot.twin.run_until(t_s, |_, _| {});
        }
        let st = self.state();
        Ok((st.chamber, st.table))
    }

    async fn advance(&mut self, t_s: f64, tick: &mut Tick) -> Result<(), DeviceError> {
        if self.active(Fault::TableInterlock) {
            // What the interlock does on the real table: both axes stop.
            for twin in self.twins() {
                twin.demand_table(Some(AxisDemand::Stop), Some(AxisDemand::Stop));
            }
        }
        self.check(&["chamber", "table", "gyro"])?;
        for (f, signal) in [
            (Fault::Hangup, rustix::process::Signal::HUP),
            (Fault::Quit, rustix::process::Signal::QUIT),
        ] {
            if self.active(f) {
                // Once: as a terminal closing sends it once.
                self.faults.retain(|(_, g)| *g != f);
                let _ = rustix::process::kill_process(rustix::process::getpid(), signal);
            }
        }
        if self.active(Fault::ProcessKill) {
            // SIGKILL itself: nothing after this line runs, no handler,
            // no unwinding, no core dump.
            let _ = rustix::process::kill_process(
                rustix::process::getpid(),
                rustix::process::Signal::KILL,
            );
            std::process::abort();
        }
        assert!(
            !self.active(Fault::Panic),
            "injected fault: a bug panics the run at {} s",
            self.twin.time_s()
        );
        // Paced: wait on the runtime's timer, never block its thread.
        if let Some(wait) = self.clock.wall_wait(t_s) {
            tokio::time::sleep(wait).await;
        }
        self.clock.sleep_until(t_s);
        tick.frames.clear();
        tick.t0_s = self.twin.time_s() + self.twin.frame_dt_s();
        let frames = &mut tick.frames;
        let corrupt = self.active(Fault::GyroCorrupt);
        let stuck = self.active(Fault::GyroStuck);
        let saturated = self.active(Fault::GyroSaturated);
        let mut crc_errors = 0;
        let from = (
            self.twin.time_s(),
            self.twin.frame_table_angles(),
            self.twin.table_rates(),
        );
        self.run_to(t_s, |g| {
            if corrupt && g.index % u64::from(crate::sim::faults::CORRUPT_EVERY_FRAMES) == 0 {
                crc_errors += 1;
                return;
            }
            let counts = match (stuck, saturated) {
                (_, true) => crate::sim::faults::SATURATED_COUNTS,
                (true, _) => crate::sim::faults::STUCK_COUNTS,
                _ => g.delta_counts,
            };
            frames.push(frame_of(g, counts));
        });
        self.run_slots(t_s, from, &mut tick.slots);
        self.crc_errors += crc_errors;
        self.frames += tick.frames.len() as u64;
        let mut state = self.state();
        // The frames' mean reads the interval's mean of the turning
        // reference, not its end's.
        state.reference_dph = self.geometry.mean_kinematic_rate_dph(
            &self.site,
            (from.1, from.2),
            (state.table.angles, state.table.rates),
            state.t_s - from.0,
        );
        tick.state = Some(state);
        Ok(())
    }

    fn units(&self) -> usize {
        1 + self.slots.len()
    }

    fn slot_link_stats(&self, slot: usize) -> LinkStats {
        match slot.checked_sub(1).and_then(|k| self.slots.get(k)) {
            Some(s) => LinkStats {
                frames: s.frames,
                bytes: s.frames * 20,
                ..LinkStats::default()
            },
            None => self.link_stats(),
        }
    }

    async fn read_back(&mut self) -> Result<(ChamberReading, TableReading), DeviceError> {
        self.check(&["chamber"])?;
        let st = self.state();
        Ok((st.chamber, st.table))
    }

    fn link_stats(&self) -> LinkStats {
        LinkStats {
            frames: self.frames,
            bytes: (self.frames + self.crc_errors) * 20,
            crc_errors: self.crc_errors,
            ..LinkStats::default()
        }
    }

    async fn identify(&mut self) -> super::Identities {
        // The embedded instruments answer as `sim serve`'s do.
        super::Identities {
            chamber: Ok(crate::sim::identity::chamber(
                crate::bench::ChamberProtocol::EspecAscii,
            )),
            table: Ok(crate::sim::identity::table()),
            supply: self.supply.as_ref().map(|p| {
                Ok(crate::protocol::supply::parse_identity(
                    &crate::sim::supply::idn(p.cfg.protocol),
                ))
            }),
        }
    }
}
