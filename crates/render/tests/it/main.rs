//! The tests of what is drawn on the GPU (the software Vulkan adapter in CI), one binary (as the
//! application's `tests/it`): previews, impostors, plane renders, and triangle LODs judged by
//! their renders.

mod impostor;
mod plane_render;
mod preview;
mod reduce;
