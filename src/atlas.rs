//! The atlas: every plane's images placed at its layout position, then the padding and every
//! uncovered texel filled by extending values outward from covered texels only (so filtering and
//! mips never pull in a dark or foreign fringe). Albedo alpha stays 0 where nothing was drawn.

use rayon::prelude::*;

use crate::gpu::PlaneImages;
use crate::layout::Layout;
use crate::texture::Texture;

/// The four atlas surfaces of a billboard cloud, before compression.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasImages {
    pub albedo: Texture,
    pub normal: Texture,
    pub mra: Texture,
    pub height: Texture,
    /// Fraction of atlas texels covered by a face.
    pub coverage: f32,
}

/// Which atlas texels a face covers: the shape of the atlas without its colours, so that a
/// colour-only edit finds it unchanged and skips the fill search.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasCoverage {
    pub width: u32,
    pub height: u32,
    pub covered: Vec<bool>,
}

/// For every atlas texel, the covered texel whose values it takes: itself where covered, the
/// nearest covered texel elsewhere. Empty when nothing is covered.
#[derive(Clone, Debug, PartialEq)]
pub struct FillSources(pub Vec<u32>);

/// Calls `visit(plane, source_texel, atlas_texel)` for every drawn texel of `planes` (in layout
/// order) at its atlas texel; later planes overwrite earlier ones.
fn for_each_drawn_texel(layout: &Layout, planes: &[&PlaneImages], mut visit: impl FnMut(usize, usize, usize)) {
    let (width, height) = (layout.width as usize, layout.height as usize);
    for (plane, (placement, images)) in layout.placements.iter().zip(planes).enumerate() {
        for row in 0..images.height {
            for column in 0..images.width {
                let source = (row * images.width + column) as usize;
                if images.albedo[source * 4 + 3] == 0 {
                    continue;
                }
                let s = (column as f32 + 0.5) / images.width as f32;
                let t = 1.0 - (row as f32 + 0.5) / images.height as f32;
                let (x, y) = placement.atlas_position(s, t);
                let (x, y) = (x.floor() as usize, y.floor() as usize);
                if x < width && y < height {
                    visit(plane, source, y * width + x);
                }
            }
        }
    }
}

/// The atlas texels that `planes` (in layout order) cover.
pub fn atlas_coverage(layout: &Layout, planes: &[&PlaneImages]) -> AtlasCoverage {
    let mut covered = vec![false; layout.width as usize * layout.height as usize];
    for_each_drawn_texel(layout, planes, |_, _, target| covered[target] = true);
    AtlasCoverage { width: layout.width, height: layout.height, covered }
}

/// Composites `planes` (in layout order) into the atlas of `layout`, then gives every uncovered
/// texel the values named by `fill` (from [`fill_sources`] of the same coverage).
pub fn composite_atlas(layout: &Layout, planes: &[&PlaneImages], coverage: &AtlasCoverage, fill: &FillSources) -> AtlasImages {
    let texels = layout.width as usize * layout.height as usize;
    let mut layers: [Vec<u8>; 4] = std::array::from_fn(|_| vec![0u8; texels * 4]);
    for_each_drawn_texel(layout, planes, |plane, source, target| {
        let images = planes[plane];
        let sources = [&images.albedo, &images.normal, &images.mra, &images.height_map];
        for (layer, image) in layers.iter_mut().zip(sources) {
            layer[target * 4..target * 4 + 4].copy_from_slice(&image[source * 4..source * 4 + 4]);
        }
    });
    let covered_count = coverage.covered.iter().filter(|&&covered| covered).count();
    apply_fill(&mut layers, fill);
    let [albedo, normal, mra, height_layer] = layers;
    AtlasImages {
        albedo: Texture::new(layout.width, layout.height, albedo),
        normal: Texture::new(layout.width, layout.height, normal),
        mra: Texture::new(layout.width, layout.height, mra),
        height: Texture::new(layout.width, layout.height, height_layer),
        coverage: covered_count as f32 / texels.max(1) as f32,
    }
}

/// Finds, for every uncovered texel, its nearest covered texel (breadth-first from all covered
/// texels at once).
pub fn fill_sources(coverage: &AtlasCoverage) -> FillSources {
    const UNREACHED: u32 = u32::MAX;
    const BORDER: u32 = u32::MAX - 1;
    let (width, height, covered) = (coverage.width as usize, coverage.height as usize, &coverage.covered);
    if !covered.iter().any(|&c| c) {
        return FillSources(Vec::new());
    }
    // The search runs on a grid with a one-texel border that counts as already reached, so a
    // texel's four neighbours are ±1 and ±stride with no bounds tests. Each cell holds the
    // (unpadded) index of the covered texel it copies from.
    let stride = width + 2;
    let mut source = vec![UNREACHED; stride * (height + 2)];
    source[..stride].fill(BORDER);
    source[(height + 1) * stride..].fill(BORDER);
    for row in 1..=height {
        source[row * stride] = BORDER;
        source[row * stride + width + 1] = BORDER;
    }
    let mut queue: Vec<u32> = Vec::with_capacity(width * height);
    for (index, _) in covered.iter().enumerate().filter(|(_, &c)| c) {
        let padded = (index / width + 1) * stride + index % width + 1;
        source[padded] = index as u32;
        queue.push(padded as u32);
    }
    // Breadth-first from every covered texel at once, neighbours in the order left, right, up,
    // down: each uncovered texel takes the source of the texel that reached it first.
    let mut next = 0;
    while let Some(&cell) = queue.get(next) {
        next += 1;
        let cell = cell as usize;
        let from = source[cell];
        for neighbour in [cell - 1, cell + 1, cell - stride, cell + stride] {
            if source[neighbour] == UNREACHED {
                source[neighbour] = from;
                queue.push(neighbour as u32);
            }
        }
    }
    FillSources((0..height).flat_map(|row| source[(row + 1) * stride + 1..(row + 1) * stride + 1 + width].iter().copied()).collect())
}

/// Gives every uncovered texel the values of its fill source, the four layers in parallel.
/// Albedo alpha is left at 0 on filled texels. With nothing covered, the normal layer becomes a
/// neutral flat normal, so the surface stays valid.
fn apply_fill(layers: &mut [Vec<u8>; 4], fill: &FillSources) {
    if fill.0.is_empty() {
        for texel in layers[1].chunks_exact_mut(4) {
            texel.copy_from_slice(&[128, 128, 255, 255]);
        }
        return;
    }
    layers.par_iter_mut().enumerate().for_each(|(layer_index, layer)| {
        let channels = if layer_index == 0 { 3 } else { 4 };
        for (index, &from) in fill.0.iter().enumerate() {
            let from = from as usize;
            if from != index {
                layer.copy_within(from * 4..from * 4 + channels, index * 4);
            }
        }
    });
}
