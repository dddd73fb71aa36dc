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
    watch: Option<std::sync::Arc<LinkWatch>>,
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
            watch: None,
        }
    }

    /// Tell the bench's `watch` of drops, returns and a loss.
    pub fn with_watch(mut self, watch: std::sync::Arc<LinkWatch>) -> Self {
        self.watch = Some(watch);
        self
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
                    drops.reopened(&self.device);
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
        let mut drops = Drops::watched(self.watch.clone());
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
        let mut a = Attempts::new(&device, &policy).watched(self.watch.clone());
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

/// What happened to one of a bench's links, as the run tells its
/// operator the moment it happens (a run waiting on a dropped link is not
/// a frozen run).
#[derive(Debug, Clone, PartialEq)]
pub enum LinkNotice {
    /// The link dropped; it is being reopened.
    Dropped {
        /// Device name.
        device: String,
        /// Why, in the system's words.
        cause: String,
        /// How long it is reopened before the device is declared lost, s.
        window_s: f64,
    },
    /// The link was reopened after a drop.
    Back {
        /// Device name.
        device: String,
        /// How long it was down, s (wall time).
        after_s: f64,
    },
    /// The link could not be reopened within its window.
    Lost {
        /// Device name.
        device: String,
        /// The window, s.
        window_s: f64,
    },
}

impl std::fmt::Display for LinkNotice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Dropped {
                device,
                cause,
                window_s,
            } => write!(
                f,
                "the {device} link dropped ({cause}): reopening it for up to {window_s:.0} s \
                 (reconnect_window_s in the bench file) before the run stops"
            ),
            Self::Back { device, after_s } => {
                write!(f, "the {device} link is back after {after_s:.1} s")
            }
            Self::Lost { device, window_s } => write!(
                f,
                "the {device} link could not be reopened within {window_s:.0} s: the run stops, \
                 and a link found down from now on is tried once, not waited for"
            ),
        }
    }
}

/// Shared by every link of one bench: what the links say as they drop,
/// come back or are lost (drained by the run, which tells its operator and
/// its log), and the word that waiting for a dropped link is over because
/// the run is stopping (an interrupt, or a device already declared lost):
/// from then on a link found down is tried once and given up, so a bench
/// that vanished ends its run within one reconnect window, not one per
/// request of the safe state and cleanup.
#[derive(Debug)]
pub struct LinkWatch {
    notices: std::sync::Mutex<Vec<LinkNotice>>,
    told: tokio::sync::Notify,
    stopping: tokio::sync::watch::Sender<Option<String>>,
    /// The first link lost: device, window (s), attempts, the last cause.
    lost: std::sync::Mutex<Option<(String, f64, u32, String)>>,
}

impl Default for LinkWatch {
    fn default() -> Self {
        Self {
            notices: std::sync::Mutex::default(),
            told: tokio::sync::Notify::new(),
            stopping: tokio::sync::watch::Sender::new(None),
            lost: std::sync::Mutex::default(),
        }
    }
}

impl LinkWatch {
    /// A watch for one bench's links.
    pub fn new() -> std::sync::Arc<Self> {
        std::sync::Arc::new(Self::default())
    }

    fn tell(&self, n: LinkNotice) {
        self.notices
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(n);
        self.told.notify_one();
    }

    /// What the links said since the last call, oldest first.
    pub fn take(&self) -> Vec<LinkNotice> {
        std::mem::take(
            &mut *self
                .notices
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        )
    }

    /// Wait until a link says something (returns at once when something
    /// was said and not yet waited for).
    pub async fn told(&self) {
        self.told.notified().await;
    }

    /// The run is stopping (`why`): dropped links are no longer waited for.
    /// The first reason is kept.
    pub fn stop_waiting(&self, why: &str) {
        self.stopping.send_if_modified(|s| {
            if s.is_some() {
                return false;
            }
            *s = Some(why.to_owned());
            true
        });
    }

    /// Why dropped links are no longer waited for, if they are not.
    pub fn stopping(&self) -> Option<String> {
        self.stopping.borrow().clone()
    }

    /// The first link that was lost, as the error that lost it: what a run
    /// stopped by a vanished bench names, whichever device it was waiting
    /// on when it noticed.
    pub fn first_loss(&self) -> Option<DeviceError> {
        let lost = self
            .lost
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        lost.as_ref().map(
            |(device, window_s, attempts, cause)| DeviceError::Unreachable {
                device: device.clone(),
                window_s: *window_s,
                attempts: *attempts,
                cause: std::io::Error::other(cause.clone()),
            },
        )
    }

    fn lose(&self, device: &str, window_s: f64, attempts: u32, cause: &std::io::Error) {
        let mut lost = self
            .lost
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if lost.is_none() {
            *lost = Some((device.to_owned(), window_s, attempts, cause.to_string()));
        }
        drop(lost);
        self.tell(LinkNotice::Lost {
            device: device.to_owned(),
            window_s,
        });
        self.stop_waiting(&format!("the {device} link was lost"));
    }

    /// Resolves once [`LinkWatch::stop_waiting`] was called.
    async fn stopped(&self) {
        let mut rx = self.stopping.subscribe();
        let _ = rx.wait_for(Option::is_some).await;
    }
}

/// Drops of a link during one exchange (or one outage of a stream): each
/// waits (0.25 s doubling to 8 s) before the link is reopened; once the
/// window has passed since the first, the device is unreachable. A
/// connection that opens and closes at once (a device behind a rebooting
/// switch) is a drop like any other, so nothing spins. With a
/// [`LinkWatch`], a drop that the first reopening does not mend, its end
/// and the loss are told as they happen, and a run that is stopping waits
/// no more.
#[derive(Debug, Default)]
pub struct Drops {
    since: Option<tokio::time::Instant>,
    wait: Duration,
    count: u32,
    /// Told down and not yet back.
    down: bool,
    watch: Option<std::sync::Arc<LinkWatch>>,
}

impl Drops {
    /// Drops told to `watch`.
    pub fn watched(watch: Option<std::sync::Arc<LinkWatch>>) -> Self {
        Self {
            watch,
            ..Self::default()
        }
    }

    /// The link dropped with `cause`: wait before reopening it, or give up
    /// once `window` has passed since the first drop (or at once when the
    /// run is stopping).
    pub async fn dropped(
        &mut self,
        device: &str,
        window: Duration,
        cause: std::io::Error,
    ) -> Result<(), DeviceError> {
        let since = *self.since.get_or_insert_with(tokio::time::Instant::now);
        self.count += 1;
        let watch = self.watch.clone();
        if let Some(w) = &watch {
            if let Some(why) = w.stopping() {
                return Err(DeviceError::GaveUp {
                    device: device.to_owned(),
                    why,
                    cause,
                });
            }
            // A link that reopens at the first try dropped for a moment
            // (counted in its figures); one that does not is told.
            if !self.down && self.count >= 2 {
                self.down = true;
                w.tell(LinkNotice::Dropped {
                    device: device.to_owned(),
                    cause: cause.to_string(),
                    window_s: window.as_secs_f64(),
                });
            }
        }
        let left = window.saturating_sub(since.elapsed());
        if left.is_zero() {
            if let Some(w) = &watch {
                w.lose(device, window.as_secs_f64(), self.count, &cause);
            }
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
        let sleep = tokio::time::sleep(self.wait.min(left));
        match &watch {
            Some(w) => {
                tokio::select! {
                    () = sleep => {}
                    // Asked to stop while waiting: the next drop gives up.
                    () = w.stopped() => {}
                }
            }
            None => sleep.await,
        }
        Ok(())
    }

    /// The link was reopened (said; the window still runs from the first
    /// drop until [`Drops::reset`], when the link works again).
    pub fn reopened(&mut self, device: &str) {
        if let (Some(since), Some(w)) = (self.since, &self.watch)
            && self.down
        {
            self.down = false;
            w.tell(LinkNotice::Back {
                device: device.to_owned(),
                after_s: since.elapsed().as_secs_f64(),
            });
        }
    }

    /// The link works again: the next drop starts a new outage.
    pub fn reset(&mut self) {
        let watch = self.watch.take();
        *self = Self::watched(watch);
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

    /// Its drops told to the bench's `watch`.
    pub fn watched(mut self, watch: Option<std::sync::Arc<LinkWatch>>) -> Self {
        self.drops = Drops::watched(watch);
        self
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
