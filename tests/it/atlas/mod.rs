//! The `Atlas` kind: its page composite and trim over the shared packer, whole bakes, and meshes
//! remapped onto the pages.

mod bake;
mod page;
mod remap;
