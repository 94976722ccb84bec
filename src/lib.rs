//! cirrus: an incremental asset-pipeline daemon that bakes meshes into billboard-cloud LODs and
//! texture sets into block-compressed GPU materials. This crate is the application: the one list
//! of kinds, the driver, the daemon and the command line. The machinery that names no kind is
//! `cirrus-core` (crates/core), each kind a crate of its own under kinds/; both are re-exported
//! here under the names the modules below use. The modules are listed bottom-up, as they stack.

// The one list of asset kinds (a macro, first so that every module below may use it).
#[macro_use]
mod kind_list;

// The shared libraries and the machinery (crates/), which depend on nothing of this one.
pub use cirrus_core::{cache, config, db, files, memory, record, schedule, sources, summary};
pub use cirrus_core::{diagnostic, gpu, impostor, isa, mesh, openddl, packing, preview, stop, texture};

// The asset kinds: what a kind is (the machinery's `kinds`), each kind's crate under the name of
// its folder, and what the one list of kinds makes of them (`entries`: the `pipeline.ron`
// entries, a rule's `kind:` names, every kind).
pub mod kinds {
    pub use cirrus_core::kinds::*;

    pub use cirrus_ambient_occlusion as ambient_occlusion;
    pub use cirrus_atlas as atlas;
    pub use cirrus_billboard_cloud as billboard_cloud;
    pub use cirrus_height as height;
    pub use cirrus_material as material;

    pub mod entries;
}
// `pipeline.ron` read with every kind's entry.
pub mod pipeline;

// Writing artifacts, the dependency graph.
pub mod artifacts;
pub mod graph;

// The driver: inputs in, jobs on workers, artifacts out; it names no kind.
pub mod project;

// The shell: the daemon, its protocol, the command line.
pub mod watch;
pub mod server;
pub mod cli;
