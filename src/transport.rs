//! Byte transports and device spec strings.
//!
//! Drivers are built on an already-open transport: anything
//! `AsyncRead + AsyncWrite + Unpin + Send` (serial port, TCP stream, pty,
//! in-memory duplex). A device is chosen by a spec string:
//! `serial:///dev/ttyUSB0?baud=9600`, `tcp://127.0.0.1:5025`,
//! `pty:///dev/pts/7`, `sim://chamber`.

use std::time::Duration;

use tokio::io::{AsyncBufRead, AsyncBufReadExt, AsyncRead, AsyncReadExt, AsyncWrite};

/// Any byte stream a driver can talk over.
pub trait Transport: AsyncRead + AsyncWrite + Unpin + Send + std::fmt::Debug {}
impl<T: AsyncRead + AsyncWrite + Unpin + Send + std::fmt::Debug> Transport for T {}

/// A boxed transport.
pub type BoxTransport = Box<dyn Transport>;

/// Read one line (through LF) into `buf`, at most `max` bytes; a longer
/// line is cut there and returned as is. `Ok(false)` at end of stream.
pub async fn read_line<R: AsyncBufRead + Unpin>(
    r: &mut R,
    buf: &mut Vec<u8>,
    max: usize,
) -> std::io::Result<bool> {
    buf.clear();
    let n = (&mut *r).take(max as u64).read_until(b'\n', buf).await?;
    while matches!(buf.last(), Some(b'\n' | b'\r')) {
        buf.pop();
    }
    Ok(n > 0)
}

/// Where a device is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceSpec {
    /// A serial port.
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
    },
    /// A TCP endpoint.
    Tcp {
        /// `host:port`.
        addr: String,
    },
    /// A pseudo-terminal (opened like a serial port, baud ignored).
    Pty {
        /// Device path of the pty's slave side.
        path: String,
    },
    /// The embedded simulator.
    Sim {
        /// Which simulated device.
        name: String,
    },
}

/// A spec string that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "bad device spec {spec:?}: {reason}; expected serial:///dev/ttyUSB0?baud=9600, tcp://127.0.0.1:5025, pty:///dev/pts/7 or sim://chamber"
)]
pub struct SpecError {
    /// The spec as given.
    pub spec: String,
    /// What is wrong with it.
    pub reason: String,
}

impl std::str::FromStr for DeviceSpec {
    type Err = SpecError;

    fn from_str(spec: &str) -> Result<Self, SpecError> {
        let err = |reason: &str| SpecError {
            spec: spec.to_owned(),
            reason: reason.to_owned(),
        };
        let (scheme, rest) = spec.split_once("://").ok_or_else(|| err("no scheme"))?;
        let (body, query) = match rest.split_once('?') {
            Some((b, q)) => (b, Some(q)),
            None => (rest, None),
        };
        if body.is_empty() {
            return Err(err("nothing after the scheme"));
        }
        match scheme {
            "serial" => {
                let mut baud = 9600;
                for kv in query.unwrap_or("").split('&').filter(|s| !s.is_empty()) {
                    match kv.split_once('=') {
                        Some(("baud", v)) => {
                            baud = v
                                .parse()
                                .ok()
                                .filter(|b| *b > 0)
                                .ok_or_else(|| err("baud must be a positive whole number"))?;
                        }
                        _ => return Err(err(&format!("unknown option {kv:?} (only baud=...)"))),
                    }
                }
                Ok(Self::Serial {
                    path: body.to_owned(),
                    baud,
                })
            }
            "tcp" if query.is_none() => {
                let (host, port) = body.rsplit_once(':').ok_or_else(|| err("no port"))?;
                if host.is_empty() || port.parse::<u16>().is_err() {
                    return Err(err("expected host:port"));
                }
                Ok(Self::Tcp {
                    addr: body.to_owned(),
                })
            }
            "pty" if query.is_none() => Ok(Self::Pty {
                path: body.to_owned(),
            }),
            "sim" if query.is_none() => Ok(Self::Sim {
                name: body.to_owned(),
            }),
            "tcp" | "pty" | "sim" => Err(err("options are only for serial ports")),
            _ => Err(err(&format!("unknown scheme {scheme:?}"))),
        }
    }
}

impl std::fmt::Display for DeviceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Serial { path, baud } => write!(f, "serial://{path}?baud={baud}"),
            Self::Tcp { addr } => write!(f, "tcp://{addr}"),
            Self::Pty { path } => write!(f, "pty://{path}"),
            Self::Sim { name } => write!(f, "sim://{name}"),
        }
    }
}

/// Open a serial port as a raw byte stream. `exclusive` locks the port
/// against other openers (right for hardware; a pty is shared with the
/// simulator that made it). Bytes the port held before it was opened are
/// discarded: they are from before this run (a free-running gyro's frames
/// of minutes ago, a reply nobody waited for).
pub fn open_serial(
    path: &str,
    baud: u32,
    exclusive: bool,
) -> std::io::Result<tokio_serial::SerialStream> {
    use tokio_serial::{ClearBuffer, SerialPort, SerialPortBuilderExt};
    let port = tokio_serial::new(path, baud)
        .timeout(Duration::from_millis(100))
        .exclusive(exclusive)
        .open_native_async()
        .map_err(std::io::Error::from)?;
    port.clear(ClearBuffer::Input)
        .map_err(std::io::Error::from)?;
    Ok(port)
}

/// Open a transport for a spec (not `sim://`, which is no byte stream).
pub async fn open(spec: &DeviceSpec, connect_timeout: Duration) -> std::io::Result<BoxTransport> {
    match spec {
        DeviceSpec::Serial { path, baud } => Ok(Box::new(open_serial(path, *baud, true)?)),
        // A pty ignores the line speed; 0 avoids "not a typewriter" on some ptys.
        DeviceSpec::Pty { path } => Ok(Box::new(open_serial(path, 0, false)?)),
        DeviceSpec::Tcp { addr } => {
            let s = tokio::time::timeout(connect_timeout, tokio::net::TcpStream::connect(addr))
                .await
                .map_err(|_| {
                    std::io::Error::new(std::io::ErrorKind::TimedOut, "connect timed out")
                })??;
            s.set_nodelay(true)?;
            Ok(Box::new(s))
        }
        DeviceSpec::Sim { name } => Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("sim://{name} is the embedded simulator, not a byte stream"),
        )),
    }
}

/// A pseudo-terminal pair: the simulator keeps `master`; a client opens
/// `path` like a serial port.
#[derive(Debug)]
pub struct PtyPair {
    /// The side the simulator reads and writes.
    pub master: tokio_serial::SerialStream,
    /// Kept open so the pty lives while no client has it open.
    pub slave: tokio_serial::SerialStream,
    /// Device path of the slave side.
    pub path: String,
}

/// Create a pty pair whose slave a client can open by path.
pub fn pty_pair() -> std::io::Result<PtyPair> {
    use tokio_serial::SerialPort;
    let (master, mut slave) = tokio_serial::SerialStream::pair().map_err(std::io::Error::from)?;
    // pair() opens the slave exclusively; a client must be able to open it.
    slave.set_exclusive(false).map_err(std::io::Error::from)?;
    let path = slave
        .name()
        .ok_or_else(|| std::io::Error::other("the pty has no device path"))?;
    Ok(PtyPair {
        master,
        slave,
        path,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_print_back() {
        for s in [
            "serial:///dev/ttyUSB0?baud=9600",
            "tcp://127.0.0.1:5025",
            "pty:///dev/pts/7",
            "sim://chamber",
        ] {
            let spec: DeviceSpec = s.parse().expect("valid spec");
            assert_eq!(spec.to_string(), s);
        }
        let d: DeviceSpec = "serial:///dev/ttyS0".parse().expect("default baud");
        assert_eq!(
            d,
            DeviceSpec::Serial {
                path: "/dev/ttyS0".into(),
                baud: 9600
            }
        );
    }

    #[test]
    fn bad_specs_say_what_is_wrong() {
        for (s, why) in [
            ("ttyUSB0", "no scheme"),
            ("tcp://localhost", "no port"),
            ("tcp://:80", "host:port"),
            ("serial:///dev/x?baud=fast", "baud"),
            ("serial:///dev/x?parity=odd", "unknown option"),
            ("usb://x", "unknown scheme"),
            ("tcp://", "nothing after"),
        ] {
            let e = s.parse::<DeviceSpec>().expect_err(s);
            assert!(e.to_string().contains(why), "{s}: {e}");
        }
    }

    #[tokio::test]
    async fn read_line_strips_terminators_and_bounds_length() {
        let data: &[u8] = b"TEMP?\r\nabcdefghij\n";
        let mut r = tokio::io::BufReader::new(data);
        let mut buf = Vec::new();
        assert!(read_line(&mut r, &mut buf, 64).await.expect("read"));
        assert_eq!(buf, b"TEMP?");
        assert!(read_line(&mut r, &mut buf, 4).await.expect("read"));
        assert_eq!(buf, b"abcd");
    }
}
