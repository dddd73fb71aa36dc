//! `sim link-bench`: the simulated gyro served over a pty and read by the
//! bench's own gyro driver, as fast as the line carries it, to measure the
//! link (frames decoded, lost, CRC errors, resyncs) on this machine.

use std::sync::Arc;
use std::time::Duration;

use crate::clock::{Clock, WallClock};
use crate::driver::DeviceError;
use crate::driver::gyro::GyroReader;
use crate::protocol::frame::{FrameLayout, LinkStats};
use crate::sim::{SharedBench, SimBench, gyro::serve_gyro};
use crate::transport::{open_serial, pty_pair};
use crate::twin::TwinConfig;

/// What the link benchmark measured.
#[derive(Debug)]
pub struct LinkBench {
    /// Wall time measured, s.
    pub elapsed_s: f64,
    /// Frames decoded.
    pub frames: u64,
    /// Link figures from the decoder.
    pub stats: LinkStats,
}

/// Why the link benchmark could not run to its end.
#[derive(Debug, thiserror::Error)]
pub enum LinkBenchError {
    /// No pty pair to serve on.
    #[error("creating a pty pair: {0}")]
    Pty(#[source] std::io::Error),
    /// The pty's client end could not be opened.
    #[error("opening {path} at {baud} baud: {cause}")]
    Open {
        /// The pty's path.
        path: String,
        /// The line speed asked for.
        baud: u32,
        /// Why.
        #[source]
        cause: std::io::Error,
    },
    /// The driver gave up on the link.
    #[error(transparent)]
    Device(#[from] DeviceError),
    /// The served end went away.
    #[error("the pty closed during the benchmark")]
    Closed,
}

/// Serve the twin's gyro at `rate_hz` frames a second over a pty at
/// `baud`, read it with the gyro driver for `seconds` of wall time.
pub async fn run(rate_hz: f64, baud: u32, seconds: f64) -> Result<LinkBench, LinkBenchError> {
    let mut twin = TwinConfig::default_rl16();
    twin.gyro.frame_rate_hz = rate_hz;
    let clock: Arc<dyn Clock> = Arc::new(WallClock::start());
    let bench = SharedBench::new(
        SimBench::new(twin, 1, FrameLayout::default()),
        clock.clone(),
    );
    let pty = pty_pair().map_err(LinkBenchError::Pty)?;
    let port = open_serial(&pty.path, baud, false).map_err(|cause| LinkBenchError::Open {
        path: pty.path.clone(),
        baud,
        cause,
    })?;
    let mut reader = GyroReader::new("gyro", port, FrameLayout::default(), Duration::from_secs(2));
    let _ticker = bench.spawn_ticker(Duration::from_millis(5));
    tokio::spawn(serve_gyro(pty.master, bench.clone()));
    let start = clock.now_s();
    let mut frames = 0u64;
    while clock.now_s() - start < seconds {
        if reader.next_frame().await?.is_none() {
            return Err(LinkBenchError::Closed);
        }
        frames += 1;
    }
    drop(pty.slave);
    Ok(LinkBench {
        elapsed_s: clock.now_s() - start,
        frames,
        stats: reader.stats(),
    })
}
