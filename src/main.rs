//! The `gyrobench` command line; see `gyrobench --help`.

use std::process::ExitCode;

fn main() -> ExitCode {
    gyrobench::cli::main()
}
