//! The texture atlas's pure steps: trimming an entry's fully transparent borders, and a page put
//! together from its entries (each copied into place, turned where packed so, its padding the
//! clamp of its own edge texels, the rest of the page the nearest entry texel).

use crate::packing::Placement;
use crate::texture::Texture;

/// The part of a texture an entry keeps: `x`, `y` is the trim offset inside the source.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TrimRect {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
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

/// A `width` × `height` page of `entries` (each texture with its placement, the texture's size
/// being the placement's): each entry copied into place, the `padding` texels around it the
/// nearest texel of its own edge, every other texel the colour of the nearest entry or padding
/// texel (with alpha 0 when any entry has transparency).
pub fn composite_page(width: u32, height: u32, entries: &[(&Texture, Placement)], padding: u32) -> Texture {
    let (page_width, page_height) = (width as usize, height as usize);
    let mut pixels = vec![0u8; page_width * page_height * 4];
    let mut covered = vec![false; page_width * page_height];
    for (texture, placement) in entries {
        debug_assert_eq!((texture.width, texture.height), (placement.width, placement.height));
        for row in 0..texture.height {
            for column in 0..texture.width {
                let (x, y) = page_texel(placement, column, row);
                let index = y as usize * page_width + x as usize;
                let source = (row as usize * texture.width as usize + column as usize) * 4;
                pixels[index * 4..][..4].copy_from_slice(&texture.pixels[source..source + 4]);
                covered[index] = true;
            }
        }
        // The padding ring: each texel the clamp of its position onto the entry's content.
        let (span_x, span_y) = if placement.rotated { (placement.height, placement.width) } else { (placement.width, placement.height) };
        let (left, top) = (placement.x.saturating_sub(padding), placement.y.saturating_sub(padding));
        let right = (placement.x + span_x + padding).min(width);
        let bottom = (placement.y + span_y + padding).min(height);
        for y in top..bottom {
            for x in left..right {
                let index = y as usize * page_width + x as usize;
                if covered[index] {
                    continue;
                }
                let clamped_x = x.clamp(placement.x, placement.x + span_x - 1) as usize;
                let clamped_y = y.clamp(placement.y, placement.y + span_y - 1) as usize;
                let from = (clamped_y * page_width + clamped_x) * 4;
                pixels.copy_within(from..from + 4, index * 4);
                covered[index] = true;
            }
        }
    }
    let sources = crate::texture::fill::texel_sources(
        width,
        height,
        covered.iter().enumerate().filter(|(_, &covered)| covered).map(|(index, _)| index as u32),
    );
    if sources.0.is_empty() {
        return Texture::new(width, height, pixels);
    }
    // Beyond the entries and their padding nothing is drawn: transparent when any entry has
    // transparency (so previews and blending show nothing there), opaque otherwise (so an
    // opaque atlas stays opaque down its mips).
    let transparent = pixels.chunks_exact(4).zip(&covered).any(|(texel, &covered)| covered && texel[3] < 255);
    let mut filled = Vec::with_capacity(pixels.len());
    for (index, &from) in sources.0.iter().enumerate() {
        let mut texel: [u8; 4] = pixels[from as usize * 4..][..4].try_into().expect("four bytes");
        if transparent && !covered[index] {
            texel[3] = 0;
        }
        filled.extend_from_slice(&texel);
    }
    Texture::new(width, height, filled)
}
