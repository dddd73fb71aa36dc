//! The gyro's output: frames at the configured rate, streamed to a
//! transport (with stream faults applied).

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use tokio::io::{AsyncWrite, AsyncWriteExt};
use tokio::sync::broadcast::error::RecvError;

use super::SharedBench;
use super::faults::mangle_stream;

/// Longest a chunk of frames waits for room on the line, wall time (ours).
/// A real gyro does not wait for its reader at all: what its UART cannot
/// send is gone. A sped-up simulator is allowed this much so that a host's
/// scheduling hiccup at 30-200x (tens of milliseconds) loses nothing; it
/// is kept short because a pty is served from the simulator's start: a
/// client opening it minutes later must not be handed those minutes of
/// frames, which would land in its first records ("the host fell behind
/// the gyro").
pub const MAX_LINE_DELAY: Duration = Duration::from_millis(500);

/// Stream the gyro's bytes to `w` until the bench goes away or `w` fails.
/// A slow reader loses bytes (the decoder counts them as lost frames), as
/// a real unit's UART would: chunks older than [`MAX_LINE_DELAY`] when the
/// line has room again are dropped whole.
pub async fn serve_gyro<W: AsyncWrite + Unpin>(
    w: W,
    bench: Arc<SharedBench>,
) -> std::io::Result<()> {
    serve_unit_gyro(w, bench, 0).await
}

/// Stream unit `unit`'s gyro bytes (0: the first unit's; a batch's
/// others after it) to `w`, as [`serve_gyro`]. The gyro faults play on
/// the first unit's line; a lost unit's line (`unit-lost`) sends nothing.
pub async fn serve_unit_gyro<W: AsyncWrite + Unpin>(
    mut w: W,
    bench: Arc<SharedBench>,
    unit: usize,
) -> std::io::Result<()> {
    let Some(mut rx) = bench.lock().subscribe_unit_gyro(unit) else {
        return Ok(());
    };
    let mut position = 0u64;
    let faulty = unit == 0;
    loop {
        if faulty && bench.faults.gyro.outage.active() {
            return Ok(());
        }
        match rx.recv().await {
            Ok(chunk) => {
                let f = &bench.faults.gyro;
                let lost = unit > 0 && f.lost_line.load(Ordering::Relaxed) == unit;
                let silent = lost || (faulty && f.silent.load(Ordering::Relaxed));
                if silent || chunk.at.elapsed() > MAX_LINE_DELAY {
                    continue;
                }
                if !faulty {
                    w.write_all(&chunk.bytes).await?;
                    w.flush().await?;
                    continue;
                }
                let bytes = mangle_stream(f, &chunk.bytes, &mut position);
                w.write_all(&bytes).await?;
                w.flush().await?;
            }
            Err(RecvError::Lagged(_)) => continue,
            Err(RecvError::Closed) => return Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use super::*;
    use crate::clock::WallClock;
    use crate::driver::gyro::GyroReader;
    use crate::protocol::frame::FrameLayout;
    use crate::sim::{SharedBench, test_bench};
    use crate::transport::{open_serial, pty_pair};

    /// A pty is served from the simulator's start; a client opening it
    /// seconds later reads the frames of now, not a backlog of those
    /// seconds (they would land in its first records). At 30x and 400 Hz:
    /// 3 s unread is 36,000 frames; the client may see at most what is
    /// younger than the line's delay plus its own half second of reading.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_client_opening_a_served_pty_late_gets_no_backlog() {
        let speed = 30.0;
        let bench = SharedBench::new(test_bench(), Arc::new(WallClock::scaled(speed)));
        let rate_hz = bench.lock().twin.config().gyro.frame_rate_hz;
        let pty = pty_pair().expect("pty");
        let _ticker = bench.spawn_ticker(Duration::from_millis(5));
        tokio::spawn(serve_gyro(pty.master, bench.clone()));
        tokio::time::sleep(Duration::from_secs(3)).await;

        let port = open_serial(&pty.path, 0, false).expect("open the pty");
        let mut reader =
            GyroReader::new("gyro", port, FrameLayout::default(), Duration::from_secs(2));
        let window = Duration::from_millis(500);
        let start = Instant::now();
        let mut frames = 0u64;
        while start.elapsed() < window {
            reader.next_frame().await.expect("frames").expect("open");
            frames += 1;
        }
        let bound = (MAX_LINE_DELAY + start.elapsed()).as_secs_f64() * speed * rate_hz + 200.0;
        assert!(
            (frames as f64) < bound,
            "{frames} frames in {:?}: a backlog from before the port was opened (at most {bound:.0})",
            start.elapsed()
        );
        assert!(frames > 0);
        drop(pty.slave);
    }
}
