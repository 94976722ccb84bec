//! cirrus: an incremental asset-pipeline daemon that bakes meshes into billboard-cloud LODs and
//! texture sets into block-compressed GPU materials. Modules are listed in pipeline order.

// Shell: configuration and diagnostics.
pub mod config;
pub mod diagnostic;

// Stages, in pipeline order: pure functions over plain data.
pub mod atlas;
pub mod container;
pub mod encode;
pub mod gpu;
pub mod layout;
pub mod lod_mesh;
pub mod lod_preview;
pub mod material_definition;
pub mod mesh;
pub mod mips;
pub mod openddl;
pub mod plane_textures;
pub mod planes;
pub mod preview;
pub mod quality;
pub mod rectangles;
pub mod surface;
pub mod texture;

// Salsa glue and the edges: persistent cache.
pub mod cache;
pub mod db;

// The edges and the driver.
pub mod artifacts;
pub mod bake;
pub mod cli;
pub mod graph;
pub mod server;
pub mod sources;
pub mod summary;
pub mod watch;
