//! The run log: one MCAP file per part of a run (`docs/report.md`).
//!
//! - [`schema`]: topics, JSON Schemas and the message types shared by the
//!   writer and every reader; attachment and metadata record names (the
//!   `gyrobench-log` crate's, with [`reader`]: the file format alone).
//! - [`meta`]: the `run` and `result` metadata, typed (the log crate's).
//! - [`writer`]: the [`Recorder`](writer::Recorder), the run's log as an
//!   [`Observer`](crate::sequencer::Observer), written through the log
//!   crate's [`LogWriter`](gyrobench_log::LogWriter).
//! - [`live`]: the same messages on a Foxglove WebSocket server, live.
//! - [`reader`]: streaming, bounded reading in file order.
//! - [`recover`]: a complete log from a killed run's file (the log
//!   crate's recovery, committed to its output only when it found a run).
//! - [`view`]: one unit of a batch's log read as that unit's log alone.
//! - [`replay`]: a run's measurements and verdict from its log alone.
//! - [`exchange`] and [`interchange`]: runs recorded elsewhere (the
//!   interchange CSV) in and out; [`import_map`]: a lab's own CSV read
//!   through a map.

pub mod exchange;
pub mod import_map;
pub mod interchange;
pub mod live;
pub mod recover;
pub mod replay;
pub mod view;
pub mod writer;

pub use gyrobench_log::{Item, ReadError, ReadSummary, Stop, meta, read, reader, refusing, schema};
