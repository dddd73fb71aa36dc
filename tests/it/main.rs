//! gyrobench's whole-system tests, one binary: the CLI across the process
//! boundary, and every driver against its simulator over real transports.

#![expect(
    clippy::expect_used,
    reason = "a test helper that cannot run should fail the test loudly"
)]

mod bad_input;
mod batch;
mod calibrate;
mod cli;
mod common;
mod diagnose;
mod diagnose_lot;
mod docs;
mod fuzz;
mod http;
mod import;
mod integrity;
mod messages;
mod outputs;
mod pages;
mod power;
mod rate;
mod readme;
mod replay;
mod results;
mod resume;
mod run;
mod safety;
mod set_identity;
mod station;
mod status;
mod sweep;
mod unit_record;
