//! The atlas: every plane's images placed at its layout position, then the padding and every
//! uncovered texel filled by extending values outward from covered texels only (so filtering and
//! mips never pull in a dark or foreign fringe). Albedo alpha stays 0 where nothing was drawn.

use rayon::prelude::*;

use crate::gpu::PlaneImages;
use crate::layout::Layout;
use crate::texture::fill::TexelSources;
use crate::texture::{SurfaceKind, Texture};

/// Which atlas texels a face covers, and what is drawn there: the shape of the atlas without its
/// colours, so that a colour-only edit finds it unchanged and skips the fill search.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct AtlasCoverage {
    pub width: u32,
    pub height: u32,
    /// Every covered texel in index order with the plane image and texel drawn on it (the last
    /// plane in layout order wins).
    pub drawn: Vec<DrawnTexel>,
}

impl AtlasCoverage {
    /// A content hash of the coverage (size and every drawn texel), hashed on every core.
    pub(crate) fn content_hash(&self) -> blake3::Hash {
        let mut hasher = blake3::Hasher::new();
        hasher.update(&self.width.to_le_bytes()).update(&self.height.to_le_bytes());
        hasher.update_rayon(bytemuck::cast_slice(&self.drawn));
        hasher.finalize()
    }
}

/// One covered atlas texel and the texel of a plane image (in layout order) drawn on it.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct DrawnTexel {
    pub atlas_texel: u32,
    pub plane: u32,
    pub plane_texel: u32,
}

/// The (atlas texel, plane texel) pairs of every drawn texel of one plane's images at its
/// placement, in the plane's texel order.
fn drawn_texels(layout: &Layout, placement: &crate::packing::Placement, images: &PlaneImages) -> Vec<(u32, u32)> {
    let (width, height) = (layout.width as usize, layout.height as usize);
    let albedo = images.surface(SurfaceKind::Albedo);
    let mut drawn = Vec::new();
    for row in 0..images.height {
        for column in 0..images.width {
            let source = (row * images.width + column) as usize;
            if albedo[source * 4 + 3] == 0 {
                continue;
            }
            let s = (column as f32 + 0.5) / images.width as f32;
            let t = 1.0 - (row as f32 + 0.5) / images.height as f32;
            let (x, y) = placement.atlas_position(s, t);
            let (x, y) = (x.floor() as usize, y.floor() as usize);
            if x < width && y < height {
                drawn.push(((y * width + x) as u32, source as u32));
            }
        }
    }
    drawn
}

/// The atlas texels that `planes` (in layout order) cover, and what each shows: the planes are
/// traced in parallel, then laid down in layout order (a later plane wins a shared texel).
pub(crate) fn atlas_coverage(layout: &Layout, planes: &[&PlaneImages]) -> AtlasCoverage {
    let texels = layout.width as usize * layout.height as usize;
    let per_plane: Vec<Vec<(u32, u32)>> = layout
        .placements
        .par_iter()
        .zip(planes.par_iter())
        .map(|(placement, images)| drawn_texels(layout, placement, images))
        .collect();
    let mut last_drawn = vec![(u32::MAX, 0u32); texels];
    for (plane, drawn) in per_plane.iter().enumerate() {
        for &(atlas_texel, plane_texel) in drawn {
            last_drawn[atlas_texel as usize] = (plane as u32, plane_texel);
        }
    }
    let drawn = last_drawn
        .par_iter()
        .enumerate()
        .filter(|(_, (plane, _))| *plane != u32::MAX)
        .map(|(atlas_texel, &(plane, plane_texel))| DrawnTexel { atlas_texel: atlas_texel as u32, plane, plane_texel })
        .collect();
    AtlasCoverage { width: layout.width, height: layout.height, drawn }
}

/// One surface of the atlas of `layout`: the drawn texels of `coverage` from `planes` (in
/// layout order), then every texel takes the values of the texel `sources` names (from
/// [`texel_sources`] of the same coverage), rows in parallel. Albedo alpha stays 0 on
/// uncovered texels. Surfaces are composited one by one, so that a surface whose parts did not
/// change is never composited (see the kind's `surface_parts_key`, its surfaces' `SurfacePlan::parts`).
pub(crate) fn composite_atlas_surface(
    layout: &Layout,
    planes: &[&PlaneImages],
    coverage: &AtlasCoverage,
    sources: &TexelSources,
    surface: SurfaceKind,
) -> Texture {
    let texels = layout.width as usize * layout.height as usize;
    let images: Vec<&[u8]> = planes.iter().map(|images| images.surface(surface)).collect();
    let mut drawn = vec![0u8; texels * 4];
    for texel in &coverage.drawn {
        let image = images[texel.plane as usize];
        drawn[texel.atlas_texel as usize * 4..][..4].copy_from_slice(&image[texel.plane_texel as usize * 4..][..4]);
    }
    if sources.0.is_empty() {
        // Nothing drawn at all: a neutral flat normal, so the surface stays valid.
        if surface == SurfaceKind::Normal {
            for texel in drawn.chunks_exact_mut(4) {
                texel.copy_from_slice(&[128, 128, 255, 255]);
            }
        }
        return Texture::new(layout.width, layout.height, drawn);
    }
    let pixels = crate::texture::fill::fill_from_sources(&drawn, layout.width, sources, surface == SurfaceKind::Albedo);
    Texture::new(layout.width, layout.height, pixels)
}

/// Where every atlas texel takes its values from: the nearest covered texel (see
/// [`crate::texture::fill`]).
pub(crate) fn texel_sources(coverage: &AtlasCoverage) -> TexelSources {
    crate::texture::fill::texel_sources(
        coverage.width,
        coverage.height,
        coverage.drawn.iter().map(|drawn| drawn.atlas_texel),
    )
}
