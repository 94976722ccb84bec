//! The `cirrus` executable: parses the command line and hands it to `cli`.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // First, while the process has one thread: it sets an environment variable.
    cirrus::gpu::quiet_wayland_probe();
    cirrus::cli::run(cirrus::cli::Cli::parse())
}
