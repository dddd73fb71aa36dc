//! The station's listener: who may hold a connection, and for how long,
//! so that the page, the API and Abort stay reachable for whoever holds
//! the token however many connections others open.
//!
//! - A connection is *unproven* until one of its requests carries the
//!   station's token ([`Admission::prove`], called by the station's gate on
//!   the request head, before any body is read); then it is a token
//!   holder's and never closed to make room.
//! - A connection has [`HEAD_TIMEOUT`] to send its first request head;
//!   one that has not is closed (a half-open connection sends nothing).
//! - At most [`HEADLESS_CAP`] unproven connections wait for their first
//!   head at once, and at most [`UNPROVEN_CAP`] are unproven in all: a new
//!   connection beyond either closes the oldest of them, so a flood evicts
//!   itself while a browser, which sends its request at once, gets in. The
//!   last [`RESERVED`] of the [`CAP`] slots are thus only ever a token
//!   holder's.
//! - At most [`CAP`] connections in all: beyond, a new connection closes
//!   the oldest unproven one, or is closed at once when every slot is a
//!   token holder's.
//! - [`Closer::close_all`] (the station stopping) closes every connection
//!   at its next read or write, whatever it waits for.

use std::collections::VecDeque;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::task::{Context, Poll};
use std::time::Duration;

use futures_util::task::AtomicWaker;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};

/// Time a connection has to send its first request head.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(10);
/// Unproven connections waiting for their first request head at once.
pub const HEADLESS_CAP: usize = 64;
/// Connections in all.
pub const CAP: usize = 512;
/// Slots only token holders' connections may take.
pub const RESERVED: usize = 64;
/// Unproven connections in all (every slot but the reserved ones).
pub const UNPROVEN_CAP: usize = CAP - RESERVED;

/// Where a connection stands.
const HEADLESS: u8 = 0;
const HEADED: u8 = 1;
const PROVEN: u8 = 2;

/// One connection's standing with the listener.
#[derive(Debug, Default)]
struct Standing {
    /// [`HEADLESS`], [`HEADED`] or [`PROVEN`]; changed under the slots'
    /// lock.
    stage: AtomicU8,
    /// Closed to make room for a newer one.
    evicted: AtomicBool,
    /// Wakes the connection's pending read or write when it is closed.
    waker: AtomicWaker,
}

impl Standing {
    fn stage(&self) -> u8 {
        self.stage.load(Ordering::Acquire)
    }

    fn live(&self) -> bool {
        !self.evicted.load(Ordering::Acquire)
    }

    fn evict(&self) {
        self.evicted.store(true, Ordering::Release);
        self.waker.wake();
    }
}

#[derive(Debug, Default)]
struct Slots {
    /// Every connection open now, oldest first (an evicted one until it
    /// has closed).
    conns: Mutex<VecDeque<Arc<Standing>>>,
    /// The station stops: every connection closes.
    closing: AtomicBool,
}

impl Slots {
    fn conns(&self) -> MutexGuard<'_, VecDeque<Arc<Standing>>> {
        self.conns.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Room for one more connection, evicting the oldest unproven ones the
    /// limits call for; false when every slot is a token holder's.
    fn admit(&self, standing: Arc<Standing>) -> bool {
        let mut conns = self.conns();
        let oldest = |conns: &VecDeque<Arc<Standing>>, stage: Option<u8>| {
            conns
                .iter()
                .find(|s| {
                    s.live() && s.stage() != PROVEN && stage.is_none_or(|want| s.stage() == want)
                })
                .cloned()
        };
        let count = |conns: &VecDeque<Arc<Standing>>, f: &dyn Fn(&Standing) -> bool| {
            conns.iter().filter(|s| s.live() && f(s)).count()
        };
        if count(&conns, &|s| s.stage() == HEADLESS) >= HEADLESS_CAP
            && let Some(s) = oldest(&conns, Some(HEADLESS))
        {
            s.evict();
        }
        if count(&conns, &|s| s.stage() != PROVEN) >= UNPROVEN_CAP
            && let Some(s) = oldest(&conns, None)
        {
            s.evict();
        }
        if count(&conns, &|_| true) >= CAP {
            match oldest(&conns, None) {
                Some(s) => s.evict(),
                None => return false,
            }
        }
        // Evicted connections close at their next poll, which their wake
        // brings at once; this bounds the descriptors should one linger.
        if conns.len() >= CAP + HEADLESS_CAP {
            return false;
        }
        conns.push_back(standing);
        true
    }

    fn leave(&self, standing: &Arc<Standing>) {
        self.conns().retain(|s| !Arc::ptr_eq(s, standing));
    }

    fn set_stage(&self, standing: &Standing, stage: u8) {
        let _conns = self.conns();
        if standing.stage() < stage {
            standing.stage.store(stage, Ordering::Release);
        }
    }
}

/// A TCP listener with the station's limits.
#[derive(Debug)]
pub struct Guarded {
    inner: TcpListener,
    slots: Arc<Slots>,
}

impl Guarded {
    /// Limits on `inner`.
    pub fn new(inner: TcpListener) -> Self {
        Self {
            inner,
            slots: Arc::default(),
        }
    }

    /// What closes every connection of this listener when the station
    /// stops.
    pub fn closer(&self) -> Closer {
        Closer(self.slots.clone())
    }
}

/// Closes every connection of a [`Guarded`] listener.
#[derive(Debug, Clone)]
pub struct Closer(Arc<Slots>);

impl Closer {
    /// Every connection open (or opened from now on) fails its next read
    /// or write: a half-sent request, an idle browser, a flood, none of
    /// them holds the station's stop.
    pub fn close_all(&self) {
        self.0.closing.store(true, Ordering::Release);
        for s in self.0.conns().iter() {
            s.waker.wake();
        }
    }

    /// Connections open now (tests, and what the stop says).
    pub fn open(&self) -> usize {
        self.0.conns().len()
    }
}

impl axum::serve::Listener for Guarded {
    type Io = Conn;
    type Addr = std::net::SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        loop {
            let (stream, addr) = match self.inner.accept().await {
                Ok(c) => c,
                // Out of descriptors, say: give the others time to close.
                Err(_) => {
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            };
            let standing = Arc::new(Standing::default());
            if self.slots.closing.load(Ordering::Acquire) || !self.slots.admit(standing.clone()) {
                drop(stream);
                continue;
            }
            let conn = Conn {
                stream,
                slots: self.slots.clone(),
                standing,
                deadline: Some(Box::pin(tokio::time::sleep(HEAD_TIMEOUT))),
                tail: [0; 3],
            };
            return (conn, addr);
        }
    }

    fn local_addr(&self) -> std::io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

/// A connection as the station's gate sees it: the gate proves it when a
/// request of it carries the token (axum's `ConnectInfo`).
#[derive(Debug, Clone)]
pub struct Admission {
    slots: Arc<Slots>,
    standing: Arc<Standing>,
}

impl Admission {
    /// The connection is a token holder's: never closed to make room
    /// again (and kept, should it just have been chosen to make room).
    pub fn prove(&self) {
        let _conns = self.slots.conns();
        self.standing.stage.store(PROVEN, Ordering::Release);
        self.standing.evicted.store(false, Ordering::Release);
    }
}

impl axum::extract::connect_info::Connected<axum::serve::IncomingStream<'_, Guarded>>
    for Admission
{
    fn connect_info(stream: axum::serve::IncomingStream<'_, Guarded>) -> Self {
        let conn = stream.io();
        Self {
            slots: conn.slots.clone(),
            standing: conn.standing.clone(),
        }
    }
}

/// An accepted connection under the listener's limits.
#[derive(Debug)]
pub struct Conn {
    stream: TcpStream,
    slots: Arc<Slots>,
    standing: Arc<Standing>,
    /// Until the first request head has arrived.
    deadline: Option<Pin<Box<tokio::time::Sleep>>>,
    /// The last bytes read, to find the head's end across reads.
    tail: [u8; 3],
}

impl Conn {
    /// The first head arrived: no deadline, no longer headless.
    fn headed(&mut self) {
        self.deadline = None;
        self.slots.set_stage(&self.standing, HEADED);
    }

    /// Whether `read` (after the bytes before it) completes a head.
    fn ends_head(&mut self, read: &[u8]) -> bool {
        let mut joined = Vec::with_capacity(3 + read.len());
        joined.extend_from_slice(&self.tail);
        joined.extend_from_slice(read);
        let found = joined.windows(4).any(|w| w == b"\r\n\r\n");
        let keep = joined.len().min(3);
        let mut tail = [0u8; 3];
        tail[3 - keep..].copy_from_slice(&joined[joined.len() - keep..]);
        self.tail = tail;
        found
    }

    /// Why this connection is closed now, if it is: the station stops, or
    /// its slot went to a newer connection. Registers for the wake-up.
    fn closed(&self, cx: &Context<'_>) -> Option<std::io::Error> {
        self.standing.waker.register(cx.waker());
        if self.slots.closing.load(Ordering::Acquire) {
            return Some(closed("the station is stopping"));
        }
        (!self.standing.live())
            .then(|| closed("closed to make room: no request with the station's token"))
    }
}

impl Drop for Conn {
    fn drop(&mut self) {
        self.slots.leave(&self.standing);
    }
}

fn closed(why: &str) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::TimedOut, why.to_owned())
}

impl AsyncRead for Conn {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let this = &mut *self;
        if let Some(e) = this.closed(cx) {
            return Poll::Ready(Err(e));
        }
        let before = buf.filled().len();
        match Pin::new(&mut this.stream).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                if this.deadline.is_some() {
                    let read = buf.filled()[before..].to_vec();
                    if this.ends_head(&read) {
                        this.headed();
                    }
                }
                Poll::Ready(Ok(()))
            }
            Poll::Pending => {
                let expired = this
                    .deadline
                    .as_mut()
                    .is_some_and(|d| d.as_mut().poll(cx).is_ready());
                if expired {
                    Poll::Ready(Err(closed("no request head within the time allowed")))
                } else {
                    Poll::Pending
                }
            }
            other => other,
        }
    }
}

impl AsyncWrite for Conn {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        // A client that never reads its answer holds no slot either.
        if let Some(e) = self.closed(cx) {
            return Poll::Ready(Err(e));
        }
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        if let Some(e) = self.closed(cx) {
            return Poll::Ready(Err(e));
        }
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A connection admitted at `stage`; those it evicted close (as their
    /// `Conn` does at its next poll).
    fn admitted(slots: &Slots, stage: u8) -> Arc<Standing> {
        let s = Arc::new(Standing::default());
        assert!(slots.admit(s.clone()));
        slots.set_stage(&s, stage);
        slots.conns().retain(|s| s.live());
        s
    }

    /// However many unproven connections come, the last slots stay a
    /// token holder's, and a token holder is never evicted.
    #[test]
    fn unproven_connections_never_take_the_reserved_slots() {
        let slots = Slots::default();
        let holders: Vec<_> = (0..10).map(|_| admitted(&slots, PROVEN)).collect();
        let flood: Vec<_> = (0..2 * CAP).map(|_| admitted(&slots, HEADED)).collect();
        let live_unproven = flood.iter().filter(|s| s.live()).count();
        assert_eq!(live_unproven, UNPROVEN_CAP);
        assert!(holders.iter().all(|s| s.live()));
        // The oldest went first.
        assert!(!flood[0].live() && flood[2 * CAP - 1].live());
        // Token holders fill every other slot...
        for s in &flood {
            slots.leave(s);
        }
        let more: Vec<_> = (0..CAP - 10).map(|_| admitted(&slots, PROVEN)).collect();
        assert!(more.iter().all(|s| s.live()));
        // ...and then a new connection is refused, none evicted.
        assert!(!slots.admit(Arc::new(Standing::default())));
        assert!(more.iter().chain(&holders).all(|s| s.live()));
    }

    /// Connections waiting for their first head have a cap of their own.
    #[test]
    fn headless_connections_evict_the_oldest_headless_first() {
        let slots = Slots::default();
        let headed = admitted(&slots, HEADED);
        let headless: Vec<_> = (0..=HEADLESS_CAP)
            .map(|_| admitted(&slots, HEADLESS))
            .collect();
        assert!(!headless[0].live(), "the oldest headless one made room");
        assert!(headless[1..].iter().all(|s| s.live()));
        assert!(headed.live(), "a headed connection is not one of them");
    }

    /// A connection chosen to make room that then proves itself is kept.
    #[test]
    fn proving_keeps_a_connection_chosen_to_make_room() {
        let slots = Arc::new(Slots::default());
        let s = admitted(&slots, HEADED);
        s.evict();
        Admission {
            slots: slots.clone(),
            standing: s.clone(),
        }
        .prove();
        assert!(s.live() && s.stage() == PROVEN);
    }
}
