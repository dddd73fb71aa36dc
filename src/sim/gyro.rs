//! The gyro's output: frames at the configured rate, streamed to a
//! transport (with stream faults applied).

use std::sync::Arc;
use std::sync::atomic::Ordering;

use tokio::io::{AsyncWrite, AsyncWriteExt};
use tokio::sync::broadcast::error::RecvError;

use super::SharedBench;
use super::faults::mangle_stream;

/// Stream the gyro's bytes to `w` until the bench goes away or `w` fails.
/// A slow reader loses bytes (the decoder counts them as lost frames), as
/// a real unit's UART would.
pub async fn serve_gyro<W: AsyncWrite + Unpin>(
    mut w: W,
    bench: Arc<SharedBench>,
) -> std::io::Result<()> {
    let mut rx = bench.lock().subscribe_gyro();
    let mut position = 0u64;
    loop {
        if bench.faults.gyro.outage.active() {
            return Ok(());
        }
        match rx.recv().await {
            Ok(chunk) => {
                let f = &bench.faults.gyro;
                if f.silent.load(Ordering::Relaxed) {
                    continue;
                }
                let bytes = mangle_stream(f, &chunk, &mut position);
                w.write_all(&bytes).await?;
                w.flush().await?;
            }
            Err(RecvError::Lagged(_)) => continue,
            Err(RecvError::Closed) => return Ok(()),
        }
    }
}
