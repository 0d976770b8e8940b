//! The `frugal` binary: see the library crate for the commands.
use std::process::ExitCode;

fn main() -> ExitCode {
    ExitCode::from(frugal::main_from(std::env::args_os()))
}
