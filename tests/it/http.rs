//! One HTTP/1.1 request to the station's API, as a plain client sends it
//! (`Connection: close`, the token in its header when given): shared by
//! the station tests and the sweep (which the `resume_sweep` example
//! also mounts, so this module needs nothing else of the tests).

use std::io::{Read, Write};

/// `method path` with `body` (JSON) to `host` (`127.0.0.1:PORT`):
/// (status, body), or what failed in words.
pub fn request(
    host: &str,
    token: Option<&str>,
    method: &str,
    path: &str,
    body: &str,
) -> Result<(u16, String), String> {
    let mut c = std::net::TcpStream::connect(host).map_err(|e| format!("connect {host}: {e}"))?;
    let auth = token.map_or(String::new(), |t| format!("X-Gyrobench-Token: {t}\r\n"));
    write!(
        c,
        "{method} {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n{auth}Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .map_err(|e| format!("send {method} {path}: {e}"))?;
    let mut raw = Vec::new();
    c.read_to_end(&mut raw)
        .map_err(|e| format!("read the response to {method} {path}: {e}"))?;
    let text = String::from_utf8_lossy(&raw).into_owned();
    let (head, body) = text
        .split_once("\r\n\r\n")
        .ok_or_else(|| format!("{method} {path}: not an HTTP response: {text:?}"))?;
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .ok_or_else(|| format!("{method} {path}: no status in {head:?}"))?;
    Ok((status, body.to_owned()))
}
