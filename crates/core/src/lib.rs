//! cirrus's machinery, which names no kind: the pipeline file read into per-asset settings, the
//! persistent cache, the database, reading sources, the build record, running jobs on workers,
//! what a build reports, and the questions every kind answers with the shared texture tail. The
//! kinds (crates under `kinds/`) build on it; the application (the driver, the daemon and the
//! command line) lists them. The modules are listed bottom-up, as they stack.

// Leaves: safe file reading and writing, the allocator's settings.
pub mod files;
pub mod memory;

// The shared libraries, crates of their own under crates/ that depend on nothing of this one:
// pure functions over plain data (no salsa, no IO), named by role; the previews and impostors
// render through the GPU device. Re-exported under the names the modules below use.
pub use base::{diagnostic, isa, stop};
pub use gpu;
pub use mesh;
pub use openddl;
pub use packing;
pub use render::{impostor, preview};
pub use texture;

// The inputs: the pipeline file, validated into per-asset settings.
pub mod config;

// The persistent cache, the database, reading sources, what a build reports, the build record,
// running jobs on workers.
pub mod cache;
pub mod db;
pub mod summary;
pub mod record;
pub mod sources;
pub mod schedule;

// What a kind is: the questions the driver asks it, and the stages every kind shares (the
// texture tail, mesh reading, source copies).
pub mod kinds;
