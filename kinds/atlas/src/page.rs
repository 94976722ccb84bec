//! The texture atlas's pure steps: trimming an entry's fully transparent borders, and a page put
//! together from its entries (each copied into place, turned where packed so, its padding the
//! clamp of its own edge texels, the rest of the page the nearest entry texel).

use crate::packing::Placement;
use crate::texture::fill::{fill_from_sources, texel_sources, TexelSources};
use crate::texture::Texture;

/// The part of a texture an entry keeps: `x`, `y` is the trim offset inside the source.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct TrimRect {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl TrimRect {
    /// The smallest rectangle holding both.
    pub fn union(self, other: TrimRect) -> TrimRect {
        let (left, top) = (self.x.min(other.x), self.y.min(other.y));
        let (right, bottom) =
            ((self.x + self.width).max(other.x + other.width), (self.y + self.height).max(other.y + other.height));
        TrimRect { x: left, y: top, width: right - left, height: bottom - top }
    }

    /// Whether `other` lies inside.
    pub fn contains(self, other: TrimRect) -> bool {
        other.x >= self.x
            && other.y >= self.y
            && other.x + other.width <= self.x + self.width
            && other.y + other.height <= self.y + self.height
    }
}

/// The texels a mesh's texture coordinates in `u` × `v` (OBJ convention: origin bottom-left,
/// v up; clamped to [0, 1]) fall on, in a `size` texture: what a remapped mesh samples.
pub(crate) fn uv_texel_rect(u: [f32; 2], v: [f32; 2], size: [u32; 2]) -> TrimRect {
    let (width, height) = (size[0] as f32, size[1] as f32);
    let column = |u: f32| (u.clamp(0.0, 1.0) * width).floor().clamp(0.0, width - 1.0) as u32;
    let row = |v: f32| ((1.0 - v.clamp(0.0, 1.0)) * height).floor().clamp(0.0, height - 1.0) as u32;
    let (left, right) = (column(u[0]), column(u[1]));
    let (top, bottom) = (row(v[1]), row(v[0]));
    TrimRect { x: left, y: top, width: right - left + 1, height: bottom - top + 1 }
}

/// The smallest rectangle holding every texel whose alpha is not zero; a fully transparent
/// texture keeps its top-left texel (an entry is never empty).
pub fn opaque_bounds(texture: &Texture) -> TrimRect {
    let (width, height) = (texture.width as usize, texture.height as usize);
    let visible = |x: usize, y: usize| texture.pixels[(y * width + x) * 4 + 3] != 0;
    let row_visible = |y: usize| (0..width).any(|x| visible(x, y));
    let Some(top) = (0..height).find(|&y| row_visible(y)) else {
        return TrimRect { x: 0, y: 0, width: 1, height: 1 };
    };
    let bottom = (0..height).rev().find(|&y| row_visible(y)).expect("a visible row exists");
    let column_visible = |x: usize| (top..=bottom).any(|y| visible(x, y));
    let left = (0..width).find(|&x| column_visible(x)).expect("a visible column exists");
    let right = (0..width).rev().find(|&x| column_visible(x)).expect("a visible column exists");
    TrimRect { x: left as u32, y: top as u32, width: (right - left + 1) as u32, height: (bottom - top + 1) as u32 }
}

/// The texels of `texture` inside `rect`.
pub fn crop(texture: &Texture, rect: TrimRect) -> Texture {
    if (rect.x, rect.y, rect.width, rect.height) == (0, 0, texture.width, texture.height) {
        return texture.clone();
    }
    let row_bytes = rect.width as usize * 4;
    let mut pixels = Vec::with_capacity(row_bytes * rect.height as usize);
    for y in rect.y..rect.y + rect.height {
        let start = (y as usize * texture.width as usize + rect.x as usize) * 4;
        pixels.extend_from_slice(&texture.pixels[start..start + row_bytes]);
    }
    Texture::new(rect.width, rect.height, pixels)
}

/// The page texel (column, row) that texel (`column`, `row`) of an entry packed at `placement`
/// lands on. A turned entry's X axis runs down the page's Y axis, its rows from right to left
/// (as [`Placement::atlas_position`] has it).
pub fn page_texel(placement: &Placement, column: u32, row: u32) -> (u32, u32) {
    if placement.rotated {
        (placement.x + placement.height - 1 - row, placement.y + column)
    } else {
        (placement.x + column, placement.y + row)
    }
}

/// What the composite knows of one entry of a page: where it lies, what its kept texels are
/// (a blake3 hash: the composite redoes only entries whose hash changed), and whether any of
/// them is translucent (which decides the fill's alpha).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageEntry {
    pub placement: Placement,
    pub kept_hash: [u8; 32],
    pub translucent: bool,
}

/// A `width` × `height` page of `entries` (each texture with its placement, the texture's size
/// being the placement's): each entry copied into place, the `padding` texels around it the
/// nearest texel of its own edge, every other texel the colour of the nearest entry or padding
/// texel (with alpha 0 when any entry has transparency).
pub fn composite_page(width: u32, height: u32, entries: &[(&Texture, Placement)], padding: u32) -> Texture {
    composite_page_keeping_sources(width, height, entries, padding).0
}

/// [`composite_page`], also giving where each texel took its colour from, so that a later
/// [`recomposite_page`] of the same placements needs no new search.
pub fn composite_page_keeping_sources(
    width: u32,
    height: u32,
    entries: &[(&Texture, Placement)],
    padding: u32,
) -> (Texture, TexelSources) {
    let mut pixels = vec![0u8; width as usize * height as usize * 4];
    for (texture, placement) in entries {
        paste_entry(&mut pixels, width, height, texture, placement, padding);
    }
    let placements: Vec<Placement> = entries.iter().map(|(_, placement)| *placement).collect();
    let sources = page_texel_sources(width, height, &placements, padding);
    let transparent = entries.iter().any(|(texture, _)| texture.pixels.chunks_exact(4).any(|texel| texel[3] < 255));
    (fill_page(&pixels, width, height, &sources, transparent), sources)
}

/// A page again after some of its entries' texels changed, their placements not: `previous`
/// (the last composite of the same placements) with the `changed` entries (index into
/// `entries`, texture) put back and the fill redone from `sources` (of the same placements).
pub fn recomposite_page(
    previous: &Texture,
    sources: &TexelSources,
    entries: &[PageEntry],
    changed: &[(usize, &Texture)],
    padding: u32,
) -> Texture {
    let mut pixels = previous.pixels.to_vec();
    for &(index, texture) in changed {
        paste_entry(&mut pixels, previous.width, previous.height, texture, &entries[index].placement, padding);
    }
    let transparent = entries.iter().any(|entry| entry.translucent);
    fill_page(&pixels, previous.width, previous.height, sources, transparent)
}

/// Copies an entry into place, then its padding ring: each texel the clamp of its position
/// onto the entry's content (rings never overlap: cells hold content and padding).
fn paste_entry(pixels: &mut [u8], width: u32, height: u32, texture: &Texture, placement: &Placement, padding: u32) {
    debug_assert_eq!((texture.width, texture.height), (placement.width, placement.height));
    let page_width = width as usize;
    for row in 0..texture.height {
        for column in 0..texture.width {
            let (x, y) = page_texel(placement, column, row);
            let index = y as usize * page_width + x as usize;
            let source = (row as usize * texture.width as usize + column as usize) * 4;
            pixels[index * 4..][..4].copy_from_slice(&texture.pixels[source..source + 4]);
        }
    }
    let (span_x, span_y) =
        if placement.rotated { (placement.height, placement.width) } else { (placement.width, placement.height) };
    let (left, top) = (placement.x.saturating_sub(padding), placement.y.saturating_sub(padding));
    let right = (placement.x + span_x + padding).min(width);
    let bottom = (placement.y + span_y + padding).min(height);
    for y in top..bottom {
        for x in left..right {
            let inside =
                (placement.x..placement.x + span_x).contains(&x) && (placement.y..placement.y + span_y).contains(&y);
            if inside {
                continue;
            }
            let clamped_x = x.clamp(placement.x, placement.x + span_x - 1) as usize;
            let clamped_y = y.clamp(placement.y, placement.y + span_y - 1) as usize;
            let from = (clamped_y * page_width + clamped_x) * 4;
            let index = y as usize * page_width + x as usize;
            pixels.copy_within(from..from + 4, index * 4);
        }
    }
}

/// Where each texel of a page of these placements takes its colour from: itself inside an
/// entry or its padding ring, else the nearest such texel.
pub(crate) fn page_texel_sources(width: u32, height: u32, placements: &[Placement], padding: u32) -> TexelSources {
    let mut covered = vec![false; width as usize * height as usize];
    for placement in placements {
        let (span_x, span_y) =
            if placement.rotated { (placement.height, placement.width) } else { (placement.width, placement.height) };
        let (left, top) = (placement.x.saturating_sub(padding), placement.y.saturating_sub(padding));
        let right = (placement.x + span_x + padding).min(width);
        let bottom = (placement.y + span_y + padding).min(height);
        for y in top..bottom {
            covered[y as usize * width as usize..][left as usize..right as usize].fill(true);
        }
    }
    texel_sources(
        width,
        height,
        covered.iter().enumerate().filter(|(_, &covered)| covered).map(|(index, _)| index as u32),
    )
}

/// The fill of a page: beyond the entries and their padding nothing is drawn, so those texels
/// are transparent when any entry has transparency (previews and blending show nothing
/// there), opaque otherwise (an opaque atlas stays opaque down its mips).
fn fill_page(pixels: &[u8], width: u32, height: u32, sources: &TexelSources, transparent: bool) -> Texture {
    if sources.0.is_empty() {
        return Texture::new(width, height, pixels.to_vec());
    }
    Texture::new(width, height, fill_from_sources(pixels, width, sources, transparent))
}
