//! Packed surfaces: the five source maps packed into the three GPU textures of a baked material
//! (albedo+opacity, metallic/roughness/AO, normal XY), each at the largest size of its sources,
//! smaller sources resampled with a Catmull-Rom filter, constants where a map is missing.

use crate::material_definition::MaterialConstants;
use crate::texture::{SurfaceKind, Texture, TextureSlot};

/// Size of a surface with no source map at all: one BC block.
const CONSTANT_SURFACE_SIDE: u32 = 4;

/// Packs `kind` from its source maps (`None` where the material has no such map).
/// `sources` must hold one entry per slot of `kind.slots()`, in that order.
pub fn pack_surface(kind: SurfaceKind, sources: &[Option<&Texture>], constants: &MaterialConstants) -> Texture {
    assert_eq!(sources.len(), kind.slots().len(), "one source per slot");
    let width = sources.iter().flatten().map(|texture| texture.width).max().unwrap_or(CONSTANT_SURFACE_SIDE);
    let height = sources.iter().flatten().map(|texture| texture.height).max().unwrap_or(CONSTANT_SURFACE_SIDE);
    let resampled: Vec<Option<Vec<u8>>> = sources
        .iter()
        .zip(kind.slots())
        .map(|(source, slot)| {
            source.map(|texture| match slot {
                TextureSlot::Opacity => resample_rgba8(&crate::texture::opacity_channel(texture), width, height, false),
                _ => resample_rgba8(texture, width, height, slot.is_srgb()),
            })
        })
        .collect();
    let texel_count = (width * height) as usize;
    let mut pixels = vec![0u8; texel_count * 4];
    match kind {
        SurfaceKind::Albedo => {
            let constant = constants.albedo.map(|c| c.clamp(0.0, 1.0));
            let constant_rgba =
                [linear_to_srgb_u8(constant[0]), linear_to_srgb_u8(constant[1]), linear_to_srgb_u8(constant[2]), unorm_u8(constant[3])];
            for (index, texel) in pixels.chunks_exact_mut(4).enumerate() {
                let mut rgba = match &resampled[0] {
                    Some(albedo) => [albedo[index * 4], albedo[index * 4 + 1], albedo[index * 4 + 2], albedo[index * 4 + 3]],
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
        SurfaceKind::Normal => {
            for (index, texel) in pixels.chunks_exact_mut(4).enumerate() {
                let normal = match &resampled[0] {
                    Some(map) => normalize_tangent_normal(decode_normal([map[index * 4], map[index * 4 + 1], map[index * 4 + 2]])),
                    None => [0.0, 0.0, 1.0],
                };
                texel.copy_from_slice(&encode_normal(normal));
            }
        }
    }
    Texture::new(width, height, pixels)
}

/// True when some texel of an albedo surface is not fully opaque.
pub fn has_transparency(albedo: &Texture) -> bool {
    albedo.pixels.chunks_exact(4).any(|texel| texel[3] < 255)
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

pub fn unorm_u8(value: f32) -> u8 {
    (value.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

pub fn srgb_u8_to_linear(value: u8) -> f32 {
    SRGB_TO_LINEAR[value as usize]
}

/// The sRGB byte nearest to `linear` (clamped to [0, 1]), from tables instead of `powf`: the
/// byte is the number of rounding thresholds at or below `linear`; a coarse table gives the
/// count at the start of the value's 1/1024 interval, a step or two finishes it.
pub fn linear_to_srgb_u8(linear: f32) -> u8 {
    let linear = linear.clamp(0.0, 1.0);
    let tables = &*LINEAR_TO_SRGB;
    let mut value = tables.start[(linear * LINEAR_TO_SRGB_STEPS as f32) as usize];
    while value < 255 && linear >= tables.thresholds[value as usize + 1] {
        value += 1;
    }
    value
}

const LINEAR_TO_SRGB_STEPS: usize = 1024;

struct LinearToSrgb {
    /// `thresholds[k]`: the smallest linear value whose sRGB byte is at least `k` (k ≥ 1).
    thresholds: [f32; 256],
    /// The byte at `i / LINEAR_TO_SRGB_STEPS`.
    start: [u8; LINEAR_TO_SRGB_STEPS + 1],
}

static LINEAR_TO_SRGB: std::sync::LazyLock<LinearToSrgb> = std::sync::LazyLock::new(|| {
    let srgb_to_linear = |c: f64| if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) };
    let byte_of = |linear: f32| {
        let linear = linear as f64;
        let srgb = if linear <= 0.003_130_8 { linear * 12.92 } else { 1.055 * linear.powf(1.0 / 2.4) - 0.055 };
        (srgb * 255.0 + 0.5).floor()
    };
    // Byte k starts where the sRGB value reaches (k − 0.5) / 255 (round half up); the f32
    // threshold is then nudged to the first f32 whose byte (in f64) is k.
    let thresholds: [f32; 256] = std::array::from_fn(|k| {
        if k == 0 {
            return f32::NEG_INFINITY;
        }
        let mut threshold = srgb_to_linear((k as f64 - 0.5) / 255.0) as f32;
        while byte_of(threshold) < k as f64 {
            threshold = threshold.next_up();
        }
        while byte_of(threshold.next_down()) >= k as f64 {
            threshold = threshold.next_down();
        }
        threshold
    });
    let start = std::array::from_fn(|i| {
        let linear = i as f32 / LINEAR_TO_SRGB_STEPS as f32;
        thresholds.iter().skip(1).take_while(|&&threshold| linear >= threshold).count() as u8
    });
    LinearToSrgb { thresholds, start }
});

static SRGB_TO_LINEAR: std::sync::LazyLock<[f32; 256]> = std::sync::LazyLock::new(|| {
    std::array::from_fn(|index| {
        let c = index as f32 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    })
});

pub fn decode_normal(rgb: [u8; 3]) -> [f32; 3] {
    rgb.map(|c| c as f32 / 255.0 * 2.0 - 1.0)
}

pub fn encode_normal(normal: [f32; 3]) -> [u8; 4] {
    let [x, y, z] = normal.map(|c| unorm_u8(c * 0.5 + 0.5));
    [x, y, z, 255]
}

/// Unit length, facing out of the surface (z ≥ 0); a degenerate normal becomes flat.
pub fn normalize_tangent_normal([x, y, z]: [f32; 3]) -> [f32; 3] {
    let z = z.max(0.0);
    let length = (x * x + y * y + z * z).sqrt();
    if length < 1e-6 {
        [0.0, 0.0, 1.0]
    } else {
        [x / length, y / length, z / length]
    }
}
