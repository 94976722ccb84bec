//! The atlas: every plane's images placed at its layout position, then the padding and every
//! uncovered texel filled by extending values outward from covered texels only (so filtering and
//! mips never pull in a dark or foreign fringe). Albedo alpha stays 0 where nothing was drawn.

use std::sync::Arc;

use rayon::prelude::*;

use crate::gpu::PlaneImages;
use crate::kinds::billboard_cloud::layout::Layout;
use crate::texture::Texture;

/// The four atlas surfaces of a billboard cloud, before compression.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasImages {
    pub albedo: Arc<Texture>,
    pub normal: Arc<Texture>,
    pub mra: Arc<Texture>,
    pub height: Arc<Texture>,
    /// Fraction of atlas texels covered by a face.
    pub coverage: f32,
}

/// Which atlas texels a face covers, and what is drawn there: the shape of the atlas without its
/// colours, so that a colour-only edit finds it unchanged and skips the fill search.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasCoverage {
    pub width: u32,
    pub height: u32,
    /// Every covered texel in index order with the plane image and texel drawn on it (the last
    /// plane in layout order wins).
    pub drawn: Vec<DrawnTexel>,
}

/// One covered atlas texel and the texel of a plane image (in layout order) drawn on it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrawnTexel {
    pub atlas_texel: u32,
    pub plane: u32,
    pub plane_texel: u32,
}

/// For every atlas texel, the covered texel it takes its values from: itself where covered,
/// the nearest covered texel elsewhere. Empty when nothing is covered.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelSources(pub Vec<u32>);

/// Calls `visit(plane, plane_texel, atlas_texel)` for every drawn texel of `planes` (in layout
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

/// The atlas texels that `planes` (in layout order) cover, and what each shows.
pub fn atlas_coverage(layout: &Layout, planes: &[&PlaneImages]) -> AtlasCoverage {
    let texels = layout.width as usize * layout.height as usize;
    let mut last_drawn = vec![(u32::MAX, 0u32); texels];
    for_each_drawn_texel(layout, planes, |plane, plane_texel, atlas_texel| last_drawn[atlas_texel] = (plane as u32, plane_texel as u32));
    let drawn = last_drawn
        .iter()
        .enumerate()
        .filter(|(_, (plane, _))| *plane != u32::MAX)
        .map(|(atlas_texel, &(plane, plane_texel))| DrawnTexel { atlas_texel: atlas_texel as u32, plane, plane_texel })
        .collect();
    AtlasCoverage { width: layout.width, height: layout.height, drawn }
}

/// Composites `planes` (in layout order) into the atlas of `layout`: the drawn texels of
/// `coverage`, then every texel takes the values of the texel `sources` names (from
/// [`texel_sources`] of the same coverage), the four surfaces and their rows in parallel.
/// Albedo alpha stays 0 on uncovered texels.
pub fn composite_atlas(layout: &Layout, planes: &[&PlaneImages], coverage: &AtlasCoverage, sources: &TexelSources) -> AtlasImages {
    let texels = layout.width as usize * layout.height as usize;
    let layer = |index: usize| -> Texture {
        let mut drawn = vec![0u8; texels * 4];
        for texel in &coverage.drawn {
            let images = planes[texel.plane as usize];
            let image = [&images.albedo, &images.normal, &images.mra, &images.height_map][index];
            drawn[texel.atlas_texel as usize * 4..][..4].copy_from_slice(&image[texel.plane_texel as usize * 4..][..4]);
        }
        if sources.0.is_empty() {
            // Nothing drawn at all: a neutral flat normal, so the surface stays valid.
            if index == 1 {
                for texel in drawn.chunks_exact_mut(4) {
                    texel.copy_from_slice(&[128, 128, 255, 255]);
                }
            }
            return Texture::new(layout.width, layout.height, drawn);
        }
        let mut pixels = vec![0u8; texels * 4];
        let row = layout.width as usize * 4;
        pixels.par_chunks_mut(row.max(4)).enumerate().for_each(|(y, row_pixels)| {
            let first = y * layout.width as usize;
            for (x, texel) in row_pixels.chunks_exact_mut(4).enumerate() {
                let from = sources.0[first + x] as usize;
                texel.copy_from_slice(&drawn[from * 4..][..4]);
                if index == 0 && from != first + x {
                    texel[3] = 0;
                }
            }
        });
        Texture::new(layout.width, layout.height, pixels)
    };
    let ((albedo, normal), (mra, height)) = rayon::join(|| rayon::join(|| layer(0), || layer(1)), || rayon::join(|| layer(2), || layer(3)));
    let [albedo, normal, mra, height] = [albedo, normal, mra, height].map(Arc::new);
    AtlasImages { albedo, normal, mra, height, coverage: coverage.drawn.len() as f32 / texels.max(1) as f32 }
}

/// Where every atlas texel takes its values from (see [`TexelSources`]): the nearest covered
/// texel, breadth-first from all covered texels at once.
pub fn texel_sources(coverage: &AtlasCoverage) -> TexelSources {
    const UNREACHED: u32 = u32::MAX;
    const BORDER: u32 = u32::MAX - 1;
    let (width, height) = (coverage.width as usize, coverage.height as usize);
    if coverage.drawn.is_empty() {
        return TexelSources(Vec::new());
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
    for index in coverage.drawn.iter().map(|drawn| drawn.atlas_texel as usize) {
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
    TexelSources((0..height).flat_map(|row| source[(row + 1) * stride + 1..(row + 1) * stride + 1 + width].iter().copied()).collect())
}
