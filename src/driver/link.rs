//! A line-oriented request/reply link with bounded retries and reconnect.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt, BufReader};

use super::{DeviceError, RetryPolicy};
use crate::transport::{BoxTransport, read_line};

/// Reopens a transport after the link dropped.
pub type Connector = Arc<
    dyn Fn() -> Pin<Box<dyn Future<Output = std::io::Result<BoxTransport>> + Send>> + Send + Sync,
>;

/// Counters of transient trouble, reported with a run's figures.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkCounters {
    /// Requests sent again after a timeout or a bad reply.
    pub retries: u64,
    /// Times the transport was reopened.
    pub reconnects: u64,
}

/// How a reply was judged.
#[derive(Debug)]
pub enum Verdict<T> {
    /// Usable.
    Ok(T),
    /// Not of the protocol's form: retry.
    Malformed(String),
    /// The instrument said no: do not retry.
    Refused(String),
}

/// Longest reply line accepted, bytes.
pub const MAX_REPLY: usize = 1024;

/// A request/reply link over a byte stream whose messages end in LF.
pub struct LineLink {
    device: String,
    io: Option<BufReader<BoxTransport>>,
    connector: Option<Connector>,
    policy: RetryPolicy,
    counters: LinkCounters,
}

impl std::fmt::Debug for LineLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LineLink")
            .field("device", &self.device)
            .field("connected", &self.io.is_some())
            .field("policy", &self.policy)
            .field("counters", &self.counters)
            .finish()
    }
}

impl LineLink {
    /// A link over an open transport; `connector` reopens it after a drop.
    pub fn new(
        device: &str,
        transport: BoxTransport,
        connector: Option<Connector>,
        policy: RetryPolicy,
    ) -> Self {
        Self {
            device: device.to_owned(),
            io: Some(BufReader::new(transport)),
            connector,
            policy,
            counters: LinkCounters::default(),
        }
    }

    /// Device name.
    pub fn device(&self) -> &str {
        &self.device
    }

    /// Transient trouble so far.
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    async fn ensure_open(&mut self) -> Result<&mut BufReader<BoxTransport>, DeviceError> {
        if self.io.is_none() {
            let Some(connect) = &self.connector else {
                return Err(DeviceError::Connect {
                    device: self.device.clone(),
                    source: std::io::Error::new(
                        std::io::ErrorKind::NotConnected,
                        "link closed and no way to reopen it",
                    ),
                });
            };
            let t = connect().await.map_err(|source| DeviceError::Connect {
                device: self.device.clone(),
                source,
            })?;
            self.counters.reconnects += 1;
            self.io = Some(BufReader::new(t));
        }
        match self.io.as_mut() {
            Some(io) => Ok(io),
            None => unreachable!("opened above"),
        }
    }

    /// Throw away bytes already waiting (a late reply to an earlier request).
    async fn drain(io: &mut BufReader<BoxTransport>) {
        let mut scratch = [0u8; 256];
        while let Ok(Ok(n)) =
            tokio::time::timeout(Duration::from_millis(1), io.read(&mut scratch)).await
        {
            if n == 0 {
                break;
            }
        }
    }

    /// Send a message that has no reply.
    pub async fn send(&mut self, request: &[u8]) -> Result<(), DeviceError> {
        let name = request_name(request);
        for _ in 0..self.policy.attempts.max(1) {
            let io = self.ensure_open().await?;
            let r = io.get_mut().write_all(request).await;
            let r = match r {
                Ok(()) => io.get_mut().flush().await,
                Err(e) => Err(e),
            };
            if r.is_ok() {
                return Ok(());
            }
            self.io = None;
            self.counters.retries += 1;
        }
        Err(DeviceError::Timeout {
            device: self.device.clone(),
            request: name,
            timeout_s: self.policy.timeout.as_secs_f64(),
            attempts: self.policy.attempts,
        })
    }

    /// Send `request` and judge the reply line with `judge`, retrying
    /// timeouts, bad replies and dropped links within the policy.
    pub async fn transact<T>(
        &mut self,
        request: &[u8],
        judge: impl Fn(&str) -> Verdict<T>,
    ) -> Result<T, DeviceError> {
        let name = request_name(request);
        let attempts = self.policy.attempts.max(1);
        let mut last_problem: Option<String> = None;
        let mut buf = Vec::new();
        for attempt in 1..=attempts {
            if attempt > 1 {
                self.counters.retries += 1;
            }
            let timeout = self.policy.timeout;
            let io = self.ensure_open().await?;
            Self::drain(io).await;
            let sent = async {
                io.get_mut().write_all(request).await?;
                io.get_mut().flush().await
            }
            .await;
            if sent.is_err() {
                self.io = None;
                continue;
            }
            match tokio::time::timeout(timeout, read_line(io, &mut buf, MAX_REPLY)).await {
                Err(_) => continue,
                Ok(Err(_)) | Ok(Ok(false)) => {
                    self.io = None;
                    continue;
                }
                Ok(Ok(true)) => {}
            }
            let line = String::from_utf8_lossy(&buf);
            match judge(&line) {
                Verdict::Ok(v) => return Ok(v),
                Verdict::Refused(reason) => {
                    return Err(DeviceError::Refused {
                        device: self.device.clone(),
                        request: name,
                        reason,
                    });
                }
                Verdict::Malformed(detail) => last_problem = Some(detail),
            }
        }
        Err(match last_problem {
            Some(detail) => DeviceError::Malformed {
                device: self.device.clone(),
                request: name,
                detail,
                attempts,
            },
            None => DeviceError::Timeout {
                device: self.device.clone(),
                request: name,
                timeout_s: self.policy.timeout.as_secs_f64(),
                attempts,
            },
        })
    }
}

/// Reopen a dropped link through its connector.
pub async fn reopen(
    device: &str,
    connector: Option<&Connector>,
) -> Result<BoxTransport, DeviceError> {
    let err = |source| DeviceError::Connect {
        device: device.to_owned(),
        source,
    };
    let Some(connect) = connector else {
        return Err(err(std::io::Error::new(
            std::io::ErrorKind::NotConnected,
            "link closed and no way to reopen it",
        )));
    };
    connect().await.map_err(err)
}

/// The request as text for messages (terminator stripped).
fn request_name(request: &[u8]) -> String {
    String::from_utf8_lossy(request).trim_end().to_owned()
}
