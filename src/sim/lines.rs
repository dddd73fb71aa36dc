//! The request/reply loop shared by the line-oriented simulators (Espec,
//! ACL): read a line, let the device's faults decide, answer.

use std::sync::Arc;

use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt, BufReader};

use super::SharedBench;
use super::faults::{Action, DeviceFaults, Faults, garble};
use crate::transport::read_line;

/// Serve one connection until it closes. `answer` gets the fault action
/// (never `NoReply` or `Disconnect`, which are handled here) and the line,
/// and returns the reply bytes with their terminator, if any.
pub(super) async fn serve_lines<S>(
    stream: S,
    bench: Arc<SharedBench>,
    faults: fn(&Faults) -> &DeviceFaults,
    max_line: usize,
    answer: impl Fn(&SharedBench, Action, &str) -> Option<Vec<u8>>,
) -> std::io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    let (r, mut w) = tokio::io::split(stream);
    let mut r = BufReader::new(r);
    let mut buf = Vec::new();
    if faults(&bench.faults).outage.active() {
        return Ok(());
    }
    while read_line(&mut r, &mut buf, max_line).await? {
        if faults(&bench.faults).outage.active() {
            return Ok(());
        }
        let line = String::from_utf8_lossy(&buf).into_owned();
        let action = faults(&bench.faults).next_action();
        match action {
            Action::NoReply => continue,
            Action::Disconnect => return Ok(()),
            _ => {}
        }
        if let Some(mut bytes) = answer(&bench, action, &line) {
            if action == Action::Garble {
                bytes = garble(&bytes);
            }
            w.write_all(&bytes).await?;
            w.flush().await?;
        }
    }
    Ok(())
}
