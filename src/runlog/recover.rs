//! `recover`: a complete, indexed log from what a killed run had flushed
//! (the log crate's [`gyrobench_log::recover`]), written to its output
//! only when something was recovered.

use std::path::Path;

pub use gyrobench_log::recover::part_start_ns;
pub use gyrobench_log::{RecoverError, Recovered};

use crate::fsutil::Pending;

/// Rewrite the possibly truncated log at `input` as a complete, indexed
/// file at `out`: every message of every complete chunk, the metadata and
/// the attachments are copied; what follows the last complete record is
/// lost. `out` appears only when something was recovered.
pub fn recover(input: &Path, out: &Path) -> Result<Recovered, RecoverError> {
    let write_err = |cause: std::io::Error| RecoverError::Write {
        path: out.display().to_string(),
        cause,
    };
    let mut pending = Pending::output(out).map_err(write_err)?;
    let file = pending.take_file().map_err(write_err)?;
    let library = format!("gyrobench {} (recovered)", env!("CARGO_PKG_VERSION"));
    let r = gyrobench_log::recover::recover(input, file, out, &library)?;
    pending.commit().map_err(write_err)?;
    Ok(r)
}
