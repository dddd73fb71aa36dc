//! A bench of real drivers (serial, TCP, ptys): instruments or `sim serve`
//! endpoints, on wall time (scaled by the bench file's `time_scale` when
//! the devices are a sped-up simulator).
//!
//! The gyro is read continuously by a background task; every tick reads
//! the chamber and the table. Chambers ramp by the set point being stepped
//! here (the drivers' constant set point has no ramp of its own).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use async_trait::async_trait;
use tokio::sync::mpsc;

use super::{BenchIo, BenchState, FrameRecord, Tick};
use crate::bench::{BenchConfig, OpenBench, SupplyDevice, SupplySafe};
use crate::clock::{Clock, WallClock};
use crate::driver::acl::AclTable;
use crate::driver::supply::ScpiSupply;
use crate::driver::{Chamber, ChamberMode, DeviceError, MotionTable, PowerSupply, SetPointRamp};
use crate::geometry::{Site, TableAngles, TableGeometry};
use crate::protocol::frame::LinkStats;

/// How long after switching the unit on its silence is expected, wall
/// time, s (ours: an RLG's discharge ignites and its frame stream starts
/// within seconds; beyond this a silent unit is a fault).
pub const BOOT_S: f64 = 10.0;

/// When the gyro's silence is expected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Quiet {
    /// Never: the unit is powered and running.
    No,
    /// The run switched the unit off.
    Off,
    /// Switched on; booting until then.
    Booting(std::time::Instant),
}

impl Quiet {
    fn now(self) -> bool {
        match self {
            Self::No => false,
            Self::Off => true,
            Self::Booting(until) => std::time::Instant::now() < until,
        }
    }
}

/// Real drivers behind [`BenchIo`].
pub struct DeviceBench {
    chamber: Box<dyn Chamber>,
    table: AclTable,
    /// Every unit's frames, by unit (0: the first; a batch's others after).
    frames: mpsc::Receiver<(usize, Result<FrameRecord, DeviceError>)>,
    /// Each unit's link figures.
    stats: Vec<Arc<Mutex<LinkStats>>>,
    /// A batch's other units' geometries (each unit on its own mount).
    slot_geometries: Vec<TableGeometry>,
    /// A batch's links that failed since the run last asked: unit, device
    /// and why. A batch goes on without a unit whose link is lost.
    unit_faults: Vec<(usize, String)>,
    /// A bench with slots (a batch, of one unit or more).
    batch: bool,
    /// The one unit's link failure seen while idle, for the next tick.
    lost: Option<DeviceError>,
    clock: WallClock,
    time_scale: f64,
    site: Site,
    geometry: TableGeometry,
    commanded: TableAngles,
    ramp: Option<SetPointRamp>,
    last_air_c: f64,
    frame_dt_s: f64,
    record_edge_s: f64,
    lsb_arcsec: f64,
    temp_lsb_c: f64,
    /// What each unit's status word means.
    status_bits: Vec<crate::protocol::frame::StatusBits>,
    supply: Option<(ScpiSupply, SupplyDevice)>,
    /// Whether the gyro's silence is expected now: while the run has the
    /// unit's power off, and for a while after switching it on.
    quiet: Arc<Mutex<Quiet>>,
    /// The table as the last tick ended (device time, angles, rates).
    last_pose: Option<(f64, (TableAngles, TableAngles))>,
    /// What the links say as they drop, come back or are lost.
    watch: Arc<crate::driver::LinkWatch>,
}

/// Longest time between two table reads over which the reference is
/// averaged, s of device time (two ticks); beyond it the end's value.
const POSE_GAP_S: f64 = 2.0;

impl std::fmt::Debug for DeviceBench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeviceBench")
            .field("time_scale", &self.time_scale)
            .finish_non_exhaustive()
    }
}

impl DeviceBench {
    /// Take over opened devices; the run's time starts now.
    pub async fn start(cfg: &BenchConfig, open: OpenBench) -> Result<Self, DeviceError> {
        let OpenBench {
            mut chamber,
            mut table,
            gyro,
            others,
            supply,
            watch,
        } = open;
        table.servo_on().await?;
        // The supply is set as the bench file says, its output left as
        // found: the run switches the unit on itself, and records when
        // (`Run::power_at_start`, a procedure's `power` step). A unit
        // found off is silent until then.
        let mut off = false;
        let supply = match (supply, &cfg.devices.supply) {
            (Some(mut p), Some(c)) => {
                let found = p.read(c.channel).await?;
                if !found.on {
                    p.configure(c.channel, c.volts, c.limit_a, c.protection)
                        .await?;
                }
                off = !found.on;
                Some((p, c.clone()))
            }
            _ => None,
        };
        let reading = chamber.read().await?;
        let quiet = Arc::new(Mutex::new(if off { Quiet::Off } else { Quiet::No }));
        let batch = !cfg.slots.is_empty();
        let (tx, rx) = mpsc::channel(1 << 16);
        let stats: Vec<_> = std::iter::once(gyro)
            .chain(others)
            .enumerate()
            .map(|(unit, gyro)| {
                let stats = Arc::new(Mutex::new(LinkStats::default()));
                tokio::spawn(read_gyro(
                    unit,
                    gyro,
                    tx.clone(),
                    stats.clone(),
                    quiet.clone(),
                    batch,
                ));
                stats
            })
            .collect();
        let slot_geometries = cfg
            .slots
            .iter()
            .skip(1)
            .map(|s| cfg.slot_geometry(s))
            .collect();
        let geometry = cfg
            .slots
            .first()
            .map_or(cfg.table.geometry, |s| cfg.slot_geometry(s));
        let layout = cfg.frame_layout();
        Ok(Self {
            chamber,
            table,
            frames: rx,
            stats,
            slot_geometries,
            unit_faults: Vec::new(),
            batch,
            lost: None,
            clock: WallClock::scaled(cfg.time_scale),
            time_scale: cfg.time_scale,
            site: cfg.site,
            geometry,
            commanded: TableAngles::default(),
            ramp: None,
            last_air_c: reading.set_point_c,
            frame_dt_s: 1.0 / cfg.devices.gyro.frame_rate_hz,
            record_edge_s: cfg.record_edge_s(),
            lsb_arcsec: cfg.devices.gyro.lsb_arcsec,
            temp_lsb_c: layout.temp_lsb_c,
            status_bits: cfg.status_bits(),
            supply,
            quiet,
            last_pose: None,
            watch,
        })
    }

    /// The cause of the gyro's failure `e`: the supply's protection when it
    /// tripped (the unit went silent because its power went off).
    async fn cause_of(&mut self, e: DeviceError) -> DeviceError {
        if matches!(e, DeviceError::Silent { .. })
            && let Some((p, c)) = self.supply.as_mut()
            && let Ok(r) = p.read(c.channel).await
            && r.tripped
        {
            return DeviceError::Overcurrent {
                device: "supply".into(),
                limit_a: r.limit_a,
            };
        }
        e
    }

    async fn step_ramp(&mut self, t_s: f64) -> Result<(), DeviceError> {
        let Some(mut r) = self.ramp else {
            return Ok(());
        };
        if let Some(sp) = r.due(t_s) {
            self.chamber.set_point(sp).await?;
        }
        self.ramp = (!r.done()).then_some(r);
        Ok(())
    }
}

/// Read unit `unit`'s gyro onto `tx` until its link fails for good (or
/// the run is gone), keeping its figures in `stats`. An unpowered or
/// booting unit's silence is expected (`quiet`). In a `batch`, a unit's
/// silence is said and reading goes on (its records show the gap; the
/// run judges them); on a one-unit bench it ends the run.
async fn read_gyro(
    unit: usize,
    mut gyro: crate::driver::gyro::GyroReader<crate::transport::BoxTransport>,
    tx: mpsc::Sender<(usize, Result<FrameRecord, DeviceError>)>,
    stats: Arc<Mutex<LinkStats>>,
    quiet: Arc<Mutex<Quiet>>,
    batch: bool,
) {
    // In a batch, a silence is said once, when it starts.
    let mut said_silent = false;
    loop {
        let next = gyro.next_frame().await;
        let silent = matches!(next, Err(DeviceError::Silent { .. }));
        if silent && (said_silent || quiet.lock().is_ok_and(|q| q.now())) {
            // An unpowered unit sends nothing; a booting one not yet.
            continue;
        }
        said_silent = batch && silent;
        if let Ok(mut s) = stats.lock() {
            *s = gyro.stats();
        }
        let msg = match next {
            Ok(Some(f)) => Ok(FrameRecord {
                seq: f.seq,
                counts: f.delta_counts,
                temps_raw: f.temps_raw,
                status: f.status,
            }),
            Ok(None) => Err(gyro_stream_ended(gyro.device())),
            Err(e) => Err(e),
        };
        let stop = msg.is_err() && !(batch && silent);
        if tx.send((unit, msg)).await.is_err() || stop {
            return;
        }
    }
}

/// Every gyro link of a batch failed for good.
fn every_link_lost() -> DeviceError {
    DeviceError::Connect {
        device: "gyro".into(),
        cause: std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            "every unit's gyro link is lost (each was said as it went)",
        ),
    }
}

/// The gyro's stream ended and cannot be reopened.
fn gyro_stream_ended(device: &str) -> DeviceError {
    DeviceError::Connect {
        device: device.into(),
        cause: std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            "the gyro's data stream ended",
        ),
    }
}

/// At rest within 0.01 deg of the commanded angles (the sequencer's
/// in-position judgement adds the settle time).
fn at_rest_on(t: &crate::driver::TableReading, c: TableAngles) -> bool {
    let near = |a: f64, b: f64| crate::geometry::wrap_deg(a - b).abs() <= 0.01;
    near(t.angles.outer_deg, c.outer_deg)
        && near(t.angles.inner_deg, c.inner_deg)
        && t.rates.outer_deg == 0.0
        && t.rates.inner_deg == 0.0
}

#[async_trait]
impl BenchIo for DeviceBench {
    fn now_s(&self) -> f64 {
        self.clock.now_s()
    }

    fn is_simulated(&self) -> bool {
        false
    }

    fn frame_dt_s(&self) -> f64 {
        self.frame_dt_s
    }

    fn record_edge_s(&self) -> f64 {
        self.record_edge_s
    }

    fn lsb_arcsec(&self) -> f64 {
        self.lsb_arcsec
    }

    fn temp_lsb_c(&self) -> f64 {
        self.temp_lsb_c
    }

    async fn set_chamber(&mut self, set_c: f64, ramp_c_per_min: f64) -> Result<(), DeviceError> {
        let now = self.now_s();
        let from = self.ramp.map_or(self.last_air_c, |r| r.at(now));
        self.chamber.set_mode(ChamberMode::Constant).await?;
        self.ramp = Some(SetPointRamp::new(from, set_c, ramp_c_per_min, now));
        self.step_ramp(now).await
    }

    async fn move_table(&mut self, angles: TableAngles) -> Result<(), DeviceError> {
        self.commanded = angles;
        self.table.move_to(angles).await
    }

    async fn rotate_table(&mut self, inner: bool, rate_dps: f64) -> Result<(), DeviceError> {
        self.table.rate(inner, rate_dps).await
    }

    async fn safe_state(&mut self) -> Result<(), DeviceError> {
        self.ramp = None;
        let table = self.table.stop().await;
        let chamber = self.chamber.set_mode(ChamberMode::Standby).await;
        let supply = match self.supply.as_mut() {
            Some((p, c)) if c.safe_state == SupplySafe::Off => {
                if let Ok(mut q) = self.quiet.lock() {
                    *q = Quiet::Off;
                }
                p.output(c.channel, false).await
            }
            _ => Ok(()),
        };
        table.and(chamber).and(supply)
    }

    async fn set_power(&mut self, on: bool, volts: f64, limit_a: f64) -> Result<(), DeviceError> {
        let Some((p, c)) = self.supply.as_mut() else {
            return Err(DeviceError::Refused {
                device: "supply".into(),
                request: "power".into(),
                reason: "the bench file names no supply".into(),
            });
        };
        let set = |q: Quiet| {
            if let Ok(mut g) = self.quiet.lock() {
                *g = q;
            }
        };
        if on {
            p.configure(c.channel, volts, limit_a, c.protection).await?;
        } else {
            set(Quiet::Off);
        }
        p.output(c.channel, on).await?;
        if on {
            set(Quiet::Booting(
                std::time::Instant::now() + Duration::from_secs_f64(BOOT_S),
            ));
        }
        Ok(())
    }

    async fn read_power(&mut self) -> Result<Option<crate::driver::SupplyReading>, DeviceError> {
        match self.supply.as_mut() {
            Some((p, c)) => p.read(c.channel).await.map(Some),
            None => Ok(None),
        }
    }

    async fn advance(&mut self, t_s: f64, tick: &mut Tick) -> Result<(), DeviceError> {
        tick.frames.clear();
        tick.t0_s = self.now_s();
        let wall = ((t_s - self.now_s()) / self.time_scale).max(0.0);
        let deadline = tokio::time::sleep(Duration::from_secs_f64(wall));
        tokio::pin!(deadline);
        tick.slots
            .resize_with(self.slot_geometries.len(), Default::default);
        for s in &mut tick.slots {
            s.frames.clear();
        }
        if let Some(e) = self.lost.take() {
            return Err(self.cause_of(e).await);
        }
        let batch = self.batch;
        loop {
            tokio::select! {
                f = self.frames.recv() => match f {
                    Some((0, Ok(f))) => tick.frames.push(f),
                    Some((k, Ok(f))) => {
                        if let Some(s) = tick.slots.get_mut(k - 1) {
                            s.frames.push(f);
                        }
                    }
                    // A batch goes on without the unit; its records say
                    // what it lost.
                    Some((k, Err(e))) if batch => self.unit_faults.push((k, e.to_string())),
                    Some((_, Err(e))) => return Err(self.cause_of(e).await),
                    // Every link's reader has ended (each said why): no
                    // unit is left to read.
                    None if batch => return Err(every_link_lost()),
                    None => return Err(gyro_stream_ended("gyro")),
                },
                () = &mut deadline => break,
            }
        }
        let now = self.now_s();
        self.step_ramp(now).await?;
        let chamber = self.chamber.read().await?;
        self.last_air_c = chamber.air_c;
        let table = self.table.read().await?;
        let power = self.read_power().await?;
        // The frames' mean reads the tick's mean of the turning reference:
        // from the table read at the last tick's end (none after an idle
        // wait, or a gap longer than two ticks: a prompt, a failed tick)
        // to this one.
        let end = (table.angles, table.rates);
        let from = self
            .last_pose
            .replace((now, end))
            .filter(|(t, _)| now - t <= POSE_GAP_S);
        let reference = |g: &TableGeometry| match from {
            Some((t, from)) => g.mean_kinematic_rate_dph(&self.site, from, end, now - t),
            None => g.kinematic_rate_dph(&self.site, table.angles, table.rates),
        };
        let reference_dph = reference(&self.geometry);
        for (s, g) in tick.slots.iter_mut().zip(&self.slot_geometries) {
            s.orientation = g.orientation(table.angles);
            s.reference_dph = reference(g);
        }
        tick.state = Some(BenchState {
            t_s: now,
            orientation: self.geometry.orientation(table.angles),
            reference_dph,
            in_position: at_rest_on(&table, self.commanded),
            chamber,
            table,
            commanded: self.commanded,
            power,
        });
        Ok(())
    }

    fn link_stats(&self) -> LinkStats {
        self.slot_link_stats(0)
    }

    fn units(&self) -> usize {
        self.stats.len()
    }

    fn status_bits(&self, slot: usize) -> crate::protocol::frame::StatusBits {
        self.status_bits.get(slot).copied().unwrap_or_default()
    }

    fn slot_link_stats(&self, slot: usize) -> LinkStats {
        self.stats.get(slot).map_or_else(LinkStats::default, |s| {
            s.lock().map_or_else(|p| *p.into_inner(), |s| *s)
        })
    }

    fn take_unit_faults(&mut self) -> Vec<(usize, String)> {
        std::mem::take(&mut self.unit_faults)
    }

    async fn idle(
        &mut self,
        t_s: f64,
    ) -> Result<(crate::driver::ChamberReading, crate::driver::TableReading), DeviceError> {
        self.last_pose = None;
        let wall = ((t_s - self.now_s()) / self.time_scale).max(0.0);
        tokio::time::sleep(Duration::try_from_secs_f64(wall).unwrap_or(Duration::ZERO)).await;
        // Frames that arrive now are not the run's: dropped, so the
        // channel never fills.
        while let Ok((k, f)) = self.frames.try_recv() {
            match f {
                Err(e) if self.batch => self.unit_faults.push((k, e.to_string())),
                Err(e) => self.lost = Some(e),
                Ok(_) => {}
            }
        }
        let now = self.now_s();
        self.step_ramp(now).await?;
        let chamber = self.chamber.read().await?;
        self.last_air_c = chamber.air_c;
        let table = self.table.read().await?;
        Ok((chamber, table))
    }

    fn pending_s(&self) -> f64 {
        self.ramp.map_or(0.0, |r| r.remaining_s(self.now_s()))
    }

    async fn read_back(
        &mut self,
    ) -> Result<(crate::driver::ChamberReading, crate::driver::TableReading), DeviceError> {
        let chamber = self.chamber.read().await?;
        let table = self.table.read().await?;
        Ok((chamber, table))
    }

    fn link_watch(&self) -> Option<Arc<crate::driver::LinkWatch>> {
        Some(self.watch.clone())
    }

    async fn identify(&mut self) -> super::Identities {
        let supply = match self.supply.as_mut() {
            Some((p, _)) => Some(p.identify().await.map_err(|e| e.to_string())),
            None => None,
        };
        super::Identities {
            chamber: self.chamber.identify().await.map_err(|e| e.to_string()),
            table: self.table.identify().await.map_err(|e| e.to_string()),
            supply,
        }
    }
}
