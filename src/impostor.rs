//! Octahedral impostors baked from a mesh: one orthographic frame per direction of a
//! [`FrameGrid`] (`mesh::octahedral`), each the bounding sphere seen from that direction, laid
//! out in one atlas (frame `j · frames + i` at column `i`, row `j`): the unlit albedo with its
//! coverage in alpha, and the world-space normal with the depth across the sphere in alpha.

use glam::Vec3;

use crate::gpu::{Gpu, GpuError, ViewMesh};
use crate::mesh::octahedral::{frame_view_projection, FrameGrid};
use crate::texture::Texture;

/// What an impostor is baked at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImpostorSettings {
    pub grid: FrameGrid,
    /// Each frame's side in texels.
    pub frame_size: u32,
}

/// A baked impostor: its frames' atlases and the sphere they frame.
#[derive(Clone, Debug)]
pub struct ImpostorFrames {
    pub settings: ImpostorSettings,
    pub center: Vec3,
    pub radius: f32,
    /// sRGB albedo, alpha 255 where the mesh was drawn.
    pub albedo: Texture,
    /// `0.5 + 0.5 n` (world space) in RGB, depth in alpha (0 at the sphere's near side, 255 at
    /// its far side); 0 where nothing was drawn.
    pub normal_depth: Texture,
}

/// Renders every frame of `settings.grid` of `mesh` (whose bounding sphere is `center`,
/// `radius`) into the atlases.
pub fn bake_impostor(
    gpu: &Gpu,
    mesh: &ViewMesh,
    (center, radius): (Vec3, f32),
    settings: ImpostorSettings,
) -> Result<ImpostorFrames, GpuError> {
    let ImpostorSettings { grid, frame_size } = settings;
    let side = (grid.frames * frame_size) as usize;
    let (mut albedo, mut normal_depth) = (vec![0u8; side * side * 4], vec![0u8; side * side * 4]);
    for frame in 0..grid.frame_count() {
        let camera = frame_view_projection(center, radius, grid.frame_direction(frame));
        let [frame_albedo, frame_normal_depth] =
            gpu.render_impostor_frame(mesh, camera.to_cols_array_2d(), frame_size)?;
        let (column, row) = ((frame % grid.frames * frame_size) as usize, (frame / grid.frames * frame_size) as usize);
        let row_bytes = frame_size as usize * 4;
        for y in 0..frame_size as usize {
            let at = ((row + y) * side + column) * 4;
            albedo[at..at + row_bytes].copy_from_slice(&frame_albedo[y * row_bytes..][..row_bytes]);
            normal_depth[at..at + row_bytes].copy_from_slice(&frame_normal_depth[y * row_bytes..][..row_bytes]);
        }
    }
    Ok(ImpostorFrames {
        settings,
        center,
        radius,
        albedo: Texture::new(side as u32, side as u32, albedo),
        normal_depth: Texture::new(side as u32, side as u32, normal_depth),
    })
}
