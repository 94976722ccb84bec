//! The `cirrus` executable: parses the command line and hands it to `cli`.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = cirrus::cli::Cli::parse();
    match cirrus::cli::run(cli) {
        Ok(code) => code,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::from(cirrus::cli::EXIT_USAGE)
        }
    }
}
