//! LOD previews: the source mesh and its billboard cloud rendered from the 26 directions of a
//! cube (face centres, edge midpoints, corners) under the same orthographic camera and light,
//! compared by silhouette IoU and PSNR, and laid out side by side in a contact sheet.

use glam::{Mat4, Vec3};
use serde::Serialize;

use crate::gpu::{Gpu, GpuError, ViewMesh};

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
    let center = Vec3::from(center);
    let radius = radius.max(1e-6);
    let light = Vec3::new(0.4, 0.8, 0.45).normalize().to_array();
    let mut metrics = Vec::new();
    let mut pairs = Vec::new();
    for direction in view_directions().into_iter().take(views) {
        let d = Vec3::from(direction);
        let up = if d.y.abs() > 0.9 { Vec3::Z } else { Vec3::Y };
        let view = Mat4::look_at_rh(center + d * 2.0 * radius, center, up);
        let projection = Mat4::orthographic_rh(-radius, radius, -radius, radius, 0.5 * radius, 3.5 * radius);
        let matrix = (projection * view).to_cols_array_2d();
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
