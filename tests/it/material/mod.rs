//! The `Material` kind: baking `.mymaterial` files (artifacts, PSNR, reports, errors), the
//! incremental re-bakes after each kind of edit, and the `.mymaterial` parser's fixtures.

pub mod bake;
mod block_compression;
mod files;
mod incremental;
