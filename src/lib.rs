//! cirrus: an incremental asset-pipeline daemon that bakes meshes into billboard-cloud LODs and
//! texture sets into block-compressed GPU materials. The modules are listed in reading order:
//! what a newcomer reads first comes first, each group builds on the ones above it.

// The inputs: the pipeline file, and how every problem with an input is reported.
pub mod config;
pub mod diagnostic;

// Shared libraries: pure functions over plain data (no salsa, no IO).
pub mod openddl;
pub mod texture;
pub mod mesh;
pub mod mips;
pub mod encode;
pub mod quality;
pub mod container;
pub mod preview;
pub mod gpu;

// The Material kind: the .mymaterial file, then channel packing (whose `SurfaceKind` the
// billboard atlas shares).
pub mod material_definition;
pub mod surface;

// The BillboardCloud kind's stages, in pipeline order.
pub mod planes;
pub mod rectangles;
pub mod layout;
pub mod plane_textures;
pub mod atlas;
pub mod lod_mesh;
pub mod lod_preview;

// The database: salsa inputs and tracked stage functions, and the persistent cache behind them.
pub mod db;
pub mod cache;

// The edges and the driver: reading sources, writing artifacts, the build, what it reports.
pub mod sources;
pub mod artifacts;
pub mod bake;
pub mod check;
pub mod summary;
pub mod graph;

// The shell: the daemon, its protocol, the command line.
pub mod watch;
pub mod server;
pub mod cli;
