//! Simulated instruments that speak the real protocols, driven by the twin.
//!
//! One [`SimBench`] holds the twin and each instrument's own state (chamber
//! mode and alarm limits, table servo modes, interlocks and error queue);
//! [`SharedBench`] advances it to the clock's time before every request and
//! on a ticker that streams gyro frames. Servers for each protocol run over
//! any byte stream (TCP, pty, in-memory duplex). Every device can be told
//! to misbehave through [`Faults`].

pub mod acl;
pub mod embedded;
pub mod espec;
pub mod faults;
pub mod gyro;
mod lines;
pub mod link_bench;
pub mod serve;
pub mod supply;
pub mod watlow;

use std::sync::{Arc, Mutex, MutexGuard};

use tokio::sync::broadcast;

pub use faults::{Action, DeviceFaults, Fault, FaultSpecError, Faults, GyroFaults, Unplayable};

use crate::clock::Clock;
use crate::protocol::acl::ServoMode;
use crate::protocol::espec::Mode;
use crate::protocol::frame::{FrameLayout, WireFrame};
use crate::protocol::scpi::ScpiError;
use crate::twin::{Twin, TwinConfig};

/// Passive drift of the chamber air towards the room when it is not
/// controlling (standby or off), degC/min (ours).
pub const PASSIVE_DRIFT_C_PER_MIN: f64 = 0.5;

/// How the simulated instruments answer their identity queries: as their
/// instruments do, in their formats, naming themselves as simulators (the
/// embedded bench reports the same).
pub mod identity {
    use crate::protocol::{Identity, acl, espec, watlow};

    /// Espec `TYPE?`.
    pub const ESPEC_TYPE: &str = "SCP-220,TEMP";
    /// Espec `ROM?`.
    pub const ESPEC_ROM: &str = concat!("GYROBENCH-SIM,", env!("CARGO_PKG_VERSION"));
    /// ACL `*IDN?`: maker, model, serial, firmware.
    pub const ACL_IDN: &str = concat!(
        "gyrobench,ACL two-axis simulator,SIM-TABLE,",
        env!("CARGO_PKG_VERSION")
    );
    /// Watlow F4T part number.
    pub const WATLOW_PART_NUMBER: &str = "F4T1L1AA1A1SIMA";

    /// True when `id` is one of these simulators' answers (a run's
    /// instruments that say so ran on `sim serve`, not on hardware).
    pub fn is_simulator(id: &Identity) -> bool {
        [ESPEC_ROM, "SIM-TABLE", WATLOW_PART_NUMBER]
            .iter()
            .any(|mark| {
                let mark = mark.split(',').next().unwrap_or(mark);
                id.raw.contains(mark)
            })
    }

    /// The simulated chamber's identity over `protocol`.
    pub fn chamber(protocol: crate::bench::ChamberProtocol) -> Identity {
        match protocol {
            crate::bench::ChamberProtocol::EspecAscii => {
                espec::parse_identity(ESPEC_TYPE, ESPEC_ROM)
            }
            crate::bench::ChamberProtocol::WatlowF4tModbus => watlow::parse_identity(
                &watlow::encode_string(WATLOW_PART_NUMBER, usize::from(watlow::PART_NUMBER_LEN)),
            ),
        }
    }

    /// The simulated table's identity.
    pub fn table() -> Identity {
        acl::parse_identity(ACL_IDN)
    }
}

/// Chamber alarm codes raised by the simulator itself.
pub mod alarm {
    /// Air above the upper alarm limit.
    pub const UPPER_LIMIT: u16 = 1;
    /// Air below the lower alarm limit.
    pub const LOWER_LIMIT: u16 = 2;
    /// The alarm [`super::faults::Fault::ChamberAlarm`] raises (the
    /// embedded bench's too).
    pub const INJECTED: u16 = 9;
}

/// Chamber controller state beyond the twin's air model.
#[derive(Debug, Clone)]
pub struct ChamberState {
    /// Operating mode.
    pub mode: Mode,
    /// Constant set point, degC.
    pub set_point_c: f64,
    /// Upper alarm limit, degC.
    pub upper_c: f64,
    /// Lower alarm limit, degC.
    pub lower_c: f64,
    /// Alarms injected by a test or an operator.
    pub injected_alarms: Vec<u16>,
}

/// Motion-simulator state beyond the twin's axis dynamics.
#[derive(Debug, Clone)]
pub struct TableState {
    /// Servo mode per axis (outer, inner).
    pub mode: [ServoMode; 2],
    /// Interlock closed (servo on) per axis.
    pub closed: [bool; 2],
    /// System interlock tripped (needs `:INT:RESET`).
    pub tripped: bool,
    /// SCPI error queue, oldest first.
    pub errors: std::collections::VecDeque<ScpiError>,
}

/// The simulated bench: twin plus instrument state.
#[derive(Debug)]
pub struct SimBench {
    /// The physics.
    pub twin: Twin,
    /// Gyro frame layout on the wire.
    pub layout: FrameLayout,
    /// Chamber controller.
    pub chamber: ChamberState,
    /// Motion simulator.
    pub table: TableState,
    /// The unit's power supply (a batch's fixture: every unit's).
    pub supply: supply::Supply,
    gyro_tx: broadcast::Sender<GyroChunk>,
    out: Vec<u8>,
    /// A batch's further units, after the first (`twin`): each its own
    /// twin in the same air, on the same table, on its own gyro line.
    pub units: Vec<SimUnit>,
    /// Counts the first unit's gyro sends in every frame instead of its
    /// own: a stuck or saturated output ([`faults::Fault::GyroStuck`],
    /// [`faults::Fault::GyroSaturated`]).
    pub forced_counts: Option<i32>,
    /// The unit shorted: it draws three times its current
    /// ([`faults::Fault::SupplyOvercurrent`]).
    pub shorted: bool,
}

/// One more unit of a simulated batch: its own twin (its parameters, its
/// noise streams, its mount) and its own gyro line.
#[derive(Debug)]
pub struct SimUnit {
    /// The slot it sits in.
    pub name: String,
    /// Its physics; every chamber and table command reaches it too.
    pub twin: Twin,
    gyro_tx: broadcast::Sender<GyroChunk>,
}

/// Gyro bytes encoded together, with the wall time they were made at (the
/// line drops what it could not send in time: [`gyro::serve_gyro`]).
#[derive(Debug, Clone)]
pub struct GyroChunk {
    /// When the frames were encoded.
    pub at: std::time::Instant,
    /// The encoded frames.
    pub bytes: Arc<Vec<u8>>,
}

impl SimBench {
    /// A bench around a fresh twin.
    pub fn new(cfg: TwinConfig, seed: u64, layout: FrameLayout) -> Self {
        let initial = cfg.chamber.initial_c;
        let (gyro_tx, _) = broadcast::channel(4096);
        Self {
            twin: Twin::new(cfg, seed),
            layout,
            chamber: ChamberState {
                mode: Mode::Constant,
                set_point_c: initial,
                upper_c: 100.0,
                lower_c: -60.0,
                injected_alarms: Vec::new(),
            },
            table: TableState {
                mode: [ServoMode::Position; 2],
                closed: [true; 2],
                tripped: false,
                errors: Default::default(),
            },
            supply: supply::Supply::powering_unit(crate::protocol::supply::Dialect::default()),
            gyro_tx,
            out: Vec::new(),
            units: Vec::new(),
            forced_counts: None,
            shorted: false,
        }
    }

    /// Add a batch's further unit in slot `name`: twin `cfg` (whose
    /// chamber and table are taken to be this bench's) seeded `seed`.
    #[must_use]
    pub fn with_unit(mut self, name: &str, cfg: TwinConfig, seed: u64) -> Self {
        let mut twin = Twin::new(cfg, seed);
        twin.set_powered(self.twin.is_powered());
        let (gyro_tx, _) = broadcast::channel(4096);
        self.units.push(SimUnit {
            name: name.to_owned(),
            twin,
            gyro_tx,
        });
        self
    }

    /// Every twin: the first unit's, then a batch's others. The chamber
    /// and table commands go to each, so they share one air and one table.
    pub(crate) fn twins_mut(&mut self) -> impl Iterator<Item = &mut Twin> {
        std::iter::once(&mut self.twin).chain(self.units.iter_mut().map(|u| &mut u.twin))
    }

    /// Advance the physics to `t_s`, encoding every gyro frame.
    pub fn advance_to(&mut self, t_s: f64) {
        // The unit runs on the supply's power: the twin is run up to each
        // moment the power came or went, and switched there (and at once
        // when a command took it away between two advances: `*RST`).
        // A batch's fixture is fed by the one supply.
        self.set_powered(self.supply.unit_powered());
        while let Some(t_change) = self.supply.advance_until_change(t_s) {
            self.run_twins(t_change);
            self.set_powered(self.supply.unit_powered());
        }
        self.run_twins(t_s);
    }

    fn set_powered(&mut self, on: bool) {
        self.twins_mut().for_each(|t| t.set_powered(on));
    }

    fn run_twins(&mut self, t_s: f64) {
        let first = Line {
            layout: &self.layout,
            tx: &self.gyro_tx,
            forced_counts: self.forced_counts,
        };
        run_twin(&mut self.twin, &first, &mut self.out, t_s);
        for u in &mut self.units {
            let line = Line {
                layout: &self.layout,
                tx: &u.gyro_tx,
                forced_counts: None,
            };
            run_twin(&mut u.twin, &line, &mut self.out, t_s);
        }
    }

    /// Subscribe to the gyro's byte stream.
    pub fn subscribe_gyro(&self) -> broadcast::Receiver<GyroChunk> {
        self.gyro_tx.subscribe()
    }

    /// Subscribe to unit `unit`'s gyro line (0: the first unit's; none
    /// past the batch's units).
    pub fn subscribe_unit_gyro(&self, unit: usize) -> Option<broadcast::Receiver<GyroChunk>> {
        match unit.checked_sub(1) {
            None => Some(self.gyro_tx.subscribe()),
            Some(k) => self.units.get(k).map(|u| u.gyro_tx.subscribe()),
        }
    }

    /// Drive the table's axes (every unit's twin: one table).
    pub(crate) fn demand_table(
        &mut self,
        outer: Option<crate::twin::AxisDemand>,
        inner: Option<crate::twin::AxisDemand>,
    ) {
        self.twins_mut().for_each(|t| t.demand_table(outer, inner));
    }

    /// Chamber alarm codes active now (injected ones and limit alarms).
    pub fn chamber_alarms(&self) -> Vec<u16> {
        let mut codes = self.chamber.injected_alarms.clone();
        let air = self.twin.chamber_state().0;
        if air > self.chamber.upper_c {
            codes.push(alarm::UPPER_LIMIT);
        }
        if air < self.chamber.lower_c {
            codes.push(alarm::LOWER_LIMIT);
        }
        codes
    }

    /// Raise a chamber alarm (as a fault on the real unit would).
    pub fn raise_chamber_alarm(&mut self, code: u16) {
        self.chamber.injected_alarms.push(code);
    }

    /// Trip the table's system interlock: both axes stop and open.
    pub fn trip_interlock(&mut self) {
        self.table.tripped = true;
        self.table.closed = [false; 2];
        self.demand_table(
            Some(crate::twin::AxisDemand::Stop),
            Some(crate::twin::AxisDemand::Stop),
        );
    }
}

/// A unit's gyro line: its frame layout, where its bytes go, and the
/// counts a fault sends instead of the unit's own.
struct Line<'a> {
    layout: &'a FrameLayout,
    tx: &'a broadcast::Sender<GyroChunk>,
    forced_counts: Option<i32>,
}

/// Run `twin` to `t_s`, encoding its frames (through the scratch buffer
/// `out`) onto its `line`.
fn run_twin(twin: &mut Twin, line: &Line<'_>, out: &mut Vec<u8>, t_s: f64) {
    let (layout, tx) = (line.layout, line.tx);
    twin.run_until(t_s, |_, g| {
        let wf = WireFrame {
            frame_type: layout.frame_type,
            seq: (g.index % 256) as u8,
            delta_counts: line.forced_counts.unwrap_or(g.delta_counts),
            temps_raw: [
                layout.temp_to_raw(g.t1_c),
                layout.temp_to_raw(g.t2_c),
                layout.temp_to_raw(g.tcase_c),
            ],
            status: g.status,
        };
        layout.encode(&wf, out);
    });
    if !out.is_empty() {
        let bytes = std::mem::take(out);
        // No subscriber = nobody on the cable: the bytes are gone.
        let _ = tx.send(GyroChunk {
            at: std::time::Instant::now(),
            bytes: Arc::new(bytes),
        });
    }
}

/// The default RL-16 bench with seed 1, for the simulators' unit tests.
#[cfg(test)]
pub(crate) fn test_bench() -> SimBench {
    SimBench::new(TwinConfig::default_rl16(), 1, FrameLayout::default())
}

/// A [`SimBench`] shared by the servers, kept at the clock's time.
pub struct SharedBench {
    bench: Mutex<SimBench>,
    clock: Arc<dyn Clock>,
    /// Fault injection for every device.
    pub faults: Faults,
}

impl std::fmt::Debug for SharedBench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SharedBench").finish_non_exhaustive()
    }
}

impl SharedBench {
    /// Share `bench`, advanced by `clock`.
    pub fn new(bench: SimBench, clock: Arc<dyn Clock>) -> Arc<Self> {
        Arc::new(Self {
            bench: Mutex::new(bench),
            clock,
            faults: Faults::default(),
        })
    }

    /// Lock the bench, brought up to the clock's time.
    pub fn lock(&self) -> MutexGuard<'_, SimBench> {
        let mut b = self.bench.lock().unwrap_or_else(|p| p.into_inner());
        b.advance_to(self.clock.now_s());
        b
    }

    /// The clock the bench follows.
    pub fn clock(&self) -> &Arc<dyn Clock> {
        &self.clock
    }

    /// Play `fault` from now on, as the embedded bench plays it, on the
    /// devices' wire protocols: the chamber raises alarm 9 or goes silent,
    /// the table's interlock trips, the gyro line goes silent, corrupts a
    /// frame in 50, sticks or saturates, a batch's last unit's line goes
    /// silent for good, the unit draws three times its current. A fault
    /// of the controller itself ([`Fault::device`] `None`) is refused, as
    /// is `unit-lost` on a bench of one unit. A fault played again changes
    /// nothing (one alarm 9, one short); a saturated output stays
    /// saturated when a stuck one is played too, as on the embedded bench.
    pub fn play(&self, fault: Fault) -> Result<(), faults::Unplayable> {
        use std::sync::atomic::Ordering::Relaxed;
        let mut b = self.lock();
        match fault {
            Fault::ChamberAlarm if b.chamber.injected_alarms.contains(&alarm::INJECTED) => {}
            Fault::ChamberAlarm => b.raise_chamber_alarm(alarm::INJECTED),
            Fault::ChamberSilent => self.faults.chamber.silent.store(true, Relaxed),
            Fault::TableInterlock => b.trip_interlock(),
            Fault::GyroSilent => self.faults.gyro.silent.store(true, Relaxed),
            Fault::GyroCorrupt => {
                let frame = u32::try_from(b.layout.len()).unwrap_or(u32::MAX);
                let every = faults::CORRUPT_EVERY_FRAMES.saturating_mul(frame);
                self.faults.gyro.corrupt_every.store(every, Relaxed);
            }
            Fault::GyroStuck if b.forced_counts == Some(faults::SATURATED_COUNTS) => {}
            Fault::GyroStuck => b.forced_counts = Some(faults::STUCK_COUNTS),
            Fault::GyroSaturated => b.forced_counts = Some(faults::SATURATED_COUNTS),
            Fault::UnitLost if b.units.is_empty() => {
                return Err(faults::Unplayable::OneUnit { example: None });
            }
            Fault::UnitLost => self.faults.gyro.lost_line.store(b.units.len(), Relaxed),
            Fault::SupplyOvercurrent if b.shorted => {}
            Fault::SupplyOvercurrent => {
                b.shorted = true;
                b.supply.load.0.steady_a *= 3.0;
            }
            Fault::SupplyIgnoresOff => b.supply.ignores_off = true,
            Fault::ProcessKill | Fault::Panic | Fault::DiskFull | Fault::Hangup | Fault::Quit => {
                return Err(faults::Unplayable::OfTheController {
                    fault,
                    served: None,
                });
            }
        }
        Ok(())
    }

    /// Keep the physics moving (and gyro frames flowing) every `period`
    /// until the bench is dropped elsewhere.
    pub fn spawn_ticker(
        self: &Arc<Self>,
        period: std::time::Duration,
    ) -> tokio::task::JoinHandle<()> {
        let weak = Arc::downgrade(self);
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(period);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
            loop {
                tick.tick().await;
                match weak.upgrade() {
                    Some(b) => drop(b.lock()),
                    None => return,
                }
            }
        })
    }
}
