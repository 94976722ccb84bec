//! LOD previews: the source mesh and its billboard cloud rendered from the 26 directions of a
//! cube (face centres, edge midpoints, corners) under the same orthographic camera and light,
//! compared by silhouette IoU and PSNR, and laid out side by side in a contact sheet.

use glam::{Mat4, Vec3};
use serde::Serialize;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use crate::diagnostic::Diagnostic;
use crate::gpu::{Gpu, GpuError, RenderVertex, ViewMaterial, ViewMesh};
use crate::texture::Texture;

/// The 26 view directions, unit length: 6 face centres, 12 edge midpoints, 8 corners.
pub fn view_directions() -> Vec<[f32; 3]> {
    let mut directions = Vec::new();
    for nonzero in 1..=3 {
        for x in -1i32..=1 {
            for y in -1i32..=1 {
                for z in -1i32..=1 {
                    if [x, y, z].iter().filter(|&&c| c != 0).count() == nonzero {
                        directions.push(Vec3::new(x as f32, y as f32, z as f32).normalize().to_array());
                    }
                }
            }
        }
    }
    directions
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewMetrics {
    pub direction: [f32; 3],
    pub iou: f64,
    pub psnr: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PreviewMetrics {
    pub views: Vec<ViewMetrics>,
    pub mean_iou: f64,
    pub min_iou: f64,
    pub mean_psnr: f64,
}

/// The result of a preview: metrics and the contact sheet (PNG bytes).
pub struct Preview {
    pub metrics: PreviewMetrics,
    pub contact_sheet: Vec<u8>,
}

/// Renders `source` and `lod` from the first `views` directions at `size`² pixels, framing the
/// sphere at `center` with `radius`.
pub fn preview(
    gpu: &Gpu,
    source: &ViewMesh,
    lod: &ViewMesh,
    center: [f32; 3],
    radius: f32,
    views: usize,
    size: u32,
) -> Result<Preview, GpuError> {
    let light = preview_light();
    let mut metrics = Vec::new();
    let mut pairs = Vec::new();
    for direction in view_directions().into_iter().take(views) {
        let matrix = view_projection(center, radius, direction);
        let source_image = gpu.render_view(source, matrix, light, size)?;
        let lod_image = gpu.render_view(lod, matrix, light, size)?;
        metrics.push(ViewMetrics { direction, iou: silhouette_iou(&source_image, &lod_image), psnr: rgb_psnr(&source_image, &lod_image) });
        pairs.push((source_image, lod_image));
    }
    let count = metrics.len().max(1) as f64;
    let mean_iou = metrics.iter().map(|view| view.iou).sum::<f64>() / count;
    let min_iou = metrics.iter().map(|view| view.iou).fold(1.0, f64::min);
    let mean_psnr = metrics.iter().map(|view| view.psnr).sum::<f64>() / count;
    Ok(Preview { metrics: PreviewMetrics { views: metrics, mean_iou, min_iou, mean_psnr }, contact_sheet: contact_sheet(&pairs, size) })
}

/// The light direction of every preview render.
pub fn preview_light() -> [f32; 3] {
    Vec3::new(0.4, 0.8, 0.45).normalize().to_array()
}

/// The orthographic camera of the previews: looking at `center` from `direction` (unit length),
/// framing the sphere of `radius`.
pub fn view_projection(center: [f32; 3], radius: f32, direction: [f32; 3]) -> [[f32; 4]; 4] {
    let (center, radius, direction) = (Vec3::from(center), radius.max(1e-6), Vec3::from(direction));
    let up = if direction.y.abs() > 0.9 { Vec3::Z } else { Vec3::Y };
    let view = Mat4::look_at_rh(center + direction * 2.0 * radius, center, up);
    let projection = Mat4::orthographic_rh(-radius, radius, -radius, radius, 0.5 * radius, 3.5 * radius);
    (projection * view).to_cols_array_2d()
}

/// The centre of the bounding box of `mesh`'s vertices and the radius around it that holds them.
pub fn bounding_sphere(mesh: &ViewMesh) -> ([f32; 3], f32) {
    let positions = || mesh.batches.iter().flat_map(|(_, vertices)| vertices.iter().map(|vertex| Vec3::from(vertex.position)));
    let (min, max) =
        positions().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(min, max), p| (min.min(p), max.max(p)));
    if min.x > max.x {
        return ([0.0; 3], 1.0);
    }
    let center = 0.5 * (min + max);
    (center.to_array(), positions().map(|p| p.distance(center)).fold(0.0, f32::max))
}

/// The files of a baked LOD, each with its path (for messages) and bytes.
pub struct LodFiles {
    pub obj: (PathBuf, Vec<u8>),
    pub albedo_ktx2: (PathBuf, Vec<u8>),
    pub normal_ktx2: (PathBuf, Vec<u8>),
    pub alpha_cutoff: f32,
}

/// The baked LOD as an engine sees it: `lod.obj` with the decoded KTX2 atlas levels (BC-decoded,
/// so renders show the compression), alpha-tested and double-sided.
pub fn lod_view_mesh(files: &LodFiles) -> Result<ViewMesh, Diagnostic> {
    let (obj_path, obj_bytes) = &files.obj;
    let folder = obj_path.parent().map(PathBuf::from).unwrap_or_default();
    let (mesh, _) = crate::mesh::load_mesh(obj_path, obj_bytes, &BTreeMap::new(), &folder)?;
    let decode = |(path, bytes): &(PathBuf, Vec<u8>)| -> Result<Vec<Texture>, Diagnostic> {
        let ktx2 = crate::container::read_ktx2(bytes).map_err(|error| Diagnostic::new(path, error))?;
        Ok(ktx2
            .levels
            .iter()
            .enumerate()
            .map(|(level, blocks)| {
                let (width, height) = ((ktx2.width >> level).max(1), (ktx2.height >> level).max(1));
                crate::quality::decode_blocks(ktx2.format, blocks, width, height)
            })
            .collect())
    };
    // BC5 holds X and Y only; the shader rebuilds Z from them.
    let normal = decode(&files.normal_ktx2)?
        .into_iter()
        .map(|level| {
            let pixels: Vec<u8> = level.pixels.chunks_exact(4).flat_map(|texel| [texel[0], texel[1], 0, 255]).collect();
            Texture::new(level.width, level.height, pixels)
        })
        .collect();
    let material = ViewMaterial {
        albedo: Some(Arc::new(decode(&files.albedo_ktx2)?)),
        opacity: None,
        normal: Some(Arc::new(normal)),
        normal_has_z: false,
        albedo_factor: [1.0; 4],
        alpha_cutoff: files.alpha_cutoff,
    };
    let uvs = mesh.uvs.as_deref().unwrap_or(&[]);
    let tangents = crate::gpu::vertex_tangents(&mesh.positions, &mesh.normals, uvs, &mesh.triangles);
    let vertices = mesh
        .triangles
        .iter()
        .flatten()
        .map(|&index| {
            let index = index as usize;
            RenderVertex {
                position: mesh.positions[index],
                normal: mesh.normals[index],
                uv: uvs.get(index).copied().unwrap_or([0.0; 2]),
                tangent: tangents.get(index).copied().unwrap_or([1.0, 0.0, 0.0, 1.0]),
            }
        })
        .collect();
    Ok(ViewMesh { batches: vec![(0, vertices)], materials: vec![material] })
}

/// |A ∩ B| / |A ∪ B| of the drawn pixels (alpha > 0); 1 when both are empty.
pub fn silhouette_iou(a: &[u8], b: &[u8]) -> f64 {
    let (mut both, mut either) = (0u64, 0u64);
    for (x, y) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        let (in_a, in_b) = (x[3] > 0, y[3] > 0);
        both += (in_a && in_b) as u64;
        either += (in_a || in_b) as u64;
    }
    if either == 0 {
        1.0
    } else {
        both as f64 / either as f64
    }
}

/// PSNR of the colour (background included), capped at 100 dB.
pub fn rgb_psnr(a: &[u8], b: &[u8]) -> f64 {
    let mut squared = 0u64;
    for (x, y) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for channel in 0..3 {
            let difference = x[channel] as i64 - y[channel] as i64;
            squared += (difference * difference) as u64;
        }
    }
    let samples = (a.len() / 4 * 3).max(1) as f64;
    if squared == 0 {
        return 100.0;
    }
    (10.0 * (255.0f64 * 255.0 / (squared as f64 / samples)).log10()).min(100.0)
}

/// Source | LOD pairs, four pairs per row, as an opaque PNG.
fn contact_sheet(pairs: &[(Vec<u8>, Vec<u8>)], size: u32) -> Vec<u8> {
    let per_row = 4usize;
    let rows = pairs.len().div_ceil(per_row).max(1);
    let (width, height) = (per_row * 2 * size as usize + (per_row - 1) * 8, rows * size as usize + (rows - 1) * 8);
    let mut pixels = vec![255u8; width * height * 4];
    for (index, (source, lod)) in pairs.iter().enumerate() {
        let (row, column) = (index / per_row, index % per_row);
        for (half, image) in [source, lod].into_iter().enumerate() {
            let x0 = column * (2 * size as usize + 8) + half * size as usize;
            let y0 = row * (size as usize + 8);
            for y in 0..size as usize {
                for x in 0..size as usize {
                    let from = (y * size as usize + x) * 4;
                    let to = ((y0 + y) * width + x0 + x) * 4;
                    pixels[to..to + 3].copy_from_slice(&image[from..from + 3]);
                    pixels[to + 3] = 255;
                }
            }
        }
    }
    crate::preview::preview_png(&crate::texture::Texture::new(width as u32, height as u32, pixels))
}
