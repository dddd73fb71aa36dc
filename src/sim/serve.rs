//! `gyrobench sim serve`: the simulated bench on loopback TCP and ptys.

use std::net::{Ipv4Addr, SocketAddr};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use serde::Deserialize;
use tokio::net::TcpListener;

use super::{
    SharedBench, SimBench,
    acl::serve_acl,
    espec::serve_espec,
    gyro::serve_gyro,
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
            Some(rel) => TwinConfig::load(&base.join(rel)).map_err(|e| match e {
                // The twin file's own errors point into it; one that cannot
                // be read points at this file's `twin`.
                ConfigError::Read { path, cause } => src.invalid(
                    "twin",
                    format!(
                        "cannot read {}: {cause}; the path is relative to this file",
                        path.display()
                    ),
                ),
                e => e,
            })?,
            None => TwinConfig::default_rl16(),
        };
        let layout = config.frame.clone().unwrap_or_default();
        layout
            .validate()
            .map_err(|e| src.invalid("frame", e.to_string()))?;
        Ok(Self {
            config,
            twin,
            layout,
        })
    }
}

/// One served endpoint: `<device> <protocol> <address>`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint {
    /// `chamber`, `table`, `gyro` or `supply`.
    pub device: &'static str,
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
        /// `chamber`, `table` or `gyro`.
        device: &'static str,
        /// The protocol served there.
        protocol: &'static str,
        /// The address asked for (port 0: any free one).
        addr: SocketAddr,
        /// The serve configuration's key of the port (`ports.espec`, ...).
        key: &'static str,
        /// Why.
        cause: std::io::Error,
        /// What to do about it.
        hint: String,
    },
    /// A pty pair could not be made.
    #[error(
        "{device}: cannot create a pty: {cause}; set `ptys = false` in the serve configuration to serve on TCP only"
    )]
    Pty {
        /// The device it was for.
        device: &'static str,
        /// Why.
        cause: std::io::Error,
    },
    /// The system could not say where a listener is.
    #[error("{device} {protocol}: cannot read the listening address: {cause}")]
    Address {
        /// The device.
        device: &'static str,
        /// Its protocol.
        protocol: &'static str,
        /// Why.
        cause: std::io::Error,
    },
}

/// Listen on loopback `port` (0: one the OS picks) for `device`.
async fn listen(
    device: &'static str,
    protocol: &'static str,
    port: u16,
    key: &'static str,
) -> Result<(TcpListener, Endpoint), ServeError> {
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
            device,
            protocol,
            addr,
            key,
            cause,
            hint,
        }
    })?;
    let local = l.local_addr().map_err(|cause| ServeError::Address {
        device,
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
    let mut sim = SimBench::new(s.twin.clone(), s.config.seed, s.layout.clone());
    sim.supply = Supply::powering_unit(s.config.supply);
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

    let (gyro, e) = listen("gyro", "rlg-frame", p.gyro, "ports.gyro").await?;
    endpoints.push(e);
    spawn_accept(gyro, bench.clone(), serve_gyro);

    let dialect = s.config.supply.as_str();
    let (supply, e) = listen("supply", dialect, p.supply, "ports.supply").await?;
    endpoints.push(e);
    spawn_accept(supply, bench.clone(), serve_supply);

    let mut ptys = Vec::new();
    if s.config.ptys {
        for (device, protocol) in [
            ("chamber", "espec-ascii"),
            ("table", "acl"),
            ("gyro", "rlg-frame"),
            ("supply", dialect),
        ] {
            let crate::transport::PtyPair {
                master,
                slave,
                path,
            } = pty_pair().map_err(|cause| ServeError::Pty { device, cause })?;
            endpoints.push(Endpoint {
                device,
                protocol,
                address: format!("pty://{path}"),
            });
            let b = bench.clone();
            match protocol {
                "espec-ascii" => drop(tokio::spawn(serve_espec(master, b))),
                "acl" => drop(tokio::spawn(serve_acl(master, b))),
                "rlg-frame" => drop(tokio::spawn(serve_gyro(master, b))),
                _ => drop(tokio::spawn(serve_supply(master, b))),
            }
            ptys.push(slave);
        }
    }
    Ok(Served {
        endpoints,
        bench,
        _ptys: ptys,
    })
}
