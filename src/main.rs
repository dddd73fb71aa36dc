//! The `gyrobench` command line (`cli`) and the web station it serves
//! (`station`): a crate of their own above the library, which is their
//! door to everything else (`gyrobench::...`). See `gyrobench --help`.

use std::process::ExitCode;

mod cli;
mod station;

fn main() -> ExitCode {
    cli::main()
}
