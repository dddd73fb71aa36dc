//! The station's listener: connections that hold the station without
//! asking it anything are dropped, so the page and its Abort button stay
//! reachable under a flood of half-open connections.
//!
//! - A connection has [`HEAD_TIMEOUT`] to send its first request head;
//!   one that has not is closed (a half-open connection sends nothing).
//! - At most [`HEADLESS_CAP`] connections may be waiting for their first
//!   head at once: a new one closes the oldest of them, so a flood evicts
//!   itself while a browser, which sends its request at once, gets in.
//! - At most [`CAP`] connections in all; beyond, a new connection is
//!   closed at once (the page and Abort keep theirs).

use std::collections::VecDeque;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use futures_util::task::AtomicWaker;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};

/// Time a connection has to send its first request head.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(10);
/// Connections waiting for their first request head at once.
pub const HEADLESS_CAP: usize = 64;
/// Connections in all.
pub const CAP: usize = 512;

/// One connection's standing with the listener.
#[derive(Debug, Default)]
struct Standing {
    /// Closed to make room for a newer one.
    evicted: AtomicBool,
    /// Wakes the connection's pending read when it is evicted.
    waker: AtomicWaker,
}

#[derive(Debug, Default)]
struct Slots {
    /// Connections open now.
    open: AtomicUsize,
    /// Those still waiting for their first head, oldest first.
    headless: Mutex<VecDeque<Arc<Standing>>>,
}

impl Slots {
    fn headless(&self) -> std::sync::MutexGuard<'_, VecDeque<Arc<Standing>>> {
        self.headless
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
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
            if self.slots.open.load(Ordering::Relaxed) >= CAP {
                drop(stream);
                continue;
            }
            let standing = Arc::new(Standing::default());
            {
                let mut waiting = self.slots.headless();
                if waiting.len() >= HEADLESS_CAP
                    && let Some(oldest) = waiting.pop_front()
                {
                    oldest.evicted.store(true, Ordering::Release);
                    oldest.waker.wake();
                }
                waiting.push_back(standing.clone());
            }
            self.slots.open.fetch_add(1, Ordering::Relaxed);
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
        let mut waiting = self.slots.headless();
        waiting.retain(|s| !Arc::ptr_eq(s, &self.standing));
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
}

impl Drop for Conn {
    fn drop(&mut self) {
        self.slots.open.fetch_sub(1, Ordering::Relaxed);
        if self.deadline.is_some() {
            let mut waiting = self.slots.headless();
            waiting.retain(|s| !Arc::ptr_eq(s, &self.standing));
        }
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
        if this.deadline.is_some() {
            this.standing.waker.register(cx.waker());
            if this.standing.evicted.load(Ordering::Acquire) {
                return Poll::Ready(Err(closed("closed to make room: no request sent")));
            }
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
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}
