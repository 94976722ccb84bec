//! The integration tests of cirrus: one binary, one module per concern.

mod support;

mod bake;
mod billboard;
mod cli;
mod config;
mod gpu;
mod graph;
mod incremental;
mod layout;
mod material_files;
mod planes;
mod watch;
