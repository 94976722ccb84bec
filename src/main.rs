//! The `cirrus` executable: parses the command line and hands it to `cli`.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    cirrus::cli::run(cirrus::cli::Cli::parse())
}
