//! The run's channels, live: a Foxglove WebSocket server
//! (`foxglove.websocket.v1`, the official `foxglove` crate) that
//! publishes every message the [`super::writer::Recorder`] writes, on the
//! same topics, with the same JSON Schemas and log times. Foxglove or
//! Lichtblick opened on `ws://127.0.0.1:PORT` shows a run as it goes, the
//! way it shows the MCAP afterwards.
//!
//! The protocol has no authentication, so the server listens on loopback
//! only; an engineer elsewhere reaches it through an SSH tunnel. Loopback
//! is not enough against a browser: any web page opened on the bench PC
//! could open a WebSocket to it. A gate in front of the SDK's server reads
//! each connection's upgrade request and refuses a browser `Origin` other
//! than loopback pages and the Foxglove and Lichtblick apps
//! ([`allowed_origin`]; `GYROBENCH_LIVE_ORIGINS` adds more), then splices
//! the connection to the server. Messages are offered, never awaited: a
//! slow or stalled client loses messages from its own backlog (the
//! server's policy), the run and its log never wait for it, and with no
//! client subscribed a message costs a check. Stopping drops every client
//! connection first and gives the server a deadline, so a client that
//! does not drain never holds the end of a run.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;

use foxglove::{Context, PartialMetadata, RawChannel, Schema, WebSocketServer};

use super::schema::{CHANNELS, SLOT_TOPICS};

/// Port Foxglove and Lichtblick try first for a live connection.
pub const DEFAULT_PORT: u16 = 8765;

/// Why the live server could not start.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// Not a loopback address.
    #[error(
        "the live Foxglove stream listens on loopback only ({0} is not): its protocol has no access control; reach it from elsewhere through an SSH tunnel"
    )]
    NotLoopback(SocketAddr),
    /// The server did not start (the port is taken, say).
    #[error(
        "starting the live Foxglove stream on {addr}: {cause} (another station or run --live may hold the port: give another with --live 127.0.0.1:PORT)"
    )]
    Start {
        /// Where it was asked to listen.
        addr: SocketAddr,
        /// The SDK's reason.
        cause: String,
    },
}

/// A running live server and the log's channels on it.
pub struct Live {
    ctx: Arc<Context>,
    server: Option<foxglove::WebSocketServerHandle>,
    /// The log's channels; a batch's other units' are made (and
    /// advertised) when their first message comes.
    channels: std::sync::Mutex<BTreeMap<String, Arc<RawChannel>>>,
    addr: SocketAddr,
    /// Ends the gate and every connection through it.
    closing: tokio::sync::watch::Sender<bool>,
}

/// Origins of browser pages allowed besides loopback ones: the apps that
/// open a live connection.
pub const APP_ORIGINS: [&str; 4] = [
    "https://app.foxglove.dev",
    "https://studio.foxglove.dev",
    "https://lichtblick-suite.github.io",
    // The desktop apps (Electron) load their pages from files.
    "file://",
];

/// The environment variable that adds origins (comma separated, exactly as
/// the browser sends them: `https://viewer.lab.example`).
pub const ORIGINS_ENV: &str = "GYROBENCH_LIVE_ORIGINS";

/// Whether a connection whose upgrade request carries `origin` (none: not
/// a browser) may read the stream: no origin, a page of this computer
/// (`http(s)://localhost`, `127.x.x.x`, `[::1]`, any port), one of
/// [`APP_ORIGINS`], or one of `extra`.
pub fn allowed_origin(origin: Option<&str>, extra: &[String]) -> bool {
    let Some(o) = origin.map(str::trim) else {
        return true;
    };
    if APP_ORIGINS.contains(&o) || extra.iter().any(|e| e == o) {
        return true;
    }
    let Some(rest) = o
        .strip_prefix("http://")
        .or_else(|| o.strip_prefix("https://"))
    else {
        return false;
    };
    let host = if let Some(v6) = rest.strip_prefix('[') {
        v6.split(']').next().unwrap_or("")
    } else {
        rest.split(':').next().unwrap_or("")
    };
    host == "localhost"
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// The `Origin` header of an HTTP request head, if it has one.
fn origin_of(head: &str) -> Option<&str> {
    head.lines().skip(1).find_map(|l| {
        let (k, v) = l.split_once(':')?;
        k.trim().eq_ignore_ascii_case("origin").then(|| v.trim())
    })
}

/// Longest request head the gate reads, bytes.
const MAX_HEAD_BYTES: usize = 16 * 1024;
/// How long a connection may take to send its request head, s.
const HEAD_TIMEOUT_S: u64 = 10;
/// How long the server is given to stop once every client is dropped, s.
const STOP_DEADLINE_S: u64 = 5;

/// One connection through the gate: its request head read (bounded in
/// size and time), its origin checked, then spliced to the server at
/// `inner` until either side closes or the stream stops.
async fn gate(
    mut client: tokio::net::TcpStream,
    inner: SocketAddr,
    extra: Arc<Vec<String>>,
    mut closing: tokio::sync::watch::Receiver<bool>,
) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut head = Vec::new();
    let read_head = async {
        let mut buf = [0u8; 2048];
        while !head.windows(4).any(|w| w == b"\r\n\r\n") && head.len() < MAX_HEAD_BYTES {
            match client.read(&mut buf).await {
                Ok(0) | Err(_) => return false,
                Ok(n) => head.extend_from_slice(&buf[..n]),
            }
        }
        head.windows(4).any(|w| w == b"\r\n\r\n")
    };
    let complete =
        tokio::time::timeout(std::time::Duration::from_secs(HEAD_TIMEOUT_S), read_head).await;
    if complete != Ok(true) {
        return;
    }
    let text = String::from_utf8_lossy(&head);
    if !allowed_origin(origin_of(&text), &extra) {
        let body = "this page's origin may not read gyrobench's live stream (docs/station.md)\n";
        let _refused = client
            .write_all(
                format!(
                    "HTTP/1.1 403 Forbidden\r\nContent-Type: text/plain\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                    body.len()
                )
                .as_bytes(),
            )
            .await;
        return;
    }
    let Ok(mut server) = tokio::net::TcpStream::connect(inner).await else {
        return;
    };
    if server.write_all(&head).await.is_err() {
        return;
    }
    tokio::select! {
        _ = tokio::io::copy_bidirectional(&mut client, &mut server) => {}
        _ = closing.wait_for(|c| *c) => {}
    }
}

impl std::fmt::Debug for Live {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Live")
            .field("addr", &self.addr)
            .finish_non_exhaustive()
    }
}

/// A JSON channel on `ctx` with its JSON Schema.
fn channel(
    ctx: &Arc<Context>,
    topic: &str,
    name: &str,
    schema: &'static str,
) -> Result<Arc<RawChannel>, foxglove::FoxgloveError> {
    ctx.channel_builder(topic)
        .message_encoding("json")
        .schema(Schema::new(name, "jsonschema", schema.as_bytes()))
        .build_raw()
}

impl Live {
    /// Serve the log's channels on `addr` (port 0: any free port) from the
    /// current async runtime.
    pub async fn start(addr: SocketAddr) -> Result<Self, LiveError> {
        if !addr.ip().is_loopback() {
            return Err(LiveError::NotLoopback(addr));
        }
        let start_err = |e: foxglove::FoxgloveError| LiveError::Start {
            addr,
            cause: e.to_string(),
        };
        let ctx = Context::new();
        let mut channels = BTreeMap::new();
        for (topic, name, schema) in CHANNELS {
            let ch = channel(&ctx, topic, name, schema).map_err(start_err)?;
            channels.insert(topic.to_owned(), ch);
        }
        // The SDK's server on a loopback port of its own; the gate takes
        // the address asked for.
        let server = WebSocketServer::new()
            .context(&ctx)
            .name(format!("gyrobench {}", env!("CARGO_PKG_VERSION")))
            .bind("127.0.0.1", 0)
            .start()
            .await
            .map_err(start_err)?;
        let inner = SocketAddr::from(([127, 0, 0, 1], server.port()));
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .map_err(|e| LiveError::Start {
                addr,
                cause: e.to_string(),
            })?;
        let addr = listener.local_addr().map_err(|e| LiveError::Start {
            addr,
            cause: e.to_string(),
        })?;
        let extra: Arc<Vec<String>> = Arc::new(
            std::env::var(ORIGINS_ENV)
                .unwrap_or_default()
                .split(',')
                .map(str::trim)
                .filter(|o| !o.is_empty())
                .map(str::to_owned)
                .collect(),
        );
        let (closing, watch) = tokio::sync::watch::channel(false);
        let mut stop = watch.clone();
        tokio::spawn(async move {
            loop {
                tokio::select! {
                    accepted = listener.accept() => {
                        if let Ok((client, _)) = accepted {
                            tokio::spawn(gate(client, inner, extra.clone(), watch.clone()));
                        }
                    }
                    _ = stop.wait_for(|c| *c) => return,
                }
            }
        });
        Ok(Self {
            ctx,
            server: Some(server),
            channels: std::sync::Mutex::new(channels),
            addr,
            closing,
        })
    }

    /// Where it listens (the port chosen when 0 was asked).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The URL a Foxglove or Lichtblick "Open connection" takes.
    pub fn url(&self) -> String {
        format!("ws://{}", self.addr)
    }

    /// The line that tells the operator where to connect.
    pub fn banner(&self) -> String {
        format!(
            "live: {} (Foxglove or Lichtblick: Open connection, Foxglove WebSocket)",
            self.url()
        )
    }

    /// Offer one logged message (its JSON and log time, ns since the
    /// epoch) to the clients subscribed to `topic`.
    pub fn publish(&self, topic: &str, log_time_ns: u64, json: &[u8]) {
        let ch = {
            // A publisher that panicked left the map whole: go on with it.
            let mut channels = self
                .channels
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            match channels.get(topic) {
                Some(ch) => Some(ch.clone()),
                None => self.slot_channel(topic).inspect(|ch| {
                    channels.insert(topic.to_owned(), ch.clone());
                }),
            }
        };
        if let Some(ch) = ch {
            ch.log_with_meta(
                json,
                PartialMetadata {
                    log_time: Some(log_time_ns),
                },
            );
        }
    }

    /// The channel of a batch's unit's topic (`/slots/NAME/gyro/frames`,
    /// ...), with the schema of the single-unit topic it copies; none for
    /// any other topic.
    fn slot_channel(&self, topic: &str) -> Option<Arc<RawChannel>> {
        let rest = topic.strip_prefix("/slots/")?;
        let own = &rest[rest.find('/')?..];
        let (_, name, schema) = CHANNELS
            .into_iter()
            .find(|(t, _, _)| *t == own && SLOT_TOPICS.contains(t))?;
        channel(&self.ctx, topic, name, schema).ok()
    }

    /// Stop listening, drop every client's connection (one that does not
    /// drain is not waited for), and stop the server within a deadline.
    pub async fn stop(mut self) {
        let _closed = self.closing.send(true);
        if let Some(server) = self.server.take() {
            let deadline = std::time::Duration::from_secs(STOP_DEADLINE_S);
            let _in_time = tokio::time::timeout(deadline, server.stop().wait()).await;
        }
    }
}

#[cfg(test)]
mod tests {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    use super::*;

    #[test]
    fn browser_pages_of_other_sites_are_refused() {
        let none: Vec<String> = Vec::new();
        for ok in [
            None,
            Some("http://localhost:3000"),
            Some("http://127.0.0.1"),
            Some("https://[::1]:8443"),
            Some("https://app.foxglove.dev"),
            Some("file://"),
        ] {
            assert!(allowed_origin(ok, &none), "{ok:?}");
        }
        for bad in [
            "http://evil.example",
            "https://app.foxglove.dev.evil.example",
            "http://localhost.evil.example",
            "http://127.0.0.1.evil.example",
            "null",
        ] {
            assert!(!allowed_origin(Some(bad), &none), "{bad}");
        }
        let lab = vec!["https://viewer.lab.example".to_owned()];
        assert!(allowed_origin(Some("https://viewer.lab.example"), &lab));
        let head = "GET / HTTP/1.1\r\nHost: x\r\norigin:  http://evil.example \r\n\r\n";
        assert_eq!(origin_of(head), Some("http://evil.example"));
    }

    /// The first line of the answer to a WebSocket upgrade from `origin`.
    async fn upgrade(addr: SocketAddr, origin: Option<&str>) -> (String, tokio::net::TcpStream) {
        let mut c = tokio::net::TcpStream::connect(addr).await.expect("connect");
        let origin = origin.map_or(String::new(), |o| format!("Origin: {o}\r\n"));
        c.write_all(
            format!(
                "GET / HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
                 Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
                 Sec-WebSocket-Protocol: foxglove.sdk.v1, foxglove.websocket.v1\r\n{origin}\r\n"
            )
            .as_bytes(),
        )
        .await
        .expect("send");
        let mut buf = vec![0u8; 512];
        let n = c.read(&mut buf).await.expect("an answer");
        let text = String::from_utf8_lossy(&buf[..n]).into_owned();
        (text.lines().next().unwrap_or_default().to_owned(), c)
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_gate_refuses_a_foreign_page_and_stop_never_waits_for_a_stalled_client() {
        let live = Live::start(SocketAddr::from(([127, 0, 0, 1], 0)))
            .await
            .expect("live");
        let addr = live.addr();
        let (refused, _) = upgrade(addr, Some("http://evil.example")).await;
        assert!(refused.contains("403"), "{refused}");
        let (local, _kept) = upgrade(addr, Some("http://localhost:8080")).await;
        assert!(local.contains("101"), "{local}");
        // A client that upgrades and then never reads, while messages flow.
        let (tool, stalled) = upgrade(addr, None).await;
        assert!(tool.contains("101"), "{tool}");
        for i in 0..2000u64 {
            live.publish("/events", i, &[b'x'; 4096]);
        }
        // Stopping ends: the stalled connection is dropped, not awaited
        // (a stop that waited for it would never return here).
        tokio::time::timeout(std::time::Duration::from_secs(60), live.stop())
            .await
            .expect("the stop does not wait for a client that does not drain");
        drop(stalled);
    }
}
