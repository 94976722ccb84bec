//! cirrus: an incremental asset-pipeline daemon that bakes meshes into billboard-cloud LODs and
//! texture sets into block-compressed GPU materials. The modules are listed in reading order:
//! what a newcomer reads first comes first, each group builds on the ones above it.

// The inputs: the pipeline file, and how every problem with an input is reported.
pub mod config;
pub mod diagnostic;

// Shared libraries: pure functions over plain data (no salsa, no IO), named by role.
pub mod isa;
pub mod openddl;
pub mod texture;
pub mod mesh;
pub mod packing;
pub mod gpu;

// The machinery, which names no kind: the database, the persistent cache, reading sources,
// writing artifacts, running jobs on workers, what a build reports, the dependency graph.
pub mod db;
pub mod cache;
pub mod sources;
pub mod artifacts;
pub mod record;
pub mod schedule;
pub mod summary;
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
pub mod cli_cache;
