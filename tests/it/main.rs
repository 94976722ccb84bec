//! The integration tests of cirrus: one binary, one module per concern.

mod support;

mod bake;
mod cli;
mod config;
mod incremental;
mod layout;
mod material_files;
mod planes;
