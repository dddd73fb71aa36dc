//! The gyro link: frames from any byte stream through the sans-IO decoder.

use tokio::io::{AsyncRead, AsyncReadExt};

use super::DeviceError;
use crate::protocol::frame::{Decoder, Event, FrameLayout, LinkStats, WireFrame};

/// Reads frames from a transport; counts resyncs, CRC failures, gaps and
/// duplicates (see [`LinkStats`]).
#[derive(Debug)]
pub struct GyroReader<R> {
    device: String,
    reader: R,
    decoder: Decoder,
    silence: std::time::Duration,
    buf: Vec<u8>,
}

impl<R: AsyncRead + Unpin> GyroReader<R> {
    /// A reader; no valid frame for `silence` is an error.
    pub fn new(device: &str, reader: R, layout: FrameLayout, silence: std::time::Duration) -> Self {
        Self {
            device: device.to_owned(),
            reader,
            decoder: Decoder::new(layout),
            silence,
            buf: vec![0; 16 * 1024],
        }
    }

    /// Link figures so far.
    pub fn stats(&self) -> LinkStats {
        self.decoder.stats()
    }

    /// The next good frame; `Ok(None)` when the stream ends.
    pub async fn next_frame(&mut self) -> Result<Option<WireFrame>, DeviceError> {
        let Self {
            decoder,
            reader,
            buf,
            ..
        } = self;
        let next = async {
            loop {
                while let Some(ev) = decoder.next_event() {
                    if let Event::Frame(f) = ev {
                        return Ok(Some(f));
                    }
                }
                match reader.read(buf).await {
                    Ok(0) => return Ok(None),
                    Ok(n) => decoder.push(&buf[..n]),
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => return Ok(None),
                }
            }
        };
        match tokio::time::timeout(self.silence, next).await {
            Ok(r) => r,
            Err(_) => Err(DeviceError::Silent {
                device: self.device.clone(),
                timeout_s: self.silence.as_secs_f64(),
            }),
        }
    }
}
