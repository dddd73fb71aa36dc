//! Sim-to-real diagnosis (`docs/diagnosis.md`): the engine is the
//! `gyrobench-diagnose` crate's (`crates/diagnose`, re-exported here);
//! the controller adds what needs the rest of the bench:
//!
//! - `data`: a run read from its log as the engine's `RunData`;
//! - `selfcheck`: the withheld-effect experiment on the twin, its runs
//!   simulated through the sequencer;
//! - `randomized`: the same on units drawn far from the twin;
//! - `html`: the page;
//! - `lot_html`, `lot_files`: a lot's page and headline, its bench
//!   correction and where each unit's files go;
//! - `lot_selfcheck`: lots of randomised units with a shared bench fault,
//!   with nothing, or with one odd unit, diagnosed as lots.

pub use gyrobench_diagnose::*;

pub mod data;
pub mod html;
pub mod lot_files;
pub mod lot_html;
pub mod lot_selfcheck;
pub mod randomized;
pub mod selfcheck;
#[cfg(test)]
mod tests;
