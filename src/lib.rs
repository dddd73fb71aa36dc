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
pub mod view;
