//! The tests of the mesh library, one binary (as the application's `tests/it`): a module per
//! library module under test.

mod occlusion;
mod pn_triangles;
mod uv_raster;
