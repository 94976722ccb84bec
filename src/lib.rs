//! cirrus: an incremental asset-pipeline daemon that bakes meshes into billboard-cloud LODs and
//! texture sets into block-compressed GPU materials. The modules are listed bottom-up, as they
//! stack: each group imports only the groups above it (the tidy test checks it), and the one
//! loop left is inside `kinds/` (a kind's `mod.rs` and its queries).

// Leaves: the one list of asset kinds (a macro, first so that every module below may use it),
// how every problem with an input is reported, safe file reading and writing and path
// normalisation, the check long work asks before it goes on, the CPU kernels' level, the
// allocator's settings, the OpenDDL parser.
#[macro_use]
mod kind_list;
pub mod diagnostic;
pub mod files;
pub mod stop;
pub mod isa;
pub mod memory;
pub mod openddl;

// Shared libraries: pure functions over plain data (no salsa, no IO), named by role; the
// previews render through the GPU device.
pub mod texture;
pub mod mesh;
pub mod packing;
pub mod gpu;
pub mod impostor;
pub mod preview;

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

// The driver: inputs in, jobs on workers, artifacts out; it names no kind.
pub mod project;

// The shell: the daemon, its protocol, the command line.
pub mod watch;
pub mod server;
pub mod cli;
