//! cirrus: an incremental asset-pipeline daemon that bakes meshes into billboard-cloud LODs and
//! texture sets into block-compressed GPU materials. The modules are listed bottom-up, as they
//! stack: each group imports only the groups above it (the tidy test checks it); the loops left,
//! each a folder's module and files under it, are listed in that test and in ARCHITECTURE.md.

// Leaves: the one list of asset kinds (a macro, first so that every module below may use it),
// safe file reading and writing, the allocator's settings.
#[macro_use]
mod kind_list;
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

// The machinery, which names no kind: the persistent cache, the database, reading sources,
// writing artifacts, the build record, running jobs on workers, what a build reports, the
// dependency graph.
pub mod cache;
pub mod db;
pub mod sources;
pub mod artifacts;
pub mod summary;
pub mod record;
pub mod schedule;
pub mod graph;

// The asset kinds: the one list of kinds and the questions the driver asks them, then one
// folder per kind.
pub mod kinds;
// `pipeline.ron` read with every kind's entry.
pub mod pipeline;

// The driver: inputs in, jobs on workers, artifacts out; it names no kind.
pub mod project;

// The shell: the daemon, its protocol, the command line.
pub mod watch;
pub mod server;
pub mod cli;
