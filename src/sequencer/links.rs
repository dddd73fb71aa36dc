//! What the bench's links say while the run waits on them: a link found
//! down is told to the operator and the log at once, not when its
//! reconnect window ends (a run waiting on a dropped link must not look
//! like a frozen one).

use std::future::Future;

use super::{Event, Observer, Operator, written};
use crate::driver::LinkWatch;
use crate::runlog::schema::Level;

/// Await `fut`, telling `log` and `op` what `links` say meanwhile (each
/// line stamped `t_s`, the device time the wait began). A log that cannot
/// be written is kept in `failed`, never a reason to stop waiting.
pub(super) async fn telling<T>(
    fut: impl Future<Output = T>,
    links: Option<&LinkWatch>,
    t_s: f64,
    log: &mut dyn Observer,
    op: &mut dyn Operator,
    failed: &mut Option<String>,
) -> T {
    let Some(links) = links else {
        return fut.await;
    };
    tokio::pin!(fut);
    loop {
        tokio::select! {
            biased;
            v = &mut fut => {
                say(links, t_s, log, op, failed);
                return v;
            }
            () = links.told() => say(links, t_s, log, op, failed),
        }
    }
}

/// Tell `log` and `op` what `links` said since last asked.
pub(super) fn say(
    links: &LinkWatch,
    t_s: f64,
    log: &mut dyn Observer,
    op: &mut dyn Operator,
    failed: &mut Option<String>,
) {
    for n in links.take() {
        let text = n.to_string();
        let _ = op.observe(&Event::Warning(&text));
        let line = Event::Line {
            t_s,
            level: Level::Warning,
            message: &text,
        };
        let _ = written(failed, true, log.observe(&line));
    }
}
