//! The gyro link: frames from any byte stream through the sans-IO decoder,
//! reopened with backoff when it drops.

use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt};
use tokio::time::Instant;

use super::DeviceError;
use super::link::{Drops, LinkWatch, Reopen, open_once};
use crate::protocol::frame::{Decoder, Event, FrameLayout, LinkStats, WireFrame};

/// Reads frames from a transport; counts resyncs, CRC failures, gaps,
/// duplicates, reconnects and the longest time without a frame (see
/// [`LinkStats`]).
pub struct GyroReader<R> {
    device: String,
    reader: R,
    decoder: Decoder,
    silence: Duration,
    buf: Vec<u8>,
    reopen: Option<(Reopen<R>, Duration)>,
    drops: Drops,
    reconnects: u64,
    last_frame: Option<Instant>,
    longest_gap: Duration,
}

impl<R> std::fmt::Debug for GyroReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GyroReader")
            .field("device", &self.device)
            .field("stats", &self.decoder.stats())
            .finish_non_exhaustive()
    }
}

impl<R: AsyncRead + Unpin> GyroReader<R> {
    /// A reader; no valid frame for `silence` is an error.
    pub fn new(device: &str, reader: R, layout: FrameLayout, silence: Duration) -> Self {
        Self {
            device: device.to_owned(),
            reader,
            decoder: Decoder::new(layout),
            silence,
            buf: vec![0; 16 * 1024],
            reopen: None,
            drops: Drops::default(),
            reconnects: 0,
            last_frame: None,
            longest_gap: Duration::ZERO,
        }
    }

    /// Reopen the link with `reopen` when it drops (end of stream or a
    /// read error), with backoff, for up to `window`.
    pub fn with_reconnect(mut self, reopen: Reopen<R>, window: Duration) -> Self {
        self.reopen = Some((reopen, window));
        self
    }

    /// Tell the bench's `watch` of drops, returns and a loss.
    pub fn with_watch(mut self, watch: std::sync::Arc<LinkWatch>) -> Self {
        self.drops = Drops::watched(Some(watch));
        self
    }

    /// The device's name in errors (`gyro`, a batch's `gyro/SLOT`).
    pub fn device(&self) -> &str {
        &self.device
    }

    /// Link figures so far.
    pub fn stats(&self) -> LinkStats {
        LinkStats {
            reconnects: self.reconnects,
            longest_gap_ms: self.longest_gap.as_millis().try_into().unwrap_or(u64::MAX),
            ..self.decoder.stats()
        }
    }

    /// The next good frame; `Ok(None)` when a stream with no way to reopen
    /// it ends. A read error, or a link that cannot be reopened within its
    /// window, is an error naming the device.
    pub async fn next_frame(&mut self) -> Result<Option<WireFrame>, DeviceError> {
        let mut deadline = Instant::now() + self.silence;
        loop {
            while let Some(ev) = self.decoder.next_event() {
                if let Event::Frame(f) = ev {
                    let now = Instant::now();
                    if let Some(last) = self.last_frame {
                        self.longest_gap = self.longest_gap.max(now - last);
                    }
                    self.last_frame = Some(now);
                    self.drops.reset();
                    return Ok(Some(f));
                }
            }
            let read = tokio::time::timeout_at(deadline, self.reader.read(&mut self.buf)).await;
            let mut cause = match read {
                Err(_) => {
                    return Err(DeviceError::Silent {
                        device: self.device.clone(),
                        timeout_s: self.silence.as_secs_f64(),
                    });
                }
                Ok(Ok(0)) => {
                    std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the gyro link closed")
                }
                Ok(Ok(n)) => {
                    self.decoder.push(&self.buf[..n]);
                    continue;
                }
                Ok(Err(e)) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Ok(Err(e)) => e,
            };
            let Some((reopen, window)) = &self.reopen else {
                if cause.kind() == std::io::ErrorKind::UnexpectedEof {
                    return Ok(None);
                }
                return Err(DeviceError::Connect {
                    device: self.device.clone(),
                    cause,
                });
            };
            loop {
                self.drops.dropped(&self.device, *window, cause).await?;
                match open_once(&self.device, Some(reopen)).await? {
                    Ok(r) => {
                        self.reader = r;
                        self.reconnects += 1;
                        self.drops.reopened(&self.device);
                        break;
                    }
                    Err(e) => cause = e,
                }
            }
            deadline = Instant::now() + self.silence;
        }
    }
}
