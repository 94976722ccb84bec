//! Colour and normal encodings shared by every texture stage: unorm bytes, sRGB ↔ linear (from
//! tables), tangent-space normals in RGB, and whether an albedo has transparency.

use super::Texture;

/// True when some texel of an albedo surface is not fully opaque.
pub fn has_transparency(albedo: &Texture) -> bool {
    albedo.pixels.chunks_exact(4).any(|texel| texel[3] < 255)
}

pub(crate) fn unorm_u8(value: f32) -> u8 {
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

pub(crate) fn decode_normal(rgb: [u8; 3]) -> [f32; 3] {
    rgb.map(|c| c as f32 / 255.0 * 2.0 - 1.0)
}

pub(crate) fn encode_normal(normal: [f32; 3]) -> [u8; 4] {
    let [x, y, z] = normal.map(|c| unorm_u8(c * 0.5 + 0.5));
    [x, y, z, 255]
}

/// Unit length, facing out of the surface (z ≥ 0); a degenerate normal becomes flat.
pub(crate) fn normalize_tangent_normal([x, y, z]: [f32; 3]) -> [f32; 3] {
    let z = z.max(0.0);
    let length = (x * x + y * y + z * z).sqrt();
    if length < 1e-6 {
        [0.0, 0.0, 1.0]
    } else {
        [x / length, y / length, z / length]
    }
}
