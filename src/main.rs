//! The `cirrus` executable: parses the command line and hands it to `cli`.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = cirrus::cli::Cli::parse();
    // First, while the process has one thread: these set environment variables.
    cirrus::gpu::quiet_wayland_probe();
    if let Some(level) = cli.isa {
        cirrus::isa::limit_isa(level);
        cirrus::gpu::limit_software_renderer_isa(level);
    }
    cirrus::cli::run(cli)
}
