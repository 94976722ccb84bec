//! What every command shares for talking to the user: standard output that reports a failed
//! write instead of panicking (`out!`, `outln!`), the exit statuses, and the pipeline loaded or
//! its error said.

use std::process::ExitCode;

pub(crate) const EXIT_ASSET_FAILED: u8 = 1;
pub(crate) const EXIT_USAGE: u8 = 2;

/// Set when a write to standard output failed (a full disk, `/dev/full`, a closed pipe): said
/// once on stderr, and the command exits with [`EXIT_ASSET_FAILED`] instead of panicking.
static STDOUT_FAILED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether a write to standard output failed in this process.
pub(crate) fn stdout_failed() -> bool {
    STDOUT_FAILED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Writes to standard output (through the `out!` and `outln!` macros); a failure is recorded in
/// [`STDOUT_FAILED`].
pub(crate) fn write_stdout(arguments: std::fmt::Arguments) {
    use std::io::Write;
    use std::sync::atomic::Ordering;
    if STDOUT_FAILED.load(Ordering::Relaxed) {
        return;
    }
    let mut stdout = std::io::stdout().lock();
    if let Err(error) = stdout.write_fmt(arguments).and_then(|()| stdout.flush()) {
        STDOUT_FAILED.store(true, Ordering::Relaxed);
        eprintln!("error: could not write to standard output: {error}");
    }
}

/// `print!` that reports a failed write instead of panicking.
macro_rules! out {
    ($($argument:tt)*) => { $crate::cli::output::write_stdout(format_args!($($argument)*)) };
}

/// `println!` that reports a failed write instead of panicking.
macro_rules! outln {
    ($($argument:tt)*) => { $crate::cli::output::write_stdout(format_args!("{}\n", format_args!($($argument)*))) };
}
pub(crate) use {out, outln};

/// The validated pipeline, or the usage exit status after printing why it is not valid.
pub(crate) fn load_pipeline_or_report(pipeline: &std::path::Path) -> Result<crate::config::PipelineConfig, ExitCode> {
    crate::pipeline::load_pipeline(pipeline).map_err(|error| {
        eprintln!("{error}");
        ExitCode::from(EXIT_USAGE)
    })
}
