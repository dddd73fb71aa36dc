//! `gyrobench sim serve`: the simulated bench on loopback TCP and ptys.

use std::net::{Ipv4Addr, SocketAddr};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use serde::Deserialize;
use tokio::net::TcpListener;

use super::faults::{Fault, Unplayable};
use super::{
    SharedBench, SimBench,
    acl::serve_acl,
    espec::serve_espec,
    gyro::serve_unit_gyro,
    supply::{Supply, serve_supply},
    watlow::WatlowService,
};
use crate::clock::WallClock;
use crate::config::{Checker, ConfigError, Source};
use crate::protocol::frame::FrameLayout;
use crate::protocol::supply::Dialect;
use crate::transport::pty_pair;
use crate::twin::TwinConfig;

/// `sim serve` configuration (`fixtures/sim/serve.toml`).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServeConfig {
    /// Twin file, relative to this file (default: the embedded RL-16 twin).
    pub twin: Option<String>,
    /// Seed of the twin's random terms.
    #[serde(default = "one")]
    pub seed: u64,
    /// Device time runs this many times faster than the wall.
    #[serde(default = "unit")]
    pub speed: f64,
    /// Offer each device on a pty as well as on TCP.
    #[serde(default = "yes")]
    pub ptys: bool,
    /// Fixed TCP ports (0 or absent: chosen by the OS).
    #[serde(default)]
    pub ports: Ports,
    /// Gyro frame layout (default: the documented one).
    #[serde(default)]
    pub frame: Option<FrameLayout>,
    /// Whose SCPI commands the power supply takes (default
    /// `keysight-e36300`; or `rigol-dp800`).
    #[serde(default)]
    pub supply: Dialect,
    /// The unit powered from the start, as by hand (a bench file without
    /// `[devices.supply]`, a batch's fixture); default false: the unit is
    /// off until a client switches the supply's output on, as on a real
    /// bench.
    #[serde(default)]
    pub unit_powered: bool,
    /// A batch's fixture: the units on the table's platform, in the
    /// bench's order, each on its own gyro line (none: one unit).
    #[serde(default)]
    pub slots: Vec<ServeSlot>,
}

/// `[[slots]]` of a serve file: one unit of a simulated batch.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServeSlot {
    /// The slot's name, as the bench file's `[[slots]]` give it; its gyro
    /// is served as `gyro/NAME`.
    pub name: String,
    /// The unit's body orientation with both table angles at zero
    /// (default: the twin's `[table.geometry] mount`).
    #[serde(default)]
    pub mount: Option<crate::geometry::Orientation>,
    /// Its twin's seed (default: `seed` plus the slot's index).
    #[serde(default)]
    pub seed: Option<u64>,
    /// Its twin file, relative to this file (default: `twin`): its own
    /// unit in the bench's chamber, on the bench's table.
    #[serde(default)]
    pub twin: Option<String>,
    /// Its gyro's TCP port (0 or absent: chosen by the OS).
    #[serde(default)]
    pub port: u16,
}

/// One unit of a simulated batch, resolved.
#[derive(Debug, Clone)]
pub struct ServedUnit {
    /// Its slot.
    pub name: String,
    /// Its twin, on the bench's chamber and table.
    pub twin: TwinConfig,
    /// Its seed.
    pub seed: u64,
    /// Its gyro's TCP port (0: any).
    pub port: u16,
}

fn one() -> u64 {
    1
}
fn unit() -> f64 {
    1.0
}
fn yes() -> bool {
    true
}

/// TCP ports of the simulated devices.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ports {
    /// Espec ASCII chamber.
    #[serde(default)]
    pub espec: u16,
    /// Watlow F4T Modbus TCP chamber.
    #[serde(default)]
    pub watlow: u16,
    /// ACL motion simulator.
    #[serde(default)]
    pub acl: u16,
    /// Gyro frame stream.
    #[serde(default)]
    pub gyro: u16,
    /// Power supply (SCPI; real ones listen on 5025).
    #[serde(default)]
    pub supply: u16,
}

/// A loaded serve configuration with its twin resolved.
#[derive(Debug, Clone)]
pub struct Serve {
    /// Settings.
    pub config: ServeConfig,
    /// The twin to serve.
    pub twin: TwinConfig,
    /// The frame layout.
    pub layout: FrameLayout,
    /// A batch's units (empty: one unit, `twin` seeded `config.seed`).
    pub units: Vec<ServedUnit>,
}

impl Serve {
    /// Read and check a serve file (None: defaults).
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let Some(path) = path else {
            return Ok(Self {
                config: ServeConfig {
                    seed: 1,
                    speed: 1.0,
                    ptys: true,
                    ..ServeConfig::default()
                },
                twin: TwinConfig::default_rl16(),
                layout: FrameLayout::default(),
                units: Vec::new(),
            });
        };
        let base = path.parent().unwrap_or(Path::new("."));
        Self::from_source(&Source::read(path)?, base)
    }

    /// Parse and check a serve file's text; a `twin` path is taken relative
    /// to `base`.
    pub fn from_source(src: &Source, base: &Path) -> Result<Self, ConfigError> {
        let config: ServeConfig = src.parse()?;
        let c = Checker::new(src);
        c.within(config.speed, 0.001, 1e6, "speed")?;
        let twin = match &config.twin {
            Some(rel) => load_twin(src, base, rel, "twin")?,
            None => TwinConfig::default_rl16(),
        };
        let layout = config.frame.clone().unwrap_or_default();
        layout
            .validate()
            .map_err(|e| src.invalid("frame", e.to_string()))?;
        let units = Self::units(&config, src, base, &twin)?;
        Ok(Self {
            config,
            twin,
            layout,
            units,
        })
    }

    /// The batch's units of `config`, each on `bench`'s chamber and table.
    fn units(
        config: &ServeConfig,
        src: &Source,
        base: &Path,
        bench: &TwinConfig,
    ) -> Result<Vec<ServedUnit>, ConfigError> {
        let c = Checker::new(src);
        c.ensure(
            config.slots.len() <= crate::bench::MAX_SLOTS,
            "slots",
            &format!("a fixture holds at most {} slots", crate::bench::MAX_SLOTS),
        )?;
        c.ensure(
            config.slots.is_empty() || config.ports.gyro == 0,
            "ports.gyro",
            "with [[slots]], each slot's `port` is its gyro's",
        )?;
        let mut units: Vec<ServedUnit> = Vec::new();
        for (i, slot) in config.slots.iter().enumerate() {
            let key = |k: &str| format!("slots.{i}.{k}");
            c.ensure(
                crate::bench::Slot::valid_name(&slot.name),
                &key("name"),
                "must be 1 to 16 letters, digits, '-' or '_'",
            )?;
            c.ensure(
                units.iter().all(|u| u.name != slot.name),
                &key("name"),
                &format!("slot {:?} is declared twice", slot.name),
            )?;
            c.ensure(
                slot.port == 0
                    || (units.iter().all(|u| u.port != slot.port)
                        && ![
                            config.ports.espec,
                            config.ports.watlow,
                            config.ports.acl,
                            config.ports.supply,
                        ]
                        .contains(&slot.port)),
                &key("port"),
                &format!("port {} is another device's", slot.port),
            )?;
            let own = match &slot.twin {
                Some(rel) => load_twin(src, base, rel, &key("twin"))?,
                None => bench.clone(),
            };
            let mut twin = own.on_bench_of(bench);
            if let Some(m) = slot.mount {
                c.ensure(
                    [m.azimuth_deg, m.elevation_deg, m.roll_deg]
                        .iter()
                        .all(|v| v.is_finite()),
                    &key("mount"),
                    "every angle must be a finite number of degrees",
                )?;
                twin.table.geometry.mount = m;
            }
            units.push(ServedUnit {
                name: slot.name.clone(),
                twin,
                seed: slot.seed.unwrap_or(config.seed.wrapping_add(i as u64)),
                port: slot.port,
            });
        }
        Ok(units)
    }
}

/// Load the twin file `rel` (relative to `base`) named at `key` of `src`.
fn load_twin(src: &Source, base: &Path, rel: &str, key: &str) -> Result<TwinConfig, ConfigError> {
    TwinConfig::load(&base.join(rel)).map_err(|e| match e {
        // The twin file's own errors point into it; one that cannot be
        // read points at this file's key.
        ConfigError::Read { path, cause } => src.invalid(
            key,
            format!(
                "cannot read {}: {cause}; the path is relative to this file",
                path.display()
            ),
        ),
        e => e,
    })
}

/// One served endpoint: `<device> <protocol> <address>`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint {
    /// `chamber`, `table`, `gyro` or `supply`; a batch's gyros are
    /// `gyro/SLOT`.
    pub device: String,
    /// `espec-ascii`, `watlow-f4t-modbus`, `acl`, `rlg-frame`,
    /// `keysight-e36300`, `rigol-dp800`.
    pub protocol: &'static str,
    /// `tcp://127.0.0.1:PORT` or `pty:///dev/pts/N`.
    pub address: String,
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {} {}", self.device, self.protocol, self.address)
    }
}

/// Why the simulated bench could not start.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A TCP endpoint could not listen (the port is taken, or not allowed).
    #[error("{device} {protocol}: cannot listen on {addr}: {cause}; {hint}")]
    Listen {
        /// `chamber`, `table`, `gyro` (`gyro/SLOT`) or `supply`.
        device: String,
        /// The protocol served there.
        protocol: &'static str,
        /// The address asked for (port 0: any free one).
        addr: SocketAddr,
        /// Why.
        #[source]
        cause: std::io::Error,
        /// What to do about it, naming the serve configuration's key of
        /// the port (`ports.espec`, `slots.0.port`, ...).
        hint: String,
    },
    /// A pty pair could not be made.
    #[error(
        "{device}: cannot create a pty: {cause}; set `ptys = false` in the serve configuration to serve on TCP only"
    )]
    Pty {
        /// The device it was for.
        device: String,
        /// Why.
        #[source]
        cause: std::io::Error,
    },
    /// The system could not say where a listener is.
    #[error("{device} {protocol}: cannot read the listening address: {cause}")]
    Address {
        /// The device.
        device: String,
        /// Its protocol.
        protocol: &'static str,
        /// Why.
        #[source]
        cause: std::io::Error,
    },
}

/// Listen on loopback `port` (0: one the OS picks) for `device`.
async fn listen(
    device: &str,
    protocol: &'static str,
    port: u16,
    key: &str,
) -> Result<(TcpListener, Endpoint), ServeError> {
    let device = device.to_owned();
    let addr = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
    let l = TcpListener::bind(addr).await.map_err(|cause| {
        let hint = if cause.kind() == std::io::ErrorKind::AddrInUse {
            format!(
                "another process holds port {port} (another `gyrobench sim serve`?): stop it, \
                 or choose another `{key}` in the serve configuration (0 lets the system choose)"
            )
        } else {
            format!("choose another `{key}` in the serve configuration (0 lets the system choose)")
        };
        ServeError::Listen {
            device: device.clone(),
            protocol,
            addr,
            cause,
            hint,
        }
    })?;
    let local = l.local_addr().map_err(|cause| ServeError::Address {
        device: device.clone(),
        protocol,
        cause,
    })?;
    let endpoint = Endpoint {
        device,
        protocol,
        address: format!("tcp://{local}"),
    };
    Ok((l, endpoint))
}

/// Accept connections forever, serving each with `serve`.
fn spawn_accept<F, Fut>(listener: TcpListener, bench: Arc<SharedBench>, serve: F)
where
    F: Fn(tokio::net::TcpStream, Arc<SharedBench>) -> Fut + Send + 'static,
    Fut: std::future::Future<Output = std::io::Result<()>> + Send + 'static,
{
    tokio::spawn(async move {
        while let Ok((stream, _)) = listener.accept().await {
            let _ = stream.set_nodelay(true);
            tokio::spawn(serve(stream, bench.clone()));
        }
    });
}

/// A running simulated bench; dropping it stops nothing until the runtime ends.
#[derive(Debug)]
pub struct Served {
    /// Every endpoint, in the order printed.
    pub endpoints: Vec<Endpoint>,
    /// The bench behind them (for fault injection in tests).
    pub bench: Arc<SharedBench>,
    /// Slave sides held open so each pty lives while no client has it.
    _ptys: Vec<tokio_serial::SerialStream>,
}

/// Start every simulated device; returns once all endpoints listen.
pub async fn start(s: &Serve) -> Result<Served, ServeError> {
    let clock = Arc::new(WallClock::scaled(s.config.speed));
    let mut sim = match s.units.split_first() {
        None => SimBench::new(s.twin.clone(), s.config.seed, s.layout.clone()),
        Some((first, others)) => others.iter().fold(
            SimBench::new(first.twin.clone(), first.seed, s.layout.clone()),
            |b, u| b.with_unit(&u.name, u.twin.clone(), u.seed),
        ),
    };
    sim.supply = if s.config.unit_powered {
        Supply::powering_unit(s.config.supply)
    } else {
        Supply::unit_off(s.config.supply)
    };
    let bench = SharedBench::new(sim, clock);
    bench.spawn_ticker(Duration::from_millis(5));
    let p = s.config.ports;
    let mut endpoints = Vec::new();

    let (espec, e) = listen("chamber", "espec-ascii", p.espec, "ports.espec").await?;
    endpoints.push(e);
    spawn_accept(espec, bench.clone(), serve_espec);

    let (watlow, e) = listen("chamber", "watlow-f4t-modbus", p.watlow, "ports.watlow").await?;
    endpoints.push(e);
    let b = bench.clone();
    tokio::spawn(async move {
        let server = tokio_modbus::server::tcp::Server::new(watlow);
        let on_connected = |stream, addr| {
            let b = b.clone();
            async move {
                tokio_modbus::server::tcp::accept_tcp_connection(stream, addr, |_| {
                    Ok(Some(WatlowService::new(b.clone())))
                })
            }
        };
        let _ = server.serve(&on_connected, |_| {}).await;
    });

    let (acl, e) = listen("table", "acl", p.acl, "ports.acl").await?;
    endpoints.push(e);
    spawn_accept(acl, bench.clone(), serve_acl);

    let gyros = gyro_lines(s);
    for (unit, (device, port, key)) in gyros.iter().enumerate() {
        let (gyro, e) = listen(device, "rlg-frame", *port, key).await?;
        endpoints.push(e);
        spawn_accept(gyro, bench.clone(), move |w, b| serve_unit_gyro(w, b, unit));
    }

    let dialect = s.config.supply.as_str();
    let (supply, e) = listen("supply", dialect, p.supply, "ports.supply").await?;
    endpoints.push(e);
    spawn_accept(supply, bench.clone(), serve_supply);

    let ptys = if s.config.ptys {
        serve_ptys(&bench, &gyros, dialect, &mut endpoints)?
    } else {
        Vec::new()
    };
    Ok(Served {
        endpoints,
        bench,
        _ptys: ptys,
    })
}

/// Whether the served bench of `s` can play `fault`: a device's fault
/// ([`Fault::device`]); `unit-lost` only on a batch of two units or more.
/// The error says why not.
pub fn can_play(s: &Serve, fault: Fault) -> Result<(), Unplayable> {
    match fault.device() {
        None => Err(Unplayable::OfTheController {
            fault,
            served: Some(
                Fault::ALL
                    .iter()
                    .filter(|f| f.device().is_some())
                    .map(|f| f.name())
                    .collect::<Vec<_>>()
                    .join(", "),
            ),
        }),
        Some(_) if fault == Fault::UnitLost && s.units.len() < 2 => Err(Unplayable::OneUnit {
            example: Some("fixtures/sim/quad.toml"),
        }),
        Some(_) => Ok(()),
    }
}

/// How often a scheduled fault looks at the served clock, wall time.
const FAULT_POLL: Duration = Duration::from_millis(20);

/// Play each of `faults` (device time, s; fault) on `bench` once its
/// clock reaches that time, calling `played` with what [`SharedBench::play`]
/// answered.
pub fn schedule_faults(
    bench: &Arc<SharedBench>,
    faults: Vec<(f64, Fault)>,
    played: impl Fn(f64, Fault, Result<(), Unplayable>) + Send + Sync + 'static,
) {
    let played = Arc::new(played);
    for (at_s, fault) in faults {
        let (bench, played) = (Arc::clone(bench), Arc::clone(&played));
        tokio::spawn(async move {
            while bench.clock().now_s() < at_s {
                tokio::time::sleep(FAULT_POLL).await;
            }
            let r = bench.play(fault);
            played(bench.clock().now_s(), fault, r);
        });
    }
}

/// One gyro line per unit: `gyro`, or a batch's `gyro/SLOT`; each with
/// its TCP port and the serve file's key of it.
fn gyro_lines(s: &Serve) -> Vec<(String, u16, String)> {
    if s.units.is_empty() {
        return vec![("gyro".into(), s.config.ports.gyro, "ports.gyro".into())];
    }
    s.units
        .iter()
        .enumerate()
        .map(|(i, u)| {
            (
                format!("gyro/{}", u.name),
                u.port,
                format!("slots.{i}.port"),
            )
        })
        .collect()
}

/// Serve the Espec chamber, the table, every gyro line and the supply
/// (`dialect`) on a pty each, adding their endpoints; returns the slave
/// sides, to be held open.
fn serve_ptys(
    bench: &Arc<SharedBench>,
    gyros: &[(String, u16, String)],
    dialect: &'static str,
    endpoints: &mut Vec<Endpoint>,
) -> Result<Vec<tokio_serial::SerialStream>, ServeError> {
    let mut served: Vec<(String, &'static str, Option<usize>)> = vec![
        ("chamber".into(), "espec-ascii", None),
        ("table".into(), "acl", None),
    ];
    served.extend(
        gyros
            .iter()
            .enumerate()
            .map(|(unit, (device, ..))| (device.clone(), "rlg-frame", Some(unit))),
    );
    served.push(("supply".into(), dialect, None));
    let mut ptys = Vec::new();
    for (device, protocol, unit) in served {
        let crate::transport::PtyPair {
            master,
            slave,
            path,
        } = pty_pair().map_err(|cause| ServeError::Pty {
            device: device.clone(),
            cause,
        })?;
        endpoints.push(Endpoint {
            device,
            protocol,
            address: format!("pty://{path}"),
        });
        let b = bench.clone();
        match (protocol, unit) {
            (_, Some(unit)) => drop(tokio::spawn(serve_unit_gyro(master, b, unit))),
            ("espec-ascii", _) => drop(tokio::spawn(serve_espec(master, b))),
            ("acl", _) => drop(tokio::spawn(serve_acl(master, b))),
            _ => drop(tokio::spawn(serve_supply(master, b))),
        }
        ptys.push(slave);
    }
    Ok(ptys)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Result<Serve, ConfigError> {
        let base = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/sim"));
        Serve::from_source(&Source::from_text("serve.toml", text), base)
    }

    #[test]
    fn a_fixtures_units_share_the_benchs_chamber_and_table_each_on_its_mount_and_seed() {
        let quad = load(include_str!("../../fixtures/sim/quad.toml")).expect("the fixture");
        let names: Vec<_> = quad.units.iter().map(|u| u.name.as_str()).collect();
        assert_eq!(names, ["A", "B", "C", "D"]);
        let seeds: Vec<_> = quad.units.iter().map(|u| u.seed).collect();
        assert_eq!(seeds, [1, 2, 3, 4]);
        let ports: Vec<_> = quad.units.iter().map(|u| u.port).collect();
        assert_eq!(ports, [5004, 5005, 5006, 5007]);

        let s = load(
            "seed = 5\n[[slots]]\nname = \"X\"\n[[slots]]\nname = \"Y\"\nseed = 9\n\
             mount = { azimuth_deg = 0.0, elevation_deg = 0.0, roll_deg = 0.0 }\n",
        )
        .expect("two units");
        assert_eq!((s.units[0].seed, s.units[1].seed), (5, 9));
        assert_eq!(s.units[1].twin.table.geometry.mount.azimuth_deg, 0.0);
        assert_eq!(
            s.units[0].twin.table.geometry.mount,
            s.twin.table.geometry.mount
        );
        assert_eq!(s.units[1].twin.chamber, s.twin.chamber);
    }

    #[test]
    fn a_fixtures_slots_are_checked_where_they_are_written() {
        for (text, says) in [
            (
                "[ports]\ngyro = 5004\n[[slots]]\nname = \"A\"\n",
                "ports.gyro",
            ),
            (
                "[[slots]]\nname = \"A\"\n[[slots]]\nname = \"A\"\n",
                "slots.1.name",
            ),
            ("[[slots]]\nname = \"A B\"\n", "slots.0.name"),
            (
                "[ports]\nacl = 5003\n[[slots]]\nname = \"A\"\nport = 5003\n",
                "slots.0.port",
            ),
            (
                "[[slots]]\nname = \"A\"\ntwin = \"nowhere.toml\"\n",
                "slots.0.twin",
            ),
        ] {
            let e = load(text).expect_err(text).to_string();
            assert!(e.contains("serve.toml:") && e.contains(says), "{text}: {e}");
        }
    }
}
