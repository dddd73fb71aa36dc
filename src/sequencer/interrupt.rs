//! A request to stop a run: Ctrl-C, SIGTERM, SIGHUP, SIGQUIT, or an operator's
//! Abort. The first request stops the run and cleanup runs; a request
//! during cleanup stops cleanup (the bench then goes to its safe state).

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// A stop request shared between whoever asks and the sequencer.
#[derive(Debug, Default)]
pub struct Interrupt {
    requested: AtomicBool,
    cause: Mutex<Option<String>>,
}

impl Interrupt {
    /// Ask the run to stop; `cause` names who asked (`Ctrl-C`, `SIGTERM`).
    /// Returns true for the first request of the run.
    pub fn request(&self, cause: &str) -> bool {
        let mut c = self
            .cause
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let first = c.is_none();
        if first {
            *c = Some(cause.to_owned());
        }
        self.requested.store(true, Ordering::Relaxed);
        first
    }

    /// A stop was asked for and not yet acted on.
    pub fn is_requested(&self) -> bool {
        self.requested.load(Ordering::Relaxed)
    }

    /// Who asked first, if anyone did.
    pub fn cause(&self) -> Option<String> {
        self.cause
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }

    /// The request was acted on: listen for another (during cleanup).
    pub(crate) fn rearm(&self) {
        self.requested.store(false, Ordering::Relaxed);
    }
}
