//! Mip chains: each level an area-weighted reduction of the one above, with the filtering each
//! surface needs (colour in linear light and alpha-weighted, coverage-preserving alpha for
//! alpha-tested albedo, renormalised normals, plain averages for data).

use rayon::prelude::*;

use crate::surface::{decode_normal, encode_normal, linear_to_srgb_u8, normalize_tangent_normal, srgb_u8_to_linear, unorm_u8, SurfaceKind};
use crate::texture::Texture;

/// How the levels of one surface are filtered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MipSettings {
    pub kind: SurfaceKind,
    /// Alpha-tested albedo: keep the fraction of texels above this cutoff equal on every level.
    pub alpha_cutoff: Option<f32>,
}

/// Level 0 followed by every smaller level down to 1×1.
pub fn mip_chain(level0: &Texture, settings: MipSettings) -> Vec<Texture> {
    let mut levels = vec![level0.clone()];
    // Reduce from unscaled float levels so that coverage scaling does not compound.
    let mut current = to_filter_space(level0, settings.kind);
    // Straight (not alpha-weighted) linear colour, for albedo texels whose whole footprint is
    // transparent: alpha weighting would leave them black, and bilinear filtering at an
    // alpha-tested edge would then pull the visible colour toward black.
    let mut straight = (settings.kind == SurfaceKind::Albedo && level0.pixels.chunks_exact(4).any(|texel| texel[3] == 0))
        .then(|| straight_linear_colour(level0));
    let (mut width, mut height) = (level0.width, level0.height);
    let coverage = settings.alpha_cutoff.map(|cutoff| alpha_coverage(&current, cutoff, 1.0));
    while width > 1 || height > 1 {
        let (next_width, next_height) = ((width / 2).max(1), (height / 2).max(1));
        current = reduce(&current, width, height, next_width, next_height);
        straight = straight.map(|colour| reduce(&colour, width, height, next_width, next_height));
        (width, height) = (next_width, next_height);
        let alpha_scale = match (settings.alpha_cutoff, coverage) {
            (Some(cutoff), Some(coverage)) => coverage_alpha_scale(&current, cutoff, coverage),
            _ => 1.0,
        };
        levels.push(from_filter_space(&current, straight.as_deref(), width, height, settings.kind, alpha_scale));
    }
    levels
}

/// Texels as floats in the space where averaging is right: linear premultiplied colour for
/// albedo, unit vectors for normals, plain values for data.
fn to_filter_space(texture: &Texture, kind: SurfaceKind) -> Vec<[f32; 4]> {
    texture
        .pixels
        .par_chunks_exact(4)
        .map(|t| match kind {
            SurfaceKind::Albedo => {
                let alpha = t[3] as f32 / 255.0;
                [srgb_u8_to_linear(t[0]) * alpha, srgb_u8_to_linear(t[1]) * alpha, srgb_u8_to_linear(t[2]) * alpha, alpha]
            }
            SurfaceKind::Normal => {
                let [x, y, z] = decode_normal([t[0], t[1], t[2]]);
                [x, y, z, 1.0]
            }
            SurfaceKind::Mra | SurfaceKind::Height => [t[0], t[1], t[2], t[3]].map(|c| c as f32 / 255.0),
        })
        .collect()
}

/// Linear colour of every texel, not weighted by alpha.
fn straight_linear_colour(texture: &Texture) -> Vec<[f32; 4]> {
    texture.pixels.par_chunks_exact(4).map(|t| [srgb_u8_to_linear(t[0]), srgb_u8_to_linear(t[1]), srgb_u8_to_linear(t[2]), 1.0]).collect()
}

fn from_filter_space(
    texels: &[[f32; 4]],
    straight: Option<&[[f32; 4]]>,
    width: u32,
    height: u32,
    kind: SurfaceKind,
    alpha_scale: f32,
) -> Texture {
    let pixels = texels
        .par_iter()
        .enumerate()
        .flat_map_iter(|(index, &[r, g, b, a])| match kind {
            SurfaceKind::Albedo => {
                // Un-premultiply; fully transparent texels take the plain average colour of
                // their footprint (the colour a fill extended there), not black.
                let (r, g, b) = match straight {
                    _ if a > 1e-6 => (r / a, g / a, b / a),
                    Some(straight) => (straight[index][0], straight[index][1], straight[index][2]),
                    None => (r, g, b),
                };
                [linear_to_srgb_u8(r), linear_to_srgb_u8(g), linear_to_srgb_u8(b), unorm_u8(a * alpha_scale)]
            }
            SurfaceKind::Normal => encode_normal(normalize_tangent_normal([r, g, b])),
            SurfaceKind::Mra | SurfaceKind::Height => [unorm_u8(r), unorm_u8(g), unorm_u8(b), unorm_u8(a)],
        })
        .collect();
    Texture::new(width, height, pixels)
}

/// Area-weighted box reduction (handles odd sizes: each target texel covers a fractional
/// footprint of the source).
fn reduce(source: &[[f32; 4]], width: u32, height: u32, new_width: u32, new_height: u32) -> Vec<[f32; 4]> {
    let scale_x = width as f32 / new_width as f32;
    let scale_y = height as f32 / new_height as f32;
    let weights = |index: u32, scale: f32, limit: u32| -> Vec<(u32, f32)> {
        let start = index as f32 * scale;
        let end = start + scale;
        let mut result = Vec::new();
        let mut texel = start.floor() as u32;
        while (texel as f32) < end && texel < limit {
            let overlap = (end.min(texel as f32 + 1.0) - start.max(texel as f32)).max(0.0);
            if overlap > 0.0 {
                result.push((texel, overlap / scale));
            }
            texel += 1;
        }
        result
    };
    let columns: Vec<Vec<(u32, f32)>> = (0..new_width).map(|x| weights(x, scale_x, width)).collect();
    // Rows in parallel: each output texel is the same arithmetic whichever thread computes it.
    (0..new_height)
        .into_par_iter()
        .flat_map_iter(|y| {
            let rows = weights(y, scale_y, height);
            columns
                .iter()
                .map(|column| {
                    let mut sum = [0.0f32; 4];
                    for &(sy, wy) in &rows {
                        for &(sx, wx) in column {
                            let texel = source[(sy * width + sx) as usize];
                            let weight = wx * wy;
                            for channel in 0..4 {
                                sum[channel] += texel[channel] * weight;
                            }
                        }
                    }
                    sum
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Fraction of texels whose alpha × `scale` passes `cutoff`.
fn alpha_coverage(texels: &[[f32; 4]], cutoff: f32, scale: f32) -> f32 {
    let passing = texels.par_iter().filter(|texel| texel[3] * scale > cutoff).count();
    passing as f32 / texels.len().max(1) as f32
}

/// The alpha scale that makes this level's coverage closest to `target` (bisection).
fn coverage_alpha_scale(texels: &[[f32; 4]], cutoff: f32, target: f32) -> f32 {
    let (mut low, mut high) = (0.0f32, 4.0f32);
    for _ in 0..20 {
        let middle = 0.5 * (low + high);
        if alpha_coverage(texels, cutoff, middle) < target {
            low = middle;
        } else {
            high = middle;
        }
    }
    [low, high]
        .into_iter()
        .min_by(|a, b| {
            let error = |scale: f32| (alpha_coverage(texels, cutoff, scale) - target).abs();
            error(*a).total_cmp(&error(*b))
        })
        .unwrap_or(1.0)
}

/// Fraction of texels of an RGBA8 texture whose alpha passes `cutoff` (for tests and reports).
pub fn texture_alpha_coverage(texture: &Texture, cutoff: f32) -> f32 {
    let passing = texture.pixels.chunks_exact(4).filter(|texel| texel[3] as f32 / 255.0 > cutoff).count();
    passing as f32 / (texture.width * texture.height) as f32
}
