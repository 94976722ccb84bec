//! The `BillboardCloud` kind: baking trees (LOD, atlas surfaces, what a texture or mesh edit
//! re-runs, in one process and across two), plane selection, the atlas layout, and the plane and
//! preview renderers on the GPU.

pub mod bake;
mod budget;
pub mod chain;
mod reduced_level;
mod impostor_level;
mod switch;
mod auto;
mod layout;
mod planes;
