//! Packed surfaces: the five source maps packed into the three GPU textures of a baked material
//! (albedo+opacity, metallic/roughness/AO, normal XY), each at the largest size of its sources,
//! smaller sources resampled with a Catmull-Rom filter, constants where a map is missing. Used by
//! the material kind and by the maps of a billboard chain's reduced levels.

use crate::color::{
    decode_normal, encode_normal, linear_to_srgb_u8, normalize_tangent_normal, srgb_u8_to_linear, unorm_u8,
};
use crate::{SurfaceKind, Texture, TextureSlot};

/// The values a packed surface takes where its material has no map.
#[derive(Clone, Debug, PartialEq)]
pub struct PackConstants {
    /// The albedo without a map (linear RGB, alpha).
    pub albedo: [f32; 4],
    pub metallic: f32,
    pub roughness: f32,
    pub ao: f32,
}

/// Size of a surface with no source map at all: one BC block.
const CONSTANT_SURFACE_SIDE: u32 = 4;

/// Packs `kind` from its source maps (`None` where the material has no such map).
/// `sources` must hold one entry per slot of `kind.slots()`, in that order.
pub fn pack_surface(kind: SurfaceKind, sources: &[Option<&Texture>], constants: &PackConstants) -> Texture {
    assert_eq!(sources.len(), kind.slots().len(), "one source per slot");
    // An albedo map alone is its own surface: sharing its texels keeps one copy of them in
    // memory instead of two (the decoded map and the surface, both memoized).
    if let (SurfaceKind::Albedo, [Some(albedo), None]) = (kind, sources) {
        return (*albedo).clone();
    }
    let width = sources.iter().flatten().map(|texture| texture.width).max().unwrap_or(CONSTANT_SURFACE_SIDE);
    let height = sources.iter().flatten().map(|texture| texture.height).max().unwrap_or(CONSTANT_SURFACE_SIDE);
    let resampled: Vec<Option<Vec<u8>>> = sources
        .iter()
        .zip(kind.slots())
        .map(|(source, slot)| {
            source.map(|texture| match slot {
                TextureSlot::Opacity => resample_rgba8(&crate::opacity_channel(texture), width, height, false),
                _ => resample_rgba8(texture, width, height, slot.is_srgb()),
            })
        })
        .collect();
    let texel_count = (width * height) as usize;
    let mut pixels = vec![0u8; texel_count * 4];
    match kind {
        SurfaceKind::Albedo => {
            let constant = constants.albedo.map(|c| c.clamp(0.0, 1.0));
            let constant_rgba = [
                linear_to_srgb_u8(constant[0]),
                linear_to_srgb_u8(constant[1]),
                linear_to_srgb_u8(constant[2]),
                unorm_u8(constant[3]),
            ];
            for (index, texel) in pixels.chunks_exact_mut(4).enumerate() {
                let mut rgba = match &resampled[0] {
                    Some(albedo) => {
                        [albedo[index * 4], albedo[index * 4 + 1], albedo[index * 4 + 2], albedo[index * 4 + 3]]
                    }
                    None => constant_rgba,
                };
                if let Some(opacity) = &resampled[1] {
                    rgba[3] = ((rgba[3] as u32 * opacity[index * 4] as u32 + 127) / 255) as u8;
                }
                texel.copy_from_slice(&rgba);
            }
        }
        SurfaceKind::Mra => {
            let constant = [constants.metallic, constants.roughness, constants.ao].map(unorm_u8);
            for (index, texel) in pixels.chunks_exact_mut(4).enumerate() {
                for channel in 0..3 {
                    texel[channel] = resampled[channel].as_ref().map_or(constant[channel], |map| map[index * 4]);
                }
                texel[3] = 255;
            }
        }
        SurfaceKind::Height => pixels.chunks_exact_mut(4).for_each(|texel| texel.copy_from_slice(&[128, 0, 0, 255])),
        // Not a material surface; grey from the AO map or constant, should a kind ask.
        SurfaceKind::Ao => {
            let constant = unorm_u8(constants.ao);
            for (index, texel) in pixels.chunks_exact_mut(4).enumerate() {
                let value = resampled[0].as_ref().map_or(constant, |map| map[index * 4]);
                texel.copy_from_slice(&[value, value, value, 255]);
            }
        }
        SurfaceKind::Normal => {
            for (index, texel) in pixels.chunks_exact_mut(4).enumerate() {
                let normal = match &resampled[0] {
                    Some(map) => normalize_tangent_normal(decode_normal([
                        map[index * 4],
                        map[index * 4 + 1],
                        map[index * 4 + 2],
                    ])),
                    None => [0.0, 0.0, 1.0],
                };
                texel.copy_from_slice(&encode_normal(normal));
            }
        }
    }
    Texture::new(width, height, pixels)
}

/// Resamples to `width` × `height` (Catmull-Rom; colour maps in linear light) as RGBA8.
fn resample_rgba8(texture: &Texture, width: u32, height: u32, srgb: bool) -> Vec<u8> {
    if texture.width == width && texture.height == height {
        return texture.pixels.to_vec();
    }
    let floats: Vec<f32> = texture
        .pixels
        .chunks_exact(4)
        .flat_map(|texel| {
            let decode = |c: u8| {
                if srgb {
                    srgb_u8_to_linear(c)
                } else {
                    c as f32 / 255.0
                }
            };
            [decode(texel[0]), decode(texel[1]), decode(texel[2]), texel[3] as f32 / 255.0]
        })
        .collect();
    let source = image::Rgba32FImage::from_raw(texture.width, texture.height, floats).expect("sized above");
    let resized = image::imageops::resize(&source, width, height, image::imageops::FilterType::CatmullRom);
    resized
        .into_raw()
        .chunks_exact(4)
        .flat_map(|texel| {
            let encode = |c: f32| {
                if srgb {
                    linear_to_srgb_u8(c)
                } else {
                    unorm_u8(c)
                }
            };
            [encode(texel[0]), encode(texel[1]), encode(texel[2]), unorm_u8(texel[3])]
        })
        .collect()
}
