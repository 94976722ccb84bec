//! The `cirrus` executable: parses the command line and hands it to `cli`.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    quiet_wayland_probe();
    cirrus::cli::run(cirrus::cli::Cli::parse())
}

/// Mesa's Vulkan drivers probe for a Wayland display when the GPU starts, and libwayland prints
/// "error: XDG_RUNTIME_DIR is invalid or not set in the environment." when that variable is
/// unset (a CI job, an SSH session, a service): users read "error" and think the bake failed.
/// Without `XDG_RUNTIME_DIR` and `WAYLAND_DISPLAY` there is no compositor to reach anyway, so the
/// variable is pointed at a folder that does not exist: the probe then fails quietly. This runs
/// first in `main`, while the process has one thread (setting the environment later would race
/// with other threads reading it).
fn quiet_wayland_probe() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
        // SAFETY-equivalent note: single-threaded here; nothing else reads the environment yet.
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir().join("cirrus-no-wayland-session"));
    }
}
