//! gyrobench: a hardware-in-the-loop test bench controller for ring laser
//! gyroscopes.
//!
//! Layers, each depending only on those above it in this list:
//! `clock` and `config` (time, TOML loading) <- `geometry` (frames, Earth
//! rate, table kinematics) <- `twin` (the simulated gyro and bench) <-
//! `analysis` (pure math) <- `cli`. See `ARCHITECTURE.md`.

pub mod analysis;
pub mod bench;
pub mod calibrate;
pub mod cli;
pub mod clock;
pub mod coeffs;
pub mod compensation;
pub mod config;
pub mod diagnose;
pub mod driver;
pub mod fsutil;
pub mod geometry;
pub mod procedure;
pub mod protocol;
pub mod report;
pub mod results;
pub mod runlog;
pub mod sequencer;
pub mod session;
pub mod sim;
pub mod station;
pub mod study;
pub mod transport;
pub mod twin;
pub mod unit;
pub mod view;

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
