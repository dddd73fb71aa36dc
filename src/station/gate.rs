//! The station's gate: every request passes it before a handler sees it.
//!
//! - The token is checked on the request head (its header
//!   `X-Gyrobench-Token` or `?token=`), before any byte of a body is read:
//!   a request without it gets `403` and its connection is closed, so
//!   whoever has no token holds nothing, whatever body it announced. The
//!   page and its two assets are the only routes served without it.
//! - A request with the token proves its connection a token holder's
//!   ([`Admission::prove`]): the listener keeps slots for those.
//! - Every body is read whole before the handler runs, within
//!   [`BODY_TIMEOUT`] of its head and at most [`BODY_LIMIT`] bytes: a body
//!   sent slowly or never finished gets `408` and the connection closed.

use std::sync::Arc;
use std::time::Duration;

use axum::body::{Body, Bytes};
use axum::extract::connect_info::ConnectInfo;
use axum::extract::{Query, Request, State};
use axum::http::{HeaderMap, Method};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use serde::Deserialize;

use super::listener::Admission;
use super::{Refused, Station};

/// Time a request's whole body has to arrive, from its head.
pub const BODY_TIMEOUT: Duration = Duration::from_secs(10);
/// The longest body the station reads (its requests are small JSON).
pub const BODY_LIMIT: usize = 64 * 1024;

/// The token in a query string.
#[derive(Debug, Deserialize)]
struct TokenQuery {
    token: Option<String>,
}

/// The routes anyone who reaches the address may read: the page (which
/// reads the token from its own URL) and its assets.
fn public(method: &Method, path: &str) -> bool {
    (method == Method::GET || method == Method::HEAD)
        && matches!(
            path,
            "/" | "/assets/uPlot.iife.min.js" | "/assets/uPlot.min.css"
        )
}

/// Whether the request head carries `token`: in its header, or for a
/// read in its query (the page's links). A state change needs the header:
/// another site's page cannot send it without a CORS preflight the
/// station never grants, even if the token leaked in a URL.
fn carries(token: &str, method: &Method, headers: &HeaderMap, uri: &axum::http::Uri) -> bool {
    let header = headers
        .get("x-gyrobench-token")
        .and_then(|v| v.to_str().ok());
    let read = method == Method::GET || method == Method::HEAD;
    let query = read
        .then(|| Query::<TokenQuery>::try_from_uri(uri).ok())
        .flatten()
        .and_then(|Query(q)| q.token);
    header.or(query.as_deref()) == Some(token)
}

/// The gate (an axum middleware on every route).
pub async fn gate(State(s): State<Arc<Station>>, req: Request, next: Next) -> Response {
    if carries(&s.cfg.token, req.method(), req.headers(), req.uri()) {
        if let Some(ConnectInfo(conn)) = req.extensions().get::<ConnectInfo<Admission>>() {
            conn.prove();
        }
    } else if !public(req.method(), req.uri().path()) {
        return Refused::Token.into_response();
    }
    let (parts, body) = req.into_parts();
    let declared = parts
        .headers
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    match read_body(body, declared, BODY_TIMEOUT, BODY_LIMIT).await {
        Ok(bytes) => {
            next.run(Request::from_parts(parts, Body::from(bytes)))
                .await
        }
        Err(e) => e.into_response(),
    }
}

/// `body` whole, within `timeout` and `limit` bytes (`declared`: its
/// `Content-Length`, refused at once when over the limit).
pub async fn read_body(
    body: Body,
    declared: Option<u64>,
    timeout: Duration,
    limit: usize,
) -> Result<Bytes, Refused> {
    if declared.is_some_and(|n| n > limit as u64) {
        return Err(Refused::TooLarge { limit });
    }
    match tokio::time::timeout(timeout, axum::body::to_bytes(body, limit)).await {
        Ok(Ok(bytes)) => Ok(bytes),
        Ok(Err(e)) => Err(Refused::Body {
            limit,
            why: e.to_string(),
        }),
        Err(_) => Err(Refused::SlowBody { timeout }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A body that never ends is cut at its deadline: nobody holds a
    /// handler (or the station's stop) by announcing more than it sends.
    #[tokio::test]
    async fn a_body_that_never_ends_is_refused_at_its_deadline() {
        let never =
            Body::from_stream(futures_util::stream::pending::<Result<Bytes, std::io::Error>>());
        let got = read_body(never, Some(100), Duration::from_millis(20), 1024).await;
        assert_eq!(
            got,
            Err(Refused::SlowBody {
                timeout: Duration::from_millis(20)
            })
        );
        let whole = read_body(Body::from("{}"), Some(2), Duration::from_secs(5), 1024).await;
        assert_eq!(whole, Ok(Bytes::from("{}")));
    }

    #[tokio::test]
    async fn a_body_over_the_limit_is_refused_before_it_is_read() {
        let never =
            Body::from_stream(futures_util::stream::pending::<Result<Bytes, std::io::Error>>());
        let got = read_body(never, Some(1 << 20), Duration::from_secs(3600), 1024).await;
        assert_eq!(got, Err(Refused::TooLarge { limit: 1024 }));
        let chunked = read_body(
            Body::from(vec![b'x'; 2048]),
            None,
            Duration::from_secs(5),
            1024,
        )
        .await;
        assert!(
            matches!(chunked, Err(Refused::Body { limit: 1024, .. })),
            "{chunked:?}"
        );
    }

    #[test]
    fn only_the_page_and_its_assets_are_public() {
        assert!(public(&Method::GET, "/"));
        assert!(public(&Method::GET, "/assets/uPlot.min.css"));
        assert!(!public(&Method::POST, "/"));
        assert!(!public(&Method::GET, "/api/state"));
        assert!(!public(&Method::GET, "/runs/1/report.html"));
        assert!(!public(&Method::GET, "/nothing"));
    }

    #[test]
    fn the_token_is_read_from_the_header_or_a_reads_query() {
        let uri = |u: &str| u.parse::<axum::http::Uri>().expect("uri");
        let mut h = HeaderMap::new();
        let get = Method::GET;
        assert!(carries("abc", &get, &h, &uri("/api/state?token=abc")));
        assert!(!carries("abc", &get, &h, &uri("/api/state?token=abd")));
        assert!(!carries("abc", &get, &h, &uri("/api/state")));
        assert!(
            !carries("abc", &Method::POST, &h, &uri("/api/abort?token=abc")),
            "a state change needs the header"
        );
        h.insert("x-gyrobench-token", "abc".parse().expect("header"));
        assert!(carries("abc", &get, &h, &uri("/api/state")));
        assert!(carries("abc", &Method::POST, &h, &uri("/api/abort")));
    }
}
