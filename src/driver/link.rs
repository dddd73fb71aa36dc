//! A line-oriented request/reply link with bounded retries and reconnect.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt, BufReader};

use super::{DeviceError, RetryPolicy};
use crate::transport::{BoxTransport, read_line};

/// Reopens a link of type `R` after it dropped.
pub type Reopen<R> =
    Arc<dyn Fn() -> Pin<Box<dyn Future<Output = std::io::Result<R>> + Send>> + Send + Sync>;

/// Reopens a transport after the link dropped.
pub type Connector = Reopen<BoxTransport>;

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

    /// Transient trouble so far (the tests read it).
    #[cfg(test)]
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    /// The open link, reopened first if it dropped (each failed attempt
    /// is a drop: backoff, then give up past the window).
    async fn ensure_open(
        &mut self,
        drops: &mut Drops,
    ) -> Result<&mut BufReader<BoxTransport>, DeviceError> {
        while self.io.is_none() {
            match open_once(&self.device, self.connector.as_ref()).await? {
                Ok(t) => {
                    self.counters.reconnects += 1;
                    self.io = Some(BufReader::new(t));
                }
                Err(e) => {
                    drops
                        .dropped(&self.device, self.policy.reconnect_window, e)
                        .await?;
                }
            }
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
        let mut drops = Drops::default();
        loop {
            let io = self.ensure_open(&mut drops).await?;
            let r = io.get_mut().write_all(request).await;
            let r = match r {
                Ok(()) => io.get_mut().flush().await,
                Err(e) => Err(e),
            };
            match r {
                Ok(()) => return Ok(()),
                Err(e) => {
                    self.io = None;
                    self.counters.retries += 1;
                    drops
                        .dropped(&self.device, self.policy.reconnect_window, e)
                        .await?;
                }
            }
        }
    }

    /// Send `request` and judge the reply line with `judge`, retrying
    /// timeouts and bad replies within the policy's attempts, and a dropped
    /// link (reopened with backoff) within its reconnect window.
    pub async fn transact<T>(
        &mut self,
        request: &[u8],
        judge: impl Fn(&str) -> Verdict<T>,
    ) -> Result<T, DeviceError> {
        let name = request_name(request);
        let device = self.device.clone();
        let policy = self.policy;
        let mut a = Attempts::new(&device, &policy);
        let mut buf = Vec::new();
        while a.left() {
            if a.retrying() {
                self.counters.retries += 1;
            }
            let t = self
                .try_once(request, &mut buf, &judge, &mut a.drops)
                .await?;
            if let Some(v) = a.judge(t, &name).await? {
                return Ok(v);
            }
        }
        Err(a.spent(name))
    }

    /// One try of `request`: sent on the open link (reopened first if it
    /// dropped), its reply line judged.
    async fn try_once<T>(
        &mut self,
        request: &[u8],
        buf: &mut Vec<u8>,
        judge: &impl Fn(&str) -> Verdict<T>,
        drops: &mut Drops,
    ) -> Result<Try<T>, DeviceError> {
        let timeout = self.policy.timeout;
        let io = self.ensure_open(drops).await?;
        Self::drain(io).await;
        let sent = async {
            io.get_mut().write_all(request).await?;
            io.get_mut().flush().await
        }
        .await;
        if let Err(e) = sent {
            self.io = None;
            return Ok(Try::Broken(e));
        }
        let open = match tokio::time::timeout(timeout, read_line(io, buf, MAX_REPLY)).await {
            Err(_) => return Ok(Try::Late),
            Ok(r) => r,
        };
        if let Err(e) = open.and_then(|open| {
            open.then_some(()).ok_or_else(|| {
                std::io::Error::new(
                    std::io::ErrorKind::UnexpectedEof,
                    "the device closed the connection",
                )
            })
        }) {
            self.io = None;
            return Ok(Try::Broken(e));
        }
        Ok(match judge(&String::from_utf8_lossy(buf)) {
            Verdict::Ok(v) => Try::Done(v),
            Verdict::Refused(reason) => Try::Refused(reason),
            Verdict::Malformed(detail) => Try::Again(Some(detail)),
        })
    }
}

/// Drops of a link during one exchange (or one outage of a stream): each
/// waits (0.25 s doubling to 8 s) before the link is reopened; once the
/// window has passed since the first, the device is unreachable. A
/// connection that opens and closes at once (a device behind a rebooting
/// switch) is a drop like any other, so nothing spins.
#[derive(Debug, Default)]
pub struct Drops {
    since: Option<tokio::time::Instant>,
    wait: Duration,
    count: u32,
}

impl Drops {
    /// The link dropped with `cause`: wait before reopening it, or give up
    /// once `window` has passed since the first drop.
    pub async fn dropped(
        &mut self,
        device: &str,
        window: Duration,
        cause: std::io::Error,
    ) -> Result<(), DeviceError> {
        let since = *self.since.get_or_insert_with(tokio::time::Instant::now);
        self.count += 1;
        let left = window.saturating_sub(since.elapsed());
        if left.is_zero() {
            return Err(DeviceError::Unreachable {
                device: device.to_owned(),
                window_s: window.as_secs_f64(),
                attempts: self.count,
                cause,
            });
        }
        self.wait = if self.wait.is_zero() {
            BACKOFF_FIRST
        } else {
            (self.wait * 2).min(BACKOFF_MAX)
        };
        tokio::time::sleep(self.wait.min(left)).await;
        Ok(())
    }

    /// The link works again: the next drop starts a new outage.
    pub fn reset(&mut self) {
        *self = Self::default();
    }
}

/// What one try of a request came to.
#[derive(Debug)]
pub enum Try<T> {
    /// The answer.
    Done(T),
    /// The device refused the request: it is not tried again.
    Refused(String),
    /// A reply that cannot be used (garbled, cut, or the device busy):
    /// another attempt, with what was wrong when there is something to say.
    Again(Option<String>),
    /// No reply within the timeout: another attempt.
    Late,
    /// The link broke: it is reopened (backoff, within the reconnect
    /// window) without spending an attempt.
    Broken(std::io::Error),
}

/// The retry policy applied to one request, the one loop every
/// request/reply driver runs: `while a.left() { ... a.judge(try) ... }`,
/// then `a.spent(request)`.
#[derive(Debug)]
pub struct Attempts<'a> {
    device: &'a str,
    policy: &'a RetryPolicy,
    /// The drops of the link during this request (reopening waits on them).
    pub drops: Drops,
    attempt: u32,
    last_problem: Option<String>,
}

impl<'a> Attempts<'a> {
    /// A request to `device` under `policy`, not yet tried.
    pub fn new(device: &'a str, policy: &'a RetryPolicy) -> Self {
        Self {
            device,
            policy,
            drops: Drops::default(),
            attempt: 0,
            last_problem: None,
        }
    }

    /// True while attempts are left.
    pub fn left(&self) -> bool {
        self.attempt < self.policy.attempts.max(1)
    }

    /// True when this try is a retry (after a failed attempt or a drop):
    /// the link's `retries` counts it.
    pub fn retrying(&self) -> bool {
        self.attempt > 0 || self.drops.since.is_some()
    }

    /// Take a try's result: the answer, none to try again, or the error
    /// that ends the request (a refusal, or a link that stayed down past
    /// its window).
    pub async fn judge<T>(&mut self, t: Try<T>, request: &str) -> Result<Option<T>, DeviceError> {
        match t {
            Try::Done(v) => Ok(Some(v)),
            Try::Refused(reason) => Err(DeviceError::Refused {
                device: self.device.to_owned(),
                request: request.to_owned(),
                reason,
            }),
            Try::Again(problem) => {
                if problem.is_some() {
                    self.last_problem = problem;
                }
                self.attempt += 1;
                Ok(None)
            }
            Try::Late => {
                self.attempt += 1;
                Ok(None)
            }
            Try::Broken(e) => {
                self.drops
                    .dropped(self.device, self.policy.reconnect_window, e)
                    .await?;
                Ok(None)
            }
        }
    }

    /// The error once every attempt is spent: the last unusable reply,
    /// else the timeout.
    pub fn spent(self, request: String) -> DeviceError {
        let attempts = self.policy.attempts.max(1);
        match self.last_problem {
            Some(detail) => DeviceError::Malformed {
                device: self.device.to_owned(),
                request,
                detail,
                attempts,
            },
            None => DeviceError::Timeout {
                device: self.device.to_owned(),
                request,
                timeout_s: self.policy.timeout.as_secs_f64(),
                attempts,
            },
        }
    }
}

/// First wait between reconnect attempts; it doubles up to [`BACKOFF_MAX`].
pub const BACKOFF_FIRST: Duration = Duration::from_millis(250);
/// Longest wait between reconnect attempts.
pub const BACKOFF_MAX: Duration = Duration::from_secs(8);

/// One attempt to reopen a dropped link: `Err` when there is no way to
/// reopen it, `Ok(Err)` when the attempt failed (a drop to wait out).
pub async fn open_once<R>(
    device: &str,
    connector: Option<&Reopen<R>>,
) -> Result<std::io::Result<R>, DeviceError> {
    let Some(connect) = connector else {
        return Err(DeviceError::Connect {
            device: device.to_owned(),
            cause: std::io::Error::new(
                std::io::ErrorKind::NotConnected,
                "link closed and no way to reopen it",
            ),
        });
    };
    Ok(connect().await)
}

/// The request as text for messages (terminator stripped).
fn request_name(request: &[u8]) -> String {
    String::from_utf8_lossy(request).trim_end().to_owned()
}
