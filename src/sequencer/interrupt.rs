//! A request to stop a run: Ctrl-C, SIGTERM, SIGHUP, SIGQUIT, or an operator's
//! Abort. The first request stops the run and cleanup runs; a request
//! during cleanup stops cleanup (the bench then goes to its safe state).

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// Called with the cause of each request, as it is made.
type Hook = Box<dyn Fn(&str) + Send + Sync>;

/// A stop request shared between whoever asks and the sequencer.
#[derive(Default)]
pub struct Interrupt {
    requested: AtomicBool,
    cause: Mutex<Option<String>>,
    hooks: Mutex<Vec<Hook>>,
}

impl std::fmt::Debug for Interrupt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Interrupt")
            .field("requested", &self.requested)
            .field("cause", &self.cause)
            .finish_non_exhaustive()
    }
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
        drop(c);
        self.requested.store(true, Ordering::Relaxed);
        for hook in self
            .hooks
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
        {
            hook(cause);
        }
        first
    }

    /// Call `hook` with the cause of every request from now on (at once
    /// when one was made already): what waits on a device learns that
    /// the run is stopping, even inside a wait.
    pub fn on_request(&self, hook: impl Fn(&str) + Send + Sync + 'static) {
        if let Some(cause) = self.cause() {
            hook(&cause);
        }
        self.hooks
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(Box::new(hook));
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
