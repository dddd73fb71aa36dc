//! The run's channels, live: a Foxglove WebSocket server
//! (`foxglove.websocket.v1`, the official `foxglove` crate) that
//! publishes every message the [`super::writer::Recorder`] writes, on the
//! same topics, with the same JSON Schemas and log times. Foxglove or
//! Lichtblick opened on `ws://127.0.0.1:PORT` shows a run as it goes, the
//! way it shows the MCAP afterwards.
//!
//! The protocol has no authentication, so the server listens on loopback
//! only; an engineer elsewhere reaches it through an SSH tunnel. Messages
//! are offered, never awaited: a slow or stalled client loses messages
//! from its own backlog (the server's policy), the run and its log never
//! wait for it, and with no client subscribed a message costs a check.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;

use foxglove::{Context, PartialMetadata, RawChannel, Schema, WebSocketServer};

use super::schema::CHANNELS;

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
    _ctx: Arc<Context>,
    server: Option<foxglove::WebSocketServerHandle>,
    channels: BTreeMap<&'static str, Arc<RawChannel>>,
    addr: SocketAddr,
}

impl std::fmt::Debug for Live {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Live")
            .field("addr", &self.addr)
            .finish_non_exhaustive()
    }
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
            let ch = ctx
                .channel_builder(topic)
                .message_encoding("json")
                .schema(Schema::new(name, "jsonschema", schema.as_bytes()))
                .build_raw()
                .map_err(start_err)?;
            channels.insert(topic, ch);
        }
        let server = WebSocketServer::new()
            .context(&ctx)
            .name(format!("gyrobench {}", env!("CARGO_PKG_VERSION")))
            .bind(addr.ip().to_string(), addr.port())
            .start()
            .await
            .map_err(start_err)?;
        let addr = SocketAddr::new(addr.ip(), server.port());
        Ok(Self {
            _ctx: ctx,
            server: Some(server),
            channels,
            addr,
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
        if let Some(ch) = self.channels.get(topic) {
            ch.log_with_meta(
                json,
                PartialMetadata {
                    log_time: Some(log_time_ns),
                },
            );
        }
    }

    /// Close the clients' connections and stop listening.
    pub async fn stop(mut self) {
        if let Some(server) = self.server.take() {
            server.stop().wait().await;
        }
    }
}
