//! Progress on stderr, shared by the long commands (`run`, `diagnose
//! selfcheck`): a live bar on a terminal with lines printed above it,
//! plain lines otherwise (a log file, CI), so stdout keeps the results only.

use std::io::IsTerminal;

/// A bar of `len` units of work, live only when stderr is a terminal.
#[derive(Debug)]
pub struct Bar {
    bar: Option<indicatif::ProgressBar>,
}

impl Bar {
    /// A bar counting to `len`; `template` is indicatif's (`{bar:30}
    /// {pos}/{len} ... {msg}`).
    pub fn new(len: u64, template: &str) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let b = indicatif::ProgressBar::new(len.max(1));
            b.set_style(
                indicatif::ProgressStyle::with_template(template)
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            b
        });
        Self { bar }
    }

    /// Whether a live bar is drawn (else the caller prints what it wants
    /// seen as plain lines).
    pub fn is_live(&self) -> bool {
        self.bar.is_some()
    }

    /// A line on stderr, above the bar when there is one.
    pub fn println(&self, line: &str) {
        match &self.bar {
            Some(b) => b.println(line),
            None => errln!("{line}"),
        }
    }

    /// Move the bar to `pos` with `msg` beside it (nothing without a bar).
    pub fn set(&self, pos: u64, msg: String) {
        if let Some(b) = &self.bar {
            b.set_position(pos);
            b.set_message(msg);
        }
    }

    /// Run `f` with the bar hidden (a prompt).
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        match &self.bar {
            Some(b) => b.suspend(f),
            None => f(),
        }
    }

    /// Take the bar off the terminal (the results follow on stdout).
    pub fn clear(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}
