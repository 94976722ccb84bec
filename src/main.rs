//! The `cirrus` executable: parses the command line and hands it to `cli`.

use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = match cirrus::cli::parse_command_line() {
        Ok(cli) => cli,
        Err(status) => return status,
    };
    // First, while the process has one thread: these set environment variables.
    cirrus::gpu::quiet_wayland_probe();
    if let Some(level) = cli.isa {
        cirrus::isa::limit_isa(level);
        cirrus::gpu::limit_software_renderer_isa(level);
    }
    cirrus::cli::run(cli)
}
