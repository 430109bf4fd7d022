//! The `lucerna` binary: the command line of src/cli.rs.

use std::process::ExitCode;

fn main() -> ExitCode {
    let this = std::env::current_exe().map_or_else(|_| "lucerna".into(), |p| p.into_os_string());
    ExitCode::from(lucerna::cli::main_with(std::env::args_os(), &[this]))
}
