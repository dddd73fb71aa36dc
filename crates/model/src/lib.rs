//! gyrobench's vocabulary, as data: the geometry a bench turns a gyro in
//! (`geometry`: orientations, the two-axis table, frames), the TOML
//! configuration checking every gyrobench file shares (`config::Checker`:
//! errors that name the file, line, key and the fix), the procedure as
//! typed values (`procedure`, checked against a bench's `limits`), how runs
//! and measurements end and what a run leaves (`outcome`), a measurement as
//! a report gives it (`measurement`), the faults a
//! run can meet by their `--inject` names (`fault`), the unit under
//! test's serial (`unit`), the instruments a run names (`instrument`), its coefficient set and that set's identity
//! (`coefficients`), and the shipped procedures' texts (`procedures`,
//! this package's `procedures/`, which the repository's top-level
//! `procedures/` is). The controller keeps the paths it always gave them
//! (`gyrobench::geometry`, `gyrobench::config`, `gyrobench::procedure`,
//! `gyrobench::unit`, `gyrobench::coeffs`).

pub mod coefficients;
pub mod config;
pub mod fault;
pub mod geometry;
pub mod instrument;
pub mod limits;
pub mod measurement;
pub mod outcome;
pub mod procedure;
pub mod procedures;
pub mod unit;
