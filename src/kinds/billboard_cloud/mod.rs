//! The `BillboardCloud` kind: a mesh turned into a cloud of textured quads (planes → rectangles
//! → layout → per-plane renders → atlas) whose surfaces end in the shared texture tail.

pub mod planes;
pub mod rectangles;
pub mod layout;
pub mod render_groups;
pub mod atlas;
pub mod lod_mesh;
pub mod lod_preview;
