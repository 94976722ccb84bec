//! The UV layout: plane rectangles packed into one atlas at one uniform texel density, sizes
//! rounded up to whole BC blocks with `padding` texels around each, 90° rotation allowed, in
//! the smallest (power-of-two when asked) atlas that fits; the density scales down uniformly
//! when `max_size` is reached.

use crate::packing::PageSettings;
use crate::packing::{pack_smallest, Placement};

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Layout {
    pub width: u32,
    pub height: u32,
    /// Texels per world unit.
    pub texel_density: f32,
    pub placements: Vec<Placement>,
    /// Fraction of the atlas covered by rectangles (without padding).
    pub occupancy: f32,
}

/// Packs rectangles of `sizes` (world units, width × height) into one atlas.
pub fn layout_rectangles(sizes: &[(f32, f32)], settings: &PageSettings, texel_density: Option<f32>) -> Layout {
    let area: f32 = sizes.iter().map(|(w, h)| w.max(1e-6) * h.max(1e-6)).sum::<f32>().max(1e-12);
    let max_side = settings.max_size as f32;
    let pack_at = |density: f32| {
        let cells: Vec<(u32, u32)> =
            sizes.iter().map(|&(w, h)| (block_size(w * density), block_size(h * density))).collect();
        pack_smallest(&cells, settings).map(|(width, height, placements)| {
            let used: u64 = cells.iter().map(|&(w, h)| w as u64 * h as u64).sum();
            let occupancy = used as f32 / (width as f32 * height as f32);
            Layout { width, height, texel_density: density, placements, occupancy }
        })
    };
    // Start from the density that would fill the largest atlas exactly, or the one asked for;
    // 5 % lower each time it does not fit, then bisection (on log density) between the first
    // that fits and the last that did not, so the rectangles fill the atlas as far as the packer
    // can (oak at 256 quads: 75 % → 80 % of the atlas; 150 test rectangles: 69 % → 75 %).
    let mut density = texel_density.unwrap_or_else(|| (max_side * max_side / area).sqrt());
    let mut failed: Option<f32> = None;
    for _ in 0..200 {
        if let Some(mut layout) = pack_at(density) {
            if let Some(mut high) = failed {
                let mut low = density;
                for _ in 0..LAYOUT_BISECTIONS {
                    let middle = (low * high).sqrt();
                    match pack_at(middle) {
                        Some(denser) => (layout, low) = (denser, middle),
                        None => high = middle,
                    }
                }
            }
            return layout;
        }
        failed = Some(density);
        density *= 0.95;
    }
    // Even one block per rectangle does not fit: the caller's max_size is far too small.
    let cells: Vec<(u32, u32)> = sizes.iter().map(|_| (4, 4)).collect();
    let (width, height, placements) =
        pack_smallest(&cells, &PageSettings { max_size: u32::MAX / 4, ..settings.clone() }).expect("unbounded atlas");
    Layout { width, height, texel_density: 0.0, placements, occupancy: 0.0 }
}

/// Bisection steps of the density between the first that fits and the last that did not (5 %
/// apart): to within 0.2 %.
const LAYOUT_BISECTIONS: usize = 5;

/// Texels rounded up to whole 4×4 blocks, at least one block.
fn block_size(texels: f32) -> u32 {
    ((texels.ceil().max(1.0) as u32).div_ceil(4) * 4).max(4)
}
