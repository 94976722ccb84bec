//! Octahedral impostors baked from a mesh: one orthographic frame per direction of a
//! [`FrameGrid`] (`mesh::octahedral`), each the bounding sphere seen from that direction, laid
//! out in one atlas per surface (frame `j · frames + i` at column `i`, row `j`): the unlit albedo
//! with its coverage in alpha, the normal in the frame's own axes (as a tangent-space normal map
//! stores it, so that it travels as BC5), and the depth across the sphere (as a height map, BC4).

use glam::Vec3;

use crate::gpu::{Gpu, GpuError, ViewMesh};
use crate::mesh::octahedral::{frame_axes, frame_view_projection, FrameGrid};
use crate::texture::fill::{fill_from_sources, texel_sources};
use crate::texture::Texture;

/// What an impostor is baked at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImpostorSettings {
    pub grid: FrameGrid,
    /// Each frame's side in texels.
    pub frame_size: u32,
}

/// A baked impostor: its frames' atlases and the sphere they frame. Texels no surface covers
/// take the values of the nearest covered texel of their frame (alpha stays 0), so that
/// filtering and mips pull in no fringe.
#[derive(Clone, Debug)]
pub struct ImpostorFrames {
    pub settings: ImpostorSettings,
    pub center: Vec3,
    pub radius: f32,
    /// sRGB albedo, alpha 255 where the mesh was drawn.
    pub albedo: Texture,
    /// The normal in the frame's axes (x right, y up, z towards the frame's eye, never below 0)
    /// as `0.5 + 0.5 n` in RGB; alpha 255.
    pub normal: Texture,
    /// The depth along the frame's direction in R (0 at the sphere's near side, 255 at its far
    /// side), repeated in G and B; alpha 255.
    pub depth: Texture,
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
    let mut atlases = [(); 3].map(|_| vec![0u8; side * side * 4]);
    for frame in 0..grid.frame_count() {
        let direction = grid.frame_direction(frame);
        let camera = frame_view_projection(center, radius, direction);
        let [albedo, normal_depth] = gpu.render_impostor_frame(mesh, camera.to_cols_array_2d(), frame_size)?;
        let images = frame_surfaces(&albedo, &normal_depth, direction, frame_size);
        let (column, row) = ((frame % grid.frames * frame_size) as usize, (frame / grid.frames * frame_size) as usize);
        let row_bytes = frame_size as usize * 4;
        for (atlas, image) in atlases.iter_mut().zip(&images) {
            for y in 0..frame_size as usize {
                let at = ((row + y) * side + column) * 4;
                atlas[at..at + row_bytes].copy_from_slice(&image[y * row_bytes..][..row_bytes]);
            }
        }
    }
    let [albedo, normal, depth] = atlases.map(|pixels| Texture::new(side as u32, side as u32, pixels));
    Ok(ImpostorFrames { settings, center, radius, albedo, normal, depth })
}

/// One frame's albedo, frame-space normal and depth images, filled, from the frame renderer's
/// albedo and world-space normal + depth (seen from `direction`).
fn frame_surfaces(albedo: &[u8], normal_depth: &[u8], direction: Vec3, size: u32) -> [Vec<u8>; 3] {
    let (right, up) = frame_axes(direction);
    let toward = direction.normalize();
    let mut normal = vec![0u8; normal_depth.len()];
    let mut depth = vec![0u8; normal_depth.len()];
    for ((source, normal), depth) in
        normal_depth.chunks_exact(4).zip(normal.chunks_exact_mut(4)).zip(depth.chunks_exact_mut(4))
    {
        let world = Vec3::new(source[0] as f32, source[1] as f32, source[2] as f32) / 127.5 - Vec3::ONE;
        // Facing away from the frame's eye only where a normal map tilts it past the silhouette.
        let seen = Vec3::new(world.dot(right), world.dot(up), world.dot(toward).max(0.0)).normalize_or(Vec3::Z);
        let encoded = (seen * 127.5 + Vec3::splat(127.5)).round().clamp(Vec3::ZERO, Vec3::splat(255.0));
        normal.copy_from_slice(&[encoded.x as u8, encoded.y as u8, encoded.z as u8, 255]);
        depth.copy_from_slice(&[source[3], source[3], source[3], 255]);
    }
    let covered = albedo.chunks_exact(4).enumerate().filter(|(_, texel)| texel[3] > 0).map(|(at, _)| at as u32);
    let sources = texel_sources(size, size, covered);
    if sources.0.is_empty() {
        return [albedo.to_vec(), normal, depth];
    }
    [
        fill_from_sources(albedo, size, &sources, true),
        fill_from_sources(&normal, size, &sources, false),
        fill_from_sources(&depth, size, &sources, false),
    ]
}
