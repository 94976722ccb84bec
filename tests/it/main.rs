//! The integration tests of cirrus: one binary, a module per kind (`material`, `billboard_cloud`)
//! and one per concern of the machinery and the shell.

mod support;

mod material;
mod memory;
mod billboard_cloud;
mod atlas;
mod ambient_occlusion;
mod height;

mod cache;
mod cli;
mod config;
mod conformance;
mod fuzz;
mod gltf;
mod graph;
mod seaweed;
mod shared_cache;
mod hostile;
mod hostile_outputs;
mod isa;
mod project_parts;
mod protocol;
mod scale;
mod tidy;
mod watch;
mod web;

/// The viewer example, compiled in so the tests drive the very code `cargo run --example viewer`
/// runs (a nested `cargo build` would wait on the build-directory lock the test run holds).
#[path = "../../examples/viewer.rs"]
mod viewer;

/// The synthetic level generator, as `cargo run --example make_level` and the `scale` bench use it.
#[path = "../../examples/make_level.rs"]
#[allow(dead_code)]
mod make_level;
