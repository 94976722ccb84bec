//! The integration tests of cirrus: one binary, one module per concern.

mod support;

mod bake;
mod billboard;
mod cache;
mod cli;
mod config;
mod conformance;
mod fuzz;
mod gpu;
mod graph;
mod hostile;
mod incremental;
mod layout;
mod material_files;
mod planes;
mod tidy;
mod watch;

/// The viewer example, compiled in so the tests drive the very code `cargo run --example viewer`
/// runs (a nested `cargo build` would wait on the build-directory lock the test run holds).
#[path = "../../examples/viewer.rs"]
mod viewer;
