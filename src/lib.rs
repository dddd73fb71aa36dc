//! gyrobench: a hardware-in-the-loop test bench controller for ring laser
//! gyroscopes.
//!
//! The modules are layered, each importing only those below it;
//! `ARCHITECTURE.md` has the table, bottom layer first, and a test fails
//! when an import runs against it. The entry types, by what a program
//! does with gyrobench:
//!
//! - **Run a procedure**: read a [`Procedure`] against a [`BenchConfig`],
//!   make a [`Plan`] ([`Plan::new`] and its `with_` methods), and
//!   [`execute`] it into a run directory ([`Place`]): the sequencer drives
//!   a [`BenchIo`] (the embedded twin of [`TwinConfig`], or the bench file's
//!   devices), logs to MCAP and ends with a [`Finished`] run, its
//!   [`Report`] and [`Outcome`].
//! - **Read a log**: [`replay`] a `run.mcap` into the same report, or read
//!   its messages with [`runlog::reader`].
//! - **Query results**: open a [`Store`] at a [`Location`]; its rows carry
//!   each run's [`RunState`] and each measurement's [`MeasureOutcome`].
//! - **Simulate devices**: `sim` serves the chamber, table, gyro and supply
//!   on their wire protocols; `protocol` (the `gyrobench-protocol` crate)
//!   holds the codecs drivers and simulators share.
//!
//! The `gyrobench` binary (`src/main.rs`: the command line and the web
//! station) is a crate of its own above this one and uses it through
//! this door alone.

/// Pure math on recorded series: the `gyrobench-analysis` crate
/// (`crates/analysis`).
pub use gyrobench_analysis as analysis;
pub mod bench;
pub mod calibrate;
pub mod clock;
pub mod coeffs;
/// The study's compensation models as data (in `gyrobench-analysis`).
pub use gyrobench_analysis::compensation;
/// TOML loading and checking (in `gyrobench-model`, `crates/model`).
pub use gyrobench_model::config;
pub mod diagnose;
pub mod driver;
pub mod fsutil;
/// Frames, orientation, Earth rate, the table's geometry (in
/// `gyrobench-model`).
pub use gyrobench_model::geometry;
/// Procedures as typed, validated values: the `gyrobench-model` crate's
/// (`crates/model`), checked against a bench's [`BenchConfig::procedure_limits`].
pub use gyrobench_model::procedure;
#[cfg(test)]
mod procedure_tests;
/// The wire protocols, sans-IO: the `gyrobench-protocol` crate
/// (`crates/protocol`), which drivers and simulators share.
pub use gyrobench_protocol as protocol;
pub mod report;
pub mod results;
pub mod runlog;
pub mod sequencer;
pub mod session;
pub mod sim;
pub mod study;
pub mod transport;
pub mod typeb;
/// The unit under test's serial rules (the vocabulary crate's).
pub use gyrobench_model::unit;
/// The digital twin of the RL-16 on its bench: the `gyrobench-twin`
/// crate (`crates/twin`).
pub use gyrobench_twin::twin;
pub mod view;

pub use bench::BenchConfig;
pub use procedure::Procedure;
pub use report::Report;
pub use results::{Location, RunState, Store};
pub use runlog::replay::replay;
pub use sequencer::measure::MeasureOutcome;
pub use sequencer::{BenchIo, Outcome};
pub use session::{Finished, Place, Plan, execute};
pub use twin::TwinConfig;

/// What built this gyrobench: its version and the source revision (a git
/// commit, `-dirty` when the sources differed from it; `build.rs`).
pub mod version {
    /// The package version.
    pub const VERSION: &str = env!("CARGO_PKG_VERSION");
    /// The source revision.
    pub const REVISION: &str = env!("GYROBENCH_REVISION");

    /// `gyrobench 0.1.0 (1a2b3c4d5e6f)`.
    pub fn software() -> String {
        format!("gyrobench {VERSION} ({REVISION})")
    }
}
