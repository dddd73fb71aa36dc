//! The bench configuration (`bench.toml`, documented in `docs/bench.md`):
//! site, table geometry, devices by spec string, timeouts, safety limits;
//! and opening the configured devices.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::config::{Checker, ConfigError, Source};
use crate::driver::acl::AclTable;
use crate::driver::espec::EspecChamber;
use crate::driver::gyro::GyroReader;
use crate::driver::link::{Connector, LineLink, LinkWatch};
use crate::driver::supply::ScpiSupply;
use crate::driver::watlow::WatlowChamber;
use crate::driver::{Chamber, DeviceError, MotionTable, RetryPolicy};
use crate::geometry::{Site, TableGeometry};
use crate::protocol::frame::FrameLayout;
use crate::transport::{BoxTransport, DeviceSpec, open};

/// A whole bench.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BenchConfig {
    /// Where the bench stands.
    pub site: Site,
    /// Geometry of the motion simulator and the gyro mount.
    pub table: TableSection,
    /// The instruments.
    pub devices: Devices,
    /// Safety limits of the bench, enforced before any command is sent.
    pub limits: Limits,
    /// Device time per wall time: 1 for real instruments; N when the
    /// devices are `sim serve --config` endpoints running at speed N.
    #[serde(default = "unit_scale")]
    pub time_scale: f64,
    /// Where this bench records its results (`docs/results.md`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub results: Option<ResultsSection>,
    /// The bench's name in every record of its runs (default: the bench
    /// file's name without `.toml`; `embedded` for the embedded bench).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    /// What a run does when an instrument is past its calibration due
    /// date: `warn` (the default: the verdict line and the report say so)
    /// or `refuse` (the run does not start).
    #[serde(default, skip_serializing_if = "OverduePolicy::is_warn")]
    pub overdue_calibration: OverduePolicy,
    /// What a batch does when one of its units cannot be judged (its link
    /// lost, its data unsound): `continue` (the default: that unit ends in
    /// error, the others go on) or `stop` (the whole batch stops, the
    /// bench to its safe state).
    #[serde(default, skip_serializing_if = "OnUnitError::is_continue")]
    pub on_unit_error: OnUnitError,
    /// The units' places on the table's platform, in the bench's order
    /// (none: one unit, mounted as `[table.geometry] mount` says). A bench
    /// with slots runs a batch: one procedure, every unit.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub slots: Vec<Slot>,
    /// The bench's own Type B contributions to its figures' uncertainty,
    /// each with its source (`[uncertainty]`, `docs/bench.md`).
    #[serde(default, skip_serializing_if = "crate::typeb::TypeB::is_empty")]
    pub uncertainty: crate::typeb::TypeB,
}

/// `on_unit_error`: a batch goes on without a unit that cannot be judged,
/// or stops.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnUnitError {
    /// The unit ends in error; the others go on.
    #[default]
    Continue,
    /// The batch stops for every unit.
    Stop,
}

impl OnUnitError {
    fn is_continue(&self) -> bool {
        *self == Self::Continue
    }
}

/// `[[slots]]`: one unit's place on the table's platform.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Slot {
    /// The slot's name (`A`, `B`, `X`, ...), given with `--dut NAME=SERIAL`.
    pub name: String,
    /// The unit's body orientation in NED with both table angles at zero,
    /// as `[table.geometry] mount` gives it (default: that mount). The
    /// table turns every slot together, so the slots keep their angles to
    /// one another: that is the mount relative to the platform.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mount: Option<crate::geometry::Orientation>,
    /// The embedded bench: the seed of this slot's twin (default: the
    /// run's seed plus the slot's index), its own noise streams and
    /// turn-on bias.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// The embedded bench: this slot's twin file, relative to the bench
    /// file (default: the run's twin), its own parameters and effects.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub twin: Option<String>,
    /// A real bench: this slot's gyro link (default: `[devices.gyro]`'s,
    /// which one slot at most may read).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro: Option<SlotGyro>,
}

/// `[slots.gyro]`: one unit's own gyro link. Its frame rate, resolution,
/// silence and reconnect window are `[devices.gyro]`'s: a batch's units
/// are read at one rate, into one set of records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlotGyro {
    /// Where it is (`tcp://...`, a serial port, `pty://...`).
    pub spec: String,
    /// Its frame layout (default: `[devices.gyro]`'s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<FrameLayout>,
}

/// Most slots a bench may declare (ours: the largest fixtures labs build
/// hold four to six units; eight leaves room and bounds a typo).
pub const MAX_SLOTS: usize = 8;

impl Slot {
    /// A slot name: 1-16 ASCII letters, digits, `-` or `_` (it names log
    /// channels, files and command-line arguments).
    pub fn valid_name(name: &str) -> bool {
        (1..=16).contains(&name.len())
            && name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
    }
}

/// `overdue_calibration`: a run on an instrument past its calibration due
/// date is flagged, or refused.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OverduePolicy {
    /// Run, and flag it in the verdict line and the report.
    #[default]
    Warn,
    /// Do not start.
    Refuse,
}

impl OverduePolicy {
    fn is_warn(&self) -> bool {
        *self == Self::Warn
    }
}

/// A calibration due date (`calibration_due = 2027-03-31`, a TOML date or
/// a `"YYYY-MM-DD"` string).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CalibrationDue(pub chrono::NaiveDate);

impl std::fmt::Display for CalibrationDue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0.format("%Y-%m-%d"))
    }
}

impl Serialize for CalibrationDue {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> Deserialize<'de> for CalibrationDue {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let expected = "a date, e.g. 2027-03-31";
        let date = match toml::Value::deserialize(d)? {
            toml::Value::Datetime(dt) => match (dt.date, dt.time) {
                (Some(date), None) => chrono::NaiveDate::from_ymd_opt(
                    i32::from(date.year),
                    u32::from(date.month),
                    u32::from(date.day),
                ),
                _ => None,
            },
            toml::Value::String(s) => chrono::NaiveDate::parse_from_str(s.trim(), "%Y-%m-%d").ok(),
            _ => None,
        };
        date.map(Self)
            .ok_or_else(|| D::Error::custom(format!("expected {expected}")))
    }
}

pub use gyrobench_model::instrument::Instrument;

/// `[results]`: the results store of this bench.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResultsSection {
    /// The store: a SQLite file path, a `postgres://` URL, or `none`
    /// (`$GYROBENCH_DB` and `--db` come first).
    #[serde(default)]
    pub db: Option<String>,
    /// The name this bench PC records its runs under (default: its host
    /// name).
    #[serde(default)]
    pub station: Option<String>,
}

fn unit_scale() -> f64 {
    1.0
}

fn reconnect_window_s() -> f64 {
    crate::driver::RECONNECT_WINDOW.as_secs_f64()
}

/// `[table]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableSection {
    /// Axis directions and mount.
    pub geometry: TableGeometry,
}

/// `[devices.*]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Devices {
    /// Climatic chamber.
    pub chamber: ChamberDevice,
    /// Two-axis motion simulator.
    pub table: TableDevice,
    /// Gyro digital output.
    pub gyro: GyroDevice,
    /// The unit's programmable supply (none: the unit is powered by hand).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply: Option<SupplyDevice>,
}

/// What the supply's output is left as when a run ends in the bench's safe
/// state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SupplySafe {
    /// Output off: the unit unpowered (the usual safe state).
    #[default]
    Off,
    /// Output left on: a unit that must stay powered (a heated unit, a
    /// unit whose turn-on is itself a stress).
    On,
}

/// `[devices.supply]`: the programmable DC supply powering the unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SupplyDevice {
    /// Where it is: `tcp://host:5025`, `serial://...`, `pty://...`,
    /// `sim://supply`.
    pub spec: String,
    /// Whose SCPI commands it takes: `keysight-e36300` or `rigol-dp800`.
    pub protocol: crate::protocol::supply::Dialect,
    /// The output the unit hangs on (1-based).
    pub channel: u8,
    /// The unit's supply voltage, V.
    pub volts: f64,
    /// Current limit, A (a Rigol trips at once when it is reached: it must
    /// clear the unit's turn-on inrush).
    pub limit_a: f64,
    /// Over-current protection: the output goes off when held at the limit.
    #[serde(default = "yes")]
    pub protection: bool,
    /// Highest voltage a `power` step may ask, V (default `volts`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_volts: Option<f64>,
    /// Highest current limit a `power` step may ask, A (default `limit_a`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_limit_a: Option<f64>,
    /// The output in the bench's safe state: `off` (default) or `on`.
    #[serde(default)]
    pub safe_state: SupplySafe,
    /// Reply timeout per attempt, s.
    pub timeout_s: f64,
    /// Attempts per request.
    pub attempts: u32,
    /// How long a dropped link is reopened before the supply is declared
    /// unreachable, s (default 180).
    #[serde(default = "reconnect_window_s")]
    pub reconnect_window_s: f64,
    /// When the supply's calibration is due (`docs/bench.md`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_due: Option<CalibrationDue>,
}

fn yes() -> bool {
    true
}

impl SupplyDevice {
    /// Highest voltage a step may ask, V.
    pub fn max_volts(&self) -> f64 {
        self.max_volts.unwrap_or(self.volts)
    }

    /// Highest current limit a step may ask, A.
    pub fn max_limit_a(&self) -> f64 {
        self.max_limit_a.unwrap_or(self.limit_a)
    }
}

/// Chamber protocols.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ChamberProtocol {
    /// Espec P300 / SCP-220 ASCII.
    EspecAscii,
    /// Watlow F4T over Modbus TCP.
    WatlowF4tModbus,
}

/// `[devices.chamber]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChamberDevice {
    /// Where it is: `serial://...`, `tcp://...`, `pty://...`, `sim://chamber`.
    pub spec: String,
    /// Which protocol it speaks.
    pub protocol: ChamberProtocol,
    /// RS-485 address (Espec only).
    #[serde(default)]
    pub address: Option<u8>,
    /// Reply timeout per attempt, s.
    pub timeout_s: f64,
    /// Attempts per request before the device is declared failed.
    pub attempts: u32,
    /// When the chamber's sensor calibration is due (`docs/bench.md`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_due: Option<CalibrationDue>,
    /// How long a dropped link is reopened (with backoff) before the
    /// device is declared unreachable, s (default 180).
    #[serde(default = "reconnect_window_s")]
    pub reconnect_window_s: f64,
}

/// `[devices.table]` (ACL language).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TableDevice {
    /// Where it is.
    pub spec: String,
    /// Reply timeout per attempt, s.
    pub timeout_s: f64,
    /// Attempts per request.
    pub attempts: u32,
    /// How long a dropped link is reopened before the device is declared
    /// unreachable, s (default 180).
    #[serde(default = "reconnect_window_s")]
    pub reconnect_window_s: f64,
    /// In-position tolerance, deg.
    pub in_position_deg: f64,
    /// Time within tolerance before "in position", s.
    pub settle_s: f64,
    /// When the table's encoder calibration is due (`docs/bench.md`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_due: Option<CalibrationDue>,
}

/// `[devices.gyro]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GyroDevice {
    /// Where it is.
    pub spec: String,
    /// Frames per second the unit sends, Hz.
    pub frame_rate_hz: f64,
    /// Angle per count, arcsec.
    pub lsb_arcsec: f64,
    /// No valid frame for this long is a failure, s.
    pub silence_s: f64,
    /// How long a dropped link is reopened before the gyro is declared
    /// unreachable, s (default 180).
    #[serde(default = "reconnect_window_s")]
    pub reconnect_window_s: f64,
    /// Frame layout (default: the documented 20-byte frame).
    #[serde(default)]
    pub frame: Option<FrameLayout>,
}

pub use gyrobench_model::limits::Limits;

/// The largest travel a table limit may name, deg: ten turns either way (a
/// position-mode axis with slip rings); beyond is a slip of the keyboard.
pub const MAX_TRAVEL_DEG: f64 = 3600.0;

/// How much later than its neighbours a frame may reach the host, wall
/// time, s (ours): what a record's frame count allows at its ends
/// ([`BenchConfig::record_edge_s`]).
pub const HOST_DELAY_S: f64 = 0.05;

/// The embedded simulated bench (`fixtures/bench/embedded.toml`).
pub const EMBEDDED_BENCH_TOML: &str = include_str!("../fixtures/bench/embedded.toml");

impl BenchConfig {
    /// What a procedure is checked against on this bench: its limits, its
    /// table's geometry and settling, its supply's values and limits.
    pub fn procedure_limits(&self) -> gyrobench_model::limits::BenchLimits {
        gyrobench_model::limits::BenchLimits {
            limits: self.limits.clone(),
            geometry: self.table.geometry,
            table_settle_s: self.devices.table.settle_s,
            supply: self
                .devices
                .supply
                .as_ref()
                .map(|p| gyrobench_model::limits::SupplyLimits {
                    volts: p.volts,
                    limit_a: p.limit_a,
                    max_volts: p.max_volts(),
                    max_limit_a: p.max_limit_a(),
                }),
        }
    }

    /// The embedded simulated bench, used when no bench file is given.
    pub fn embedded() -> Self {
        // A unit test loads the embedded file, so this cannot fail.
        match Self::from_source(&Source::from_text(
            "fixtures/bench/embedded.toml",
            EMBEDDED_BENCH_TOML,
        )) {
            Ok(b) => b,
            Err(e) => unreachable!("embedded bench is invalid: {e}"),
        }
    }

    /// Device time by which a record's ends may fall off its frames, s: a
    /// record spans the host's clock and takes the frames that reach the
    /// host meanwhile, late by the link's varying delay (a USB serial
    /// adapter's latency timer, 16 ms by default on FTDI chips; the host's
    /// scheduling; `sim serve`'s 5 ms ticks), and at `time_scale` N that
    /// delay is N times more device time. [`HOST_DELAY_S`] of it on wall
    /// time; none for the embedded gyro, whose frames are made on the
    /// run's own clock. Frames lost inside a record show as gaps of the
    /// sequence counter, which this does not excuse.
    pub fn record_edge_s(&self) -> f64 {
        if self.devices.gyro.spec.starts_with("sim://") {
            0.0
        } else {
            HOST_DELAY_S * self.time_scale
        }
    }

    /// True when every device is the embedded simulator.
    pub fn is_embedded(&self) -> bool {
        [
            &self.devices.chamber.spec,
            &self.devices.table.spec,
            &self.devices.gyro.spec,
        ]
        .into_iter()
        .chain(self.devices.supply.as_ref().map(|s| &s.spec))
        .all(|s| s.starts_with("sim://"))
    }

    /// Read and validate a bench file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::from_source(&Source::read(path)?)
    }

    /// Parse and validate bench text.
    pub fn from_source(src: &Source) -> Result<Self, ConfigError> {
        let cfg: Self = src.parse()?;
        cfg.validate(src)?;
        Ok(cfg)
    }

    fn validate(&self, src: &Source) -> Result<(), ConfigError> {
        let c = Checker::new(src);
        c.within(self.time_scale, 0.001, 1e4, "time_scale")?;
        if let Some(id) = &self.id {
            c.ensure(
                crate::unit::check_serial(id).is_ok(),
                "id",
                "must be 1 to 64 printable characters",
            )?;
        }
        self.site.validate(&c, "site")?;
        self.table.geometry.validate(&c, "table.geometry")?;
        self.validate_slots(&c)?;
        self.validate_devices(&c, src)?;
        self.uncertainty.validate(&c)?;
        self.validate_limits(&c)
    }

    /// `[devices]`: each spec, timeouts, attempts, windows, the supply and
    /// the gyro's frame.
    fn validate_devices(&self, c: &Checker, src: &Source) -> Result<(), ConfigError> {
        let d = &self.devices;
        for (key, spec, role) in [
            ("devices.chamber.spec", &d.chamber.spec, "chamber"),
            ("devices.table.spec", &d.table.spec, "table"),
            ("devices.gyro.spec", &d.gyro.spec, "gyro"),
        ] {
            spec.parse::<DeviceSpec>()
                .map_err(|e| src.invalid(key, e.to_string()))?;
            // The embedded simulator has one device of each kind, by name.
            if let Some(name) = spec.strip_prefix("sim://") {
                c.ensure(
                    name == role,
                    key,
                    &format!(
                        "{spec:?} is not the embedded simulator's {role}; the {role} there is \"sim://{role}\""
                    ),
                )?;
            }
        }
        c.within(d.chamber.timeout_s, 0.01, 60.0, "devices.chamber.timeout_s")?;
        c.ensure(
            (1..=20).contains(&d.chamber.attempts),
            "devices.chamber.attempts",
            "must be 1 to 20",
        )?;
        c.within(d.table.timeout_s, 0.01, 60.0, "devices.table.timeout_s")?;
        c.ensure(
            (1..=20).contains(&d.table.attempts),
            "devices.table.attempts",
            "must be 1 to 20",
        )?;
        c.within(
            d.table.in_position_deg,
            1e-6,
            10.0,
            "devices.table.in_position_deg",
        )?;
        c.within(d.table.settle_s, 0.0, 600.0, "devices.table.settle_s")?;
        c.within(
            d.gyro.frame_rate_hz,
            1.0,
            100_000.0,
            "devices.gyro.frame_rate_hz",
        )?;
        c.within(d.gyro.lsb_arcsec, 1e-6, 100.0, "devices.gyro.lsb_arcsec")?;
        c.within(d.gyro.silence_s, 0.01, 600.0, "devices.gyro.silence_s")?;
        for (v, key) in [
            (
                d.chamber.reconnect_window_s,
                "devices.chamber.reconnect_window_s",
            ),
            (
                d.table.reconnect_window_s,
                "devices.table.reconnect_window_s",
            ),
            (d.gyro.reconnect_window_s, "devices.gyro.reconnect_window_s"),
        ] {
            c.within(v, 0.0, 3600.0, key)?;
        }
        if let Some(p) = &d.supply {
            Self::validate_supply(c, src, p)?;
        }
        if let Some(layout) = &d.gyro.frame {
            layout
                .validate()
                .map_err(|e| src.invalid("devices.gyro.frame", e.to_string()))?;
        }
        Ok(())
    }

    /// `[limits]`: the chamber's and the table's, and the unit's.
    fn validate_limits(&self, c: &Checker) -> Result<(), ConfigError> {
        let l = &self.limits;
        c.within(l.chamber_min_c, -100.0, 300.0, "limits.chamber_min_c")?;
        c.within(l.chamber_max_c, -100.0, 300.0, "limits.chamber_max_c")?;
        c.ensure(
            l.chamber_max_c > l.chamber_min_c,
            "limits.chamber_max_c",
            "must be above limits.chamber_min_c",
        )?;
        // Upper bounds are what no chamber or motion simulator reaches: a
        // value beyond them is a slip of the keyboard, not a limit.
        c.positive(
            l.chamber_max_ramp_c_per_min,
            "limits.chamber_max_ramp_c_per_min",
        )?;
        c.within(
            l.chamber_max_ramp_c_per_min,
            0.0,
            100.0,
            "limits.chamber_max_ramp_c_per_min",
        )?;
        for (r, key) in [
            (l.outer_range_deg, "limits.outer_range_deg"),
            (l.inner_range_deg, "limits.inner_range_deg"),
        ] {
            c.ensure(
                r.iter().all(|v| v.is_finite() && v.abs() <= MAX_TRAVEL_DEG) && r[0] < r[1],
                key,
                &format!(
                    "must be [min, max] with min below max, each within +-{MAX_TRAVEL_DEG} deg (ten turns)"
                ),
            )?;
        }
        c.positive(l.table_max_rate_dps, "limits.table_max_rate_dps")?;
        c.positive(l.table_max_acc_dps2, "limits.table_max_acc_dps2")?;
        c.within(
            l.table_max_rate_dps,
            0.0,
            5000.0,
            "limits.table_max_rate_dps",
        )?;
        c.within(
            l.table_max_acc_dps2,
            0.0,
            100_000.0,
            "limits.table_max_acc_dps2",
        )?;
        if let Some(r) = l.table_rate_mode_max_dps {
            c.within(r, 1e-6, 5000.0, "limits.table_rate_mode_max_dps")?;
        }
        if let Some(a) = l.table_rate_mode_max_acc_dps2 {
            c.within(a, 1e-6, 100_000.0, "limits.table_rate_mode_max_acc_dps2")?;
        }
        c.within(l.dut_max_c, -100.0, 300.0, "limits.dut_max_c")?;
        Ok(())
    }

    fn validate_slots(&self, c: &Checker) -> Result<(), ConfigError> {
        c.ensure(
            self.slots.len() <= MAX_SLOTS,
            "slots",
            &format!("a bench holds at most {MAX_SLOTS} slots"),
        )?;
        for (i, slot) in self.slots.iter().enumerate() {
            let key = format!("slots.{i}");
            c.ensure(
                Slot::valid_name(&slot.name),
                &format!("{key}.name"),
                "must be 1 to 16 letters, digits, '-' or '_'",
            )?;
            c.ensure(
                !self.slots[..i].iter().any(|s| s.name == slot.name),
                &format!("{key}.name"),
                &format!("slot {:?} is declared twice", slot.name),
            )?;
            if let Some(m) = &slot.mount {
                let mut g = self.table.geometry;
                g.mount = *m;
                g.validate(c, &key)?;
            }
            for (given, name) in [(slot.seed.is_some(), "seed"), (slot.twin.is_some(), "twin")] {
                c.ensure(
                    !given || self.is_embedded(),
                    &format!("{key}.{name}"),
                    &format!("a slot's {name} is the embedded bench's (sim:// devices)"),
                )?;
            }
            if let Some(g) = &slot.gyro {
                c.ensure(
                    !self.is_embedded(),
                    &format!("{key}.gyro"),
                    "the embedded bench simulates each slot's unit: its slots name no gyro link",
                )?;
                let spec_key = format!("{key}.gyro.spec");
                if let Err(e) = g.spec.parse::<DeviceSpec>() {
                    c.ensure(false, &spec_key, &e.to_string())?;
                }
                c.ensure(
                    !g.spec.starts_with("sim://"),
                    &spec_key,
                    "a slot's gyro is a real link (tcp://, pty:// or a serial port)",
                )?;
                if let Some(frame) = &g.frame {
                    let key = format!("{key}.gyro.frame");
                    if let Err(e) = frame.validate() {
                        c.ensure(false, &key, &e.to_string())?;
                    }
                    // Every unit's temperatures are read at one scale.
                    let bench = self.frame_layout().temp_lsb_c;
                    c.ensure(
                        frame.temp_lsb_c == bench,
                        &format!("{key}.temp_lsb_c"),
                        &format!(
                            "must be [devices.gyro]'s ({bench} degC): a batch's units are read at one temperature scale"
                        ),
                    )?;
                }
            }
            if !self.is_embedded() {
                let spec = self.slot_gyro_spec(slot);
                let first = self.slots[..i]
                    .iter()
                    .position(|s| self.slot_gyro_spec(s) == spec);
                c.ensure(
                    first.is_none(),
                    &format!("{key}.gyro"),
                    &match first {
                        Some(j) if slot.gyro.is_none() => format!(
                            "slots {:?} and {:?} would both read [devices.gyro]'s link: give every slot but one its own [slots.gyro] spec",
                            self.slots[j].name, slot.name
                        ),
                        Some(j) => format!(
                            "slot {:?} reads {spec:?} too: every unit needs its own link",
                            self.slots[j].name
                        ),
                        None => String::new(),
                    },
                )?;
            }
        }
        c.ensure(
            self.on_unit_error.is_continue() || !self.slots.is_empty(),
            "on_unit_error",
            "is a batch's: a bench without [[slots]] has one unit, whose error ends its run",
        )?;
        c.ensure(
            self.slots.is_empty() || self.devices.supply.is_none(),
            "devices.supply",
            "a bench with slots has no supply yet (one output per unit is to come): power its units by hand and leave out [devices.supply]",
        )?;
        Ok(())
    }

    /// The spec of the gyro link `slot`'s unit is read on.
    pub fn slot_gyro_spec<'a>(&'a self, slot: &'a Slot) -> &'a str {
        slot.gyro
            .as_ref()
            .map_or(self.devices.gyro.spec.as_str(), |g| g.spec.as_str())
    }

    /// The frame layout of `slot`'s gyro link.
    pub fn slot_frame_layout(&self, slot: &Slot) -> FrameLayout {
        slot.gyro
            .as_ref()
            .and_then(|g| g.frame.clone())
            .unwrap_or_else(|| self.frame_layout())
    }

    /// The bench's units as slots: its `[[slots]]`, or the one unit of a
    /// bench without them (an unnamed slot on the table's mount).
    pub fn unit_slots(&self) -> Vec<Slot> {
        if self.slots.is_empty() {
            return vec![Slot {
                name: String::new(),
                mount: None,
                seed: None,
                twin: None,
                gyro: None,
            }];
        }
        self.slots.clone()
    }

    /// The slots' names as an operator reads them (`A, B, C, D`).
    pub fn slot_names(&self) -> String {
        self.slots
            .iter()
            .map(|s| s.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The table's geometry with the unit in `slot` mounted on it.
    pub fn slot_geometry(&self, slot: &Slot) -> crate::geometry::TableGeometry {
        self.geometry_with(slot.mount)
    }

    /// The table's geometry with a unit on `mount` (none: the table's own
    /// mount).
    pub fn geometry_with(
        &self,
        mount: Option<crate::geometry::Orientation>,
    ) -> crate::geometry::TableGeometry {
        let mut g = self.table.geometry;
        if let Some(m) = mount {
            g.mount = m;
        }
        g
    }

    fn validate_supply(c: &Checker, src: &Source, p: &SupplyDevice) -> Result<(), ConfigError> {
        let key = "devices.supply.spec";
        p.spec
            .parse::<DeviceSpec>()
            .map_err(|e| src.invalid(key, e.to_string()))?;
        if let Some(name) = p.spec.strip_prefix("sim://") {
            c.ensure(
                name == "supply",
                key,
                &format!(
                    "{:?} is not the embedded simulator's supply; the supply there is \"sim://supply\"",
                    p.spec
                ),
            )?;
        }
        c.ensure(
            (1..=16).contains(&p.channel),
            "devices.supply.channel",
            "must be an output number, 1 to 16",
        )?;
        if p.spec.starts_with("sim://") {
            // The embedded supply is the model its dialect names: its
            // outputs and their ratings are known.
            let r = crate::protocol::supply::ratings(p.protocol);
            let Some(rating) = r.get(usize::from(p.channel) - 1) else {
                return Err(src.invalid(
                    "devices.supply.channel",
                    format!(
                        "the simulated {} supply has outputs 1 to {}",
                        p.protocol.as_str(),
                        r.len()
                    ),
                ));
            };
            c.within(p.max_volts(), 0.1, rating.max_v, "devices.supply.volts")?;
            c.within(
                p.max_limit_a(),
                0.001,
                rating.max_a,
                "devices.supply.limit_a",
            )?;
        }
        // Bench supplies for a gyro stay under 100 V and 20 A; beyond is a
        // slip of the keyboard.
        c.within(p.volts, 0.1, 100.0, "devices.supply.volts")?;
        c.within(p.limit_a, 0.001, 20.0, "devices.supply.limit_a")?;
        if let Some(v) = p.max_volts {
            c.within(v, p.volts, 100.0, "devices.supply.max_volts")?;
        }
        if let Some(a) = p.max_limit_a {
            c.within(a, p.limit_a, 20.0, "devices.supply.max_limit_a")?;
        }
        c.within(p.timeout_s, 0.01, 60.0, "devices.supply.timeout_s")?;
        c.ensure(
            (1..=20).contains(&p.attempts),
            "devices.supply.attempts",
            "must be 1 to 20",
        )?;
        c.within(
            p.reconnect_window_s,
            0.0,
            3600.0,
            "devices.supply.reconnect_window_s",
        )?;
        Ok(())
    }

    /// The bench's id for the record: `id`, else the bench file's name
    /// without its extension (`label` is the file as named), else
    /// `embedded`.
    pub fn bench_id(&self, label: &str) -> String {
        if let Some(id) = &self.id {
            return id.clone();
        }
        if self.is_embedded() && label == "embedded" {
            return "embedded".into();
        }
        Path::new(label)
            .file_stem()
            .map_or_else(|| label.to_owned(), |s| s.to_string_lossy().into_owned())
    }

    /// The chamber, the table and the supply as a run records them: their reported
    /// identities, due dates, and whether each is past it on `today`.
    pub fn instruments(
        &self,
        chamber: Result<crate::protocol::Identity, String>,
        table: Result<crate::protocol::Identity, String>,
        supply: Option<Result<crate::protocol::Identity, String>>,
        today: chrono::NaiveDate,
    ) -> Vec<Instrument> {
        let d = &self.devices;
        [
            (
                "chamber",
                &d.chamber.spec,
                d.chamber.calibration_due,
                chamber,
            ),
            ("table", &d.table.spec, d.table.calibration_due, table),
        ]
        .into_iter()
        .chain(
            d.supply
                .as_ref()
                .zip(supply)
                .map(|(p, id)| ("supply", &p.spec, p.calibration_due, id)),
        )
        .map(|(role, spec, due, id)| {
            let (identity, identity_error) = match id {
                Ok(i) => (Some(i), None),
                Err(e) => (None, Some(e)),
            };
            Instrument {
                role: role.into(),
                spec: spec.clone(),
                identity,
                identity_error,
                calibration_due: due.map(|d| d.to_string()),
                calibration_overdue: due.is_some_and(|d| today > d.0),
            }
        })
        .collect()
    }

    /// The gyro frame layout in use.
    pub fn frame_layout(&self) -> FrameLayout {
        self.devices.gyro.frame.clone().unwrap_or_default()
    }

    /// What the status word of each unit's frames means, in unit order
    /// (the slots', or the one unit's).
    pub fn status_bits(&self) -> Vec<crate::protocol::frame::StatusBits> {
        if self.slots.is_empty() {
            return vec![self.frame_layout().status_bits];
        }
        self.slots
            .iter()
            .map(|s| self.slot_frame_layout(s).status_bits)
            .collect()
    }

    /// What the status word of the unit in slot `name` means (the one
    /// unit's for an empty name or a bench without slots).
    pub fn unit_status_bits(&self, name: &str) -> crate::protocol::frame::StatusBits {
        self.slots
            .iter()
            .find(|s| s.name == name)
            .map_or_else(|| self.frame_layout(), |s| self.slot_frame_layout(s))
            .status_bits
    }
}

fn connector(spec: DeviceSpec, timeout: Duration) -> Connector {
    Arc::new(move || {
        let spec = spec.clone();
        Box::pin(async move { open(&spec, timeout).await })
    })
}

async fn open_device(
    name: &str,
    spec: &str,
    timeout: Duration,
) -> Result<(DeviceSpec, BoxTransport), DeviceError> {
    let connect = |cause| DeviceError::Open {
        device: name.to_owned(),
        spec: spec.to_owned(),
        cause,
    };
    let spec: DeviceSpec = spec.parse().map_err(|e: crate::transport::SpecError| {
        connect(std::io::Error::new(std::io::ErrorKind::InvalidInput, e))
    })?;
    let t = open(&spec, timeout).await.map_err(connect)?;
    Ok((spec, t))
}

/// The configured instruments, opened (the drivers are the crate's own:
/// a `DeviceBench` runs them).
pub struct OpenBench {
    /// Chamber driver.
    pub(crate) chamber: Box<dyn Chamber>,
    /// Table driver.
    pub(crate) table: AclTable,
    /// Gyro link (a batch's first slot's).
    pub(crate) gyro: GyroReader<BoxTransport>,
    /// A batch's other slots' gyro links, in the bench's order.
    pub(crate) others: Vec<GyroReader<BoxTransport>>,
    /// The unit's supply, if the bench has one.
    pub(crate) supply: Option<ScpiSupply>,
    /// What every link above says as it drops, comes back or is lost.
    pub(crate) watch: Arc<LinkWatch>,
}

impl std::fmt::Debug for OpenBench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OpenBench")
            .field("chamber", &self.chamber.name())
            .field("table", &self.table.name())
            .finish_non_exhaustive()
    }
}

/// Open every device of a bench whose specs are byte streams (not `sim://`).
pub async fn open_bench(cfg: &BenchConfig) -> Result<OpenBench, DeviceError> {
    let d = &cfg.devices;
    let watch = LinkWatch::new();
    let ct = Duration::from_secs_f64(d.chamber.timeout_s);
    let (cs, t) = open_device("chamber", &d.chamber.spec, ct).await?;
    let cpol = RetryPolicy {
        timeout: ct,
        attempts: d.chamber.attempts,
        reconnect_window: Duration::from_secs_f64(d.chamber.reconnect_window_s),
    };
    let chamber: Box<dyn Chamber> = match d.chamber.protocol {
        ChamberProtocol::EspecAscii => Box::new(EspecChamber::new(
            LineLink::new("chamber", t, Some(connector(cs, ct)), cpol).with_watch(watch.clone()),
            d.chamber.address,
        )),
        ChamberProtocol::WatlowF4tModbus => Box::new(
            WatlowChamber::new("chamber", t, Some(connector(cs, ct)), cpol)
                .with_watch(watch.clone()),
        ),
    };
    let tt = Duration::from_secs_f64(d.table.timeout_s);
    let (ts, t) = open_device("table", &d.table.spec, tt).await?;
    let table = AclTable::new(
        LineLink::new(
            "table",
            t,
            Some(connector(ts, tt)),
            RetryPolicy {
                timeout: tt,
                attempts: d.table.attempts,
                reconnect_window: Duration::from_secs_f64(d.table.reconnect_window_s),
            },
        )
        .with_watch(watch.clone()),
    );
    let supply = match &d.supply {
        Some(p) => {
            let pt = Duration::from_secs_f64(p.timeout_s);
            let (ps, t) = open_device("supply", &p.spec, pt).await?;
            Some(ScpiSupply::new(
                LineLink::new(
                    "supply",
                    t,
                    Some(connector(ps, pt)),
                    RetryPolicy {
                        timeout: pt,
                        attempts: p.attempts,
                        reconnect_window: Duration::from_secs_f64(p.reconnect_window_s),
                    },
                )
                .with_watch(watch.clone()),
                p.protocol,
            ))
        }
        None => None,
    };
    let gt = Duration::from_secs_f64(d.gyro.silence_s);
    let window = Duration::from_secs_f64(d.gyro.reconnect_window_s);
    let open_gyro = |device: String, spec: String, layout: FrameLayout| {
        let watch = watch.clone();
        async move {
            let (gs, t) = open_device(&device, &spec, gt).await?;
            Ok::<_, DeviceError>(
                GyroReader::new(&device, t, layout, gt)
                    .with_reconnect(connector(gs, gt), window)
                    .with_watch(watch),
            )
        }
    };
    // A batch's units each on their own link, `gyro/SLOT`.
    let mut gyros = Vec::new();
    for slot in &cfg.slots {
        gyros.push(
            open_gyro(
                format!("gyro/{}", slot.name),
                cfg.slot_gyro_spec(slot).to_owned(),
                cfg.slot_frame_layout(slot),
            )
            .await?,
        );
    }
    let mut gyros = gyros.into_iter();
    let gyro = match gyros.next() {
        Some(g) => g,
        None => open_gyro("gyro".into(), d.gyro.spec.clone(), cfg.frame_layout()).await?,
    };
    Ok(OpenBench {
        chamber,
        table,
        gyro,
        others: gyros.collect(),
        supply,
        watch,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIM: &str = include_str!("../fixtures/bench/sim-serve.toml");

    #[test]
    fn a_records_ends_may_move_by_the_hosts_delay_in_device_time() {
        assert_eq!(BenchConfig::embedded().record_edge_s(), 0.0);
        let mut served =
            BenchConfig::from_source(&Source::from_text("sim-serve.toml", SIM)).expect("loads");
        assert_eq!(served.record_edge_s(), HOST_DELAY_S * served.time_scale);
        served.time_scale = 30.0;
        assert!((served.record_edge_s() - 1.5).abs() < 1e-12);
    }

    #[test]
    fn shipped_bench_files_load() {
        for (name, text) in [
            ("sim-serve.toml", SIM),
            (
                "embedded.toml",
                include_str!("../fixtures/bench/embedded.toml"),
            ),
            (
                "lab-espec-serial.toml",
                include_str!("../fixtures/bench/lab-espec-serial.toml"),
            ),
            (
                "lab-watlow-tcp.toml",
                include_str!("../fixtures/bench/lab-watlow-tcp.toml"),
            ),
        ] {
            BenchConfig::from_source(&Source::from_text(name, text))
                .unwrap_or_else(|e| panic!("{name} must load: {e}"));
        }
    }

    #[test]
    fn a_bad_spec_is_refused_at_its_line() {
        let text = SIM.replacen("tcp://127.0.0.1:5003", "tcp://nowhere", 1);
        let err =
            BenchConfig::from_source(&Source::from_text("b.toml", &text)).expect_err("bad spec");
        let line = text
            .lines()
            .position(|l| l.contains("tcp://nowhere"))
            .expect("edited line")
            + 1;
        assert_eq!(err.line(), Some(line));
        assert!(
            err.to_string()
                .contains("`devices.table.spec` bad device spec"),
            "{err}"
        );
    }

    #[test]
    fn a_table_with_parallel_axes_is_refused() {
        let text = SIM.replacen(
            "inner_axis_ned = [0.0, 1.0, 0.0]",
            "inner_axis_ned = [2.0, 0.0, 0.0]",
            1,
        );
        let err =
            BenchConfig::from_source(&Source::from_text("b.toml", &text)).expect_err("parallel");
        assert!(
            err.to_string()
                .contains("`table.geometry.inner_axis_ned` must not be parallel"),
            "{err}"
        );
    }

    #[test]
    fn inverted_limits_are_refused() {
        let text = SIM.replacen(
            "outer_range_deg = [-180.0, 180.0]",
            "outer_range_deg = [10.0, -10.0]",
            1,
        );
        let err =
            BenchConfig::from_source(&Source::from_text("b.toml", &text)).expect_err("inverted");
        assert!(err.to_string().contains("limits.outer_range_deg"), "{err}");
    }

    const QUAD: &str = include_str!("../fixtures/bench/sim-quad.toml");

    fn quad_with(from: &str, to: &str) -> Result<BenchConfig, ConfigError> {
        BenchConfig::from_source(&Source::from_text("q.toml", &QUAD.replacen(from, to, 1)))
    }

    #[test]
    fn a_real_batch_reads_each_unit_on_its_own_link() {
        let q = quad_with("", "").expect("the fixture loads");
        let specs: Vec<_> = q.slots.iter().map(|s| q.slot_gyro_spec(s)).collect();
        assert_eq!(
            specs,
            [
                "tcp://127.0.0.1:5004",
                "tcp://127.0.0.1:5005",
                "tcp://127.0.0.1:5006",
                "tcp://127.0.0.1:5007"
            ]
        );
        // A slot's own layout, else the bench's.
        let mut q = q;
        if let Some(g) = q.slots[2].gyro.as_mut() {
            g.frame = Some(FrameLayout {
                frame_type: 0x52,
                ..FrameLayout::default()
            });
        }
        assert_eq!(q.slot_frame_layout(&q.slots[2]).frame_type, 0x52);
        // ... but not its own temperature scale.
        let frame = toml::to_string(&FrameLayout {
            temp_lsb_c: 0.02,
            ..FrameLayout::default()
        })
        .expect("TOML");
        let text = QUAD.replacen(
            "gyro = { spec = \"tcp://127.0.0.1:5006\" }",
            &format!("[slots.gyro]\nspec = \"tcp://127.0.0.1:5006\"\n[slots.gyro.frame]\n{frame}"),
            1,
        );
        let e = BenchConfig::from_source(&Source::from_text("q.toml", &text))
            .expect_err("another temperature scale");
        assert!(
            e.to_string().contains("slots.2.gyro.frame.temp_lsb_c"),
            "{e}"
        );
        assert_eq!(q.slot_frame_layout(&q.slots[1]), q.frame_layout());

        let two_on_the_bench_link = quad_with("gyro = { spec = \"tcp://127.0.0.1:5005\" }\n", "")
            .expect_err("two slots on [devices.gyro]'s link");
        let e = two_on_the_bench_link.to_string();
        assert!(
            e.contains("q.toml:") && e.contains("slots.1.gyro") && e.contains("would both read"),
            "{e}"
        );
        let shared = quad_with("127.0.0.1:5006", "127.0.0.1:5005").expect_err("one link twice");
        assert!(
            shared
                .to_string()
                .contains("slot \"B\" reads \"tcp://127.0.0.1:5005\" too"),
            "{shared}"
        );
        let bad = quad_with("tcp://127.0.0.1:5007", "127.0.0.1:5007").expect_err("no scheme");
        assert!(bad.to_string().contains("slots.3.gyro.spec"), "{bad}");
    }

    #[test]
    fn the_embedded_benchs_slots_name_no_link() {
        let text = include_str!("../fixtures/bench/quad.toml").replace(
            "name = \"D\"",
            "name = \"D\"\ngyro = { spec = \"tcp://127.0.0.1:5004\" }",
        );
        let e = BenchConfig::from_source(&Source::from_text("e.toml", &text))
            .expect_err("a link on the embedded bench");
        assert!(e.to_string().contains("slots.3.gyro"), "{e}");
    }
}
