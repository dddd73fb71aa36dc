//! The gyrobench run log's file format, for any tool that reads the logs:
//! one MCAP file per part of a run, every message JSON with a JSON Schema
//! (`docs/report.md` of the gyrobench repository has the layout).
//!
//! - [`schema`]: the topics, their JSON Schemas and the message types the
//!   writer serializes and every reader deserializes; attachment and
//!   metadata record names.
//! - [`reader`]: streaming, bounded reading in file order; a file cut short
//!   or damaged is read as far as it is whole, and the summary says what
//!   was lost.
//! - [`meta`]: the `run` and `result` metadata, typed (MCAP metadata is
//!   string to string; these types alone know the keys).
//! - [`writer`]: a log written message by message, flushed every second
//!   of wall time, whose first write failure sticks; `finish` returns what
//!   it holds.
//! - [`recover`]: a complete, indexed log from what a killed run flushed.
//!
//! ```no_run
//! use std::ops::ControlFlow;
//!
//! use gyrobench_log::{Item, Stop, read, schema::topics};
//!
//! // The first hour of 1 Hz intervals; the rest of the file is not read.
//! let mut intervals = 0;
//! let summary = read(std::path::Path::new("run.mcap"), |item| {
//!     if let Item::Message { topic, .. } = item
//!         && topic == topics::RATE_1HZ
//!     {
//!         intervals += 1;
//!         if intervals == 3600 {
//!             return ControlFlow::Break(Stop::Enough);
//!         }
//!     }
//!     ControlFlow::Continue(())
//! })?;
//! println!("{intervals} seconds, complete: {}", summary.complete);
//! # Ok::<(), gyrobench_log::ReadError>(())
//! ```

pub mod meta;
pub mod reader;
pub mod recover;
pub mod schema;
pub mod writer;

pub use reader::{Item, ReadError, ReadSummary, Stop, read, refusing};
pub use recover::{RecoverError, Recovered};
pub use writer::{LogWriter, Opening, Tap, Written};
